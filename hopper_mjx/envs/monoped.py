"""A Brax training environment on the MJX monoped: hop to a commanded apex height and speed.

    env = MonopedEnv()                       # brax.envs.base.Env
    ppo.train(environment=env, randomization_fn=randomize_gravity, ...)

- **Physics**: `hopper_mjx.model.load()` stepped by `mjx.step` at the config's
  `timestep` (2 ms for training; the core evaluates at its own 1 ms); the policy acts
  every `n_frames` physics steps (default 50 Hz).
- **Actions** (3, in [-1, 1]) are joint position targets around the standing pose
  (`model.robot.stance_qpos`), `target = stance + action_scale * action`, clipped to the
  joint range and tracked by a PD law at the physics rate (`pd_torque`), saturated
  at the effort limits like the seed's position controllers on its effort joints.
- **Observations** (`observe`) are what a real robot reads: the IMU (orientation,
  angular rate), odometry (base height, linear velocity), the foot contact flag and
  force, joint positions and velocities, the command and the previous action;
  gravity only when `observe_gravity` is set.
- **Gravity** is drawn per environment, log-uniformly over `gravity_range`, by
  `randomize_gravity`, the Brax domain-randomisation hook that batches `opt.gravity`
  of the MJX model.
- **Reward and termination**: see `reward_terms` and `fallen`, documented in docs/learning.md.

State between steps lives in `State.info`: the command, the previous action and
the joint targets. Everything is one instance; Brax's wrappers vmap it.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from brax.envs.base import Env, State
from mujoco import mjx

from hopper_mjx import metrics
from hopper_mjx import model as hopper_model
from hopper_mjx.control.base import joint_state, pd, saturate, to_ctrl
from hopper_mjx.engine.mjx import foot_contact
from hopper_mjx.model import robot
from hopper_mjx.model.layout import Layout
from hopper_mjx.signals import Contact, Observation

MAX_TILT_FROM_VERTICAL = 0.8  # rad between the base's z axis and the vertical that ends an episode


@dataclasses.dataclass(frozen=True)
class MonopedConfig:
    """Everything that shapes the task; saved beside a trained policy (`to_dict`)."""

    policy_rate: float = 50.0  # Hz; the physics runs at 1 / timestep
    # m/s², per environment, log-uniform: as much experience per factor of g at the Moon end
    # (slow hops, few per episode) as at the Earth end.
    gravity_range: tuple[float, float] = (1.0, 12.0)
    observe_gravity: bool = False
    apex_range: tuple[float, float] = (1.0, 1.2)  # m, commanded base height at the top of a hop
    speed_range: tuple[float, float] = (-0.2, 0.2)  # m/s, commanded horizontal velocity, x and y
    action_scale: tuple[float, float, float] = (0.3, 0.6, 0.8)  # rad per unit action: haa, hfe, kfe
    kp: tuple[float, float, float] = (300.0, 300.0, 300.0)  # N·m/rad
    kd: tuple[float, float, float] = (6.0, 6.0, 6.0)  # N·m·s/rad
    # Reward weights (per policy step) and kernel widths.
    w_apex: float = 1.0
    apex_scale: float = 0.1  # m; exp(-|error| / scale)
    w_speed: float = 0.5
    speed_scale: float = 0.3  # m/s
    w_upright: float = 0.5
    upright_scale: float = 0.25  # rad; exp(-(tilt / scale)²)
    w_effort: float = 0.05  # times the mean of (torque / limit)²
    w_action_rate: float = 0.02
    w_spin: float = 0.01  # times |angular rate|², rad²/s²
    fall_penalty: float = 10.0
    # A fall: the base's z axis this far from vertical (rad; not the metrics' per-axis roll/pitch
    # bound, see docs/learning.md), or its origin this low (m).
    max_tilt: float = MAX_TILT_FROM_VERTICAL
    min_base_height: float = metrics.FALL_HEIGHT  # m
    initial_clearance: tuple[float, float] = (0.0, 0.1)  # m, foot above the floor at reset
    initial_joint_noise: float = 0.05  # rad
    # Training physics: a 2 ms step (half the core's cost per simulated second; a policy
    # behaves alike at 1 and 2 ms) and MuJoCo's Newton solver, warm-started, capped at
    # these iterations (the core runs to convergence; a capped solve is ~3x cheaper on CPU MJX).
    timestep: float = 0.002  # s
    solver_iterations: int = 2
    ls_iterations: int = 4

    def __post_init__(self):
        for name in ("gravity_range", "apex_range", "speed_range", "initial_clearance"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ValueError(f"{name} must be a finite (low, high) pair with low <= high, got {(lo, hi)}")
        if not self.gravity_range[0] > 0:
            raise ValueError(f"gravity_range must be > 0 m/s² (magnitudes, drawn log-uniformly), "
                             f"got {self.gravity_range}")
        if not (self.policy_rate > 0 and self.timestep > 0):
            raise ValueError(f"policy_rate and timestep must be positive, got {self.policy_rate}, {self.timestep}")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, values: dict) -> "MonopedConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(values) - known
        if unknown:
            raise ValueError(f"unknown MonopedConfig field(s): {sorted(unknown)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def decimation(layout: Layout, cfg: MonopedConfig) -> int:
    """Physics steps per policy step; the policy rate must divide the physics rate."""
    steps = 1.0 / (cfg.policy_rate * layout.timestep)
    if steps < 1 or abs(steps - round(steps)) > 1e-6:
        raise ValueError(f"policy_rate={cfg.policy_rate} Hz must divide the physics rate {1 / layout.timestep:g} Hz")
    return int(round(steps))


# -- the pieces shared with the policy controller (hopper_mjx.envs.policy) ------------------


def joint_targets(layout: Layout, cfg: MonopedConfig, stance: jax.Array, action: jax.Array) -> jax.Array:
    """Action in [-1, 1]³ -> joint position targets (rad), inside the joint ranges."""
    rng = jnp.asarray(layout.joint_range)
    target = stance + jnp.asarray(cfg.action_scale) * jnp.clip(action, -1.0, 1.0)
    return jnp.clip(target, rng[:, 0], rng[:, 1])


def pd_torque(layout: Layout, cfg: MonopedConfig, target: jax.Array, obs) -> jax.Array:
    """The PD law on joint angles -> joint torques (haa, hfe, kfe), saturated at the effort limits."""
    q, qd = joint_state(layout, obs)
    return saturate(layout, pd(jnp.asarray(cfg.kp), jnp.asarray(cfg.kd), target - q, qd))


def observation_of(foot_geom: int, m: mjx.Model, d: mjx.Data) -> Observation:
    """The controller's `Observation` of MJX data after a forward (the env steps MJX itself)."""
    return Observation(time=d.time, qpos=d.qpos, qvel=d.qvel, contact=Contact(*foot_contact(foot_geom, m, d)))


def observe(layout: Layout, cfg: MonopedConfig, obs: Observation, gravity: jax.Array,
            command: jax.Array, last_action: jax.Array) -> jax.Array:
    """The policy's input, from the robot's own signals, roughly unit-scaled: the IMU's
    orientation and rate, the odometry's height and velocity, the foot contact, the joints."""
    weight = layout.total_mass * 9.81
    q, qd = joint_state(layout, obs)
    parts = [
        obs.qpos[3:7],
        0.25 * obs.qvel[3:6],
        obs.qpos[2:3],
        obs.qvel[:3],
        obs.contact.flag[None].astype(jnp.float32),
        obs.contact.force / weight,
        q,
        0.1 * qd,
        command,
        last_action,
    ]
    if cfg.observe_gravity:
        parts.append(-gravity[2:3] / 9.81)
    return jnp.nan_to_num(jnp.concatenate(parts), posinf=0.0, neginf=0.0)


def predicted_apex(d: mjx.Data, g: jax.Array) -> jax.Array:
    """Height the base would reach on a ballistic arc from here (its current height when falling)."""
    vz = jnp.maximum(d.qvel[2], 0.0)
    return d.qpos[2] + vz**2 / (2.0 * jnp.maximum(g, 0.1))


def tilt_from_vertical(d: mjx.Data) -> jax.Array:
    """Angle (rad) between the base's z axis and the world's vertical."""
    w, x, y, _ = d.qpos[3:7]
    cos = 1.0 - 2.0 * (x * x + y * y)  # z-component of the body z axis
    return jnp.arccos(jnp.clip(cos, -1.0, 1.0))


def fallen(cfg: MonopedConfig, d: mjx.Data) -> jax.Array:
    finite = jnp.isfinite(d.qpos).all() & jnp.isfinite(d.qvel).all()
    return ~finite | (tilt_from_vertical(d) > cfg.max_tilt) | (d.qpos[2] < cfg.min_base_height)


def reward_terms(
    cfg: MonopedConfig, d: mjx.Data, g: jax.Array, command: jax.Array,
    action: jax.Array, last_action: jax.Array, effort: jax.Array, fell: jax.Array,
) -> dict[str, jax.Array]:
    """Per-step reward terms (already weighted); their sum is the reward."""
    apex_error = jnp.abs(predicted_apex(d, g) - command[0])
    speed_error = jnp.sum((d.qvel[0:2] - command[1:3]) ** 2)
    return {
        "apex": cfg.w_apex * jnp.exp(-apex_error / cfg.apex_scale),
        "speed": cfg.w_speed * jnp.exp(-speed_error / cfg.speed_scale**2),
        "upright": cfg.w_upright * jnp.exp(-((tilt_from_vertical(d) / cfg.upright_scale) ** 2)),
        "effort": -cfg.w_effort * effort,
        "action_rate": -cfg.w_action_rate * jnp.sum((action - last_action) ** 2),
        "spin": -cfg.w_spin * jnp.sum(d.qvel[3:6] ** 2),
        "fall": -cfg.fall_penalty * fell.astype(jnp.float32),
    }


def sample_command(cfg: MonopedConfig, key: jax.Array) -> jax.Array:
    """(apex height m, vx m/s, vy m/s), uniform over the configured ranges."""
    k_apex, k_speed = jax.random.split(key)
    apex = jax.random.uniform(k_apex, (1,), minval=cfg.apex_range[0], maxval=cfg.apex_range[1])
    speed = jax.random.uniform(k_speed, (2,), minval=cfg.speed_range[0], maxval=cfg.speed_range[1])
    return jnp.concatenate([apex, speed])


def training_model(mj_model: mujoco.MjModel, cfg: MonopedConfig) -> mujoco.MjModel:
    """The model the environment steps: the configured timestep, MuJoCo's sensor stage off
    (signals come from the state), the constraint solver capped at the configured iterations."""
    m = copy.deepcopy(mj_model)
    m.opt.timestep = cfg.timestep
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
    m.opt.iterations = cfg.solver_iterations
    m.opt.ls_iterations = cfg.ls_iterations
    return m


def stance_qpos(mj_model: mujoco.MjModel) -> np.ndarray:
    """The robot's standing pose with the foot on the floor; its joint angles are the
    centre of the action space."""
    return robot.stance_qpos(mj_model, clearance=0.0).astype(np.float32)


# -- the environment -------------------------------------------------------------------------


class MonopedEnv(Env):
    """One monoped under one gravity (the model's `opt.gravity`), Brax `Env` interface."""

    def __init__(self, config: MonopedConfig = MonopedConfig(), mj_model: mujoco.MjModel | None = None):
        mj_model = mj_model if mj_model is not None else hopper_model.load()
        trained = training_model(mj_model, config)
        self.config = config
        self.layout = Layout.of(trained)
        self.n_frames = decimation(self.layout, config)
        self.sys = mjx.put_model(trained)
        self._stance_qpos = stance_qpos(mj_model)  # the same pose the policy controller uses
        self.stance = self._stance_qpos[list(self.layout.joint_qpos)]

    # Brax reads these.
    @property
    def observation_size(self) -> int:
        return 21 + 3 + 3 + int(self.config.observe_gravity)

    @property
    def action_size(self) -> int:
        return 3

    @property
    def backend(self) -> str:
        return "mjx"

    @property
    def dt(self) -> float:
        return self.layout.timestep * self.n_frames

    def reset(self, rng: jax.Array) -> State:
        cfg, lay = self.config, self.layout
        k_cmd, k_lift, k_joint = jax.random.split(rng, 3)
        qpos = jnp.asarray(self._stance_qpos)
        lift = jax.random.uniform(k_lift, (), minval=cfg.initial_clearance[0], maxval=cfg.initial_clearance[1])
        joints = jnp.asarray(self.stance) + cfg.initial_joint_noise * jax.random.normal(k_joint, (3,))
        qpos = qpos.at[2].add(lift).at[jnp.asarray(lay.joint_qpos)].set(joints)
        data = mjx.forward(self.sys, mjx.make_data(self.sys).replace(qpos=qpos))
        command = sample_command(cfg, k_cmd)
        last_action = jnp.zeros(3)
        obs = observe(lay, cfg, observation_of(lay.foot_geom, self.sys, data), self.sys.opt.gravity, command,
                      last_action)
        zero = jnp.zeros(())
        metrics = {k: zero for k in reward_terms(cfg, data, zero, command, last_action, last_action, zero, zero > 0)}
        info = {"command": command, "last_action": last_action}
        return State(data, obs, zero, zero, metrics, info)

    def step(self, state: State, action: jax.Array) -> State:
        cfg, lay, m = self.config, self.layout, self.sys
        target = joint_targets(lay, cfg, jnp.asarray(self.stance), action)
        limit = jnp.asarray(lay.effort_limit)

        def physics_step(carry, _):
            d, effort = carry
            torque = pd_torque(lay, cfg, target, d)
            return (mjx.step(m, d.replace(ctrl=to_ctrl(lay, torque))), effort + jnp.mean((torque / limit) ** 2)), None

        (data, effort), _ = jax.lax.scan(physics_step, (state.pipeline_state, jnp.zeros(())), None, self.n_frames)
        g = -m.opt.gravity[2]
        fell = fallen(cfg, data)
        command, last_action = state.info["command"], state.info["last_action"]
        terms = reward_terms(cfg, data, g, command, action, last_action, effort / self.n_frames, fell)
        reward = jnp.nan_to_num(sum(terms.values()), nan=-cfg.fall_penalty)
        obs = observe(lay, cfg, observation_of(lay.foot_geom, m, data), m.opt.gravity, command, action)
        info = {**state.info, "last_action": action}
        return state.replace(pipeline_state=data, obs=obs, reward=reward, done=fell.astype(jnp.float32),
                             metrics={**state.metrics, **terms}, info=info)


def randomize_gravity(sys: mjx.Model, rng: jax.Array, gravity_range=(1.0, 12.0)):
    """Brax `randomization_fn`: one gravity magnitude per environment (rng is (N, 2)),
    log-uniform over `gravity_range` (m/s², low > 0).

    Returns the model with `opt.gravity` batched (N, 3) and the matching vmap in_axes.
    """
    log_lo, log_hi = math.log(gravity_range[0]), math.log(gravity_range[1])
    magnitude = jax.vmap(lambda k: jnp.exp(jax.random.uniform(k, (), minval=log_lo, maxval=log_hi)))(rng)
    gravity = jnp.stack([jnp.zeros_like(magnitude), jnp.zeros_like(magnitude), -magnitude], axis=1)
    batched = sys.replace(opt=sys.opt.replace(gravity=gravity))
    in_axes = jax.tree_util.tree_map(lambda _: None, sys)
    in_axes = in_axes.replace(opt=in_axes.opt.replace(gravity=0))
    return batched, in_axes
