"""The full stroke: a stance that uses the whole of the knee's travel, for a hop the ordinary thrust cannot give.

Raibert's thrust pushes from the bottom of a light landing to the touchdown length: of the knee's 1.6 rad an Earth
hop turns it through about 0.45, so asked for more it gets a fifth to a third of what its motors allow
(docs/sweeps.md). A hop that needs more energy than that stroke holds with the knee at its effort limit
(`needs_full`, decided at touchdown) takes the whole stroke, as the bound's push does (`hardware.bound`):

- *Compression* brakes the leg to rest `LOW_MARGIN` short of the knee's lower stop: the leg force that takes its
  inward speed to zero over the length left, m·(g + L̇²/2(L - L_low)).
- *Thrust* pushes from that bottom with the force that gives the hop's energy, m·g·(z_apex - z), over the stroke to
  the release length (the knee at `RELEASE_KNEE`, about where the bound's ideal push leaves the floor), or until the
  motors' speed line has no push left (`spent`). The energy
  is capped at what the same stroke can take back on the landing (`absorbable`): the robot has no spring, so a hop
  higher than the leg can brake from lands on the knee's stop.
- Both are capped at the force the knee's effort limit gives along the foot -> COM line (and a share of the hip's,
  `HIP_SHARE`, the rest left to steer the spin), so that no joint clips and the push stays through the COM.
- *From the thrust to lift-off* the hip holds the whole robot's angular momentum at zero (`SpinLoop`), in place of
  the attitude servo: nothing in the flight changes that momentum, so a robot that leaves the floor turning keeps
  turning, over flights of up to half a minute at the lowest gravities. The body's tilt is left free: the leg is as
  heavy in rotation as the body, so as the knee unfolds in a tenth of a second the body must turn back by some
  0.3 rad with no spin at all (the robot's shape, not its rotation). A servo that levelled that tilt would give the
  robot the spin it tumbles with in the flight.
- *In the flight after it* the leg is set at the release length, its foot where Raibert's speed loop places it,
  in the body's own frame, not the world's: with no spin, returning the shape turns the body back level.

Unloading has no hip brake (a hip torque while the foot is down would spin the body) and brakes the knee only after
a spent push; a hop the ordinary stroke gives stays Raibert's.
"""

from __future__ import annotations

from typing import NamedTuple

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
HIP_SHARE = 0.5  # of the hip's effort limit the push may take: the rest steers the spin (`SpinLoop`)
SPIN_TIME = 0.002  # s: from the thrust to lift-off the spin is taken to zero at H / SPIN_TIME (two steps)
MAX_UNASKED = 200.0  # N·m: the bound on the leg's own turning fed forward (a jolt in the gyro is not one)
SPENT = 0.95  # of a joint's no-load speed at which the thrust's push is spent: its motor's line gives 5 % of stall
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


def spent(body, no_load) -> jax.Array:
    """Is the push spent: has the hip or knee reached `SPENT` of its motor's no-load speed `no_load` (3,) rad/s (inf:
    motors with no speed line)? A DC motor's push is spent so before the release length: the foot would drag on the
    floor under a fading push and a hip that can no longer steer, and tilt the floor's force off the COM."""
    return jnp.any(jnp.abs(body.qd[HFE:]) >= SPENT * no_load[HFE:])


def release(leg, body, no_load) -> jax.Array:
    """m: the leg length that ends the full stroke's thrust: the release length, or at once where the push is
    `spent` (its unloading then brakes the knee, which lifts the foot off the floor)."""
    return jnp.where(spent(body, no_load), 0.0, release_length(leg))


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


def push(full, leg, body, phase, thrust_force, g, mass: float, lowest_knee: float, effort, loop: "SpinLoop",
         dt: float, braked) -> tuple[OwnPush, "SpinLoop"]:
    """The full stroke's stance where `full`: the leg force in compression (brake to rest at its bottom) or
    thrust (`thrust_force`), capped where the knee, or the hip's share, reaches `effort` (3,) N·m; from the
    thrust to lift-off, the hip torques that hold the spin at zero (`SpinLoop`, one step `dt` s). Its unloading
    brakes the knee where `braked` (a spent push); else the knee coasts: braked at 40-50 rad/s with the floor still
    pushing on the foot, it would kick the robot into a spin as it leaves the floor."""
    compressing = phase == COMPRESSION
    squeeze = jnp.maximum(body.length - kinematics.leg_length(leg, lowest_knee + LOW_MARGIN), MIN_SQUEEZE)
    brake = mass * (g + body.length_rate**2 / (2.0 * squeeze))
    to_com = body.com - body.foot
    jac = kinematics.jacobian(leg, body.q)
    per_newton = jnp.abs(jac.T @ (to_com / jnp.linalg.norm(to_com)))
    cap = jnp.minimum(effort[KNEE] / jnp.maximum(per_newton[KNEE], 1e-6),
                      HIP_SHARE * effort[HFE] / jnp.maximum(per_newton[HFE], 1e-6))
    force = jnp.clip(jnp.where(compressing, brake, thrust_force), 0.0, cap)
    thrusting = full & ~compressing
    turn, loop = loop.step(kinematics.angular_momentum(leg, body.q, body.qd, body.gyro)[:2], thrusting, jac,
                           to_com, dt)
    return OwnPush(where=full, force=force, stiffness=jnp.where(thrusting, 0.0, 1.0),
                   damping=jnp.where(thrusting, 0.0, 1.0), braked=jnp.where(braked, 1.0, 0.0) * jnp.eye(3)[KNEE],
                   turn=turn), loop


class SpinLoop(NamedTuple):
    """Holds the whole robot's roll and pitch momentum H at zero from the thrust to lift-off, with the hip alone
    (the knee's torque is the push's). The floor's force F at the foot turns the robot at (foot - COM) x F, and a
    hip torque Δτ moves F by -J'⁻¹Δτ (the static balance of the leg); a 2 x 2 solve gives the haa and hfe torques
    for the rate Ḣ asked. That balance leaves out the leg's own inertia: as the knee unfolds at 20-40 rad/s it
    turns the robot faster than a feedback of H alone can follow at one step. What H did beyond what was asked of it
    last step is that turning, fed forward (the next step's is much like it)."""

    spin: jax.Array  # (2,) N·m·s, roll and pitch momentum last step
    asked: jax.Array  # (2,) N·m, the turning rate asked for last step (0 outside the thrust)
    unasked: jax.Array  # (2,) N·m, the turning rate the leg's own motion gave last step

    @classmethod
    def zero(cls) -> "SpinLoop":
        zero = jnp.zeros(2, jnp.float32)
        return cls(spin=zero, asked=zero, unasked=zero)

    def step(self, spin, on, jac, to_com, dt: float) -> tuple[jax.Array, "SpinLoop"]:
        """(joint torques (3,) N·m, haa and hfe, that turn the robot at the rate asked; the next loop): `spin` this
        step's roll and pitch momentum, `jac` the foot's Jacobian, `to_com` foot -> COM, base frame."""
        unasked = jnp.where(on, jnp.clip((spin - self.spin) / dt - self.asked, -MAX_UNASKED, MAX_UNASKED), 0.0)
        asked = jnp.where(on, -spin / SPIN_TIME - unasked, 0.0)
        # Off, the solve is dropped: with the leg straight in a flight J' has no inverse, and its NaN must not pass.
        turn = jnp.where(on, hip_torques(jac, to_com, asked), 0.0)
        return turn, SpinLoop(spin=spin, asked=asked, unasked=unasked)


def hip_torques(jac, to_com, rate) -> jax.Array:
    """(3,) N·m: the haa and hfe torques (the knee's 0) whose move of the floor's force, -J'⁻¹Δτ, turns the robot
    at `rate` (2,) N·m about its roll and pitch axes: (foot - COM) x ΔF = to_com x J'⁻¹Δτ. Both inverses in closed
    form: XLA:CPU's LU for a 3 x 3 and a 2 x 2 cost the jump's step two thirds more time."""
    c0, c1, c2 = jac[:, 0], jac[:, 1], jac[:, 2]  # J' has these as rows: J'⁻¹'s columns are their cross products
    inverse = jnp.stack([jnp.cross(c1, c2), jnp.cross(c2, c0)]) / jnp.dot(c0, jnp.cross(c1, c2))  # haa's, hfe's
    (a, b), (c, d) = jnp.cross(to_com[None, :], inverse)[:, :2].T  # (roll, pitch) per (haa, hfe)
    hips = jnp.stack([d * rate[0] - b * rate[1], a * rate[1] - c * rate[0]]) / (a * d - b * c)
    return jnp.concatenate([hips, jnp.zeros(1)])


def flight(leg, body, speed, scale) -> jax.Array:
    """Joint torques (3,) N·m in the flight after a full stroke: the leg at the release length, its foot where
    Raibert's speed loop places it from the COM, in the body's frame (the body's tilt from the push undone by the
    shape's return)."""
    shape = placement_angles(leg, jnp.eye(3), speed_placement(body, speed), release_length(leg), body.com)
    return flight_pd(body, shape, scale)
