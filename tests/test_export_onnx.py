"""experiments/export_onnx.py: a PPO and a SAC policy written as ONNX, onnxruntime's actions against the core's
on rollouts; bad input refused in one line with nothing written.

The policies are Brax networks with seeded initial params and an observation normaliser fitted (Brax's own
`running_statistics.update`) to spread-out observations, saved as experiments/train.py saves a policy: what is
tested is the export of any such network, not what training reaches.
"""

import functools
import importlib
import json
import re
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hopper_mjx import envs

export = importlib.import_module("export_onnx")


def _save_policy(out, mj_model, task: str, algo: str, key: int = 0):
    """A `task` policy folder at `out` (run folder layout), an `algo` network with 8x8 hidden layers."""
    from brax.training.acme import running_statistics, specs
    from brax.training.agents.ppo import checkpoint as ppo_checkpoint
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.sac import checkpoint as sac_checkpoint
    from brax.training.agents.sac import networks as sac_networks

    from hopper_mjx.envs import policy

    env = envs.make(task, mj_model)
    if algo == "ppo":
        checkpoint = ppo_checkpoint
        factory = functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=(8, 8),
                                    value_hidden_layer_sizes=(8, 8))
    else:
        checkpoint = sac_checkpoint
        factory = functools.partial(sac_networks.make_sac_networks, hidden_layer_sizes=(8, 8))
    network = factory(env.observation_size, env.action_size, preprocess_observations_fn=running_statistics.normalize)
    spread = np.random.default_rng(key).normal(size=(256, env.observation_size)) * np.geomspace(0.1, 5.0,
                                                                                              env.observation_size)
    normaliser = running_statistics.update(
        running_statistics.init_state(specs.Array((env.observation_size,), jnp.dtype("float32"))),
        jnp.asarray(spread + 0.3, jnp.float32))
    params = (normaliser, network.policy_network.init(jax.random.PRNGKey(key)))
    checkpoint.save(out / "checkpoints", 1, params,
                    checkpoint.network_config(env.observation_size, env.action_size, True, factory))
    shutil.copytree(policy.write_env_config(out / "checkpoints" / f"{1:012d}", env.config), out / "policy")
    return out


@pytest.fixture(scope="module")
def hop_ppo(tmp_path_factory, mj_model):
    return _save_policy(tmp_path_factory.mktemp("export") / "hop-ppo", mj_model, "hop", "ppo")


def _export(capsys, *argv):
    code = export.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out.strip().splitlines(), err.strip().splitlines()


@pytest.mark.parametrize("task, algo", [("hop", "ppo"), ("stand", "sac")])
def test_the_onnx_file_acts_as_the_core_controller_on_rollouts(task, algo, hop_ppo, mj_model, tmp_path, capsys):
    """onnxruntime's actions equal those the policy controller sent in the core within 1e-5 on >= 1,000
    observations of real rollouts; the file takes the policy's observation size and gives 3 actions."""
    import onnxruntime

    folder = hop_ppo if (task, algo) == ("hop", "ppo") else _save_policy(tmp_path / "run", mj_model, task, algo)
    onnx_file = tmp_path / "policy.onnx"
    code, out, err = _export(capsys, folder, "--out", onnx_file, "--num", 20)
    assert code == 0, err
    checked = int(out[0].split()[2].replace(",", ""))
    assert checked >= 1000 and out[-1].startswith("largest action difference (onnxruntime vs JAX): ")
    assert float(out[-1].rsplit(" ", 1)[1]) <= 1e-5
    session = onnxruntime.InferenceSession(str(onnx_file), providers=["CPUExecutionProvider"])
    (given,), (taken,) = session.get_inputs(), session.get_outputs()
    size = envs.make(task, mj_model).observation_size
    assert given.shape[1:] == [size] and taken.shape[1:] == [3]
    recorded = json.loads(session.get_modelmeta().custom_metadata_map["hopper_env"])
    assert recorded["task"] == task and recorded["policy_rate"] == 50.0
    layout = json.loads(session.get_modelmeta().custom_metadata_map["observation_layout"])
    assert sum(n for _, n in layout) == size
    # The normaliser is in the graph: far from the fitted statistics the actions saturate as JAX's do.
    from hopper_mjx.envs import policy

    act = jax.jit(jax.vmap(policy.load(folder)[0]))
    probe = np.random.default_rng(1).normal(scale=3.0, size=(64, size)).astype(np.float32)
    np.testing.assert_allclose(session.run(None, {"observation": probe})[0], np.asarray(act(probe)), atol=1e-5)


def _damaged(folder, tmp_path):
    copy = tmp_path / "damaged"
    shutil.copytree(folder / "policy", copy)
    for part in copy.iterdir():  # the parameters go, the JSON stays: a checkpoint whose copy was cut short
        if not part.name.endswith(".json"):
            shutil.rmtree(part) if part.is_dir() else part.unlink()
    return copy


def _edited(folder, tmp_path, **fields):
    copy = tmp_path / "edited"
    shutil.copytree(folder / "policy", copy)
    config = json.loads((copy / "hopper_env.json").read_text())
    (copy / "hopper_env.json").write_text(json.dumps({**config, **fields}))
    return copy


BAD = {
    "not .onnx": (lambda f, t: [f, "--out", t / "policy.pt"], "--out .*: give a file ending in .onnx"),
    "a folder": (lambda f, t: [f, "--out", t / "dir.onnx"], "--out .*dir.onnx is a folder; give a file"),
    "no such policy": (lambda f, t: [t / "nowhere", "--out", t / "p.onnx"], "nowhere is not a trained policy"),
    "no policy files": (lambda f, t: [t, "--out", t / "p.onnx"], "is not a trained policy: no hopper_env.json"),
    "missing checkpoint": (lambda f, t: [_damaged(f, t), "--out", t / "p.onnx"], "parameters cannot be read"),
    "another task asked": (lambda f, t: [f, "--task", "hop_velocity", "--out", t / "p.onnx"],
                           "is a hop policy, not hop_velocity"),
    "an unknown task asked": (lambda f, t: [f, "--task", "jump", "--out", t / "p.onnx"],
                              "--task: unknown task 'jump'; choose from: stand, hop"),
    "another task recorded": (lambda f, t: [_edited(f, t, task="stand"), "--out", t / "p.onnx"],
                              "takes 27 observations but task 'stand'"),
    "another robot": (lambda f, t: [_edited(f, t, robot="0123456789ab"), "--out", t / "p.onnx"],
                      "is for another robot"),
    "too few observations": (lambda f, t: [f, "--num", 5, "--out", t / "p.onnx"], "fewer than 1000 observations"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_one_line_and_writes_nothing(case, hop_ppo, tmp_path, capsys):
    (tmp_path / "dir.onnx").mkdir()
    argv, message = BAD[case]
    argv = argv(hop_ppo, tmp_path)
    before = sorted(tmp_path.rglob("*"))
    code, out, err = _export(capsys, *argv)
    assert code == 2 and out == [] and len(err) == 1 and err[0].startswith("error: "), (code, out, err)
    assert re.search(message, err[0]), err[0]
    assert sorted(tmp_path.rglob("*")) == before
