"""The tasks (stand, hop, hop_velocity), the training wrapper, the training script and the policy controller.

Compiles once per fixture (4 environments; one rollout function per task; one tiny PPO and one
tiny SAC run shared by the training, checkpoint and controller tests).
"""

import dataclasses
import functools
import importlib.util
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from mujoco import mjx

from hopper_mjx import envs
from hopper_mjx.envs import MonopedConfig, monoped, tasks
from hopper_mjx.envs.wrappers import wrap_for_training

N = 4  # environments, a multiple of the 2 host devices


def _load_script(name):
    path = Path(__file__).resolve().parents[1] / "experiments" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


train_script = _load_script("train")
# Dropped from 0.5 m with the joints exactly at their targets: the first policy step is free fall.
DROP = dict(observe_gravity=True, initial_clearance=(0.5, 0.5), initial_joint_noise=0.0)


def test_registry_names_defaults_and_overrides(mj_model):
    assert envs.names() == ["stand", "hop", "hop_velocity"]
    for name in envs.names():
        cfg = envs.default_config(name)
        assert cfg.task == name and cfg.gravity_range == (0.5, 12.0)
    env = envs.make("hop_velocity", mj_model, observe_gravity=True)
    assert isinstance(env, tasks.HopVelocity) and env.config.observe_gravity
    assert (env.observation_size, envs.make("stand", mj_model).observation_size) == (28, 24)
    with pytest.raises(ValueError, match="unknown task 'run'"):
        envs.make("run")
    with pytest.raises(ValueError, match="unknown hop config field"):
        envs.make("hop", gravity=3.0)


@pytest.fixture(scope="module")
def rollouts(mj_model):
    """Per task: a jitted (keys, actions) -> (reset state, states after each action), vmapped over N."""
    out = {}
    for name in envs.names():
        env = envs.make(name, mj_model, **DROP)

        def run(keys, actions, env=env):
            first = jax.vmap(env.reset)(keys)
            step = jax.vmap(env.step)
            return first, jax.lax.scan(lambda s, a: (step(s, a),) * 2, first, actions)[1]

        out[name] = env, jax.jit(run)
    return out


# The first action holds the joints at their targets (free fall), the second moves them.
ACTIONS = jnp.stack([jnp.zeros((N, 3), jnp.float32), jnp.full((N, 3), -0.5, jnp.float32)])


@pytest.mark.parametrize("name", ["stand", "hop", "hop_velocity"])
def test_each_task_resets_and_steps_with_shapes_dtypes_and_its_own_gravity(rollouts, name):
    env, run = rollouts[name]
    first, states = run(jax.random.split(jax.random.PRNGKey(0), N), ACTIONS)
    size = env.observation_size
    assert first.obs.shape == (N, size) and states.obs.shape == (2, N, size)
    assert first.obs.dtype == states.obs.dtype == states.reward.dtype == jnp.float32
    assert states.reward.shape == states.done.shape == (2, N)
    assert first.info["command"].shape == (N, env.command_size)
    np.testing.assert_allclose(states.pipeline_state.time[0], 0.02, atol=1e-6)  # 10 steps of 2 ms
    g = -np.asarray(first.info["gravity"][:, 2])
    assert len(np.unique(g)) == N and (g >= 0.5).all() and (g <= 12.0).all()
    np.testing.assert_allclose(np.asarray(first.obs[:, -1]) * 9.81, g, rtol=1e-5)  # observed gravity
    # Free fall with the joints held: the base falls at each environment's own g.
    np.testing.assert_allclose(np.asarray(states.pipeline_state.qvel[0, :, 2]), -g * 0.02, rtol=1e-3)
    assert np.isfinite(np.asarray(states.obs)).all()


@pytest.mark.parametrize("name", ["stand", "hop", "hop_velocity"])
def test_each_task_is_deterministic_per_seed(rollouts, name):
    _, run = rollouts[name]
    a = run(jax.random.split(jax.random.PRNGKey(7), N), ACTIONS)[1]
    b = run(jax.random.split(jax.random.PRNGKey(7), N), ACTIONS)[1]
    c = run(jax.random.split(jax.random.PRNGKey(8), N), ACTIONS)[1]
    np.testing.assert_array_equal(np.asarray(a.obs), np.asarray(b.obs))
    np.testing.assert_array_equal(np.asarray(a.reward), np.asarray(b.reward))
    assert not np.allclose(np.asarray(a.obs), np.asarray(c.obs))


def test_gravity_draws_are_log_uniform():
    """As many episodes per factor of g at the Moon end as at the Earth end."""
    keys = jax.random.split(jax.random.PRNGKey(0), 4000)
    g = np.asarray(jax.vmap(lambda k: monoped.log_uniform(k, (1.0, 12.0)))(keys))
    assert 1.0 <= g.min() and g.max() <= 12.0
    np.testing.assert_allclose(np.median(g), np.sqrt(12.0), rtol=0.05)  # uniform would give 6.5
    np.testing.assert_allclose(np.mean(g < 2.0), np.log(2) / np.log(12), atol=0.03)
    np.testing.assert_allclose(np.mean(g > 6.0), np.log(2) / np.log(12), atol=0.03)


def test_the_training_wrapper_draws_a_fresh_episode_after_each_end(mj_model):
    """Episodes of 2 steps: after the auto-reset every environment has a new gravity and command,
    the episode counter restarts, and the truncation is reported on the ending step."""
    env = envs.make("hop_velocity", mj_model, **DROP)
    wrapped = wrap_for_training(env, episode_length=2)
    step = jax.jit(wrapped.step)
    state = jax.jit(wrapped.reset)(jax.random.split(jax.random.PRNGKey(1), N))
    g0, cmd0 = np.asarray(state.info["gravity"]), np.asarray(state.info["command"])
    state = step(state, jnp.zeros((N, 3)))
    np.testing.assert_array_equal(np.asarray(state.info["gravity"]), g0)  # mid-episode: unchanged
    state = step(state, jnp.zeros((N, 3)))
    assert (np.asarray(state.done) == 1).all() and (np.asarray(state.info["truncation"]) == 1).all()
    assert (np.asarray(state.info["gravity"])[:, 2] != g0[:, 2]).all()
    assert (np.asarray(state.info["command"]) != cmd0).all()
    np.testing.assert_allclose(np.asarray(state.pipeline_state.time), 0.0)  # the fresh episode's state
    state = step(state, jnp.zeros((N, 3)))
    assert (np.asarray(state.info["steps"]) == 1).all() and not np.asarray(state.done).any()
    with pytest.raises(ValueError, match="randomization_fn"):
        wrap_for_training(env, randomization_fn=lambda s: s)


def _state(mj_model, *, height, quat=(1.0, 0.0, 0.0, 0.0), vz=0.0, vx=0.0):
    qpos = monoped.stance_qpos(mj_model).copy()
    qpos[2], qpos[3:7] = height, quat
    qvel = np.zeros(mj_model.nv, np.float32)
    qvel[0], qvel[2] = vx, vz
    m = mjx.put_model(mj_model)
    return mjx.make_data(m).replace(qpos=jnp.asarray(qpos), qvel=jnp.asarray(qvel))


def _reward(env, d, command, g=9.81):
    zero = jnp.zeros(3)
    fell = monoped.fallen(env.config, d)
    terms = env.reward_terms(d, jnp.float32(g), jnp.asarray(command, jnp.float32), zero, zero,
                             jnp.float32(0.0), fell)
    return float(sum(terms.values())), bool(fell)


HALF = np.sqrt(0.5)


def test_hop_a_fallen_state_scores_lower_than_hopping(mj_model):
    env = envs.make("hop", mj_model)
    command = [1.1, 0.0, 0.0]
    r_apex, fell_apex = _reward(env, _state(mj_model, height=1.1), command)  # at the apex, vz = 0
    r_rising, _ = _reward(env, _state(mj_model, height=0.95, vz=float(np.sqrt(2 * 9.81 * 0.15))), command)
    r_stand, _ = _reward(env, _state(mj_model, height=0.88), command)
    r_side, fell_side = _reward(env, _state(mj_model, height=0.3, quat=(HALF, HALF, 0.0, 0.0)), command)
    r_tilt, fell_tilt = _reward(env, _state(mj_model, height=1.0, quat=(np.cos(0.5), np.sin(0.5), 0, 0)), command)
    assert not fell_apex and fell_side and fell_tilt
    np.testing.assert_allclose(r_rising, r_apex, atol=1e-3)  # the ballistic apex is what counts
    assert r_apex > r_stand > 0 > r_tilt and r_apex > r_side + env.config.fall_penalty * 0.9


def test_hop_velocity_tracking_the_command_scores_above_ignoring_it(mj_model):
    env = envs.make("hop_velocity", mj_model)
    command = [0.98, 0.5, 0.0]  # apex 0.98 m (a 0.10 m rise), 0.5 m/s forward
    r_track, _ = _reward(env, _state(mj_model, height=0.98, vx=0.5), command)
    r_in_place, _ = _reward(env, _state(mj_model, height=0.98), command)
    r_too_low, _ = _reward(env, _state(mj_model, height=0.90, vx=0.5), command)
    r_fallen, _ = _reward(env, _state(mj_model, height=0.3, quat=(HALF, HALF, 0.0, 0.0), vx=0.5), command)
    # The speed kernel: exp(-0.5² / 0.3²) of the 1.0 weight is lost by hopping in place.
    np.testing.assert_allclose(r_track - r_in_place, 1.0 - np.exp(-(0.5 / 0.3) ** 2), atol=1e-4)
    assert r_track > r_too_low > r_fallen


def test_stand_upright_at_height_and_carrying_its_weight_scores_highest(mj_model):
    """The reset state of a stand episode with no drop (foot on the floor, forward'd contact)."""
    env = envs.make("stand", mj_model, initial_clearance=(0.0, 0.0), initial_joint_noise=0.0)
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    g = float(-state.info["gravity"][2])
    standing = state.pipeline_state
    terms = env.task_terms(standing, jnp.float32(g), jnp.zeros(0))
    np.testing.assert_allclose(float(terms["height"]), 1.0, atol=1e-4)
    assert float(terms["support"]) > 0.0  # the foot pushes up while the base is held by nothing else
    r_stand, fell = _reward(env, standing, [], g)
    r_crouch, _ = _reward(env, standing.replace(qpos=standing.qpos.at[2].add(-0.15)), [], g)
    r_side, fell_side = _reward(env, standing.replace(qpos=standing.qpos.at[2].set(0.3)
                                                      .at[3:7].set(jnp.array([HALF, HALF, 0.0, 0.0]))), [], g)
    assert not fell and fell_side and r_stand > r_crouch > r_side


def test_config_rejects_bad_ranges(mj_model):
    with pytest.raises(ValueError, match="gravity_range"):
        MonopedConfig(gravity_range=(12.0, 1.0))
    with pytest.raises(ValueError, match="gravity_range"):
        MonopedConfig(gravity_range=(0.0, 1.0))  # log-uniform draws need a positive low end
    with pytest.raises(ValueError, match="policy_rate"):
        envs.make("hop", mj_model, policy_rate=300.0)  # 500 Hz / 300 Hz
    with pytest.raises(ValueError, match="unknown"):
        MonopedConfig.from_dict({**MonopedConfig().to_dict(), "gravity": 3})
    cfg = dataclasses.replace(envs.default_config("hop_velocity"), speed_range=(0.0, 0.5))
    assert MonopedConfig.from_dict(cfg.to_dict()) == cfg
    legacy = {k: v for k, v in MonopedConfig().to_dict().items() if k not in ("task", "lateral_speed_range")}
    assert MonopedConfig.from_dict(legacy).task == "hop"  # policy folders from before the tasks


# -- PPO and SAC: tiny runs, their checkpoints, a resume, and the policy as a core controller -----

TINY = ["--timesteps", "80", "--num-envs", "4", "--batch-size", "4", "--num-minibatches", "2",
        "--unroll-length", "5", "--episode-length", "20", "--eval-every", "40", "--num-eval-envs", "2",
        "--policy-layers", "8,8", "--value-layers", "8,8", "--sac-min-replay", "16"]


def _train(base, *args):
    cwd = os.getcwd()
    os.chdir(base)
    try:  # a relative --out, as on the command line (orbax itself needs absolute paths)
        record = train_script.train(train_script.parser().parse_args([*TINY, *args, "--out", "run"]))
    finally:
        os.chdir(cwd)
    return base / "run", record


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    return _train(tmp_path_factory.mktemp("ppo"), "--task", "hop", "--algo", "ppo")


@pytest.fixture(scope="module")
def trained_sac(tmp_path_factory):
    return _train(tmp_path_factory.mktemp("sac"), "--task", "stand", "--algo", "sac")


def _params_at_start(restore=None):
    """What ppo.train starts from: the seeded initial params, or a restored checkpoint."""
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as ppo

    factory = functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=(8, 8),
                                value_hidden_layer_sizes=(8, 8))
    _, params, _ = ppo.train(environment=envs.make("hop"), num_timesteps=0, episode_length=20, num_envs=4,
                             normalize_observations=True, network_factory=factory, seed=0,
                             wrap_env_fn=wrap_for_training, restore_checkpoint_path=restore)
    return params


def _leaves(tree):
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(tree)]


def _check_outputs(out, record):
    assert record["final_step"] >= 80
    steps = sorted(p.name for p in (out / "checkpoints").iterdir())
    assert steps[-1] == f"{record['final_step']:012d}" and len(steps) >= 2
    assert (out / "reward_curve.png").stat().st_size > 1000
    assert [r["step"] for r in record["history"]][0] == 0 and len(record["history"]) >= 2
    assert all(np.isfinite(r["eval/episode_reward"]) for r in record["history"])


def test_ppo_smoke_run_changes_the_params_and_writes_its_outputs(trained):
    from brax.training import checkpoint

    out, record = trained
    _check_outputs(out, record)
    final = checkpoint.load(out / "policy")
    changed = [not np.array_equal(a, b) for a, b in zip(_leaves(final[1]), _leaves(_params_at_start()[1]))]
    assert any(changed), "PPO left the policy params untouched"


def test_ppo_checkpoint_restores_identical_params(trained):
    from brax.training import checkpoint

    out, record = trained
    path = out / "checkpoints" / f"{record['final_step']:012d}"
    for a, b in zip(_leaves(checkpoint.load(path)[:2]), _leaves(_params_at_start(restore=str(path))[:2])):
        np.testing.assert_array_equal(a, b)


def test_sac_smoke_run_changes_the_params_and_its_checkpoint_restores_them(trained_sac):
    """SAC's policy params differ from one evaluation's checkpoint to the next (it learned in
    between); the final policy/ holds the last checkpoint's params exactly, and acts with them."""
    from brax.training import checkpoint

    from hopper_mjx.envs import policy

    out, record = trained_sac
    _check_outputs(out, record)
    first, last = (checkpoint.load(p) for p in sorted((out / "checkpoints").iterdir())[-2:])
    assert any(not np.array_equal(a, b) for a, b in zip(_leaves(first[1]), _leaves(last[1])))
    for a, b in zip(_leaves(last), _leaves(checkpoint.load(out / "policy"))):
        np.testing.assert_array_equal(a, b)
    act, config = policy.load(out)
    assert config.task == "stand" and policy.algorithm_of(out / "policy") == "sac"
    action = np.asarray(act(jnp.zeros(24)))
    assert action.shape == (3,) and (np.abs(action) <= 1).all()


def test_a_rerun_resumes_from_the_last_checkpoint(trained, capsys):
    """Run again with the same total: it finds the newest checkpoint and has nothing left to train."""
    out, record = trained
    first = record["final_step"]
    (out / "checkpoints" / "000000000001.orbax-checkpoint-tmp").mkdir()  # a save cut short by a kill
    args = [*TINY, "--out", str(out), "--timesteps", str(first)]
    again = train_script.train(train_script.parser().parse_args(args))
    assert f"resuming from {out / 'checkpoints' / f'{first:012d}'} (step {first:,})" in capsys.readouterr().out
    assert again["final_step"] == first and again["history"] == record["history"]


@pytest.mark.parametrize("args, message", [
    (["--task", "run"], "--task 'run' is unknown; choose from stand, hop, hop_velocity"),
    (["--algo", "a2c"], "--algo 'a2c' is unknown; choose from ppo, sac"),
    (["--task", "hop_velocity", "--observe-gravity"], "holds a ppo policy of task 'hop' with 27 observations"),
    (["--task", "hop", "--algo", "sac"], "holds a ppo policy of task 'hop'"),
])
def test_train_rejects_bad_input_in_one_line_before_anything_runs(trained, capsys, args, message):
    out, _ = trained
    before = sorted(p.name for p in (out / "checkpoints").iterdir())
    assert train_script.main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == before


def test_policy_runs_as_a_core_controller(trained, mj_model, sim):
    from hopper_mjx.envs import policy
    from hopper_mjx.sim import gravity_vectors

    out, _ = trained
    controller = policy.policy_controller(mj_model, os.path.relpath(out))  # relative, as typed on a command line
    params = policy.policy_params(sim.robot, 3, height=0.2, config=policy.read(out)[3])
    standing = monoped.stance_qpos(mj_model)[2]
    np.testing.assert_allclose(np.asarray(params.command[0]), [standing + 0.2, 0.0, 0.0], rtol=1e-6)
    state = sim.reset(gravity_vectors([9.81, 3.71, 1.62]), key=0, controller=controller, params=params)
    final, traj = sim.rollout(state, controller, steps=100)
    assert not np.asarray(final.diverged).any() and np.isfinite(np.asarray(traj.qpos)).all()
    cs = final.cstate
    assert (np.asarray(cs.tick) == 100).all() and (np.asarray(cs.work) > 0).all()
    lo, hi = np.asarray(sim.layout.joint_range).T
    assert ((np.asarray(cs.target) >= lo - 1e-6) & (np.asarray(cs.target) <= hi + 1e-6)).all()
    # Five policy decisions in 0.1 s at 50 Hz: the last action is a real policy output in [-1, 1].
    assert (np.abs(np.asarray(cs.last_action)) <= 1).all() and np.abs(np.asarray(cs.last_action)).sum() > 0


def test_policy_path_errors_name_the_problem(tmp_path, mj_model, sim):
    from hopper_mjx.envs import policy

    with pytest.raises(ValueError, match="not a trained policy"):
        policy.policy_controller(mj_model, tmp_path)
    with pytest.raises(ValueError, match="speed"):
        policy.policy_params(sim.robot, 2, height=0.1, speed=(0.1,))


def test_policy_commands_and_sizes_are_checked_before_anything_runs(trained, sim, tmp_path, capsys):
    """simulate with a hop policy: a command outside its training box, or a folder whose task config
    does not match its network's input, is one line on stderr and exit 2, with nothing written."""
    import json
    import shutil

    from hopper_mjx import simulate

    out, _ = trained
    npz = tmp_path / "x.npz"
    from hopper_mjx.envs import policy

    rise = [apex - sim.robot.standing_height for apex in policy.read(out)[3].apex_range]  # m
    cases = [(["--height", "0.5"],
              f"--height 0.5 is outside the hop policy's trained range [{rise[0]:g}, {rise[1]:g}]"),
             (["--height", "0.15", "--speed", "0.3,0"],
              "--speed VX 0.3 is outside the hop policy's trained range [0, 0]")]
    for args, message in cases:
        assert simulate.main(["--controller", f"policy:{out}", *args, "--out", str(npz)]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    other = tmp_path / "other"
    shutil.copytree(out / "policy", other)
    config = json.loads((other / "hopper_env.json").read_text())
    (other / "hopper_env.json").write_text(json.dumps({**config, "task": "stand"}))
    assert simulate.main(["--controller", f"policy:{other}", "--out", str(npz)]) == 2
    assert "takes 27 observations but task 'stand' (observe_gravity=False) gives 24" in capsys.readouterr().err
    assert not npz.exists()


def test_evaluation_kicks_are_the_sweeps():
    """The evaluation claims the sweep's kicks: replicate r gets the sweep's kick for replicate r."""
    from hopper_mjx.sweep.grid import KICK, SweepSpec, expand

    g, qvel = train_script.evaluation_batch([9.81, 1.62], 3, seed=4, nv=9)
    sweep = expand(SweepSpec(kind="gravity", gravity=(9.81, 1.62), num=3, duration=10.0, height=0.1,
                             speed=(0.0, 0.0), seed=4), 9)
    np.testing.assert_array_equal(g, sweep.gravity)
    np.testing.assert_array_equal(qvel, sweep.qvel)
    np.testing.assert_array_equal(qvel[:3], qvel[3:])  # common random numbers across gravities
    assert 0 < np.abs(qvel[:, [0, 1, 3, 4]]).max() < 6 * KICK and not qvel[:, [2, 5, 6, 7, 8]].any()


def test_env_and_metrics_falls_are_different_measures(mj_model):
    """The env ends an episode on the angle of the base z axis from vertical; the metrics call a fall
    on |roll| or |pitch| each. A base rolled and pitched 0.7 rad each (1.0 rad from vertical) is
    fallen to the env and upright to the metrics; the two are named apart."""
    from hopper_mjx import metrics

    roll = pitch = 0.7
    # ZYX Euler (yaw 0): q = q_y(pitch) * q_x(roll), [w, x, y, z]
    cr, sr, cp, sp = np.cos(roll / 2), np.sin(roll / 2), np.cos(pitch / 2), np.sin(pitch / 2)
    quat = (cp * cr, cp * sr, sp * cr, -sp * sr)
    d = _state(mj_model, height=1.0, quat=quat)
    np.testing.assert_allclose(metrics.roll_pitch(np.asarray(quat)), (roll, pitch), atol=1e-6)
    np.testing.assert_allclose(float(monoped.tilt_from_vertical(d)), np.arccos(np.cos(roll) * np.cos(pitch)),
                               atol=1e-5)
    assert bool(monoped.fallen(MonopedConfig(), d))
    assert max(roll, pitch) < metrics.FALL_ROLL_PITCH


def test_sweep_compare_judges_the_policy_and_raibert_alike(trained, tmp_path, capsys):
    """`sweep compare`: one gravity sweep per controller, same grid and kicks, one table and plot."""
    import json

    from hopper_mjx.sweep import __main__ as sweep

    out, _ = trained
    args = ["compare", "--controllers", f"raibert,policy:{out}", "--values", "9.81,1.62", "--num", "2",
            "--duration", "0.2", "--chunk", "4", "--height", "0.15", "--no-progress", "--out", str(tmp_path)]
    assert sweep.main(args) == 0
    groups = json.loads((tmp_path / "comparison.json").read_text())["groups"]
    assert [(g["controller"], g["gravity"], g["n"]) for g in groups] == [
        ("raibert", 9.81, 2), ("raibert", 1.62, 2), ("policy-run", 9.81, 2), ("policy-run", 1.62, 2)]
    assert (tmp_path / "gravity.png").stat().st_size > 1000
    table = (tmp_path / "table.txt").read_text()
    assert table.count("raibert") == 2 and table.count("policy-run") == 2
    manifests = [json.loads((tmp_path / d / "manifest.json").read_text()) for d in ("raibert", "policy-run")]
    assert manifests[0]["controller"] == "raibert" and manifests[1]["controller"] == f"policy:{out}"
    assert {k: v for k, v in manifests[0].items() if k != "controller"} == \
        {k: v for k, v in manifests[1].items() if k != "controller"}  # same grid, kicks, commands
    capsys.readouterr()
    assert sweep.main(["compare", "--controllers", f"raibert,policy:{tmp_path}", "--out", str(tmp_path / "x")]) == 2
    assert "is not a trained policy" in capsys.readouterr().err and not (tmp_path / "x").exists()
