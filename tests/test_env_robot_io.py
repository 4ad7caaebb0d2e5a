"""The tasks run the robots the core runs: dc motors, action and sensor delays, IMU and odometry noise, pushes.

One wrapped training step (`wrap_for_training`) of one env that asks for all of them at once, compiled
once, stepped at the physics rate (a 500 Hz policy on the 2 ms step: one physics step per env step), the
robot dropped from 0.5 m under 1 m/s² so that every step checked is in flight: no external horizontal
force, so the base's horizontal momentum (MuJoCo C, float64) moves only by the pushes.
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hopper_mjx import envs
from hopper_mjx.envs import monoped
from hopper_mjx.envs.task_config import training_model
from hopper_mjx.envs.terms import observe
from hopper_mjx.envs.wrappers import wrap_for_training
from hopper_mjx.hardware.actuators import envelope

N = 4  # environments, a multiple of the 2 host devices
STEPS = 34  # env (= physics) steps; the episode ends after EPISODE of them and a fresh one starts
EPISODE = 30
PUSH = (0.02, 0.3)  # every 10 physics steps of 2 ms, 0.3 m/s
RANDOMIZE = ("sensor_delay=2..10,gyro_noise=0.02..0.05,gyro_bias=normal(0,0.02),odom_pos_noise=0.01..0.02,"
             "odom_vel_noise=0.02..0.04,action_delay=0..6,motor_stall_torque=scale(0.4,0.7)")
# On a 2 ms step (not training's default 1 ms): a 500 Hz policy is then one physics step per env step.
CONFIG = dict(timestep=0.002, motor="dc", push=PUSH, randomize=RANDOMIZE, randomize_seed=3, policy_rate=500.0,
              gravity_range=(1.0, 1.0), initial_clearance=(0.5, 0.5), initial_joint_noise=0.0)
# The observation's slices (ROBOT_SIGNALS): what the noise touches, and what it leaves exact.
RATE, HEIGHT, VELOCITY, EXACT = slice(4, 7), 7, slice(8, 11), np.r_[0:4, 11:21]
# m/s: the centre of mass's horizontal velocity drifts by up to ~3e-3 per 2 ms step in flight with the legs
# swinging at full torque (the discrete step conserves momentum only to first order); a push is 0.3.
DRIFT = 0.01


@pytest.fixture(scope="module")
def run(mj_model):
    """(env, the states at t = 0..STEPS stacked (STEPS + 1, N, ...), the actions (STEPS, N, 3))."""
    env = envs.make("hop", mj_model, **CONFIG)
    wrapped = wrap_for_training(env, episode_length=EPISODE)
    reset, step = jax.jit(wrapped.reset), jax.jit(wrapped.step)
    state = reset(jax.random.split(jax.random.PRNGKey(7), N))
    actions = jax.random.uniform(jax.random.PRNGKey(1), (STEPS, N, 3), minval=-1.0, maxval=1.0)
    states = [state]
    for action in actions:
        state = step(state, action)
        states.append(state)
    return env, jax.tree_util.tree_map(lambda *x: np.stack(x), *states), np.asarray(actions)


def test_the_config_is_the_env_it_makes_and_a_default_one_adds_nothing(mj_model, run):
    env, states, _ = run
    assert env.n_frames == 1 and env.actuation.kind == "dc" and env.pushes.every == 10
    assert env.task_info == monoped.TASK_INFO + monoped.EPISODE_INFO
    assert env.actuation.depth == 4 and env.sensing.depth == 6 and env.sensing.noisy  # 6 ms, 10 ms at 2 ms
    sense = states.info["sense"]
    assert set(np.unique(sense.delay)) <= set(range(1, 6)) and len(np.unique(sense.delay[0])) > 1
    plain = envs.make("hop", mj_model)  # nothing asked: no motors, sensors or counter in its step
    assert plain.task_info == monoped.TASK_INFO and plain.motors is None and plain.sensors is None
    assert not states.done[:EPISODE].any()  # no fall: every step below is in flight


def test_a_dc_motor_never_applies_a_torque_outside_its_envelope(run):
    env, states, _ = run
    lay = env.layout
    act, gear, dof = list(lay.actuator_of_joint), np.asarray(lay.gear), list(lay.joint_dof)
    motor = jax.tree_util.tree_map(lambda x: x[1:], states.info["drive"].motor)  # each step's episode's motor
    # Step t+1 applied its torque at the joint speeds of state t (after its push).
    applied = states.pipeline_state.ctrl[1:, :, act] * gear
    low, high = envelope(motor, states.pipeline_state.qvel[:-1, :, dof])
    low, high = np.asarray(low), np.asarray(high)
    assert (applied >= low - 1e-4).all() and (applied <= high + 1e-4).all()
    at_bound = np.isclose(applied, low, atol=1e-4) | np.isclose(applied, high, atol=1e-4)
    moving = np.abs(states.pipeline_state.qvel[:-1, :, dof]) > 0.5
    assert (at_bound & moving).sum() > 10  # the envelope binds where the speed has moved it
    assert (np.abs(applied) > 0.1).mean() > 0.5


def test_the_drivers_track_the_late_targets_on_the_joints_as_they_are_now(run):
    """The action delay holds back the policy's joint targets (the standing ones until the first arrives),
    not the PD loop: each step's applied torque is the PD law on the target `delay` steps old and on the
    joints of the state it starts from (not the sensors' late, noisy reading), within the motor's envelope."""
    env, states, actions = run
    lay, cfg = env.layout, env.config
    act, gear, dof, qpos = list(lay.actuator_of_joint), np.asarray(lay.gear), list(lay.joint_dof), list(lay.joint_qpos)
    targets = np.asarray(jax.vmap(jax.vmap(env.targets))(jnp.asarray(actions)))  # (STEPS, N, 3)
    delay = np.asarray(states.info["drive"].motor.delay[0])  # (N,) the first episode's robots
    assert len(set(delay)) > 1
    for t in range(EPISODE - 1):  # step t+1 starts from state t
        late = np.where((t - delay >= 0)[:, None], targets[np.maximum(t - delay, 0), np.arange(N)], env.stance)
        ps = states.pipeline_state
        torque = np.asarray(cfg.kp) * (late - ps.qpos[t][:, qpos]) - np.asarray(cfg.kd) * ps.qvel[t][:, dof]
        torque = np.clip(torque, -np.asarray(lay.effort_limit), np.asarray(lay.effort_limit))
        motor = jax.tree_util.tree_map(lambda x: x[t + 1], states.info["drive"].motor)
        low, high = (np.asarray(b) for b in envelope(motor, ps.qvel[t][:, dof]))
        np.testing.assert_allclose(ps.ctrl[t + 1][:, act] * gear, np.clip(torque, low, high), atol=2e-3)


def _true_rows(env, states):
    """The policy observation's robot signals of the TRUE state at each t (no noise, no delay)."""
    from hopper_mjx.hardware import signals

    def one(d, info, action):
        return observe(env.layout, env.config, signals.observe(env.engine, env.engine.model, d),
                               info["gravity"], info["command"], action)

    return np.asarray(jax.vmap(jax.vmap(one))(states.pipeline_state, states.info, states.info["last_action"]))


def test_the_policy_reads_the_state_delay_steps_old_with_its_drawn_noise(run):
    env, states, _ = run
    true = _true_rows(env, states)
    sense = jax.tree_util.tree_map(lambda x: x[0], states.info["sense"])  # the first episode's robots
    delay = np.asarray(sense.delay)
    ts = np.arange(delay.max(), EPISODE)  # read after the delay (before it, the first state, exact)
    old = true[ts[:, None] - delay[None, :], np.arange(N)[None, :]]  # (T, N, obs): the state `delay` steps old
    obs = states.obs[ts]
    np.testing.assert_allclose(obs[..., EXACT], old[..., EXACT], atol=1e-6)  # joints, orientation, contact
    assert not np.allclose(obs[..., EXACT], true[ts][..., EXACT], atol=1e-3)  # not the current state
    rate = (obs[..., RATE] - old[..., RATE]) / 0.25 - np.asarray(sense.gyro_bias)
    for error, std in ((rate, sense.gyro_noise[:, None]), (obs[..., HEIGHT] - old[..., HEIGHT], sense.odom_pos_noise),
                       (obs[..., VELOCITY] - old[..., VELOCITY], sense.odom_vel_noise[:, None])):
        z = error / np.asarray(std)  # standard normal if the noise has the drawn std
        assert abs(z.mean()) < 0.25 and 0.8 < z.std() < 1.2, (z.mean(), z.std())


def test_the_reward_reads_the_true_state(run):
    env, states, actions = run
    g = -states.info["gravity"][..., 2]
    terms = jax.vmap(jax.vmap(env.task_terms))(states.pipeline_state, g, states.info["command"])
    for name, value in terms.items():
        np.testing.assert_allclose(states.metrics[name][1:EPISODE], np.asarray(value)[1:EPISODE], rtol=1e-5,
                                   atol=1e-6)


def _momentum(env, mj_model, qpos, qvel):
    """(T, N, 2) horizontal velocity of the robot's centre of mass, MuJoCo C in float64."""
    m = training_model(mj_model, env.config)
    d = mujoco.MjData(m)
    out = np.zeros((*qpos.shape[:2], 2))
    for idx in np.ndindex(qpos.shape[:2]):
        d.qpos, d.qvel = qpos[idx], qvel[idx]
        mujoco.mj_forward(m, d)
        mujoco.mj_subtreeVel(m, d)
        out[idx] = d.subtree_linvel[0, :2]
    return out


def test_pushes_change_the_velocity_by_their_speed_when_due_and_only_then(run, mj_model):
    env, states, _ = run
    ps = states.pipeline_state
    com = _momentum(env, mj_model, ps.qpos[:EPISODE].astype(np.float64), ps.qvel[:EPISODE].astype(np.float64))
    jump = np.linalg.norm(np.diff(com, axis=0), axis=-1)  # (EPISODE - 1, N): from t - 1 to t
    due = np.arange(1, EPISODE) % 10 == 0
    np.testing.assert_allclose(jump[due], PUSH[1], atol=DRIFT)
    assert jump[~due].max() < DRIFT
    # In the direction drawn from the episode's key and the step's index.
    key = jax.vmap(env.episode_key)(jnp.asarray(states.info["rng"][0]))
    for t in np.flatnonzero(due) + 1:
        angle = jax.vmap(lambda k: jax.random.uniform(jax.random.fold_in(k, t), (), minval=0.0,
                                                      maxval=2 * jnp.pi))(key)
        np.testing.assert_allclose(com[t] - com[t - 1], PUSH[1] * np.stack([np.cos(angle), np.sin(angle)], -1),
                                   atol=DRIFT)


def test_a_fresh_episode_starts_its_motors_sensors_and_count_anew(run):
    env, states, _ = run
    info = states.info
    assert (info["physics_steps"][:EPISODE] == np.arange(EPISODE)[:, None]).all()
    assert (info["physics_steps"][EPISODE] == 0).all() and (info["physics_steps"][-1] == STEPS - EPISODE).all()
    drive = info["drive"]
    assert (drive.energy[EPISODE - 1] > 0).all() and (drive.energy[EPISODE] == 0).all()
    stance = np.broadcast_to(env.stance, drive.line[EPISODE].shape)  # a fresh line: the standing targets
    assert not np.allclose(drive.line[EPISODE - 1], stance) and (drive.line[EPISODE] == stance).all()
    # The fresh episode's line holds its own first observation (every slot but the newest exact).
    line = info["sense"].line.qpos[EPISODE]
    np.testing.assert_array_equal(line[:, 1:], np.broadcast_to(states.pipeline_state.qpos[EPISODE][:, None],
                                                               line[:, 1:].shape))
    assert not np.array_equal(info["robot"][EPISODE], info["robot"][EPISODE - 1])  # another robot drawn
