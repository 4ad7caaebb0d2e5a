"""The full stroke: a stance that uses the whole of the knee's travel, for a hop the ordinary thrust cannot give.

Raibert's thrust pushes from the bottom of a light landing to the touchdown length: of the knee's 1.6 rad an Earth
hop turns it through about 0.45, so asked for more it gets a fifth to a third of what its motors allow
(docs/sweeps.md). A hop that needs more energy than that stroke holds with the knee at its effort limit
(`needs_full`, decided at touchdown) takes the whole stroke, as the bound's push does (`hardware.bound`):

- *Compression* brakes the leg to rest `LOW_MARGIN` short of the knee's lower stop: the leg force that takes its
  inward speed to zero over the length left, m·(g + L̇²/2(L - L_low)).
- *Thrust* pushes from that bottom with the force that gives the hop's energy, m·g·(z_apex - z), over the stroke to
  the release length (the knee at `RELEASE_KNEE`, about where the bound's ideal push leaves the floor). The energy
  is capped at what the same stroke can take back on the landing (`absorbable`): the robot has no spring, so a hop
  higher than the leg can brake from lands on the knee's stop.
- Both are capped at the force the knee's effort limit gives along the foot -> COM line (and a share of the hip's,
  `HIP_SHARE`, the rest left to the attitude servo), so that no joint clips and the push stays through the COM.
- *The attitude servo* keeps its damping of the whole robot's spin, not its stiffness on the body's tilt in the
  thrust: the leg is as heavy in rotation as the body, so as the knee unfolds in a tenth of a second the hip must
  turn the body back by some 0.3 rad with no spin at all (the robot's shape, not its rotation). A servo that
  levelled that tilt would give the robot the spin it tumbles with in the flight.
- *In the flight after it* the leg is set at the release length, its foot where Raibert's speed loop places it,
  in the body's own frame, not the world's: with no spin, returning the shape turns the body back level.

Unloading is Raibert's but for its hip brake (a hip torque while the foot is down would spin the body); a hop the
ordinary stroke gives stays Raibert's.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from hopper_mjx.control import kinematics
from hopper_mjx.control.foothold import placement_angles
from hopper_mjx.control.plan import OwnPush
from hopper_mjx.control.raibert import COMPRESSION, MIN_SQUEEZE, flight_pd, speed_placement
from hopper_mjx.model.world import EARTH_GRAVITY

KNEE, HFE = 2, 1  # in (haa, hfe, kfe)
LOW_MARGIN = 0.15  # rad short of the knee's lower stop the full stroke's compression stops
RELEASE_KNEE = -0.45  # rad: the knee where the full stroke's thrust ends (the bound's ideal lift-off, -0.46..-0.48)
READY_TILT = 0.1  # rad of roll or pitch the body may have when the thrust starts
READY_RATE = 0.3  # rad/s the body may turn at when it starts
HIP_SHARE = 0.5  # of the hip's effort limit the push may take: the rest is the attitude servo's
SPIN_DAMPING = 6.0  # factor on the servo's damping of the spin in the thrust: the push is over in 0.1 s
# Times the ordinary stroke's energy a hop must need to take the full stroke. Between one and two the ordinary
# thrust falls a little short but its gentle landings keep robots up that the full stroke's would not (Mars at
# 0.6 m: Raibert hops on, the full stroke at a margin of 1 fell).
FULL_MARGIN = 2.0


def steady(body) -> jax.Array:
    """Is the body level and still enough to launch the full stroke's thrust from (`READY_TILT`, `READY_RATE`)?
    The push takes a tenth of a second, too short for the servo to correct what it starts with."""
    return (jnp.maximum(jnp.abs(body.roll), jnp.abs(body.pitch)) < READY_TILT) & \
        (jnp.linalg.norm(body.gyro[:2]) < READY_RATE)


def knee_at(leg, length) -> jax.Array:
    """rad: the knee angle (bent backwards, <= 0) whose virtual leg is `length` m (`kinematics.leg_length`'s
    inverse)."""
    l1, l2 = leg.thigh, leg.shank
    return -jnp.arccos(jnp.clip((length**2 - l1**2 - l2**2) / (2.0 * l1 * l2), -1.0, 1.0))


def release_length(leg) -> jax.Array:
    """m: the virtual leg where the full stroke's thrust ends."""
    return kinematics.leg_length(leg, RELEASE_KNEE)


def absorbable(lowest_knee: float, effort) -> jax.Array:
    """J: the most the knee at its effort limit (N·m) brakes over the stroke, release length to the bottom."""
    return effort * (RELEASE_KNEE - (lowest_knee + LOW_MARGIN))


def needs_full(leg, body, gains, target_z, g, mass: float, effort) -> jax.Array:
    """At touchdown: does the hop to a base apex at world z `target_z` need `FULL_MARGIN` times the energy the
    ordinary stroke holds? That stroke runs from the bottom Raibert's spring reaches for this landing's sink speed
    (undamped, so deepest) back to the touchdown length, the knee at its effort limit `effort` (N·m) all the way."""
    stiffness = mass * EARTH_GRAVITY / gains.sag
    weight = mass * g
    depth = (weight + jnp.sqrt(weight**2 + stiffness * mass * body.zdot**2)) / stiffness
    held = effort * (knee_at(leg, gains.leg_length) - knee_at(leg, gains.leg_length - depth))
    return mass * g * (target_z - (body.z - depth)) > FULL_MARGIN * held


def thrust(leg, body, target_z, g, mass: float, lowest_knee: float, effort) -> jax.Array:
    """N: at the full stroke's bottom, the leg force whose work over the stroke to the release length lifts the
    robot from rest to a base apex at world z `target_z`, or as high as the stroke can brake from (`absorbable`)."""
    stroke = jnp.maximum(release_length(leg) - body.length, MIN_SQUEEZE)
    energy = jnp.minimum(mass * g * (target_z - body.z), absorbable(lowest_knee, effort[KNEE]))
    return jnp.maximum(energy, 0.0) / stroke


def push(full, leg, body, phase, thrust_force, g, mass: float, lowest_knee: float, effort) -> OwnPush:
    """The full stroke's stance where `full`: the leg force in compression (brake to rest at its bottom) or
    thrust (`thrust_force`), capped where the knee, or the hip's share, reaches `effort` (3,) N·m."""
    compressing = phase == COMPRESSION
    squeeze = jnp.maximum(body.length - kinematics.leg_length(leg, lowest_knee + LOW_MARGIN), MIN_SQUEEZE)
    brake = mass * (g + body.length_rate**2 / (2.0 * squeeze))
    to_com = body.com - body.foot
    per_newton = jnp.abs(kinematics.jacobian(leg, body.q).T @ (to_com / jnp.linalg.norm(to_com)))
    cap = jnp.minimum(effort[KNEE] / jnp.maximum(per_newton[KNEE], 1e-6),
                      HIP_SHARE * effort[HFE] / jnp.maximum(per_newton[HFE], 1e-6))
    force = jnp.clip(jnp.where(compressing, brake, thrust_force), 0.0, cap)
    thrusting = full & ~compressing
    return OwnPush(where=full, force=force, stiffness=jnp.where(thrusting, 0.0, 1.0),
                   damping=jnp.where(thrusting, SPIN_DAMPING, 1.0), braked=jnp.array([0.0, 0.0, 1.0]))


def flight(leg, body, speed, scale) -> jax.Array:
    """Joint torques (3,) N·m in the flight after a full stroke: the leg at the release length, its foot where
    Raibert's speed loop places it from the COM, in the body's frame (the body's tilt from the push undone by the
    shape's return)."""
    shape = placement_angles(leg, jnp.eye(3), speed_placement(body, speed), release_length(leg), body.com)
    return flight_pd(body, shape, scale)
