"""Raibert's three-part hopping controller for the articulated haa/hfe/kfe leg.

The leg is treated as Raibert's telescopic leg through its *virtual leg* (hfe
axis -> foot, see `kinematics`): its length is set by the knee alone, so a leg
force f maps to joint torques by the Jacobian transpose, τ = f·∂L/∂q (knee only),
and the hips stay free for attitude and foot placement. Every gravity-dependent
quantity uses the instance's own g.

Phases (driven by foot contact and the virtual leg length L / rate L̇):

    FLIGHT       joint PD (the seed's position controllers' p, d) to the IK target
                 of the foot placement below; the leg is shortened by `retract`
                 while the body rises, for ground clearance.
    COMPRESSION  touchdown -> L̇ >= 0: a virtual spring-damper along the leg,
                 stiffness k = m·g/sag; hip torques servo body pitch and roll.
    THRUST       bottom -> L = leg_length: the spring plus a constant extra force
                 that supplies the energy still missing for the commanded apex.
    UNLOADING    L = leg_length -> lift-off: no leg force, no hip torque.

Part 1, hop height: at the bottom the controller has m·g·z + ½m·ż² + ½k·ΔL²; the
thrust force adds W = m·g·(z_apex - z) - ½m·ż² - ½k·ΔL² over the remaining stroke.
The apex target is the standing height + command + a bias adapted hop by hop
from the measured apex (it absorbs the energy lost when the unsprung leg is
jerked off the floor and the body's share of the COM motion).

Part 2, speed: at touchdown the foot is placed (relative to the COM, world axes)
at x_f = v·T_s/2 + k_v·(v - v_d) + x_i in x and y, with T_s the last measured stance
time and k_v = speed_gain·L/(g·T_s): over one stance the COM's horizontal
velocity changes by about -g·T_s·x/L, so `speed_gain` is the fraction of the
speed error removed per hop at any gravity. x_i integrates the residual error
hop by hop (`speed_integral`), absorbing the neutral-point model error.
Lateral placement uses haa, so the robot balances in 3-D.

Part 3, attitude: during compression and thrust, τ_hfe = kp·pitch + kd·ω_y and
τ_haa = kp·roll + kd·ω_x (the joint pushes the body the other way).

Contact is read inside `act` from the MJX contact rows of the foot (distance < 0),
the same definition as `hopper_mjx.signals.contact`; like the controller's other
sensors it is one physics step (1 ms) old.
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
MIN_GRAVITY = 0.1  # m/s², floor under g in the formulas (g = 0 has no hops)
MAX_PLACEMENT = 0.25  # m, bound on the foot placement from the COM


@dataclass(frozen=True)
class RaibertConfig:
    """Gains of the three-part controller; all may be overridden per instance."""

    leg_length: float = 0.64  # m, virtual leg length at touchdown and lift-off
    retract: float = 0.04  # m the leg is shortened while rising in flight
    sag: float = 0.025  # m, static compression of the virtual spring under m·g (k = m·g/sag)
    damping_ratio: float = 0.1  # of the virtual spring during compression
    height_adapt: float = 0.5  # fraction of the apex error added to the apex target per hop
    speed_gain: float = 0.3  # fraction of the speed error removed per stance (see k_v)
    speed_integral: float = 0.2  # fraction of k_v·(v - v_d) accumulated into the placement per hop
    pitch_kp: float = 150.0  # N·m/rad, stance hfe servo on body pitch
    pitch_kd: float = 12.0  # N·m·s/rad
    roll_kp: float = 150.0  # N·m/rad, stance haa servo on body roll
    roll_kd: float = 12.0  # N·m·s/rad


def default_config() -> RaibertConfig:
    return RaibertConfig()


GAINS = tuple(f.name for f in dataclasses.fields(RaibertConfig))
DEFAULT_HEIGHT = 0.10  # m, commanded apex rise over the standing height when none is given


class RaibertState(NamedTuple):
    params: dict  # "height" () m, "speed" (2,) m/s, and every RaibertConfig field
    phase: jax.Array  # int32, one of FLIGHT..UNLOADING
    phase_start: jax.Array  # s, simulation time the phase began
    stance_time: jax.Array  # s, last measured stance duration
    apex: jax.Array  # m, highest base height of the current flight
    height_bias: jax.Array  # m added to the apex target (adapted per hop)
    speed_offset: jax.Array  # (2,) m, integral part of the foot placement
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
    return params


def _tilt(quat: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(roll, pitch), rad, of a [w, x, y, z] body->world quaternion (ZYX Euler angles)."""
    rot = bmath.quat_to_3x3(quat)
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
    defaults = {k: v[0] for k, v in raibert_params(1, height=DEFAULT_HEIGHT, config=config).items()}

    def init(data, params):
        params = defaults if params is None else params
        params = {k: jnp.asarray(v, dtype=jnp.float32) for k, v in params.items()}
        return RaibertState(
            params=params,
            phase=jnp.int32(FLIGHT),
            phase_start=jnp.asarray(data.time, dtype=jnp.float32),
            stance_time=jnp.float32(math.pi) * jnp.sqrt(params["sag"] / 9.81),  # replaced after one hop
            apex=jnp.asarray(data.qpos[2], dtype=jnp.float32),
            height_bias=jnp.float32(0.0),
            speed_offset=jnp.zeros(2, dtype=jnp.float32),
            thrust_force=jnp.float32(0.0),
            work=jnp.float32(0.0),
        )

    def act(s: RaibertState, data, gravity):
        p = s.params
        g = jnp.maximum(jnp.linalg.norm(gravity), MIN_GRAVITY)
        q, qd = data.qpos[qadr], data.qvel[dadr]
        z, zdot, v = data.qpos[2], data.qvel[2], data.qvel[:2]
        roll, pitch = _tilt(data.qpos[3:7])
        length = kinematics.leg_length(leg, q[2])
        length_rate = kinematics.leg_length_rate(leg, q[2], qd[2])
        stiffness = mass * g / p["sag"]
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
        stance_time = jnp.where(liftoff, elapsed, s.stance_time)
        speed_gain = p["speed_gain"] * p["leg_length"] / (g * stance_time)
        speed_offset = jnp.where(
            touchdown,
            jnp.clip(s.speed_offset + p["speed_integral"] * speed_gain * (v - p["speed"]), -0.1, 0.1),
            s.speed_offset,
        )
        apex = jnp.where(liftoff, z, jnp.where(phase == FLIGHT, jnp.maximum(s.apex, z), s.apex))

        # -- stance: virtual leg force through J^T, hip attitude servo ---------
        spring = stiffness * (p["leg_length"] - length)
        damping = 2.0 * p["damping_ratio"] * jnp.sqrt(stiffness * mass) * length_rate
        leg_force = jnp.select(
            [phase == COMPRESSION, phase == THRUST], [spring - damping, spring + thrust_force], 0.0
        )
        leg_force = jnp.maximum(leg_force, 0.0)  # a foot can only push on the floor
        servo = (phase == COMPRESSION) | (phase == THRUST)
        gyro = data.qvel[3:6]
        stance_torque = jnp.stack([
            jnp.where(servo, p["roll_kp"] * roll + p["roll_kd"] * gyro[0], 0.0),
            jnp.where(servo, p["pitch_kp"] * pitch + p["pitch_kd"] * gyro[1], 0.0),
            leg_force * kinematics.leg_length_gradient(leg, q[2]),
        ])

        # -- flight: foot placement by IK, joint PD -----------------------------
        placement = v * stance_time / 2 + speed_gain * (v - p["speed"]) + speed_offset
        placement = jnp.clip(placement, -MAX_PLACEMENT, MAX_PLACEMENT)
        flight_length = p["leg_length"] - jnp.where(zdot > 0, p["retract"], 0.0)
        target = _placement_angles(leg, data.qpos[3:7], placement, flight_length)
        flight_torque, _ = pid.effort(flight_gains, target - q, -qd, jnp.zeros(3), dt)

        ctrl = clip_to_limits(layout, jnp.where(phase == FLIGHT, flight_torque, stance_torque))
        torque = ctrl[jnp.asarray(layout.actuator_of_joint)]
        state = RaibertState(
            params=p,
            phase=phase,
            phase_start=jnp.where(changed, data.time, s.phase_start),
            stance_time=stance_time,
            apex=apex,
            height_bias=height_bias,
            speed_offset=speed_offset,
            thrust_force=thrust_force,
            work=s.work + jnp.abs(torque * qd).sum() * dt,
        )
        return ctrl, state

    return Controller(name="raibert", init=init, act=act)


def _placement_angles(leg: LegGeometry, quat: jax.Array, placement: jax.Array, length: jax.Array) -> jax.Array:
    """Joint targets that put the foot `placement` (world x, y, m) from the COM with a
    virtual leg of `length`, for the body's current attitude."""
    below = length + leg.hfe_below_haa
    in_body = bmath.rotate(jnp.stack([placement[0], placement[1], -below]), bmath.quat_inv(quat))
    x = in_body[0] + leg.com_ahead_of_haa
    y = in_body[1]
    down = jnp.sqrt(jnp.maximum(length**2 - x**2, 1e-4)) + leg.hfe_below_haa
    z = -jnp.sqrt(jnp.maximum(down**2 - y**2, 1e-4))
    return kinematics.inverse(leg, jnp.stack([x, y, z]))
