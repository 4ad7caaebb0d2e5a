"""The environment every monoped task is (`MonopedEnv`, Brax's `Env`): reset, the policy step, the episode's robot,
motors, sensors and pushes. Its configuration is `task_config.MonopedConfig`; its action, observation, reward and
termination kernels are `terms`; its physics step is the core's (`hopper_mjx.step`).

A task (`hopper_mjx.envs.tasks`) is a `MonopedEnv` that says what it commands
(`sample_command`) and what it rewards (`task_terms`); everything else is shared, once.

- **Physics**: `hopper_mjx.model.load()` stepped by the config's engine
  (`hopper_mjx.engine.make(config.engine, ...)`: "auto" is the chain engine for the monoped,
  "mjx" MuJoCo MJX) at the config's `timestep` (training's default is the core's 1 ms; a coarser step is
  the config's to choose); the policy acts every `n_frames` physics steps (default 50 Hz). `MonopedEnv.physics`
  is the one place the env steps the physics, through the core's step (`hopper_mjx.step`), traced once per
  policy step.
- **Actions** (3, in [-1, 1]) are joint position targets around the standing pose,
  `target = stance + action_scale * action`, clipped to the joint range and tracked by a PD
  law at the physics rate (`pd_torque`), saturated at the effort limits.
- **Observations** (`observe`) are what a real robot reads: the IMU, the odometry's height
  and velocity, the foot contact, the joints, the task's command and the previous action;
  gravity only when `observe_gravity` is set; on a `terrain`, the base's height over the ground at
  the height scan's points (the config's `scan`, legged_gym's measured_heights).
- **Terrain** (`terrain`, a --terrain spec; "" the flat plane): one fixed ground every episode
  starts on, at the origin, as the core's instances start (train.py's --terrain check keeps it below the foot there);
  on a `course`, each episode starts on a tile of its curriculum level instead (`envs.curriculum`).
- **Gravity** is drawn per episode at `reset`, log-uniformly over `gravity_range`, and kept
  in `State.info["gravity"]`; `wrappers.wrap_for_training` makes Brax's auto-reset draw a
  fresh episode (gravity, command, initial state) instead of replaying the first one.
- **Robots** (`randomize`, a `--randomize` spec): a pool of `ROBOT_POOL` robots is drawn once with
  `randomize_seed` (the model fields with MuJoCo's constants, and the control parameters: PD factors,
  dc motor figures, action and sensor delays, IMU and odometry noise and bias), and each episode runs
  one of them (`State.info["robot"]`).
- **Motors, sensors, pushes**, through the core's own step (`hopper_mjx.step`: `actuate`, `advance`), at the physics
  rate inside `physics`, as the core runs a policy (a position controller, `control.base.Servo`): its joint targets
  go through the delay line (`actuators.Actuation`: a fixed `action_delay` or the robot's), the joints' drivers
  track them with the PD law on the joints as they are now, and the motors (`motor` ideal or dc) apply that torque
  within their envelope; the policy reads the sensors (`sensor_noise.Sensing`: the robot's noise and bias on the
  IMU's rate and the odometry, its sensor delay), while the reward and the termination read the true state; every
  `push` interval the base gets a horizontal velocity change (`pushes.push`). The drive, the sensors' line and the
  episode's physics-step count live in `State.info` (`EPISODE_INFO`); a fresh episode starts its delay line full of
  the standing targets. A config that asks none of them steps today's program.

Everything is one instance; Brax's wrappers vmap it.
"""

from __future__ import annotations

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
from hopper_mjx.control import kinematics
from hopper_mjx.control.base import PDScale, Servo
from hopper_mjx.envs.curriculum import Curriculum
from hopper_mjx.envs.task_config import MonopedConfig, decimation, training_model
from hopper_mjx.envs.terms import (
    DROPPING,
    FLIGHT_INFO,
    clearance_term,
    fallen,
    flight_apex,
    joint_targets,
    observation_size,
    observe,
    pd_torque,
    posture_terms,
    predicted_apex,
)
from hopper_mjx.hardware import rotation, signals
from hopper_mjx.hardware.actuators import Actuation, Drive, Motor
from hopper_mjx.hardware.pushes import Pushes
from hopper_mjx.hardware.sensor_noise import FIGURES, Sensing, SensorState, reading
from hopper_mjx.hardware.signals import Observation
from hopper_mjx.model import robot
from hopper_mjx.model.layout import Layout
from hopper_mjx.sim import per_instance
from hopper_mjx.step import Plant, actuate, advance
from hopper_mjx.terrain import scan as terrain_scan

# State.info keys a task owns; the resampling auto-reset replaces exactly these (wrappers.py).
TASK_INFO = ("command", "gravity", "last_action", "rng")
# And these, each where the config asks for it (`MonopedEnv.task_info`): the episode's robot (randomised),
# its motors' drive (`actuators.Drive`: figures, delay line, energy; dc or delayed motors), its sensors'
# state (`sensing.SensorState`: figures and delay line; drawn sensor delay or noise), and the physics steps
# since the episode's start (pushes, sensor noise).
EPISODE_INFO = ("robot", "drive", "sense", "physics_steps")
LEVEL_METRIC = "level"  # on a course: the episode's curriculum level (`MonopedEnv._course_metrics`)
ROBOT_POOL = 256  # robots a randomised task draws once; an episode runs one of them
EPISODE_STREAM = 2  # folded into an episode's key: the pushes' directions and the sensor noise


def log_uniform(key: jax.Array, bounds: tuple[float, float]) -> jax.Array:
    """One draw, uniform in log: every factor of the range gets the same share."""
    lo, hi = math.log(bounds[0]), math.log(bounds[1])
    return jnp.exp(jax.random.uniform(key, (), minval=lo, maxval=hi))


def gravity_vector(magnitude: jax.Array) -> jax.Array:
    return jnp.stack([jnp.zeros_like(magnitude), jnp.zeros_like(magnitude), -magnitude])


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


# -- the environment -------------------------------------------------------------------------


class MonopedEnv(Env):
    """One monoped under one gravity per episode, Brax `Env` interface. Subclasses (the tasks)
    define `command_size`, `sample_command(key)` and `task_terms(data, g, command)`."""

    command_size: int = 0

    def __init__(self, config: MonopedConfig, mj_model: mujoco.MjModel | None = None):
        ground = config.ground
        if mj_model is None:  # a config names no URDF: the shipped robot, held to the config's fingerprint below
            mj_model = hopper_model.load(hopper_model.DEFAULT_URDF, terrain=ground.terrain())
        config = dataclasses.replace(config, robot=robot.same_robot(config.robot, mj_model, "this task's config"))
        self.terrain = same_ground(ground, mj_model, "this task's config")
        self.curriculum = Curriculum.of(ground)  # None but on a course: every episode starts at the origin
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
        self.leg = robot.LegGeometry.of(mj_model) if config.w_clearance else None  # the foot's clearance

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
        sensed = () if self.terrain is None else (*self.terrain, jnp.asarray(self.config.scan, jnp.float32))
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
        return observation_size(self.command_size, self.config.observe_gravity, self.config.scan_size)

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
        course = () if self.curriculum is None else ("level", "start")
        return TASK_INFO + flight + course + tuple(k for k, used in zip(EPISODE_INFO, on) if used)

    def reward_terms(self, d, g, command, action, last_action, effort, fell, apex=None,
                     clearance=None) -> dict[str, jax.Array]:
        """Per-step reward terms (already weighted); their sum is the reward. `apex`: the apex the task judges
        (m; None: `predicted_apex` of `d`); `clearance`: (the foot's clearance m, flying), None at reset."""
        terms = {**self.task_terms(d, g, command, apex),
                 **posture_terms(self.config, d, action, last_action, effort, fell)}
        if self.config.w_clearance:
            terms["clearance"] = jnp.zeros(()) if clearance is None else clearance_term(self.config, *clearance)
        return terms

    def foot_clearance(self, d) -> jax.Array:
        """The foot's bottom over the ground under its centre (m), from the joint angles and the base's pose: the
        highest ground the centre passes over within `clearance_lookahead` s at the base's horizontal velocity."""
        leg, q = self.leg, d.qpos[jnp.asarray(self.layout.joint_qpos)]
        foot = d.qpos[:3] + rotation.rotate(kinematics.from_base(leg, kinematics.foot_position(leg, q)), d.qpos[3:7])
        if self.terrain is None:
            return foot[2] - leg.foot_radius
        ahead = self.config.clearance_lookahead
        # the foot's path at the base's velocity, every 10 ms: a face 1 m/s brings on is sampled every cm
        times = jnp.linspace(0.0, ahead, 1 + math.ceil(ahead / 0.01))[:, None]
        path = foot[:2] + times * d.qvel[:2]
        ground = jnp.max(terrain_scan.height_at(*self.terrain, path[:, 0], path[:, 1]))
        return foot[2] - leg.foot_radius - ground

    def reset(self, rng: jax.Array) -> State:
        return self.reset_at(rng)

    def reset_at(self, rng: jax.Array, level: jax.Array | None = None) -> State:
        """A fresh episode from `rng`; on a course, on a tile of `level` (None: a first episode's draw)."""
        cfg, lay = self.config, self.layout
        rng, k_cmd, k_lift, k_joint, k_g = jax.random.split(rng, 5)
        gravity = gravity_vector(log_uniform(k_g, cfg.gravity_range))
        lift = jax.random.uniform(k_lift, (), minval=cfg.initial_clearance[0], maxval=cfg.initial_clearance[1])
        joints = jnp.asarray(self.stance) + cfg.initial_joint_noise * jax.random.normal(k_joint, (3,))
        qpos = jnp.asarray(self.standing_qpos).at[2].add(lift).at[jnp.asarray(lay.joint_qpos)].set(joints)
        course = {}
        if self.curriculum is not None:  # on its level's tile's pad, at z = 0 as the origin is
            course["level"] = self.curriculum.first(rng) if level is None else level
            course["start"] = self.curriculum.start(course["level"], rng)
            qpos = qpos.at[:2].set(course["start"])
        # As the core's reset: no forward yet, so the first observation's contact is the engine's
        # "none yet" and the physics is traced only in `physics` (the auto-reset runs this in every step).
        data = self.engine.make_data(qpos, jnp.zeros(lay.nv, qpos.dtype))
        command = self.sample_command(k_cmd)
        last_action = jnp.zeros(3)
        info = {"command": command, "gravity": gravity, "last_action": last_action, "rng": rng, **course}
        if cfg.apex_reward == "flight":  # no hop yet: judged at the standing height until the first lift-off
            info |= {"apex": jnp.float32(self.standing_height), "flight_top": jnp.float32(DROPPING)}
        info |= self._start_episode(rng, self.observe_signals(self.engine.model, data))
        obs = observe(lay, cfg, self.read(data, info), gravity, command, last_action)
        zero = jnp.zeros(())
        terms = self.reward_terms(data, -gravity[2], command, last_action, last_action, zero, zero > 0)
        return State(data, obs, zero, zero, {k: zero for k in terms} | self._course_metrics(info), info)

    def _course_metrics(self, info: dict) -> dict:
        """On a course, the episode's curriculum level as a metric. Brax's training log keeps each metric's sum
        over a finished episode (here its level times its length) beside the episode's length; the loop divides
        one by the other, so that its level is the mean over env steps, not over episodes, where short falls would
        count as much as whole episodes (a `_per_step` name would have Brax divide each episode's alone)."""
        return {} if self.curriculum is None else {LEVEL_METRIC: info["level"].astype(jnp.float32)}

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
        apex = clearance = None
        if cfg.apex_reward == "flight" or cfg.w_clearance:  # the true contact, as the reward reads the true state
            flying = ~signals.contact(self.engine, model, data).flag
        if cfg.apex_reward == "flight":
            apex, carried = flight_apex(predicted_apex(data, -gravity[2]), flying, info)
            info = {**info, **carried}
        if cfg.w_clearance:
            clearance = (self.foot_clearance(data), flying)
        terms = self.reward_terms(data, -gravity[2], command, action, last_action, effort, fell, apex, clearance)
        reward = jnp.nan_to_num(sum(terms.values()), nan=-cfg.fall_penalty)
        # The sensors' reading, or the state with the contact of the last forward, as the core's controllers see it.
        sensed = self.observe_signals(model, data) if self.sensors is None else reading(state.info["sense"])
        obs = observe(lay, cfg, sensed, gravity, command, action)
        info = {**info, "last_action": action}
        return state.replace(pipeline_state=data, obs=obs, reward=reward, done=fell.astype(jnp.float32),
                             metrics={**state.metrics, **terms, **self._course_metrics(info)}, info=info)
