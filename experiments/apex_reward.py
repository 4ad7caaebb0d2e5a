"""What the hop task's apex term pays a hopper, per policy step, under each `apex_reward` (docs/learning.md).

    python -m hopper_mjx.simulate --controller raibert --height 0.08 --gravity 9.81,3.71,1.62 --num 1 \\
        --duration 10 --rate 500 --out runs/apex/h08.npz        # one file per hop height
    python experiments/apex_reward.py runs/apex/*.npz --command 0.10

Each file is a `simulate --out` recording. Its states are read at the training's policy rate (50 Hz), over
the last half of the run, and judged as `hopper_mjx.envs` judges them: the term `exp(-|apex - command| /
0.1)` of hop, with the apex `predicted` (the ballistic apex of each state) or `flight` (each hop's own,
held through the stance after it). The rise printed is the median flight apex over the standing height.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from hopper_mjx.shell import checks, process
from hopper_mjx.shell.checks import check_readable_file

POLICY_RATE = 50.0  # Hz, the tasks' default


def judged(qpos: np.ndarray, qvel: np.ndarray, contact: np.ndarray, g: float, standing: float):
    """(predicted, flight) apex (T,) m of one instance's states, by the environment's own rules."""
    import jax.numpy as jnp

    from hopper_mjx.envs.terms import DROPPING, flight_apex, predicted_apex

    class State:  # what `predicted_apex` reads
        def __init__(self, q, v):
            self.qpos, self.qvel = q, v

    predicted = np.asarray([float(predicted_apex(State(q, v), jnp.float32(g))) for q, v in zip(qpos, qvel)])
    info = {"apex": jnp.float32(standing), "flight_top": jnp.float32(DROPPING)}
    flight = []
    for apex, touching in zip(predicted, contact):
        value, carried = flight_apex(jnp.float32(apex), jnp.asarray(not touching), info)
        info = {**info, **carried}
        flight.append(float(value))
    return predicted, np.asarray(flight)


RECORDED = ("time", "gravity", "qpos", "qvel", "contact")


def read_run(name: str) -> dict:
    """The arrays of a `simulate --out` recording; ValueError naming the file for one that is not such a file."""
    check_readable_file("run", name)
    try:
        with np.load(name, allow_pickle=False) as f:
            run = {k: f[k] for k in RECORDED if k in f.files}
    except (OSError, ValueError, EOFError):  # not an .npz, cut short, or objects NumPy will not unpickle
        raise ValueError(f"run {name}: cannot be read as a simulate --out recording (.npz)") from None
    missing = [k for k in RECORDED if k not in run]
    if missing:
        raise ValueError(f"run {name}: not a simulate --out recording: no {', '.join(missing)}")
    if run["time"].size < 2:
        raise ValueError(f"run {name}: holds {run['time'].size} sample(s); the apex term needs a run of at least two")
    return run


def main(argv=None) -> int:
    p = checks.parser("python experiments/apex_reward.py", __doc__)  # one-line refusals, as every command's
    p.add_argument("runs", nargs="+", help="simulate --out .npz files")
    p.add_argument("--command", type=float, default=0.10, help="commanded apex rise above standing, m")
    p.add_argument("--scale", type=float, default=0.1, help="the apex kernel's width, m (hop's)")
    p.add_argument("--urdf", default=None, help="the robot the runs were made with (default: the shipped seed monoped)")
    args = p.parse_args(argv)
    try:  # every input read before anything is computed
        if not (np.isfinite(args.command) and args.command > 0 and np.isfinite(args.scale) and args.scale > 0):
            raise ValueError(f"--command and --scale must be > 0, got {args.command}, {args.scale}")
        if args.urdf is not None:
            check_readable_file("--urdf", args.urdf)
        runs = [(name, read_run(name)) for name in args.runs]
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    from hopper_mjx import model
    from hopper_mjx.model import robot

    standing = float(robot.standing_qpos(model.load(args.urdf or model.DEFAULT_URDF))[2])
    print(f"apex term per policy step, hop's kernel exp(-|apex - command| / {args.scale:g} m), command "
          f"{args.command:g} m above standing ({standing:.3f} m); the last half of each run at {POLICY_RATE:g} Hz\n")
    print("| run | g m/s² | measured rise m | predicted | flight |")
    print("|---|---|---|---|---|")
    for name, run in runs:
        every = max(1, round(1 / (POLICY_RATE * float(run["time"][1] - run["time"][0]))))
        for i, gvec in enumerate(run["gravity"]):
            g = float(-gvec[2])
            predicted, flight = judged(run["qpos"][i, ::every], run["qvel"][i, ::every], run["contact"][i, ::every],
                                       g, standing)
            half = len(flight) // 2  # the flight rule runs from the start, judged over the last half
            predicted, flight = predicted[half:], flight[half:]
            term = lambda apex: float(np.mean(np.exp(-np.abs(apex - standing - args.command) / args.scale)))
            print(f"| {Path(name).name} | {g:g} | {np.median(flight) - standing:.3f} | {term(predicted):.3f} | "
                  f"{term(flight):.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
