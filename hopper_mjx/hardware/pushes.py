"""Random pushes during a run: every `every` physics steps each instance's base gets a horizontal
velocity change of `speed` m/s in a direction of its own (not only the kick at the start).

A push is an impulse: it changes the base's linear velocity at once, as a short shove would,
and it is applied before the step's forward, so every engine sees the same state. The
directions are drawn from the instance's key and the step's index, so the same seed gives the
same pushes whatever the chunking.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp


class Pushes(NamedTuple):
    """The static schedule: how often and how hard."""

    every: int  # physics steps between pushes (the first after `every` steps, at t = every·dt)
    speed: float  # m/s, the horizontal velocity change of one push

    @classmethod
    def of(cls, interval: float, speed: float, timestep: float) -> "Pushes":
        """From an interval in s (whole physics steps) and a speed in m/s."""
        every = round(interval / timestep)
        if every < 1 or abs(every * timestep - interval) > 1e-9:
            raise ValueError(f"the push interval must be a whole number (>= 1) of physics steps ({timestep:g} s), "
                             f"got {interval:g} s")
        if not speed >= 0:
            raise ValueError(f"the push speed must be >= 0 m/s, got {speed:g}")
        return cls(every, float(speed))


def push(pushes: Pushes, key: jax.Array, step: jax.Array, qvel: jax.Array) -> jax.Array:
    """One instance's qvel with the push due after `step` physics steps (unchanged between pushes):
    +speed along a horizontal direction drawn from (key, step)."""
    angle = jax.random.uniform(jax.random.fold_in(key, step), (), minval=0.0, maxval=2 * jnp.pi)
    due = (step > 0) & (step % pushes.every == 0)
    dv = jnp.where(due, pushes.speed, 0.0) * jnp.stack([jnp.cos(angle), jnp.sin(angle)])
    return qvel.at[:2].add(dv.astype(qvel.dtype))
