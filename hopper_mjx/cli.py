"""The options the `python -m hopper_mjx.*` commands share, checked whole: the simulated batch
(gravities or worlds, size, controller, model), the engine and the live options.

The value, path and name checks themselves live below, in `hopper_mjx.checks` (re-exported here
for the tools); a bad value is one line on stderr, `error: ...`, exit code 2, nothing written,
before any model is built or compiled.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from hopper_mjx import budget, registry
from hopper_mjx.checks import (  # noqa: F401  re-exported: the tools use them beside the options
    DEFAULT_TIMESTEP,
    MAX_TIMESTEP,
    ArgumentParser,
    check_engine,
    check_indices,
    check_range,
    check_readable_file,
    check_seed,
    check_writable,
    fail,
    floats,
    parse_floats,
    parse_indices,
    parser,
    warn_diverged,
)
from hopper_mjx.scenario import Scenario


def check_controller(text: str, height: float = 0.0, speed=(0.0, 0.0), urdf=None) -> None:
    """A known controller; a `policy:PATH` must be a trained policy whose training range holds the
    command (`height`, `speed`). Reads the policy's JSON and MuJoCo's compiled model (for the
    standing height) only."""
    if not registry.is_policy(text):
        try:
            registry.check("controller", registry.CONTROLLERS, text, extra=f"{registry.POLICY_PREFIX}PATH")
        except ValueError as err:
            raise ValueError(f"--controller: {err}") from None
        return
    path = Path(registry.policy_path(text))
    if not path.is_dir():
        raise ValueError(f"--controller {text}: {path} is not a trained policy: no such folder")
    from hopper_mjx import model
    from hopper_mjx.envs import monoped, policy
    from hopper_mjx.model.robot import standing_height

    try:
        config = policy.load(path)[1]  # the parameters too: a damaged copy is refused before any compile
        mj_model = model.load(urdf)
        monoped.same_robot(config.robot, mj_model, f"the policy {path}")
    except ValueError as err:
        raise ValueError(f"--controller: {err}") from None
    policy.check_command(config, standing_height(mj_model), height, speed)


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
def add_batch_options(p: argparse.ArgumentParser, *, gravity=(9.81, 3.71, 1.62), duration: float = 2.0) -> None:
    """The options of a simulated batch: its gravities (or worlds), size, duration, controller and model."""
    p.add_argument("--gravity", type=floats("--gravity"), default=None,
                   help=f"gravity magnitudes in m/s², pointing down (default: {','.join(map(str, gravity))}), "
                        "one instance each (x --num)")
    p.add_argument("--world", type=Path, nargs="+", default=None, metavar="FILE.world",
                   help="Gazebo world files instead of --gravity, one instance each (x --num): their gravity "
                        "vectors, physics step and ground friction (e.g. hopper_mjx/model/low_gravity.world)")
    p.set_defaults(default_gravity=list(gravity))
    p.add_argument("--num", type=int, default=1, help="instances per gravity value or world")
    p.add_argument("--duration", type=float, default=duration, help="simulated time, s")
    p.add_argument("--controller", default="hold",
                   help=f"{registry.listed(registry.CONTROLLERS)} or {registry.POLICY_PREFIX}PATH (a policy trained "
                        "by experiments/train.py)")
    p.add_argument("--height", type=float, default=0.10,
                   help="raibert, policy: commanded apex rise of the base above its standing height, m")
    p.add_argument("--speed", type=floats("--speed"), default=[0.0, 0.0],
                   help="raibert, policy: commanded horizontal speed VX,VY in m/s")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--gyro-noise", type=float, default=0.0, help="IMU angular-rate noise std, rad/s")
    p.add_argument("--accel-noise", type=float, default=0.0, help="IMU specific-force noise std, m/s²")
    p.add_argument("--gains", type=Path, default=None, metavar="FILE_OR_FOLDER",
                   help="pid: joint gains from a seed-style monoped.yaml or .yml (the file, or the seed's "
                        "package or config/ folder holding it; default: the shipped one)")
    p.add_argument("--urdf", default=None, help="monoped URDF (default: the shipped one)")
    add_randomize_option(p)
    p.add_argument("--motor", default="ideal",
                   help=f"what becomes of the controller's torque at the joint: {registry.listed(registry.MOTORS)}")
    p.add_argument("--scenario", type=Path, default=None, metavar="FILE.yaml",
                   help="a scenario file: these options' values by name (gravity: [9.81, 1.62], num: 8, "
                        "controller: raibert, urdf: my.urdf, ...; paths from the file's folder); the command "
                        "line wins over the file")
    p.add_argument("--timestep", type=float, default=None, help="physics step, s (default: the world's, or 0.001)")
    p.add_argument("--chunk", type=int, default=256, help="instances per vmapped chunk on a device")
    add_engine_option(p)


def add_randomize_option(p: argparse.ArgumentParser) -> None:
    """The one --randomize option: each instance's robot drawn with --seed (`hopper_mjx.randomize`)."""
    p.add_argument("--randomize", default=None, metavar="NAME=DIST,...",
                   help="robot parameters drawn per instance with --seed, e.g. \"foot_friction=uniform(0.4,1.0),"
                        "body_mass=scale(0.9,1.1),dof_damping=0.02..0.2\"; DIST: a number, a..b, uniform(a,b), "
                        "loguniform(a,b), normal(mu,sigma) or scale(a,b) (times the URDF's value); NAME: "
                        f"{', '.join(registry.PARAMETERS)} (docs/variation.md)")


def check_randomize(text: str | None, engine: str, mj_model_of, n: int, seed: int):
    """--randomize read and drawn once (before JAX is imported): an unknown parameter, a bad distribution,
    an engine that cannot take the varied fields, or a drawn value outside its parameter's range raise
    ValueError. `mj_model_of()` compiles the nominal model (only when there is a variation). Returns the
    `randomize.Spec` or None."""
    if not text:
        return None
    from hopper_mjx.randomize import Spec, check_engine_varies

    try:
        spec = Spec.parse(text)
    except ValueError as err:
        raise ValueError(f"--randomize: {err}") from None
    try:
        check_engine_varies(engine, spec.fields)
    except ValueError as err:
        raise ValueError(f"--randomize: {err}; use --engine mjx or auto") from None
    from hopper_mjx.model import variation

    try:
        variation.draw(spec, mj_model_of(), n, seed)
    except ValueError as err:
        raise ValueError(f"--randomize: {err}") from None
    return spec


def add_engine_option(p: argparse.ArgumentParser, *, extra_help: str = "") -> None:
    """The one --engine option of every tool."""
    p.add_argument("--engine", default=registry.DEFAULT_ENGINE,
                   help=f"physics engine: {registry.listed(registry.ENGINES)}; default {registry.DEFAULT_ENGINE}"
                        + extra_help)


def read_worlds(paths, gravity_given: str | None = None):
    """The `world.WorldBatch` of --world FILE...; `gravity_given`: the gravity flag the user also gave."""
    from hopper_mjx.model import world

    if gravity_given:
        raise ValueError(f"give {gravity_given} or --world, not both (a world file sets the gravity)")
    return world.batch(world.read(check_readable_file("--world", path)) for path in paths)


def batch_from_worlds(args):
    """(gravity rows, model options, warning) of --world, or None without it."""
    if args.world is None:
        return None
    from hopper_mjx.model import loader

    worlds = read_worlds(args.world, "--gravity" if args.gravity is not None else None)
    options = worlds.model_options(loader.FOOT_FRICTION)
    if args.timestep is not None and "timestep" in options and abs(options["timestep"] - args.timestep) > 1e-12:
        raise ValueError(f"--timestep {args.timestep:g} contradicts the world's <max_step_size> "
                         f"{options['timestep']:g}; leave one out")
    return worlds.gravity, options, worlds.warning()


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
    try:
        registry.check("motor", registry.MOTORS, args.motor)
    except ValueError as err:
        raise ValueError(f"--motor: {err}") from None
    if args.timestep is not None:
        check_range("--timestep", args.timestep, low=0, high=MAX_TIMESTEP, open_low=True)
    from hopper_mjx.model.checks import check_urdf  # MuJoCo's import waits for the cheap checks above

    check_urdf(args.urdf)
    check_controller(args.controller, args.height, args.speed, args.urdf)
    from_worlds = batch_from_worlds(args)
    if from_worlds is None:
        from hopper_mjx.model.world import gravity_vectors

        try:
            rows, options, warning = gravity_vectors(args.gravity or args.default_gravity), {}, None
        except ValueError as err:
            raise ValueError(f"--gravity: {err}") from None
    else:
        rows, options, warning = from_worlds
    options.setdefault("timestep", args.timestep or DEFAULT_TIMESTEP)
    gains = check_gains(args)
    if warning:
        print(warning, file=sys.stderr)
    budget.check_memory("--num", len(rows) * args.num)  # before the rows are repeated; the recording: check_rates
    from hopper_mjx import model

    variation = check_randomize(args.randomize, args.engine, lambda: model.load(args.urdf, **options),
                                len(rows) * args.num, args.seed)
    return Scenario(gravity=np.repeat(rows, args.num, axis=0), model_options=options, urdf=args.urdf,
                    variation=variation, motor=args.motor, engine=args.engine, controller=args.controller,
                    height=args.height, speed=tuple(args.speed), gains=gains, seed=args.seed, chunk=args.chunk)


# Values one sample of each stream records per instance, for the size estimate (the monoped's nq + nv for
# the state; the IMU's quaternion, rate and force; the odometry's pose and twist; the contact's flag, force, point).
STREAM_FLOATS = {"state": 19, "imu": 10, "odom": 13, "contact": 7}


def check_rates(flags: str, sensors, batch: Scenario, duration: float | None = None) -> None:
    """Every stream's rate divides the batch's physics rate (SensorConfig.periods says which does not);
    `flags` names the options that set the rates. With a `duration`, the run must fit: its steps in one
    compiled loop, its recording in this machine's memory (`budget`)."""
    try:
        periods = sensors.periods(batch.timestep)
    except ValueError as err:
        raise ValueError(f"{flags}: {err}") from None
    if duration is not None:
        steps = budget.check_steps("--duration", duration, batch.timestep)
        recorded = sum(STREAM_FLOATS[s] * steps / p for s, p in periods.items())
        budget.check_memory("--num, --duration", batch.n, recorded)


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


