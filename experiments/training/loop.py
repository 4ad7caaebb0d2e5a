"""One training run: resume from the latest checkpoint, train, record every evaluation (metrics.json, TensorBoard),
copy the final policy, plot the reward curve (`train`)."""

from __future__ import annotations

import json
import math
import shutil
import textwrap
import time
from pathlib import Path

from hopper_mjx import cli
from hopper_mjx.metrics.thresholds import APEX_TOLERANCE, MIN_HOPS, SPEED_TOLERANCE  # noqa: F401 (one definition)
from hopper_mjx.shell import files, process
from hopper_mjx.shell.files import atomic_write_text
from training.learners import learner_settings, networks, run_ppo, run_sac, task_config
from training.options import HISTORY, check, latest_checkpoint, read_history, start_of

# A course's curriculum: Brax's names for the means over the last finished training episodes (its buffer of 100) of
# their summed level (`envs.monoped.LEVEL_METRIC`, the level times the length) and of their length; the history's
# name for the one over the other, the mean level of those episodes' env steps.
TRAINING_LEVEL, TRAINING_LENGTH = "episode/level", "episode/length"
LEVEL = "training/level"
# Brax's evaluation reports the same metric for its episodes, each a first episode drawn afresh (no curriculum
# carries over between them): the level a course starts at, not progress. Not filed.
EVAL_LEVEL = "eval/episode_level"


def training_log(metrics: dict, carried: dict) -> bool:
    """Whether `metrics` is Brax's log of finished training episodes, which comes between evaluations; if so, the
    mean curriculum level of its episodes' steps goes into `carried`, to be filed with the next evaluation's row."""
    if TRAINING_LEVEL not in metrics:
        return False
    carried[LEVEL] = float(metrics[TRAINING_LEVEL]) / float(metrics[TRAINING_LENGTH])
    return True


def evaluation_metrics(metrics: dict) -> dict:
    """What an evaluation's row files of Brax's metrics: its evaluation's and the training's steps/s."""
    return {k: float(v) for k, v in metrics.items() if k.startswith(("eval/", "training/sps"))
            and not k.startswith(EVAL_LEVEL)}  # its mean and its _std


class OutOfTime(Exception):
    """The --minutes budget is spent: training stops after the evaluation that found it so."""


def train(args, physics=None) -> dict:
    """Trains (or resumes) as the arguments say on `physics` (`check`'s, checked here when not given);
    returns the metrics record also saved to metrics.json."""
    import jax

    from hopper_mjx.envs import policy, tfevents

    physics = check(args) if physics is None else physics
    out = Path(args.out).resolve()  # orbax writes checkpoints to absolute paths only
    devices = jax.local_device_count()
    if args.num_envs % devices:
        raise ValueError(f"--num-envs={args.num_envs} must be a multiple of the {devices} local devices")
    if args.algo == "ppo" and (args.batch_size * args.num_minibatches) % args.num_envs:
        raise ValueError("--batch-size x --num-minibatches must be a multiple of --num-envs")
    cli.make_folder("--out", out)
    process.on_stop(f"the checkpoints are saved in {out / 'checkpoints'}; rerun the same command to resume")
    env = task_config(args, physics)
    config = env.config
    factory, checkpoint = networks(args)
    network_config = checkpoint.network_config(env.observation_size, env.action_size, True, factory)

    record_path = out / HISTORY
    record = read_history(record_path) if record_path.exists() else {"history": [], "wall_time": 0.0}
    record.update(args={**vars(args), **learner_settings(args)}, env_config=config.to_dict())
    resume = latest_checkpoint(out)
    start_step = resume[1] if resume else 0
    remaining = args.timesteps - start_step
    if resume:
        print(f"resuming from {resume[0]} (step {start_step:,})", flush=True)
    elif start_of(args) is not None:  # SAC restores a normaliser and a policy, a PPO checkpoint's first two
        resume = (policy.resolve(start_of(args)), 0)
        print(f"starting SAC's policy from {resume[0]}", flush=True)
    started, wall_before = time.perf_counter(), record["wall_time"]
    board = tfevents.EventWriter(out / "tensorboard")  # the same curves for TensorBoard: tensorboard --logdir OUT

    trained = {}  # the latest log of finished training episodes (a course's curriculum level), for the next row

    def progress(step, metrics):
        if training_log(metrics, trained):
            return
        row = {"step": start_step + int(step), "wall_time": wall_before + time.perf_counter() - started,
               **evaluation_metrics(metrics), **trained}
        record["history"].append(row)
        board.scalars(row["step"], {k: v for k, v in row.items() if k not in ("step", "wall_time")})
        record["wall_time"] = row["wall_time"]
        atomic_write_text(record_path, json.dumps(record, indent=1))
        print(f"step {row['step']:>10,} | reward {row.get('eval/episode_reward', math.nan):8.1f} | "
              f"episode {row.get('eval/avg_episode_length', math.nan):5.0f} steps | "
              f"{row.get('training/sps', math.nan):6.0f} steps/s | {row['wall_time'] / 60:5.1f} min"
              + (f" | level {row[LEVEL]:.2f}" if LEVEL in row else ""), flush=True)
        # Brax files an evaluation's checkpoint before reporting it, so stopping here keeps it.
        if args.minutes is not None and step > 0 and row["wall_time"] >= 60 * args.minutes:
            raise OutOfTime

    def save_checkpoint(step, params):
        if step > 0:
            step = start_step + int(step)
            folder = out / "checkpoints" / f"{step:012d}"
            if folder.exists() and not (folder / policy.ENV_CONFIG).exists():
                shutil.rmtree(folder)  # an earlier run was stopped while saving it
            with files.partial(folder):  # complete once its task config is beside it (latest_checkpoint)
                try:
                    checkpoint.save(out / "checkpoints", step, params, network_config)
                    policy.write_env_config(folder, config)
                except BaseException:  # a full disk: neither the checkpoint nor orbax's temporary folder stays
                    shutil.rmtree(folder, ignore_errors=True)
                    for tmp in folder.parent.glob(f"{folder.name}.orbax-checkpoint-tmp*"):
                        shutil.rmtree(tmp, ignore_errors=True)
                    raise

    out_of_time = args.minutes is not None and record["wall_time"] >= 60 * args.minutes
    if remaining > 0 and not out_of_time:
        run = run_ppo if args.algo == "ppo" else run_sac
        try:
            run(args, env, factory, remaining, start_step, resume, progress, save_checkpoint)
        except OutOfTime:
            print(f"stopped: {args.minutes:g} min of training (--minutes)", flush=True)
    board.close()
    final = latest_checkpoint(out)
    if final is None:
        raise ValueError(f"no checkpoint was written under {out / 'checkpoints'}")
    with files.partial(out / "policy"):
        shutil.rmtree(out / "policy", ignore_errors=True)
        shutil.copytree(final[0], out / "policy")
    record["final_step"] = final[1]
    atomic_write_text(record_path, json.dumps(record, indent=1))
    title = (f"{args.algo.upper()} on {args.task} ({config.timestep * 1e3:g} ms physics step, solver ≤ "
             f"{config.solver_iterations} iterations)")
    plot_rewards(out / "reward_curve.png", record["history"], title, physics, config.policy_rate, args.num_eval_envs)
    return record


def reward_figure(history: list[dict], title: str, physics, policy_rate: float, episodes: int):
    """The evaluation reward against environment steps (a matplotlib Figure): the mean over the `episodes`
    evaluation episodes, ± 1 standard deviation shaded where recorded; the subtitle `physics` in words."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    rows = [r for r in history if "eval/episode_reward" in r]
    step = np.array([r["step"] for r in rows])
    mean = np.array([r["eval/episode_reward"] for r in rows])
    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    ax.plot(step, mean, "o-", label=f"mean over {episodes} evaluation episodes")
    if rows and all("eval/episode_reward_std" in r for r in rows):  # Brax's, beside each mean
        std = np.array([r["eval/episode_reward_std"] for r in rows])
        ax.fill_between(step, mean - std, mean + std, alpha=0.25, lw=0, label="± 1 standard deviation over them")
    ax.set_xlabel(f"environment steps (policy steps, {policy_rate:g} Hz)")
    ax.set_ylabel("episode reward (1, summed per episode)")
    subtitle = textwrap.fill("; ".join(physics.described().values()), 110)  # a course's spec is long
    ax.set_title(f"{title}, the batched monoped\n{subtitle}", fontsize=9)
    handles = ax.get_legend_handles_labels()
    levels = [r for r in history if LEVEL in r]
    if levels:  # a course: the curriculum's level beside the reward
        twin = ax.twinx()
        twin.plot([r["step"] for r in levels], [r[LEVEL] for r in levels], "s--", color="tab:green", ms=3,
                  label="mean curriculum level of training steps (last 100 episodes)")
        twin.set_ylabel("curriculum level (0 the easiest)")
        twin.set_ylim(bottom=0)
        handles = [a + b for a, b in zip(handles, twin.get_legend_handles_labels())]
    ax.legend(*handles, fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_rewards(path: Path, history: list[dict], title: str, physics, policy_rate: float, episodes: int) -> None:
    import matplotlib.pyplot as plt

    fig = reward_figure(history, title, physics, policy_rate, episodes)
    files.atomic_write(path, lambda f: fig.savefig(f, dpi=120, format=Path(path).suffix[1:] or None))
    plt.close(fig)
