"""Argument parsing shared by the `python -m hopper_mjx.*` commands.

Every command checks its arguments here before any model is built or compiled;
a bad value is one line on stderr naming the argument, and exit code 2.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

POLICY_PREFIX = "policy:"


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


def parse_indices(text: str) -> list[int]:
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--instances must be comma-separated integers, got {text!r}") from None


def add_batch_options(p: argparse.ArgumentParser, *, gravity=(9.81, 3.71, 1.62), duration: float = 2.0) -> None:
    """The options of a simulated batch: its gravities, size, duration, controller and model."""
    p.add_argument("--gravity", type=floats("--gravity"), default=list(gravity),
                   help=f"gravity magnitudes in m/s², pointing down (default: {','.join(map(str, gravity))}), "
                        "one instance each (x --num)")
    p.add_argument("--num", type=int, default=1, help="instances per gravity value")
    p.add_argument("--duration", type=float, default=duration, help="simulated time, s")
    p.add_argument("--controller", default="hold",
                   help="none (limp), hold (keep initial joint angles), pid (the seed's joint position "
                        "controllers, holding them), raibert (hop) or policy:PATH (a policy trained by "
                        "experiments/train.py)")
    p.add_argument("--height", type=float, default=0.10,
                   help="raibert, policy: commanded apex rise of the base above its standing height, m")
    p.add_argument("--speed", type=floats("--speed"), default=[0.0, 0.0],
                   help="raibert, policy: commanded horizontal speed VX,VY in m/s")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--gyro-noise", type=float, default=0.0, help="IMU angular-rate noise std, rad/s")
    p.add_argument("--accel-noise", type=float, default=0.0, help="IMU specific-force noise std, m/s²")
    p.add_argument("--urdf", default=None, help="monoped URDF (default: the shipped one)")
    p.add_argument("--timestep", type=float, default=1e-3, help="physics step, s")
    p.add_argument("--chunk", type=int, default=256, help="instances per vmapped chunk on a device")


def check_batch(args) -> None:
    """Raises ValueError naming the first bad batch option (before anything is built)."""
    if args.num < 1:
        raise ValueError(f"--num must be >= 1, got {args.num}")
    if not (math.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be > 0 s, got {args.duration}")
    if len(args.speed) != 2:
        raise ValueError(f"--speed needs two values VX,VY in m/s, got {args.speed}")
    if args.chunk < 1:
        raise ValueError(f"--chunk must be >= 1, got {args.chunk}")
    check_controller(args.controller, args.height, args.speed, getattr(args, "urdf", None))


def check_controller(name: str, height: float, speed, urdf=None) -> None:
    """Raises ValueError if a `policy:PATH` is no policy, or the command is outside its training
    range. Reads the policy's JSON and MuJoCo's compiled model (for the standing height) only."""
    if not name.startswith(POLICY_PREFIX):
        return
    from hopper_mjx import model
    from hopper_mjx.envs import policy
    from hopper_mjx.model.robot import standing_height

    _, _, _, config = policy.read(name.removeprefix(POLICY_PREFIX))
    policy.check_command(config, standing_height(model.load(urdf)), height, speed)


def batch_gravity(args) -> np.ndarray:
    """(N, 3) gravity vectors, gravity-major: instance i has gravity value i // num."""
    from hopper_mjx.sim import gravity_vectors

    return gravity_vectors(np.repeat(args.gravity, args.num))


def make_controller(args, sim, n: int):
    """(controller, params) for --controller: the registry `control.make`, or a trained policy."""
    if args.controller.startswith(POLICY_PREFIX):
        from hopper_mjx.envs import policy

        path = args.controller.removeprefix(POLICY_PREFIX)
        config = policy.read(path)[3]
        params = policy.policy_params(sim.robot, n, height=args.height, speed=args.speed, config=config)
        return policy.policy_controller(sim.mj_model, path), params
    from hopper_mjx import control

    return control.make(args.controller, sim.robot, n, height=args.height, speed=args.speed)


def run_batch(args, sensors):
    """(Sim, final state, trajectory) of the batch the arguments describe, on the one batch-run path."""
    import jax

    from hopper_mjx import model
    from hopper_mjx.sim import Sim

    check_batch(args)
    gravity = batch_gravity(args)
    sim = Sim(model.load(args.urdf, timestep=args.timestep), chunk=args.chunk)
    controller, params = make_controller(args, sim, len(gravity))
    start = time.perf_counter()
    final, traj = sim.run(gravity, controller, params, duration=args.duration, sensors=sensors, key=args.seed)
    jax.block_until_ready(traj)
    wall = time.perf_counter() - start
    steps = len(traj.time["state"]) * sensors.periods(sim.layout.timestep)["state"]
    print(f"{len(gravity)} instances x {steps} steps on {len(sim.devices)} device(s): {wall:.1f} s "
          f"incl. compile, {len(gravity) * steps / wall:,.0f} steps/s", file=sys.stderr)
    return sim, final, jax.tree_util.tree_map(np.asarray, traj)


def fail(err: Exception) -> int:
    print(f"error: {err}", file=sys.stderr)
    return 2


def warn_diverged(diverged) -> None:
    bad = np.flatnonzero(diverged)
    if bad.size:
        print(f"warning: {bad.size} instance(s) diverged and were frozen: {bad[:20].tolist()}", file=sys.stderr)
