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
body frame by the body's present tilt (see `_placement_angles`), and the hip
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
enough to lean the body back at 0.5 m/s without upsetting it sideways. The servo's torque is capped at `traction`·leg force·L, a share
of the friction cone: at touchdown the leg force is still small, and a hip
torque beyond the floor's grip makes the foot slip or bounce.

Every gravity-dependent quantity uses the instance's own g, its downward (vertical)
part, floored at `MIN_GRAVITY` so that a weightless robot gets finite commands.
Contact is read in `act` from the MJX contact rows of the foot (distance < 0), the
definition of `hopper_mjx.signals.contact`; like the joint readings it is one step
(1 ms) old.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from brax import math as bmath

from hopper_mjx.control import kinematics, pid
from hopper_mjx.control.base import Controller, clip_to_limits
from hopper_mjx.control.kinematics import LegGeometry
from hopper_mjx.model.layout import Layout

FLIGHT, COMPRESSION, THRUST, UNLOADING = 0, 1, 2, 3
PHASES = ("flight", "compression", "thrust", "unloading")
MIN_PHASE_TIME = 0.01  # s in flight / stance before contact may end it (debounce)
EARTH_GRAVITY = 9.81  # m/s², where the attitude stiffness holds as given
MIN_GRAVITY = 0.1  # m/s², floor under g in the formulas (g = 0 has no hops)
STANCE_HFE, STANCE_KFE = 0.5, -0.95  # rad, the core's default stance (for the robot's inertia)
MAX_PLACEMENT = 0.25  # m, bound on the foot placement from the COM


@dataclass(frozen=True)
class RaibertConfig:
    """Gains of the three-part controller; all may be overridden per instance."""

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


def default_config() -> RaibertConfig:
    return RaibertConfig()


GAINS = tuple(f.name for f in dataclasses.fields(RaibertConfig))
DEFAULT_HEIGHT = 0.10  # m, commanded apex rise over the standing height when none is given


class RaibertState(NamedTuple):
    params: dict  # "height" () m, "speed" (2,) m/s, and every RaibertConfig field
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


def raibert_params(n: int, *, height, speed=(0.0, 0.0), config: RaibertConfig | None = None,
                   **gain_overrides) -> dict:
    """Per-instance commands and gains, every leaf with leading axis n.

    height: apex rise over the standing height, m, scalar or (n,);
    speed: (vx, vy) m/s, (2,) or (n, 2); gain_overrides: any RaibertConfig field,
    scalar or (n,) (a sweep over a gain is just an array here).
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    unknown = set(gain_overrides) - set(GAINS)
    if unknown:
        raise ValueError(f"unknown Raibert gain(s) {sorted(unknown)}; expected some of {list(GAINS)}")
    config = config or default_config()

    def batch(name, value, shape):
        value = np.asarray(value, dtype=np.float32)
        try:
            out = np.broadcast_to(value, (n,) + shape).copy()
        except ValueError:
            raise ValueError(f"{name} must be a scalar or shape {(n,) + shape}, got {value.shape}") from None
        if not np.all(np.isfinite(out)):
            raise ValueError(f"{name} must be finite")
        return out

    params = {"height": batch("height", height, ()), "speed": batch("speed", speed, (2,))}
    if np.any(params["height"] < 0):
        raise ValueError("height (apex rise) must be >= 0 m")
    for name in GAINS:
        params[name] = batch(name, gain_overrides.get(name, getattr(config, name)), ())
    for name in ("leg_length", "sag"):
        if np.any(params[name] <= 0):
            raise ValueError(f"{name} must be > 0 m")
    if np.any(params["tilt_budget"] <= 0):
        raise ValueError("tilt_budget must be > 0 rad")
    if np.any((params["tilt_lead"] < 0) | (params["tilt_lead"] > 1)):
        raise ValueError("tilt_lead must be in [0, 1]")
    return params


def _tilt(rot: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(roll, pitch), rad, of a body->world rotation matrix (ZYX Euler angles)."""
    return jnp.arctan2(rot[2, 1], rot[2, 2]), -jnp.arcsin(jnp.clip(rot[2, 0], -1.0, 1.0))


def foot_contact(layout: Layout, data) -> jax.Array:
    """The foot touches the floor (MJX contact rows of the foot with distance < 0)."""
    con = data._impl.contact
    return ((con.geom == layout.foot_geom).any(axis=-1) & (con.dist < 0)).any()


def raibert(layout: Layout, config: RaibertConfig | None = None, *, leg: LegGeometry | None = None) -> Controller:
    """`raibert`: hops at the per-instance commanded apex rise and speed.

    params: `raibert_params(...)` or None (`config` gains, DEFAULT_HEIGHT in place).
    leg: the leg geometry (default: the shipped monoped's, checked against `layout`).
    """
    config = config or default_config()
    leg = kinematics.geometry_for(layout, leg)
    qadr, dadr = jnp.asarray(layout.joint_qpos), jnp.asarray(layout.joint_dof)
    flight_gains = pid.gains_of()._replace(i=jnp.zeros(3))  # the seed's position controllers, PD only
    mass, dt = layout.total_mass, layout.timestep
    stance = jnp.array([0.0, STANCE_HFE, STANCE_KFE])
    robot_inertia = jax.vmap(lambda axis: kinematics.angular_momentum(leg, stance, jnp.zeros(3), axis))(jnp.eye(3)).diagonal()
    # In flight a hip swing of Δ turns the body back by α·Δ (zero angular momentum),
    # so a leg that swings its world angle by Δθ tilts the body by -α/(1-α)·Δθ.
    leg_momentum = jax.vmap(lambda hip: kinematics.angular_momentum(leg, stance, hip, jnp.zeros(3)))(jnp.eye(3)).diagonal()
    alpha = (leg_momentum / robot_inertia)[:2]  # (haa/roll, hfe/pitch)
    swing_tilt = alpha / (1.0 - alpha)
    defaults = {k: v[0] for k, v in raibert_params(1, height=DEFAULT_HEIGHT, config=config).items()}

    def init(data, params):
        params = defaults if params is None else params
        params = {k: jnp.asarray(v, dtype=jnp.float32) for k, v in params.items()}
        return RaibertState(
            params=params,
            phase=jnp.int32(FLIGHT),
            phase_start=jnp.asarray(data.time, dtype=jnp.float32),
            touchdown_time=jnp.asarray(data.time, dtype=jnp.float32),
            stance_time=jnp.float32(0.0),  # none measured yet
            apex=jnp.asarray(data.qpos[2], dtype=jnp.float32),
            height_bias=jnp.float32(0.0),
            speed_offset=jnp.zeros(2, dtype=jnp.float32),
            speed_reference=jnp.zeros(2, dtype=jnp.float32),
            thrust_force=jnp.float32(0.0),
            work=jnp.float32(0.0),
        )

    def act(s: RaibertState, data, gravity):
        p = s.params
        # The floor is level, so hops and flights follow gravity's vertical part; a sideways
        # part only pushes the robot along, which the speed loop sees as an error.
        g = jnp.maximum(-gravity[2], MIN_GRAVITY)
        q, qd = data.qpos[qadr], data.qvel[dadr]
        z, zdot = data.qpos[2], data.qvel[2]
        # Horizontal velocity of the COM (constant through a flight, unlike the base's).
        gyro = data.qvel[3:6]
        com, com_rate = jax.jvp(lambda a: kinematics.com_position(leg, a), (q,), (qd,))
        from_base = com + jnp.array([0.0, 0.0, -leg.haa_below_base])
        rot = bmath.quat_to_3x3(data.qpos[3:7])  # body -> world ([w, x, y, z] quaternion)
        unturn = _unturn(rot)  # world -> heading frame
        level = unturn @ rot  # body -> level frame: roll and pitch only
        heading = lambda xy: unturn[:2, :2] @ xy  # a horizontal world vector in the heading frame
        v = (data.qvel[:3] + rot @ (jnp.cross(gyro, from_base) + com_rate))[:2]
        roll, pitch = _tilt(rot)
        length = kinematics.leg_length(leg, q[2])
        length_rate = kinematics.leg_length_rate(leg, q[2], qd[2])
        stiffness = mass * EARTH_GRAVITY / p["sag"]
        touching = foot_contact(layout, data)
        elapsed = data.time - s.phase_start

        # -- phase transitions -------------------------------------------------
        in_stance = s.phase != FLIGHT
        touchdown = ~in_stance & touching & (elapsed > MIN_PHASE_TIME)
        liftoff = in_stance & ~touching & (elapsed > MIN_PHASE_TIME)
        bottom = (s.phase == COMPRESSION) & (length_rate >= 0) & (elapsed > MIN_PHASE_TIME)
        extended = (s.phase == THRUST) & (length >= p["leg_length"])
        phase = jnp.where(touchdown, COMPRESSION, s.phase)
        phase = jnp.where(bottom, THRUST, phase)
        phase = jnp.where(extended, UNLOADING, phase)
        phase = jnp.where(liftoff, FLIGHT, phase)
        changed = phase != s.phase

        # Part 1 bookkeeping: adapt the apex target at touchdown, size the thrust at the bottom.
        rise = s.apex - leg.standing_height
        height_bias = jnp.where(
            touchdown, jnp.clip(s.height_bias + p["height_adapt"] * (p["height"] - rise), -0.3, 0.3), s.height_bias
        )
        squeeze = jnp.maximum(p["leg_length"] - length, 0.0)
        target_z = leg.standing_height + p["height"] + height_bias
        needed = mass * g * (target_z - z) - 0.5 * mass * zdot**2 - 0.5 * stiffness * squeeze**2
        thrust_force = jnp.where(bottom, jnp.maximum(needed, 0.0) / jnp.maximum(squeeze, 0.02), s.thrust_force)

        # Part 2 bookkeeping: stance time at lift-off, the placement integral at touchdown.
        # Before the first lift-off: half a period of the virtual spring-mass.
        stance_time = jnp.where(s.stance_time > 0, s.stance_time, math.pi * jnp.sqrt(p["sag"] / EARTH_GRAVITY))
        touchdown_time = jnp.where(touchdown, data.time, s.touchdown_time)
        stance_time = jnp.where(liftoff, data.time - touchdown_time, stance_time)
        speed_gain = p["speed_gain"] * p["leg_length"] / (g * stance_time)
        step = jnp.clip(p["speed"] - s.speed_reference, -p["speed_step"], p["speed_step"])
        speed_reference = jnp.where(touchdown, s.speed_reference + step, s.speed_reference)
        speed_error = v - speed_reference
        speed_offset = jnp.where(
            touchdown,
            jnp.clip(s.speed_offset + p["speed_integral"] * speed_gain * speed_error, -0.1, 0.1),
            s.speed_offset,
        )
        apex = jnp.where(liftoff, z, jnp.where(phase == FLIGHT, jnp.maximum(s.apex, z), s.apex))

        # -- stance: leg force through J^T, hip attitude servo -------------------
        # The floor's push is aimed at the COM (not the hip), so that it does not
        # spin the robot; the spring acts on the virtual leg length.
        spring = stiffness * (p["leg_length"] - length)
        damping = 2.0 * p["damping_ratio"] * jnp.sqrt(stiffness * mass) * length_rate
        leg_force = jnp.select(
            [phase == COMPRESSION, phase == THRUST], [spring - damping, spring + thrust_force], 0.0
        )
        leg_force = jnp.maximum(leg_force, 0.0)  # a foot can only push on the floor
        foot = kinematics.foot_position(leg, q)
        to_com = com - foot
        floor_push = leg_force * to_com / jnp.linalg.norm(to_com)
        servo = (phase == COMPRESSION) | (phase == THRUST)
        # The damping acts on the whole robot's rotation rate H / I, not the body's:
        # the leg carries as much angular momentum as the body, and what H is at
        # lift-off is how fast the robot will tumble through the flight.
        # The stiffness falls with g (as √g, see the module docstring).
        spin = kinematics.angular_momentum(leg, q, qd, gyro) / robot_inertia
        lean = jnp.sqrt(g / EARTH_GRAVITY)
        # The next flight swings the leg from about -x_f to +x_f (x_f = v·T_s/2, the
        # neutral placement) and so tilts the body by swing_tilt·2x_f/L: leaving the
        # floor leaned the other way by half of that centres the tilt on level.
        neutral = heading(v * stance_time / 2) / p["leg_length"]
        lean_ref = p["tilt_lead"] * swing_tilt * jnp.stack([neutral[1], -neutral[0]])
        attitude = jnp.stack([lean * p["roll_kp"] * (roll - lean_ref[0]) + p["roll_kd"] * spin[0],
                              lean * p["pitch_kp"] * (pitch - lean_ref[1]) + p["pitch_kd"] * spin[1], 0.0])
        # A hip torque τ pushes the foot sideways with τ/L: beyond the floor's grip
        # (friction 1 times the leg force) the foot slides and the hop is lost.
        grip = p["traction"] * leg_force * length
        attitude = attitude * jnp.minimum(1.0, grip / (jnp.linalg.norm(attitude) + 1e-6))
        brake = -flight_gains.d * qd  # unloading: let the joints coast to rest, no push
        stance_torque = jnp.where(
            phase == UNLOADING, brake,
            -kinematics.jacobian(leg, q).T @ floor_push + jnp.where(servo, attitude, 0.0),
        )

        # -- flight: foot placement by IK, joint PD -----------------------------
        placement = v * stance_time / 2 + speed_gain * speed_error + speed_offset
        placement = heading(jnp.clip(placement, -MAX_PLACEMENT, MAX_PLACEMENT))
        foot_height = z + (rot @ (foot - jnp.array([0.0, 0.0, leg.haa_below_base])))[2] - leg.foot_radius
        time_left = (zdot + jnp.sqrt(zdot**2 + 2.0 * g * jnp.maximum(foot_height, 0.0))) / g  # to touchdown
        drift = jnp.stack([roll, pitch]) + spin[:2] * time_left / (1.0 - alpha)  # tilt at touchdown, leg held
        placement = _within_tilt_budget(placement, (level @ (foot - com))[:2], drift, swing_tilt,
                                        p["tilt_budget"], p["leg_length"])
        flight_length = p["leg_length"] - jnp.where(zdot > 0, p["retract"], 0.0)
        target = _placement_angles(leg, level, placement, flight_length, com)
        leg_rate = qd + jnp.concatenate([gyro[:2], jnp.zeros(1)])  # the leg's rate in the world
        flight_torque, _ = pid.effort(flight_gains, target - q, -leg_rate, jnp.zeros(3), dt)

        ctrl = clip_to_limits(layout, jnp.where(phase == FLIGHT, flight_torque, stance_torque))
        torque = ctrl[jnp.asarray(layout.actuator_of_joint)]
        state = RaibertState(
            params=p,
            phase=phase,
            phase_start=jnp.where(changed, data.time, s.phase_start),
            touchdown_time=touchdown_time,
            stance_time=stance_time,
            apex=apex,
            height_bias=height_bias,
            speed_offset=speed_offset,
            speed_reference=speed_reference,
            thrust_force=thrust_force,
            work=s.work + jnp.abs(torque * qd).sum() * dt,
        )
        return ctrl, state

    return Controller(name="raibert", init=init, act=act)


def _within_tilt_budget(wanted: jax.Array, now: jax.Array, drift: jax.Array, swing_tilt: jax.Array,
                        budget: jax.Array, length: jax.Array) -> jax.Array:
    """The placement `wanted` moved, if need be, so that the body lands tilted <= `budget`.

    Heading frame, from the COM: `now` is where the foot is, `drift` the (roll,
    pitch) the body would land with if the leg were held where it is. In flight,
    tilt + swing_tilt·(leg world angle) - H·t/I_body is constant (the robot's angular
    momentum H is), so sending the foot Δ further tilts the body by swing_tilt·Δ/L
    more. Past the budget the leg is sent short, taking up part of H itself.
    """
    # +x placement turns the leg by -x/L about y (pitch +), +y by +y/L about x (roll -).
    sign = jnp.array([-1.0, 1.0])  # (roll, pitch) per unit of (y, x)
    landing = drift + sign * swing_tilt * (wanted[::-1] - now[::-1]) / length
    allowed = jnp.clip(landing, -budget, budget)
    return (now[::-1] + sign * (allowed - drift) * length / swing_tilt)[::-1]


def _unturn(rot: jax.Array) -> jax.Array:
    """World -> heading frame (the world turned by the body's yaw)."""
    heading = jnp.arctan2(rot[1, 0], rot[0, 0])
    c, s = jnp.cos(heading), jnp.sin(heading)
    return jnp.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def _placement_angles(leg: LegGeometry, level: jax.Array, placement: jax.Array, length: jax.Array,
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
