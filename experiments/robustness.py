"""The robustness table: Raibert and trained policies under pushes, on the URDF's robot and on randomised
robots, medians over each policy's seeds, made from `sweep compare` runs, not by hand.

    python experiments/robustness.py --policies urdf=runs/hop-ppo-seeds pg=runs/hop-ppo-pg-seeds \\
        --out runs/robustness                      # runs what is missing, then writes runs/robustness/robustness.md

Each NAME=PATH is one row group: PATH a training run or a `--seeds` parent of seed-<s>/ runs (each seed's
policy is one controller). Raibert is the reference row. Two columns, each one `python -m hopper_mjx.sweep
compare` per row group (OUT/<column>/<NAME>/, the same kicks and robots for every controller): the URDF's
robot, and robots drawn with --randomize; both with --push. Per gravity: the median and [min-max] over seeds
of the survival and of the survivors' mean |apex rise - command| (m). A sweep already in its folder is read,
not run again, if it was run with the same settings (else the command stops and says which differs).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
from pathlib import Path

from hopper_mjx import cli
from hopper_mjx.shell import checks, process

COLUMNS = ("urdf", "randomized")  # the URDF's robot, and --randomize's robots
SETTINGS = ("gravity", "num", "duration", "height", "push", "variation")  # what a reused sweep must share


def parser():
    p = cli.parser("python experiments/robustness.py", __doc__)
    p.add_argument("--policies", nargs="+", required=True, metavar="NAME=PATH",
                   help="row groups: a name and a training run or --seeds parent")
    p.add_argument("--out", type=Path, required=True, help="folder of the sweeps and robustness.md")
    p.add_argument("--gravity", "--values", dest="gravity", default="9.81,3.71,1.62", metavar="G,...",
                   help="gravities m/s² (default Earth, Mars, Moon); --values is the same option, its older name")
    p.add_argument("--num", type=int, default=64, help="instances per gravity (default 64)")
    p.add_argument("--duration", type=float, default=20.0, help="seconds per instance (default 20)")
    p.add_argument("--height", type=float, default=0.10, help="commanded apex rise m (default 0.10)")
    p.add_argument("--push", default="2,0.3", help="INTERVAL,SPEED of the pushes (default 2,0.3)")
    p.add_argument("--randomize", default="playground", help="the randomised column's robots (default playground)")
    return p


def seeds_of(path: Path) -> list[Path]:
    """The run folders of one row group: PATH itself, or its seed-<s>/ children in seed order."""
    children = sorted(path.glob("seed-*/policy"), key=lambda p: int(p.parent.name.split("-")[1]))
    if (path / "policy").is_dir():
        return [path]
    if not children:
        raise ValueError(f"--policies: {path} is neither a training run (no policy/) nor a parent of seed-<s>/ runs")
    return [c.parent for c in children]


def groups(args) -> dict[str, list[str]]:
    """{row group: its controllers}: raibert first."""
    from hopper_mjx.envs import policy

    found = {"raibert": ["raibert"]}
    for item in args.policies:
        name, sep, path = item.partition("=")
        if not sep or not name or name in found or "/" in name:
            raise ValueError(f"--policies needs distinct NAME=PATH items (NAME without '/'), got {item!r}")
        runs = seeds_of(Path(path))
        for run in runs:
            policy.resolve(run)  # raises for a folder without a policy
        found[name] = [f"policy:{run}" for run in runs]
    return found


def sweep_args(args, controllers: list[str], column: str, folder: Path) -> list[str]:
    extra = ["--randomize", args.randomize] if column == "randomized" else []
    return ["compare", "--controllers", ",".join(controllers), "--gravity", args.gravity, "--num", str(args.num),
            "--duration", repr(args.duration), "--height", repr(args.height), "--push", args.push, *extra,
            "--no-progress", "--out", str(folder)]


def check(args) -> dict[str, list[str]]:
    """Every input, before anything runs: the row groups, then each sweep's own checks (its robots, pushes,
    policies and folder); raises ValueError."""
    cli.check_writable("--out", args.out, folder=True, make_parents=True)
    found = groups(args)
    from hopper_mjx.sweep import __main__ as sweep

    for column in COLUMNS:
        for name, controllers in found.items():
            words = sweep_args(args, controllers, column, args.out / column / name)
            try:
                sweep.check(sweep.parser().parse_args(words))
            except SystemExit:  # argparse has said what it could not parse
                raise ValueError(f"the {column} sweep of {name} takes no {' '.join(words[3:-3])}") from None
    return found


def recorded(folder: Path) -> dict | None:
    path = folder / "comparison.json"
    return json.loads(path.read_text()) if path.is_file() else None


def run_sweeps(args, found: dict[str, list[str]]) -> dict[tuple[str, str], dict]:
    """{(column, row group): its comparison.json}, running the missing sweeps (each resumable)."""
    done, reference = {}, None
    for column in COLUMNS:
        for name, controllers in found.items():
            folder = args.out / column / name
            if recorded(folder) is None:
                print(f"{column} / {name}: {checks.counted(len(controllers), 'controller')}", file=sys.stderr,
                      flush=True)
                command = [sys.executable, "-m", "hopper_mjx.sweep", *sweep_args(args, controllers, column, folder)]
                code = subprocess.run(command).returncode
                if code == 2:  # refused: the sweep said why on its one line
                    raise SystemExit(2)
                if code != 0:
                    raise SystemExit(f"error: the sweep into {folder} failed (exit {code})")
            result = recorded(folder)
            settings = {k: result["arguments"][k] for k in SETTINGS}
            if column == "urdf":
                reference = reference or settings
                differs = [k for k in SETTINGS if k != "variation" and settings[k] != reference[k]]
                if differs:
                    raise SystemExit(f"error: {folder} was swept with other {', '.join(differs)}: use another --out")
            done[column, name] = result
    return done


def spread(values: list[float], fmt: str) -> str:
    values = [v for v in values if v is not None]
    if not values:
        return "–"
    middle = fmt.format(statistics.median(values))
    return middle if len(values) == 1 else f"{middle} [{fmt.format(min(values))}–{fmt.format(max(values))}]"


def table(args, found: dict[str, list[str]], done: dict) -> str:
    head = (f"| g m/s² | controller | seeds | URDF's robot: alive | \\|apex err\\| m | `{args.randomize}`: alive | "
            "\\|apex err\\| m |\n|---|---|---|---|---|---|---|\n")
    rows = []
    for name in found:
        for g in (float(v) for v in args.gravity.split(",")):
            cells = []
            for column in COLUMNS:
                at = [row for row in done[column, name]["groups"] if abs(row["gravity"] - g) < 1e-9]
                alive = [100 * row["survival"] for row in at]
                errors = [row["apex_error"] if row["survival"] > 0 else None for row in at]
                cells += [spread(alive, "{:.0f} %"), spread(errors, "{:.3f}")]
            rows.append(f"| {g:g} | {name} | {len(found[name])} | " + " | ".join(cells) + " |")
    return head + "\n".join(rows) + "\n"


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        found = check(args)
    except ValueError as err:
        return cli.fail(err)
    done = run_sweeps(args, found)
    text = table(args, found, done)
    (args.out / "robustness.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
