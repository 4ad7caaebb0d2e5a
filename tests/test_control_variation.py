"""Per-instance controller, motor, delay and sensor parameters (`--randomize kp_scale=...,action_delay=...`):
drawn like the model fields, and run in one batch against MuJoCo C given each instance's figures."""

import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hopper_mjx.control.base import HOLD_GAINS, Controller, hold, pd_scale
from hopper_mjx.hardware import signals
from hopper_mjx.hardware.sensor_noise import Sensing
from hopper_mjx.sim import Sim, gravity_vectors
from hopper_mjx.variation import draw
from hopper_mjx.variation.spec import Spec

STEPS = 450  # 0.45 s: the drop from DROP lands at about 0.25 s, so 200 steps of stance follow
DROP = 0.25  # m added to the stance's clearance
SENSORS = signals.SensorConfig(imu_rate=100, odom_rate=100, contact_rate=1000, state_rate=1000)
# One batch, one compile: instance i's (action delay steps, sensor delay steps, kp factor, kd factor).
# (3, 2, 0.5, 2.0) is not among them: that delayed, over-damped loop is chaotic (a 1e-6 rad change of the start
# moves MuJoCo C's own path by 1.6 cm), so float32 cannot follow float64 there.
CASES = [(0, 0, 1.0, 1.0), (8, 0, 1.0, 1.0), (0, 8, 1.0, 1.0), (3, 2, 2.0, 0.5), (0, 0, 0.0, 0.0), (0, 0, 1.0, 1.0),
         (0, 0, 0.5, 2.0)]
NOISY = 5  # this instance's IMU and odometry are noisy and biased (the others exact): the hold law reads neither
BIAS = np.array([0.1, -0.2, 0.3])  # rad/s
GYRO_STD, POS_STD, ACCEL_STD = 0.05, 0.01, 0.5


def c_hold_run(mj_model, layout, qpos0, action_delay: int, sensor_delay: int, kp: float, kd: float):
    """Base path (STEPS, 3) of MuJoCo C under the hold law with gains times (kp, kd), which reads the joints
    `sensor_delay` steps late (the first reading until then) and whose commands reach the joints
    `action_delay` steps late (no torque until then), in float64."""
    m = mj_model
    d = mujoco.MjData(m)
    d.qpos[:] = qpos0
    joints_q, joints_v = list(layout.joint_qpos), list(layout.joint_dof)
    act, gear, limit = list(layout.actuator_of_joint), np.asarray(layout.gear), np.asarray(layout.effort_limit)
    target = d.qpos[joints_q].copy()
    readings, line, base = [], [np.zeros(3)] * (action_delay + 1), []
    for j in range(STEPS):
        base.append(d.qpos[:3].copy())
        readings.append((d.qpos[joints_q].copy(), d.qvel[joints_v].copy()))
        q, w = readings[max(j - sensor_delay, 0)]
        line = [np.clip(HOLD_GAINS["p"] * kp * (target - q) - HOLD_GAINS["d"] * kd * w, -limit, limit)] + line[:-1]
        d.ctrl[act] = line[action_delay] / gear
        mujoco.mj_step(m, d)
    return np.array(base)


def observing_hold(layout) -> Controller:
    """`hold`, and the sums of the IMU rate and odometry position it was given (what it read)."""
    inner = hold(layout)

    def act(cs, obs, gravity):
        ctrl, held = inner.act(cs[0], obs, gravity)
        return ctrl, (held, cs[1] + obs.qvel[3:6], cs[2] + obs.qpos[:3])

    return Controller(name="observing hold",
                      init=lambda obs, params: (inner.init(obs, params), jnp.zeros(3), jnp.zeros(3)), act=act)


@pytest.fixture(scope="module")
def batch(mj_model, tmp_path_factory):
    """The batch run with one compile, then again from the values its .npz file recorded (`simulate.arrays`):
    (sim, qpos0, [(final, trajectory)] * 2)."""
    from hopper_mjx import registry, simulate

    sim = Sim(mj_model, engine="chain", max_delay=8, sensing=Sensing(max_delay=8, noisy=True))
    n = len(CASES)
    action, sensor, kp, kd = (np.array(c, dtype=float) for c in zip(*CASES))
    qpos0 = np.array(sim.robot.stance_qpos)
    qpos0[2] += DROP
    noise = np.zeros(n)
    noise[NOISY] = 1.0
    # As `Scenario.controls` draws them (delays in ms: 1 ms steps here).
    controls = {"action_delay": action, "sensor_delay": sensor, "kp_scale": np.outer(kp, np.ones(3)),
                "kd_scale": np.outer(kd, np.ones(3)), "gyro_noise": GYRO_STD * noise,
                "gyro_bias": np.outer(noise, BIAS), "odom_pos_noise": POS_STD * noise, "accel_noise": ACCEL_STD * noise}
    controller = observing_hold(sim.layout)
    runs, file = [], tmp_path_factory.mktemp("recorded") / "run.npz"
    for _ in range(2):
        final, traj = sim.run(gravity_vectors([9.81] * n), controller,
                              pd_scale(n, controls["kp_scale"], controls["kd_scale"]),
                              duration=STEPS * sim.layout.timestep, sensors=SENSORS, qpos=qpos0, key=3,
                              **sim.per_instance(controls))
        runs.append(jax.tree_util.tree_map(np.asarray, (final, traj)))
        np.savez(file, **simulate.arrays(traj, np.zeros((n, 3)), final.diverged, final.drive, controls=controls))
        with np.load(file) as recorded:  # the next run: what the file holds, and nothing else
            controls = {k: recorded[k] for k in registry.CONTROL_PARAMETERS if k in recorded}
    return sim, qpos0, runs


def test_each_instances_delays_and_gains_are_mujoco_cs_given_the_same(mj_model, batch):
    """Every instance follows MuJoCo C given its own action delay, sensor delay and PD factors, through the
    landing, in one batch; the delays and gains change the path measurably; an instance whose gains are 0
    holds no torque (its motors do no work, and it falls as the limp robot)."""
    sim, qpos0, [(final, traj), _] = batch
    prompt = traj.qpos[0, :, :3]
    assert traj.contact.flag[0].any()
    for i, case in enumerate(CASES):
        reference = c_hold_run(mj_model, sim.layout, qpos0, *case)
        err = np.abs(reference - traj.qpos[i, :, :3]).max()
        assert err < 1e-3, f"instance {i} {case}: {err:.2e} m from MuJoCo C"
        if case[:2] != (0, 0) or case[2:] != (1.0, 1.0):
            assert np.abs(prompt - traj.qpos[i, :, :3]).max() > 5e-3, f"instance {i} {case} changed nothing"
    assert float(final.drive.energy[4]) == 0.0
    assert float(final.drive.energy[0]) > 1.0


def test_sensor_noise_and_bias_are_each_instances_own(batch):
    """The noisy instance's controller reads its IMU rate with the bias (the mean over the run), its recorded
    IMU and odometry carry its noise's std and bias; every other instance reads exact values, as late as its
    sensor delay, and records exact values. The run re-created from the values its file recorded (and the
    same seed) is the same run, noise and all."""
    _, _, [(final, traj), (final2, traj2)] = batch
    for a, b in ((traj.qpos, traj2.qpos), (traj.imu.gyro, traj2.imu.gyro), (final.cstate[1], final2.cstate[1])):
        np.testing.assert_array_equal(a, b)
    read_rate = final.cstate[1] / STEPS  # the mean rate the controller read
    true_rate = traj.qvel[:, :, 3:6].mean(axis=1)  # every step's state (1 kHz)
    np.testing.assert_allclose(read_rate[NOISY] - true_rate[NOISY], BIAS, atol=4 * GYRO_STD / math.sqrt(STEPS))
    exact = [i for i in range(len(CASES)) if i != NOISY]
    for i in exact:  # what it read: each step's state, `sensor delay` steps late (the first until then)
        late = np.maximum(np.arange(STEPS) - CASES[i][1], 0)
        np.testing.assert_allclose(read_rate[i], traj.qvel[i, late, 3:6].mean(axis=0), atol=1e-5)
        np.testing.assert_allclose(final.cstate[2][i] / STEPS, traj.qpos[i, late, :3].mean(axis=0), atol=1e-5)
    every = 10  # the IMU and odometry at 100 Hz, the state at 1 kHz: the same instants
    gyro_error = traj.imu.gyro - traj.qvel[:, ::every, 3:6]
    pos_error = traj.odom.pos - traj.qpos[:, ::every, :3]
    assert np.abs(gyro_error[exact]).max() == 0.0 and np.abs(pos_error[exact]).max() == 0.0
    samples = gyro_error.shape[1]
    np.testing.assert_allclose(gyro_error[NOISY].mean(axis=0), BIAS, atol=4 * GYRO_STD / math.sqrt(samples))
    assert 0.7 * GYRO_STD < gyro_error[NOISY].std(axis=0).mean() < 1.3 * GYRO_STD
    assert 0.7 * POS_STD < pos_error[NOISY].std() < 1.3 * POS_STD


def test_control_parameters_draw_from_the_seed_and_land_where_they_say(mj_model):
    """Per-joint factors (3,) per instance, delays rounded to whole steps (ms), a bias per axis; the
    same seed the same values; adding them leaves the model fields' draws as they were."""
    spec = Spec.parse("foot_friction=0.4..1.0,kp_scale=scale(0.5,1.5),action_delay=0..10,gyro_bias=normal(0,0.01),"
                      "motor_stall_torque=scale(0.8,1.2)")
    drawn = draw.draw_controls(spec, mj_model, 50, 4)
    assert {k: v.shape for k, v in drawn.items()} == {"kp_scale": (50, 3), "action_delay": (50,),
                                                      "gyro_bias": (50, 3), "motor_stall_torque": (50, 3)}
    assert drawn["kp_scale"].min() >= 0.5 and drawn["kp_scale"].max() <= 1.5 and drawn["kp_scale"].std() > 0.2
    np.testing.assert_array_equal(drawn["action_delay"], np.round(drawn["action_delay"]))  # 1 ms steps
    assert set(drawn["action_delay"]) <= set(range(11)) and len(set(drawn["action_delay"])) > 5
    effort = np.asarray(sim_layout(mj_model).effort_limit)
    ratio = drawn["motor_stall_torque"] / effort
    assert ratio.min() >= 0.8 and ratio.max() <= 1.2
    again = draw.draw_controls(spec, mj_model, 50, 4)
    for k in drawn:
        np.testing.assert_array_equal(drawn[k], again[k])
    alone = Spec.parse("foot_friction=0.4..1.0")
    np.testing.assert_array_equal(draw.draw(spec, mj_model, 50, 4)["pair_friction"],
                                  draw.draw(alone, mj_model, 50, 4)["pair_friction"])
    assert set(draw.control_columns(drawn)) >= {"kp_scale_haa", "kp_scale_kfe", "action_delay", "gyro_bias_z"}


def sim_layout(mj_model):
    from hopper_mjx.model.layout import Layout

    return Layout.of(mj_model)


def test_a_drawn_negative_value_is_refused_naming_the_instance(mj_model):
    with pytest.raises(ValueError, match=r"action_delay drew a value of -[\d.]+ ms for instance \d+; it must be >= 0"):
        draw.draw_controls(Spec.parse("action_delay=normal(1,5)"), mj_model, 20, 0)
