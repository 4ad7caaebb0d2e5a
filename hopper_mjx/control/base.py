"""The controller protocol of the batched core, and the two trivial controllers.

A controller is a pair of pure functions for one instance, vmapped by the core:

- ``init(data, params) -> cstate``: per-instance controller state; per-instance
  parameters (gains, commands) live inside it, so they can differ across the batch;
- ``act(cstate, data, gravity) -> (ctrl, cstate)``: joint torques (N·m, in actuator
  order) from the instance's MJX data. Contacts in ``data`` are those of the
  previous physics step, as a real controller reads its sensors before it acts.

Controllers are built by factories from a `Layout` and compared by identity, so
one built controller reuses one compiled rollout.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp
from mujoco import mjx

from hopper_mjx.model.layout import Layout

CState = Any  # a pytree of arrays, one instance's worth


@dataclass(frozen=True, eq=False)
class Controller:
    name: str
    init: Callable[[mjx.Data, Any], CState]
    act: Callable[[CState, mjx.Data, jax.Array], tuple[jax.Array, CState]]


def clip_to_limits(layout: Layout, torque_by_joint: jax.Array) -> jax.Array:
    """Joint torques (haa, hfe, kfe) -> actuator controls, saturated at the effort limits."""
    limit = jnp.asarray(layout.effort_limit)
    ctrl = jnp.zeros(layout.nu).at[jnp.asarray(layout.actuator_of_joint)].set(torque_by_joint)
    return jnp.clip(ctrl, -limit, limit)


def zero_torque(layout: Layout) -> Controller:
    """`none`: every joint limp."""
    return Controller(
        name="none",
        init=lambda data, params: (),
        act=lambda cstate, data, gravity: (jnp.zeros(layout.nu), cstate),
    )


HOLD_GAINS = {"p": 400.0, "d": 8.0}  # N·m/rad and N·m·s/rad; stiff enough to carry 6.8 kg


def hold(layout: Layout, p: float = HOLD_GAINS["p"], d: float = HOLD_GAINS["d"]) -> Controller:
    """`hold`: PD back to the joint angles the instance started with."""
    qadr, dadr = jnp.asarray(layout.joint_qpos), jnp.asarray(layout.joint_dof)

    def act(target, data, gravity):
        torque = p * (target - data.qpos[qadr]) - d * data.qvel[dadr]
        return clip_to_limits(layout, torque), target

    return Controller(name="hold", init=lambda data, params: data.qpos[qadr], act=act)
