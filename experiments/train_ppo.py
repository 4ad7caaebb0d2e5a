"""Brax PPO on the MJX monoped with per-environment gravity: hop to a commanded apex height.

    nice -n 5 python experiments/train_ppo.py --out runs/ppo30 --observe-gravity   # ~25 min on 2 CPU cores
    python experiments/train_ppo.py --out runs/ppo30 --observe-gravity   # again: resumes from the last checkpoint
    python experiments/train_ppo.py --out runs/ppo30 --observe-gravity --evaluate --eval-height 0.12  # vs Raibert
    python -m hopper_mjx.simulate --controller policy:runs/ppo30 --gravity 9.81,3.71,1.62 --duration 10

Writes into --out: checkpoints/<env step>/ (every evaluation), policy/ (the final
params, loadable by `hopper_mjx.envs.policy`), metrics.json (arguments, env config,
one record per evaluation, wall time) and reward_curve.png.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import shutil
import sys
import time
from pathlib import Path

from hopper_mjx import runtime

HISTORY = "metrics.json"


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="runs/ppo", help="output folder (resumes if it holds checkpoints)")
    p.add_argument("--timesteps", type=int, default=8_000_000, help="total environment steps (policy steps)")
    p.add_argument("--num-envs", type=int, default=256, help="parallel environments (a multiple of the devices)")
    p.add_argument("--episode-length", type=int, default=500, help="policy steps per episode (500 = 10 s at 50 Hz)")
    p.add_argument("--eval-every", type=int, default=400_000, help="environment steps between evaluations")
    p.add_argument("--num-eval-envs", type=int, default=64)
    p.add_argument("--unroll-length", type=int, default=20)
    p.add_argument("--batch-size", type=int, default=128)
    p.add_argument("--num-minibatches", type=int, default=8)
    p.add_argument("--updates-per-batch", type=int, default=4)
    p.add_argument("--learning-rate", type=float, default=3e-4)
    p.add_argument("--entropy-cost", type=float, default=1e-2)
    p.add_argument("--discounting", type=float, default=0.99)
    p.add_argument("--policy-layers", default="64,64,64", help="hidden layer sizes of the policy MLP")
    p.add_argument("--value-layers", default="128,128,128", help="hidden layer sizes of the value MLP")
    p.add_argument("--gravity-range", default="1.0,12.0", help="low,high m/s², drawn log-uniformly per environment")
    p.add_argument("--observe-gravity", action="store_true", help="put the gravity magnitude in the observation")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--evaluate", action="store_true",
                   help="afterwards, run the policy and the Raibert controller in the core at --eval-gravity "
                        "for --eval-duration s and compare their hop metrics (evaluation.json / .md)")
    p.add_argument("--eval-gravity", default="9.81,3.71,1.62", help="m/s², comma-separated")
    p.add_argument("--eval-duration", type=float, default=10.0, help="s of simulated time")
    p.add_argument("--eval-height", type=float, default=0.2, help="commanded apex rise above standing, m")
    p.add_argument("--eval-num", type=int, default=4, help="instances per gravity (initial kicks differ)")
    return p


def _layers(text: str) -> tuple[int, ...]:
    sizes = tuple(int(v) for v in text.split(",") if v.strip())
    if not sizes or min(sizes) < 1:
        raise ValueError(f"layer sizes must be positive integers, got {text!r}")
    return sizes


def _pair(text: str, what: str) -> tuple[float, float]:
    values = tuple(float(v) for v in text.split(","))
    if len(values) != 2:
        raise ValueError(f"{what} must be 'low,high', got {text!r}")
    return values


def latest_checkpoint(out: Path) -> tuple[Path, int] | None:
    """The newest complete checkpoint under out/checkpoints, and its env step."""
    from hopper_mjx.envs.policy import ENV_CONFIG

    done = [p for p in (out / "checkpoints").glob("[0-9]" * 12) if (p / ENV_CONFIG).exists()]
    if not done:
        return None
    path = max(done, key=lambda p: int(p.name))
    return path, int(path.name)


def _run_ppo(args, env, config, factory, remaining: int, start_step: int, resume, progress, save_checkpoint) -> None:
    """Brax PPO for the `remaining` environment steps, resuming from `resume` (path, step) if given."""
    from brax.training.agents.ppo import train as ppo

    from hopper_mjx.envs import randomize_gravity

    per_train_step = args.batch_size * args.num_minibatches * args.unroll_length
    ppo.train(
        environment=env,
        num_timesteps=remaining,
        num_evals=max(1, math.ceil(remaining / max(args.eval_every, per_train_step))) + 1,
        episode_length=args.episode_length,
        num_envs=args.num_envs,
        num_eval_envs=args.num_eval_envs,
        deterministic_eval=True,
        randomization_fn=functools.partial(randomize_gravity, gravity_range=config.gravity_range),
        unroll_length=args.unroll_length,
        batch_size=args.batch_size,
        num_minibatches=args.num_minibatches,
        num_updates_per_batch=args.updates_per_batch,
        learning_rate=args.learning_rate,
        entropy_cost=args.entropy_cost,
        discounting=args.discounting,
        gae_lambda=0.95,
        clipping_epsilon=0.2,
        max_grad_norm=1.0,
        normalize_observations=True,
        network_factory=factory,
        seed=args.seed + start_step,  # a resumed run draws fresh environments
        restore_checkpoint_path=str(resume[0]) if resume else None,
        progress_fn=progress,
        policy_params_fn=save_checkpoint,
    )


def train(args) -> dict:
    """Trains (or resumes) as the arguments say; returns the metrics record also saved to metrics.json."""
    import jax
    from brax.training.agents.ppo import checkpoint as ppo_checkpoint
    from brax.training.agents.ppo import networks as ppo_networks

    from hopper_mjx.envs import MonopedConfig, MonopedEnv, policy

    out = Path(args.out).resolve()  # orbax writes checkpoints to absolute paths only
    out.mkdir(parents=True, exist_ok=True)
    devices = jax.local_device_count()
    if args.num_envs % devices:
        raise ValueError(f"--num-envs={args.num_envs} must be a multiple of the {devices} local devices")
    if (args.batch_size * args.num_minibatches) % args.num_envs:
        raise ValueError("--batch-size x --num-minibatches must be a multiple of --num-envs")
    config = MonopedConfig(gravity_range=_pair(args.gravity_range, "--gravity-range"),
                           observe_gravity=args.observe_gravity)
    env = MonopedEnv(config)
    factory = functools.partial(ppo_networks.make_ppo_networks,
                                policy_hidden_layer_sizes=_layers(args.policy_layers),
                                value_hidden_layer_sizes=_layers(args.value_layers))
    network_config = ppo_checkpoint.network_config(env.observation_size, env.action_size, True, factory)

    record_path = out / HISTORY
    record = json.loads(record_path.read_text()) if record_path.exists() else {"history": [], "wall_time": 0.0}
    record.update(args=vars(args), env_config=config.to_dict())
    resume = latest_checkpoint(out)
    start_step = resume[1] if resume else 0
    remaining = args.timesteps - start_step
    if resume:
        print(f"resuming from {resume[0]} (step {start_step:,})", flush=True)
    started, wall_before = time.perf_counter(), record["wall_time"]

    def progress(step, metrics):
        row = {"step": start_step + int(step), "wall_time": wall_before + time.perf_counter() - started,
               **{k: float(v) for k, v in metrics.items() if k.startswith(("eval/", "training/sps"))}}
        record["history"].append(row)
        record["wall_time"] = row["wall_time"]
        record_path.write_text(json.dumps(record, indent=1))
        print(f"step {row['step']:>10,} | reward {row.get('eval/episode_reward', math.nan):8.1f} | "
              f"episode {row.get('eval/avg_episode_length', math.nan):5.0f} steps | "
              f"apex {row.get('eval/episode_apex', math.nan):6.1f} | "
              f"{row.get('training/sps', math.nan):6.0f} steps/s | {row['wall_time'] / 60:5.1f} min", flush=True)

    def save_checkpoint(step, make_policy, params):
        if step > 0:
            policy.save(out / "checkpoints", start_step + int(step), params, network_config, config)

    if remaining > 0:
        _run_ppo(args, env, config, factory, remaining, start_step, resume, progress, save_checkpoint)
    final = latest_checkpoint(out)
    if final is None:
        raise ValueError(f"no checkpoint was written under {out / 'checkpoints'}")
    shutil.rmtree(out / "policy", ignore_errors=True)
    shutil.copytree(final[0], out / "policy")
    record["final_step"] = final[1]
    record_path.write_text(json.dumps(record, indent=1))
    plot_rewards(record["history"], out / "reward_curve.png")
    return record


COMPARED = ("survival", "hops", "apex_height", "hop_period", "tracking_error", "cost_of_transport")


def evaluation_batch(gravities, num: int, seed: int, nv: int):
    """(gravity magnitudes (n,), initial velocities (n, nv)): `num` instances per gravity, kicked
    exactly as a gravity sweep with this seed kicks its replicates (`sweep.grid.expand`)."""
    from hopper_mjx.sweep.grid import SweepSpec, expand

    spec = SweepSpec(kind="gravity", gravity=tuple(gravities), num=num, duration=1.0, height=0.0,
                     speed=(0.0, 0.0), seed=seed)
    instances = expand(spec, nv)
    return instances.gravity, instances.qvel


def evaluate(policy_path, *, gravities, duration: float, height: float, num: int, seed: int = 0) -> dict:
    """Hop metrics of the policy and of the Raibert controller, same batch, same commands.

    Each controller runs `num` instances per gravity for `duration` s in the core,
    from the standing pose with small random initial base velocities (the sweep's kicks).
    Returns {controller: {gravity: {metric: mean over instances}}}.
    """
    import numpy as np

    from hopper_mjx import metrics, model
    from hopper_mjx.control import raibert
    from hopper_mjx.envs import policy
    from hopper_mjx.sim import Sim, gravity_vectors
    from hopper_mjx.sweep.runner import SENSORS

    mj_model = model.load()
    sim = Sim(mj_model)
    g, kick = evaluation_batch(gravities, num, seed, sim.layout.nv)
    sensors = SENSORS  # the sweep's streams and kicks: the numbers compare with a sweep's
    controllers = {
        "policy": (policy.policy_controller(mj_model, policy_path),
                   policy.policy_params(sim.robot, len(g), height=height)),
        "raibert": (raibert.raibert(sim.robot), raibert.raibert_params(len(g), height=height)),
    }
    out = {}
    for name, (controller, params) in controllers.items():
        final, traj = sim.run(gravity_vectors(g), controller, params, duration=duration, sensors=sensors,
                              key=seed, qvel=kick)
        m = metrics.hop_metrics(traj, g, standing_height=sim.robot.standing_height,
                                work=np.asarray(final.cstate.work), mass=sim.layout.total_mass)
        m["survival"] = ~(m["fell"] | np.asarray(final.diverged))
        out[name] = {f"{v:g}": {**{k: _mean(m[k][g == v]) for k in COMPARED}, "min_hops": int(m["hops"][g == v].min())}
                     for v in gravities}
    return out


def _mean(values) -> float | None:
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


def plot_rewards(history: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in history if "eval/episode_reward" in r]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot([r["step"] for r in rows], [r["eval/episode_reward"] for r in rows], "o-")
    ax.set_xlabel("environment steps (50 Hz policy steps)")
    ax.set_ylabel("evaluation episode reward")
    ax.set_title("PPO on the MJX monoped, gravity 1-12 m/s²")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    runtime.configure()
    try:
        record = train(args)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}/policy (step {record['final_step']:,}), {HISTORY}, reward_curve.png; "
          f"{record['wall_time'] / 60:.1f} min of training")
    if args.evaluate:
        gravities = [float(v) for v in args.eval_gravity.split(",")]
        result = evaluate(Path(args.out) / "policy", gravities=gravities, duration=args.eval_duration,
                          height=args.eval_height, num=args.eval_num, seed=args.seed)
        table = evaluation_table(result, args.eval_height)
        (Path(args.out) / "evaluation.json").write_text(json.dumps(result, indent=1))
        (Path(args.out) / "evaluation.md").write_text(table + "\n")
        print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
