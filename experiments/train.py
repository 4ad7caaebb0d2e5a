"""Brax PPO or SAC on any monoped task (`hopper_mjx.envs.names()`), gravity drawn per episode, the
physics on the chain engine (`--engine mjx` for MuJoCo MJX).

    nice -n 5 python experiments/train.py --task hop --algo ppo --out runs/hop-ppo --observe-gravity
    python experiments/train.py --task hop --algo ppo --out runs/hop-ppo --observe-gravity   # again: resumes
    python experiments/train.py --task hop_velocity --algo sac --out runs/hopv-sac
    python experiments/train.py --task hop_terrain --algo ppo --out runs/hopt-ppo   # its terrain course, a height scan
    python experiments/train.py --task hop --out runs/hop-ppo --observe-gravity --scan-checkpoints --eval-num 64
    python -m hopper_mjx.simulate --controller policy:runs/hop-ppo --gravity 9.81,3.71,1.62 --duration 10

Writes into --out: checkpoints/<env step>/ (every evaluation), policy/ (the final
params, loadable by `hopper_mjx.envs.policy` as `policy:PATH`; with --scan-checkpoints the best
evaluated checkpoint instead, see selection.json), metrics.json (arguments, task config, one
record per evaluation, wall time) and reward_curve.png.
"""

from __future__ import annotations

# First, so that Ctrl-C during the imports below is already one line (hopper_mjx.shell.startup arms it).
import hopper_mjx  # noqa: F401  # isort: skip

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from hopper_mjx import cli
from hopper_mjx.metrics.thresholds import APEX_TOLERANCE, MIN_HOPS, SPEED_TOLERANCE  # noqa: F401 (one definition)
from hopper_mjx.shell import files, jaxsetup, process
from hopper_mjx.shell.files import atomic_write_text
from training.evaluation import (
    SELECTION,
    evaluate,
    evaluation_table,
    first_at_threshold,
    scan_checkpoints,
    select_policy,
    threshold,
)
from training.loop import HISTORY, train
from training.options import check, parse_floats, parser


def seed_runs(args) -> list[argparse.Namespace]:
    """The runs a command asks for: itself, or with --seeds K one per seed, each into --out/seed-<s>."""
    if args.seeds is None:
        return [args]
    return [argparse.Namespace(**{**vars(args), "seed": s, "seeds": None, "out": str(Path(args.out) / f"seed-{s}")})
            for s in range(args.seed, args.seed + args.seeds)]


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    jaxsetup.configure()
    runs = seed_runs(args)
    try:
        check(args)  # with --seeds: every option, and --out as the seeds' parent
        physics = [check(run) for run in runs]  # each seed's folder (one of another task or algorithm is refused)
        if args.seeds is not None:  # only once every seed is checked: a refused seed leaves nothing behind
            cli.make_folder("--out", args.out)
    except ValueError as err:
        return cli.fail(err)
    for run, run_physics in zip(runs, physics):
        if len(runs) > 1:
            print(f"== seed {run.seed}: {run.out}", flush=True)
        code = train_and_report(run, run_physics)
        if code:
            return code
    return 0


def train_and_report(args, physics) -> int:
    """One seed's training on `physics`, then its scan and evaluation as the arguments ask, holding its folder:
    a second live run given the same --out refuses in one line (two runs resuming one folder at once had each
    written the same checkpoints)."""
    try:
        with files.hold(cli.make_folder("--out", args.out), "another training run"):
            return _train_and_report(args, physics)
    except files.OutputError as err:  # the folder refused, or in use
        return cli.fail(err)


def _train_and_report(args, physics) -> int:
    try:
        record = train(args, physics)
    except ValueError as err:
        return cli.fail(err)
    from hopper_mjx import terrain
    from hopper_mjx.envs.curriculum import judged_on

    # Judged in the core on its own ground, but for a course: one ground, from the origin (`judged_on`).
    physics = dataclasses.replace(physics, ground=terrain.parse(judged_on(str(physics.ground))))
    print(f"wrote {args.out}/policy (step {record['final_step']:,}), {HISTORY}, reward_curve.png; "
          f"{record['wall_time'] / 60:.1f} min of training")
    if args.scan_checkpoints:  # first: the policy evaluated below is the one the scan selects
        scanned = scan_checkpoints(args, physics)
        found = first_at_threshold(args.task, scanned, args.eval_height, args.eval_gravity)
        atomic_write_text(Path(args.out) / "threshold.json", json.dumps(found, indent=1))
        print(f"no checkpoint meets the threshold ({threshold(args.task)})" if found is None else
              f"first at step {found['step']:,}, {found['wall_time'] / 60:.1f} min of training")
        chosen = select_policy(args, scanned)
        if chosen is not None:
            print(f"policy/ holds the best evaluated checkpoint, step {chosen['step']:,} ({SELECTION})")
    if args.evaluate:
        gravities = parse_floats(args.eval_gravity, "--eval-gravity")
        result = evaluate(Path(args.out) / "policy", physics, gravities=gravities, duration=args.eval_duration,
                          height=args.eval_height, num=args.eval_num, seed=args.seed, speed=args.eval_speed)
        table = evaluation_table(result, args.eval_height)
        atomic_write_text(Path(args.out) / "evaluation.json", json.dumps(result, indent=1))
        atomic_write_text(Path(args.out) / "evaluation.md", table + "\n")
        print(table)
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
