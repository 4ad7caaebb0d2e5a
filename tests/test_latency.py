"""The jump knows its action delay: its prediction against MuJoCo C's own integration, its slower loops, and robots
that stay up under a delay at which the same gait, told none, falls."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from hopper_mjx import control
from hopper_mjx.control import latency
from hopper_mjx.control.base import PDScale
from hopper_mjx.hardware.signals import Contact, Observation


def test_the_state_ahead_is_where_mujoco_c_moves_it_at_the_velocities_read(mj_model):
    """Over 2, 5 and 20 ms, a tumbling, travelling robot with its joints turning: `ahead` puts the base, its attitude
    and the joints where MuJoCo C's `mj_integratePos` does (the same constant velocities), to float32 precision."""
    rng = np.random.default_rng(3)
    d = mujoco.MjData(mj_model)
    for delay in (0.002, 0.005, 0.02):
        qpos = mj_model.qpos0.copy()
        qpos[:3] = (0.2, -0.1, 0.9)
        quat = rng.normal(size=4)
        qpos[3:7] = quat / np.linalg.norm(quat)
        qpos[7:] += rng.uniform(-0.3, 0.3, mj_model.nq - 7)
        qvel = rng.uniform(-8.0, 8.0, mj_model.nv)  # rad/s up to 8 about each axis: a robot falling over
        expected = qpos.copy()
        mujoco.mj_integratePos(mj_model, expected, qvel, delay)
        d.qpos[:], d.qvel[:] = qpos, qvel
        obs = Observation(jnp.float32(0.0), jnp.asarray(qpos, jnp.float32), jnp.asarray(qvel, jnp.float32),
                          Contact(jnp.bool_(False), jnp.zeros(3), jnp.zeros(3)))
        got = np.asarray(jax.jit(latency.ahead)(obs, jnp.float32(delay)).qpos)
        np.testing.assert_allclose(got, expected, atol=2e-6)
        assert np.abs(got - qpos).max() > 0.01  # it moved: the check is not of a state left as it was


def test_the_joint_loops_slow_down_beyond_the_delay_the_gains_were_designed_for():
    """Up to `PROMPT_DELAY` the gains, and an instance's own factors, are as given; beyond it the damping falls as
    1/delay (kd·delay held) and the stiffness as its `STIFFNESS_POWER`."""
    own = PDScale(jnp.array([0.5, 1.0, 2.0]), jnp.array([1.5, 1.0, 0.5]))
    for delay in (0.0, 0.001, latency.PROMPT_DELAY):
        factors = latency.detuned(own, jnp.float32(delay))
        np.testing.assert_array_equal(factors.kp, own.kp)
        np.testing.assert_array_equal(factors.kd, own.kd)
    for delay in (0.003, 0.006, 0.02):
        factors = latency.detuned(None, jnp.float32(delay))
        np.testing.assert_allclose(factors.kd * delay, latency.PROMPT_DELAY, rtol=1e-6)
        np.testing.assert_allclose(factors.kp, factors.kd**latency.STIFFNESS_POWER, rtol=1e-6)


def test_only_the_gaits_that_predict_are_given_a_delay():
    assert control.predicted_latency("jump", 0.005) == 0.005
    assert control.predicted_latency("raibert", 0.005) is None  # Raibert stays as it was designed
    assert control.predicted_latency("jump", 0.0) is None  # no delay: the prompt program, no leaves
    assert control.predicted_latency("jump", np.zeros(4)) is None


def test_the_jump_told_its_delay_stays_up_where_told_none_it_falls():
    """10 ms from torque to motor (DC motors, chain engine), 4 s at the Moon, Mars and Earth: each robot that knows
    the delay hops on, near its commanded rise; the same gait with the same delay, told there is none (its torques
    taken as prompt, as Raibert's are), falls. Both run in one batch, one program."""
    from hopper_mjx.metrics import hops
    from hopper_mjx.scenario import Physics
    from hopper_mjx.sim import gravity_vectors
    from hopper_mjx.sweep.runner import recorded

    physics = Physics(motor="dc", engine="chain", action_delay=0.01)
    sim = physics.sim(chunk=6)
    told = np.array([0.01, 0.01, 0.01, 0.0, 0.0, 0.0])
    controller, params = control.make("jump", sim.robot, 6, height=0.1, latency=told)
    final, traj = sim.run(gravity_vectors([1.62, 3.71, 9.81] * 2), controller, params, duration=4.0,
                          sensors=recorded(physics.timestep), key=0)
    traj = jax.tree_util.tree_map(np.asarray, traj)
    fell = hops.fallen(traj.qpos).any(axis=1)
    assert list(fell) == [False] * 3 + [True] * 3
    rise = traj.qpos[:3, 1000:, 2].max(axis=1) - sim.robot.standing_height  # the highest apex after the first second
    assert np.all(np.abs(rise - 0.1) < 0.05)
