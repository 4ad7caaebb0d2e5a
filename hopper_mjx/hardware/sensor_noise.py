"""What a controller reads of its robot, per instance: its sensors' noise and bias, and their delay.

Between the engine and the controller, as the motors (`hopper_mjx.hardware.actuators`) sit between the
controller and the engine, per instance and pure:

    observation -> [IMU and odometry noise, gyro bias] -> [delay line] -> the controller

- Noise: each physics step the IMU's angular rate (the base's body-frame rate, qvel[3:6]) gets
  its bias plus Gaussian noise of its std, the odometry's position (qpos[:3]) and linear velocity
  (qvel[:3]) theirs; joint encoders and the contact stay exact. The recorded IMU and odometry
  streams get the same per-instance std and bias (`signals.add_noise`, in one pass with the streams' own
  noise); the accelerometer only there (no controller reads it).
- Delay: the controller reads the observation `delay` physics steps old (its time, joints and
  contact as they were then); before that many steps have passed it reads the first one.

The delay line's length and whether noise is drawn are static (they shape the program); the
figures are per-instance values in the batch's state (`SensorState`), so instances differ without a
recompile. Noise draws come from the instance's key and the step's index, so the same seed gives the
same noise whatever the chunking.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx.hardware.signals import Observation

NOISE_STREAM = 1  # folded into an instance's per-step key: its own stream beside the pushes' directions


class SensorState(NamedTuple):
    """One instance's sensor figures and its delay line."""

    line: Observation  # each leaf (depth, ...): the readings of the last `depth` steps, newest first
    delay: jax.Array  # () int32, physics steps from a reading to the controller
    gyro_noise: jax.Array  # () rad/s, std per axis
    gyro_bias: jax.Array  # (3,) rad/s
    accel_noise: jax.Array  # () m/s², the recorded IMU's only
    odom_pos_noise: jax.Array  # () m
    odom_vel_noise: jax.Array  # () m/s (the recorded angular velocity too, rad/s)


FIGURES = ("gyro_noise", "gyro_bias", "accel_noise", "odom_pos_noise", "odom_vel_noise")


class Sensing:
    """The static part: the delay line's length and whether the readings are noisy."""

    def __init__(self, max_delay: int = 0, noisy: bool = False):
        if max_delay < 0:
            raise ValueError(f"the sensor delay must be >= 0 steps, got {max_delay}")
        self.depth, self.noisy = max_delay + 1, noisy

    @property
    def passthrough(self) -> bool:
        """Adds nothing to the step: the core then skips it altogether."""
        return self.depth == 1 and not self.noisy

    def init(self, obs: Observation, delay_steps, figures: dict) -> SensorState:
        """A batch's sensor state: `obs` the batched first observation (fills the line), `delay_steps`
        (N,) ints, `figures` {FIGURES name: (N,) or (N, 3) for the bias} (absent: 0)."""
        n = obs.qpos.shape[0]
        delay = np.broadcast_to(np.asarray(delay_steps, dtype=np.int32), (n,))
        if delay.min() < 0 or delay.max() >= self.depth:
            raise ValueError(f"sensor delays must be 0..{self.depth - 1} steps, got {delay.min()}..{delay.max()}")
        unknown = set(figures) - set(FIGURES)
        if unknown:
            raise ValueError(f"unknown sensor figure(s) {sorted(unknown)}; expected some of {list(FIGURES)}")
        if any(np.any(np.asarray(v) != 0) for v in figures.values()) and not self.noisy:
            raise ValueError("noisy sensor figures need Sensing(noisy=True)")
        f32 = lambda name, shape: jnp.asarray(np.broadcast_to(figures.get(name, 0.0), (n, *shape)), jnp.float32)
        return SensorState(line=jax.vmap(self.first)(obs), delay=jnp.asarray(delay), gyro_noise=f32("gyro_noise", ()),
                           gyro_bias=f32("gyro_bias", (3,)), accel_noise=f32("accel_noise", ()),
                           odom_pos_noise=f32("odom_pos_noise", ()), odom_vel_noise=f32("odom_vel_noise", ()))

    def first(self, obs: Observation) -> Observation:
        """One instance's delay line before its first step: every slot holds its first observation."""
        return jax.tree_util.tree_map(lambda x: jnp.repeat(x[None], self.depth, axis=0), obs)

    def apply(self, s: SensorState, obs: Observation, key: jax.Array, step: jax.Array
              ) -> tuple[Observation, SensorState]:
        """(what the controller reads, the state after this step) of one instance, at physics step `step`."""
        if self.noisy:
            obs = noisy(s, obs, jax.random.fold_in(jax.random.fold_in(key, step), NOISE_STREAM))
        shift = lambda new, old: jnp.concatenate([new[None], old[:-1]])  # newest first
        s = s._replace(line=jax.tree_util.tree_map(shift, obs, s.line))
        return reading(s), s


def reading(s: SensorState) -> Observation:
    """What one instance's controller reads now: the line's observation `delay` steps old."""
    return jax.tree_util.tree_map(lambda x: x[s.delay], s.line)


def noisy(s: SensorState, obs: Observation, key: jax.Array) -> Observation:
    """The observation as the IMU and odometry read it: rate + bias + noise, position and velocity + noise."""
    k = jax.random.split(key, 3)
    gauss = lambda k, std, like: std * jax.random.normal(k, like.shape, like.dtype)
    rate = obs.qvel[3:6] + s.gyro_bias + gauss(k[0], s.gyro_noise, obs.qvel[3:6])
    pos = obs.qpos[:3] + gauss(k[1], s.odom_pos_noise, obs.qpos[:3])
    vel = obs.qvel[:3] + gauss(k[2], s.odom_vel_noise, obs.qvel[:3])
    return obs._replace(qpos=obs.qpos.at[:3].set(pos), qvel=obs.qvel.at[:3].set(vel).at[3:6].set(rate))
