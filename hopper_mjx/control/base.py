"""The controller protocol of the batched core, the one PD law, and the two trivial controllers.

A controller is a pair of pure functions for one instance, vmapped by the core:

- ``init(obs, params) -> cstate``: per-instance controller state; per-instance
  parameters (gains, commands) live inside it, so they can differ across the batch;
- ``act(cstate, obs, gravity) -> (ctrl, cstate)``: actuator controls (actuator order)
  from the instance's `Observation` (time, qpos, qvel and the foot contact of the
  previous physics step, as a real controller reads its sensors before it acts).

A position controller (``servo`` set: a trained policy) instead returns joint targets from ``act``;
its joints' drivers track them with ``servo.track`` at the physics rate, on the joints as they are
now. An action delay then holds back the targets, not the torque: the policy's command is late, the
drivers' PD loop is not (the seed's ros_control position controllers; Isaac Lab's delayed PD actuator).
A delayed stiff PD loop is unstable: a policy whose 300 N·m/rad PD torque was delayed by 4 ms fell
at every gravity.

Controllers are built by factories and compared by identity, so one built
controller reuses one compiled rollout.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx.hardware.signals import Observation
from hopper_mjx.model.layout import Layout

CState = Any  # a pytree of arrays, one instance's worth


@dataclass(frozen=True)
class Commands:
    """Where a controller's (batched) state keeps the commands a user may change while it runs:
    `read(cstate) -> (speed (N, 2) m/s, apex rise (N,) m over the standing height)` and
    `write(cstate, speed (2,), rise) -> cstate` with those commands for every instance."""

    read: Callable[[CState], tuple[Any, Any]]
    write: Callable[[CState, Any, float], CState]


@dataclass(frozen=True)
class Servo:
    """The joint drivers of a position controller: `track(cstate, target (3,) rad, obs) -> (joint torques
    (3,) N·m, cstate)` at the physics rate, and `first(cstate) -> (3,)` the targets it starts from (what
    a delay line holds before the first command reaches it)."""

    track: Callable[[CState, jax.Array, Observation], tuple[jax.Array, CState]]
    first: Callable[[CState], jax.Array]


@dataclass(frozen=True, eq=False)
class Controller:
    name: str
    init: Callable[[Observation, Any], CState]
    # (ctrl (nu,), cstate); with `servo`: (joint targets (3,) rad, cstate)
    act: Callable[[CState, Observation, jax.Array], tuple[jax.Array, CState]]
    commands: Commands | None = None  # None: the controller takes no commands (none, hold, pid)
    servo: Servo | None = None  # a position controller's joint drivers; None: `act` gives the torque
    # A controller with weights (a trained policy's network): `act` is `act_with(weights)`. The core passes them
    # to its compiled rollout as a run-time input, so another set of the same shapes (`with_weights`: another
    # checkpoint of the run) reuses that program rather than compiling one with its numbers folded in.
    weights: Any = None
    act_with: Callable[[Any], Callable] | None = None
    # Everything the functions above closed over besides the robot's model, as a string: the core keeps its traced
    # program on disk under it (`shell.programs`). None (a controller built by hand): traced in every process.
    key: str | None = None

    def __post_init__(self):
        # The core passes `weights` to `act_with` inside its compiled rollout; without it they would reach no one.
        if self.weights is not None and self.act_with is None:
            raise ValueError(f"controller {self.name!r} has weights but no act_with to run them")

    def with_weights(self, weights) -> Controller:
        """This controller acting with `weights` (the shapes of its own), in the same compiled rollout."""
        if self.act_with is None:
            raise ValueError(f"controller {self.name!r} has no weights")
        return dataclasses.replace(self, weights=weights, act=self.act_with(weights))


def pd(kp, kd, error: jax.Array, rate: jax.Array, bias: jax.Array | None = None) -> jax.Array:
    """The PD law of every joint controller here: kp·error (+ bias) - kd·rate.

    kp N·m/rad, kd N·m·s/rad, error rad, rate rad/s (the joint's, or the leg's in the world);
    bias N·m, e.g. a PID's integral term.
    """
    torque = kp * error
    if bias is not None:
        torque = torque + bias
    return torque - kd * rate


class PDScale(NamedTuple):
    """One instance's factors on a controller's joint PD gains, (3,) each, joint order (haa, hfe, kfe):
    a robot whose servo loops are tuned otherwise (`--randomize kp_scale=...,kd_scale=...`). A controller
    that takes one keeps it in its state; None (no leaves): its gains as designed, today's program."""

    kp: jax.Array
    kd: jax.Array


def scaled(kp, kd, scale: PDScale | None) -> tuple:
    """(kp, kd) times an instance's factors, or as given without them (static: nothing added)."""
    return (kp, kd) if scale is None else (kp * scale.kp, kd * scale.kd)


def pd_scale(n: int, kp=None, kd=None) -> PDScale | None:
    """(n, 3) factors of n instances, 1 where not given (kp, kd: a scalar, (3,) or (n, 3)); None without either."""
    if kp is None and kd is None:
        return None
    batch = lambda v: jnp.asarray(np.broadcast_to(1.0 if v is None else np.asarray(v, dtype=float), (n, 3)),
                                  jnp.float32)
    return PDScale(batch(kp), batch(kd))


def joint_state(layout: Layout, obs: Observation) -> tuple[jax.Array, jax.Array]:
    """(angles rad, rates rad/s) of haa, hfe, kfe."""
    return obs.qpos[jnp.asarray(layout.joint_qpos)], obs.qvel[jnp.asarray(layout.joint_dof)]


def saturate(layout: Layout, torque_by_joint: jax.Array) -> jax.Array:
    """Joint torques (haa, hfe, kfe), N·m, clipped at each joint's effort limit."""
    limit = jnp.asarray(layout.effort_limit)
    return jnp.clip(torque_by_joint, -limit, limit)


def to_ctrl(layout: Layout, torque_by_joint: jax.Array) -> jax.Array:
    """Joint torques (haa, hfe, kfe) -> actuator controls (actuator order, torque / gear)."""
    ctrl = torque_by_joint / jnp.asarray(layout.gear)
    return jnp.zeros(layout.nu).at[jnp.asarray(layout.actuator_of_joint)].set(ctrl)


def clip_to_limits(layout: Layout, torque_by_joint: jax.Array) -> jax.Array:
    """Joint torques (haa, hfe, kfe) -> actuator controls, saturated at the effort limits."""
    return to_ctrl(layout, saturate(layout, torque_by_joint))


def zero_torque(layout: Layout) -> Controller:
    """`none`: every joint limp."""
    return Controller(
        name="none",
        init=lambda obs, params: (),
        act=lambda cstate, obs, gravity: (jnp.zeros(layout.nu), cstate),
        key=f"none|{layout!r}",
    )


HOLD_GAINS = {"p": 400.0, "d": 8.0}  # N·m/rad and N·m·s/rad; stiff enough to carry 6.8 kg


def hold(layout: Layout, p: float = HOLD_GAINS["p"], d: float = HOLD_GAINS["d"]) -> Controller:
    """`hold`: PD back to the joint angles the instance started with; params: a `PDScale` or None.
    Its state is the target, and with factors (target, factors): without them, today's program."""

    def act(cstate, obs, gravity):
        target, scale = cstate if isinstance(cstate, tuple) else (cstate, None)  # static: the state's structure
        q, qd = joint_state(layout, obs)
        return clip_to_limits(layout, pd(*scaled(p, d, scale), target - q, qd)), cstate

    def init(obs, params):
        target = joint_state(layout, obs)[0]
        return target if params is None else (target, params)

    return Controller(name="hold", init=init, act=act, key=f"hold|{p!r}|{d!r}|{layout!r}")
