"""A scenario: the typed description of one batch, built once, checked whole, taken by every tool.

    scenario = Scenario(gravity=gravity_vectors([9.81, 1.62] * 50), controller="raibert")
    sim, final, traj = scenario.run(duration=2.0)

It holds what a batch is: the robot (its URDF), the world of each instance (gravity vector,
the physics step and friction a world sets, the ground), the per-instance variation of the
robot, the engine, and the controller with its commands. `cli.check_batch` builds one from
the command line; Python builds one directly. `build` compiles the model once and makes the
engine and the controller from it; `run` is the batch-run path of simulate, render and
record, and live runs (`view`, the Foxglove stream) build theirs from the same scenario.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from hopper_mjx import registry

FLAT = "flat"  # the ground every instance stands on today; terrain fills this field in


class Built(NamedTuple):
    """A scenario compiled: the batched core, and the controller with its per-instance params."""

    sim: Any  # hopper_mjx.sim.Sim
    controller: Any
    params: Any


@dataclass(frozen=True)
class Scenario:
    gravity: np.ndarray  # (N, 3) m/s², world frame: instance i's world
    model_options: dict = field(default_factory=dict)  # keywords of model.load a world sets: timestep, friction
    urdf: str | None = None  # the robot (None: the shipped seed monoped)
    ground: str = FLAT
    variation: None = None  # per-instance robot parameters: none yet, every instance is the URDF's robot
    engine: str = registry.DEFAULT_ENGINE
    controller: str = "hold"  # a registry.CONTROLLERS name or policy:PATH
    height: float = 0.10  # m, commanded apex rise over the standing height (raibert, hopping policies)
    speed: tuple[float, float] = (0.0, 0.0)  # m/s, commanded (vx, vy)
    gains: dict | None = None  # pid: joint gains as pid.load_gains reads them
    seed: int = 0
    chunk: int = 256  # instances per vmapped chunk on a device

    @property
    def n(self) -> int:
        return len(self.gravity)

    @property
    def timestep(self) -> float:
        from hopper_mjx.model.loader import DEFAULT_TIMESTEP

        return self.model_options.get("timestep", DEFAULT_TIMESTEP)

    def build(self) -> Built:
        """Compiles the robot once, and makes the batched core and the controller from it."""
        from hopper_mjx import model
        from hopper_mjx.sim import Sim

        sim = Sim(model.load(self.urdf, **self.model_options), engine=self.engine, chunk=self.chunk)
        return Built(sim, *self._controller(sim))

    def _controller(self, sim):
        """(controller, params): the registry's `control.make`, or a trained policy."""
        if registry.is_policy(self.controller):
            from hopper_mjx.envs import policy

            path = registry.policy_path(self.controller)
            config = policy.read(path)[3]
            params = policy.policy_params(sim.robot, self.n, height=self.height, speed=self.speed, config=config)
            return policy.policy_controller(sim.mj_model, path), params
        from hopper_mjx import control

        return control.make(self.controller, sim.robot, self.n, height=self.height, speed=self.speed, gains=self.gains,
                            mj_model=sim.mj_model)

    def run(self, duration: float, sensors):
        """(Sim, final state, trajectory as NumPy) of the whole batch for `duration` s; prints the rate."""
        import jax

        sim, controller, params = self.build()
        start = time.perf_counter()
        final, traj = sim.run(self.gravity, controller, params, duration=duration, sensors=sensors, key=self.seed)
        jax.block_until_ready(traj)
        wall = time.perf_counter() - start
        steps = len(traj.time["state"]) * sensors.periods(sim.layout.timestep)["state"]
        print(f"{self.n} instances x {steps} steps on {len(sim.devices)} device(s): {wall:.1f} s "
              f"incl. compile, {self.n * steps / wall:,.0f} steps/s", file=sys.stderr)
        return sim, final, jax.tree_util.tree_map(np.asarray, traj)
