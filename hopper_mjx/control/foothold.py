"""Where a hopping controller's foot lands on terrain: the foothold a placement gives (`foothold`), that foothold
moved clear of the ground's edges (`clear_of_edges`), the ground the next hop must clear (`landing_floor`), a placement
kept within the body's tilt budget (`within_tilt_budget`), and the joint angles that place the foot there
(`placement_angles`).

Pure and per instance. `body` is what the controller senses of the robot (`raibert.Body`: its rotation, COM, foot,
velocity, heading frame `unturn`), `speed` its gait's timing (`raibert.Speed`: the last stance time), `ground`
the sensed terrain (`signals.SensedGround`, heights on the triangles the engine collides with).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx.control import kinematics
from hopper_mjx.model.robot import LegGeometry

# The foothold kept off terrain edges (`clear_of_edges`): the ground is sampled every EDGE_STEP m along the travel
# direction; an edge is a kink (a second difference above EDGE_KINK m: a step's riser, a ramp across one 4 cm cell,
# gives up to 12 mm at its ends; rough ground's curvature, 0.5 mm on amp=0.02 at wavelength 0.4, passes) or ground
# steeper than EDGE_SLOPE (the ramp between its kinks; that rough ground's steepest is 0.31). The foot's centre
# lands with no edge sample within EDGE_MARGIN (so no edge within 2 cm: a 3 cm sphere that close to a 51° riser's
# foot stands on the ground; on top of a step it stands on the top), the foothold moving at most EDGE_SHIFTS steps to
# find that. Windows reaching 10 cm ahead with shifts of up to 10 cm tilted the body at touchdown and took the
# Moon's step from 66 % cleared to 53 % (docs/control.md).
EDGE_STEP, EDGE_KINK, EDGE_SLOPE, EDGE_MARGIN, EDGE_SHIFTS = 0.01, 0.003, 0.6, 0.01, 5


def sink_speed(zdot, drop, g):
    """m/s downwards when a body rising at `zdot` m/s comes down `drop` m below where it is now (none when above)."""
    return jnp.sqrt(zdot**2 + 2.0 * g * jnp.maximum(drop, 0.0))


def fall_time(zdot, drop, g):
    """s until a body rising at `zdot` m/s comes down `drop` m below where it is now, ballistic under `g`."""
    return (zdot + sink_speed(zdot, drop, g)) / g


def foot_offset(leg: LegGeometry, body) -> jax.Array:
    """(3,) the foot's centre from the base origin, world axes."""
    return body.rot @ kinematics.from_base(leg, body.foot)


def world_com_xy(leg: LegGeometry, body, base_xy) -> jax.Array:
    """World (x, y) of the robot's centre of mass, the base origin at `base_xy`."""
    return base_xy + (body.rot @ kinematics.from_base(leg, body.com))[:2]


def foothold(leg: LegGeometry, body, base_xy, placement) -> tuple[jax.Array, jax.Array]:
    """World (x, y) where the foot lands if placed `placement` (heading frame, m) from the COM."""
    com = world_com_xy(leg, body, base_xy)
    there = com + body.unturn[:2, :2].T @ placement
    return there[0], there[1]


def _edge_windows() -> tuple[np.ndarray, np.ndarray]:
    """(sample offsets (S,) m along the travel direction, (2 EDGE_SHIFTS + 1, S - 2) which edge samples each candidate
    shift's landing window holds), constants of `clear_of_edges`."""
    back = front = round(EDGE_MARGIN / EDGE_STEP)
    first = -EDGE_SHIFTS - back - 1
    offsets = np.arange(first, EDGE_SHIFTS + front + 2) * EDGE_STEP
    kinks = np.arange(first + 1, EDGE_SHIFTS + front + 1)  # the sample each second difference is centred on
    shifts = np.arange(-EDGE_SHIFTS, EDGE_SHIFTS + 1)[:, None]
    return offsets, ((kinks >= shifts - back) & (kinks <= shifts + front)).astype(np.float32)


def clear_of_edges(leg: LegGeometry, body, ground, base_xy, placement, foot_height, g):
    """`placement` (heading frame, m from the COM) moved along the travel direction, by the least whole number of
    EDGE_STEPs (at most EDGE_SHIFTS; forward first among equals), so that the foot lands clear of terrain edges
    (the EDGE_ constants): a foot set down on a step's edge is thrown off it. Unchanged where the ground has no edge
    there, or no shift clears it. The landing point is predicted from the ballistic flight: the COM moves v·t more
    before the foot (its bottom `foot_height` m up, world z) comes down to the ground."""
    offsets, windows = _edge_windows()
    speed = jnp.linalg.norm(body.v)
    # The travel direction, heading frame; hopping in place, the heading.
    along = jnp.where(speed > 0.05, body.unturn[:2, :2] @ body.v / jnp.maximum(speed, 1e-6), jnp.array([1.0, 0.0]))
    x, y = foothold(leg, body, base_xy, placement)
    fall = fall_time(body.zdot, foot_height - ground.height(x, y), g)
    world_along = body.unturn[:2, :2].T @ along
    lands = jnp.stack([x, y]) + body.v * fall
    samples = lands[:, None] + world_along[:, None] * jnp.asarray(offsets)[None, :]
    h = ground.height(samples[0], samples[1])
    kink = jnp.abs(h[2:] - 2.0 * h[1:-1] + h[:-2]) > EDGE_KINK
    steep = jnp.abs(h[2:] - h[:-2]) > 2.0 * EDGE_STEP * EDGE_SLOPE  # a riser's ramp is straight between its kinks
    blocked = jnp.asarray(windows) @ (kink | steep).astype(jnp.float32) > 0
    steps = np.arange(-EDGE_SHIFTS, EDGE_SHIFTS + 1)
    order = jnp.asarray(np.abs(steps) + 0.5 * (steps < 0))  # nearest first, forward before back
    best = jnp.argmin(jnp.where(blocked, jnp.inf, order))
    shift = jnp.where(blocked.all(), 0.0, jnp.asarray(steps * EDGE_STEP)[best])
    return placement + shift * along


def landing_floor(leg: LegGeometry, body, ground, base_xy, speed, height, g):
    """m: the ground the next hop is aimed above: the higher of the ground under the foot now and where
    the foot lands a hop ahead (the COM travels about v·(T_s + T_f) by then, T_f the commanded flight),
    so that a hop up a step is given the energy to climb it."""
    foot = base_xy + foot_offset(leg, body)[:2]
    flight = 2.0 * jnp.sqrt(2.0 * jnp.maximum(height, 0.0) / g)
    ahead = foothold(leg, body, base_xy, body.unturn[:2, :2] @ (body.v * (speed.stance_time + flight)))
    return jnp.maximum(ground.height(foot[0], foot[1]), ground.height(*ahead))


def within_tilt_budget(wanted: jax.Array, now: jax.Array, drift: jax.Array, swing_tilt: jax.Array,
                        budget: jax.Array, length: jax.Array) -> jax.Array:
    """The placement `wanted` moved, if need be, so that the body lands tilted <= `budget`.

    Heading frame, from the COM: `now` is where the foot is, `drift` the (roll,
    pitch) the body would land with if the leg were held where it is. In flight,
    tilt + swing_tilt·(leg world angle) - H·t/I_body is constant (the robot's angular
    momentum H is), so sending the foot Δ further tilts the body by swing_tilt·Δ/L
    more. Past the budget the leg is sent short, taking up part of H itself.
    """
    allowed = jnp.clip(landing_tilt(wanted, now, drift, swing_tilt, length), -budget, budget)
    return (now[::-1] + jnp.array(SWING_SIGN) * (allowed - drift) * length / swing_tilt)[::-1]


# +x placement turns the leg by -x/L about y (pitch +), +y by +y/L about x (roll -): (roll, pitch) per unit of (y, x).
SWING_SIGN = (-1.0, 1.0)


def landing_tilt(wanted: jax.Array, now: jax.Array, drift: jax.Array, swing_tilt: jax.Array,
                 length: jax.Array) -> jax.Array:
    """(roll, pitch) rad the body lands with when the foot is sent from `now` to `wanted` (heading frame, from the
    COM), `drift` the tilt it would land with if the leg were held where it is: swing_tilt·Δ/L more per Δ m."""
    return drift + jnp.array(SWING_SIGN) * swing_tilt * (wanted[::-1] - now[::-1]) / length


def placement_angles(leg: LegGeometry, level: jax.Array, placement: jax.Array, length: jax.Array,
                      com: jax.Array) -> jax.Array:
    """Joint targets that put the foot `placement` (m, heading-frame x and y) from the
    COM (`com`, base frame from the haa axis) with a virtual leg of `length`.

    The target is built in the level frame (the body's frame without its roll and
    pitch; `level` turns body vectors into it) and turned into the body frame by
    the body's present tilt, so the foot lands where wanted although the body
    tilts: in flight it must, because this leg is as heavy in rotation as the body
    and every swing turns the body back.
    """
    x, y = placement + (level @ com)[:2]
    down = jnp.sqrt(jnp.maximum(length**2 - x**2, 1e-4)) + leg.hfe_below_haa
    z = -jnp.sqrt(jnp.maximum(down**2 - y**2, 1e-4))
    return kinematics.inverse(leg, level.T @ jnp.stack([x, y, z]))
