"""The parts every monoped task shares: config, physics step, action, observation, reward kernels, termination.

A task (`hopper_mjx.envs.tasks`) is a `MonopedEnv` that says what it commands
(`sample_command`) and what it rewards (`task_terms`); everything else is here, once.

- **Physics**: `hopper_mjx.model.load()` stepped by the config's engine
  (`hopper_mjx.engine.make(config.engine, ...)`: "auto" is the chain engine for the monoped,
  "mjx" MuJoCo MJX) at the config's `timestep` (2 ms for training; the core evaluates at its
  own 1 ms); the policy acts every `n_frames` physics steps (default 50 Hz). `MonopedEnv.physics`
  is the one place the engine steps, traced once per policy step.
- **Actions** (3, in [-1, 1]) are joint position targets around the standing pose,
  `target = stance + action_scale * action`, clipped to the joint range and tracked by a PD
  law at the physics rate (`pd_torque`), saturated at the effort limits.
- **Observations** (`observe`) are what a real robot reads: the IMU, the odometry's height
  and velocity, the foot contact, the joints, the task's command and the previous action;
  gravity only when `observe_gravity` is set; on a `terrain`, the base's height over the ground at
  the height scan's points (`SCAN`, legged_gym's measured_heights).
- **Terrain** (`terrain`, a --terrain spec; "" the flat plane): one fixed ground every episode
  starts on, at the origin, as the core's instances start (train.py's --terrain check keeps it below the foot there).
- **Gravity** is drawn per episode at `reset`, log-uniformly over `gravity_range`, and kept
  in `State.info["gravity"]`; `wrappers.wrap_for_training` makes Brax's auto-reset draw a
  fresh episode (gravity, command, initial state) instead of replaying the first one.
- **Robots** (`randomize`, a `--randomize` spec): a pool of `ROBOT_POOL` robots is drawn once with
  `randomize_seed` (the model fields with MuJoCo's constants, and the control parameters: PD factors,
  dc motor figures, action and sensor delays, IMU and odometry noise and bias), and each episode runs
  one of them (`State.info["robot"]`).
- **Motors, sensors, pushes**, composed as the core composes them (`hopper_mjx.sim`), from the same
  pure pieces, at the physics rate inside `physics`, as the core runs a policy (a position controller,
  `control.base.Servo`): its joint targets go through the delay line (`actuators.Actuation`: a fixed
  `action_delay` or the robot's), the joints' drivers track them with the PD law on the joints as they
  are now, and the motors (`motor` ideal or dc) apply that torque within their envelope; the policy
  reads the sensors (`sensing.Sensing`: the robot's noise and bias on the IMU's rate and the odometry,
  its sensor delay), while the reward and the termination read the true state; every `push` interval
  the base gets a horizontal velocity change (`pushes.push`). The drive, the sensors' line and the
  episode's physics-step count live in `State.info` (`EPISODE_INFO`); a fresh episode starts its delay
  line full of the standing targets. A config that asks none of them steps today's program.

Everything is one instance; Brax's wrappers vmap it.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from brax.envs.base import Env, State

from hopper_mjx import engine as engines
from hopper_mjx import model as hopper_model
from hopper_mjx import registry
from hopper_mjx.control.base import PDScale, Servo, joint_state, pd, saturate, scaled
from hopper_mjx.hardware import signals
from hopper_mjx.hardware.actuators import Actuation, Drive, Motor
from hopper_mjx.hardware.pushes import Pushes
from hopper_mjx.hardware.sensor_noise import FIGURES, Sensing, SensorState, reading
from hopper_mjx.hardware.signals import Observation
from hopper_mjx.metrics import hops
from hopper_mjx.model import robot
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.world import EARTH_GRAVITY
from hopper_mjx.sim import per_instance
from hopper_mjx.step import Plant, actuate, advance
from hopper_mjx.terrain import scan as terrain_scan
from hopper_mjx.variation.spec import Spec

MAX_TILT_FROM_VERTICAL = 0.8  # rad between the base's z axis and the vertical that ends an episode
# State.info keys a task owns; the resampling auto-reset replaces exactly these (wrappers.py).
TASK_INFO = ("command", "gravity", "last_action", "rng")
# And these, each where the config asks for it (`MonopedEnv.task_info`): the episode's robot (randomised),
# its motors' drive (`actuators.Drive`: figures, delay line, energy; dc or delayed motors), its sensors'
# state (`sensing.SensorState`: figures and delay line; drawn sensor delay or noise), and the physics steps
# since the episode's start (pushes, sensor noise).
EPISODE_INFO = ("robot", "drive", "sense", "physics_steps")
ROBOT_POOL = 256  # robots a randomised task draws once; an episode runs one of them
EPISODE_STREAM = 2  # folded into an episode's key: the pushes' directions and the sensor noise
APEX_REWARDS = ("predicted", "flight")
# The flight apex's carry (`apex_reward="flight"`): the apex judged in stance, and the flight's highest predicted
# apex so far (NO_FLIGHT in stance), both m.
FLIGHT_INFO = ("apex", "flight_top")
NO_FLIGHT = -1e3
# flight_top through an episode's first fall, from its initial clearance: a drop is not a hop.
DROPPING = -2e3
RANGES = ("gravity_range", "apex_range", "speed_range", "lateral_speed_range", "initial_clearance", "height_band")
# Fields of configs saved before stand was redefined (its foot-support term); a policy's hopper_env.json with
# them still loads (they only shaped the reward it was trained on).
RETIRED = ("w_support", "support_scale")


@dataclasses.dataclass(frozen=True)
class MonopedConfig:
    """Everything that shapes a task; saved beside a trained policy (`to_dict`). Each task's
    `default_config()` sets its own defaults (hopper_mjx.envs.tasks)."""

    task: str = "hop"  # a policy folder saved before tasks existed is a `hop` policy
    policy_rate: float = 50.0  # Hz; the physics runs at 1 / timestep
    # m/s², per episode, log-uniform: as much experience per factor of g at the Moon end
    # (slow hops, few per episode) as at the Earth end.
    gravity_range: tuple[float, float] = (1.0, 12.0)
    observe_gravity: bool = False
    apex_range: tuple[float, float] = (1.0, 1.2)  # m, commanded base height at the top of a hop
    speed_range: tuple[float, float] = (-0.2, 0.2)  # m/s, commanded vx (and vy unless lateral_speed_range)
    lateral_speed_range: tuple[float, float] | None = None  # m/s, commanded vy; None: as speed_range
    action_scale: tuple[float, float, float] = (0.3, 0.6, 0.8)  # rad per unit action: haa, hfe, kfe
    kp: tuple[float, float, float] = (300.0, 300.0, 300.0)  # N·m/rad
    kd: tuple[float, float, float] = (6.0, 6.0, 6.0)  # N·m·s/rad
    # Reward weights (per policy step) and kernel widths.
    w_alive: float = 0.0  # per step upright (stand)
    w_height: float = 0.0  # stand: exp(-(distance of z outside height_band) / height_scale)
    # m about the standing height, stand: the base anywhere from a crouch to a small hop's apex is "up".
    height_band: tuple[float, float] = (0.0, 0.0)
    height_scale: float = 0.05  # m
    w_apex: float = 1.0
    apex_scale: float = 0.1  # m; exp(-|error| / scale)
    # What the apex kernel judges (`APEX_REWARDS`): "predicted", the ballistic apex from the state (its height
    # when falling: a hop is judged below its top all through its fall and stance); "flight", the apex of the
    # flight under way, held through the stance after it (each hop's apex, as the evaluation measures it).
    apex_reward: str = "predicted"
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
    min_base_height: float = hops.FALL_HEIGHT  # m
    initial_clearance: tuple[float, float] = (0.0, 0.1)  # m, foot above the floor at reset
    initial_joint_noise: float = 0.05  # rad
    # Training physics: a 2 ms step (half the core's cost per simulated second; a policy
    # behaves alike at 1 and 2 ms) and MuJoCo's Newton solver, warm-started, capped at
    # these iterations (the core runs to convergence; a capped solve is ~3x cheaper on CPU MJX).
    timestep: float = 0.002  # s
    solver_iterations: int = 2
    ls_iterations: int = 4
    engine: str = "auto"  # hopper_mjx.engine name: auto (chain for the monoped), chain or mjx
    robot: str = ""  # `model.robot.fingerprint` of the robot (set by the env); "" in policies saved before it
    # The robots episodes run: a --randomize spec ("" the URDF's robot), drawn once with randomize_seed.
    randomize: str = ""
    randomize_seed: int = 0
    motor: str = registry.DEFAULT_MOTOR  # a registry.MOTORS name: the joints' motors (hopper_mjx.hardware.actuators)
    action_delay: float = 0.0  # s from the PD torque to the motors', whole steps of `timestep`; a drawn one wins
    push: tuple[float, float] | None = None  # (interval s, speed m/s) of random horizontal pushes in an episode
    terrain: str = ""  # a --terrain spec with a fixed seed: the ground of every episode ("" the flat plane)

    def __post_init__(self):
        for name in RANGES:
            pair = getattr(self, name)
            if pair is None:
                continue
            lo, hi = pair
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ValueError(f"{name} must be a finite (low, high) pair with low <= high, got {(lo, hi)}")
        if not self.gravity_range[0] > 0:
            raise ValueError(f"gravity_range must be > 0 m/s² (magnitudes, drawn log-uniformly), "
                             f"got {self.gravity_range}")
        if self.apex_reward not in APEX_REWARDS:
            raise ValueError(f"apex_reward must be one of {', '.join(APEX_REWARDS)}, got {self.apex_reward!r}")
        if not (self.policy_rate > 0 and self.timestep > 0):
            raise ValueError(f"policy_rate and timestep must be positive, got {self.policy_rate}, {self.timestep}")
        engines.check_name(self.engine)
        registry.check("motor", registry.MOTORS, self.motor)
        if not (math.isfinite(self.action_delay) and self.action_delay >= 0
                and abs(self.delay_steps * self.timestep - self.action_delay) <= 1e-9):
            raise ValueError(f"action_delay must be a whole number (>= 0) of physics steps ({self.timestep * 1e3:g} "
                             f"ms), got {self.action_delay * 1e3:g} ms")
        if self.push is not None:
            Pushes.of(*self.push, self.timestep)  # raises for an interval of no whole step, a negative speed
        ground = self.ground  # raises TerrainError (a ValueError) for a bad spec
        if ground.each:
            raise ValueError(f"terrain {self.terrain!r}: training puts every episode on one ground; give a fixed seed")
        dc_only = [name for name in self.variation.controls if registry.CONTROL_PARAMETERS[name].needs == "dc"]
        if dc_only and self.motor != "dc":
            raise ValueError(f"randomize: {', '.join(dc_only)} are a dc motor's figures; set motor='dc'")

    @property
    def delay_steps(self) -> int:
        """The fixed action delay in physics steps."""
        return round(self.action_delay / self.timestep)

    @property
    def variation(self) -> Spec:
        """The robots' spec (empty: the URDF's robot); raises ValueError for a bad one."""
        return Spec.parse(self.randomize) if self.randomize else Spec()

    @property
    def ground(self):
        """The parsed `terrain` (`terrain.Ground`; FLAT for "")."""
        from hopper_mjx import terrain

        return terrain.parse(self.terrain) if self.terrain else terrain.FLAT

    @property
    def vy_range(self) -> tuple[float, float]:
        return self.speed_range if self.lateral_speed_range is None else self.lateral_speed_range

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def overridden(self, pairs: list[str], owned: dict[str, str]) -> "MonopedConfig":
        """This config with `KEY=VALUE` texts applied (a pair as `low,high`), checked whole; raises ValueError
        naming the first bad one. `owned`: fields another option sets {field: that option}, refused here."""
        fields = {f.name for f in dataclasses.fields(self)}
        changes = {}
        for pair in pairs:
            key, sep, text = pair.partition("=")
            key = key.strip()
            if not sep or key not in fields or key in ("task", "robot"):
                known = ", ".join(sorted(set(fields) - set(owned) - {"task", "robot"}))
                raise ValueError(f"{pair!r} is not KEY=VALUE with a task config field; fields: {known}")
            if key in owned:
                raise ValueError(f"{key} is set by {owned[key]}, not here")
            default = getattr(self, key)
            try:
                if isinstance(default, bool):
                    if text.lower() not in ("true", "false"):
                        raise ValueError
                    value = text.lower() == "true"
                elif isinstance(default, (int, float)):
                    value = type(default)(text)
                elif isinstance(default, str):
                    value = text
                else:  # a tuple, or a pair whose default is None: comma-separated numbers
                    value = tuple(float(v) for v in text.split(","))
                    if len(value) != (2 if default is None else len(default)):
                        raise ValueError
            except ValueError:
                raise ValueError(f"{key}={text!r}: expected {_kind(default)}") from None
            changes[key] = value
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_dict(cls, values: dict) -> "MonopedConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        values = {k: v for k, v in values.items() if k not in RETIRED}
        unknown = set(values) - known
        if unknown:
            raise ValueError(f"unknown MonopedConfig field(s): {sorted(unknown)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def _kind(default) -> str:
    if isinstance(default, bool):
        return "true or false"
    if isinstance(default, (int, float, str)):
        return f"a {type(default).__name__}"
    return f"{2 if default is None else len(default)} comma-separated numbers"


def same_robot(recorded: str, mj_model, what: str) -> str:
    """The fingerprint of `mj_model`'s robot, refusing one other than `recorded` (when recorded)."""
    found = robot.fingerprint(mj_model)
    if recorded and recorded != found:
        raise ValueError(f"{what} is for another robot (fingerprint {recorded}) than the one given ({found}): "
                         "give the --urdf it was trained with")
    return found


def steps_per_action(rate: float, timestep: float) -> int | None:
    """Whole physics steps of `timestep` s per policy step at `rate` Hz; None where the rate does not divide the
    physics rate (or is not a positive number)."""
    steps = 1.0 / (rate * timestep) if math.isfinite(rate) and rate > 0 else 0.0
    return int(round(steps)) if steps >= 1 and abs(steps - round(steps)) <= 1e-6 else None


def decimation(layout: Layout, cfg: MonopedConfig) -> int:
    """Physics steps per policy step; the policy rate must divide the physics rate."""
    steps = steps_per_action(cfg.policy_rate, layout.timestep)
    if steps is None:
        raise ValueError(f"policy_rate={cfg.policy_rate} Hz must divide the physics rate {1 / layout.timestep:g} Hz")
    return steps


def log_uniform(key: jax.Array, bounds: tuple[float, float]) -> jax.Array:
    """One draw, uniform in log: every factor of the range gets the same share."""
    lo, hi = math.log(bounds[0]), math.log(bounds[1])
    return jnp.exp(jax.random.uniform(key, (), minval=lo, maxval=hi))


def gravity_vector(magnitude: jax.Array) -> jax.Array:
    return jnp.stack([jnp.zeros_like(magnitude), jnp.zeros_like(magnitude), -magnitude])


# -- the pieces shared with the policy controller (hopper_mjx.envs.policy) ------------------


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
# The policy's height scan on a terrain, (K, 2) m in the base's yaw frame: the core's default scan (5 x 5 points
# 0.1 m apart), fixed here so that a policy reads the points it was trained on whatever scan a run records.
SCAN = terrain_scan.scan_points()


def observation_size(command_size: int, observe_gravity: bool, on_terrain: bool = False) -> int:
    """The robot's signals + the command + 3 of the previous action (+ gravity) (+ the height scan)."""
    return (sum(size for _, size in ROBOT_SIGNALS) + command_size + 3 + int(observe_gravity)
            + len(SCAN) * int(on_terrain))


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
    if cfg.terrain:  # the base's height over the ground at each scan point, from where the odometry puts it
        ground = terrain_scan.measured_heights(obs.ground.heights, obs.ground.size, obs.qpos[:3], obs.qpos[3:7],
                                               jnp.asarray(SCAN, obs.qpos.dtype))
        parts.append(obs.qpos[2] - ground)
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


def speed_term(cfg: MonopedConfig, d, command_speed: jax.Array) -> jax.Array:
    """Horizontal velocity against the commanded (vx, vy), a Gaussian kernel of width speed_scale."""
    return cfg.w_speed * jnp.exp(-jnp.sum((d.qvel[0:2] - command_speed) ** 2) / cfg.speed_scale**2)


def robot_pool(cfg: MonopedConfig, mj_model: mujoco.MjModel) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """({model field: (ROBOT_POOL, ...)}, {control parameter: (ROBOT_POOL, ...)}) of the robots a randomised
    task's episodes run: the model fields with the constants MuJoCo derives from them, the control parameters
    as `variation.draw.draw_controls` draws them (delays in ms); ({}, {}) without."""
    spec = cfg.variation
    if not spec:
        return {}, {}
    from hopper_mjx.variation import draw

    fields = draw.with_constants(mj_model, draw.draw(spec, mj_model, ROBOT_POOL, cfg.randomize_seed))
    return fields, draw.draw_controls(spec, mj_model, ROBOT_POOL, cfg.randomize_seed)


def same_ground(ground, mj_model: mujoco.MjModel, what: str):
    """(heights (nrow, ncol) float32 m, half-extents) of `mj_model`'s height field, None on its plane; refuses
    a model whose floor is not `ground` (a `terrain.Ground`)."""
    from hopper_mjx import terrain

    grid, wanted = terrain.from_model(mj_model), ground.terrain()
    same = (grid is None) == (wanted is None) and (wanted is None or (
        grid.shape == wanted.shape and np.allclose(grid.size, wanted.size)
        and np.allclose(grid.heights, wanted.heights, atol=1e-4)))
    if not same:
        raise ValueError(f"{what} is for the ground {ground}, not the model's: give --terrain {ground}")
    return None if grid is None else (jnp.asarray(grid.heights, jnp.float32), tuple(float(h) for h in grid.size))


class Episode(NamedTuple):
    """What one episode's physics carries from step to step besides the engine's data; () where the config
    adds nothing (then the step is today's)."""

    drive: Drive | tuple = ()  # the motors' figures, delay line and energy
    sense: SensorState | tuple = ()  # the sensors' figures and delay line
    steps: jax.Array | tuple = ()  # () int32, physics steps since the episode's start


def training_model(mj_model: mujoco.MjModel, cfg: MonopedConfig) -> mujoco.MjModel:
    """The model the environment steps: the configured timestep, MuJoCo's sensor stage off
    (signals come from the state), the constraint solver capped at the configured iterations."""
    m = copy.deepcopy(mj_model)
    m.opt.timestep = cfg.timestep
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
    m.opt.iterations = cfg.solver_iterations
    m.opt.ls_iterations = cfg.ls_iterations
    return m


# -- the environment -------------------------------------------------------------------------


class MonopedEnv(Env):
    """One monoped under one gravity per episode, Brax `Env` interface. Subclasses (the tasks)
    define `command_size`, `sample_command(key)` and `task_terms(data, g, command)`."""

    command_size: int = 0

    def __init__(self, config: MonopedConfig, mj_model: mujoco.MjModel | None = None):
        ground = config.ground
        mj_model = mj_model if mj_model is not None else hopper_model.load(terrain=ground.terrain())
        config = dataclasses.replace(config, robot=same_robot(config.robot, mj_model, "this task's config"))
        self.terrain = same_ground(ground, mj_model, "this task's config")
        trained = training_model(mj_model, config)
        self.config = config
        self.layout = Layout.of(trained)
        self.n_frames = decimation(self.layout, config)
        fields, controls = robot_pool(config, mj_model)
        # {model field or PD factor: (ROBOT_POOL, ...)}: {} for the URDF's robot with its own gains
        self.robots = {k: jnp.asarray(v, jnp.float32) for k, v in fields.items()} | {
            k: jnp.asarray(v, jnp.float32) for k, v in controls.items() if k in ("kp_scale", "kd_scale")}
        self.engine = engines.make(config.engine, trained, config.variation.fields)
        self.motors, self.sensors = self._robot_io(controls)
        self.pushes = None if config.push is None else Pushes.of(*config.push, self.layout.timestep)
        self.standing_qpos = robot.standing_qpos(mj_model).astype(np.float32)  # as the policy controller
        self.stance = self.standing_qpos[list(self.layout.joint_qpos)]
        self.standing_height = float(self.standing_qpos[2])

    def _robot_io(self, controls: dict) -> tuple[Motor | None, SensorState | None]:
        """Sets the static motors (`self.actuation`) and sensors (`self.sensing`) the config asks for, and
        returns the pool's motor figures and sensor figures, (P, ...) each (P = ROBOT_POOL when drawn, else 1),
        or None where they add nothing."""
        lay, step_ms = self.layout, self.layout.timestep * 1e3
        longest = lambda name: int(round(controls[name].max() / step_ms)) if name in controls else 0
        self.actuation = Actuation(lay, self.config.motor, max(self.config.delay_steps, longest("action_delay")))
        self.sensing = Sensing(longest("sensor_delay"), any(name in controls for name in FIGURES))
        drawn = per_instance(controls, self.actuation, self.sensing, lay.timestep, self.config.delay_steps)
        motors = None
        if not self.actuation.passthrough:
            motors = drawn.get("motor") or self.actuation.motor(1, delay_steps=self.config.delay_steps)
        sensors = None
        if not self.sensing.passthrough:  # the pool's figures (its line is filled at each episode's start)
            data = jax.eval_shape(self.engine.make_data, jnp.zeros(lay.nq), jnp.zeros(lay.nv))
            shapes = jax.eval_shape(lambda d: self.observe_signals(self.engine.model, d), data)
            blank = jax.tree_util.tree_map(lambda x: jnp.zeros((ROBOT_POOL, *x.shape), x.dtype), shapes)
            figures = dict(drawn["sensing"])
            sensors = self.sensing.init(blank, figures.pop("delay", 0), figures)
        return motors, sensors

    def observe_signals(self, model, data) -> Observation:
        """What a controller reads of the state (`signals.observe`), with the ground on a terrain."""
        sensed = () if self.terrain is None else (*self.terrain, jnp.asarray(SCAN, jnp.float32))
        return signals.observe(self.engine, model, data, sensed)

    @property
    def counts_steps(self) -> bool:
        """An episode counts its physics steps: the pushes' schedule and the sensor noise are keyed by them."""
        return self.pushes is not None or self.sensing.noisy

    @classmethod
    def default_config(cls) -> MonopedConfig:
        raise NotImplementedError

    def sample_command(self, key: jax.Array) -> jax.Array:
        raise NotImplementedError

    def task_terms(self, d, g: jax.Array, command: jax.Array, apex=None) -> dict[str, jax.Array]:
        raise NotImplementedError

    # Brax reads these.
    @property
    def observation_size(self) -> int:
        return observation_size(self.command_size, self.config.observe_gravity, self.terrain is not None)

    @property
    def action_size(self) -> int:
        return 3

    @property
    def backend(self) -> str:
        return self.engine.name

    @property
    def dt(self) -> float:
        return self.layout.timestep * self.n_frames

    @property
    def task_info(self) -> tuple[str, ...]:
        """The `State.info` keys a fresh episode replaces (`wrappers.ResampleAutoReset`)."""
        on = (bool(self.config.variation), self.motors is not None, self.sensors is not None, self.counts_steps)
        flight = FLIGHT_INFO if self.config.apex_reward == "flight" else ()
        return TASK_INFO + flight + tuple(k for k, used in zip(EPISODE_INFO, on) if used)

    def reward_terms(self, d, g, command, action, last_action, effort, fell, apex=None) -> dict[str, jax.Array]:
        """Per-step reward terms (already weighted); their sum is the reward. `apex`: the apex the task judges
        (m; None: `predicted_apex` of `d`)."""
        return {**self.task_terms(d, g, command, apex),
                **posture_terms(self.config, d, action, last_action, effort, fell)}

    def reset(self, rng: jax.Array) -> State:
        cfg, lay = self.config, self.layout
        rng, k_cmd, k_lift, k_joint, k_g = jax.random.split(rng, 5)
        gravity = gravity_vector(log_uniform(k_g, cfg.gravity_range))
        lift = jax.random.uniform(k_lift, (), minval=cfg.initial_clearance[0], maxval=cfg.initial_clearance[1])
        joints = jnp.asarray(self.stance) + cfg.initial_joint_noise * jax.random.normal(k_joint, (3,))
        qpos = jnp.asarray(self.standing_qpos).at[2].add(lift).at[jnp.asarray(lay.joint_qpos)].set(joints)
        # As the core's reset: no forward yet, so the first observation's contact is the engine's
        # "none yet" and the physics is traced only in `physics` (the auto-reset runs this in every step).
        data = self.engine.make_data(qpos, jnp.zeros(lay.nv, qpos.dtype))
        command = self.sample_command(k_cmd)
        last_action = jnp.zeros(3)
        info = {"command": command, "gravity": gravity, "last_action": last_action, "rng": rng}
        if cfg.apex_reward == "flight":  # no hop yet: judged at the standing height until the first lift-off
            info |= {"apex": jnp.float32(self.standing_height), "flight_top": jnp.float32(DROPPING)}
        info |= self._start_episode(rng, self.observe_signals(self.engine.model, data))
        obs = observe(lay, cfg, self.read(data, info), gravity, command, last_action)
        zero = jnp.zeros(())
        terms = self.reward_terms(data, -gravity[2], command, last_action, last_action, zero, zero > 0)
        return State(data, obs, zero, zero, {k: zero for k in terms}, info)

    def _start_episode(self, rng: jax.Array, first: Observation) -> dict:
        """The `EPISODE_INFO` of an episode from its key: its robot, its motors at rest with their delay line
        full of the standing targets, its sensors' line holding the `first` observation (read at step 0, as
        the core's), no step yet."""
        info = {}
        robot = 0
        if self.config.variation:
            robot = info["robot"] = jax.random.randint(jax.random.fold_in(rng, 1), (), 0, ROBOT_POOL)
        pick = lambda pool: jax.tree_util.tree_map(lambda x: x[robot if x.shape[0] > 1 else 0], pool)
        if self.motors is not None:
            line = jnp.tile(jnp.asarray(self.stance), (self.actuation.depth, 1))  # the standing targets
            info["drive"] = Drive(pick(self.motors), line, jnp.zeros(()))
        if self.sensors is not None:
            sense = pick(self.sensors)._replace(line=self.sensing.first(first))
            info["sense"] = self.sensing.apply(sense, first, self.episode_key(rng), jnp.zeros((), jnp.int32))[1]
        if self.counts_steps:
            info["physics_steps"] = jnp.zeros((), jnp.int32)
        return info

    @staticmethod
    def episode_key(rng: jax.Array) -> jax.Array:
        """The key of an episode's pushes and sensor noise (with the physics step's index)."""
        return jax.random.fold_in(rng, EPISODE_STREAM)

    def read(self, data, info: dict) -> Observation:
        """What the policy reads of its robot: the sensors' reading, else the state (its last contact)."""
        if self.sensors is None:
            return self.observe_signals(self.engine.model, data)
        return reading(info["sense"])

    def physics(self, model, data, gravity: jax.Array, target: jax.Array, scale: PDScale | None = None,
                episode: Episode = Episode(), key: jax.Array | None = None):
        """`n_frames` physics steps of one instance under its own gravity, the PD law tracking `target`:
        (data, mean of (torque / limit)², the episode's carry). The engine's step is traced once, in the
        loop. `scale`: the episode's robot's PD factors; `episode`: its drive, sensors and step count
        (`Episode`), `key` its `episode_key`. Each physics step is the core's (`sim`), rotated so that it
        ends on what the next one reads: the PD law, the motors, the engine; then
        the step counted, the push due, and the new state into the sensors. The joints' drivers run the PD
        law on the targets the delay line gives them and on the joints as they are now: the sensors' delay and
        noise are the policy's, not the drivers' (the core's policy controller does the same)."""
        cfg, lay = self.config, self.layout
        limit = jnp.asarray(lay.effort_limit)
        plant = Plant(self.engine, self.actuation, self.pushes, self.counts_steps)
        # The joints' drivers, as the core's policy controller's (`control.base.Servo`): the PD law on the targets
        # the delay line gives them and on the joints as they are now.
        servo = Servo(track=lambda cs, late, now: (pd_torque(lay, cfg, late, now, scale), cs), first=None)

        def one_physics_step(carry, _):
            d, effort, ep = carry
            ctrl, torque, _, drive = actuate(plant, servo, target, (), ep.drive, d, d.qvel)
            d, steps, _, _ = advance(plant, model, d, gravity, ctrl, key, ep.steps)
            ep, effort = ep._replace(drive=drive, steps=steps), effort + jnp.mean((torque / limit) ** 2)
            if self.sensors is not None:  # the new state into the sensors, as the core's next step reads it
                ep = ep._replace(sense=self.sensing.apply(ep.sense, self.observe_signals(model, d), key,
                                                          ep.steps)[1])
            return (d, effort, ep), None

        (data, effort, episode), _ = jax.lax.scan(one_physics_step, (data, jnp.zeros(()), episode), None,
                                                  self.n_frames)
        return data, effort / self.n_frames, episode

    def run_time_model(self, gravity: jax.Array):
        """The engine's model as a value known only at run time, as the core passes it (an argument
        of the compiled function): the chain engine stores each stage's outputs behind a conditional
        on it, which a compile-time constant would fold away (several times slower, and over twice the
        compile). `gravity`: one instance's (3,) or a batch's (n, 3); every episode's gravity points
        down (`gravity_range` > 0), so the selection keeps the model, but the compiler cannot know it.
        Unbatched when `gravity` is: `batch_step` hands one model to all instances."""
        downward = jnp.all(gravity[..., 2] < 0)
        return jax.tree_util.tree_map(lambda x: jnp.where(downward, x, jnp.zeros_like(x)), self.engine.model)

    def batch_step(self, state: State, action: jax.Array) -> State:
        """`step` of a batch of instances (leading axis), one run-time engine model for all, vmapped as the core
        vmaps (a stage no instance needs, the base box on a terrain, is skipped for the batch)."""
        model = self.run_time_model(state.info["gravity"])
        return jax.vmap(self.step_with, in_axes=(None, 0, 0), axis_name=engines.BATCH_AXIS)(model, state, action)

    def step(self, state: State, action: jax.Array) -> State:
        """One policy step of one instance (vmapped, prefer `batch_step`: its model stays unbatched)."""
        return self.step_with(self.run_time_model(state.info["gravity"]), state, action)

    def step_with(self, model, state: State, action: jax.Array) -> State:
        """`step` with the engine's model pytree given: the physics, then `after_physics`."""
        info, scale = state.info, None
        if self.robots:  # the episode's robot: its model and PD factors
            k = info["robot"]
            model = self.engine.vary(model, {f: v[k] for f, v in self.robots.items() if f in self.engine.varies})
            pick = lambda name: self.robots[name][k] if name in self.robots else None
            scale = None if pick("kp_scale") is None and pick("kd_scale") is None else PDScale(
                *(jnp.ones(3) if v is None else v for v in (pick("kp_scale"), pick("kd_scale"))))
        episode = Episode(*(info.get(name, ()) for name in ("drive", "sense", "physics_steps")))
        key = self.episode_key(info["rng"]) if self.counts_steps else None
        data, effort, episode = self.physics(model, state.pipeline_state, info["gravity"], self.targets(action),
                                             scale, episode, key)
        carried = {name: value for name, value in zip(("drive", "sense", "physics_steps"), episode) if name in info}
        if carried:
            state = state.replace(info={**info, **carried})
        return self.after_physics(model, state, action, data, effort)

    def targets(self, action: jax.Array) -> jax.Array:
        """The joint targets (rad) an action sets for the next policy step."""
        return joint_targets(self.layout, self.config, jnp.asarray(self.stance), action)

    def after_physics(self, model, state: State, action: jax.Array, data, effort: jax.Array) -> State:
        """The state after `action`, given the physics' result: reward, termination, observation.
        Every task shares `physics`; this is where they differ."""
        cfg, lay, gravity = self.config, self.layout, state.info["gravity"]
        fell = fallen(cfg, data)
        command, last_action, info = state.info["command"], state.info["last_action"], state.info
        apex = None
        if cfg.apex_reward == "flight":  # the true contact, as the reward reads the true state
            flying = ~signals.contact(self.engine, model, data).flag
            apex, carried = flight_apex(predicted_apex(data, -gravity[2]), flying, info)
            info = {**info, **carried}
        terms = self.reward_terms(data, -gravity[2], command, action, last_action, effort, fell, apex)
        reward = jnp.nan_to_num(sum(terms.values()), nan=-cfg.fall_penalty)
        # The sensors' reading, or the state with the contact of the last forward, as the core's controllers see it.
        sensed = self.observe_signals(model, data) if self.sensors is None else reading(state.info["sense"])
        obs = observe(lay, cfg, sensed, gravity, command, action)
        info = {**info, "last_action": action}
        return state.replace(pipeline_state=data, obs=obs, reward=reward, done=fell.astype(jnp.float32),
                             metrics={**state.metrics, **terms}, info=info)
