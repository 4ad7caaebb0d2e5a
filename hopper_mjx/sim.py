"""The batched core: N monopeds, each under its own gravity, stepped by an engine.

    sim = Sim(model.load())                       # engine="auto": the best engine for the model
    state = sim.reset(gravity_vectors(...), key=0)
    state, traj = sim.rollout(state, controller, steps=2000)
    final, traj = sim.run(gravity_vectors(...), controller, params, duration=2.0)   # the one batch-run path

Batching is laid out for CPU hosts: the instance axis is sharded over every
local device with `shard_map` (XLA does not spread these small ops over cores
by itself), and on each device the instances are processed in chunks with
`lax.map`, each chunk a `vmap` over instances of a `lax.scan` over time (a
plain `vmap` over >= 1024 instances was seen to deadlock XLA's CPU runtime on
jax 0.10.2). The batch is padded to a whole number of chunks per device.
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from hopper_mjx import engine as engines
from hopper_mjx import registry
from hopper_mjx.control.base import Controller, CState, zero_torque
from hopper_mjx.hardware import signals
from hopper_mjx.hardware.actuators import Actuation, Drive, Motor
from hopper_mjx.hardware.pushes import Pushes
from hopper_mjx.hardware.sensor_noise import FIGURES, Sensing, SensorState
from hopper_mjx.model import world
from hopper_mjx.model.robot import Robot
from hopper_mjx.shell import budget, programs
from hopper_mjx.step import Plant, actuate, advance
from hopper_mjx.terrain import from_model
from hopper_mjx.variation import draw

gravity_vectors = world.gravity_vectors  # the gravity convention lives beside the world files

AXIS = "instances"

class State(NamedTuple):
    """The batch's state; every leaf has the instance axis first."""

    data: Any  # the engine's data (mjx.Data for "mjx"), every leaf batched
    gravity: jax.Array  # (N, 3) m/s², world frame
    key: jax.Array  # (N, 2) uint32, per-instance PRNG key for sensor noise
    cstate: CState  # the controller's state (with its per-instance parameters)
    diverged: jax.Array  # (N,) bool, the instance's state went non-finite
    drive: Drive | tuple = ()  # the motors' figures and state (hopper_mjx.hardware.actuators); () for ideal motors
    step: jax.Array | tuple = ()  # (N,) int32 physics steps taken, for the pushes and sensor noise; () without
    sense: SensorState | tuple = ()  # sensor figures, delay line (hopper_mjx.hardware.sensor_noise); () if exact
    # Model field -> (N, ...) values of each instance's robot (`variation.draw`); empty: every instance is
    # the nominal robot, and the compiled step is the one without variation.
    variation: dict = {}
    # (N, nrow, ncol) m: each instance's own ground on the model's height-field grid; (): every instance on
    # the model's own ground (the plane, or its height field).
    ground: jax.Array | tuple = ()


class Trajectory(NamedTuple):
    """Recorded streams, each (N, T_stream, ...) with its own time axis (s)."""

    imu: signals.Imu
    odom: signals.Odometry
    contact: signals.Contact
    qpos: jax.Array
    qvel: jax.Array
    time: dict  # stream name -> (T_stream,) seconds
    ground: signals.GroundTrace | tuple = ()  # on a height field, at the contact stream's rate; () on the plane
    # (N, T_state, 3) N·m, joint order: the torque each joint's motor applied at the state samples (after the
    # delay line, the motors' envelope and the actuators' control range); () where `SensorConfig.torque` is off.
    torque: jax.Array | tuple = ()


def split_rollout_key(key: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(this rollout's noise key, the next rollout's key) from an instance's key: the noise
    draws from the first only, so the second was never used."""
    noise, following = jax.random.split(key)
    return noise, following


def steps_for(duration: float, timestep: float, sensors: signals.SensorConfig) -> int:
    """Physics steps closest to `duration` s that hold a whole number of every stream's period (at least one)."""
    return budget.whole_steps(duration, timestep, sensors.whole(timestep))


def _check_gravity(gravity) -> np.ndarray:
    g = np.asarray(gravity, dtype=float)
    if g.ndim != 2 or g.shape[1] != 3:
        raise ValueError(f"gravity must be (N, 3) vectors, got shape {g.shape} (gravity_vectors makes them)")
    if g.shape[0] == 0:
        raise ValueError("N=0: need at least one instance")
    if not np.all(np.isfinite(g)):
        raise ValueError("gravity contains NaN or infinite values")
    if np.any(g[:, 2] > 0):
        raise ValueError(f"gravity must not point up (g_z > 0): {g[g[:, 2] > 0][:3].tolist()}")
    return g


def _per_instance(name: str, values, n: int, size: int) -> np.ndarray:
    """`values` as (n, size) float32: one row for every instance, or one per instance."""
    values = np.asarray(values, dtype=np.float32)
    if values.shape not in ((size,), (n, size)):
        raise ValueError(f"{name} must be ({size},) or (N, {size}) with N = {n} instances, got shape {values.shape}")
    return np.broadcast_to(values, (n, size))


def _check_params(params, n: int) -> None:
    """Per-instance controller parameters have N = len(gravity) rows: vmap's own error for a mismatch named no
    argument ("inconsistent sizes for array axes")."""
    rows = {np.shape(leaf)[0] if np.ndim(leaf) else 0 for leaf in jax.tree_util.tree_leaves(params)}
    if rows - {n}:
        raise ValueError(f"controller params hold {', '.join(map(str, sorted(rows)))} instances (their leading axis) "
                         f"where the gravity holds {n}: make them for {n} (e.g. control.make(name, robot, {n}))")


class Sim:
    """A compiled monoped model batched over instances and local devices."""

    def __init__(self, mj_model: mujoco.MjModel, *, engine: str = "auto", chunk: int = 256, devices=None,
                 motor: str = registry.DEFAULT_MOTOR, delay_steps: int = 0, pushes: Pushes | None = None,
                 varies: frozenset[str] = frozenset(), max_delay: int | None = None,
                 sensing: Sensing | None = None):
        """motor: a registry.MOTORS name; delay_steps: every instance's action delay by default;
        max_delay: the longest one a batch may be given (`reset(motor=...)`; default delay_steps);
        pushes: random pushes during runs; varies: the model fields a variation may set per instance
        (`reset(..., variation=)`), so that the engine is one that takes them at run time; sensing: the
        sensors' delay line and noise (`reset(..., sensing=)`; default exact and prompt)."""
        if chunk < 1:
            raise ValueError("chunk must be >= 1")
        self.mj_model = mj_model
        self.robot = Robot.of(mj_model)  # the robot facts, measured once and passed down
        self.layout = self.robot.layout
        self.engine = engines.make(engine, mj_model, frozenset(varies))
        self.actuation = Actuation(self.layout, motor, max(delay_steps, max_delay or 0))
        self.delay_steps = delay_steps
        self.pushes = pushes
        self.sensing = sensing or Sensing()
        self.devices = tuple(devices or jax.local_devices())
        self.mesh = Mesh(np.array(self.devices), (AXIS,))
        self.model = jax.device_put(self.engine.model, NamedSharding(self.mesh, PartitionSpec()))
        self.terrain = from_model(mj_model)  # the height field's grid, or None on the plane
        # The model's own heights as the engine holds them (float32), what the scan reads by default.
        self.heights = () if self.terrain is None else jax.device_put(
            jnp.asarray(self.terrain.heights, jnp.float32), NamedSharding(self.mesh, PartitionSpec()))
        self.chunk = chunk
        self._compiled = {}
        self._starts = {}  # (controller, shared params) -> the jitted start of `reset`
        # Padded and laid over the devices in one program (device_put compiled one per leaf, in every process).
        self._lay_out = jax.jit(_padded, static_argnums=1, out_shardings=NamedSharding(self.mesh, PartitionSpec(AXIS)))
        self.limp = zero_torque(self.layout)  # the default controller, one object so one compile

    # -- state ----------------------------------------------------------------
    def reset(
        self,
        gravity,
        *,
        key: int | jax.Array = 0,
        controller: Controller | None = None,
        params: Any = None,
        qpos=None,
        qvel=None,
        motor: Motor | None = None,
        variation: dict | None = None,
        sensing: dict | None = None,
        ground=None,
    ) -> State:
        """Initial state for N = len(gravity) instances.

        gravity: (N, 3) m/s²; qpos/qvel: (nq,) or (N, nq) / (nv,) or (N, nv),
        default the robot's stance (upright at rest, the foot `model.robot.CLEARANCE`
        above the floor; each instance's own when the variation moves the leg's geometry);
        params: per-instance controller parameters (leading axis N) or None;
        motor: per-instance motor figures (`self.actuation.motor(N, ...)`), default the URDF's
        with the Sim's delay; variation: {model field: (N, ...)} of each instance's robot
        (`variation.draw.with_constants`); sensing: {"delay": (N,) steps, and `sensing.FIGURES`}
        of each instance's sensors (default prompt and exact); ground: (N, nrow, ncol) m, each instance's
        heights on the model's height-field grid (default: the model's own ground for every instance).
        """
        g = _check_gravity(gravity)
        n = g.shape[0]
        _check_params(params, n)
        own = None if qpos is not None or not variation else draw.stances(self.mj_model, variation)
        variation = self._check_variation(variation or {}, n)
        ground = () if ground is None else self._check_ground(ground, n)
        qpos = (self.robot.stance_qpos if own is None else own) if qpos is None else qpos
        qvel = np.zeros(self.layout.nv) if qvel is None else qvel
        qpos, qvel = _per_instance("qpos", qpos, n, self.layout.nq), _per_instance("qvel", qvel, n, self.layout.nv)
        if not (np.isfinite(qpos).all() and np.isfinite(qvel).all()):
            raise ValueError("initial qpos/qvel must be finite")
        if not isinstance(key, jax.Array):
            if not isinstance(key, (int, np.integer)) or isinstance(key, bool):
                raise ValueError(f"key must be an int seed or a JAX PRNG key, got {key!r}")
            key = jax.random.PRNGKey(key)
        controller = controller or self.limp
        data, obs, cstate = self._start(controller, params is None)(qpos, qvel, ground, params)
        if motor is None and not self.actuation.passthrough:
            motor = self.actuation.motor(n, delay_steps=self.delay_steps)
        sensing = dict(sensing or {})
        if sensing and self.sensing.passthrough:
            raise ValueError("per-instance sensors need a Sim made with sensing=Sensing(...)")
        sense = () if self.sensing.passthrough else self.sensing.init(obs, sensing.pop("delay", 0), sensing)
        drive = () if motor is None else self.actuation.init(motor)
        if drive and controller.servo is not None:  # a delay line of targets starts full of the first ones
            first = jax.vmap(controller.servo.first)(cstate)
            drive = drive._replace(line=jnp.repeat(first[:, None], self.actuation.depth, axis=1))
        return State(
            data=data,
            gravity=jnp.asarray(g, dtype=jnp.float32),
            key=jax.random.split(key, n),
            cstate=cstate,
            diverged=jnp.zeros(n, dtype=bool),
            drive=drive,
            step=jnp.zeros(n, jnp.int32) if self.counts_steps else (),
            variation=variation,
            sense=sense,
            ground=ground,
        )

    @property
    def counts_steps(self) -> bool:
        """The state counts its steps: the pushes' schedule and the sensors' noise are keyed by them."""
        return self.pushes is not None or self.sensing.noisy

    def per_instance(self, controls: dict) -> dict:
        """`reset`'s motor= and sensing= for each instance's drawn control parameters (`per_instance`)."""
        return per_instance(controls, self.actuation, self.sensing, self.layout.timestep, self.delay_steps)

    def _start(self, controller: Controller, shared_params: bool):
        """The initial data, first observation and controller state from (qpos, qvel, ground, params): one
        program per controller (run eagerly, they were some 30 small programs, each compiled in every process)."""
        key = (controller, shared_params)
        if key not in self._starts:
            def start(qpos, qvel, ground, params):
                data = jax.vmap(self.engine.make_data)(qpos, qvel)
                obs = self._first_observation(data, ground)
                return data, obs, jax.vmap(controller.init, in_axes=(0, None if shared_params else 0))(obs, params)

            self._starts[key] = jax.jit(start)
        return self._starts[key]

    def _first_observation(self, data, ground):
        """What each controller's `init` reads: the observation at the start, on the instance's ground."""
        observe = lambda d, sensed: signals.observe(self.engine, self.engine.model, d, sensed)
        if self.terrain is None:
            return jax.vmap(lambda d: observe(d, ()))(data)
        points = jnp.asarray(signals.SensorConfig().scan_points(), jnp.float32)  # init reads the heights, not a scan
        # On one device, as `data` is (`self.heights` is laid over the mesh, for the compiled rollout).
        heights = ground if isinstance(ground, jax.Array) else jnp.asarray(self.terrain.heights, jnp.float32)
        axis = 0 if isinstance(ground, jax.Array) else None
        return jax.vmap(lambda d, h: observe(d, (h, self.terrain.size, points)), in_axes=(0, axis))(data, heights)

    def _check_ground(self, heights, n: int) -> jax.Array:
        if self.terrain is None:
            raise ValueError("a per-instance ground needs a model on a height field (a --terrain other than flat)")
        heights = np.asarray(heights, dtype=np.float32)
        if heights.shape != (n, *self.terrain.shape):
            raise ValueError(f"ground must be {(n, *self.terrain.shape)} heights, got {heights.shape}")
        if not np.isfinite(heights).all():
            raise ValueError("ground heights must be finite")
        return jnp.asarray(heights)

    def _check_variation(self, variation: dict, n: int) -> dict:
        """The per-instance fields checked, as float32 arrays (like the rest of the state), each (n, *field shape)."""
        out = {}
        for field, values in variation.items():
            if field not in self.engine.varies:
                raise ValueError(f"this batch's engine cannot vary {field} per instance")
            nominal = np.shape(getattr(self.mj_model, field))
            values = np.asarray(values)
            if values.shape != (n, *nominal):
                raise ValueError(f"variation {field} must be {(n, *nominal)}, got {values.shape}")
            if not np.isfinite(values).all():
                raise ValueError(f"variation {field} must be finite")
            out[field] = jnp.asarray(values, dtype=jnp.float32)
        return out

    # -- rollout --------------------------------------------------------------
    def rollout(
        self,
        state: State,
        controller: Controller | None = None,
        *,
        steps: int,
        sensors: signals.SensorConfig = signals.SensorConfig(),
    ) -> tuple[State, Trajectory]:
        """Steps every instance `steps` times with `controller` inside the compiled loop.

        Records each stream at its own rate; the first sample is the initial
        state (t = state time). `steps` must be a multiple of every stream period.
        """
        controller = controller or self.limp
        periods = sensors.periods(self.layout.timestep)
        fn, args = self._program(state, controller, steps, sensors)
        final, traj = fn(*args)
        n = state.gravity.shape[0]
        if n < args[2].gravity.shape[0]:  # one program for every leaf (eagerly, each slice would compile its own)
            final, traj = _head((final, traj), n)
        t0 = float(state.data.time[0])
        dt = self.layout.timestep
        times = {k: t0 + dt * np.arange(0, steps, p) for k, p in periods.items()}
        return final, Trajectory(*traj[:5], time=times, ground=traj[5], torque=traj[6])

    def rollout_program(self, state: State, controller: Controller | None = None, *, steps: int,
                        sensors: signals.SensorConfig = signals.SensorConfig()):
        """The program `rollout` runs for these arguments, lowered (`jax.stages.Lowered`): its `.compile()` is
        the one `rollout` compiled, read back from the compile cache; `perf.kernels` counts its kernels."""
        fn, args = self._program(state, controller or self.limp, steps, sensors)
        return fn.lower(*args)

    def _program(self, state: State, controller: Controller, steps: int, sensors: signals.SensorConfig):
        """The compiled rollout for `steps` of `controller` recording `sensors`, and its arguments: the state padded
        to whole chunks on every device."""
        periods = sensors.periods(self.layout.timestep)
        tick = math.gcd(*periods.values())
        if steps < 1 or any(steps % p for p in periods.values()):
            raise ValueError(f"steps={steps} must be a positive multiple of the stream periods {periods}")
        per_device = -(-state.gravity.shape[0] // len(self.devices))
        chunk = min(self.chunk, per_device)
        padded = -(-per_device // chunk) * chunk * len(self.devices)
        fn = self._compiled_rollout(controller, steps, tick, periods, sensors, chunk)
        return fn, (self.model, self.heights, self._lay_out(state, padded), controller.weights)

    def run(
        self,
        gravity,
        controller: Controller | None = None,
        params: Any = None,
        *,
        duration: float,
        sensors: signals.SensorConfig = signals.SensorConfig(),
        key: int | jax.Array = 0,
        qpos=None,
        qvel=None,
        motor: Motor | None = None,
        variation: dict | None = None,
        sensing: dict | None = None,
        ground=None,
    ) -> tuple[State, Trajectory]:
        """The batch-run path of every tool: N = len(gravity) instances from `reset` for
        `duration` s, rounded to whole periods of every stream (`steps_for`)."""
        if not (math.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be > 0 s, got {duration}")
        state = self.reset(gravity, key=key, controller=controller, params=params, qpos=qpos, qvel=qvel,
                           motor=motor, variation=variation, sensing=sensing, ground=ground)
        steps = steps_for(duration, self.layout.timestep, sensors)
        return self.rollout(state, controller, steps=steps, sensors=sensors)

    def _compiled_rollout(self, controller, steps, tick, periods, sensors, chunk):
        # tick and periods follow from sensors; a controller with weights compiles once for every set of them
        program = controller if controller.act_with is None else controller.act_with
        cache_key = (program, steps, sensors, chunk)
        if cache_key not in self._compiled:
            one = _instance_rollout(self.engine, self.actuation, self.pushes, self.sensing, controller, steps, tick,
                                    periods, sensors, self.terrain, self.mj_model)

            def per_device(model, heights, state, weights):
                n_local = state.gravity.shape[0]
                chunks = jax.tree_util.tree_map(
                    lambda x: x.reshape((n_local // chunk, chunk) + x.shape[1:]), state
                )
                out = jax.lax.map(jax.vmap(lambda s: one(model, heights, s, weights), axis_name=engines.BATCH_AXIS),
                                  chunks)
                return jax.tree_util.tree_map(lambda x: x.reshape((n_local,) + x.shape[2:]), out)

            sharded = jax.shard_map(
                per_device,
                mesh=self.mesh,
                in_specs=(PartitionSpec(), PartitionSpec(), PartitionSpec(AXIS), PartitionSpec()),
                out_specs=PartitionSpec(AXIS),
                check_vma=False,
            )
            options = self.engine.compiler_options if all(d.platform == "cpu" for d in self.devices) else None
            if controller.key is None:  # it cannot say what it closed over: traced in this process
                self._compiled[cache_key] = jax.jit(sharded, compiler_options=options)
            else:  # traced once per configuration, then read back by later processes (`shell.programs`)
                self._compiled[cache_key] = programs.Stored(sharded, self._program_key(controller, steps, sensors,
                                                                                       chunk), options)
        return self._compiled[cache_key]

    def _program_key(self, controller, steps, sensors, chunk) -> str:
        """Everything a rollout's trace closes over besides its arguments: the model (every number), the engine
        made from it, the motors, pushes and sensors, the controller's own key, the steps and the record."""
        return repr((programs.model_digest(self.mj_model), self.engine.program_key(), self.actuation.kind,
                     self.actuation.depth, self.pushes, self.sensing.depth, self.sensing.noisy, controller.key, steps,
                     sensors.key(), chunk))


def per_instance(controls: dict, actuation: Actuation, sensing: Sensing, timestep: float, delay_steps: int = 0) -> dict:
    """{"motor": `Motor`, "sensing": {"delay": steps, `sensing.FIGURES`...}} of N instances' drawn control
    parameters ({name: (N, ...)}, `variation.draw.draw_controls`; delays in ms, to whole steps of `timestep` s),
    each only when drawn and its model adds something ({} when neither); `delay_steps`: the action delay of
    instances that draw none. The PD factors go to the controller (`control.base.pd_scale`)."""
    step_ms = timestep * 1e3
    steps = lambda name: np.round(np.asarray(controls[name]) / step_ms).astype(np.int32)
    out = {}
    figures = {k: controls[f"motor_{k}"] for k in ("stall_torque", "no_load_speed", "torque_limit")
               if f"motor_{k}" in controls}
    if (figures or "action_delay" in controls) and not actuation.passthrough:  # else all ideal, prompt
        n = len(next(iter(controls.values())))
        delay = steps("action_delay") if "action_delay" in controls else delay_steps
        out["motor"] = actuation.motor(n, delay_steps=delay, **figures)
    drawn = {k: controls[k] for k in FIGURES if k in controls}
    if "sensor_delay" in controls:
        drawn["delay"] = steps("sensor_delay")
    if drawn and not sensing.passthrough:  # else every drawn delay is 0 and no noise is drawn
        out["sensing"] = drawn
    return out


@functools.partial(jax.jit, static_argnums=1)
def _head(tree, n: int):
    """Every leaf's first `n` rows."""
    return jax.tree_util.tree_map(lambda x: x[:n], tree)


def _padded(state: State, size: int) -> State:
    """The state padded to `size` instances with copies of the first."""
    n = state.gravity.shape[0]
    return jax.tree_util.tree_map(lambda x: jnp.concatenate([x, jnp.broadcast_to(x[:1], (size - n,) + x.shape[1:])]),
                                  state)


def _instance_rollout(engine, actuation: Actuation, pushes: Pushes | None, sensing: Sensing, controller, steps, tick,
                      periods, sensors, terrain=None, mj_model=None):
    """One instance's rollout: `steps` physics steps, a record every `tick` steps; on a height field
    (`terrain`, the model's grid) the observation and the record carry the ground."""
    plant = Plant(engine, actuation, pushes, counts=pushes is not None or sensing.noisy)
    points = None if terrain is None else jnp.asarray(sensors.scan_points(), jnp.float32)

    def physics_step(model, sensed, act, state, record, previous):
        """One step; `record` is a traced, batch-wide flag: the signals are measured
        (after forward, before integrate) where it is true, else `previous` is passed on.
        `sensed`: (heights, size, scan points) of the instance's ground, or () on the plane."""
        d, sense = state.data, state.sense
        now = obs = signals.observe(engine, model, d, sensed)
        if not sensing.passthrough:  # static: exact, prompt sensors add nothing
            obs, sense = sensing.apply(sense, obs, state.key, state.step)
        command, cstate = act(state.cstate, obs, state.gravity)
        ctrl, _, cstate, drive = actuate(plant, controller.servo, command, cstate, state.drive, now, d.qvel)
        # An unbatched predicate stays a real conditional under vmap: off-tick steps skip the signals.
        measure = lambda d1: jax.lax.cond(record, lambda: signals.measure(engine, model, d1, state.gravity, sensed,
                                                                          sensors.torque), lambda: previous)
        d1, step, sig, bad = advance(plant, model, d, state.gravity, ctrl, state.key, state.step, measure,
                                     state.diverged)
        # A diverged instance is frozen at its last finite state; the others never see it.
        keep = lambda new, old: jnp.where(bad, old, new)
        cstate, drive = jax.tree_util.tree_map(keep, (cstate, drive), (state.cstate, state.drive))
        return state._replace(data=d1, cstate=cstate, drive=drive, step=step, sense=sense, diverged=bad), sig

    def one_tick(carry, _):
        # The step is traced once, in one loop, so XLA compiles the engine once (not
        # once for the recorded step and again for the others).
        model, heights, weights, state = carry
        sensed = () if terrain is None else (heights, terrain.size, points)
        act = controller.act if weights is None else controller.act_with(weights)

        def body(k, state_sig):
            return physics_step(model, sensed, act, state_sig[0], record=k == 0, previous=state_sig[1])

        measure = lambda: signals.measure(engine, model, state.data, state.gravity, sensed, sensors.torque)
        state, sig = jax.lax.fori_loop(0, tick, body, (state, _zeros_like(jax.eval_shape(measure))))
        return (model, heights, weights, state), sig

    def run(model, heights, state, weights=None):
        """`heights`: the model's own ground, unless the state gives the instance its own."""
        variation = state.variation
        model = engine.vary(model, variation)  # this instance's robot: per instance only where varied
        if isinstance(state.ground, jax.Array):  # static: this instance's own ground, into its engine's model
            heights = state.ground
            model = engine.on_ground(model, heights)
        # The loop carries the robot once, in `model`, not its drawn fields again in the state.
        (_, _, _, state), sig = jax.lax.scan(one_tick, (model, heights, weights, state._replace(variation={})),
                                             None, length=steps // tick)
        state = state._replace(variation=variation)
        every = {k: p // tick for k, p in periods.items()}
        decimate = lambda tree, stream: jax.tree_util.tree_map(lambda x: x[:: every[stream]], tree)
        noise_key, next_key = split_rollout_key(state.key)
        # The streams' noise and each instance's own sensors' (static: where it has noisy ones), in one pass.
        imu, odom = signals.add_noise(sensors, noise_key, decimate(sig.imu, "imu"), decimate(sig.odom, "odom"),
                                      state.sense if sensing.noisy else None)
        contact = decimate(sig.contact, "contact")
        traj = (imu, odom, contact, sig.qpos[:: every["state"]], sig.qvel[:: every["state"]],
                decimate(sig.ground, "contact"),
                applied_torque(actuation.layout, sig.ctrl[:: every["state"]]) if sensors.torque else ())
        return state._replace(key=next_key), traj

    return run


def applied_torque(layout, ctrl: jax.Array) -> jax.Array:
    """(..., 3) N·m, joint order: what MuJoCo's motor actuators apply for `ctrl` (..., nu), clamped to their control
    range (the URDF's effort limit)."""
    act, gear = jnp.asarray(layout.actuator_of_joint), jnp.asarray(layout.gear, ctrl.dtype)
    effort = jnp.asarray(layout.effort_limit, ctrl.dtype)
    return jnp.clip(ctrl[..., act] * gear, -effort, effort)


def _zeros_like(shapes):
    return jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), shapes)
