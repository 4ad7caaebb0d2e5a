"""The batched core against analytic oracles and MuJoCo C, three gravities in one batch,
on both engines (every physics test runs on chain and on mjx)."""

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hopper_mjx import control, simulate
from hopper_mjx.control.base import HOLD_GAINS, hold, zero_torque
from hopper_mjx.hardware import signals
from hopper_mjx.sim import gravity_vectors, split_rollout_key

G = np.array([1.62, 3.71, 9.81])  # Moon, Mars, Earth, m/s²
DROP = 0.05  # m, foot clearance of the default initial state
FALL_STEPS = 500
FALL_SENSORS = signals.SensorConfig(imu_rate=100, odom_rate=500, contact_rate=1000, state_rate=1000, torque=True)
REST_STEPS = 1000
REST_SENSORS = signals.SensorConfig.uniform(100, torque=True)
# Gyro, accelerometer and odometry noise over 90 steps, all three instances airborne: one program for the tests of
# the noise and of the keys it draws from.
NOISE_STEPS = 90
NOISE_SENSORS = signals.SensorConfig.uniform(1000, gyro_noise=0.1, accel_noise=0.5, odom_pos_noise=0.01)


@pytest.fixture(scope="module", params=["chain", "mjx"])
def sim(request, mj_model):
    from hopper_mjx.sim import Sim

    return Sim(mj_model, engine=request.param)


@pytest.fixture(scope="module")
def limp(sim):
    return zero_torque(sim.layout)


@pytest.fixture(scope="module")
def fall(sim, limp):
    """Limp drop from DROP m: free fall, touchdown and collapse, recorded at 1 kHz."""
    state = sim.reset(gravity_vectors(G), key=7, controller=limp)
    final, traj = sim.rollout(state, limp, steps=FALL_STEPS, sensors=FALL_SENSORS)
    return state, final, jax.tree_util.tree_map(np.asarray, traj)


@pytest.fixture(scope="module")
def rest(sim):
    """Drop onto the foot holding the stance angles, then stand for the rest of 1 s."""
    ctrl = hold(sim.layout)
    state = sim.reset(gravity_vectors(G), key=0, controller=ctrl)
    _, traj = sim.rollout(state, ctrl, steps=REST_STEPS, sensors=REST_SENSORS)
    return jax.tree_util.tree_map(np.asarray, traj)


def _first_contact(traj):
    return np.array([np.argmax(f) if f.any() else -1 for f in traj.contact.flag])


def test_free_fall_matches_the_discrete_integrator_exactly(sim, fall):
    _, _, traj = fall
    dt = sim.layout.timestep
    z = traj.qpos[:, :, 2]
    n = np.arange(z.shape[1])
    first = _first_contact(traj)
    assert (first > 50).all(), "every instance must be airborne for a while"
    for i, g in enumerate(G):
        airborne = slice(0, first[i])
        exact = z[i, 0] - g * dt**2 * n * (n + 1) / 2  # semi-implicit Euler
        assert np.abs(z[i, airborne] - exact[airborne]).max() < 5e-5
        t = n * dt
        continuous = z[i, 0] - 0.5 * g * t**2
        assert (np.abs(z[i, airborne] - continuous[airborne]) <= 0.5 * g * dt * t[airborne] + 5e-5).all()
        # x, y and the attitude do not move in a uniform field.
        assert np.abs(traj.qpos[i, airborne, :2]).max() < 1e-6
        np.testing.assert_allclose(traj.qpos[i, airborne, 3:7], np.tile([1, 0, 0, 0], (first[i], 1)), atol=1e-6)


def test_imu_reads_no_specific_force_while_airborne(fall):
    _, _, traj = fall
    first_t = traj.time["state"][_first_contact(traj)]
    for i in range(len(G)):
        airborne = traj.time["imu"] < first_t[i] - 1e-9
        assert airborne.sum() >= 5
        assert np.linalg.norm(traj.imu.accel[i, airborne], axis=-1).max() < 0.05
        assert np.abs(traj.imu.gyro[i, airborne]).max() < 1e-6


def test_first_contact_at_the_analytic_drop_time(sim, fall):
    _, _, traj = fall
    first = _first_contact(traj)
    t_contact = traj.time["contact"][first]
    t_drop = np.sqrt(2 * DROP / G)
    assert np.abs(t_contact - t_drop).max() <= 2e-3
    for i in range(len(G)):
        assert not traj.contact.flag[i, : first[i]].any()
        assert np.all(traj.contact.force[i, : first[i]] == 0)


def test_streams_are_decimated_to_their_own_rates(fall):
    _, _, traj = fall
    n = FALL_STEPS
    assert traj.qpos.shape == (3, n, 10) and traj.contact.flag.shape == (3, n)
    assert traj.imu.quat.shape == (3, n // 10, 4) and traj.odom.pos.shape == (3, n // 2, 3)
    np.testing.assert_allclose(np.diff(traj.time["imu"]), 0.01)
    # A decimated stream is the full-rate state sampled every k steps (noise is 0: exact).
    np.testing.assert_array_equal(traj.imu.quat, traj.qpos[:, ::10, 3:7])
    np.testing.assert_array_equal(traj.odom.pos, traj.qpos[:, ::2, :3])
    np.testing.assert_array_equal(traj.odom.linvel, traj.qvel[:, ::2, :3])


def test_odometry_position_is_the_integral_of_its_velocity(sim, fall):
    _, _, traj = fall
    dt = sim.layout.timestep
    pos, vel = traj.qpos[:, :, :3], traj.qvel[:, :, :3]
    # Semi-implicit Euler: p[n+1] = p[n] + dt * v[n+1], through touchdown and collapse.
    integrated = pos[:, :1] + dt * np.concatenate([np.zeros_like(vel[:, :1]), np.cumsum(vel[:, 1:], axis=1)], axis=1)
    assert traj.time["state"][-1] >= 0.499
    assert np.abs(pos - integrated).max() < 1e-3


def test_engine_agrees_with_mujoco_c_through_touchdown(mj_model, sim, fall):
    state0, _, traj = fall
    m = copy.deepcopy(mj_model)
    for i, g in enumerate(G):
        m.opt.gravity[:] = (0, 0, -g)
        d = mujoco.MjData(m)
        d.qpos[:] = np.asarray(state0.data.qpos[i])
        base = []
        for _ in range(FALL_STEPS):
            base.append(d.qpos[:3].copy())
            mujoco.mj_step(m, d)
        assert _first_contact(traj)[i] < FALL_STEPS // 2, "the comparison must include touchdown"
        err = np.abs(np.array(base) - traj.qpos[i, :, :3]).max()
        assert err < 1e-3, f"g={g}: {sim.engine.name} and MuJoCo C differ by {err:.2e} m"


def test_the_recorded_torque_is_what_the_controller_asked_and_what_mujoco_c_applies(mj_model, sim, rest, fall):
    """At every state sample the torque is hold's PD law on that same sample's joints (clipped at the effort limit),
    so torque and state line up; MuJoCo C, given it as ctrl at that state, applies exactly it to the joints."""
    lay = sim.layout
    q, qd = rest.qpos[..., list(lay.joint_qpos)], rest.qvel[..., list(lay.joint_dof)]
    effort = np.asarray(lay.effort_limit)
    asked = np.clip(HOLD_GAINS["p"] * (q[:, :1] - q) - HOLD_GAINS["d"] * qd, -effort, effort)
    assert rest.torque.shape == q.shape and np.abs(rest.torque).max() > 10.0  # it carries the robot's weight
    np.testing.assert_allclose(rest.torque, asked, rtol=1e-4, atol=1e-3)
    assert not np.any(fall[2].torque)  # limp: nothing applied
    d = mujoco.MjData(mj_model)
    for i, k in ((0, 3), (1, 50), (2, 99)):
        d.qpos[:], d.qvel[:] = rest.qpos[i, k], rest.qvel[i, k]
        d.ctrl[list(lay.actuator_of_joint)] = rest.torque[i, k] / np.asarray(lay.gear)
        mujoco.mj_forward(mj_model, d)
        np.testing.assert_allclose(d.qfrc_actuator[list(lay.joint_dof)], rest.torque[i, k], rtol=1e-6)


def test_at_rest_imu_and_contact_carry_the_weight(sim, rest):
    weight = sim.layout.total_mass * G
    settled = rest.time["state"] >= 0.8
    for i, g in enumerate(G):
        assert rest.contact.flag[i, settled].all()
        fz = rest.contact.force[i, settled, 2]
        np.testing.assert_allclose(fz, weight[i], rtol=0.02)
        accel = rest.imu.accel[i, rest.time["imu"] >= 0.8]
        assert np.abs(accel - [0, 0, g]).max() < 0.02 * g
        # Standing upright, not toppled.
        assert np.abs(rest.qpos[i, -1, :2]).max() < 0.05


def test_a_diverging_instance_is_flagged_and_isolated(sim, limp, fall):
    state0, clean_final, clean = fall
    poisoned = state0._replace(data=state0.data.replace(qvel=state0.data.qvel.at[1, 2].set(np.nan)))
    final, traj = sim.rollout(poisoned, limp, steps=FALL_STEPS, sensors=FALL_SENSORS)
    np.testing.assert_array_equal(np.asarray(final.diverged), [False, True, False])
    assert np.isfinite(np.asarray(final.data.qpos)).all()
    for i in (0, 2):
        np.testing.assert_array_equal(np.asarray(traj.qpos[i]), clean.qpos[i])
        np.testing.assert_array_equal(np.asarray(traj.contact.force[i]), clean.contact.force[i])
    assert not np.asarray(clean_final.diverged).any()


def test_same_seed_gives_bit_identical_results(sim, limp, fall):
    state0, _, first = fall
    _, again = sim.rollout(state0, limp, steps=FALL_STEPS, sensors=FALL_SENSORS)
    for a, b in zip(jax.tree_util.tree_leaves(first), jax.tree_util.tree_leaves(again)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_sensor_noise_has_its_configured_spread_per_instance(sim, limp):
    state = sim.reset(gravity_vectors(G), key=3, controller=limp)
    _, traj = sim.rollout(state, limp, steps=NOISE_STEPS, sensors=NOISE_SENSORS)
    gyro, accel = np.asarray(traj.imu.gyro), np.asarray(traj.imu.accel)
    assert np.std(gyro) == pytest.approx(0.1, rel=0.1)
    assert np.std(accel) == pytest.approx(0.5, rel=0.1)
    noise_pos = np.asarray(traj.odom.pos) - np.asarray(traj.qpos[:, :, :3])
    assert np.std(noise_pos) == pytest.approx(0.01, rel=0.1)
    assert not np.allclose(gyro[0], gyro[1])  # per-instance keys
    np.testing.assert_array_equal(np.asarray(traj.imu.quat), np.asarray(traj.qpos[:, :, 3:7]))  # orientation noise 0


def test_the_next_rollout_key_was_never_used_for_noise(sim, limp):
    """The key a rollout hands on is none of the keys its noise drew from (under jax 0.9.2,
    split(key)[0] is bit-identical to split(key, 6)[0]: handing on split(key)[0] while drawing
    the noise from `key` itself reused the orientation noise's key). Every noise's key is checked, whichever
    noises are on, so the noise test's program serves."""
    state = sim.reset(gravity_vectors(G), key=5, controller=limp)
    final, _ = sim.rollout(state, limp, steps=NOISE_STEPS, sensors=NOISE_SENSORS)
    for key, handed_on in zip(np.asarray(state.key), np.asarray(final.key)):
        noise_key, next_key = split_rollout_key(jnp.asarray(key))
        np.testing.assert_array_equal(handed_on, next_key)  # what the rollout did
        used = np.concatenate([np.asarray(noise_key)[None], np.asarray(signals.noise_keys(noise_key)), key[None]])
        assert not (used == handed_on).all(axis=1).any(), f"key {handed_on} reused"


@pytest.mark.parametrize("gravity", [[[0, 0, np.nan]], [[0, 0, np.inf]], [[0, 0, 9.81]], np.zeros((0, 3))])
def test_bad_gravity_is_rejected(sim, gravity):
    with pytest.raises(ValueError, match="gravity|N=0"):
        sim.reset(gravity)


def test_controller_params_for_another_batch_size_are_rejected_by_name(sim):
    """Params made for 6 instances run on 4 gravities failed inside vmap ("inconsistent sizes for array axes")."""
    ctrl, params = control.make("raibert", sim.robot, 6, height=0.1)
    with pytest.raises(ValueError, match=r"controller params hold 6 instances .* where the gravity holds 4"):
        sim.reset(gravity_vectors([9.81, 1.62] * 2), controller=ctrl, params=params)


@pytest.mark.parametrize("given, message", [
    ({"qpos": np.zeros(5)}, r"qpos must be \(10,\) or \(N, 10\) with N = 2 instances, got shape \(5,\)"),
    ({"qvel": np.zeros((3, 9))}, r"qvel must be \(9,\) or \(N, 9\) with N = 2 instances, got shape \(3, 9\)"),
    ({"key": 1.5}, r"key must be an int seed or a JAX PRNG key, got 1.5")])
def test_a_start_of_the_wrong_shape_or_key_is_rejected_by_name(sim, given, message):
    """NumPy's broadcast error ("could not be broadcast together with remapped shapes"), and JAX's for a float seed,
    named neither argument."""
    with pytest.raises(ValueError, match=message):
        sim.reset(gravity_vectors([9.81, 1.62]), **given)


def test_bad_rates_are_rejected(sim, limp):
    state = sim.reset(gravity_vectors([9.81]), controller=limp)
    with pytest.raises(ValueError, match="must divide the physics rate"):
        sim.rollout(state, limp, steps=300, sensors=signals.SensorConfig.uniform(300))
    with pytest.raises(ValueError, match="multiple of the stream periods"):
        sim.rollout(state, limp, steps=25, sensors=signals.SensorConfig.uniform(100))


def test_simulate_cli_writes_the_documented_arrays(tmp_path, sim, rest):
    out = tmp_path / "run"  # written under the exact name given, no ".npz" added
    args = ["--gravity", "1.62,3.71,9.81", "--num", "1", "--duration", "1", "--controller", "hold",
            "--rate", "100", "--engine", sim.engine.name, "--out", str(out)]
    assert simulate.main(args) == 0
    saved = np.load(out)
    assert saved["time"].shape == (100,) and saved["gravity"].shape == (3, 3)
    assert saved["qpos"].shape == (3, 100, 10) and saved["qvel"].shape == (3, 100, 9)
    for key, shape in (("imu_quat", 4), ("imu_gyro", 3), ("imu_accel", 3), ("odom_pos", 3), ("odom_quat", 4),
                       ("odom_linvel", 3), ("odom_angvel", 3), ("contact_force", 3)):
        assert saved[key].shape == (3, 100, shape), key
    assert saved["contact"].shape == (3, 100) and saved["diverged"].shape == (3,)
    assert saved["torque"].shape == (3, 100, 3)
    # Same inputs and seed as the `rest` fixture: the same numbers.
    np.testing.assert_array_equal(saved["qpos"], rest.qpos)
    np.testing.assert_array_equal(saved["contact_force"], rest.contact.force)


def test_signals_equal_mujoco_native_sensors(mj_model, fall):
    """The core's state-derived IMU/odometry equal MuJoCo C's own sensors at the same state."""
    _, _, traj = fall
    m = copy.deepcopy(mj_model)
    d = mujoco.MjData(m)
    checked_contact = 0
    for i, g in enumerate(G):
        m.opt.gravity[:] = (0, 0, -g)
        for k in range(0, traj.time["imu"].size, 7):
            step = k * 10  # the IMU runs at a tenth of the state rate here
            d.qpos[:], d.qvel[:] = traj.qpos[i, step], traj.qvel[i, step]
            mujoco.mj_forward(m, d)
            sensor = lambda name: d.sensor(name).data
            np.testing.assert_allclose(traj.imu.quat[i, k], sensor("imu_quat"), atol=1e-6)
            np.testing.assert_allclose(traj.imu.gyro[i, k], sensor("imu_gyro"), atol=1e-5)
            np.testing.assert_allclose(traj.imu.accel[i, k], sensor("imu_accel"), atol=0.02 * g + 0.02)
            np.testing.assert_allclose(traj.odom.pos[i, step // 2], sensor("odom_pos"), atol=1e-6)
            np.testing.assert_allclose(traj.odom.linvel[i, step // 2], sensor("odom_linvel"), atol=1e-5)
            np.testing.assert_allclose(traj.odom.angvel[i, step // 2], sensor("odom_angvel"), atol=1e-5)
            if traj.contact.flag[i, step]:
                checked_contact += 1
                touch = sensor("foot_touch")[0]
                assert abs(traj.contact.force[i, step, 2] - touch) <= 0.02 * touch + 0.05
    assert checked_contact >= 3
