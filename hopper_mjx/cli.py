"""The options the `python -m hopper_mjx.*` commands share, checked whole: the simulated batch
(gravities or worlds, size, controller, model), the engine and the live options.

The value, path and name checks themselves live below, in `hopper_mjx.shell.checks` (re-exported here
for the tools); a bad value is one line on stderr, `error: ...`, exit code 2, nothing written,
before any model is built or compiled.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from hopper_mjx import registry
from hopper_mjx.model.robot import same_robot
from hopper_mjx.scenario import Physics, Scenario
from hopper_mjx.shell import budget, jaxsetup
from hopper_mjx.shell.checks import (  # noqa: F401  re-exported: the tools use them beside the options
    DEFAULT_TIMESTEP,
    MAX_TIMESTEP,
    PLOT_SUFFIXES,
    ArgumentParser,
    check_engine,
    check_indices,
    check_range,
    check_readable_file,
    check_seed,
    check_writable,
    counted,
    fail,
    floats,
    make_folder,
    parse_floats,
    parse_indices,
    parse_scan,
    parser,
    say,
    warn_diverged,
)
from hopper_mjx.terrain.spec import check_terrain, refuse_each, terrain_help  # noqa: F401 (refuse_each: the tools')


def check_controller(text: str, height: float = 0.0, speed=(0.0, 0.0), physics: Physics | None = None,
                     flag: str = "--controller") -> None:
    """A known controller; a `policy:PATH` must be a trained policy for `physics`' robot whose training
    range holds the command (`height`, `speed`). Reads the policy and the physics' model (compiled once,
    kept for the build) only. `flag`: the option that named it, for the refusal."""
    if not registry.is_policy(text):
        try:
            registry.check("controller", registry.CONTROLLERS, text, extra=f"{registry.POLICY_PREFIX}PATH")
        except ValueError as err:
            raise ValueError(f"{flag}: {err}") from None
        return
    path = Path(registry.policy_path(text))
    if not path.is_dir():
        raise ValueError(f"{flag} {text}: {no_policy_folder(path)}")
    from hopper_mjx.envs import policy
    from hopper_mjx.model.robot import standing_height

    physics = physics or Physics()
    jaxsetup.configure()  # reading the policy is the command's first JAX computation
    try:
        config = policy.load(path)[1]  # the parameters too: a damaged copy is refused before any compile
        same_robot(config.robot, physics.mj_model, f"the policy {path}")
    except ValueError as err:
        raise ValueError(f"{flag}: {err}") from None
    policy.check_command(config, standing_height(physics.mj_model), height, speed)


def no_policy_folder(path: Path) -> str:
    """Why `path`, which is not a folder, is no policy; if nothing is there, how to make one there (the README's tour
    names a policy folder before its training line)."""
    if Path(path).exists():
        return f"{path} is not a trained policy: a file, not a training run's folder"
    return f"{path} is not a trained policy: no such folder (train one: python experiments/train.py --out {path})"


def check_gains(args) -> dict | None:
    """--gains, read: only for the pid controller, from a file (or seed folder) `pid.load_gains` reads."""
    if args.gains is None:
        return None
    if args.controller != "pid":
        raise ValueError(f"--gains sets the pid controller's gains; --controller is {args.controller}")
    from hopper_mjx.control import pid

    try:
        return pid.load_gains(args.gains)
    except ValueError as err:
        raise ValueError(f"--gains: {err}") from None


# -- the simulated batch of simulate, record and render -----------------------------------------
# Every tool's --chunk: the size is part of the compiled program, so another size may move the numbers.
CHUNK_HELP = ("instances per vmapped chunk on a device (another size is another compiled program, whose numbers "
              "may differ in their last bits)")


def add_batch_options(p: argparse.ArgumentParser, *, gravity=(9.81, 3.71, 1.62), duration: float = 2.0) -> None:
    """The options of a simulated batch: its gravities (or worlds), size, duration, controller and model."""
    p.add_argument("--gravity", type=floats("--gravity"), default=None,
                   help=f"gravity magnitudes in m/s², pointing down (default: {','.join(map(str, gravity))}), "
                        "one instance each (x --num)")
    p.add_argument("--world", type=Path, nargs="+", default=None, metavar="FILE.world",
                   help="Gazebo world files instead of --gravity, one instance each (x --num): their gravity "
                        "vectors, physics step, ground friction and <heightmap> ground "
                        "(e.g. hopper_mjx/model/low_gravity.world)")
    p.set_defaults(default_gravity=list(gravity))
    p.add_argument("--num", type=int, default=1, help="instances per gravity value or world")
    p.add_argument("--duration", type=float, default=duration,
                   help="simulated time, s; a run is whole samples of every stream, and a note says when that "
                        "rounds it")
    p.add_argument("--controller", default="hold",
                   help=f"{registry.listed(registry.CONTROLLERS)} or {registry.POLICY_PREFIX}PATH (a policy trained "
                        "by experiments/train.py)")
    p.add_argument("--height", type=float, default=0.10,
                   help="raibert, policy: commanded apex rise of the base above its standing height, m; a note "
                        "names each gravity where a gait's rise passes the motors' energy bound")
    p.add_argument("--speed", type=floats("--speed"), default=[0.0, 0.0],
                   help="raibert, policy: commanded horizontal speed VX,VY in m/s")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--gyro-noise", type=float, default=0.0, help="IMU angular-rate noise std, rad/s")
    p.add_argument("--accel-noise", type=float, default=0.0, help="IMU specific-force noise std, m/s²")
    p.add_argument("--gains", type=Path, default=None, metavar="FILE_OR_FOLDER",
                   help="pid: joint gains from a seed-style monoped.yaml or .yml (the file, or the seed's "
                        "package or config/ folder holding it; default: the shipped one)")
    p.add_argument("--scenario", type=Path, default=None, metavar="FILE.yaml",
                   help="a scenario file: these options' values by name (gravity: [9.81, 1.62], num: 8, "
                        "controller: raibert, urdf: my.urdf, ...; paths from the file's folder); the command "
                        "line wins over the file")
    p.add_argument("--timestep", type=float, default=None, help="physics step, s (default: the world's, or 0.001)")
    p.add_argument("--chunk", type=int, default=256, help=CHUNK_HELP)
    add_physics_options(p)


# -- the physics every tool runs: the robot, the engine (and what a world sets) ------------------
def add_physics_options(p: argparse.ArgumentParser, *, engine_help: str = "", terrain: str | None = "flat",
                        terrain_default: str = "flat") -> None:
    """The options of a `scenario.Physics`, one set for every tool; `check_physics` reads them. `terrain`: the
    --terrain default (None: the tool picks one, `terrain_default` says which)."""
    p.add_argument("--urdf", default=None, help="monoped URDF (default: the shipped one)")
    p.add_argument("--terrain", default=terrain, metavar="SPEC", help=terrain_help(terrain_default))
    p.add_argument("--randomize", default=None, metavar="NAME=DIST,...",
                   help="robot parameters drawn per instance with --seed, e.g. \"foot_friction=uniform(0.4,1.0),"
                        "body_mass=scale(0.9,1.1),dof_damping=0.02..0.2\"; DIST: a number, a..b, uniform(a,b), "
                        "loguniform(a,b), normal(mu,sigma) or scale(a,b) (times the URDF's value); NAME: "
                        f"{', '.join(registry.PARAMETERS)}; the controller's, motors' and sensors': "
                        f"{', '.join(registry.CONTROL_PARAMETERS)}; or a preset among them: "
                        f"{', '.join(registry.RANDOMIZE_PRESETS)} (docs/variation.md)")
    p.add_argument("--engine", default=registry.DEFAULT_ENGINE,
                   help=f"physics engine: {registry.listed(registry.ENGINES)}; default {registry.DEFAULT_ENGINE}"
                        + engine_help)
    p.add_argument("--motor", default=registry.DEFAULT_MOTOR,
                   help=f"the joints' motors: {registry.listed(registry.MOTORS)}; default {registry.DEFAULT_MOTOR}")
    p.add_argument("--action-delay", type=float, default=0.0, metavar="MS",
                   help="ms from a controller's command (a torque, or a policy's joint targets) to the motors "
                        "(whole physics steps)")
    p.add_argument("--push", type=floats("--push"), default=None, metavar="INTERVAL,SPEED",
                   help="random pushes during the run: every INTERVAL s each base's horizontal velocity changes "
                        "by SPEED m/s in a direction of its own")


MAX_PUSH_SPEED = 340.0  # m/s, the speed of sound: a shove, not a shot (1e300 would be inf in the float32 core)


def check_push(values) -> tuple[float, float] | None:
    """--push INTERVAL,SPEED: a positive finite interval in s and a speed in 0..MAX_PUSH_SPEED m/s."""
    if values is None:
        return None
    if len(values) != 2:
        raise ValueError(f"--push takes INTERVAL,SPEED (s, m/s), got {len(values)} value(s)")
    check_range("--push interval", values[0], low=0, open_low=True)
    check_range("--push speed", values[1], low=0, high=MAX_PUSH_SPEED)
    return float(values[0]), float(values[1])


def check_ground(text: str, n: int = 1):
    """--terrain parsed and sized for `n` instances (`engines`: the names the tool may step it with); the foot
    must start above it."""
    from hopper_mjx.model.robot import CLEARANCE

    ground = check_terrain(text, n)
    top = ground.start_height()  # every instance starts with its foot CLEARANCE above z = 0 at the origin
    if top >= CLEARANCE:
        shown = f"{top:.3f}" if top < 1e6 else f"{top:.3g}"  # amp=1e300: not 300 digits
        raise ValueError(f"--terrain {text}: the ground within 0.1 m of the start rises to {shown} m, and the foot "
                         f"starts {CLEARANCE:g} m above z = 0; move the shape away from the origin or lower it")
    return ground


def check_randomize(text: str | None, engines):
    """--randomize read (`hopper_mjx.variation.spec.Spec`, or None without it): an unknown parameter, a bad
    distribution, or an engine that cannot take the varied fields raise ValueError."""
    if not text:
        return None
    from hopper_mjx.variation.spec import Spec, check_engine_varies

    try:
        spec = Spec.parse(text)
    except ValueError as err:
        raise ValueError(f"--randomize: {err}") from None
    for engine in engines:
        try:
            check_engine_varies(engine, spec.fields)
        except ValueError as err:
            raise ValueError(f"--randomize: {err}; use --engine mjx or auto") from None
    return spec


def check_delay(physics: Physics, duration: float | None, n: int = 1, seed: int = 0, *,
                run: str = "the run's --duration") -> None:
    """An action delay shorter than the run (else no command ever reaches the motors), and so every delay
    the `n` instances draw with `seed` (`--randomize action_delay=...,sensor_delay=...`); `run` names the
    duration in the message (training: an episode)."""
    if duration is None:
        return
    if physics.action_delay >= duration:
        raise ValueError(f"--action-delay {physics.action_delay * 1e3:g} ms is not shorter than {run} "
                         f"{duration:g} s: no command would reach the motors")
    for name in ("action_delay", "sensor_delay"):
        longest = physics.longest_delay(name) * physics.timestep
        if longest < duration:  # the distribution cannot draw so long a delay: no draws needed
            continue
        from hopper_mjx.variation.draw import draw_controls

        drawn = draw_controls(physics.variation, physics.mj_model, n, seed)[name]
        i = int(np.argmax(drawn))
        if drawn[i] * 1e-3 >= duration:
            raise ValueError(f"--randomize: {name} drew {drawn[i]:g} ms for instance {i}, not shorter than "
                             f"{run} {duration:g} s")


def check_controls(physics: Physics, controller: str) -> None:
    """The drawn control parameters apply: a dc motor's figures need --motor dc, PD factors a controller
    with joint PD gains."""
    drawn = physics.variation.controls if physics.variation else {}
    for name in drawn:
        needs = registry.CONTROL_PARAMETERS[name].needs
        if needs == "dc" and physics.motor != "dc":
            raise ValueError(f"--randomize: {name} is a dc motor's figure; add --motor dc")
        if needs == "pd" and controller not in registry.PD_CONTROLLERS and not registry.is_policy(controller):
            raise ValueError(f"--randomize: {name} scales joint PD gains, which --controller {controller} has "
                             f"not; use {', '.join(registry.PD_CONTROLLERS)} or a policy")


def check_physics(args, model_options: dict | None = None, *, engines: list[str] | None = None,
                  n: int = 1, seed: int = 0, terrain: str | None = None) -> Physics:
    """The checked `Physics` of `add_physics_options`' options (with the model options a tool or its
    world sets, and the ground `terrain` its world sets, a --terrain spec); `engines`: the names a tool
    that runs several takes from --engine (else one); `n`: the instances that hold the ground's heights
    and whose robots are drawn with `seed` (a drawn value out of its range is refused before anything runs)."""
    for name in engines or [args.engine]:
        check_engine(name)
    if terrain is not None and args.terrain != "flat":
        raise ValueError(f"give --terrain or a world's <heightmap> ({terrain}), not both")
    try:
        ground = check_ground(terrain or args.terrain, n)
    except ValueError as err:  # a world's <heightmap> is named as the user gave it, not as --terrain
        raise ValueError(str(err).replace("--terrain", "--world <heightmap>", 1) if terrain else str(err)) from None
    variation = check_randomize(args.randomize, engines or [args.engine])
    try:
        registry.check("motor", registry.MOTORS, args.motor)
    except ValueError as err:
        raise ValueError(f"--motor: {err}") from None
    check_range("--action-delay", args.action_delay, low=0)
    push = check_push(args.push)
    physics = Physics(urdf=args.urdf, model_options=dict(model_options or {}), ground=ground, variation=variation,
                      engine=args.engine, motor=args.motor, action_delay=args.action_delay / 1e3, push=push)
    if push is not None:
        from hopper_mjx.hardware.pushes import Pushes

        try:
            Pushes.of(*push, physics.timestep)
        except ValueError as err:
            raise ValueError(f"--push: {err}") from None
    if abs(physics.delay_steps * physics.timestep - physics.action_delay) > 1e-9:
        raise ValueError(f"--action-delay must be a whole number of physics steps ({physics.timestep * 1e3:g} ms), "
                         f"got {args.action_delay:g} ms")
    if args.urdf is not None or physics.motor != registry.DEFAULT_MOTOR:
        from hopper_mjx.model.urdf_checks import check_urdf  # MuJoCo's import waits for the cheap checks

        leg = check_urdf(args.urdf)
        no_speed = [t.joint for t in leg.transmissions if not math.isfinite(t.velocity)]
        if physics.motor == "dc" and no_speed:
            raise ValueError(f"--motor dc: the URDF gives no <limit velocity> (the motor's no-load speed) for "
                             f"{', '.join(no_speed)}")
    if variation is not None:  # drawn once now (MuJoCo's compile, no JAX): a value out of its range is refused
        from hopper_mjx.variation import draw

        try:  # and a leg that cannot reach the floor
            draw.stances(physics.mj_model, draw.draw(variation, physics.mj_model, n, seed))
            draw.draw_controls(variation, physics.mj_model, n, seed)
        except ValueError as err:
            raise ValueError(f"--randomize: {err}") from None
    return physics


def read_worlds(paths, gravity_given: str | None = None):
    """The `world.WorldBatch` of --world FILE...; `gravity_given`: the gravity flag the user also gave."""
    from hopper_mjx.model import world

    if gravity_given:
        raise ValueError(f"give {gravity_given} or --world, not both (a world file sets the gravity)")
    return world.batch(world.read(check_readable_file("--world", path)) for path in paths)


def batch_from_worlds(args):
    """(gravity rows, model options, terrain spec or None, warning) of --world, or None without it."""
    if args.world is None:
        return None
    from hopper_mjx.model import loader

    worlds = read_worlds(args.world, "--gravity" if args.gravity is not None else None)
    options = worlds.model_options(loader.FOOT_FRICTION)
    if args.timestep is not None and "timestep" in options and abs(options["timestep"] - args.timestep) > 1e-12:
        raise ValueError(f"--timestep {args.timestep:g} contradicts the world's <max_step_size> "
                         f"{options['timestep']:g}; leave one out")
    return worlds.gravity, options, worlds.terrain, worlds.warning()


def check_batch(args) -> Scenario:
    """Checks every batch option before anything is built (and before JAX is imported); raises
    ValueError naming the first bad one. Prints the worlds' one-line warning, if any.
    The streams' rates are checked by `check_rates`, which needs the signals module.
    A --duration of None (`view`: until the window closes) passes."""
    if args.num < 1:
        raise ValueError(f"--num must be >= 1, got {args.num}")
    if args.duration is not None:
        check_range("--duration", args.duration, low=0, open_low=True)
    check_range("--height", args.height, low=0)
    if len(args.speed) != 2 or not all(math.isfinite(v) for v in args.speed):
        raise ValueError(f"--speed needs two finite values VX,VY in m/s, got {args.speed}")
    for name in ("gyro_noise", "accel_noise"):
        check_range(f"--{name.replace('_', '-')}", getattr(args, name), low=0)
    if args.chunk < 1:
        raise ValueError(f"--chunk must be >= 1, got {args.chunk}")
    check_seed(args.seed)
    check_engine(args.engine)
    if args.timestep is not None:
        check_range("--timestep", args.timestep, low=0, high=MAX_TIMESTEP, open_low=True)
    from_worlds = batch_from_worlds(args)
    if from_worlds is None:
        from hopper_mjx.model.world import gravity_vectors

        try:
            rows, options, terrain, warning = gravity_vectors(args.gravity or args.default_gravity), {}, None, None
        except ValueError as err:
            raise ValueError(f"--gravity: {err}") from None
    else:
        rows, options, terrain, warning = from_worlds
    options.setdefault("timestep", args.timestep or DEFAULT_TIMESTEP)
    # The ground's memory and the robots' draws, for the N instances.
    physics = check_physics(args, options, n=len(rows) * args.num, seed=args.seed, terrain=terrain)
    check_delay(physics, args.duration, len(rows) * args.num, args.seed)
    check_controls(physics, args.controller)
    check_controller(args.controller, args.height, args.speed, physics)
    gains = check_gains(args)
    if warning:
        print(warning, file=sys.stderr)
    budget.check_memory("--num", len(rows) * args.num)  # before the rows are repeated; the recording: check_rates
    return Scenario(gravity=np.repeat(rows, args.num, axis=0), physics=physics, controller=args.controller,
                    height=args.height, speed=tuple(args.speed), gains=gains, seed=args.seed, chunk=args.chunk)


# Values one sample of each stream records per instance, for the size estimate (the monoped's nq + nv for
# the state; the IMU's quaternion, rate and force; the odometry's pose and twist; the contact's flag, force, point).
STREAM_FLOATS = {"state": 19, "imu": 10, "odom": 13, "contact": 7}


def check_rates(flags: str | dict, sensors, batch: Scenario, duration: float | None = None) -> str | None:
    """Every stream's rate divides the batch's physics rate; `flags` names the option that set the rates (one for
    all streams), or {stream: option} (imu, odom, contact, state), so that a refusal names what the user typed
    and the rates that would work. With a `duration`, the run must fit: its steps in one compiled loop, its
    recording in this machine's memory (`budget`); returns the note to print where the run, whole samples of
    every stream, is not `duration` s long."""
    rate = round(1 / batch.timestep)
    for stream in STREAM_FLOATS:
        hz = getattr(sensors, f"{stream}_rate")
        steps = rate / hz if hz > 0 else 0.0
        if not (steps >= 1 - 1e-9 and abs(steps - round(steps)) < 1e-6):
            flag = flags if isinstance(flags, str) else flags[stream]
            works = [rate // k for k in range(rate, 0, -1) if rate % k == 0 and 5 <= rate // k <= 100]
            raise ValueError(f"{flag} {hz:g} must divide the physics rate {rate} Hz (a sample every whole number of "
                             f"steps), e.g. {', '.join(map(str, works))}")
    periods = sensors.periods(batch.timestep)
    if duration is not None:
        steps = budget.check_steps("--duration", duration, batch.timestep)
        recorded = sum(STREAM_FLOATS[s] * steps / p for s, p in periods.items())
        budget.check_memory("--num, --duration", batch.n, recorded)
        return budget.duration_note(duration, batch.timestep, sensors.whole(batch.timestep))
    return None


def speed_note(batch: Scenario, duration: float) -> str | None:
    """`control.ramp_note` for a batch run for `duration` s: its gait needs longer than that to reach --speed."""
    from hopper_mjx import control

    return control.ramp_note(batch.controller, batch.speed, batch.height, batch.magnitudes(), duration)


def check_whole_periods(option: str, steps: int, timestep: float) -> None:
    """`steps` (an option's value) holds a whole number of every default stream's period at `timestep`: a
    rollout records its streams over whole periods."""
    from hopper_mjx.hardware.signals import SensorConfig  # here: it imports JAX

    whole = SensorConfig().whole(timestep)
    if steps % whole:
        raise ValueError(f"{option} must be a multiple of {whole} (the streams' period at this timestep), got {steps}")


FOXGLOVE_PORT = 8765  # Foxglove's default for a WebSocket connection


def port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--foxglove takes a port number, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"--foxglove port must be in 0..65535, got {value}")
    return value


def add_live_options(p: argparse.ArgumentParser, *, foxglove_help: str) -> None:
    """The options of a batch played live: the Foxglove stream and the pace."""
    p.add_argument("--foxglove", type=port, nargs="?", const=FOXGLOVE_PORT, default=None, metavar="PORT",
                   help=f"{foxglove_help} on ws://127.0.0.1:PORT (default port {FOXGLOVE_PORT}), "
                        "paced at --speed-factor x real time")
    p.add_argument("--speed-factor", type=float, default=1.0,
                   help="simulated seconds per wall-clock second of a live run (1: real time)")


def check_live(args) -> None:
    if not (math.isfinite(args.speed_factor) and args.speed_factor > 0):
        raise ValueError(f"--speed-factor must be > 0, got {args.speed_factor}")


