"""`jump`: Raibert's gait, each hop sized to the ground ahead and the leg drawn up over what is there.

Raibert (`raibert`) aims a hop at the commanded rise above the ground it lands on. A block it must pass over on the
way to its landing (a wall whose far side it lands beyond) it does not see: the leg swings into it. The jump looks
ahead along the commanded direction of travel, on the known ground (`signals.SensedGround`, `obstacle`), and makes
the stance before an obstacle a *leap*:

- *Decide, in the flight before.* Where the foot comes down, would the next ordinary stride reach the obstacle's
  face? Then that stance launches a leap. The leap's apex is what lets the leg, drawn up (`tuck_drop` below the
  base), pass `CLEARANCE` over the top; its flight lasts 2·√(2·rise/g), in which the COM must carry from its lift-off
  (v·T_s/2 past the foot) to within `LAND_AHEAD` of a landing `LAND_BEYOND` past the far edge. The speed that needs
  comes from the launching stance: its foot is set `boost` behind Raibert's neutral point, and the push along the
  leg, tilted by b/L, gives the COM about b/L of its vertical speed change forwards (at most `MAX_BOOST`). A foot
  that would come down within `FACE_MARGIN` of the face is set back to it.
- *Slow hops.* A touchdown while the body still rises is the last stance's foot bouncing, not the launching
  stance. Below about 1.3 m/s² the flight before a leap keeps Raibert's foothold, shifted by the boost (`Leap.shift`),
  a gap's leap takes height for boost (`gap_lift`), and a launching stance squeezed less than Raibert's thrust
  assumes gets the force its shorter stroke needs.
- *Launch.* At the stance's bottom the leap's rise, `LEAP_GAIN` over what the geometry asks (the leg's jerk off the
  floor takes a share of a hop's energy that Raibert's bias learns over many hops, and a leap is one hop), becomes
  the apex Raibert's height loop sizes the thrust for, capped by what the motors give; a boosted block leap's thrust
  also gives the forward speed its push makes (`forward_work`). The leap does not adapt the bias of the hops after
  it. A boosted leap over a block leaves the floor with the spin that lands it level
  (`landing_spin`): the flight's swing of the foot from behind the COM to ahead of it turns the body forward.
- *Over.* In the leap's flight the leg is drawn up (the knee `TUCK_KNEE` short of its stop), the foot held
  `FACE_MARGIN` short of the face until its bottom is above the top, then carried on just far enough that it is past
  the far edge when, falling, it would reach the top: each centimetre of the foot ahead of the COM turns the body
  back, the leg being as heavy in rotation as the body. Past the far edge the leg reaches down beyond it, within
  Raibert's tilt budget and no nearer than Raibert's speed loop would set it; over a block taller than the knee
  stands, far enough that the knee lands past the edge (`knee_room`).
- *Gaps.* Ground `STEP_UP` below the foot's, with its far side back at the foot's level in view, is a gap: its top
  is the lip, which asks no rise, so the leap rises as high as carrying the COM across needs with the most boost
  (`carry_speed`), or, for slow hops, where height is cheap, as high as carrying it across with less (`gap_lift`).
  The boost's swing tilts the body forward before that stance; a gap's launching stance leaves the
  tilt to the leap's flight (its servo only damps the spin), since levelling it from the floor spins the robot in
  a flight of up to a second. A step down with no far side in view is hopped down.

On the flat plane (no height field) the jump is Raibert: nothing to look at. Hopping in place (no commanded speed)
it leaps nothing. On any ground, a hop asked for more than Raibert's ordinary stroke holds takes the full stroke
(`control.stroke`) instead: the knee's whole travel, as the energy bound's push does. The commands, gains and
per-instance legs are Raibert's (`raibert_params`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from hopper_mjx import registry
from hopper_mjx.control import raibert, stroke
from hopper_mjx.control.base import Controller
from hopper_mjx.control.foothold import (
    fall_time,
    foot_offset,
    landing_tilt,
    placement_angles,
    sink_speed,
    within_tilt_budget,
    world_com_xy,
)
from hopper_mjx.control.kinematics import leg_length
from hopper_mjx.hardware.actuators import nominal_no_load
from hopper_mjx.model.robot import Robot

STEP_UP = 0.05  # m over the floor under the foot: ground the foot must be drawn up over
CLEARANCE = 0.05  # m the drawn-up foot's bottom is aimed over an obstacle's top
TUCK_AHEAD = 0.10  # m ahead of the hip the drawn-up foot is carried (level frame)
TUCK_KNEE = 0.1  # rad short of the knee's lower stop the drawn-up leg holds
FACE_MARGIN = 0.06  # m the foot's edge is held short of an obstacle's face until it is above the top
LAND_BEYOND = 0.08  # m past an obstacle's far edge the foot's edge is set down
# m past a tall block's far edge the knee lands (`knee_room`): the shank's radius and 3 cm for the leg's lean at
# touchdown. Of 1, 3, 5 and 7 cm, the DC motors' block sweep kept 207, 240, 249 and 241 of 480 robots up.
KNEE_CLEAR = 0.05
LEAP_REACH = 0.3  # m: the farthest ahead of the COM a leap's foot is set down
LEAP_GAIN = 1.25  # on a leap's rise over the stance (see `Leap.aim`)
LAND_AHEAD = 0.05  # m: the farthest ahead of the COM a leap's landing may want the foot, so the body lands upright
MAX_BOOST = 0.16  # m: the farthest a launching stance's foot is set behind the neutral point
# m/s: the fastest a gap's leap lifts off to carry the COM across with less boost (`gap_lift`)
LEVEL_LIFT = 1.0
# m/s: a hop that leaves the floor slower than this (its commanded rise, below about 1.3 m/s² at 0.1 m) flies before a
# leap as Raibert's does (`Leap.shift`)
SLOW_LIFT = 0.5
SHALLOWEST = 0.002  # m: the least stroke a shallow leap's thrust is spread over
KNEE = 2  # kfe in (haa, hfe, kfe)
SAMPLES = 64  # ground samples along the way
LOOK_SPAN = 1.2  # m the samples span ahead of the foot (a flight's travel, the foot's reach and margins)


class JumpState(NamedTuple):
    """The jump's own state, one instance's; positions along the way are world (x, y)·`along`, m."""

    launch: jax.Array  # bool: decided in a flight, the stance it lands in launches a leap
    boost: jax.Array  # m behind Raibert's neutral point that stance's foot is set down, for the leap's speed
    setback: jax.Array  # m an ordinary stance's foot is set back, to land FACE_MARGIN short of a block it steps onto
    leap: jax.Array  # bool: this stance launches a leap, or this flight is one (latched at its touchdown)
    base: jax.Array  # m, world z of the ground under the foot at that touchdown: what obstacles rise from
    along: jax.Array  # (2,) the travel direction, world, at that touchdown
    face: jax.Array  # m, the obstacle's near face along the way
    far: jax.Array  # m, its far edge
    top: jax.Array  # m, world z of its top
    full: jax.Array  # bool: this stance (decided at its touchdown) takes the full stroke (`control.stroke`)
    rise: jax.Array  # m over standing the leap must rise to carry its travel, decided with the launch
    spin: stroke.SpinLoop  # the full stroke's steering of the whole robot's spin
    spent: jax.Array  # bool: the full stroke's push was spent (`stroke.spent`), from then to lift-off


def knee_room(leg, top, floor, length) -> jax.Array:
    """m further than `LAND_BEYOND` past a block's far edge its leap sets the foot down, where its top is above the
    knee in the landing pose (the virtual leg at `length`, the hip over the foot): far enough that the knee, which
    stands behind the foot, lands `KNEE_CLEAR` past the edge; 0 for lower blocks and gaps. Set down closer, the knee
    of the Moon's robots came down on the far top corner of a 0.45 m block, and 23 of 32 fell. Lower blocks land as
    before: a landing further out asks more boost and lands harder (4 cm further, Earth's 0.3 m block kept 16
    robots up of the 26 it keeps)."""
    # The knee sits off the hip-foot line by the height of the thigh-shank triangle on the virtual leg.
    along = (leg.thigh**2 - leg.shank**2 + length**2) / (2.0 * length)  # from the hip to the knee's foot point
    behind = jnp.sqrt(jnp.maximum(leg.thigh**2 - along**2, 0.0))
    knee_up = length - along + leg.foot_radius  # m over the ground the foot stands on
    room = jnp.maximum(behind + KNEE_CLEAR - (leg.foot_radius + LAND_BEYOND), 0.0)
    return jnp.where(top - floor > knee_up, room, 0.0)


def tuck_length(robot: Robot, leg) -> jax.Array:
    """m: the virtual leg drawn up, the knee `TUCK_KNEE` short of its lower stop."""
    return leg_length(leg, robot.layout.joint_range[KNEE][0] + TUCK_KNEE)


def tuck_drop(robot: Robot, leg) -> jax.Array:
    """m from the base origin down to the drawn-up foot's bottom, the body level: the least height of the base over
    an obstacle's top for the foot to pass over it."""
    length = tuck_length(robot, leg)
    return leg.haa_below_base + leg.hfe_below_haa + jnp.sqrt(length**2 - TUCK_AHEAD**2) + leg.foot_radius


def _along(s) -> jax.Array:
    """(2,) the commanded direction of travel, world: obstacles are leapt going that way only (a robot pushed back
    does not leap back over what it crossed); zeros when hopping in place."""
    command = s.params.speed
    size = jnp.linalg.norm(command)
    return jnp.where(size > 0.05, command / jnp.maximum(size, 1e-6), 0.0)


def obstacle(ground, foot_xy, along, radius) -> tuple[jax.Array, ...]:
    """(any, near face, far edge, top) of the first obstacle ahead of the foot, m along `along` from `foot_xy` (the
    top world z); within `LOOK_SPAN`. An obstacle is ground `STEP_UP` over the ground under the foot (a block, a step
    up: its top is its highest), or a gap: ground `STEP_UP` under it with a far side back at the foot's level in
    view (its top is that level, the lip the foot must pass; a step down with no far side in view is hopped down)."""
    offsets = jnp.linspace(-radius, LOOK_SPAN, SAMPLES)
    points = foot_xy[:, None] + along[:, None] * offsets[None, :]
    heights = ground.height(points[0], points[1])
    here = ground.height(foot_xy[0], foot_xy[1])
    high, low = heights > here + STEP_UP, heights < here - STEP_UP
    odd = high | low
    face = jnp.min(jnp.where(odd, offsets, jnp.inf))
    after = jnp.min(jnp.where(~odd & (offsets > face), offsets, jnp.inf))  # the first sample past it
    run = odd & (offsets < after)
    far = jnp.minimum(after, LOOK_SPAN) - (LOOK_SPAN + radius) / (SAMPLES - 1) / 2
    seen = jnp.where(jnp.any(low & (offsets == face)), after < jnp.inf, odd.any())  # a gap needs its far side
    return seen, face, far, jnp.maximum(jnp.max(jnp.where(run, heights, -jnp.inf)), here)


def is_gap(top, floor) -> jax.Array:
    """Is the obstacle whose top `obstacle` found a gap (its top the lip, at the `floor` the foot stands on)?"""
    return top < floor + STEP_UP


def carry_speed(travel, v, push, leg_length, g) -> jax.Array:
    """m/s up at lift-off: the least that carries the COM `travel` m in the flight with the launching foot at most
    `MAX_BOOST` behind the neutral point. In the flight 2·up/g the COM moves at v plus the boost's b/L of the stance's
    vertical speed change (up + `push`), so b = `MAX_BOOST` makes travel·g/2 = v·up + (b/L)(up² + push·up)."""
    a = MAX_BOOST / leg_length
    b = v + a * push
    return (jnp.sqrt(b**2 + 2.0 * a * g * jnp.maximum(travel, 0.0)) - b) / (2.0 * a)


def gap_lift(travel, v, push, leg_length, g, slow) -> jax.Array:
    """m/s up at lift-off for a gap's leap: the least that carries the COM `travel` m with the most boost
    (`carry_speed`); where the hop is `slow` (`slow_lift`), raised towards the lift-off that carries it at the speed
    `v` it has with no boost, up to `LEVEL_LIFT`, the boost giving only the rest. Below the Moon a flight is long, so
    height is cheap: the boost's swing to 0.16 m behind the neutral point pitched the body 0.4 rad before the
    launching stance at 0.5 m/s², and the stance lost the floor. At the Moon the higher leap crossed the narrow gaps
    too, but far fewer robots were up after it (of 16 at 0.1-0.45 m, 2-6 where 13-14 were)."""
    level = jnp.minimum(travel * g / (2.0 * jnp.maximum(v, 1e-3)), LEVEL_LIFT)
    return jnp.maximum(carry_speed(travel, v, push, leg_length, g), jnp.where(slow, level, 0.0))


class Leap:
    """The jump's `plan.Plan`."""

    def __init__(self, robot: Robot, no_load):
        self.robot, self.no_load = robot, jnp.asarray(no_load, jnp.float32)  # rad/s, its motors' (`stroke.release`)

    def initial(self, obs) -> JumpState:
        base = (jnp.float32(0.0) if obs.ground is None
                else jnp.asarray(obs.ground.height(obs.qpos[0], obs.qpos[1]), jnp.float32))
        zero, no = jnp.float32(0.0), jnp.bool_(False)
        return JumpState(launch=no, boost=zero, setback=zero, leap=no, base=base,
                         along=jnp.array([1.0, 0.0], jnp.float32), face=zero, far=zero, top=base, full=no, rise=zero,
                         spin=stroke.SpinLoop.zero(), spent=no)

    def _launch(self, leg, body, ground, base_xy, speed, s, standing, g) -> tuple[jax.Array, ...]:
        """In a flight: (does the stance it lands in launch a leap, the boost m that stance's foot is set behind
        Raibert's neutral point so that the leap carries the COM past the obstacle, the leap's rise m, the setback m
        of a stance before a block it does not leap)."""
        along = _along(s)
        v = jnp.maximum(jnp.dot(body.v, along), 0.0)  # m/s the way it goes
        foot = foot_offset(leg, body)
        bottom = body.z + foot[2] - leg.foot_radius
        com_xy = world_com_xy(leg, body, base_xy)
        here = ground.height(*(base_xy + foot[:2]))
        sink = sink_speed(body.zdot, bottom - here, g)  # m/s down at touchdown
        time_left = (body.zdot + sink) / g
        touch = com_xy + body.v * time_left + along * v * speed.stance_time / 2  # where the foot comes down
        seen, face, far, top = obstacle(ground, touch, along, leg.foot_radius)
        floor = ground.height(*touch)
        rise = jnp.maximum(top + tuck_drop(self.robot, leg) + CLEARANCE - standing - floor, 0.0)
        gap = is_gap(top, floor)
        # The COM leaves v·T_s/2 ahead of the foot, and must come down within LAND_AHEAD of the landing past the far
        # edge. A foot set b behind the neutral point gives the stance a forward push of about b/L of its vertical.
        # A gap's lip asks no rise: its leap rises as carrying the COM across with the most boost needs. A block too
        # low for its leap to carry that far is not leapt: Raibert's hops step onto it (of a 0.1 m block's robots,
        # 0-3 % were up at 10 s leapt so, 50-97 % stepping onto it).
        room = knee_room(leg, top, floor, s.params.gains.leg_length)
        travel = far + leg.foot_radius + LAND_BEYOND + room - LAND_AHEAD - v * speed.stance_time / 2
        push = sink + g * speed.stance_time
        up = jnp.sqrt(2.0 * g * rise)
        up = jnp.where(gap, jnp.maximum(up, gap_lift(travel, v, push, s.params.gains.leg_length, g, slow_lift(s, g))),
                       up)
        flight = 2.0 * up / g
        wanted = travel / jnp.maximum(flight, 1e-3) - v
        boost = jnp.maximum(wanted, 0.0) * s.params.gains.leg_length / (up + push)
        # A leap now: the next ordinary stride would reach the obstacle's face. A gap has no face for the launching
        # leg to strike: its foot need only come down before the lip.
        stride = v * (speed.stance_time + 2.0 * jnp.sqrt(2.0 * jnp.maximum(s.params.height, 0.0) / g))
        near = face - leg.foot_radius - FACE_MARGIN < stride
        margin = jnp.where(gap, 0.0, FACE_MARGIN)
        # A foot that would come down closer to the face than its margin is set back to it: at low gravity a stride
        # is long (0.27 m at 0.28 m/s²), and the one before the face can end anywhere in the margin.
        boost = jnp.maximum(boost, leg.foot_radius + margin - face)
        able = gap | (boost <= MAX_BOOST)
        # A block not leapt is stepped onto, and a stance within the margin of its face would have the next swing
        # strike the face as the foot rises (4 of Mars's 16 robots at a 0.1 m block): that foot is set back too.
        setback = jnp.where(seen & (face > 0.0) & ~gap & ~able,
                            jnp.clip(leg.foot_radius + FACE_MARGIN - face, 0.0, MAX_BOOST), 0.0)
        return (seen & near & (face > 0.0) & able, jnp.minimum(boost, MAX_BOOST), up**2 / (2.0 * g), setback)

    def aim(self, leg, body, ground, base_xy, speed, s, ev, phase, floor, standing, g):
        """In a flight: does the next stance launch a leap. At touchdown: the obstacle it leaps. At the bottom: the
        leap's apex aimed over it."""
        launch, boost, rise, setback = self._launch(leg, body, ground, base_xy, speed, s, standing, g)
        deciding = (phase == raibert.FLIGHT) & ~s.plan.leap
        plan = s.plan._replace(launch=jnp.where(deciding, launch, s.plan.launch & ~s.plan.leap),
                               boost=jnp.where(deciding, boost, s.plan.boost),
                               setback=jnp.where(deciding, setback, 0.0),
                               rise=jnp.where(deciding, rise, s.plan.rise))
        along, foot = _along(s), base_xy + foot_offset(leg, body)[:2]
        _, face, far, top = obstacle(ground, foot, along, leg.foot_radius)
        at = jnp.dot(foot, along)
        # A foot that bounces off the floor in the launching stance lands again short of the obstacle: still that
        # stance, not the landing beyond it.
        leap = s.plan.launch | (s.plan.leap & (jnp.dot(foot, s.plan.along) < s.plan.face))
        # A touchdown while the body still rises is the last stance's foot bouncing (at Ceres, 20 ms after it left):
        # the launch waits for the landing.
        bounce = (body.zdot > 0.0) & ~s.plan.leap
        leap = leap & ~bounce
        landed = plan._replace(leap=leap, launch=bounce & plan.launch, base=ground.height(foot[0], foot[1]),
                               along=along, face=at + face, far=at + far, top=top)
        plan = jax.tree_util.tree_map(lambda a, b: jnp.where(ev.touchdown, a, b), landed, plan)
        aimed = jnp.where(ev.bottom & plan.leap,
                          jnp.maximum(floor, plan.base + leap_rise(plan, self.robot, leg, standing) - s.params.height),
                          floor)
        return aimed, plan

    def release(self, s, leg, body):
        return (jnp.where(s.plan.full, stroke.release(leg, body, self.no_load), s.params.gains.leg_length),
                s.plan.full & ~stroke.steady(body))

    def push(self, leg, body, s, ev, phase, plan, height_bias, thrust_force, standing, g, inertia):
        """A hop asked for more than the ordinary stroke holds takes the full stroke (`control.stroke`); a leap's
        stance stays Raibert's."""
        lay = self.robot.layout
        mass, effort, lowest = lay.total_mass, jnp.asarray(lay.effort_limit), lay.joint_range[KNEE][0]
        # The commanded apex over the ground the foot stands on (`base`, at this touchdown; 0 on the plane).
        target = standing + s.params.height + height_bias + plan.base
        needs = stroke.needs_full(leg, body, s.params.gains, target, g, mass, effort[KNEE]) & ~plan.leap
        full = jnp.where(ev.touchdown, needs, plan.full)
        # Raibert's thrust spreads its energy over at least MIN_SQUEEZE of stroke, to the touchdown length: a leap's
        # stance squeezed less (a landing at 0.16 m/s at Ceres squeezes 8 mm) would give 40 % of it. That energy is
        # spread over the stroke it has (the knee's effort limit caps the force).
        squeeze = s.params.gains.leg_length - body.length
        held = jnp.maximum(squeeze, raibert.MIN_SQUEEZE)
        energy = thrust_force * held  # J: what Raibert's thrust holds
        shallow = plan.leap & ev.bottom & (squeeze < raibert.MIN_SQUEEZE)
        spread = jnp.where(shallow, jnp.maximum(squeeze, SHALLOWEST), held)  # m of stroke the thrust is spread over
        thrust_force = jnp.where(shallow, energy / spread, thrust_force)
        # A boosted block leap's thrust also gives the forward speed its push makes (`forward_work`).
        block = plan.leap & steers_spin(plan)
        rise = leap_rise(plan, self.robot, leg, standing)
        extra = forward_work(body, plan, rise, standing, mass, g) / spread
        thrust_force = jnp.where(block & ev.bottom, thrust_force + extra, thrust_force)
        thrust_force = jnp.where(full & ev.bottom, stroke.thrust(leg, body, target, g, mass, lowest, effort),
                                 thrust_force)
        pushing = full & ((phase == raibert.THRUST) | (phase == raibert.UNLOADING))
        spent = pushing & (plan.spent | stroke.spent(body, self.no_load))
        own, spin = stroke.push(full, leg, body, phase, thrust_force, g, mass, lowest, effort, plan.spin,
                                lay.timestep, spent)
        # A leap's launching stance starts the body tilted by the flight's boost, a shape the leap's flight undoes:
        # its servo only damps the spin, so that the leap leaves the floor without one.
        # A boosted block leap's servo also leaves the tilt alone, and steers the spin to what lands the body level.
        target = landing_spin(body, rise, s.params.gains.leg_length, s.stance_time, g, inertia)
        own = own._replace(stiffness=jnp.where((plan.leap & is_gap(plan.top, plan.base)) | block, 0.0, own.stiffness),
                           spin=jnp.where(block, jnp.append(target, 0.0), jnp.zeros(3, jnp.float32)))
        return own, thrust_force, plan._replace(full=full, spin=spin, spent=spent)

    def bias(self, s, ev, height_bias):
        return jnp.where(ev.touchdown & s.plan.leap, s.height_bias, height_bias)

    def shift(self, s, plan, g) -> jax.Array:
        """(2,) m, world: where a hop lifts off slowly (`slow_lift`), the flight before a leap is Raibert's with its
        foot set `boost` further back along the way. Its speed loop keeps the foot near where it left the floor while
        the robot is still short of its speed: at 0.28 m/s² the body rises at 0.2 m/s, and the foot swung straight
        to the neutral point scuffed the floor and set the robot spinning. Faster hops keep the leap's own foothold:
        with Raibert's there, fewer of Mars's and Earth's robots were up after leaping a 0.3 m block. The flight
        before a block the jump steps onto sets the foot `setback` back, short of its face."""
        return jnp.where(plan.launch & ~plan.leap & slow_lift(s, g), -_along(s) * plan.boost, 0.0) \
            - _along(s) * plan.setback

    def flight(self, leg, body, ground, base_xy, speed, s, plan, torque, g, scale, spin, inertia):
        """A leap's flight: the leg drawn up until the foot is past the obstacle, then set down beyond it."""
        foot = foot_offset(leg, body)
        at = jnp.dot(base_xy + foot[:2], plan.along)
        com = jnp.dot(world_com_xy(leg, body, base_xy), plan.along)
        bottom = body.z + foot[2] - leg.foot_radius
        passed = at - leg.foot_radius > plan.far
        above = bottom > plan.top + 0.5 * CLEARANCE
        room = knee_room(leg, plan.top, plan.base, s.params.gains.leg_length)
        beyond = plan.far + leg.foot_radius + LAND_BEYOND + room
        # Drawn up: short of the face until the foot's bottom is above the top; from then on (or once over the
        # obstacle) carried on so that it is past the far edge when, falling, it would come down to the top. Each
        # centimetre ahead of the COM turns the body back (the leg is as heavy in rotation as the body), so no sooner.
        short = jnp.minimum(TUCK_AHEAD, plan.face - leg.foot_radius - FACE_MARGIN - com)
        to_top = fall_time(body.zdot, bottom - plan.top, g)
        over = jnp.clip(beyond - com - jnp.dot(body.v, plan.along) * to_top, TUCK_AHEAD, LEAP_REACH)
        tuck = jnp.where(above | (at > plan.face), over, short)
        # Set down past the far edge: the foot kept beyond it (from the COM now) while the leg reaches down, and aimed
        # there from where the COM is when it lands (the fall to the ground beyond), whichever is further.
        time_left = fall_time(body.zdot, bottom - plan.base, g)
        landing = com + jnp.dot(body.v, plan.along) * time_left
        # No nearer than Raibert's speed loop would set it: a leap that carries the COM well past the edge lands
        # with its foot behind the COM otherwise, and the stance speeds the robot on (to 0.7 m/s at the Moon).
        loop = jnp.dot(raibert.speed_placement(body, speed), body.unturn[:2, :2] @ plan.along)
        down = jnp.clip(jnp.maximum(jnp.maximum(beyond - landing, beyond - com), loop), -0.1, LEAP_REACH)
        ahead = jnp.where(passed, down, tuck)
        along = jnp.where(plan.leap, plan.along, _along(s))
        ahead = jnp.where(plan.leap, ahead, jnp.dot(body.v, along) * speed.stance_time / 2 - plan.boost)
        length = jnp.where(plan.leap & ~passed, tuck_length(self.robot, leg), s.params.gains.leg_length)
        placement = body.unturn[:2, :2] @ (along * ahead)
        # Reaching down, as Raibert's flight does: no further than lands the body tilted within its budget.
        drift = jnp.stack([body.roll, body.pitch]) + spin[:2] * time_left / (1.0 - inertia.alpha)
        now = (body.level @ (body.foot - body.com))[:2]
        budgeted = within_tilt_budget(placement, now, drift, inertia.swing_tilt,
                                      s.params.gains.tilt_budget, s.params.gains.leg_length)
        placement = jnp.where(plan.leap & passed, budgeted, placement)
        target = placement_angles(leg, body.level, placement, length, body.com)
        torque = jnp.where(plan.leap | (plan.launch & ~slow_lift(s, g)), raibert.flight_pd(body, target, scale), torque)
        return jnp.where(plan.full, stroke.flight(leg, body, speed, scale), torque)


def landing_spin(body, rise, length, stance_time, g, inertia) -> jax.Array:
    """(2,) rad/s, roll and pitch: the whole robot's spin (H/I) a block's leap of `rise` (`leap_rise`) should leave
    the floor with to land level. Without it the body lands tilted by its tilt now plus the flight's swing of the
    foot, from where it is (behind the COM, by the boost) to Raibert's neutral placement ahead (`swing_tilt` per
    radian of leg, as `foothold.within_tilt_budget` models it); a spin turns the body by H/I·T/(1-α) more in the
    leap's flight T.
    Raibert's servo, which damps the spin to zero and levels the body, landed Mars's leaps over a 0.1-0.2 m block
    pitched forward at the tilt budget, the foot behind the COM, and most fell."""
    now = (body.level @ (body.foot - body.com))[:2]
    ahead = body.unturn[:2, :2] @ (body.v * stance_time / 2)
    tilt = landing_tilt(ahead, now, jnp.stack([body.roll, body.pitch]), inertia.swing_tilt, length)
    flight = 2.0 * jnp.sqrt(2.0 * jnp.maximum(rise, 0.01) / g)
    return -(1.0 - inertia.alpha) * tilt / flight


def forward_work(body, plan: JumpState, rise, standing, mass, g) -> jax.Array:
    """J: the kinetic energy a block leap's push gives the COM along the way, beyond the rise (`leap_rise`) that
    Raibert's thrust is sized for. The floor pushes from the foot at the COM: from the stance's bottom, the COM tanφ
    ahead of the foot (φ the leg's lean from upright along the way), a push that lifts the COM at `up` to the leap's
    apex speeds it on by about up·tanφ. Sized for the rise alone, the leaps over a 0.15 m block at the Moon and Earth
    rose 4-15 cm short of their aim, and half of them came down on the block's near edge."""
    rel = body.level @ (body.com - body.foot)  # the COM from the foot, level frame
    lean = jnp.clip(jnp.dot(rel[:2], body.unturn[:2, :2] @ plan.along) / jnp.maximum(rel[2], 0.1), 0.0, 1.0)
    apex = standing + plan.base + rise
    on = jnp.sqrt(2.0 * g * jnp.maximum(apex - body.z, 0.0)) * lean
    return mass * jnp.maximum(jnp.dot(body.v, plan.along) * on + 0.5 * on**2, 0.0)


def steers_spin(plan: JumpState) -> jax.Array:
    """Does this leap's launching stance steer the spin (`landing_spin`): a block's, its foot set behind the neutral
    point (a boost)."""
    return ~is_gap(plan.top, plan.base) & (plan.boost > 0.0)


def slow_lift(s, g) -> jax.Array:
    """Does this instance's ordinary hop leave the floor slower than `SLOW_LIFT`, √(2·g·rise)?"""
    return jnp.sqrt(2.0 * g * jnp.maximum(s.params.height, 0.0)) < SLOW_LIFT


def leap_rise(plan: JumpState, robot: Robot, leg, standing) -> jax.Array:
    """m over standing on the launching floor the leap is aimed at: its rise over the obstacle (`plan_apex`) or across
    it, `LEAP_GAIN` higher. What the leg's jerk off the floor takes from a hop Raibert's bias learns over hops, and a
    leap is one hop."""
    return LEAP_GAIN * jnp.maximum(plan_apex(plan, robot, leg) - (standing + plan.base), plan.rise)


def plan_apex(plan: JumpState, robot: Robot, leg) -> jax.Array:
    """m, world z the base's apex must reach for the drawn-up foot to pass `CLEARANCE` over the obstacle's top."""
    return plan.top + tuck_drop(robot, leg) + CLEARANCE


def jump(robot: Robot, config: raibert.RaibertConfig | None = None, motor: str = registry.DEFAULT_MOTOR) -> Controller:
    """`jump`: Raibert's gait that leaps what lies ahead (the module's docstring), for `motor`s (a registry.MOTORS
    name, whose speed line ends the full stroke's push); params: `raibert_params(...)`."""
    no_load = tuple(float(w) for w in nominal_no_load(robot.layout, motor))
    key = repr((STEP_UP, CLEARANCE, TUCK_AHEAD, TUCK_KNEE, FACE_MARGIN, LAND_BEYOND, KNEE_CLEAR, LEAP_REACH, LEAP_GAIN,
                LAND_AHEAD, MAX_BOOST, LEVEL_LIFT, SLOW_LIFT, SHALLOWEST, SAMPLES, LOOK_SPAN,
                stroke.LOW_MARGIN, stroke.RELEASE_KNEE, stroke.HIP_SHARE, stroke.READY_TILT, stroke.READY_RATE,
                stroke.SPIN_TIME, stroke.MAX_UNASKED, stroke.SPENT, stroke.FULL_MARGIN, no_load))
    return raibert.gait(robot, config, name="jump", plan=Leap(robot, no_load), key=key)


