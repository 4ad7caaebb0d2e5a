"""The Brax training environment, the PPO script and the policy controller.

Compiles once per fixture (a 4-environment batch; one tiny PPO run shared by the
training, checkpoint and controller tests).
"""

import functools
import importlib.util
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from brax.envs.wrappers import training
from mujoco import mjx

from hopper_mjx.envs import MonopedConfig, MonopedEnv, monoped, randomize_gravity

N = 4  # environments, a multiple of the 2 host devices


def _load_script():
    path = Path(__file__).resolve().parents[1] / "experiments" / "train_ppo.py"
    spec = importlib.util.spec_from_file_location("train_ppo", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


train_ppo = _load_script()


@pytest.fixture(scope="module")
def env(mj_model):
    # Dropped from 0.5 m with the joints exactly at their targets: the first policy step is free fall.
    cfg = MonopedConfig(observe_gravity=True, initial_clearance=(0.5, 0.5), initial_joint_noise=0.0)
    return MonopedEnv(cfg, mj_model)


@pytest.fixture(scope="module")
def batch(env):
    """The env as PPO sees it: gravity-randomised, vmapped, episode + auto-reset wrapped."""
    rng = jax.random.split(jax.random.PRNGKey(3), N)
    wrapped = training.wrap(env, episode_length=50, randomization_fn=functools.partial(randomize_gravity, rng=rng))
    return wrapped, jax.jit(wrapped.reset), jax.jit(wrapped.step)


def _rollout(batch, seed, actions):
    _, reset, step = batch
    state = reset(jax.random.split(jax.random.PRNGKey(seed), N))
    for a in actions:
        state = step(state, a)
    return state


def test_reset_and_step_shapes_and_dtypes(env, batch):
    wrapped, reset, step = batch
    state = reset(jax.random.split(jax.random.PRNGKey(0), N))
    assert env.observation_size == 28 and env.action_size == 3 and env.n_frames == 10
    assert state.obs.shape == (N, env.observation_size) and state.obs.dtype == jnp.float32
    state = step(state, jnp.zeros((N, 3)))
    assert state.obs.shape == (N, env.observation_size) and state.obs.dtype == jnp.float32
    assert state.reward.shape == (N,) and state.reward.dtype == jnp.float32
    assert state.done.shape == (N,)
    assert state.info["command"].shape == (N, 3)
    assert np.isfinite(np.asarray(state.obs)).all()
    # 10 physics steps of 2 ms (the training timestep) per policy step.
    np.testing.assert_allclose(state.pipeline_state.time, 0.02, atol=1e-6)


def test_gravity_is_drawn_per_environment_within_the_range(env, batch):
    wrapped, reset, _ = batch
    g = -np.asarray(wrapped._sys_v.opt.gravity[:, 2])  # the DomainRandomizationVmapWrapper inside
    assert g.shape == (N,) and len(np.unique(g)) == N
    assert (g >= 1.0).all() and (g <= 12.0).all()
    state = reset(jax.random.split(jax.random.PRNGKey(0), N))
    # The observed gravity (last entry, in units of 9.81) is the environment's own.
    np.testing.assert_allclose(np.asarray(state.obs[:, -1]) * 9.81, g, rtol=1e-5)


def test_gravity_draws_are_log_uniform(env):
    """As many environments per factor of g at the Moon end as at the Earth end."""
    sys, _ = randomize_gravity(env.sys, jax.random.split(jax.random.PRNGKey(0), 4000), gravity_range=(1.0, 12.0))
    g = -np.asarray(sys.opt.gravity[:, 2])
    assert np.allclose(np.asarray(sys.opt.gravity[:, :2]), 0.0)
    assert 1.0 <= g.min() and g.max() <= 12.0
    np.testing.assert_allclose(np.median(g), np.sqrt(12.0), rtol=0.05)  # uniform would give 6.5
    below_2, above_6 = np.mean(g < 2.0), np.mean(g > 6.0)  # each a factor of 2
    np.testing.assert_allclose(below_2, np.log(2) / np.log(12), atol=0.03)
    np.testing.assert_allclose(above_6, np.log(2) / np.log(12), atol=0.03)


def test_physics_uses_each_environments_gravity(batch):
    """In free fall with the joints held, the base falls at each environment's own g."""
    wrapped, reset, step = batch
    state = step(reset(jax.random.split(jax.random.PRNGKey(0), N)), jnp.zeros((N, 3)))
    g = -np.asarray(wrapped._sys_v.opt.gravity[:, 2])
    vz = np.asarray(state.pipeline_state.qvel[:, 2])
    np.testing.assert_allclose(vz, -g * 0.02, rtol=1e-3)


def test_same_seed_same_rollout_and_different_seed_differs(batch):
    # float32 arrays (jnp.full of a Python float is weakly typed, a new signature for the jitted step)
    actions = [jnp.full((N, 3), 0.3, jnp.float32), jnp.full((N, 3), -0.5, jnp.float32), jnp.zeros((N, 3))]
    a, b = _rollout(batch, 7, actions), _rollout(batch, 7, actions)
    np.testing.assert_array_equal(np.asarray(a.obs), np.asarray(b.obs))
    np.testing.assert_array_equal(np.asarray(a.reward), np.asarray(b.reward))
    c = _rollout(batch, 8, actions)
    assert not np.allclose(np.asarray(a.obs), np.asarray(c.obs))


def _state(mj_model, *, height, quat=(1.0, 0.0, 0.0, 0.0), vz=0.0):
    qpos = monoped.stance_qpos(mj_model).copy()
    qpos[2], qpos[3:7] = height, quat
    qvel = np.zeros(mj_model.nv, np.float32)
    qvel[2] = vz
    m = mjx.put_model(mj_model)
    return mjx.make_data(m).replace(qpos=jnp.asarray(qpos), qvel=jnp.asarray(qvel))


def test_a_fallen_state_scores_lower_than_hopping(mj_model):
    cfg, g = MonopedConfig(), jnp.float32(9.81)
    command = jnp.array([1.1, 0.0, 0.0])
    zero = jnp.zeros(3)

    def reward(d):
        fell = monoped.fallen(cfg, d)
        terms = monoped.reward_terms(cfg, d, g, command, zero, zero, jnp.float32(0.0), fell)
        return float(sum(terms.values())), bool(fell)

    at_apex = _state(mj_model, height=1.1)  # upright, at the commanded apex, vz = 0
    rising = _state(mj_model, height=0.95, vz=float(np.sqrt(2 * 9.81 * 0.15)))  # on its way to 1.1 m
    standing = _state(mj_model, height=0.88)
    half = np.sqrt(0.5)
    on_its_side = _state(mj_model, height=0.3, quat=(half, half, 0.0, 0.0))  # rolled 90°, base near the floor
    tilted = _state(mj_model, height=1.0, quat=(np.cos(0.5), np.sin(0.5), 0.0, 0.0))  # 1 rad roll

    r_apex, fell_apex = reward(at_apex)
    r_rising, _ = reward(rising)
    r_stand, _ = reward(standing)
    r_side, fell_side = reward(on_its_side)
    r_tilt, fell_tilt = reward(tilted)
    assert not fell_apex and fell_side and fell_tilt
    np.testing.assert_allclose(r_rising, r_apex, atol=1e-3)  # the ballistic apex is what counts
    assert r_apex > r_stand > 0 > r_tilt and r_apex > r_side + cfg.fall_penalty * 0.9


def test_config_rejects_bad_ranges(env):
    with pytest.raises(ValueError, match="gravity_range"):
        MonopedConfig(gravity_range=(12.0, 1.0))
    with pytest.raises(ValueError, match="gravity_range"):
        MonopedConfig(gravity_range=(0.0, 1.0))  # log-uniform draws need a positive low end
    with pytest.raises(ValueError, match="policy_rate"):
        monoped.decimation(env.layout, MonopedConfig(policy_rate=300.0))  # 1000 Hz / 300 Hz
    with pytest.raises(ValueError, match="unknown"):
        MonopedConfig.from_dict({**MonopedConfig().to_dict(), "gravity": 3})
    cfg = MonopedConfig(speed_range=(0.0, 0.5))
    assert MonopedConfig.from_dict(cfg.to_dict()) == cfg


# -- PPO: a tiny run, its checkpoint, a resume, and the policy as a core controller -------------

TINY = ["--timesteps", "80", "--num-envs", "4", "--batch-size", "4", "--num-minibatches", "2",
        "--unroll-length", "5", "--episode-length", "20", "--eval-every", "40", "--num-eval-envs", "2",
        "--policy-layers", "8,8", "--value-layers", "8,8"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    base = tmp_path_factory.mktemp("ppo")
    cwd = os.getcwd()
    os.chdir(base)
    try:  # a relative --out, as on the command line (orbax itself needs absolute paths)
        record = train_ppo.train(train_ppo.parser().parse_args([*TINY, "--out", "run"]))
    finally:
        os.chdir(cwd)
    return base / "run", record


def _params_at_start(out, restore=None):
    """What ppo.train starts from: the seeded initial params, or a restored checkpoint."""
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as ppo

    factory = functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=(8, 8),
                                value_hidden_layer_sizes=(8, 8))
    _, params, _ = ppo.train(environment=MonopedEnv(), num_timesteps=0, episode_length=20, num_envs=4,
                             normalize_observations=True, network_factory=factory, seed=0,
                             restore_checkpoint_path=restore)
    return params


def _leaves(tree):
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(tree)]


def test_ppo_smoke_run_changes_the_params_and_writes_its_outputs(trained):
    from brax.training.agents.ppo import checkpoint as ppo_checkpoint

    out, record = trained
    assert record["final_step"] >= 80
    assert sorted(p.name for p in (out / "checkpoints").iterdir())[-1] == f"{record['final_step']:012d}"
    assert (out / "reward_curve.png").stat().st_size > 1000
    assert [r["step"] for r in record["history"]][0] == 0 and len(record["history"]) >= 2
    assert all(np.isfinite(r["eval/episode_reward"]) for r in record["history"])
    final = ppo_checkpoint.load(out / "policy")
    start = _params_at_start(out)
    changed = [not np.array_equal(a, b) for a, b in zip(_leaves(final[1]), _leaves(start[1]))]
    assert any(changed), "PPO left the policy params untouched"


def test_checkpoint_restores_identical_params(trained):
    from brax.training.agents.ppo import checkpoint as ppo_checkpoint

    out, record = trained
    path = out / "checkpoints" / f"{record['final_step']:012d}"
    saved = ppo_checkpoint.load(path)
    restored = _params_at_start(out, restore=str(path))
    for a, b in zip(_leaves(saved[:2]), _leaves(restored[:2])):
        np.testing.assert_array_equal(a, b)


def test_a_rerun_resumes_from_the_last_checkpoint(trained, capsys):
    """Run again with the same total: it finds the newest checkpoint and has nothing left to train."""
    out, record = trained
    first = record["final_step"]
    (out / "checkpoints" / "000000000001.orbax-checkpoint-tmp").mkdir()  # a save cut short by a kill
    again = train_ppo.train(train_ppo.parser().parse_args([*TINY, "--out", str(out), "--timesteps", str(first)]))
    assert f"resuming from {out / 'checkpoints' / f'{first:012d}'} (step {first:,})" in capsys.readouterr().out
    assert again["final_step"] == first and again["history"] == record["history"]


def test_policy_runs_as_a_core_controller(trained, mj_model, sim):
    from hopper_mjx.envs import policy
    from hopper_mjx.sim import gravity_vectors

    out, _ = trained
    controller = policy.policy_controller(mj_model, os.path.relpath(out))  # relative, as typed on a command line
    params = policy.policy_params(sim.robot, 3, height=0.2, speed=(0.1, 0.0))
    standing = monoped.stance_qpos(mj_model)[2]
    np.testing.assert_allclose(np.asarray(params.command[0]), [standing + 0.2, 0.1, 0.0], rtol=1e-6)
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


def test_evaluation_kicks_are_the_sweeps():
    """The evaluation claims the sweep's kicks: replicate r gets the sweep's kick for replicate r."""
    from hopper_mjx.sweep.grid import KICK, SweepSpec, expand

    g, qvel = train_ppo.evaluation_batch([9.81, 1.62], 3, seed=4, nv=9)
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
