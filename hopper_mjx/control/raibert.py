"""Raibert's three-part hopping controller for the articulated haa/hfe/kfe leg.

The leg is treated as Raibert's telescopic leg through its *virtual leg* (hfe
axis -> foot, see `kinematics`): its length is set by the knee alone. In stance
the desired floor push (along the foot -> COM line, so that it does not spin the
robot) maps to joint torques through the Jacobian transpose, τ = -J^T·F.

Phases (driven by foot contact and the virtual leg length L / rate L̇):

    FLIGHT       joint PD (the shipped position controllers' p, d) to the IK
                 target of the foot placement below.
    COMPRESSION  touchdown -> L̇ >= 0: a virtual spring-damper along the leg,
                 stiffness k = m·9.81/sag (a physical spring: the same
                 k under every g); hip torques servo body pitch and roll.
    THRUST       bottom -> L = leg_length: the spring plus a constant extra force
                 that supplies the energy still missing for the commanded apex.
    UNLOADING    L = leg_length -> lift-off: the joints are braked, no push.

Part 1, hop height: at the bottom the controller has m·g·z + ½m·ż² + ½k·ΔL²; the
thrust adds W = m·g·(z_apex - z) - ½m·ż² - ½k·ΔL² over the remaining stroke. The
apex target is the standing height + command + a bias adapted hop by hop from
the measured apex (it absorbs the energy lost when the leg is jerked off the floor).

Part 2, speed: the foot is placed (from the COM, in the heading frame) at
x_f = v·T_s/2 + k_v·(v - v_ref) + x_i in x and y, with v the COM velocity, T_s the
last measured stance time (touchdown to lift-off), k_v = speed_gain·L/(g·T_s)
(over a stance the COM's speed changes by about -g·T_s·x_f/L, so `speed_gain` is
the fraction of the error removed per hop), x_i a per-hop integral of the error,
and v_ref a reference that ramps to the command by `speed_step` per hop. Lateral
placement uses haa. The target is built in the level frame and turned into the
body frame by the body's present tilt (see `foothold.placement_angles`), and the hip
damping acts on the leg's world rate: this leg is as heavy in rotation as the
body, so every swing in flight tilts the body back, and targets fixed to the
body would land the foot off by L·tilt.

Part 3, attitude: in compression and thrust, τ_hfe = √(g/9.81)·kp·(pitch - p_ref)
+ kd·H_y/I_y and τ_haa likewise with roll, H being the whole robot's angular
momentum about its COM and I its inertia at the default stance. Damping H rather
than the body's rate matters because H at lift-off is how fast the robot tumbles
through the flight. The reference p_ref leans the body against the tilt the next
flight's swing will cause (α/(1-α)·x_f/L, α the body's turn-back per hip swing),
so the tilt swings about level instead of from level to one side. The stiffness
falls with g: leveling the body pushes the robot sideways through the foot, and
what undoes that push, leaning over the foot placed in flight, works in
proportion to g; √g (measured against g and 1) keeps the Moon's servo stiff
enough to lean the body back at 0.5 m/s without upsetting it sideways. The servo's
torque is capped at `traction`·leg force·L, a share
of the friction cone: at touchdown the leg force is still small, and a hip
torque beyond the floor's grip makes the foot slip or bounce.

The leg model (lengths, foot radius, link centres of mass and inertias, standing height)
is the URDF's, or each instance's own (`RaibertParams.leg`, from `legs`: a drawn thigh,
shank or foot radius, as run-time values); an instance's touchdown length `leg_length`
keeps the URDF's margin over its standing virtual leg. Masses stay the URDF's.

Every gravity-dependent quantity uses the instance's own g, its downward (vertical)
part, floored at `MIN_GRAVITY` so that a weightless robot gets finite commands. Contact is the
observation's (`signals.Observation.contact`, the engine's one foot-contact test);
like the joint readings it is one step (1 ms) old.

`act` composes pure per-part functions, each tested on its own: `sense` (what the
body is doing), `next_phase`, `height_update` and `speed_update` (the bookkeeping of
parts 1 and 2), `stance_torque` and `flight_torque`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx.control import kinematics
from hopper_mjx.control.base import Commands, Controller, PDScale, joint_state, pd, saturate, scaled, to_ctrl
from hopper_mjx.control.foothold import (
    clear_of_edges,
    fall_time,
    foot_offset,
    foothold,
    landing_floor,
    placement_angles,
    within_tilt_budget,
)
from hopper_mjx.control.latency import ahead, detuned
from hopper_mjx.control.plan import OwnPush, Plan
from hopper_mjx.hardware import rotation
from hopper_mjx.hardware.signals import Observation
from hopper_mjx.model.robot import LegGeometry, Robot
from hopper_mjx.model.world import EARTH_GRAVITY  # where the attitude stiffness holds as given
from hopper_mjx.shell import programs

FLIGHT, COMPRESSION, THRUST, UNLOADING = 0, 1, 2, 3
MIN_PHASE_TIME = 0.01  # s in flight / stance before contact may end it (debounce)
MIN_GRAVITY = 0.1  # m/s², floor under g in the formulas (g = 0 has no hops)
# rad (haa, hfe, kfe): the nominal stance at which the robot's inertia is taken (the
# computed stance, `Robot.stance_joints`, has kfe -0.9502; the gains were tuned with this one).
INERTIA_POSE = (0.0, 0.5, -0.95)
MAX_PLACEMENT = 0.25  # m, bound on the foot placement from the COM
MAX_HEIGHT_BIAS = 0.3  # m, bound on the adapted apex-target bias
MAX_SPEED_OFFSET = 0.1  # m, bound on the integral part of the foot placement
MAX_RETRACT = 0.15  # m, bound on the leg's shortening in a rising flight towards higher ground
MIN_SQUEEZE = 0.02  # m, floor under the remaining thrust stroke the extra force is spread over
# m: a flight towards ground higher than under the foot by more than RISER holds the foot where it is (relative to
# the COM) until its bottom is SWING_CLEARANCE above the ground it lands on, so that its swing does not catch the riser.
RISER, SWING_CLEARANCE = 0.02, 0.02
# The flight PD: the shipped position controllers' p and d (hopper_mjx/control/monoped.yaml), no i.
FLIGHT_KP = (400.0, 400.0, 200.0)  # N·m/rad, haa, hfe, kfe
FLIGHT_KD = (18.0, 15.0, 4.0)  # N·m·s/rad


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class RaibertConfig:
    """Gains of the three-part controller; all may be overridden per instance (then each is an array)."""

    leg_length: float = 0.64  # m, virtual leg length at touchdown and lift-off
    retract: float = 0.0  # m the leg is shortened while rising in flight
    sag: float = 0.025  # m, static compression of the virtual spring under m·9.81 (k = m·9.81/sag)
    damping_ratio: float = 0.1  # of the virtual spring during compression
    height_adapt: float = 0.5  # fraction of the apex error added to the apex target per hop
    speed_gain: float = 0.1  # fraction of the speed error removed per stance (sets k_v, see above)
    tilt_lead: float = 1.0  # 0..1, share of the flight's predicted tilt the stance servo leans against
    speed_step: float = 0.05  # m/s per hop: the speed reference ramps to the command at this rate
    speed_integral: float = 0.1  # fraction of k_v·(v - v_d) accumulated into the placement per hop
    pitch_kp: float = 400.0  # N·m/rad at g = 9.81 (x √(g/9.81)), stance hfe servo on body pitch
    pitch_kd: float = 200.0  # N·m·s/rad, on the whole robot's pitch rate H_y / I_y
    roll_kp: float = 400.0  # N·m/rad at g = 9.81 (x √(g/9.81)), stance haa servo on body roll
    roll_kd: float = 200.0  # N·m·s/rad, on H_x / I_x
    tilt_budget: float = 0.4  # rad, largest body tilt at touchdown the foot placement may cause
    traction: float = 0.3  # attitude hip torque <= traction · leg force · L (a share of the friction cone)


GAINS = tuple(f.name for f in dataclasses.fields(RaibertConfig))
# Each gain's unit, as its comment above gives it (the others are ratios, unit 1): for plots' axes.
GAIN_UNITS = {"leg_length": "m", "retract": "m", "sag": "m", "speed_step": "m/s", "pitch_kp": "N·m/rad",
              "pitch_kd": "N·m·s/rad", "roll_kp": "N·m/rad", "roll_kd": "N·m·s/rad", "tilt_budget": "rad"}
DEFAULT_HEIGHT = 0.10  # m, commanded apex rise over the standing height when none is given


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class RaibertParams:
    """Per-instance commands and gains; each leaf has a leading axis n when batched."""

    height: jax.Array  # m, commanded apex rise over the standing height
    speed: jax.Array  # (2,) m/s, commanded (vx, vy)
    gains: RaibertConfig  # every gain, one value per instance
    # Factors on the joint PD gains (the flight PD, the attitude servo, the brake); None: as designed.
    pd: PDScale | None = None
    leg: "Leg | None" = None  # each instance's own leg (`legs`); None: the URDF's, folded as constants
    # s, each instance's action delay, which the gait predicts over (`control.latency`); None: it takes its torques
    # as prompt (Raibert's own, today's program).
    latency: jax.Array | None = None


def _read_commands(s: "RaibertState"):
    return s.params.speed, s.params.height


def _write_commands(s: "RaibertState", speed, rise: float) -> "RaibertState":
    p = s.params
    speed = jnp.broadcast_to(jnp.asarray(speed, jnp.float32), p.speed.shape)
    return s._replace(params=dataclasses.replace(p, speed=speed, height=jnp.full_like(p.height, rise)))


class RaibertState(NamedTuple):
    params: RaibertParams
    phase: jax.Array  # int32, one of FLIGHT..UNLOADING
    phase_start: jax.Array  # s, simulation time the phase began
    touchdown_time: jax.Array  # s, simulation time of the last touchdown
    stance_time: jax.Array  # s, last measured stance duration (0 before the first)
    apex: jax.Array  # m, highest base height of the current flight
    height_bias: jax.Array  # m added to the apex target (adapted per hop)
    speed_offset: jax.Array  # (2,) m, integral part of the foot placement
    speed_reference: jax.Array  # (2,) m/s, ramping towards the commanded speed
    thrust_force: jax.Array  # N, the extra leg force of this thrust
    work: jax.Array  # J, ∫ Σ|τ·q̇| dt of the three motors (for the cost of transport)
    floor: jax.Array  # m, world z of the ground the apex is aimed above (0 on the flat plane)
    plan: Any = ()  # a `Plan`'s own state (`jump`); () for Raibert: no leaves, today's program


def _batch(n: int, name: str, value, shape: tuple) -> np.ndarray:
    value = np.asarray(value, dtype=np.float32)
    try:
        out = np.broadcast_to(value, (n,) + shape).copy()
    except ValueError:
        raise ValueError(f"{name} must be a scalar or shape {(n,) + shape}, got {value.shape}") from None
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{name} must be finite")
    return out


def check_gain(name: str, value: float) -> None:
    """One gain's value, checked as `raibert_params` checks it (a sweep's values, before it runs)."""
    _check_gains(dataclasses.replace(RaibertConfig(), **{name: value}))


def _check_gains(gains: RaibertConfig) -> None:
    for name in ("leg_length", "sag"):
        if np.any(getattr(gains, name) <= 0):
            raise ValueError(f"{name} must be > 0 m")
    if np.any(gains.tilt_budget <= 0):
        raise ValueError("tilt_budget must be > 0 rad")
    if np.any((gains.tilt_lead < 0) | (gains.tilt_lead > 1)):
        raise ValueError("tilt_lead must be in [0, 1]")


def raibert_params(n: int, *, height, speed=(0.0, 0.0), config: RaibertConfig | None = None,
                   pd: PDScale | None = None, leg: "Leg | None" = None, latency=None,
                   **gain_overrides) -> RaibertParams:
    """Per-instance commands and gains, every leaf with leading axis n.

    height: apex rise over the standing height, m, scalar or (n,);
    speed: (vx, vy) m/s, (2,) or (n, 2); gain_overrides: any RaibertConfig field,
    scalar or (n,) (a sweep over a gain is just an array here); pd: (n, 3) factors on the joint
    PD gains (`base.pd_scale`); leg: each instance's own leg (`legs`), whose `length_shift` moves
    `leg_length` (given for the URDF's leg) to that leg's; latency: s of action delay, scalar or (n,), for a gait
    that predicts over it (None: prompt).
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    unknown = set(gain_overrides) - set(GAINS)
    if unknown:
        raise ValueError(f"unknown Raibert gain(s) {sorted(unknown)}; expected some of {list(GAINS)}")
    config = config or RaibertConfig()
    heights = _batch(n, "height", height, ())
    if np.any(heights < 0):
        raise ValueError("height (apex rise) must be >= 0 m")
    gains = RaibertConfig(**{k: _batch(n, k, gain_overrides.get(k, getattr(config, k)), ()) for k in GAINS})
    if leg is not None:
        if np.shape(leg.standing_height) != (n,):
            raise ValueError(f"leg must hold n={n} legs, got {np.shape(leg.standing_height)}")
        gains = dataclasses.replace(gains, leg_length=gains.leg_length + np.asarray(leg.length_shift, np.float32))
    _check_gains(gains)
    if latency is not None:
        latency = _batch(n, "latency", latency, ())
        if np.any(latency < 0):
            raise ValueError("latency (action delay) must be >= 0 s")
    return RaibertParams(height=heights, speed=_batch(n, "speed", speed, (2,)), gains=gains, pd=pd, leg=leg,
                         latency=latency)


def _tilt(rot: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(roll, pitch), rad, of a body->world rotation matrix (ZYX Euler angles)."""
    return jnp.arctan2(rot[2, 1], rot[2, 2]), -jnp.arcsin(jnp.clip(rot[2, 0], -1.0, 1.0))


class Body(NamedTuple):
    """What the controller derives from one observation (base frame unless said)."""

    q: jax.Array  # (3,) joint angles, rad
    qd: jax.Array  # (3,) joint rates, rad/s
    z: jax.Array  # base height, m
    zdot: jax.Array  # m/s
    gyro: jax.Array  # (3,) base angular velocity, rad/s
    com: jax.Array  # (3,) whole-robot COM from the haa axis point, m
    rot: jax.Array  # (3, 3) body -> world
    unturn: jax.Array  # (3, 3) world -> heading frame
    level: jax.Array  # (3, 3) body -> level frame (roll and pitch only)
    v: jax.Array  # (2,) horizontal COM velocity, world, m/s
    roll: jax.Array
    pitch: jax.Array
    length: jax.Array  # virtual leg length, m
    length_rate: jax.Array  # m/s
    foot: jax.Array  # (3,) foot centre from the haa axis point, m


def sense(robot: Robot, obs: Observation, leg: LegGeometry | None = None) -> Body:
    """What the body is doing, seen through `leg` (default the URDF's)."""
    q, qd = joint_state(robot.layout, obs)
    leg = robot.leg if leg is None else leg
    gyro = obs.qvel[3:6]
    com, com_rate = jax.jvp(lambda a: kinematics.com_position(leg, a), (q,), (qd,))
    from_base = kinematics.from_base(leg, com)
    rot = rotation.matrix(obs.qpos[3:7])  # body -> world ([w, x, y, z] quaternion)
    unturn = _unturn(rot)
    # Horizontal velocity of the COM (constant through a flight, unlike the base's).
    v = (obs.qvel[:3] + rot @ (jnp.cross(gyro, from_base) + com_rate))[:2]
    roll, pitch = _tilt(rot)
    return Body(q=q, qd=qd, z=obs.qpos[2], zdot=obs.qvel[2], gyro=gyro, com=com, rot=rot, unturn=unturn,
                level=unturn @ rot, v=v, roll=roll, pitch=pitch, length=kinematics.leg_length(leg, q[2]),
                length_rate=kinematics.leg_length_rate(leg, q[2], qd[2]), foot=kinematics.foot_position(leg, q))


class Events(NamedTuple):
    touchdown: jax.Array
    liftoff: jax.Array
    bottom: jax.Array  # compression ended: the leg stopped shortening
    extended: jax.Array  # thrust ended: the leg reached its touchdown length


def next_phase(phase: jax.Array, touching: jax.Array, elapsed: jax.Array, length: jax.Array,
               length_rate: jax.Array, leg_length: jax.Array, hold=None) -> tuple[jax.Array, Events]:
    """The phase after this observation, and which transitions fired; `hold`: a plan's bool that keeps the leg at the
    bottom of its compression (None: never)."""
    in_stance = phase != FLIGHT
    settled = elapsed > MIN_PHASE_TIME
    bottom = (phase == COMPRESSION) & (length_rate >= 0) & settled
    if hold is not None:  # static: Raibert's own, today's program
        bottom = bottom & ~hold
    events = Events(
        touchdown=~in_stance & touching & settled,
        liftoff=in_stance & ~touching & settled,
        bottom=bottom,
        extended=(phase == THRUST) & (length >= leg_length),
    )
    new = jnp.where(events.touchdown, COMPRESSION, phase)
    new = jnp.where(events.bottom, THRUST, new)
    new = jnp.where(events.extended, UNLOADING, new)
    return jnp.where(events.liftoff, FLIGHT, new), events


def height_update(s: RaibertState, ev: Events, body: Body, g, stiffness, mass: float,
                  standing_height: float, floor=None) -> tuple[jax.Array, jax.Array]:
    """Part 1: (apex-target bias adapted at touchdown, extra thrust force sized at the bottom, N).
    On a terrain the rise is measured above `s.floor`, and the thrust aims above `floor` (the ground
    the next hop takes off from and lands on); None: the flat plane at z = 0."""
    p = s.params
    rise = s.apex - standing_height if floor is None else s.apex - s.floor - standing_height
    adapted = jnp.clip(s.height_bias + p.gains.height_adapt * (p.height - rise), -MAX_HEIGHT_BIAS, MAX_HEIGHT_BIAS)
    height_bias = jnp.where(ev.touchdown, adapted, s.height_bias)
    squeeze = jnp.maximum(p.gains.leg_length - body.length, 0.0)
    target_z = standing_height + p.height + height_bias
    if floor is not None:  # static: the flat plane's arithmetic stays today's
        target_z = target_z + floor
    needed = mass * g * (target_z - body.z) - 0.5 * mass * body.zdot**2 - 0.5 * stiffness * squeeze**2
    thrust = jnp.maximum(needed, 0.0) / jnp.maximum(squeeze, MIN_SQUEEZE)
    return height_bias, jnp.where(ev.bottom, thrust, s.thrust_force)


class Speed(NamedTuple):
    stance_time: jax.Array  # s
    touchdown_time: jax.Array  # s
    gain: jax.Array  # k_v, s
    reference: jax.Array  # (2,) m/s
    error: jax.Array  # (2,) m/s
    offset: jax.Array  # (2,) m


def speed_update(s: RaibertState, ev: Events, v: jax.Array, time: jax.Array, g) -> Speed:
    """Part 2 bookkeeping: stance time at lift-off, the reference ramp and placement integral at touchdown."""
    p = s.params.gains
    # Before the first lift-off: half a period of the virtual spring-mass.
    stance_time = jnp.where(s.stance_time > 0, s.stance_time, math.pi * jnp.sqrt(p.sag / EARTH_GRAVITY))
    touchdown_time = jnp.where(ev.touchdown, time, s.touchdown_time)
    stance_time = jnp.where(ev.liftoff, time - touchdown_time, stance_time)
    gain = p.speed_gain * p.leg_length / (g * stance_time)
    step = jnp.clip(s.params.speed - s.speed_reference, -p.speed_step, p.speed_step)
    reference = jnp.where(ev.touchdown, s.speed_reference + step, s.speed_reference)
    error = v - reference
    offset = jnp.clip(s.speed_offset + p.speed_integral * gain * error, -MAX_SPEED_OFFSET, MAX_SPEED_OFFSET)
    return Speed(stance_time, touchdown_time, gain, reference, error, jnp.where(ev.touchdown, offset, s.speed_offset))


class Inertia(NamedTuple):
    """The robot's rotational facts at `INERTIA_POSE`, computed once per controller."""

    robot: jax.Array  # (3,) kg·m², whole-robot inertia about each base axis
    alpha: jax.Array  # (2,) body turn-back per hip swing (haa/roll, hfe/pitch)
    swing_tilt: jax.Array  # (2,) α/(1-α)


def inertia_facts(leg: LegGeometry, pose=INERTIA_POSE) -> Inertia:
    """At `pose` (haa, hfe, kfe), rad: `INERTIA_POSE` for the URDF's leg, an instance's own stance for its own."""
    pose = jnp.asarray(pose)
    momentum = lambda rates, gyro: kinematics.angular_momentum(leg, pose, rates, gyro)
    robot = jax.vmap(lambda axis: momentum(jnp.zeros(3), axis))(jnp.eye(3)).diagonal()
    # In flight a hip swing of Δ turns the body back by α·Δ (zero angular momentum),
    # so a leg that swings its world angle by Δθ tilts the body by -α/(1-α)·Δθ.
    leg_momentum = jax.vmap(lambda hip: momentum(hip, jnp.zeros(3)))(jnp.eye(3)).diagonal()
    alpha = (leg_momentum / robot)[:2]
    return Inertia(robot=robot, alpha=alpha, swing_tilt=alpha / (1.0 - alpha))


class Leg(NamedTuple):
    """Each instance's own leg as the controller models it (`legs`); every leaf (n, ...) when batched."""

    geometry: LegGeometry  # lengths, foot radius, link centres of mass and inertias (the URDF's masses)
    standing_height: jax.Array  # m, base height standing in its stance: where the apex rise counts from
    inertia: Inertia  # the robot's rotational facts at its own stance
    # m, its standing virtual leg's length minus the URDF's: `raibert_params` adds it to `leg_length`, so that
    # the touchdown length keeps the URDF's margin over the standing leg (the spring's preload at rest).
    length_shift: jax.Array


def _stance_length(robot: Robot) -> float:
    return float(kinematics.leg_length(robot.leg, robot.stance_joints[2]))


_inertias = jax.jit(jax.vmap(inertia_facts))  # one compile, not hundreds of small eager ops


def legs(robot: Robot, own: Sequence[Robot]) -> Leg:
    """The `Leg`s (n, ...) of n instances whose robot facts are `own` (`variation.draw.legs`), `robot`
    the URDF's."""
    stack = lambda *v: np.asarray(v, np.float32)
    geometry = LegGeometry(**{f.name: stack(*(getattr(r.leg, f.name) for r in own))
                              for f in dataclasses.fields(LegGeometry)})
    poses = stack(*(r.stance_joints for r in own))
    return Leg(geometry=geometry, standing_height=stack(*(r.standing_height for r in own)),
               inertia=jax.tree_util.tree_map(np.asarray, _inertias(geometry, poses)),
               length_shift=stack(*(_stance_length(r) - _stance_length(robot) for r in own)))


def stance_torque(leg: LegGeometry, gains: RaibertConfig, phase, body: Body, spin, speed: Speed, thrust_force,
                  g, stiffness, mass: float, swing_tilt, scale: PDScale | None = None,
                  own: OwnPush | None = None) -> jax.Array:
    """Joint torques (3,) N·m in compression, thrust and unloading: the leg force through J^T
    plus the hip attitude servo; in unloading only a brake. `scale`: factors on the servo's and
    the brake's gains (haa: roll, hfe: pitch). `own`: a plan's stance where it says; None: the spring's."""
    # The floor's push is aimed at the COM (not the hip), so that it does not
    # spin the robot; the spring acts on the virtual leg length.
    spring = stiffness * (gains.leg_length - body.length)
    damping = 2.0 * gains.damping_ratio * jnp.sqrt(stiffness * mass) * body.length_rate
    leg_force = jnp.select([phase == COMPRESSION, phase == THRUST], [spring - damping, spring + thrust_force], 0.0)
    leg_force = jnp.maximum(leg_force, 0.0)  # a foot can only push on the floor
    if own is not None:  # static: Raibert's own, today's program
        leg_force = jnp.where(own.where, own.force, leg_force)
    to_com = body.com - body.foot
    floor_push = leg_force * to_com / jnp.linalg.norm(to_com)
    servo = (phase == COMPRESSION) | (phase == THRUST)
    lean = jnp.sqrt(g / EARTH_GRAVITY)  # the stiffness falls with g (see the module docstring)
    # The next flight swings the leg from about -x_f to +x_f (x_f = v·T_s/2, the
    # neutral placement) and so tilts the body by swing_tilt·2x_f/L: leaving the
    # floor leaned the other way by half of that centres the tilt on level.
    neutral = body.unturn[:2, :2] @ (body.v * speed.stance_time / 2) / gains.leg_length
    lean_ref = gains.tilt_lead * swing_tilt * jnp.stack([neutral[1], -neutral[0]])
    # The damping acts on the whole robot's rotation rate H / I, not the body's.
    roll_kp, pitch_kp, roll_kd, pitch_kd = gains.roll_kp, gains.pitch_kp, gains.roll_kd, gains.pitch_kd
    if scale is not None:  # static: without factors, the gains as designed (today's program)
        roll_kp, roll_kd = scaled(roll_kp, roll_kd, PDScale(scale.kp[0], scale.kd[0]))
        pitch_kp, pitch_kd = scaled(pitch_kp, pitch_kd, PDScale(scale.kp[1], scale.kd[1]))
    if own is not None:
        lean, spin = lean * own.stiffness, spin * own.damping - own.spin
    attitude = jnp.stack([lean * roll_kp * (body.roll - lean_ref[0]) + roll_kd * spin[0],
                          lean * pitch_kp * (body.pitch - lean_ref[1]) + pitch_kd * spin[1], 0.0])
    # A hip torque τ pushes the foot sideways with τ/L: beyond the floor's grip the foot slides.
    grip = gains.traction * leg_force * body.length
    attitude = attitude * jnp.minimum(1.0, grip / (jnp.linalg.norm(attitude) + 1e-6))
    brake = -scaled(0.0, jnp.asarray(FLIGHT_KD), scale)[1] * body.qd  # unloading: coast to rest, no push
    push = -kinematics.jacobian(leg, body.q).T @ floor_push + jnp.where(servo, attitude, 0.0)
    if own is not None:  # a plan's stance brakes the joints it says, and steers the spin while the foot is down
        brake = jnp.where(own.where, brake * own.braked, brake)
        push, brake = (jnp.where(own.where, t + own.turn, t) for t in (push, brake))
    return jnp.where(phase == UNLOADING, brake, push)


def speed_placement(body: Body, speed: Speed) -> jax.Array:
    """(2,) m, heading frame: part 2's foot placement from the COM, v·T_s/2 + k_v·(v - v_ref) + x_i, bounded."""
    placement = body.v * speed.stance_time / 2 + speed.gain * speed.error + speed.offset
    return body.unturn[:2, :2] @ jnp.clip(placement, -MAX_PLACEMENT, MAX_PLACEMENT)


def flight_torque(leg: LegGeometry, gains: RaibertConfig, body: Body, spin, speed: Speed, g,
                 inertia: Inertia, scale: PDScale | None = None, ground=None, base_xy=None) -> jax.Array:
    """Joint torques (3,) N·m in flight: PD to the joint angles that place the foot (part 2). On a
    terrain (`ground`, `signals.SensedGround`; `base_xy` the base's world position) the time left to
    touchdown is the foot's fall to the ground where it will land."""
    placement = speed_placement(body, speed)
    foot = foot_offset(leg, body)
    foot_height = body.z + foot[2] - leg.foot_radius
    retract, hold = gains.retract, False
    if ground is not None:  # static: the plane's foot height is above z = 0
        placement = clear_of_edges(leg, body, ground, base_xy, placement, foot_height, g)
        landing = ground.height(*foothold(leg, body, base_xy, placement))
        foot_height = foot_height - landing
        # Rising towards higher ground (a step's riser just ahead), the foot is drawn up by the rise so that
        # its swing does not catch the edge; it reaches out again from the apex on.
        rise = landing - ground.height(base_xy[0] + foot[0], base_xy[1] + foot[1])
        retract = retract + jnp.clip(rise, 0.0, MAX_RETRACT)
        hold = (rise > RISER) & (foot_height < SWING_CLEARANCE)
    time_left = fall_time(body.zdot, foot_height, g)  # to touchdown
    drift = jnp.stack([body.roll, body.pitch]) + spin[:2] * time_left / (1.0 - inertia.alpha)  # tilt at touchdown
    now = (body.level @ (body.foot - body.com))[:2]  # where the foot is, heading frame from the COM
    placement = within_tilt_budget(placement, now, drift,
                                    inertia.swing_tilt, gains.tilt_budget, gains.leg_length)
    # Below a riser's top the foot stays where it is, the leg shortening: the swing waits until it clears.
    placement = jnp.where(hold, now, placement)
    flight_length = gains.leg_length - jnp.where(body.zdot > 0, retract, 0.0)
    target = placement_angles(leg, body.level, placement, flight_length, body.com)
    return flight_pd(body, target, scale)


def flight_pd(body: Body, target: jax.Array, scale: PDScale | None = None) -> jax.Array:
    """Joint torques (3,) N·m of the flight PD to joint `target`s (rad), damping the leg's rate in the world."""
    leg_rate = body.qd + jnp.concatenate([body.gyro[:2], jnp.zeros(1)])  # the leg's rate in the world
    return pd(*scaled(jnp.asarray(FLIGHT_KP), jnp.asarray(FLIGHT_KD), scale), target - body.q, leg_rate)


def initial_state(params: RaibertParams, obs: Observation) -> RaibertState:
    params = jax.tree_util.tree_map(lambda v: jnp.asarray(v, dtype=jnp.float32), params)
    now = jnp.asarray(obs.time, dtype=jnp.float32)
    floor = (jnp.float32(0.0) if obs.ground is None
             else jnp.asarray(obs.ground.height(obs.qpos[0], obs.qpos[1]), jnp.float32))
    return RaibertState(
        params=params,
        phase=jnp.int32(FLIGHT),
        phase_start=now,
        touchdown_time=now,
        stance_time=jnp.float32(0.0),  # none measured yet
        apex=jnp.asarray(obs.qpos[2], dtype=jnp.float32),
        height_bias=jnp.float32(0.0),
        speed_offset=jnp.zeros(2, dtype=jnp.float32),
        speed_reference=jnp.zeros(2, dtype=jnp.float32),
        thrust_force=jnp.float32(0.0),
        work=jnp.float32(0.0),
        floor=floor,
    )


COMMANDS = Commands(read=_read_commands, write=_write_commands)


def raibert(robot: Robot, config: RaibertConfig | None = None) -> Controller:
    """`raibert`: hops at the per-instance commanded apex rise and speed.

    params: `raibert_params(...)` or None (`config` gains, DEFAULT_HEIGHT in place).
    """
    return gait(robot, config)


def gait(robot: Robot, config: RaibertConfig | None = None, name: str = "raibert", plan: Plan | None = None,
         key: str = "") -> Controller:
    """Raibert's three-part gait as a controller named `name`, changed where `plan` says (None: Raibert's own).
    `key`: what `plan` closed over, for the controller's key."""
    layout = robot.layout
    mass, dt = layout.total_mass, layout.timestep
    # Eager, op by op: under one jit XLA fuses it and rounds the float32 facts otherwise, which moves every sweep's
    # numbers (make sweep's results.csv is kept byte for byte). Its ~80 small programs cost a second of every
    # process, so the facts are worked out once and kept on disk beside the stored programs.
    urdf_inertia = programs.remembered(f"raibert inertia facts|{robot!r}",
                                       lambda: jax.tree_util.tree_map(np.asarray, inertia_facts(robot.leg)))
    defaults = jax.tree_util.tree_map(lambda v: v[0], raibert_params(1, height=DEFAULT_HEIGHT, config=config))

    def act(s: RaibertState, obs: Observation, gravity):
        gains, own = s.params.gains, s.params.leg
        # Static: without legs of their own, the URDF's leg folded as constants (today's program).
        leg, standing, inertia = ((robot.leg, robot.standing_height, urdf_inertia) if own is None
                                  else (own.geometry, own.standing_height, own.inertia))
        # The floor is level, so hops and flights follow gravity's vertical part; a sideways
        # part only pushes the robot along, which the speed loop sees as an error.
        g = jnp.maximum(-gravity[2], MIN_GRAVITY)
        scale = s.params.pd
        if s.params.latency is not None:  # static: what the torque will meet when it acts, with loops that wait
            obs, scale = ahead(obs, s.params.latency), detuned(scale, s.params.latency)
        body = sense(robot, obs, leg)
        stiffness = mass * EARTH_GRAVITY / gains.sag
        release, hold = (gains.leg_length, None) if plan is None else plan.release(s, leg, body)
        phase, ev = next_phase(s.phase, obs.contact.flag, obs.time - s.phase_start, body.length,
                               body.length_rate, release, hold)
        speed = speed_update(s, ev, body.v, obs.time, g)
        ground, base_xy, floor, planned = obs.ground, obs.qpos[:2], s.floor, s.plan
        if ground is not None:  # static: on a terrain, the ground under the next hop (the plane: z = 0)
            floor = jnp.where(ev.bottom, landing_floor(leg, body, ground, base_xy, speed, s.params.height, g),
                              s.floor)
            if plan is not None:  # static: Raibert's own (today's program)
                floor, planned = plan.aim(leg, body, ground, base_xy, speed, s, ev, phase, floor, standing, g)
        height_bias, thrust_force = height_update(s, ev, body, g, stiffness, mass, standing,
                                                  None if ground is None else floor)
        apex = jnp.where(ev.liftoff, body.z, jnp.where(phase == FLIGHT, jnp.maximum(s.apex, body.z), s.apex))
        spin = kinematics.angular_momentum(leg, body.q, body.qd, body.gyro) / inertia.robot
        own = None
        if plan is not None:  # static
            own, thrust_force, planned = plan.push(leg, body, s, ev, phase, planned, height_bias, thrust_force,
                                                   standing, g, inertia)
        stance = stance_torque(leg, gains, phase, body, spin, speed, thrust_force, g, stiffness, mass,
                               inertia.swing_tilt, scale, own)
        placed = speed if plan is None else speed._replace(offset=speed.offset + plan.shift(s, planned, g))
        flight = flight_torque(leg, gains, body, spin, placed, g, inertia, scale, ground, base_xy)
        if plan is not None:  # static
            height_bias = height_bias if ground is None else plan.bias(s, ev, height_bias)
            flight = plan.flight(leg, body, ground, base_xy, speed, s, planned, flight, g, scale, spin, inertia)
        torque = saturate(layout, jnp.where(phase == FLIGHT, flight, stance))
        ctrl = to_ctrl(layout, torque)
        state = RaibertState(
            params=s.params, phase=phase, phase_start=jnp.where(phase != s.phase, obs.time, s.phase_start),
            touchdown_time=speed.touchdown_time, stance_time=speed.stance_time, apex=apex,
            height_bias=height_bias, speed_offset=speed.offset, speed_reference=speed.reference,
            thrust_force=thrust_force, work=s.work + jnp.abs(torque * body.qd).sum() * dt, floor=floor, plan=planned,
        )
        return ctrl, state

    def init(obs, params):
        state = initial_state(defaults if params is None else params, obs)
        return state if plan is None else state._replace(plan=plan.initial(obs))

    return Controller(name=name, init=init, act=act, commands=COMMANDS, key=f"{name}|{key}|{config!r}|{robot!r}"
                      if plan is not None else f"raibert|{config!r}|{robot!r}")


def _unturn(rot: jax.Array) -> jax.Array:
    """World -> heading frame (the world turned by the body's yaw)."""
    heading = jnp.arctan2(rot[1, 0], rot[0, 0])
    c, s = jnp.cos(heading), jnp.sin(heading)
    return jnp.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
