"""The tasks (stand, hop, hop_velocity, hop_terrain) and the training wrapper.

The physics is what costs the compile. Every task's physics (`MonopedEnv.physics`) is the same
XLA program (same physics config), compiled once and found in the compile cache by the others; a
task's own part (`after_physics`) compiles apart, cheaply. One test runs the real wrapped step
(`wrap_for_training`) and checks it against that composition.
"""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hopper_mjx import envs, registry
from hopper_mjx.envs import MonopedConfig, monoped, tasks
from hopper_mjx.envs.terms import DROPPING, fallen, flight_apex, observe, tilt_from_vertical
from hopper_mjx.envs.wrappers import wrap_for_training

N = 4  # environments, a multiple of the 2 host devices
# Dropped from 0.5 m with the joints exactly at their targets: the first policy step is free fall.
DROP = dict(observe_gravity=True, initial_clearance=(0.5, 0.5), initial_joint_noise=0.0)


def test_registry_names_defaults_and_overrides(mj_model):
    assert envs.names() == list(registry.TASKS) == ["stand", "hop", "hop_velocity", "hop_terrain"]
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


def test_hop_terrain_observes_the_base_height_over_the_ground_mujoco_c_casts(tmp_path):
    """hop_terrain's observation ends with the height scan: at each point of the config's `scan` (turned with
    the base's yaw), the base's height over the ground. MuJoCo C's ray cast down onto the same model's height field
    gives the ground; they agree to float32 rounding at reset poses spread over the ground. A config's own scan
    (here 9 x 5 points reaching 0.6 m ahead) is read the same way, and sizes the observation."""
    import dataclasses

    import mujoco

    from hopper_mjx import model as hopper_model
    from hopper_mjx.terrain import scan as terrain_scan

    env = envs.make("hop_terrain", observe_gravity=True)
    assert env.config.terrain == tasks.HOP_TERRAIN and env.observation_size == 28 + 25 == 53
    far = dataclasses.replace(env.config, scan_counts=(9, 5), scan_spacing=(0.15, 0.1))
    assert tasks.observation_size(far) == 28 + 45 and float(far.scan[:, 0].max()) == pytest.approx(0.6)
    m, rng = hopper_model.load(terrain=env.config.ground.terrain()), np.random.default_rng(0)
    d = mujoco.MjData(m)
    d.qpos[:2] = 100.0  # the robot far off the ground, out of the rays' way
    mujoco.mj_kinematics(m, d)
    reset = jax.jit(env.reset)
    worst = 0.0
    for k in range(6):
        state = reset(jax.random.PRNGKey(k))
        xy, psi = rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi)
        qpos = state.pipeline_state.qpos.at[:2].set(xy).at[3:7].set(
            jnp.array([np.cos(psi / 2), 0, 0, np.sin(psi / 2)]))
        obs = env.observe_signals(env.engine.model, state.pipeline_state.replace(qpos=qpos))
        config = (env.config, far)[k % 2]
        features = observe(env.layout, config, obs, state.info["gravity"], state.info["command"], jnp.zeros(3))
        scan = np.asarray(features[-len(config.scan):])
        assert float(terrain_scan.yaw(qpos[3:7])) == pytest.approx(psi, abs=1e-5)
        c, s = np.cos(psi), np.sin(psi)
        for (px, py), height_over in zip(config.scan, scan):
            start = np.array([xy[0] + c * px - s * py, xy[1] + s * px + c * py, 5.0])
            geomid = np.array([-1], np.int32)
            distance = mujoco.mj_ray(m, d, start, np.array([0.0, 0.0, -1.0]), None, 1, -1, geomid)
            assert m.geom_type[geomid[0]] == mujoco.mjtGeom.mjGEOM_HFIELD
            worst = max(worst, abs(height_over - (float(qpos[2]) - (5.0 - distance))))
    assert worst < 2e-5, worst


def test_the_clearance_term_pays_the_foots_height_over_the_ground_under_it_in_flight_as_mujoco_c_measures_it():
    """`w_clearance`: in flight, the foot's bottom over the ground under its centre, a share of `clearance_target`
    capped at 1. The env measures it from the joint angles and the base's pose; MuJoCo C's foot geom (its world
    position from `mj_kinematics`, less its radius) over C's ray cast down onto the same height field agree to
    float32 rounding, at tilted poses with random joints over the course. With `clearance_lookahead` the ground is
    the highest of C's ray casts along the foot's path at the base's horizontal velocity, every 10 ms. A foot on
    the ground earns nothing."""
    import mujoco

    from hopper_mjx import model as hopper_model
    from hopper_mjx.envs.terms import clearance_term
    from hopper_mjx.model.layout import Layout

    env = envs.make("hop_terrain", observe_gravity=True, w_clearance=0.5)
    ahead = envs.make("hop_terrain", observe_gravity=True, w_clearance=0.5, clearance_lookahead=0.15)
    plain = envs.make("hop_terrain", observe_gravity=True)
    assert "clearance" in jax.eval_shape(env.reset, jax.random.PRNGKey(0)).metrics
    assert "clearance" not in jax.eval_shape(plain.reset, jax.random.PRNGKey(0)).metrics
    m = hopper_model.load(terrain=env.config.ground.terrain())
    d, rng, foot = mujoco.MjData(m), np.random.default_rng(1), Layout.of(m).foot_geom
    clearance, clearance_ahead = jax.jit(env.foot_clearance), jax.jit(ahead.foot_clearance)
    times = np.arange(16) * 0.01  # 0.15 s in 10 ms samples

    def ground_under(xy) -> float:  # C's ray cast down onto the height field (the robot 50 m up, out of its way)
        geomid = np.array([-1], np.int32)
        down = mujoco.mj_ray(m, d, np.array([*xy, 10.0]), np.array([0.0, 0.0, -1.0]), None, 1, -1, geomid)
        assert m.geom_type[geomid[0]] == mujoco.mjtGeom.mjGEOM_HFIELD
        return 10.0 - down

    seen, rises = [], []
    for _ in range(48):
        d.qpos[:] = env.standing_qpos
        d.qpos[:2] = rng.uniform(-5, 5, 2)
        d.qpos[2] = rng.uniform(0.8, 1.3)
        tilt = rng.normal(0, 0.2, 3)
        d.qpos[3:7] = np.concatenate([[1.0], 0.5 * tilt]) / np.linalg.norm(np.concatenate([[1.0], 0.5 * tilt]))
        d.qpos[list(env.layout.joint_qpos)] += rng.uniform(-0.5, 0.5, 3)
        mujoco.mj_kinematics(m, d)
        centre = d.geom_xpos[foot].copy()
        velocity = rng.uniform(-1.5, 1.5, 2)
        d.qpos[2] += 50.0
        mujoco.mj_kinematics(m, d)
        under = ground_under(centre[:2])
        highest = max(ground_under(centre[:2] + t * velocity) for t in times)
        expected, expected_ahead = (centre[2] - m.geom_size[foot][0] - g for g in (under, highest))
        d.qpos[2] -= 50.0
        qvel = np.zeros(env.layout.nv, np.float32)
        qvel[:2] = velocity
        data = env.engine.make_data(jnp.asarray(d.qpos, jnp.float32), jnp.asarray(qvel))
        got, got_ahead = float(clearance(data)), float(clearance_ahead(data))
        assert got == pytest.approx(expected, abs=3e-5), (got, expected)
        assert got_ahead == pytest.approx(expected_ahead, abs=3e-5), (got_ahead, expected_ahead)
        seen.append(expected)
        rises.append(highest - under)
    assert min(seen) < 0.05 and max(seen) > 0.3  # near the ground and well above it
    assert max(rises) > 0.05  # a face, not only the gentle rise of rough ground, ahead of some feet
    cfg = env.config
    pay = lambda c, flying: float(clearance_term(cfg, jnp.float32(c), jnp.bool_(flying)))
    assert pay(0.06, True) == pytest.approx(0.5 * 0.06 / cfg.clearance_target)
    assert pay(1.0, True) == pytest.approx(0.5) and pay(-0.01, True) == 0.0 and pay(0.06, False) == 0.0


# What `MonopedEnv.physics` reads of the config: tasks that agree on these share its program.
PHYSICS_FIELDS = ("kp", "kd", "timestep", "solver_iterations", "ls_iterations", "policy_rate", "engine")


@pytest.fixture(scope="module")
def physics(mj_model):
    """One compiled physics (policy) step, vmapped, for every task: (env it belongs to, function)."""
    env = envs.make("hop", mj_model, **DROP)
    return env, jax.jit(jax.vmap(env.physics, in_axes=(None, 0, 0, 0)))


class Stepper:
    """A task's step as its parts, each compiled: reset, the shared physics, the task's own part."""

    def __init__(self, env, physics):
        owner, physics = physics
        assert all(getattr(env.config, f) == getattr(owner.config, f) for f in PHYSICS_FIELDS)
        self.env, model = env, env.engine.model
        self.reset = jax.jit(jax.vmap(env.reset))
        after = jax.jit(jax.vmap(env.after_physics, in_axes=(None, 0, 0, 0, 0)))
        targets = jax.vmap(env.targets)
        # physics gives (data, effort, the episode's carry); the URDF's ideal, prompt robot carries nothing
        self.step = lambda s, a: after(model, s, a,
                                       *physics(model, s.pipeline_state, s.info["gravity"], targets(a))[:2])

    def __call__(self, keys, actions):
        """(reset state, the states after each action, stacked)."""
        first = state = self.reset(keys)
        states = []
        for action in actions:
            state = self.step(state, action)
            states.append(state)
        return first, jax.tree_util.tree_map(lambda *x: jnp.stack(x), *states)


@pytest.fixture(scope="module")
def rollouts(mj_model, physics):
    # The tasks on the flat plane (hop_terrain's rough ground is another program: its own test below).
    return {name: Stepper(envs.make(name, mj_model, **DROP), physics) for name in envs.names()
            if not envs.default_config(name).terrain}


# The first action holds the joints at their targets (free fall), the second moves them.
ACTIONS = jnp.stack([jnp.zeros((N, 3), jnp.float32), jnp.full((N, 3), -0.5, jnp.float32)])


@pytest.mark.parametrize("name", ["stand", "hop", "hop_velocity"])
def test_each_task_resets_and_steps_with_shapes_dtypes_and_its_own_gravity(rollouts, name):
    run = rollouts[name]
    env = run.env
    first, states = run(jax.random.split(jax.random.PRNGKey(0), N), ACTIONS)
    size = env.observation_size
    assert first.obs.shape == (N, size) and states.obs.shape == (2, N, size)
    assert first.obs.dtype == states.obs.dtype == states.reward.dtype == jnp.float32
    assert states.reward.shape == states.done.shape == (2, N)
    assert first.info["command"].shape == (N, env.command_size)
    np.testing.assert_allclose(states.pipeline_state.time[0], 0.02, atol=1e-6)  # one 50 Hz policy step: 20 of 1 ms
    g = -np.asarray(first.info["gravity"][:, 2])
    assert len(np.unique(g)) == N and (g >= 0.5).all() and (g <= 12.0).all()
    np.testing.assert_allclose(np.asarray(first.obs[:, -1]) * 9.81, g, rtol=1e-5)  # observed gravity
    # Free fall with the joints held: the base falls at each environment's own g.
    np.testing.assert_allclose(np.asarray(states.pipeline_state.qvel[0, :, 2]), -g * 0.02, rtol=1e-3)
    assert np.isfinite(np.asarray(states.obs)).all()


@pytest.mark.parametrize("name", ["stand", "hop", "hop_velocity"])
def test_each_task_is_deterministic_per_seed(rollouts, name):
    run = rollouts[name]
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


def test_the_training_wrapper_draws_a_fresh_episode_after_each_end(rollouts):
    """Episodes of 2 steps: the first wrapped step is the task's step (physics, then the task's
    part); after the auto-reset every environment has a new gravity and command, the episode
    counter restarts, and the truncation is reported on the ending step."""
    run = rollouts["hop_velocity"]
    wrapped = wrap_for_training(run.env, episode_length=2)
    step = jax.jit(wrapped.step)
    keys = jax.random.split(jax.random.PRNGKey(1), N)
    state = jax.jit(wrapped.reset)(keys)
    g0, cmd0 = np.asarray(state.info["gravity"]), np.asarray(state.info["command"])
    action = jnp.full((N, 3), 0.3, jnp.float32)
    state = step(state, action)
    np.testing.assert_array_equal(np.asarray(state.info["gravity"]), g0)  # mid-episode: unchanged
    composed = run.step(run.reset(keys), action)
    for got, want in ((state.obs, composed.obs), (state.reward, composed.reward),
                      (state.pipeline_state.qpos, composed.pipeline_state.qpos)):
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-5, atol=1e-6)
    state = step(state, jnp.zeros((N, 3)))
    assert (np.asarray(state.done) == 1).all() and (np.asarray(state.info["truncation"]) == 1).all()
    assert (np.asarray(state.info["gravity"])[:, 2] != g0[:, 2]).all()
    assert (np.asarray(state.info["command"]) != cmd0).all()
    np.testing.assert_allclose(np.asarray(state.pipeline_state.time), 0.0)  # the fresh episode's state
    state = step(state, jnp.zeros((N, 3)))
    assert (np.asarray(state.info["steps"]) == 1).all() and not np.asarray(state.done).any()
    with pytest.raises(ValueError, match="randomization_fn"):
        wrap_for_training(run.env, randomization_fn=lambda s: s)


def _state(env, *, height, quat=(1.0, 0.0, 0.0, 0.0), vz=0.0, vx=0.0):
    qpos = np.array(env.standing_qpos)
    qpos[2], qpos[3:7] = height, quat
    qvel = np.zeros(env.layout.nv, np.float32)
    qvel[0], qvel[2] = vx, vz
    return env.engine.make_data(jnp.asarray(qpos), jnp.asarray(qvel))


def _reward(env, d, command, g=9.81):
    zero = jnp.zeros(3)
    fell = fallen(env.config, d)
    terms = env.reward_terms(d, jnp.float32(g), jnp.asarray(command, jnp.float32), zero, zero,
                             jnp.float32(0.0), fell)
    return float(sum(terms.values())), bool(fell)


HALF = np.sqrt(0.5)


def test_hop_a_fallen_state_scores_lower_than_hopping(mj_model):
    env = envs.make("hop", mj_model)
    command = [1.1, 0.0, 0.0]
    r_apex, fell_apex = _reward(env, _state(env, height=1.1), command)  # at the apex, vz = 0
    r_rising, _ = _reward(env, _state(env, height=0.95, vz=float(np.sqrt(2 * 9.81 * 0.15))), command)
    r_stand, _ = _reward(env, _state(env, height=0.88), command)
    r_side, fell_side = _reward(env, _state(env, height=0.3, quat=(HALF, HALF, 0.0, 0.0)), command)
    r_tilt, fell_tilt = _reward(env, _state(env, height=1.0, quat=(np.cos(0.5), np.sin(0.5), 0, 0)), command)
    assert not fell_apex and fell_side and fell_tilt
    np.testing.assert_allclose(r_rising, r_apex, atol=1e-3)  # the ballistic apex is what counts
    assert r_apex > r_stand > 0 > r_tilt and r_apex > r_side + env.config.fall_penalty * 0.9


def test_hop_velocity_tracking_the_command_scores_above_ignoring_it(mj_model):
    env = envs.make("hop_velocity", mj_model)
    command = [0.98, 0.5, 0.0]  # apex 0.98 m (a 0.10 m rise), 0.5 m/s forward
    r_track, _ = _reward(env, _state(env, height=0.98, vx=0.5), command)
    r_in_place, _ = _reward(env, _state(env, height=0.98), command)
    r_too_low, _ = _reward(env, _state(env, height=0.90, vx=0.5), command)
    r_fallen, _ = _reward(env, _state(env, height=0.3, quat=(HALF, HALF, 0.0, 0.0), vx=0.5), command)
    # The speed kernel: exp(-0.5² / 0.3²) of the 1.0 weight is lost by hopping in place.
    np.testing.assert_allclose(r_track - r_in_place, 1.0 - np.exp(-(0.5 / 0.3) ** 2), atol=1e-4)
    assert r_track > r_too_low > r_fallen


def _hop_cycle(env, *, rise, stance_dip, speed_swing=0.0, mean_speed=0.0, g=9.81, samples=100):
    """States of one hop cycle at `mean_speed` m/s forward: a ballistic flight rising `rise` m from the
    standing height, then a stance of 0.18 s whose base dips `stance_dip` m while its forward speed swings
    by `speed_swing` m/s (as Raibert's hops do at Earth)."""
    flight = 2 * np.sqrt(2 * rise / g)
    t = np.linspace(0.0, flight + 0.18, samples, endpoint=False)
    in_flight = t < flight
    vz0 = np.sqrt(2 * g * rise)
    phase = np.clip((t - flight) / 0.18, 0.0, 1.0)
    z = np.where(in_flight, env.standing_height + vz0 * t - g * t**2 / 2,
                 env.standing_height - stance_dip * np.sin(np.pi * phase))
    vz = np.where(in_flight, vz0 - g * t, -np.pi * stance_dip / 0.18 * np.cos(np.pi * phase))
    vx = mean_speed - np.where(in_flight, 0.0, speed_swing * np.sin(2 * np.pi * phase))
    return [_state(env, height=float(zi), vz=float(vzi), vx=float(vxi)) for zi, vzi, vxi in zip(z, vz, vx)]


def _mean_reward(env, states, g):
    """Mean per-step reward of `states` (no effort, no action), one vmapped call."""
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *states)
    zero = jnp.zeros(3)
    reward = lambda d: sum(env.reward_terms(d, jnp.float32(g), jnp.zeros(0), zero, zero, jnp.float32(0.0),
                                            fallen(env.config, d)).values())
    return float(jnp.mean(jax.jit(jax.vmap(reward))(batch)))


def _hop_cycle_terms(env, *, command, g=9.81, **cycle):
    """Mean apex + speed terms over one hop cycle at 0.5 m/s (`_hop_cycle`)."""
    states = _hop_cycle(env, mean_speed=0.5, g=g, **cycle)
    return np.mean([float(sum(env.task_terms(d, jnp.float32(g), jnp.asarray(command, jnp.float32))[k]
                              for k in ("apex", "speed"))) for d in states])


def test_hop_velocity_pays_more_for_hopping_than_for_shuffling_at_the_speed(mj_model):
    """Hopping to the commanded apex, its speed swinging through stance, must clearly outscore
    shuffling at the commanded speed on 1.5 cm hops (per step, of the apex and speed terms' 3).
    With hop's apex kernel (weight 1, 0.1 m) the margin is a fifth as large, and a hop_velocity
    policy trained on it shuffled."""
    command = [0.882 + 0.10, 0.5, 0.0]
    margins = {}
    for name, overrides in (("hop_velocity", {}), ("hop kernel", dict(w_apex=1.0, apex_scale=0.1))):
        env = envs.make("hop_velocity", mj_model, **overrides)
        assert abs(env.standing_height - 0.882) < 1e-3
        hopping, shuffling = (_hop_cycle_terms(env, rise=rise, stance_dip=dip, speed_swing=swing, command=command)
                              for rise, dip, swing in ((0.10, 0.08, 0.3), (0.015, 0.01, 0.0)))
        margins[name] = hopping - shuffling
    assert margins["hop_velocity"] > 0.5 and margins["hop kernel"] < 0.25


def test_stand_pays_small_hops_in_place_like_standing_and_far_more_than_a_fall(mj_model, physics):
    """stand, redefined (standing still under kicks is ill-posed, docs/control.md): a stand episode started
    on the floor and held one policy step (the tasks' shared compiled physics) is inside the height band;
    a 5 cm hop cycle in place (its reference's) pays within 1 % of standing per step, a 0.3 m hop less
    (above the band), drifting less, and a fallen state less than nothing (the fall penalty)."""
    run = Stepper(envs.make("stand", mj_model, **{**DROP, "initial_clearance": (0.0, 0.0)}), physics)
    env = run.env
    state = run.step(run.reset(jax.random.split(jax.random.PRNGKey(0), N)), jnp.zeros((N, 3)))
    g = float(-state.info["gravity"][0, 2])
    standing = jax.tree_util.tree_map(lambda x: x[0], state.pipeline_state)
    assert float(env.task_terms(standing, jnp.float32(g), jnp.zeros(0))["height"]) == 1.0
    r_stand, fell = _reward(env, standing, [], g)
    cycle = lambda **kw: _mean_reward(env, _hop_cycle(env, g=g, samples=50, **kw), g)
    small = registry.TASK_REFERENCES["stand"].height
    r_small, r_big = cycle(rise=small, stance_dip=0.03), cycle(rise=0.3, stance_dip=0.1)
    r_drift = cycle(rise=small, stance_dip=0.03, mean_speed=0.3)
    r_side, fell_side = _reward(env, standing.replace(qpos=standing.qpos.at[2].set(0.3)
                                                      .at[3:7].set(jnp.array([HALF, HALF, 0.0, 0.0]))), [], g)
    assert not fell and fell_side
    assert abs(r_small - r_stand) < 0.01 * r_stand, (r_small, r_stand)
    assert r_small > r_big + 0.3 and r_small > r_drift + 0.2 and r_small > r_side + env.config.fall_penalty


def test_the_flight_apex_is_each_hops_apex_held_through_the_stance_after_it():
    """apex_reward="flight": a drop from the initial clearance is no hop (judged at the standing height);
    from a lift-off on, the flight's highest predicted apex, at once (its ballistic apex), held through the
    following stance until the next lift-off."""
    stand = 0.882
    info = {"apex": jnp.float32(stand), "flight_top": jnp.float32(DROPPING)}
    # (predicted apex m, flying): a 5 cm drop, a stance, a 0.98 m hop rising then falling, a stance, a 0.93 m hop.
    steps = [(0.93, True), (0.90, True), (0.88, False), (0.87, False), (0.98, True), (0.98, True), (0.95, True),
             (0.90, True), (0.86, False), (0.85, False), (0.93, True), (0.91, True), (0.88, False)]
    want = [stand, stand, stand, stand, 0.98, 0.98, 0.98, 0.98, 0.98, 0.98, 0.93, 0.93, 0.93]
    judged = []
    for apex, flying in steps:
        value, carried = flight_apex(jnp.float32(apex), jnp.asarray(flying), info)
        info = {**info, **carried}
        judged.append(float(value))
    np.testing.assert_allclose(judged, want, atol=1e-6)


def test_a_task_config_takes_key_value_overrides_and_names_what_is_wrong():
    hop = envs.default_config("hop")
    owned = {"gravity_range": "--gravity-range"}
    cfg = hop.overridden(["apex_reward=flight", "apex_range=0.95,1.1", "w_apex=2", "solver_iterations=3",
                          "lateral_speed_range=-0.1,0.1"], owned)
    assert (cfg.apex_reward, cfg.apex_range, cfg.w_apex, cfg.solver_iterations) == ("flight", (0.95, 1.1), 2.0, 3)
    assert cfg.vy_range == (-0.1, 0.1)
    assert isinstance(cfg.solver_iterations, int) and hop.overridden([], owned) == hop
    for pairs, message in ((["apex_reward=top"], "apex_reward must be one of predicted, flight"),
                           (["apex_range=1.1"], "apex_range='1.1': expected 2 comma-separated"),
                           (["lateral_speed_range=0.1,0.2,0.3"], "expected 2 comma-separated"),
                           (["w_apex=lots"], "w_apex='lots': expected a float"),
                           (["apex_range=1.2,1.0"], "apex_range must be a finite"),
                           (["gravity_range=1,2"], "gravity_range is set by --gravity-range"),
                           (["task=stand"], "not KEY=VALUE with a task config field"),
                           (["w_apex"], "not KEY=VALUE"),
                           # a negative width made the apex kernel pay more the further off the hop (it trained)
                           (["apex_scale=-1"], r"apex_scale must be finite and > 0 \(a kernel's width\), got -1.0"),
                           (["upright_scale=0"], "upright_scale must be finite and > 0"),
                           (["w_spin=inf"], "w_spin must be finite, got inf"),
                           (["kd=6,6,nan"], r"kd must be finite and >= 0, got \(6.0, 6.0, nan\)"),
                           (["action_scale=0.3,0,0.8"], "action_scale must be three finite values > 0"),
                           (["timestep=inf"], "timestep must be finite and > 0 s, got inf"),
                           (["max_tilt=4"], r"max_tilt must be in \(0, pi\] rad"),
                           (["ls_iterations=0"], "solver_iterations and ls_iterations must be >= 1")):
        with pytest.raises(ValueError, match=message):
            hop.overridden(pairs, owned)


def test_config_rejects_bad_ranges(mj_model):
    with pytest.raises(ValueError, match="gravity_range"):
        MonopedConfig(gravity_range=(12.0, 1.0))
    with pytest.raises(ValueError, match="gravity_range"):
        MonopedConfig(gravity_range=(0.0, 1.0))  # log-uniform draws need a positive low end
    with pytest.raises(ValueError, match="policy_rate"):
        envs.make("hop", mj_model, policy_rate=300.0)  # 1000 Hz / 300 Hz
    with pytest.raises(ValueError, match="unknown"):
        MonopedConfig.from_dict({**MonopedConfig().to_dict(), "gravity": 3})
    cfg = dataclasses.replace(envs.default_config("hop_velocity"), speed_range=(0.0, 0.5))
    assert MonopedConfig.from_dict(cfg.to_dict()) == cfg
    legacy = {k: v for k, v in MonopedConfig().to_dict().items() if k not in ("task", "lateral_speed_range")}
    assert MonopedConfig.from_dict(legacy).task == "hop"  # policy folders from before the tasks
    # The robot's motors and pushes: saved as JSON (the push a list) and read back; a config saved before them
    # loads as ideal, prompt motors without pushes.
    io = dataclasses.replace(cfg, motor="dc", action_delay=0.004, push=(1.0, 0.3), randomize="gyro_noise=0..0.05")
    assert MonopedConfig.from_dict(json.loads(json.dumps(io.to_dict()))) == io
    before = {k: v for k, v in cfg.to_dict().items() if k not in ("motor", "action_delay", "push")}
    assert (MonopedConfig.from_dict(before).motor, MonopedConfig.from_dict(before).action_delay,
            MonopedConfig.from_dict(before).push) == ("ideal", 0.0, None)
    for bad, message in ((dict(motor="stepper"), "unknown motor 'stepper'"),
                         (dict(action_delay=0.0025), "action_delay must be a whole number .* \\(1 ms\\), got 2.5 ms"),
                         (dict(push=(0.0015, 0.3)), "push interval must be a whole number"),
                         (dict(push=(1.0, -0.3)), "push speed must be >= 0"),
                         (dict(randomize="motor_stall_torque=scale(0.5,1)"), "dc motor's figures; set motor='dc'")):
        with pytest.raises(ValueError, match=message):
            dataclasses.replace(cfg, **bad)


def test_a_config_on_the_flat_spec_is_the_plane_s_config():
    # "flat" is a --terrain spec like any other; read as a terrain, the env's reset looked for heights there were none.
    assert MonopedConfig(terrain="flat") == MonopedConfig()
    assert MonopedConfig(terrain="flat").scan_size == 0 < MonopedConfig(terrain="rough:amp=0.02,seed=1").scan_size


def test_env_and_metrics_falls_are_different_measures(mj_model):
    """The env ends an episode on the angle of the base z axis from vertical; the metrics call a fall
    on |roll| or |pitch| each. A base rolled and pitched 0.7 rad each (1.0 rad from vertical) is
    fallen to the env and upright to the metrics; the two are named apart."""
    from hopper_mjx.metrics import hops

    roll = pitch = 0.7
    # ZYX Euler (yaw 0): q = q_y(pitch) * q_x(roll), [w, x, y, z]
    cr, sr, cp, sp = np.cos(roll / 2), np.sin(roll / 2), np.cos(pitch / 2), np.sin(pitch / 2)
    quat = (cp * cr, cp * sr, sp * cr, -sp * sr)
    d = _state(envs.make("hop", mj_model), height=1.0, quat=quat)
    np.testing.assert_allclose(hops.roll_pitch(np.asarray(quat)), (roll, pitch), atol=1e-6)
    np.testing.assert_allclose(float(tilt_from_vertical(d)), np.arccos(np.cos(roll) * np.cos(pitch)),
                               atol=1e-5)
    assert bool(fallen(MonopedConfig(), d))
    assert max(roll, pitch) < hops.FALL_ROLL_PITCH


def test_on_the_course_each_episode_starts_on_a_tile_of_its_level_and_the_level_follows_the_last_episode():
    """The terrain curriculum (`envs.curriculum`): a first episode starts on the pad of a tile of the course's
    lower half, at z over the pad as at the origin; an episode that lasted moves up a level, one that fell down
    (not below 0), and past the top one goes to a random level."""
    from hopper_mjx import terrain
    from hopper_mjx.envs.curriculum import JITTER, Curriculum, judged_on
    from hopper_mjx.envs.monoped import LEVEL_METRIC
    from hopper_mjx.terrain import spec

    env = envs.make("hop_terrain", terrain="course:levels=5,tile=2,gap=0.15,seed=3,cell=0.1")
    assert env.task_info[-2:] == ("level", "start") and env.curriculum.levels == 5
    keys = jax.random.split(jax.random.PRNGKey(0), 400)
    first = jax.jit(jax.vmap(env.reset))(keys)
    level, xy = np.asarray(first.info["level"]), np.asarray(first.pipeline_state.qpos[:, :2])
    assert set(level) == {0, 1, 2}  # the lower half, the middle level with it
    # Brax's training log sums it over each episode: the level times the length (`training.loop` divides).
    np.testing.assert_array_equal(np.asarray(first.metrics[LEVEL_METRIC]), level)
    centres = spec.tile_centres(env.config.ground)[level]  # (n, kinds, 2): each episode's level's tiles
    off = np.abs(xy[:, None, :] - centres).max(axis=2)
    kind = off.argmin(axis=1)
    assert off.min(axis=1).max() <= JITTER and set(kind) == {0, 1, 2, 3}  # every kind, on the pad
    np.testing.assert_array_equal(np.asarray(first.info["start"]), xy)  # what the next level's distance is from
    lift = np.asarray(first.pipeline_state.qpos[:, 2]) - env.standing_height  # over the pad, at z = 0
    assert lift.min() >= -1e-6 and lift.max() <= env.config.initial_clearance[1] + 1e-6
    # The scan zeroed (`observe_scan=False`, the ablation): the same observation but for the scan.
    blind = envs.make("hop_terrain", terrain="course:levels=5,tile=2,gap=0.15,seed=3,cell=0.1", observe_scan=False)
    seen, unseen = (jax.jit(e.reset)(keys[0]).obs for e in (env, blind))
    assert blind.observation_size == env.observation_size and np.asarray(seen[-len(env.config.scan):]).min() > 0.8
    np.testing.assert_array_equal(np.asarray(unseen[:-len(env.config.scan)]), np.asarray(seen[:-len(env.config.scan)]))
    assert not np.asarray(unseen[-len(env.config.scan):]).any()
    placed = jax.jit(jax.vmap(env.reset_at))(keys, jnp.full(400, 4, jnp.int32))
    np.testing.assert_array_less(np.abs(np.asarray(placed.pipeline_state.qpos[:, 1]) - 4.0), JITTER + 1e-6)

    course = Curriculum.of(env.config.ground)
    step = jax.jit(jax.vmap(course.next_level))
    # (level, lasted, m travelled, m the command asked for): across its tile (1 m on a 2 m tile) up; a fall, or
    # less than half the asked distance, down; in place where nothing was asked, or part-way, stays; past the top.
    cases = [(0, True, 3.0, 2.0), (0, False, 0.1, 2.0), (2, True, 1.2, 2.0), (2, True, 0.2, 0.0),
             (2, True, 0.2, 2.0), (3, False, 3.0, 2.0), (3, True, 0.8, 1.0), (4, True, 3.0, 2.0)]
    levels, lasted, travelled, asked = (jnp.asarray(np.tile(np.array(c), 100)) for c in zip(*cases))
    after = np.asarray(step(levels.astype(jnp.int32), lasted.astype(bool), travelled, asked,
                            jax.random.split(jax.random.PRNGKey(1), len(levels)))).reshape(100, len(cases))
    assert (after[:, :-1] == [1, 0, 3, 2, 1, 2, 3]).all()
    assert set(after[:, -1]) == {0, 1, 2, 3, 4}  # past the top: anywhere
    assert Curriculum.of(terrain.parse("rough:amp=0.02,seed=1")) is None
    assert judged_on(str(env.config.ground)) == "rough:amp=0.02,wavelength=0.4,seed=1,size=24x24"
    assert judged_on("obstacle:height=0.1") == "obstacle:height=0.1"
