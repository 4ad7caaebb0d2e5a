"""The learning results table, built from training run folders (experiments/train.py), not by hand.

    python experiments/results.py runs/hop-ppo runs/stand-sac --out results.md          # tables from the folders
    python experiments/results.py runs/hop-ppo --out results.md --sweep                 # also run the sweeps

A RUN folder is one training run, or a `--seeds` parent holding seed-<s>/ runs. Per task x algorithm, over its
seeds, the median and [min-max] of: minutes of training and env steps to the task's threshold (threshold.json of
--scan-checkpoints; `hopper_mjx.metrics.thresholds`), env steps/s (Brax's, the median over the run's evaluations),
and on the kicked gravity sweep of the run's policy (RUN/sweep/: `python -m hopper_mjx.sweep gravity --controller
policy:RUN`, nine default gravities, the default kick) the worst gravity's survival, apex error |rise/command - 1|
and speed error, each twice: on the physics the policy was trained on (RUN/sweep-trained/: the same sweep with
`--as-trained`, its config's timestep and solver caps) and in the core; then the gap between the two at Earth, Mars
and the Moon, held to 5 points of survival and 5 % of the commanded apex (and, the last column, the core's survival
at each of the three); where it is over, the sweep again on each
part of the training physics alone (`--as-trained=timestep` and `=solver`, the other part the core's:
RUN/sweep-trained-timestep/, RUN/sweep-trained-solver/), and the row names the part whose gap stays over. The row
names the step and solver cap its policies were trained on, so runs on other training physics are rows of their own,
and so are runs whose learner's settings differ (epochs per batch, minibatches, learning rate...: `LEARNER`) or
whose task config does (`--config`, e.g. the scan ablation's observe_scan=false), named by what they differ in;
a run trained with --config, or on a --terrain other than its task's own, is named by it even alone.
Each task's reference controller
(`registry.TASK_REFERENCES`: Raibert at the runs' command for the hopping tasks, Raibert at a 5 cm apex for stand)
is swept the same way (OUT's folder, reference-<task>/). Every sweep runs on the run's own ground (`--terrain`;
a course's runs on each ground they are judged on, `curriculum.JUDGE_GROUNDS`, a row each; flat for most tasks).
Stand's apex column is its reference's error against its own command. With --sweep the missing sweeps are run
(each resumable); without it a run without a sweep shows n/a; ∞ marks an error with no survivor or no hop to measure
it on. One plot beside the table (OUT with .png): every seed's evaluation reward against training minutes.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

from hopper_mjx import cli, registry
from hopper_mjx.shell import process
from hopper_mjx.shell.files import is_device

SWEEP = "sweep"  # the policy in the core
TRAINED = "sweep-trained"  # the same sweep on the physics the policy was trained on (`sweep --as-trained`)
# Where a gap is over: the sweep on each part of the training physics alone (`sweep --as-trained=PART`), to say which.
PARTS = {"timestep": "step", "solver": "solver cap"}
COMPARED_GRAVITIES = (9.81, 3.71, 1.62)  # where the two are held to agree: Earth, Mars, the Moon
GAP = {"survival_gap": 0.05, "apex_gap": 0.05}  # the most the core may differ from training: 5 points, 5 % of apex
# The learner's settings (train.py's options, as metrics.json records them), in the words a row uses: runs of one task,
# algorithm and training physics that differ in any of them are rows of their own, named by the ones they differ in.
LEARNER = {"updates_per_batch": "epochs per batch", "num_minibatches": "minibatches", "batch_size": "batch size",
           "unroll_length": "unroll", "num_envs": "envs", "learning_rate": "learning rate",
           "entropy_cost": "entropy cost", "reward_scaling": "reward scaling", "policy_layers": "policy MLP",
           "value_layers": "value MLP", "sac_grad_updates": "SAC updates per batch",
           "sac_target_entropy": "SAC target entropy", "start_from": "started from",
           "sac_hold_policy": "SAC policy held", "sac_policy_lr": "SAC policy learning rate",
           "sac_anchor": "SAC anchored to its start with weight"}


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python experiments/results.py", __doc__)
    p.add_argument("runs", nargs="+", type=Path, help="training run folders, or --seeds parents of seed-<s>/ runs")
    p.add_argument("--out", type=Path, required=True, help="the table's Markdown file (the plot: same name, .png)")
    p.add_argument("--sweep", action="store_true", help="run the missing gravity sweeps (policies and references)")
    p.add_argument("--num", type=int, default=64, help="sweep replicates per gravity (default 64)")
    p.add_argument("--duration", type=float, default=10.0, help="sweep seconds per instance (default 10)")
    return p


def runs_of(paths: list[Path]) -> list[Path]:
    """Every run folder (one holding metrics.json) among `paths` and their seed-<s>/ children."""
    found = []
    for path in paths:
        children = sorted(path.glob("seed-*/metrics.json"), key=lambda p: int(p.parent.name.split("-")[1]))
        if (path / "metrics.json").is_file():
            found.append(path)
        elif children:
            found += [c.parent for c in children]
        else:
            raise ValueError(f"{path} is not a training run (no metrics.json) nor a parent of seed-<s>/ runs")
    return found


def _json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: cannot be read ({err})") from None


def command(args: dict) -> tuple[float, tuple[float, float]]:
    """(commanded apex rise m, speed (vx, vy) m/s) a run is judged on: its evaluation's."""
    if args["task"] == "stand":
        return 0.0, (0.0, 0.0)
    return float(args["eval_height"]), tuple(float(v) for v in args["eval_speed"])


def sweep_measures(folder: Path, height: float) -> dict:
    """The worst gravity's survival, apex error (None without a commanded rise) and speed error of a finished
    sweep, and the survival at each of `COMPARED_GRAVITIES` (None: no sweep, or not that gravity)."""
    if not (folder / "summary.json").is_file():
        return {"survival": None, "apex_error": None, "speed_error": None,
                "compared_survival": [None] * len(COMPARED_GRAVITIES)}
    groups = _json(folder / "summary.json")["groups"]
    by_g = {g["gravity"]: g["survival"] for g in groups}
    apex = [g.get("apex_height") for g in groups]
    speed = [g.get("tracking_error") for g in groups]
    return {
        "survival": min(g["survival"] for g in groups),
        "apex_error": None if not height > 0 else (max(abs(a / height - 1) for a in apex)
                                                   if all(a is not None for a in apex) else float("inf")),
        "speed_error": max(speed) if all(s is not None for s in speed) else float("inf"),
        "compared_survival": [by_g.get(g) for g in COMPARED_GRAVITIES],
    }


def gap(core: Path, trained: Path, height: float) -> dict:
    """The largest difference between the core's sweep and the training physics' at `COMPARED_GRAVITIES`: in
    survival (a fraction) and in the apex rise, as a fraction of the command (None without one); None where a
    sweep is missing."""
    if not ((core / "summary.json").is_file() and (trained / "summary.json").is_file()):
        return {"survival_gap": None, "apex_gap": None}
    by_g = [{g["gravity"]: g for g in _json(folder / "summary.json")["groups"]} for folder in (core, trained)]
    rows = [(by_g[0].get(g), by_g[1].get(g)) for g in COMPARED_GRAVITIES]
    rows = [(a, b) for a, b in rows if a is not None and b is not None]
    apexes = [(a.get("apex_height"), b.get("apex_height")) for a, b in rows]
    # A gravity with a hop to measure on one side only is an unbounded gap; on neither (all down in both), none.
    apex = [float("inf") if a is None or b is None else abs(a - b) / height
            for a, b in apexes if a is not None or b is not None]
    return {"survival_gap": max((abs(a["survival"] - b["survival"]) for a, b in rows), default=None),
            "apex_gap": None if not height > 0 else max(apex, default=None)}


def run_sweep(controller: str, folder: Path, height: float, speed, num: int, duration: float,
              ground: str = "flat", as_trained: str | None = None) -> None:
    """The kicked gravity sweep of `controller` into `folder` on `ground` (a --terrain spec; resumes a cut-short
    one), by the sweep's own command; `as_trained` (all, timestep or solver): on that of the physics the policy was
    trained on."""
    from hopper_mjx.sweep.__main__ import main as sweep

    argv = ["gravity", "--controller", controller, "--num", str(num), "--duration", str(duration),
            "--height", str(height), "--speed", f"{speed[0]},{speed[1]}", "--terrain", ground, "--out", str(folder),
            "--no-progress"] + ([f"--as-trained={as_trained}"] if as_trained else [])
    if sweep(argv) != 0:
        raise ValueError(f"the sweep of {controller} into {folder} failed")


def run_records(run: Path, do_sweep: bool, num: int, duration: float) -> list[dict]:
    """One run's records, one per ground it is judged on (`curriculum.judge_grounds`: its own; a course's, rough
    ground and a block ahead), each swept into its own folder (the first `SWEEP`, the others `SWEEP-<i>`); the
    training physics' sweeps and the gap on the first only."""
    from hopper_mjx.envs.curriculum import judge_grounds

    record = _json(run / "metrics.json")
    grounds = judge_grounds(record["args"].get("terrain") or "flat")  # runs before the option: flat
    first = run_record(run, record, do_sweep, num, duration, grounds[0])
    height, speed = command(record["args"])
    others = []
    for i, ground in enumerate(grounds[1:], start=2):
        folder = run / f"{SWEEP}-{i}"
        if do_sweep and not (folder / "summary.json").is_file():
            run_sweep(f"policy:{run}", folder, height, speed, num, duration, ground)
        blank = {k: None for k in (*(f"trained_{k}" for k in sweep_measures(folder, height)), *GAP)}
        others.append({**first, **sweep_measures(folder, height), **blank, "parts": {}, "ground": ground})
    return [first, *others]


def run_record(run: Path, record: dict, do_sweep: bool, num: int, duration: float, ground: str) -> dict:
    """One run's row on `ground` (a --terrain spec), from its `record` (metrics.json): its task, algorithm, seed
    and measures."""
    args = record["args"]
    height, speed = command(args)
    found = _json(run / "threshold.json") if (run / "threshold.json").is_file() else None
    rates = [r["training/sps"] for r in record["history"] if r.get("training/sps")]
    if do_sweep and not (run / SWEEP / "summary.json").is_file():
        run_sweep(f"policy:{run}", run / SWEEP, height, speed, num, duration, ground)
    if do_sweep and not (run / TRAINED / "summary.json").is_file():
        run_sweep(f"policy:{run}", run / TRAINED, height, speed, num, duration, ground, as_trained="all")
    trained = {f"trained_{k}": v for k, v in sweep_measures(run / TRAINED, height).items()}
    gaps = gap(run / SWEEP, run / TRAINED, height)
    parts = {}
    if over(gaps):  # which part of the training physics makes it: each alone, the other the core's
        for part in PARTS:
            folder = run / f"{TRAINED}-{part}"
            if do_sweep and not (folder / "summary.json").is_file():
                run_sweep(f"policy:{run}", folder, height, speed, num, duration, ground, as_trained=part)
            parts[part] = gap(run / SWEEP, folder, height)
    return {"run": str(run), "task": args["task"], "algo": args["algo"], "seed": args["seed"], "ground": ground,
            "scanned": (run / "threshold.json").is_file(),
            "minutes_to_threshold": None if found is None else found["wall_time"] / 60,
            # steps too: a seed's steps are the same on any machine, its minutes are not
            "steps_to_threshold": None if found is None else found["step"],
            "steps_per_s": statistics.median(rates) if rates else None,
            "curve": [(r["wall_time"] / 60, r["eval/episode_reward"]) for r in record["history"]
                      if "eval/episode_reward" in r],
            **sweep_measures(run / SWEEP, height), **trained, **gaps, "parts": parts,
            "training": training_physics(run), "learner": {k: args.get(k) for k in LEARNER},
            "config": sorted(args.get("config") or []),  # --config's task fields (the scan ablation's switch)
            "trained_ground": trained_ground(args),
            "height": height, "speed": list(speed),
            "physics": list(physics_of(args).described().values())}


def trained_ground(args: dict) -> str:
    """The --terrain a run trained on where it is not its task's own ground ("" where it is)."""
    from hopper_mjx import terrain
    from hopper_mjx.envs import tasks

    trained = str(physics_of(args).ground)
    return "" if trained == str(terrain.parse(tasks.default_config(args["task"]).terrain or "flat")) else trained


def training_physics(run: Path) -> str:
    """The step and solver cap a run's policy was trained on, in words ("" for a run without its policy/)."""
    from hopper_mjx.envs import policy

    if not (run / "policy" / "hopper_env.json").is_file():
        return ""
    config = policy.read(run / "policy")[3]  # JSON only
    return f"{config.timestep * 1e3:g} ms step, solver ≤ {config.solver_iterations} iterations"


def over(gaps: dict) -> bool:
    """A gap past `GAP` in survival or apex."""
    return any(gaps.get(k) is not None and gaps[k] > limit for k, limit in GAP.items())


def spread(values, fmt: str) -> str:
    """'median [min-max]' of the defined values; n/a if none."""
    values = [v for v in values if v is not None]
    if not values:
        return "n/a"
    show = lambda v: format(v, fmt) if math.isfinite(v) else "∞"  # an error with no survivor or hop to measure
    text = show(statistics.median(values))
    return text if len(values) == 1 else f"{text} [{show(min(values))}–{show(max(values))}]"


HEADER = ("| task × algorithm | seeds | at threshold | min to threshold | M steps to threshold | env steps/s "
          "| worst survival: training / core | worst apex error: training / core | worst speed error m/s "
          "| training → core gap at Earth, Mars, Moon: survival, apex | core survival at Earth / Mars / Moon "
          "|\n|---|---|---|---|---|---|---|---|---|---|---|")


def _millions(steps):
    return None if steps is None else steps / 1e6


def _setting(key: str, value) -> str:
    """A learner setting as a row's name says it."""
    if key == "start_from":
        return f", started from {Path(value).name}'s policy" if value else ", from its own start"
    if key == "sac_hold_policy":
        return f", SAC policy held for its first {value:,} env steps" if value else ", SAC policy not held"
    if key == "sac_anchor":
        return f", SAC policy anchored to its start, weight {value:g}" if value else ", SAC policy not anchored"
    if key == "sac_policy_lr":
        return f", SAC policy learning rate {value:g}" if value else ", SAC policy at the critic's learning rate"
    return f", {LEARNER[key]} {value}"


def rows_of(records: list[dict]) -> list[tuple[str, list[dict]]]:
    """The table's rows, (name, runs): one per task x algorithm x training physics x the learner's settings
    (`LEARNER`), named by the task, the algorithm, the physics and the settings its runs differ in from the
    other rows of the same task, algorithm and physics."""
    physics = lambda r: (r["task"], r["algo"], r.get("training", ""))
    config = lambda r: " ".join(r.get("config", []))
    settings = lambda r: (tuple(sorted((k, str(v)) for k, v in r.get("learner", {}).items())), config(r),
                          r.get("trained_ground", ""))
    grounds = lambda rs: list(dict.fromkeys(r.get("ground", "flat") for r in rs))  # in the runs' judging order
    rows = []
    for group in sorted({physics(r) for r in records}):
        runs = [r for r in records if physics(r) == group]
        varied = [k for k in LEARNER if len({str(r.get("learner", {}).get(k)) for r in runs}) > 1]
        configs = len({config(r) for r in runs}) > 1
        for own in sorted({settings(r) for r in runs}):
            mine = [r for r in runs if settings(r) == own]
            learner = mine[0].get("learner", {})
            said = "".join(_setting(k, learner.get(k)) for k in varied if k != "start_from")
            if "start_from" in varied or learner.get("start_from"):  # said always: another's start
                said += _setting("start_from", learner.get("start_from"))
            if mine[0].get("trained_ground"):  # said always: not the ground the task trains on
                said += f", on {mine[0]['trained_ground']}"
            if config(mine[0]):  # said always: not the task's own config
                said += f", --config {config(mine[0])}"
            elif configs:
                said += ", the task's own config"
            on = f", trained on a {group[2]}" if group[2] else ""
            several = len(grounds(mine)) > 1  # judged on several grounds (a course's): a row for each
            for ground in grounds(mine):
                judged = f", judged on {ground}" if several else ""
                rows.append((f"{group[0]} × {group[1].upper()}{on}{said}{judged}",
                             [r for r in mine if r.get("ground", "flat") == ground]))
    return rows


def table(records: list[dict], references: dict) -> str:
    lines = [HEADER]
    for name, rows in rows_of(records):
        reached = sum(r["minutes_to_threshold"] is not None for r in rows)
        scanned = sum(r["scanned"] for r in rows)
        lines.append(f"| {name} | {len(rows)} "
                     f"| {reached} of {scanned} scanned "
                     f"| {spread([r['minutes_to_threshold'] for r in rows], '.1f')} "
                     f"| {spread([_millions(r['steps_to_threshold']) for r in rows], '.2f')} "
                     f"| {spread([r['steps_per_s'] for r in rows], ',.0f')} "
                     f"| {spread([r['trained_survival'] for r in rows], '.0%')} / "
                     f"{spread([r['survival'] for r in rows], '.0%')} "
                     f"| {spread([r['trained_apex_error'] for r in rows], '.0%')} / "
                     f"{spread([r['apex_error'] for r in rows], '.0%')} "
                     f"| {spread([r['speed_error'] for r in rows], '.3f')} | {gap_cell(rows)} "
                     f"| {compared_cell(rows)} |")
    for task, ref in sorted(references.items()):
        lines.append(f"| {task} × {ref['controller']} (reference) | — | — | — | — | — "
                     f"| {spread([ref['survival']], '.0%')} | {spread([ref['apex_error']], '.0%')} "
                     f"| {spread([ref['speed_error']], '.3f')} | — | {compared_cell([ref])} |")
    return "\n".join(lines)


def compared_cell(rows: list[dict]) -> str:
    """The core's survival at Earth, Mars and the Moon, each over the row's seeds (a judged ground's survival per
    gravity: the honest threshold asks for every robot up at each)."""
    return " / ".join(spread([r["compared_survival"][i] for r in rows], ".0%") for i in range(len(COMPARED_GRAVITIES)))


def _worst(gaps: list[dict]) -> dict:
    return {k: max((g[k] for g in gaps if g.get(k) is not None), default=None) for k in GAP}


def _gap_text(worst: dict) -> str:
    """'survival, apex' of a worst gap, in points and % of the command."""
    apex = "n/a" if worst["apex_gap"] is None else format(worst["apex_gap"], ".0%")
    return f"{worst['survival_gap']:.0%}, {apex}"


def gap_cell(rows: list[dict]) -> str:
    """The largest gap over a row's seeds and whether it is within `GAP` (n/a without both sweeps); over it, which
    part of the training physics makes it, from the sweeps on each part alone (`PARTS`)."""
    worst = _worst(rows)
    if worst["survival_gap"] is None:
        return "n/a"
    if not over(worst):
        return f"{_gap_text(worst)}: within"
    alone = {part: _worst([r["parts"][part] for r in rows if part in r.get("parts", {})]) for part in PARTS}
    alone = {part: w for part, w in alone.items() if w["survival_gap"] is not None}
    if not alone:
        return f"{_gap_text(worst)}: **over**: the training physics differs"
    causes = [PARTS[part] for part, w in alone.items() if over(w)]
    said = "; ".join(f"{PARTS[part]} alone {_gap_text(w)}" for part, w in alone.items())
    return f"{_gap_text(worst)}: **over**: {'from the ' + ' and '.join(causes) if causes else 'neither alone'} ({said})"


def physics_of(args: dict):
    """The `Physics` a run trained on, from its recorded options (a run older than an option: its default)."""
    from hopper_mjx import terrain
    from hopper_mjx.scenario import Physics
    from hopper_mjx.variation.spec import Spec

    return Physics(urdf=args.get("urdf"), ground=terrain.parse(args.get("terrain") or "flat"),
                   variation=Spec.parse(args["randomize"]) if args.get("randomize") else None,
                   engine=args.get("engine", registry.DEFAULT_ENGINE), motor=args.get("motor", registry.DEFAULT_MOTOR),
                   action_delay=args.get("action_delay", 0.0) / 1e3,
                   push=tuple(args["push"]) if args.get("push") else None)


def _lines(parts: list[str], sep: str, width: int) -> str:
    """The parts joined by `sep`, a new line begun between two parts (never within one) once a line passes `width`."""
    lines = [""]
    for part in parts:
        if lines[-1] and len(lines[-1]) + len(sep) + len(part) > width:
            lines[-1] += sep.rstrip()
            lines.append(part)
        else:
            lines[-1] += (sep if lines[-1] else "") + part
    return "\n".join(lines)


def figure(records: list[dict]):
    """Every seed's evaluation reward against training minutes (a matplotlib Figure), a colour per task x
    algorithm; the physics every run shared in the subtitle, a group's own in its legend entry."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    shared = [w for w in records[0]["physics"] if all(w in r["physics"] for r in records)]
    # A course's run is a record per ground it is judged on, all with its one training curve: each run's first only,
    # so that rows_of names its row without a ground.
    first = {}
    for r in records:
        first.setdefault(r.get("run", id(r)), r)
    for colour, (name, rows) in zip(plt.rcParams["axes.prop_cycle"].by_key()["color"] * 4, rows_of([*first.values()])):
        for i, r in enumerate(rows):  # a row of the table
            t, reward = zip(*r["curve"]) if r["curve"] else ((), ())
            own = "".join(f"; {w}" for w in r["physics"] if w not in shared)
            label = _lines(f"{name}{own}".split(", "), ", ", 90)  # a row named by many settings: several lines
            ax.plot(t, reward, "o-", ms=3, color=colour, alpha=0.8, label=label if i == 0 else None)
    ax.set_xlabel("training wall time (min)")
    ax.set_ylabel("episode reward (1, summed per episode)")
    ax.set_title(f"every seed's curve: the mean over its evaluation episodes\n"
                 f"{_lines(shared, '; ', 100)}", fontsize=9)
    ax.grid(alpha=0.3)
    # Below the axes, where long row names neither cover the curves nor squeeze the plot.
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0, -0.15))
    return fig


def plot(records: list[dict], path: Path) -> None:
    import matplotlib.pyplot as plt

    fig = figure(records)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def build(paths: list[Path], out: Path, *, do_sweep: bool, num: int, duration: float) -> str:
    """Reads (and with `do_sweep` sweeps) every run, writes OUT (.md), OUT .json and OUT .png; returns the table."""
    records = [r for run in runs_of(paths) for r in run_records(run, do_sweep, num, duration)]
    references = {}
    pairs = list(dict.fromkeys((r["task"], r["ground"]) for r in records))  # in the runs' judging order
    for task, ground in pairs:
        first = next(r for r in records if r["task"] == task and r["ground"] == ground)
        ref = registry.TASK_REFERENCES[task]
        height = first["height"] if ref.height is None else ref.height  # stand's runs command no apex
        grounds = [g for t, g in pairs if t == task]  # a course's runs: each judge ground its own reference
        index = grounds.index(ground)
        folder = out.parent / (f"reference-{task}" + (f"-{index + 1}" if index else ""))
        if do_sweep and not (folder / "summary.json").is_file():
            run_sweep(ref.controller, folder, height, first["speed"], num, duration, ground)
        name = task + (f", on {ground}" if len(grounds) > 1 else "")
        references[name] = {"controller": f"{ref.controller} at {height:g} m", "height": height,
                            **sweep_measures(folder, height)}
    text = table(records, references)
    out.write_text(f"{text}\n")
    out.with_suffix(".json").write_text(json.dumps({"runs": records, "references": references}, indent=1))
    plot(records, out.with_suffix(".png"))
    return text


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        cli.check_writable("--out", args.out, suffixes=(".md",))
        if is_device(args.out):  # the table's .json and .png are named after it, beside it
            raise ValueError(f"--out {args.out}: results.py writes its .json and .png beside the table, named after "
                             "it; give a file name ending in .md")
        if args.num < 1 or not args.duration > 0:
            raise ValueError("--num must be >= 1 and --duration > 0 s")
        runs_of(args.runs)
    except ValueError as err:
        return cli.fail(err)
    from hopper_mjx.shell import jaxsetup

    jaxsetup.configure()
    try:
        print(build(args.runs, args.out, do_sweep=args.sweep, num=args.num, duration=args.duration))
    except ValueError as err:
        return cli.fail(err)
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
