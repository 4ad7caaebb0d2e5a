"""The task a run trains on (`task_config`) and Brax's PPO and SAC set up from the options (`run_ppo`, `run_sac`,
`networks`)."""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from hopper_mjx.metrics.thresholds import APEX_TOLERANCE, MIN_HOPS, SPEED_TOLERANCE  # noqa: F401 (one definition)
from training.options import parse_layers, run_config, start_network, start_params


def task_config(args, physics):
    """The env a run trains: its task's config as the options set it (`options.run_config`) on `physics`' model."""
    from hopper_mjx import envs

    return envs.from_config(run_config(args, physics), physics.mj_model)


REWARD_SCALING = {"ppo": 0.1, "sac": 1.0}  # --reward-scaling's defaults
LEARNING_RATE = {"ppo": 6e-4, "sac": 3e-4}  # --learning-rate's defaults


def learner_settings(args) -> dict:
    """The learning rate, reward scaling and (PPO) gradient clip a run uses, its algorithm's defaults filled in."""
    rate = LEARNING_RATE[args.algo] if args.learning_rate is None else args.learning_rate
    scaling = REWARD_SCALING[args.algo] if args.reward_scaling is None else args.reward_scaling
    clip = {} if args.algo != "ppo" else {"max_grad_norm": 1.0 if args.max_grad_norm is None else args.max_grad_norm}
    return {"learning_rate": rate, "reward_scaling": scaling, **clip}


def _shared(args, env, factory, remaining: int, start_step: int, resume, per_train_step: int) -> dict:
    """The keyword arguments Brax's PPO and SAC `train` both take, from ours."""
    from hopper_mjx.envs.wrappers import wrap_for_training

    settings = learner_settings(args)
    return dict(
        environment=env,
        num_timesteps=remaining,
        num_evals=max(1, math.ceil(remaining / max(args.eval_every, per_train_step))) + 1,
        episode_length=args.episode_length,
        num_envs=args.num_envs,
        num_eval_envs=args.num_eval_envs,
        deterministic_eval=True,
        wrap_env_fn=wrap_for_training,  # a fresh gravity and command every episode
        learning_rate=settings["learning_rate"],
        discounting=args.discounting,
        reward_scaling=settings["reward_scaling"],
        batch_size=args.batch_size,
        normalize_observations=True,
        network_factory=factory,
        seed=args.seed + start_step,  # a resumed run draws fresh environments
        restore_checkpoint_path=str(resume[0]) if resume else None,
    )


def run_ppo(args, env, factory, remaining: int, start_step: int, resume, progress, save_checkpoint) -> None:
    """Brax PPO for the `remaining` environment steps, resuming from `resume` (path, step) if given."""
    from brax.training.agents.ppo import train as ppo

    per_train_step = args.batch_size * args.num_minibatches * args.unroll_length
    with one_evaluation_program(ppo):
        ppo.train(
            **_shared(args, env, factory, remaining, start_step, resume, per_train_step),
            unroll_length=args.unroll_length,
            num_minibatches=args.num_minibatches,
            num_updates_per_batch=args.updates_per_batch,
            entropy_cost=args.entropy_cost,
            # A float32, not Brax's default Python 0.0: that is weakly typed until the first update makes it an
            # array, so the first evaluation's program and the update's were each traced twice.
            normalize_observations_std_eps=np.float32(0.0),
            gae_lambda=0.95,
            clipping_epsilon=0.2,
            max_grad_norm=learner_settings(args)["max_grad_norm"] or None,
            **({} if args.desired_kl is None else
               {"learning_rate_schedule": "ADAPTIVE_KL", "desired_kl": args.desired_kl}),
            progress_fn=progress,
            # On a course, Brax's log of finished training episodes carries their curriculum level (filed by the loop).
            log_training_metrics=getattr(env, "curriculum", None) is not None,
            training_metrics_steps=args.eval_every,
            run_evals=not args.no_eval,
            policy_params_fn=lambda step, make_policy, params: save_checkpoint(step, params),
        )


def run_sac(args, env, factory, remaining: int, start_step: int, resume, progress, save_checkpoint) -> None:
    """Brax SAC for the `remaining` environment steps; Brax saves its checkpoints before each
    evaluation into a scratch folder, from where `progress` files them under the global step."""
    import tempfile

    from brax.training import checkpoint as brax_checkpoint
    from brax.training.agents.sac import train as sac

    from hopper_mjx.envs.replay import (
        losses_in_sac,
        policy_update_in_sac,
        replicated_restore_in_sac,
        ring_replay_in_sac,
    )

    # The ring replay: Brax's own copies the whole replay on every insert once full (hopper_mjx.envs.replay).
    with (tempfile.TemporaryDirectory(dir=Path(args.out).resolve()) as scratch, ring_replay_in_sac(),
          losses_in_sac(args.sac_target_entropy, start_anchor(args)), replicated_restore_in_sac(),
          policy_update_in_sac(held_policy_updates(args), args.sac_policy_lr), one_evaluation_program(sac)):
        def progress_and_file(step, metrics):
            if step > 0:
                save_checkpoint(step, brax_checkpoint.load(Path(scratch) / f"{int(step):012d}"))
            progress(step, metrics)

        sac.train(
            **_shared(args, env, factory, remaining, start_step, resume, args.num_envs),
            min_replay_size=min(args.sac_min_replay, remaining - 1),
            max_replay_size=args.sac_replay,
            grad_updates_per_step=args.sac_grad_updates,
            checkpoint_logdir=scratch,
            progress_fn=progress_and_file,
        )


def one_evaluation_program(train):
    """Brax's evaluator as `train` (PPO's or SAC's module) builds it, with its episodes' first states on the device
    the policy's parameters reach it on. Brax leaves those states uncommitted to a device, and its first evaluation
    hands back committed ones, so the evaluation's program was compiled twice: 6-8 s more at every run's start from
    an empty compile cache."""
    import jax
    from brax.training import acting

    from hopper_mjx.envs.replay import in_brax

    class Evaluator(acting.Evaluator):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            # Brax's `_unpmap` hands the evaluation the first device's copy of the parameters.
            self._eval_state_to_donate = jax.device_put(self._eval_state_to_donate, jax.local_devices()[0])

    return in_brax(train, "acting", Evaluator=Evaluator)


def start_anchor(args) -> tuple | None:
    """(--sac-anchor's weight, the --start-from policy's (normaliser, policy params)), or None without it."""
    return (args.sac_anchor, start_params(args)) if args.sac_anchor else None


def held_policy_updates(args) -> int:
    """--sac-hold-policy's env steps as SAC's gradient steps: each batch of --num-envs env steps is followed by
    --sac-grad-updates of them."""
    return math.ceil((args.sac_hold_policy or 0) / args.num_envs) * args.sac_grad_updates


def networks(args):
    """(network factory, Brax checkpoint module) of the algorithm."""
    if args.algo == "ppo":
        from brax.training.agents.ppo import checkpoint, networks

        return functools.partial(networks.make_ppo_networks, policy_hidden_layer_sizes=parse_layers(args.policy_layers),
                                 value_hidden_layer_sizes=parse_layers(args.value_layers)), checkpoint
    from brax.training import networks as brax_networks
    from brax.training.agents.sac import checkpoint, networks

    start = start_network(args)  # a start's policy keeps its activation (Brax's PPO: SiLU; its SAC: ReLU)
    activation = {} if start is None else {
        "activation": brax_networks.ACTIVATION[start["network_factory_kwargs"]["activation"]]}
    factory = functools.partial(networks.make_sac_networks, hidden_layer_sizes=parse_layers(args.policy_layers),
                                **activation)
    return factory, checkpoint
