"""experiments/train.py: a tiny SAC run (SAC compiles three programs with the physics: the replay
prefill, the training epoch and Brax's evaluation, so it has its own file)."""

import jax.numpy as jnp
import numpy as np
import pytest
from test_train import TINY, _check_outputs, _checkpoints, _leaves, _train, learners, train_script

SAC = ["--task", "stand", "--algo", "sac"]


@pytest.fixture(scope="module")
def trained_sac(tmp_path_factory):
    return _train(tmp_path_factory.mktemp("sac"), *SAC)


def test_sac_tiny_run_changes_the_params_and_its_policy_acts(trained_sac):
    """SAC's policy params differ from one checkpoint to the next (it learned in between); the final
    policy/ holds the last checkpoint's params exactly, and acts with them."""
    from brax.training import checkpoint

    from hopper_mjx.envs import policy

    out, record = trained_sac
    _check_outputs(out, record)
    assert all(np.isfinite(r["eval/episode_reward"]) for r in record["history"])
    first, last = (checkpoint.load(p) for p in _checkpoints(out))
    assert any(not np.array_equal(a, b) for a, b in zip(_leaves(first[1]), _leaves(last[1])))
    for a, b in zip(_leaves(last), _leaves(checkpoint.load(out / "policy"))):
        np.testing.assert_array_equal(a, b)
    act, config = policy.load(out)
    assert config.task == "stand" and policy.algorithm_of(out / "policy") == "sac"
    action = np.asarray(act(jnp.zeros(24)))
    assert action.shape == (3,) and (np.abs(action) <= 1).all()


class _Evaluated(Exception):
    """Raised from the progress callback at the resumed run's first evaluation, to stop there."""


def test_a_resumed_sac_run_restores_its_checkpoint_and_evaluates_it(trained_sac):
    """Resuming, Brax's SAC puts the newest checkpoint into its state and evaluates it before it trains on; it
    failed there until train.py handed it the checkpoint replicated over the devices
    (`hopper_mjx.envs.replay.replicated_restore_in_sac`). Stopped at that evaluation, so nothing more compiles."""
    out, record = trained_sac
    args = train_script.parser().parse_args([*TINY, *SAC, "--out", str(out)])
    factory, _ = learners.networks(args)
    seen = {}

    def progress(step, metrics):
        seen.update(metrics, step=step)
        raise _Evaluated

    with pytest.raises(_Evaluated):
        learners.run_sac(args, learners.task_config(args, train_script.check(args)), factory, 40,
                         record["final_step"], (_checkpoints(out)[-1], record["final_step"]), progress,
                         save_checkpoint=lambda step, params: None)
    assert seen["step"] == 0 and np.isfinite(seen["eval/episode_reward"])
