"""experiments/train.py: a tiny SAC run (SAC compiles three programs with the physics: the replay
prefill, the training epoch and Brax's evaluation, so it has its own file)."""

import jax.numpy as jnp
import numpy as np
import pytest
from test_train import _check_outputs, _checkpoints, _leaves, _train


@pytest.fixture(scope="module")
def trained_sac(tmp_path_factory):
    """Trained in two legs, as a killed run is: 40 steps, then the same command with the full 80 resumes it from
    the checkpoint at 40 (Brax's SAC could not restore one: `hopper_mjx.envs.replay.replicated_restore_in_sac`)."""
    base = tmp_path_factory.mktemp("sac")
    _, first = _train(base, "--task", "stand", "--algo", "sac", "--timesteps", "40")
    assert first["final_step"] == 40
    return _train(base, "--task", "stand", "--algo", "sac")


def test_sac_tiny_run_changes_the_params_and_its_policy_acts(trained_sac):
    """SAC's policy params differ from one checkpoint to the next (it learned in between); the final
    policy/ holds the last checkpoint's params exactly, and acts with them."""
    from brax.training import checkpoint

    from hopper_mjx.envs import policy

    out, record = trained_sac
    _check_outputs(out, record, legs=2)
    assert [int(p.name) for p in _checkpoints(out)] == [40, 80] and record["final_step"] == 80
    assert all(np.isfinite(r["eval/episode_reward"]) for r in record["history"])
    first, last = (checkpoint.load(p) for p in _checkpoints(out))
    assert any(not np.array_equal(a, b) for a, b in zip(_leaves(first[1]), _leaves(last[1])))
    for a, b in zip(_leaves(last), _leaves(checkpoint.load(out / "policy"))):
        np.testing.assert_array_equal(a, b)
    act, config = policy.load(out)
    assert config.task == "stand" and policy.algorithm_of(out / "policy") == "sac"
    action = np.asarray(act(jnp.zeros(24)))
    assert action.shape == (3,) and (np.abs(action) <= 1).all()
