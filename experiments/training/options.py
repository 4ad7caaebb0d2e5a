"""The training command's options (`parser`) and their checks, whole, before anything is built (`check`)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from hopper_mjx import cli, registry
from hopper_mjx.metrics.thresholds import APEX_TOLERANCE, MIN_HOPS, SPEED_TOLERANCE  # noqa: F401 (one definition)
from hopper_mjx.sweep.grid import DEFAULT_GRAVITY

HISTORY = "metrics.json"  # a run's record of its evaluations

ALGORITHMS = ("ppo", "sac")


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python experiments/train.py", __doc__)
    p.add_argument("--task", default="hop", help=registry.listed(registry.TASKS))
    p.add_argument("--algo", default="ppo", help="ppo or sac (Brax's agents)")
    p.add_argument("--out", default="runs/ppo", help="output folder (resumes if it holds checkpoints)")
    p.add_argument("--timesteps", type=int, default=8_000_000, help="total environment steps (policy steps)")
    p.add_argument("--minutes", type=float, default=None,
                   help="wall-time budget: stop at the first evaluation after this many minutes of training "
                        "(summed over resumes), with its checkpoint as the policy")
    p.add_argument("--num-envs", type=int, default=256, help="parallel environments (a multiple of the devices)")
    p.add_argument("--episode-length", type=int, default=500, help="policy steps per episode (500 = 10 s at 50 Hz)")
    p.add_argument("--eval-every", type=int, default=400_000,
                   help="environment steps between checkpoints (and Brax's evaluations)")
    p.add_argument("--no-eval", action="store_true",
                   help="PPO: no evaluation episodes, checkpoints only (metrics.json then holds training rates)")
    p.add_argument("--num-eval-envs", type=int, default=64)
    p.add_argument("--unroll-length", type=int, default=20)
    p.add_argument("--batch-size", type=int, default=128)
    p.add_argument("--num-minibatches", type=int, default=8)
    # 8 epochs over each batch and a value MLP as small as the policy's: seed 1 of hop met its threshold at 5.7 M
    # steps (3.4 min) where 4 epochs and a 128-128-128 value MLP needed 16.0 M (6.9 min; docs/learning-notebook.md).
    p.add_argument("--updates-per-batch", type=int, default=8, help="PPO: epochs over each batch (default 8)")
    # PPO at 6e-4: hop's three seeds met the honest threshold at a median 4.9 M steps where 3e-4 took 7.4 M, and
    # every seed's policy kept all its robots up at the nine sweep gravities (docs/learning-notebook.md).
    p.add_argument("--learning-rate", type=float, default=None,
                   help="Adam's step (PPO: the first one with --desired-kl; default 6e-4 for ppo, 3e-4 for sac)")
    p.add_argument("--desired-kl", type=float, default=None, metavar="KL",
                   help="PPO: adapt the learning rate after each update to keep the policy's KL step near KL "
                        "(x1.5 below KL/2, /1.5 above 2 KL, as legged_gym's PPO does); default: a fixed rate")
    # 1e-3, not Brax's usual 1e-2: on hop the 1e-2 exploration kept knocking the robot over (evaluation reward
    # collapsing 623 -> 100 and back), and no seed met the honest threshold in 8 M steps (docs/learning-notebook.md).
    p.add_argument("--entropy-cost", type=float, default=1e-3, help="PPO's entropy bonus (default 0.001)")
    p.add_argument("--discounting", type=float, default=0.99)
    # PPO at 0.1: hop's returns are some 200 at 1, and seeds 0 and 2 met the honest threshold at 10.6 M and 4.9 M
    # steps where 1 took 16.8 M and 12.3 M (0.02 left seed 0 hopping 70 % low; docs/learning-notebook.md).
    p.add_argument("--reward-scaling", type=float, default=None,
                   help="factor on the rewards the learner sees (its value targets scale with it; "
                        "default 0.1 for ppo, 1 for sac)")
    p.add_argument("--max-grad-norm", type=float, default=None,
                   help="PPO: clip the gradient of both networks together to this global norm (0: no clip; default 1)")
    p.add_argument("--policy-layers", default="64,64,64", help="hidden layer sizes of the policy MLP")
    p.add_argument("--value-layers", default="64,64,64", help="hidden layer sizes of the value MLP")
    p.add_argument("--gravity-range", default=None,
                   help="low,high m/s², drawn log-uniformly per episode (default: the task's, 0.5,12)")
    p.add_argument("--observe-gravity", action="store_true", help="put the gravity magnitude in the observation")
    p.add_argument("--policy-rate", type=float, default=None, metavar="HZ",
                   help="policy steps per second (default: the task's, 50); must divide the training's physics rate "
                        "(1000 Hz at the task's 1 ms step; --config timestep=... changes it). --episode-length "
                        "counts policy steps at this rate")
    p.add_argument("--config", action="append", default=[], metavar="KEY=VALUE",
                   help="set a field of the task's config (envs.task_config.MonopedConfig: reward weights and "
                        "kernels, command ranges, ...; a pair as low,high), e.g. --config apex_reward=flight; "
                        "repeatable. Saved with the policy")
    cli.add_physics_options(p, terrain=None, terrain_default="the task's own: hop_terrain's course (its policies are "
                                                             "judged on rough ground), flat for the others")
    p.add_argument("--sac-replay", type=int, default=1_000_000, help="SAC: replay buffer size (env steps)")
    p.add_argument("--sac-min-replay", type=int, default=8192, help="SAC: env steps collected before learning")
    p.add_argument("--sac-grad-updates", type=int, default=8, help="SAC: gradient updates per env step batch")
    p.add_argument("--start-from", default=None, metavar="RUN",
                   help="SAC: start the policy and its observation normaliser from RUN's trained policy (a PPO or "
                        "SAC run folder or checkpoint of the same task and observations; with --seeds a --seeds "
                        "parent, seed s from RUN/seed-<s>), its hidden layers and activation becoming SAC's; the Q "
                        "networks, temperature and replay start fresh. A folder with checkpoints of its own resumes "
                        "from them instead")
    p.add_argument("--sac-hold-policy", type=int, default=None, metavar="STEPS",
                   help="SAC: hold the policy as it is for the first STEPS env steps of learning, while the Q "
                        "networks and the temperature learn (a --start-from policy is otherwise pulled wherever "
                        "the fresh critic points); default none")
    p.add_argument("--sac-policy-lr", type=float, default=None, metavar="LR",
                   help="SAC: the policy's own Adam step (default --learning-rate, as the Q networks'); smaller "
                        "keeps a --start-from policy near its start while the fresh critic learns")
    p.add_argument("--sac-anchor", type=float, default=None, metavar="WEIGHT",
                   help="SAC: add WEIGHT x the squared distance between the policy's mean action and its "
                        "--start-from policy's to the policy's loss (a behaviour-cloning term towards the start); "
                        "default none")
    p.add_argument("--sac-target-entropy", type=float, default=None, metavar="NATS",
                   help="SAC: the policy entropy its temperature aims at (default Brax's, -0.5 per action: -1.5); "
                        "lower keeps less exploration noise in the joint targets")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--seeds", type=int, default=None, metavar="K",
                   help="train K seeds, --seed, --seed+1, ..., one after another, each into --out/seed-<s>/ "
                        "(each resumable as one run is; results.py builds the table from them)")
    _add_evaluation_options(p)
    return p


def _add_evaluation_options(p: argparse.ArgumentParser) -> None:
    """--evaluate's and --scan-checkpoints' options."""
    p.add_argument("--evaluate", action="store_true",
                   help="afterwards, run the policy and the Raibert controller in the core at --eval-gravity "
                        "for --eval-duration s and compare their hop metrics (evaluation.json / .md)")
    p.add_argument("--eval-gravity", default="9.81,3.71,1.62",
                   help="m/s², comma-separated: --evaluate's gravities, and the scan's threshold is met at all of them")
    # The table judges each seed's policy on the nine-gravity sweep: a policy chosen at three gravities only
    # (27 Nov) could rise 27 % too high at 0.5 m/s² with none of them telling.
    p.add_argument("--select-gravity", default=",".join(f"{g:g}" for g in DEFAULT_GRAVITY),
                   help="m/s², comma-separated: the scan also evaluates every checkpoint at these, and keeps the "
                        "one best at all of them (default: the gravity sweep's nine)")
    p.add_argument("--eval-duration", type=float, default=10.0, help="s of simulated time")
    p.add_argument("--eval-height", type=float, default=0.2, help="commanded apex rise above standing, m")
    p.add_argument("--eval-num", type=int, default=4, help="instances per gravity (initial kicks differ)")
    p.add_argument("--eval-speed", type=cli.floats("--eval-speed"), default=[0.0, 0.0],
                   help="commanded VX,VY m/s of the evaluation")
    p.add_argument("--scan-checkpoints", action="store_true",
                   help="afterwards, evaluate every checkpoint as --evaluate does (policy only; scan.json), "
                        "report the first that meets the task's threshold at every --eval-gravity (stand: "
                        f"every instance survives; hop and hop_velocity: and >= {MIN_HOPS} hops, apex within "
                        f"{APEX_TOLERANCE * 100:.0f} %%, drift or speed error <= {SPEED_TOLERANCE} m/s) in "
                        "threshold.json, and make policy/ the best at every --select-gravity (selection.json); "
                        "checkpoints whose Brax evaluation episodes ended early are skipped")


# The layer options each algorithm's network config records (`hopper_mjx.envs.policy.FACTORY_KEYS`).
LAYER_FLAGS = {"ppo": (("policy_layers", "policy_hidden_layer_sizes"), ("value_layers", "value_hidden_layer_sizes")),
               "sac": (("policy_layers", "hidden_layer_sizes"),)}


def parse_layers(text: str) -> tuple[int, ...]:
    sizes = tuple(int(v) for v in text.split(",") if v.strip())
    if not sizes or min(sizes) < 1:
        raise ValueError(f"layer sizes must be positive integers, got {text!r}")
    return sizes


def parse_floats(text: str, what: str) -> list[float]:
    try:
        return cli.parse_floats(text, what)
    except argparse.ArgumentTypeError as err:
        raise ValueError(str(err)) from None


def parse_pair(text: str, what: str) -> tuple[float, float]:
    values = tuple(parse_floats(text, what))
    if len(values) != 2 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what} must be two finite numbers 'low,high', got {text!r}")
    return values


def read_history(path: Path) -> dict:
    """A run's metrics record; one cut short (a kill mid-write, before writes were atomic) is refused in one line."""
    try:
        record = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise ValueError(f"--out: {path} is damaged (cut short?); move it away to train from the checkpoints "
                         "without the old history, or use another --out") from None
    if not isinstance(record, dict) or not isinstance(record.get("history"), list):
        raise ValueError(f"--out: {path} is not a training record (no history list)")
    return record


def latest_checkpoint(out: Path) -> tuple[Path, int] | None:
    """The newest complete checkpoint under out/checkpoints, and its env step."""
    from hopper_mjx.envs.policy import ENV_CONFIG

    done = [p for p in (out / "checkpoints").glob("[0-9]" * 12) if (p / ENV_CONFIG).exists()]
    if not done:
        return None
    path = max(done, key=lambda p: int(p.name))
    return path, int(path.name)


# Options Brax's SAC has no counterpart for, and why.
PPO_ONLY = {"desired_kl": "Brax's SAC has no adaptive learning rate", "max_grad_norm": "Brax's SAC does not clip its "
            "gradients"}


def _check_learner(args) -> None:
    """`check`'s part for the networks and the optimiser: raises ValueError naming the first bad argument."""
    for flag in ("policy_layers", "value_layers"):
        try:
            parse_layers(getattr(args, flag))
        except ValueError:
            raise ValueError(f"--{flag.replace('_', '-')} must be comma-separated positive integers (hidden layer "
                             f"sizes), got {getattr(args, flag)!r}") from None
    for flag, why in PPO_ONLY.items():
        if getattr(args, flag) is not None and args.algo != "ppo":
            raise ValueError(f"--{flag.replace('_', '-')} is for --algo ppo ({why})")
    cli.check_range("--discounting", args.discounting, low=0, high=1, open_low=True)  # a return's weight a step
    cli.check_range("--entropy-cost", args.entropy_cost, low=0)  # nan ran, its losses nan from the first update
    for flag, low, open_low in (("learning_rate", 0, True), ("desired_kl", 0, True), ("max_grad_norm", 0, False),
                                ("reward_scaling", 0, True)):
        if getattr(args, flag) is not None:
            cli.check_range(f"--{flag.replace('_', '-')}", getattr(args, flag), low=low, open_low=open_low)
    if args.sac_hold_policy is not None:
        if args.algo != "sac":
            raise ValueError("--sac-hold-policy is for --algo sac (PPO has no critic to wait for)")
        if args.sac_hold_policy < 0:
            raise ValueError(f"--sac-hold-policy must be >= 0 env steps, got {args.sac_hold_policy}")
    if args.sac_policy_lr is not None:
        if args.algo != "sac":
            raise ValueError("--sac-policy-lr is for --algo sac (PPO's policy and value share --learning-rate)")
        cli.check_range("--sac-policy-lr", args.sac_policy_lr, low=0, open_low=True)
    if args.sac_anchor is not None:
        if args.algo != "sac" or args.start_from is None:
            raise ValueError("--sac-anchor is for --algo sac with --start-from (it pulls the policy towards its start)")
        cli.check_range("--sac-anchor", args.sac_anchor, low=0)
    if args.sac_target_entropy is not None:
        if args.algo != "sac":
            raise ValueError("--sac-target-entropy is for --algo sac (PPO has no temperature; see --entropy-cost)")
        if not math.isfinite(args.sac_target_entropy):
            raise ValueError(f"--sac-target-entropy must be a finite number of nats, got {args.sac_target_entropy}")


def check(args):
    """The run's `scenario.Physics`; raises ValueError naming the first bad argument (JSON reads only,
    nothing is built)."""
    from hopper_mjx import envs

    try:
        registry.check("task", registry.TASKS, args.task)
    except ValueError as err:
        raise ValueError(f"--task: {err}") from None
    if args.algo not in ALGORITHMS:
        raise ValueError(f"--algo {args.algo!r} is unknown; choose from {', '.join(ALGORITHMS)}")
    if args.terrain is None:
        args.terrain = envs.default_config(args.task).terrain or "flat"
    physics = cli.check_physics(args)
    cli.refuse_each(physics.ground, "training")
    cli.check_controls(physics, registry.POLICY_PREFIX)  # a dc motor's drawn figures need --motor dc
    if args.gravity_range is not None:
        lo, hi = parse_pair(args.gravity_range, "--gravity-range")
        if not 0 < lo <= hi:
            raise ValueError(f"--gravity-range must be 0 < low <= high m/s², got {args.gravity_range!r}")
    _check_learner(args)
    for flag in ("num_envs", "timesteps", "episode_length", "eval_every", "num_eval_envs", "unroll_length",
                 "batch_size", "num_minibatches", "updates_per_batch", "eval_num", "sac_replay", "sac_grad_updates"):
        if getattr(args, flag) < 1:
            raise ValueError(f"--{flag.replace('_', '-')} must be >= 1, got {getattr(args, flag)}")
    cli.check_seed(args.seed)
    if args.seeds is not None:
        if args.seeds < 1:
            raise ValueError(f"--seeds must be >= 1, got {args.seeds}")
        cli.check_seed(args.seed + args.seeds - 1)
    try:
        config = envs.default_config(args.task).overridden(args.config, OWNED_FIELDS)
    except ValueError as err:
        raise ValueError(f"--config: {err}") from None
    check_task_physics(args, physics, config)
    run_config(args, physics, config)  # whole: --config against the other options (a scan zeroed on the plane)
    # The evaluation's options too: a mistake there would otherwise surface after the whole training run.
    for flag in ("--eval-gravity", "--select-gravity"):
        for g in parse_floats(getattr(args, flag[2:].replace("-", "_")), flag):
            cli.check_range(flag, g, low=0, open_low=True)
    cli.check_range("--eval-duration", args.eval_duration, low=0, open_low=True)
    cli.check_range("--eval-height", args.eval_height, low=0)
    if len(args.eval_speed) != 2 or not all(math.isfinite(v) for v in args.eval_speed):
        raise ValueError(f"--eval-speed needs two finite values VX,VY in m/s, got {args.eval_speed}")
    if args.minutes is not None and not (math.isfinite(args.minutes) and args.minutes > 0):
        raise ValueError(f"--minutes must be finite and > 0, got {args.minutes:g}")
    cli.check_writable("--out", args.out, folder=True, make_parents=True)  # runs/ need not exist yet
    if (Path(args.out) / HISTORY).exists():  # a resume's record must read, before the folder is taken
        read_history(Path(args.out).resolve() / HISTORY)
    if args.no_eval and args.algo != "ppo":
        raise ValueError("--no-eval is for --algo ppo (Brax's SAC evaluates at every checkpoint)")
    _check_start(args, physics)
    resume = latest_checkpoint(Path(args.out))
    if resume:  # a folder of another task or algorithm cannot be resumed into this one
        from hopper_mjx.envs import policy

        _, algo, net, config = policy.read(resume[0])
        size = observations(args, physics)
        differs = _differences(args, algo, config.task, net["observation_size"], size)
        if differs:
            raise ValueError(f"--out {args.out} holds a {algo} policy of task {config.task!r} with "
                             f"{net['observation_size']} observations; this run differs in {differs}: "
                             "use another --out")
        # Brax restores the checkpoint's parameters into networks of the asked sizes: they must be its sizes.
        kwargs = net["network_factory_kwargs"]
        for flag, key in LAYER_FLAGS[algo]:
            saved, asked, option = tuple(kwargs[key]), parse_layers(getattr(args, flag)), "--" + flag.replace("_", "-")
            if saved != asked:
                raise ValueError(f"--out {args.out} holds networks with {'-'.join(map(str, saved))} hidden layers "
                                 f"where {option} asks {'-'.join(map(str, asked))}: pass {option} "
                                 f"{','.join(map(str, saved))} to resume it, or use another --out")
    return physics


def start_of(args) -> Path | None:
    """The policy folder --start-from names for this run's seed: RUN itself, or a --seeds parent's seed-<s>/."""
    if args.start_from is None:
        return None
    from hopper_mjx.envs.policy import ENV_CONFIG

    start = Path(args.start_from)
    if (start / "policy").exists() or (start / ENV_CONFIG).exists() or not any(start.glob("seed-*")):
        return start
    return start / f"seed-{args.seed}"  # a --seeds parent; a seed it lacks is refused by name


def start_params(args):
    """The --start-from policy's (observation normaliser, policy parameters) for this run's seed; None without it."""
    start = start_of(args)
    if start is None:
        return None
    from brax.training import checkpoint

    from hopper_mjx.envs import policy

    return tuple(checkpoint.load(policy.resolve(start))[:2])


def observations(args, physics) -> int:
    """The observation count of the run's task as its options set it."""
    from hopper_mjx import envs

    return envs.tasks.observation_size(run_config(args, physics))


def _read_start(args):
    """`policy.read` of --start-from's policy (path, algorithm, network config, task config; JSON only), or None
    without --start-from."""
    start = start_of(args)
    if start is None:
        return None
    from hopper_mjx.envs import policy

    try:
        return policy.read(start)
    except ValueError as err:
        raise ValueError(f"--start-from: {err}") from None


def start_network(args) -> dict | None:
    """The network config of --start-from's policy, checked: None without --start-from."""
    start = _read_start(args)
    return None if start is None else start[2]


def sac_policy_defaults() -> dict:
    """What, besides its layers, makes Brax's SAC policy map its outputs to actions, as train.py builds it; PPO's
    own `mean_clip_scale` (a clip SAC has not) must be off."""
    import inspect

    from brax.training.agents.sac import networks

    defaults = inspect.signature(networks.make_sac_networks).parameters
    return {"mean_clip_scale": None,
            **{k: defaults[k].default for k in ("distribution_type", "noise_std_type", "state_dependent_std")}}


def _differences(args, algo: str, task: str, saved_size: int, size: int) -> str:
    """What of a saved policy (its algorithm, task, observation count) this run asks otherwise, e.g. "its task
    (--task hop_velocity)": only what differs, so that a task refused for itself does not read as a count."""
    found = [f"its algorithm (--algo {args.algo})" if algo != args.algo else "",
             f"its task (--task {args.task})" if task != args.task else "",
             f"its observations ({size} here)" if saved_size != size else ""]
    return " and ".join(x for x in found if x)


def _check_start(args, physics) -> None:
    """--start-from: a readable policy of this task, with this run's observations and SAC's action distribution,
    whose policy layers are --policy-layers (Brax builds SAC's networks from the option). JSON reads only."""
    if args.start_from is None:
        return
    if args.algo != "sac":
        raise ValueError("--start-from is for --algo sac (a PPO run resumes from its own checkpoints)")
    from hopper_mjx.envs import policy

    path, algo, net, config = _read_start(args)
    size = observations(args, physics)
    differs = _differences(args, args.algo, config.task, net["observation_size"], size)
    if differs:
        raise ValueError(f"--start-from {path} is a policy of task {config.task!r} with {net['observation_size']} "
                         f"observations; this run differs in {differs}")
    kwargs = net["network_factory_kwargs"]
    for key, sac in sac_policy_defaults().items():  # how the network's outputs become actions: SAC's way
        if kwargs.get(key, sac) != sac:
            raise ValueError(f"--start-from {path}'s policy has {key}={kwargs[key]!r} where SAC's has {sac!r}")
    saved = tuple(kwargs[LAYER_FLAGS[algo][0][1]])
    if saved != parse_layers(args.policy_layers):
        raise ValueError(f"--start-from {path} has {'-'.join(map(str, saved))} hidden layers where --policy-layers "
                         f"asks {args.policy_layers}: pass --policy-layers {','.join(map(str, saved))}")
    policy.check_stored(path)


def run_config(args, physics, config=None):
    """The task's config as a run's options set it: its defaults, --config's fields (`config`, when `check` has
    applied them already), and the fields other options own (`OWNED_FIELDS`) from them and from `physics`. Raises
    ValueError for a combination it refuses."""
    import dataclasses

    from hopper_mjx import envs

    overrides = {"observe_gravity": args.observe_gravity, "engine": physics.engine, "motor": physics.motor,
                 "action_delay": physics.action_delay, "push": physics.push,
                 "terrain": "" if physics.ground.is_flat else str(physics.ground)}
    if physics.variation:  # the robots episodes run: drawn once, with the run's seed
        overrides |= {"randomize": str(physics.variation), "randomize_seed": args.seed}
    if args.gravity_range is not None:
        overrides["gravity_range"] = parse_pair(args.gravity_range, "--gravity-range")
    if args.policy_rate is not None:
        overrides["policy_rate"] = args.policy_rate
    if config is None:
        config = envs.default_config(args.task).overridden(args.config, OWNED_FIELDS)
    return dataclasses.replace(config, **overrides)


def check_task_physics(args, physics, config) -> None:
    """The motors' delay and the pushes in whole steps of the task's own physics step (`config`'s, with --config's
    fields: it may be coarser than the core's 1 ms), and every delay the robot pool of each seed draws shorter than
    an episode."""
    from hopper_mjx.envs.monoped import ROBOT_POOL
    from hopper_mjx.envs.task_config import steps_per_action
    from hopper_mjx.hardware.pushes import Pushes

    step = config.timestep
    rate = config.policy_rate if args.policy_rate is None else args.policy_rate
    if args.policy_rate is not None and steps_per_action(args.policy_rate, step) is None:
        raise ValueError(f"--policy-rate must divide the training's physics rate ({1 / step:g} Hz) into whole "
                         f"steps, got {args.policy_rate:g} Hz")
    if abs(round(physics.action_delay / step) * step - physics.action_delay) > 1e-9:
        raise ValueError(f"--action-delay must be a whole number of the training's physics steps ({step * 1e3:g} ms), "
                         f"got {physics.action_delay * 1e3:g} ms")
    if physics.push is not None:
        try:
            Pushes.of(*physics.push, step)
        except ValueError as err:
            raise ValueError(f"--push: {err} in training") from None
    episode = args.episode_length / rate
    for seed in range(args.seed, args.seed + (args.seeds or 1)):
        cli.check_delay(physics, episode, ROBOT_POOL, seed,
                        run=f"an episode (--episode-length {args.episode_length} at {rate:g} Hz)")


# The task config's fields other options set: --config refuses them.
OWNED_FIELDS = {"observe_gravity": "--observe-gravity", "engine": "--engine", "motor": "--motor",
                "action_delay": "--action-delay", "push": "--push", "terrain": "--terrain",
                "randomize": "--randomize", "randomize_seed": "--seed", "gravity_range": "--gravity-range",
                "policy_rate": "--policy-rate"}
