"""experiments/train.py: a tiny SAC run (SAC compiles three programs with the physics: the replay
prefill, the training epoch and Brax's evaluation, so it has its own file)."""

from pathlib import Path

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


def test_sac_started_from_a_runs_policy_evaluates_that_policy_first(trained_sac, tmp_path, monkeypatch):
    """--start-from: a new SAC run restores the named run's observation normaliser and policy, bit for bit, and
    evaluates them before it trains (stopped there; the same programs as the resume above)."""
    from brax.training import checkpoint
    from brax.training.agents.sac import checkpoint as sac_checkpoint

    from training import loop

    start, _ = trained_sac
    loaded, seen = [], {}
    brax_load = sac_checkpoint.load
    monkeypatch.setattr(sac_checkpoint, "load", lambda path: loaded.append(brax_load(path)) or loaded[-1])

    def stop(step, metrics):
        seen.update(metrics, step=step)
        raise _Evaluated

    def run_sac(args, env, factory, remaining, start_step, resume, progress, save_checkpoint):
        learners.run_sac(args, env, factory, remaining, start_step, resume, stop, save_checkpoint)

    monkeypatch.setattr(loop, "run_sac", run_sac)
    args = train_script.parser().parse_args([*TINY, *SAC, "--start-from", str(start), "--out", str(tmp_path / "run")])
    with pytest.raises(_Evaluated):
        loop.train(args)
    assert len(loaded) == 1 and seen["step"] == 0 and np.isfinite(seen["eval/episode_reward"])
    saved = checkpoint.load(start / "policy")
    for a, b in zip(_leaves(loaded[0][:2]), _leaves(saved[:2]), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_ppo_policy_acts_alike_in_the_sac_networks_it_starts(tmp_path):
    """A PPO policy handed to SAC (--start-from) gives SAC's networks, as train.py builds them for it, PPO's own
    deterministic actions, to the bit; SAC's usual networks (ReLU where PPO has SiLU) would not."""
    import jax
    from brax.training.acme import running_statistics, specs
    from brax.training.agents.ppo import checkpoint as ppo_checkpoint
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.sac import networks as sac_networks

    from hopper_mjx import envs
    from hopper_mjx.envs import policy

    config, size, actions = envs.default_config("stand"), 24, 3
    ppo_args = train_script.parser().parse_args([*TINY, "--task", "stand", "--algo", "ppo", "--out", "x"])
    ppo_factory, _ = learners.networks(ppo_args)
    ppo = ppo_factory(size, actions, preprocess_observations_fn=running_statistics.normalize)
    keys = jax.random.split(jax.random.PRNGKey(7), 4)
    obs = jax.random.normal(keys[0], (256, size)) * 3
    normalizer = running_statistics.update(running_statistics.init_state(specs.Array((size,), jnp.float32)), obs)
    params = (normalizer, ppo.policy_network.init(keys[1]), ppo.value_network.init(keys[2]))
    ppo_checkpoint.save(tmp_path, 1, params, ppo_checkpoint.network_config(size, actions, True, ppo_factory))
    policy.write_env_config(tmp_path / f"{1:012d}", config)

    def acts(network, make_inference):
        return np.asarray(make_inference(network)(params[:2], deterministic=True)(obs, keys[3])[0])

    sac_args = train_script.parser().parse_args([*TINY, *SAC, "--start-from", str(tmp_path / f"{1:012d}"),
                                                 "--out", "x"])
    train_script.check(sac_args)  # the start passes the checks
    expected = acts(ppo, ppo_networks.make_inference_fn)
    assert np.ptp(expected) > 0.5  # the actions are far from constant
    for args, alike in ((sac_args, True), (train_script.parser().parse_args([*TINY, *SAC, "--out", "x"]), False)):
        factory, _ = learners.networks(args)
        sac = factory(size, actions, preprocess_observations_fn=running_statistics.normalize)
        assert np.array_equal(acts(sac, sac_networks.make_inference_fn), expected) == alike


@pytest.mark.parametrize("args, message", [
    (["--algo", "ppo"], "--start-from is for --algo sac (a PPO run resumes from its own checkpoints)"),
    (["--task", "hop"], "is a policy of task 'stand' with 24 observations; this run differs in its task (--task hop) "
                        "and its observations (27 here)"),
    (["--observe-gravity"], "is a policy of task 'stand' with 24 observations; this run differs in its observations "
                            "(25 here)"),
    (["--policy-layers", "16"], "has 8-8 hidden layers where --policy-layers asks 16: pass --policy-layers 8,8"),
])
def test_a_start_that_cannot_be_sacs_is_refused_before_the_run_folder_is_made(trained_sac, tmp_path, capsys, args,
                                                                              message):
    start, _ = trained_sac
    out = tmp_path / "run"
    assert train_script.main([*TINY, *SAC, "--start-from", str(start), *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1
    assert not out.exists()


def test_a_start_that_is_no_policy_is_refused_in_one_line(tmp_path, capsys):
    assert train_script.main([*TINY, *SAC, "--start-from", str(tmp_path), "--out", str(tmp_path / "run")]) == 2
    assert capsys.readouterr().err == (f"error: --start-from: {tmp_path.resolve()} is not a trained policy: no "
                                       "hopper_env.json (expected an experiments/train.py output folder or one of its "
                                       "checkpoints)\n")
    assert not (tmp_path / "run").exists()


def test_with_seeds_each_seed_starts_from_its_own_and_a_seed_missing_is_refused_first(trained_sac, tmp_path, capsys):
    """A --seeds parent as the start: seed s starts from its seed-<s>/; one the parent lacks is refused by name
    before any folder is made (the seeds' parent included)."""
    import shutil

    from training.options import start_of

    start, _ = trained_sac
    shutil.copytree(start / "policy", tmp_path / "parent" / "seed-0" / "policy")
    args = train_script.parser().parse_args([*TINY, *SAC, "--start-from", str(tmp_path / "parent"), "--out", "x"])
    assert start_of(args) == tmp_path / "parent" / "seed-0"
    out = tmp_path / "runs"
    assert train_script.main([*TINY, *SAC, "--start-from", str(tmp_path / "parent"), "--seeds", "2",
                              "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --start-from: {(tmp_path / 'parent' / 'seed-1').resolve()} is not a trained "
                          "policy") and err.count("\n") == 1
    assert not out.exists()


def test_the_scan_passes_over_checkpoints_still_holding_the_start(trained_sac, tmp_path, monkeypatch):
    """A run started from another's policy: its checkpoints that still hold that policy exactly (held by
    --sac-hold-policy) are not scanned, so neither threshold.json nor policy/ can credit SAC with its start; a
    checkpoint whose policy SAC changed is."""
    import json
    import shutil

    from training import evaluation

    start, _ = trained_sac
    first, last = _checkpoints(start)  # policy/ is the last: the start a new run holds
    out = tmp_path / "run"
    shutil.copytree(last, out / "checkpoints" / "000000000010")
    shutil.copytree(first, out / "checkpoints" / "000000000020")
    history = [{"step": s, "wall_time": 1.0, "eval/avg_episode_length": 20.0} for s in (10, 20)]
    (out / "metrics.json").write_text(json.dumps({"history": history, "wall_time": 1.0}))
    scanned = []

    def evaluate(path, *_, **__):
        scanned.append(Path(path).name)
        return {"policy": {"9.81": {"survival": 1.0, "min_hops": 5}}}

    monkeypatch.setattr(evaluation, "evaluate", evaluate)
    args = train_script.parser().parse_args([*TINY, *SAC, "--start-from", str(start), "--out", str(out)])
    assert [row["step"] for row in evaluation.scan_checkpoints(args, train_script.check(args))] == [20]
    assert scanned == ["000000000020"]
