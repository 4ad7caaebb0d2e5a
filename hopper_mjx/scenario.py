"""A scenario: the typed description of one batch, built once, checked whole, taken by every tool.

    scenario = Scenario(gravity=gravity_vectors([9.81, 1.62] * 50), controller="raibert")
    sim, final, traj = scenario.run(duration=2.0)

It holds what a batch is: its `Physics` (the robot's URDF, the physics step and friction a
world sets, the ground, the per-instance variation of the robot, the engine), the gravity
vector of each instance, and the controller with its commands. `cli.check_batch` builds one
from the command line; Python builds one directly. `build` makes the batched core and the
controller from the model its physics compiled once; `run` is the batch-run path of
simulate, render and record, and live runs (`view`, the Foxglove stream) build theirs from
the same scenario.

`Physics` alone is what every tool that lays out its own instances takes (the sweeps, the
bench, the profile, training): a new dimension of the world or the robot is one field here,
one option in `cli.add_physics_options`, and one input of the step.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field, fields
from functools import cached_property
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from hopper_mjx import registry
from hopper_mjx.shell.checks import counted
from hopper_mjx.terrain import FLAT, Ground
from hopper_mjx.variation.spec import Spec


class Built(NamedTuple):
    """A scenario compiled: the batched core, and the controller with its per-instance params."""

    sim: Any  # hopper_mjx.sim.Sim
    controller: Any
    params: Any


@dataclass(frozen=True)
class Physics:
    """What compiles into the batched core, whatever the instances' gravity and controller."""

    urdf: str | None = None  # the robot (None: the shipped seed monoped)
    model_options: dict = field(default_factory=dict)  # keywords of model.load a world sets: timestep, friction
    ground: Ground = FLAT  # `terrain.parse` of a --terrain spec; under seed=each the model holds instance 0's
    variation: Spec | None = None  # per-instance robot parameters, drawn per instance (None: the URDF's robot)
    engine: str = registry.DEFAULT_ENGINE
    motor: str = registry.DEFAULT_MOTOR  # a registry.MOTORS name (hopper_mjx.hardware.actuators)
    action_delay: float = 0.0  # s from a command (torque, or a policy's targets) to the motors, whole steps
    push: tuple[float, float] | None = None  # (interval s, speed m/s) of random horizontal pushes during runs

    @property
    def timestep(self) -> float:
        from hopper_mjx.model.loader import DEFAULT_TIMESTEP

        return self.model_options.get("timestep", DEFAULT_TIMESTEP)

    @property
    def delay_steps(self) -> int:
        return round(self.action_delay / self.timestep)

    @cached_property
    def mj_model(self):
        """The compiled MuJoCo model: compiled on first use, once (the checks and the build share it)."""
        from hopper_mjx import model

        return model.load(self.urdf, terrain=self.ground.terrain(), **self.model_options)

    def spec(self):
        """A fresh editable `MjSpec` of the same model, for what only pictures add to it."""
        from hopper_mjx import model

        return model.build_spec(self.urdf, terrain=self.ground.terrain(), **self.model_options)

    def sim(self, *, chunk: int = 256, devices=None, controls: dict | None = None):
        """The batched core (hopper_mjx.sim.Sim) on this physics' model and engine; `controls`: the drawn
        control parameters of the batch it will run (`Scenario.controls`), whose longest delays size its
        delay lines (without them, the distributions' largest values)."""
        from hopper_mjx.hardware.pushes import Pushes
        from hopper_mjx.hardware.sensor_noise import FIGURES, Sensing
        from hopper_mjx.sim import Sim

        pushes = None if self.push is None else Pushes.of(*self.push, self.timestep)
        varies = self.variation.fields if self.variation else frozenset()
        drawn = self.variation.controls if self.variation else {}
        noisy = any(name in drawn for name in FIGURES)
        return Sim(self.mj_model, engine=self.engine, chunk=chunk, devices=devices, motor=self.motor,
                   delay_steps=self.delay_steps, pushes=pushes, varies=varies,
                   max_delay=self.longest_delay("action_delay", controls),
                   sensing=Sensing(self.longest_delay("sensor_delay", controls), noisy))

    def longest_delay(self, name: str, controls: dict | None = None) -> int:
        """Physics steps of the longest `name` (action_delay, sensor_delay) an instance may draw: the drawn
        values' largest, else the distribution's (within the parameter's range); 0 when not drawn."""
        dist = (self.variation.controls if self.variation else {}).get(name)
        if dist is None:
            return 0
        if controls is not None and name in controls:
            ms = float(controls[name].max())
        else:
            ms = min(dist.bound(), registry.CONTROL_PARAMETERS[name].high)
        return round(ms / (self.timestep * 1e3))

    def to_json(self) -> dict:
        """The fields as a run's manifest or config records them (the ground and the variation as their specs)."""
        record = {f.name: getattr(self, f.name) for f in fields(self)}
        return record | {"ground": str(self.ground), "variation": str(self.variation) if self.variation else None}

    @classmethod
    def from_json(cls, record: dict) -> Physics:
        """The physics of a `to_json` record (a sweep's manifest); a field the record lacks, an older run's: its
        default. Other keys beside the fields (a manifest's grid) are left alone."""
        from hopper_mjx import terrain

        known = {f.name: record[f.name] for f in fields(cls) if f.name in record}
        known["ground"] = terrain.parse(known.get("ground") or "flat")
        known["variation"] = Spec.parse(known["variation"]) if known.get("variation") else None
        known["push"] = tuple(known["push"]) if known.get("push") else None
        known["model_options"] = {k: tuple(v) if isinstance(v, list) else v  # JSON's lists were tuples
                                  for k, v in known.get("model_options", {}).items()}
        return cls(**known)

    def described(self) -> dict[str, str]:
        """This physics in words, one phrase per field (a plot's subtitle): the motors, delay, pushes, robot and
        ground always, so that two runs never look alike; the URDF, model options and engine where not the
        defaults."""
        from hopper_mjx.model import loader

        words = {"motor": f"{self.motor} motors",
                 "action_delay": f"action delay {self.action_delay * 1e3:g} ms" if self.action_delay else "no delay",
                 "push": f"pushes of {self.push[1]:g} m/s every {self.push[0]:g} s" if self.push else "no pushes",
                 "variation": f"randomised {self.variation}" if self.variation else "the URDF's robot",
                 "ground": "flat ground" if self.ground.is_flat else f"terrain {self.ground}"}
        if self.urdf:
            words["urdf"] = f"URDF {Path(self.urdf).name}"
        defaults = {"timestep": loader.DEFAULT_TIMESTEP, "friction": (loader.FOOT_FRICTION,) * 2,
                    "iterations": loader.SOLVER_ITERATIONS, "ls_iterations": loader.SOLVER_ITERATIONS}
        changed = [f"timestep {v * 1e3:g} ms" if k == "timestep" else f"{k.replace('_', ' ')} {v}"
                   for k, v in self.model_options.items() if v != defaults.get(k)]  # a world's, or --as-trained's
        if changed:
            words["model_options"] = ", ".join(changed)
        if self.engine != registry.DEFAULT_ENGINE:
            words["engine"] = f"engine {self.engine}"
        return words

    def flags(self) -> list[str]:
        """The command-line options that give this physics but its engine (`cli.add_physics_options`'),
        for a child process; of a world's model options only the timestep has a flag."""
        extra = set(self.model_options) - {"timestep"}
        if extra:
            raise ValueError(f"this physics has no command-line form ({', '.join(sorted(extra))})")
        return ((["--urdf", str(self.urdf)] if self.urdf else [])
                + (["--terrain", str(self.ground)] if not self.ground.is_flat else [])
                + (["--randomize", str(self.variation)] if self.variation else [])
                + (["--timestep", repr(self.timestep)] if "timestep" in self.model_options else [])
                + (["--motor", self.motor] if self.motor != registry.DEFAULT_MOTOR else [])
                + (["--action-delay", repr(self.action_delay * 1e3)] if self.action_delay else [])
                + (["--push", ",".join(map(repr, self.push))] if self.push else []))


@dataclass(frozen=True)
class Scenario:
    gravity: np.ndarray  # (N, 3) m/s², world frame: instance i's world
    physics: Physics = field(default_factory=Physics)
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
        return self.physics.timestep

    def magnitudes(self) -> list[float]:
        """The batch's distinct gravity magnitudes above 0, m/s², ascending."""
        return sorted({float(g) for g in np.round(np.linalg.norm(self.gravity, axis=1), 9) if g > 0})

    def build(self) -> Built:
        """The batched core on the physics' model (compiled once), and the controller (with each instance's
        PD factors, when drawn)."""
        controls = self.controls(self.physics.mj_model)
        sim = self.physics.sim(chunk=self.chunk, controls=controls)
        return Built(sim, *self._controller(sim, controls))

    def draws(self, mj_model) -> dict[str, np.ndarray]:
        """{model field: (N, ...)} float64 of each instance's robot, drawn with the scenario's seed (empty
        without a variation); raises ValueError naming a parameter that drew a value outside its range."""
        if not self.physics.variation:
            return {}
        from hopper_mjx.variation import draw

        return draw.draw(self.physics.variation, mj_model, self.n, self.seed)

    def controls(self, mj_model) -> dict[str, np.ndarray]:
        """{control parameter: (N,) or (N, 3)} of each instance's controller, motors and sensors, drawn with
        the scenario's seed (`variation.draw.draw_controls`; empty without any)."""
        if not self.physics.variation:
            return {}
        from hopper_mjx.variation import draw

        return draw.draw_controls(self.physics.variation, mj_model, self.n, self.seed)

    def grounds(self) -> np.ndarray | None:
        """(N, nrow, ncol) m: each instance's own ground under a --terrain with seed=each (drawn with the
        scenario's seed); None: every instance on the model's ground."""
        return self.physics.ground.grids(self.seed, range(self.n))

    def varied(self, mj_model) -> dict[str, np.ndarray]:
        """`draws` and the constants MuJoCo derives from them, per instance: what `Sim.reset` takes."""
        from hopper_mjx.variation.draw import with_constants

        return with_constants(mj_model, self.draws(mj_model))

    def _controller(self, sim, controls: dict):
        """(controller, params): the registry's `control.make`, or a trained policy."""
        from hopper_mjx.control.base import pd_scale

        pd = pd_scale(self.n, controls.get("kp_scale"), controls.get("kd_scale"))
        if registry.is_policy(self.controller):
            from hopper_mjx.envs import policy

            path = registry.policy_path(self.controller)
            config = policy.read(path)[3]
            params = policy.policy_params(sim.robot, self.n, height=self.height, speed=self.speed, config=config,
                                          pd=pd)
            return policy.policy_controller(sim.mj_model, path), params
        from hopper_mjx import control
        from hopper_mjx.variation.draw import legs

        # Raibert models each drawn leg (the others take none): measured only for it, a few ms per distinct leg.
        own = legs(sim.mj_model, self.draws(sim.mj_model)) if self.controller in registry.GAIT_CONTROLLERS \
            else None
        latency = controls["action_delay"] * 1e-3 if "action_delay" in controls else self.physics.action_delay
        return control.make(self.controller, sim.robot, self.n, height=self.height, speed=self.speed, gains=self.gains,
                            mj_model=sim.mj_model, pd=pd, legs=own, latency=latency,
                            motor=sim.actuation.kind)

    def run(self, duration: float, sensors):
        """(Sim, final state, trajectory as NumPy) of the whole batch for `duration` s; prints the rate."""
        import jax

        sim, controller, params = self.build()
        start = time.perf_counter()
        final, traj = sim.run(self.gravity, controller, params, duration=duration, sensors=sensors, key=self.seed,
                              variation=self.varied(sim.mj_model), ground=self.grounds(),
                              **sim.per_instance(self.controls(sim.mj_model)))
        jax.block_until_ready(traj)
        wall = time.perf_counter() - start
        steps = len(traj.time["state"]) * sensors.periods(sim.layout.timestep)["state"]
        print(f"{counted(self.n, 'instance')} x {steps} steps on {counted(len(sim.devices), 'device')}: {wall:.1f} s "
              f"incl. compile, {self.n * steps / wall:,.0f} steps/s", file=sys.stderr)
        return sim, final, jax.tree_util.tree_map(np.asarray, traj)
