"""The kernels every monoped task shares, pure and per instance: an action's joint targets and the PD law that
tracks them (`joint_targets`, `pd_torque`), the observation a policy reads (`observe`), the reward kernels and the
termination (`fallen`). The trained policy as a core controller (`hopper_mjx.envs.policy`) uses the same ones."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from hopper_mjx.control.base import PDScale, joint_state, pd, saturate, scaled
from hopper_mjx.envs.task_config import MonopedConfig
from hopper_mjx.hardware.signals import Observation
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.world import EARTH_GRAVITY
from hopper_mjx.terrain import scan as terrain_scan

# The flight apex's carry (`apex_reward="flight"`): the apex judged in stance, and the flight's highest predicted
# apex so far (NO_FLIGHT in stance), both m.
FLIGHT_INFO = ("apex", "flight_top")
NO_FLIGHT = -1e3
# flight_top through an episode's first fall, from its initial clearance: a drop is not a hop.
DROPPING = -2e3


def joint_targets(layout: Layout, cfg: MonopedConfig, stance: jax.Array, action: jax.Array) -> jax.Array:
    """Action in [-1, 1]³ -> joint position targets (rad), inside the joint ranges."""
    rng = jnp.asarray(layout.joint_range)
    target = stance + jnp.asarray(cfg.action_scale) * jnp.clip(action, -1.0, 1.0)
    return jnp.clip(target, rng[:, 0], rng[:, 1])


def pd_torque(layout: Layout, cfg: MonopedConfig, target: jax.Array, obs, scale: PDScale | None = None) -> jax.Array:
    """The PD law on joint angles -> joint torques (haa, hfe, kfe), saturated at the effort limits;
    `scale`: an instance's factors on kp and kd."""
    q, qd = joint_state(layout, obs)
    return saturate(layout, pd(*scaled(jnp.asarray(cfg.kp), jnp.asarray(cfg.kd), scale), target - q, qd))


# The robot's own signals in the observation, in order, with their sizes (`observe` checks them).
ROBOT_SIGNALS = (("orientation", 4), ("angular rate", 3), ("height", 1), ("linear velocity", 3), ("foot contact", 1),
                 ("contact force", 3), ("joint angles", 3), ("joint rates", 3))
MIN_GRAVITY = 0.1  # m/s², a floor under g where it divides (no task draws less than 0.5)


def observation_size(command_size: int, observe_gravity: bool, scan_points: int = 0) -> int:
    """The robot's signals + the command + 3 of the previous action (+ gravity) (+ the height scan's points, on a
    terrain)."""
    return sum(size for _, size in ROBOT_SIGNALS) + command_size + 3 + int(observe_gravity) + scan_points


def observe(layout: Layout, cfg: MonopedConfig, obs: Observation, gravity: jax.Array,
            command: jax.Array, last_action: jax.Array) -> jax.Array:
    """The policy's input, from the robot's own signals, roughly unit-scaled: the IMU's
    orientation and rate, the odometry's height and velocity, the foot contact, the joints."""
    weight = layout.total_mass * EARTH_GRAVITY
    q, qd = joint_state(layout, obs)
    robot = [
        obs.qpos[3:7],
        0.25 * obs.qvel[3:6],
        obs.qpos[2:3],
        obs.qvel[:3],
        obs.contact.flag[None].astype(jnp.float32),
        obs.contact.force / weight,
        q,
        0.1 * qd,
    ]
    assert [p.shape[0] for p in robot] == [size for _, size in ROBOT_SIGNALS]  # static shapes: trace time
    parts = [*robot, command, last_action]
    if cfg.observe_gravity:
        parts.append(-gravity[2:3] / EARTH_GRAVITY)
    if cfg.terrain:  # the base's height over the ground at each scan point (the config's: those it trained on)
        ground = terrain_scan.measured_heights(obs.ground.heights, obs.ground.size, obs.qpos[:3], obs.qpos[3:7],
                                               jnp.asarray(cfg.scan, obs.qpos.dtype))
        over = obs.qpos[2] - ground
        parts.append(over if cfg.observe_scan else jnp.zeros_like(over))
    return jnp.nan_to_num(jnp.concatenate(parts), posinf=0.0, neginf=0.0)


# -- reward kernels and termination ---------------------------------------------------------


def closeness(error: jax.Array, scale: float) -> jax.Array:
    """1 at zero error, 1/e at `scale`: a tracking reward with a gradient everywhere."""
    return jnp.exp(-jnp.abs(error) / scale)


def outside(value: jax.Array, band: tuple[float, float]) -> jax.Array:
    """Distance of `value` outside the interval `band` (0 inside it)."""
    return jnp.maximum(band[0] - value, 0.0) + jnp.maximum(value - band[1], 0.0)


def predicted_apex(d, g: jax.Array) -> jax.Array:
    """Height the base would reach on a ballistic arc from here (its current height when falling)."""
    vz = jnp.maximum(d.qvel[2], 0.0)
    return d.qpos[2] + vz**2 / (2.0 * jnp.maximum(g, MIN_GRAVITY))


def flight_apex(apex: jax.Array, flying: jax.Array, info: dict) -> tuple[jax.Array, dict]:
    """(the apex judged now, the new `FLIGHT_INFO`) for `apex_reward="flight"`, from this step's predicted
    `apex` and foot contact: in flight the highest predicted apex of this flight (from lift-off on: the
    ballistic apex), in stance the last flight's, held."""
    top, held = info["flight_top"], info["apex"]
    new_top = jnp.where(flying, jnp.where(top == DROPPING, top, jnp.maximum(top, apex)), NO_FLIGHT)
    held = jnp.where(~flying & (top > NO_FLIGHT), top, held)
    return jnp.where(flying & (new_top > NO_FLIGHT), new_top, held), {"apex": held, "flight_top": new_top}


def tilt_from_vertical(d) -> jax.Array:
    """Angle (rad) between the base's z axis and the world's vertical."""
    w, x, y, _ = d.qpos[3:7]
    cos = 1.0 - 2.0 * (x * x + y * y)  # z-component of the body z axis
    return jnp.arccos(jnp.clip(cos, -1.0, 1.0))


def fallen(cfg: MonopedConfig, d) -> jax.Array:
    finite = jnp.isfinite(d.qpos).all() & jnp.isfinite(d.qvel).all()
    return ~finite | (tilt_from_vertical(d) > cfg.max_tilt) | (d.qpos[2] < cfg.min_base_height)


def posture_terms(cfg: MonopedConfig, d, action: jax.Array, last_action: jax.Array,
                  effort: jax.Array, fell: jax.Array) -> dict[str, jax.Array]:
    """The terms every task pays (already weighted): upright, effort, smoothness, spin, fall."""
    return {
        "upright": cfg.w_upright * jnp.exp(-((tilt_from_vertical(d) / cfg.upright_scale) ** 2)),
        "effort": -cfg.w_effort * effort,
        "action_rate": -cfg.w_action_rate * jnp.sum((action - last_action) ** 2),
        "spin": -cfg.w_spin * jnp.sum(d.qvel[3:6] ** 2),
        "fall": -cfg.fall_penalty * fell.astype(jnp.float32),
    }


def clearance_term(cfg: MonopedConfig, clearance: jax.Array, flying: jax.Array) -> jax.Array:
    """In flight, the foot's bottom over the ground under it (m; with `clearance_lookahead`, the highest ground on
    its way) as a share of `clearance_target`, capped at 1."""
    return cfg.w_clearance * flying * jnp.clip(clearance / cfg.clearance_target, 0.0, 1.0)


def speed_term(cfg: MonopedConfig, d, command_speed: jax.Array) -> jax.Array:
    """Horizontal velocity against the commanded (vx, vy), a Gaussian kernel of width speed_scale."""
    return cfg.w_speed * jnp.exp(-jnp.sum((d.qvel[0:2] - command_speed) ** 2) / cfg.speed_scale**2)
