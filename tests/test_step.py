"""One physics step for training and the core: the training env's physics and the core's rollout both call
`hopper_mjx.step` (`actuate`, then `advance`), so from the same state, in the same configuration (the
training model's 2 ms step and capped solver, DC motors, an action delay, pushes), they reach the same state."""

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx import model as hopper_model
from hopper_mjx.control.base import Controller, Servo
from hopper_mjx.envs import monoped, tasks
from hopper_mjx.envs.task_config import training_model
from hopper_mjx.envs.terms import pd_torque
from hopper_mjx.hardware.signals import SensorConfig
from hopper_mjx.sim import Sim
from hopper_mjx.step import Plant, advance

POLICY_STEPS = 4


def test_the_env_and_the_core_step_the_same_physics():
    env = tasks.make("hop", engine="chain", motor="dc", action_delay=0.004, push=(0.03, 0.4), timestep=0.002)
    assert env.config.delay_steps == 2 and env.pushes.every == 15
    lay, cfg = env.layout, env.config
    target = env.targets(jnp.array([0.4, -0.6, 0.9]))  # a crouch held for the whole run: the leg moves, pushes land
    servo = Servo(track=lambda cs, late, now: (pd_torque(lay, cfg, late, now), cs), first=lambda cs: target)
    hold = Controller("targets", init=lambda obs, params: jnp.zeros(()), act=lambda cs, obs, g: (target, cs),
                      servo=servo)
    # The core on the training configuration: the env's model (2 ms, the solver capped), its motors, delay, pushes.
    sim = Sim(training_model(hopper_model.load(), cfg), engine="chain", motor=cfg.motor,
              delay_steps=cfg.delay_steps, pushes=env.pushes)
    qpos = np.asarray(env.standing_qpos).copy()
    qpos[2] += 0.05
    gravity = np.array([[0.0, 0.0, -3.71]])
    rate = 1.0 / (lay.timestep * env.n_frames)
    state0 = sim.reset(gravity, key=7, controller=hold, qpos=qpos)
    core, _ = sim.rollout(state0, hold, steps=POLICY_STEPS * env.n_frames,
                          sensors=SensorConfig(imu_rate=rate, odom_rate=rate, contact_rate=rate, state_rate=rate))

    pick = lambda tree: jax.tree_util.tree_map(lambda x: x[0], tree)
    episode = monoped.Episode(drive=pick(state0.drive), steps=jnp.zeros((), jnp.int32))

    @jax.jit
    def env_run(data, episode):
        model = env.run_time_model(jnp.asarray(gravity[0], jnp.float32))

        def policy_step(_, carry):  # a loop, not unrolled: one copy of the physics to compile
            data, episode = carry
            data, _, episode = env.physics(model, data, jnp.asarray(gravity[0], jnp.float32), target,
                                           episode=episode, key=state0.key[0])
            return data, episode

        return jax.lax.fori_loop(0, POLICY_STEPS, policy_step, (data, episode))

    data, episode = env_run(env.engine.make_data(jnp.asarray(qpos, jnp.float32), jnp.zeros(lay.nv)), episode)
    assert int(episode.steps) == int(core.step[0]) == POLICY_STEPS * env.n_frames
    # The pushes landed (4 in 40 steps of 2 ms, 0.4 m/s each), and the motors drew energy.
    assert np.abs(np.asarray(core.data.qvel[0, :2])).max() > 0.1 and float(core.drive.energy[0]) > 0
    for name, ours, theirs in (("qpos", data.qpos, core.data.qpos[0]), ("qvel", data.qvel, core.data.qvel[0]),
                               ("delay line", episode.drive.line, core.drive.line[0]),
                               ("energy", episode.drive.energy, core.drive.energy[0])):
        np.testing.assert_allclose(np.asarray(ours), np.asarray(theirs), rtol=1e-5, atol=1e-6, err_msg=name)


def test_advance_freezes_a_diverged_instance_and_counts_and_pushes_after_the_step():
    env = tasks.make("hop", engine="chain", push=(0.002, 1.0), timestep=0.002)  # a push due after every 2 ms step
    plant = Plant(env.engine, env.actuation, env.pushes, counts=True)
    qpos = jnp.asarray(env.standing_qpos)
    data = env.engine.make_data(qpos, jnp.zeros(env.layout.nv))
    g = jnp.array([0.0, 0.0, -9.81])
    key = jax.random.PRNGKey(0)
    new, step, _, bad = advance(plant, env.engine.model, data, g, jnp.zeros(env.layout.nu), key,
                                jnp.int32(0), diverged=jnp.array(False))
    assert int(step) == 1 and not bool(bad)
    assert abs(float(jnp.linalg.norm(new.qvel[:2])) - 1.0) < 0.05  # the push after step 1: 1 m/s horizontal
    # A non-finite control diverges the instance: it keeps its last finite state, and says so.
    frozen, _, _, bad = advance(plant, env.engine.model, new, g, jnp.full(env.layout.nu, jnp.nan), key,
                                jnp.int32(1), diverged=jnp.array(False))
    assert bool(bad)
    np.testing.assert_array_equal(np.asarray(frozen.qpos), np.asarray(new.qpos))
