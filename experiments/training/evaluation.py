"""A trained policy judged in the core: kicked robots at the sweep's gravities, hop metrics against the task's
threshold (`evaluate`), every checkpoint scanned and the best selected (`scan_checkpoints`, `select_policy`), the
table."""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
from pathlib import Path

from hopper_mjx import registry
from hopper_mjx.metrics import thresholds
from hopper_mjx.metrics.thresholds import APEX_TOLERANCE, MIN_HOPS, SPEED_TOLERANCE  # noqa: F401 (one definition)
from hopper_mjx.shell.files import atomic_write_text
from training.options import HISTORY, parse_floats, read_history, start_params

SCAN = "scan.json"  # every scanned checkpoint's evaluation
SELECTION = "selection.json"  # which checkpoint policy/ holds, and why
COMPARED = ("survival", "hops", "apex_height", "hop_period", "tracking_error", "cost_of_transport")


def evaluation_batch(gravities, num: int, seed: int, nv: int):
    """(gravity magnitudes (n,), initial velocities (n, nv)): `num` instances per gravity, kicked
    exactly as a gravity sweep with this seed kicks its replicates (`sweep.grid.expand`)."""
    from hopper_mjx.sweep.grid import SweepSpec, expand

    spec = SweepSpec(kind="gravity", gravity=tuple(gravities), num=num, duration=1.0, height=0.0,
                     speed=(0.0, 0.0), seed=seed)
    instances = expand(spec, nv)
    return instances.gravity, instances.qvel


def evaluate(policy_path, physics, *, gravities, duration: float, height: float, num: int, seed: int = 0,
             speed=(0.0, 0.0), raibert_too: bool = True, reuse: dict | None = None) -> dict:
    """Hop metrics of the policy and (`raibert_too`) of the Raibert controller, same batch, same commands
    (Raibert at the policy task's reference apex when the task names one: stand's, `registry.TASK_REFERENCES`).

    Each controller runs `num` instances per gravity for `duration` s in the core,
    from the standing pose with small random initial base velocities (the sweep's kicks).
    `reuse`: a dict kept across calls (the scan's): the core and the policy controller, whose compiled rollout
    a policy of the same network and task config (another checkpoint of the run) runs with its own weights.
    Returns {controller: {gravity: {metric: mean over instances}}}.
    """
    import numpy as np

    from hopper_mjx.control import raibert
    from hopper_mjx.envs import policy
    from hopper_mjx.metrics import hops
    from hopper_mjx.sim import gravity_vectors
    from hopper_mjx.sweep.runner import recorded

    mj_model = physics.mj_model
    reuse = {} if reuse is None else reuse
    if "sim" not in reuse:  # the URDF's robot: `sweep compare --randomize` judges a policy on randomised ones
        reuse["sim"] = dataclasses.replace(physics, variation=None).sim()
    sim = reuse["sim"]
    g, kick = evaluation_batch(gravities, num, seed, sim.layout.nv)
    sensors = recorded(sim.layout.timestep)  # the sweep's streams and kicks: the numbers compare with a sweep's
    _, _, net, config = policy.read(policy_path)
    same = (json.dumps(net, sort_keys=True), json.dumps(config.to_dict(), sort_keys=True))
    if reuse.get("network") == same:
        controller = reuse["policy"].with_weights(policy.load_network(policy_path)[1])
    else:
        controller = reuse["policy"] = policy.policy_controller(mj_model, policy_path)
        reuse["network"] = same
    controllers = {"policy": (controller,
                              policy.policy_params(sim.robot, len(g), height=height, speed=speed, config=config))}
    if raibert_too:
        reference = registry.TASK_REFERENCES[config.task].height
        controllers["raibert"] = (raibert.raibert(sim.robot), raibert.raibert_params(
            len(g), height=height if reference is None else reference, speed=speed))
    out = {}
    for name, (controller, params) in controllers.items():
        final, traj = sim.run(gravity_vectors(g), controller, params, duration=duration, sensors=sensors,
                              key=seed, qvel=kick)
        m = hops.hop_metrics(traj, g, standing_height=sim.robot.standing_height, command_speed=speed,
                                work=np.asarray(final.cstate.work), mass=sim.layout.total_mass)
        m["survival"] = ~(m["fell"] | np.asarray(final.diverged))
        out[name] = {f"{v:g}": {**{k: mean_defined(m[k][g == v]) for k in COMPARED},
                                "min_hops": int(m["hops"][g == v].min())}
                     for v in gravities}
    return out


threshold = thresholds.describe


def meets_threshold(task: str, row: dict, height: float) -> bool:
    """Does one gravity's `evaluate` row meet the task's threshold (`hopper_mjx.metrics.thresholds`)?"""
    return thresholds.meets(task, row, height)


def scan_checkpoints(args, physics) -> list[dict]:
    """Every checkpoint's policy evaluated as --evaluate does (policy only), in step order, each with the
    training wall time at which it was saved; resumable (SCAN keeps those already run). Checkpoints whose
    Brax evaluation episodes lasted < 95 % of --episode-length already fell in training, and are not run (but on a
    course, whose evaluation episodes are on its tiles, not on the ground the core judges). Nor are checkpoints whose
    policy is still the one --start-from handed SAC (held by --sac-hold-policy): what they would show is the start's,
    not what SAC learned."""
    out = Path(args.out)
    start = start_params(args)
    start = None if start is None else start[1]  # the policy's parameters
    rows = {r["step"]: r for r in read_history(out / HISTORY)["history"]}
    gravities = list(dict.fromkeys(parse_floats(args.eval_gravity, "--eval-gravity")
                                   + parse_floats(args.select_gravity, "--select-gravity")))
    settings = {"gravities": gravities, "duration": args.eval_duration, "height": args.eval_height,
                "num": args.eval_num, "seed": args.seed, "speed": list(args.eval_speed)}
    saved = json.loads((out / SCAN).read_text()) if (out / SCAN).exists() else {}
    done = {s["step"]: s for s in saved.get("checkpoints", [])} if saved.get("settings") == settings else {}
    scanned, reuse = [], {}  # one core and one compiled rollout for every checkpoint
    # Brax's evaluation episodes fall on harder ground than the core judges a course's policy on: no skipping there.
    from hopper_mjx.envs.curriculum import is_course

    skips = not is_course(args.terrain)
    for path in sorted((out / "checkpoints").glob("[0-9]" * 12)):
        step = int(path.name)
        row = rows.get(step, {})
        if skips and row.get("eval/avg_episode_length", args.episode_length) < 0.95 * args.episode_length:
            continue
        if start is not None and same_policy(path, start):
            continue
        if step not in done:
            result = evaluate(path, physics, gravities=gravities, duration=args.eval_duration,
                              height=args.eval_height, num=args.eval_num, seed=args.seed, speed=args.eval_speed,
                              raibert_too=False, reuse=reuse)["policy"]
            done[step] = {"step": step, "wall_time": row.get("wall_time"), "evaluation": result}
            print(f"step {step:>10,} ({row.get('wall_time', math.nan) / 60:.1f} min): "
                  + ", ".join(f"g {g}: {r['survival']:.0%} alive, >= {r['min_hops']} hops"
                              for g, r in result.items()), flush=True)
        scanned.append(done[step])
        atomic_write_text(out / SCAN, json.dumps({"settings": settings, "checkpoints": scanned}, indent=1))
    return scanned


def same_policy(path: Path, params) -> bool:
    """Whether the checkpoint at `path` holds exactly the policy parameters `params`."""
    import jax
    import numpy as np
    from brax.training import checkpoint

    saved = jax.tree.leaves(checkpoint.load(path)[1])
    return len(saved) == len(jax.tree.leaves(params)) and all(
        np.array_equal(a, b) for a, b in zip(saved, jax.tree.leaves(params)))


def at_gravities(evaluation: dict, gravities: str, flag: str) -> dict:
    """The rows of a scanned `evaluation` at the comma-separated `gravities` (one option's)."""
    return {f"{g:g}": evaluation[f"{g:g}"] for g in parse_floats(gravities, flag)}


def first_at_threshold(task: str, scanned: list[dict], height: float, gravities: str) -> dict | None:
    """The first scanned checkpoint that meets the task's threshold at every one of `gravities` (--eval-gravity);
    None if none does."""
    for s in scanned:
        if all(meets_threshold(task, r, height) for r in at_gravities(s["evaluation"], gravities,
                                                                      "--eval-gravity").values()):
            return {**s, "threshold": threshold(task)}
    return None


def select_policy(args, scanned: list[dict]) -> dict | None:
    """Copies the best scanned checkpoint (`hopper_mjx.metrics.thresholds.best`) into policy/ and records the
    choice in SELECTION: its step, wall time, measures and rank."""
    out = Path(args.out)
    judged = [{**s, "evaluation": at_gravities(s["evaluation"], args.select_gravity, "--select-gravity")}
              for s in scanned]
    chosen = thresholds.best(args.task, judged, args.eval_height)
    if chosen is None:
        return None
    shutil.rmtree(out / "policy", ignore_errors=True)
    shutil.copytree(out / "checkpoints" / f"{chosen['step']:012d}", out / "policy")
    record = {**chosen, "rule": "most gravities at the threshold, then the worst gravity's survival, then its "
              "error over the threshold's bounds (hopper_mjx.metrics.thresholds.rank)",
              "rank": list(thresholds.rank(args.task, chosen["evaluation"], args.eval_height)),
              "gravities": list(chosen["evaluation"]), "threshold": threshold(args.task),
              "meets": all(meets_threshold(args.task, r, args.eval_height) for r in chosen["evaluation"].values())}
    atomic_write_text(out / SELECTION, json.dumps(record, indent=1))
    return record


def mean_defined(values) -> float | None:
    """Mean over instances of the defined (finite) values; None if there are none."""
    import numpy as np

    values = np.asarray(values, dtype=float)
    return float(values[np.isfinite(values)].mean()) if np.isfinite(values).any() else None


def evaluation_table(result: dict, height: float) -> str:
    """Markdown: one row per controller and gravity."""
    lines = [f"| controller | g (m/s²) | survival | hops (min) | apex rise (m, cmd {height:g}) | hop period (s) "
             "| speed error (m/s) | cost of transport |", "|---|---|---|---|---|---|---|---|"]
    fmt = lambda v, f: "n/a" if v is None else format(v, f)
    for name, by_g in result.items():
        for g, row in by_g.items():
            lines.append(f"| {name} | {g} | {fmt(row['survival'], '.0%')} | {fmt(row['hops'], '.1f')} "
                         f"({row['min_hops']}) | {fmt(row['apex_height'], '.3f')} | {fmt(row['hop_period'], '.3f')} "
                         f"| {fmt(row['tracking_error'], '.3f')} | {fmt(row['cost_of_transport'], '.2f')} |")
    return "\n".join(lines)
