"""Argument parsing and checking shared by the `python -m hopper_mjx.*` commands.

Every command checks its arguments here before any model is built or compiled
(and mostly before JAX or MuJoCo is even imported): a bad value is one line on
stderr, `error: ...`, naming the argument and what is wrong, exit code 2, and
nothing written. `ArgumentParser` gives argparse's own refusals the same form.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hopper_mjx import registry

MAX_TIMESTEP = 0.01  # s, as model.load accepts
DEFAULT_TIMESTEP = 1e-3  # s, model.DEFAULT_TIMESTEP (checked equal by a test; importing model loads MuJoCo)


class ArgumentParser(argparse.ArgumentParser):
    """argparse, refusing in one line: `error: <what>` on stderr and exit code 2 (no usage block)."""

    def error(self, message: str):
        self.exit(2, f"error: {message} (see {self.prog} --help)\n")


def parser(prog: str, doc: str | None) -> ArgumentParser:
    return ArgumentParser(prog=prog, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)


def parse_floats(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be comma-separated numbers, got {text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError(f"{what} is empty")
    return values


def floats(what: str):
    """An argparse `type` for a comma-separated list of numbers."""
    return lambda text: parse_floats(text, what)


def parse_indices(text: str, what: str = "--instances") -> list[int]:
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be comma-separated integers, got {text!r}") from None


# -- single checks, each raising ValueError with the one line to print -------------------------
def check_range(name: str, value: float, *, low: float | None = None, high: float | None = None,
                open_low: bool = False) -> None:
    """`value` finite and within [low, high] (or (low, high] with `open_low`)."""
    too_low = low is not None and (value <= low if open_low else value < low)
    if not math.isfinite(value) or too_low or (high is not None and value > high):
        lower = "" if low is None else f"{'>' if open_low else '>='} {low:g}"
        upper = "" if high is None else f"<= {high:g}"
        raise ValueError(f"{name} must be finite and {' and '.join(b for b in (lower, upper) if b)}, got {value:g}")


def check_writable(name: str, path: str | Path, *, folder: bool = False, may_exist: bool = True,
                   make_parents: bool = False) -> Path:
    """An output path that can be written, checked without creating anything: its parent exists and is a
    folder (with `make_parents`, its nearest existing ancestor); a file output is not a folder (a folder
    output not a file); with `may_exist` False it must be new."""
    path = Path(path)
    parent = path.parent
    while make_parents and not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        why = "does not exist" if not parent.exists() else "is not a folder"
        raise ValueError(f"{name} {path}: its folder {parent} {why}")
    if path.exists() and not may_exist:
        raise ValueError(f"{name} {path} exists; remove it or choose another")
    if path.exists() and path.is_dir() != folder:
        wanted, found = ("folder", "file") if folder else ("file", "folder")
        raise ValueError(f"{name} {path} is a {found}; give a {wanted}")
    if not os.access(parent, os.W_OK):
        raise ValueError(f"{name} {path}: cannot write in {parent}")
    return path


def check_readable_file(name: str, path: str | Path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{name} {path}: {'is a folder, not a file' if path.is_dir() else 'no such file'}")
    return path


def check_indices(name: str, indices, n: int) -> None:
    """Instance indices of a batch of n: within 0..n-1, none twice, at least one."""
    indices = list(indices)
    if not indices:
        raise ValueError(f"{name}: no instance given")
    bad = [i for i in indices if not 0 <= i < n]
    if bad:
        raise ValueError(f"{name} {bad} out of range: the batch has {n} instance(s), 0..{n - 1}")
    if len(set(indices)) != len(indices):
        raise ValueError(f"{name} lists an instance twice: {indices}")


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
    from hopper_mjx.envs import policy
    from hopper_mjx.model.robot import standing_height

    try:
        config = policy.read(path)[3]
    except ValueError as err:
        raise ValueError(f"--controller: {err}") from None
    policy.check_command(config, standing_height(model.load(urdf)), height, speed)


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


def check_urdf(path: str | Path | None) -> None:
    """--urdf exists and describes a monoped (checked as XML, before MuJoCo compiles anything)."""
    if path is None:
        return
    from hopper_mjx.model import loader

    path = check_readable_file("--urdf", path)
    try:
        loader.describe(loader.read_text(path, "URDF file", loader.URDFError), str(path))
    except loader.URDFError as err:
        raise ValueError(f"--urdf: {err}") from None


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
    p.add_argument("--timestep", type=float, default=None, help="physics step, s (default: the world's, or 0.001)")
    p.add_argument("--chunk", type=int, default=256, help="instances per vmapped chunk on a device")
    add_engine_option(p)


def add_engine_option(p: argparse.ArgumentParser, *, extra_help: str = "") -> None:
    """The one --engine option of every tool."""
    p.add_argument("--engine", default=registry.DEFAULT_ENGINE,
                   help=f"physics engine: {registry.listed(registry.ENGINES)}; default {registry.DEFAULT_ENGINE}"
                        + extra_help)


@dataclass(frozen=True)
class Batch:
    """What the batch options resolve to, once checked."""

    gravity: np.ndarray  # (N, 3) m/s², gravity-major: instance i has gravity value (or world) i // num
    model_options: dict  # keywords of model.load: timestep, and the foot-floor friction a world sets
    gains: dict | None = None  # --gains, as pid.load_gains read them


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


def check_batch(args) -> Batch:
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
    check_engine(args.engine)
    if args.timestep is not None:
        check_range("--timestep", args.timestep, low=0, high=MAX_TIMESTEP, open_low=True)
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
    return Batch(gravity=np.repeat(rows, args.num, axis=0), model_options=options, gains=gains)


def check_engine(name: str) -> None:
    try:
        registry.check("engine", registry.ENGINES, name)
    except ValueError as err:
        raise ValueError(f"--engine: {err}") from None


def check_rates(flags: str, sensors, batch: Batch) -> None:
    """Every stream's rate divides the batch's physics rate (SensorConfig.periods says which does not);
    `flags` names the options that set the rates."""
    try:
        sensors.periods(batch.model_options["timestep"])
    except ValueError as err:
        raise ValueError(f"{flags}: {err}") from None


def make_controller(args, sim, batch: Batch):
    """(controller, params) for --controller: the registry `control.make`, or a trained policy."""
    n = len(batch.gravity)
    if registry.is_policy(args.controller):
        from hopper_mjx.envs import policy

        path = registry.policy_path(args.controller)
        config = policy.read(path)[3]
        params = policy.policy_params(sim.robot, n, height=args.height, speed=args.speed, config=config)
        return policy.policy_controller(sim.mj_model, path), params
    from hopper_mjx import control

    return control.make(args.controller, sim.robot, n, height=args.height, speed=args.speed, gains=batch.gains)


def build_batch(args, batch: Batch):
    """(Sim, controller, params) of a checked batch."""
    from hopper_mjx import model
    from hopper_mjx.sim import Sim

    sim = Sim(model.load(args.urdf, **batch.model_options), engine=args.engine, chunk=args.chunk)
    controller, params = make_controller(args, sim, batch)
    return sim, controller, params


def run_batch(args, batch: Batch, sensors):
    """(Sim, final state, trajectory) of a checked batch, on the one batch-run path."""
    import jax

    sim, controller, params = build_batch(args, batch)
    start = time.perf_counter()
    final, traj = sim.run(batch.gravity, controller, params, duration=args.duration, sensors=sensors, key=args.seed)
    jax.block_until_ready(traj)
    wall = time.perf_counter() - start
    n, steps = len(batch.gravity), len(traj.time["state"]) * sensors.periods(sim.layout.timestep)["state"]
    print(f"{n} instances x {steps} steps on {len(sim.devices)} device(s): {wall:.1f} s "
          f"incl. compile, {n * steps / wall:,.0f} steps/s", file=sys.stderr)
    return sim, final, jax.tree_util.tree_map(np.asarray, traj)


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


def fail(err: Exception | str) -> int:
    print(f"error: {err}", file=sys.stderr)
    return 2


def warn_diverged(diverged) -> None:
    bad = np.flatnonzero(diverged)
    if bad.size:
        print(f"warning: {bad.size} instance(s) diverged and were frozen: {bad[:20].tolist()}", file=sys.stderr)
