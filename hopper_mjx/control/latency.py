"""A gait that knows its action delay: the torque it works out now reaches the joints `latency` s later.

Two things make a controller tuned for prompt torques fall under a delay of a few milliseconds:
- It acts on a state that is old by the time its torque acts. So `ahead` advances what it reads by the delay, at
  the velocities it reads: the base's position, its attitude (turned at the gyro's rate) and the joints' angles.
- Its joint loops are too fast for the delay. A PD loop whose damping rate kd/I is well above 1/delay pushes each
  joint back after it has already turned round: the flight PD's knee chatters at 50 Hz from 4 ms on. So `detuned`
  slows every joint loop (the flight PD, the stance's attitude servo, the unloading brake) as the delay grows
  beyond the one its gains were designed for.

Pure and per instance; a `latency` of 0 changes nothing but the attitude's rounding.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from hopper_mjx.control.base import PDScale
from hopper_mjx.hardware import rotation
from hopper_mjx.hardware.signals import Observation

# s: the delay up to which the gait's joint gains hold as designed (Raibert keeps every robot up at 2 ms and few at
# 4 ms, docs/variation.md). Beyond it the damping falls as PROMPT_DELAY/latency, so that the loop's damping rate keeps
# below the same multiple of 1/latency, and the stiffness as that ratio to STIFFNESS_POWER.
PROMPT_DELAY = 1.5e-3
# Below 2 (the power that keeps each loop's damping ratio) the flight keeps more stiffness to place the foot in its
# short Earth flights: 1.5 kept 32 of 32 robots up at Earth at 5 ms with DC motors and pushes, 2 kept 29.
STIFFNESS_POWER = 1.5


def ahead(obs: Observation, latency: jax.Array) -> Observation:
    """`obs` advanced `latency` s at its velocities: the base's position, its attitude (`qvel[3:6]`, rad/s in the
    body frame, as MuJoCo's free joint) and the joints' angles. The velocities, the time, the contact and the ground
    are as read."""
    qpos, qvel = obs.qpos, obs.qvel
    turn = qvel[3:6] * latency
    angle = jnp.linalg.norm(turn)
    axis = turn / jnp.maximum(angle, 1e-12)
    step = jnp.concatenate([jnp.cos(0.5 * angle)[None], jnp.sin(0.5 * angle) * axis])
    quat = rotation.multiply(qpos[3:7], step)  # a body-frame turn: applied after the present attitude
    return obs._replace(qpos=jnp.concatenate([qpos[:3] + qvel[:3] * latency, quat, qpos[7:] + qvel[6:] * latency]))


def detuned(scale: PDScale | None, latency: jax.Array) -> PDScale:
    """The factors on the gait's joint PD gains (times an instance's own, `scale`, when drawn) for `latency` s."""
    slower = jnp.minimum(1.0, PROMPT_DELAY / jnp.maximum(latency, 1e-9))
    kp, kd = jnp.full(3, slower**STIFFNESS_POWER), jnp.full(3, slower)
    return PDScale(kp, kd) if scale is None else PDScale(kp * scale.kp, kd * scale.kd)
