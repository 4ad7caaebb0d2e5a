"""Motor models and action delay: the core against MuJoCo C's own voltage-driven motor, the
torque-speed envelope, the no-load speed, the energy drawn and the delay line."""

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hopper_mjx.control.base import HOLD_GAINS, Controller, hold
from hopper_mjx.hardware import signals
from hopper_mjx.hardware.actuators import Actuation, envelope
from hopper_mjx.sim import Sim, gravity_vectors

G = np.array([9.81, 1.62])
STEPS = 700  # 0.7 s: the Moon instance lands too (0.61 s from 0.30 m)
SENSORS = signals.SensorConfig(imu_rate=100, odom_rate=100, contact_rate=1000, state_rate=1000)
DROP = 0.25  # m added to the stance's clearance: the landing drives the joints up the motors' torque-speed line
STIFF = {"p": 1500.0, "d": 8.0}  # N·m/rad, N·m·s/rad: a hold stiff enough to ask for more than the motors give
SLOW = 8.0  # rad/s: a motor's no-load speed (the URDF's is 20), given per instance, so that the line binds hard


def dropped(sim: Sim) -> np.ndarray:
    qpos = np.array(sim.robot.stance_qpos)
    qpos[2] += DROP
    return qpos


def c_motor_model(mj_model, layout, motor: str, w0) -> mujoco.MjModel:
    """MuJoCo C's model with each joint's actuator as the motor: `dc`, a voltage-driven DC motor
    (force = tau_s u - tau_s / w0 * speed, u in [-1, 1]: MuJoCo's affine gain and bias); `ideal`, as loaded."""
    m = copy.deepcopy(mj_model)
    if motor == "ideal":
        return m
    for a, tau_s, w0, gear in zip(layout.actuator_of_joint, layout.effort_limit, w0, layout.gear):
        m.actuator_gaintype[a] = mujoco.mjtGain.mjGAIN_FIXED
        m.actuator_gainprm[a, :3] = (tau_s / gear, 0, 0)
        m.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
        m.actuator_biasprm[a, :3] = (0, 0, -tau_s / (w0 * gear * gear))  # actuator velocity = gear * joint speed
        m.actuator_ctrlrange[a] = (-1, 1)
        m.actuator_forcelimited[a] = 1
        m.actuator_forcerange[a] = (-tau_s / gear, tau_s / gear)
    return m


def c_hold_run(mj_model, layout, motor: str, g: float, qpos0, delay: int = 0, gains=HOLD_GAINS, w0=None):
    """(base path (STEPS, 3), joint speeds (STEPS, 3), energy J) of MuJoCo C holding the initial joint
    angles with the hold law through `motor` (no-load speeds `w0`, default the URDF's; commands applied
    `delay` steps late), in float64."""
    w0 = np.asarray(layout.speed_limit if w0 is None else w0, dtype=float)
    m = c_motor_model(mj_model, layout, motor, w0)
    m.opt.gravity[:] = (0, 0, -g)
    d = mujoco.MjData(m)
    d.qpos[:] = qpos0
    joints_q, joints_v = list(layout.joint_qpos), list(layout.joint_dof)
    act, gear = list(layout.actuator_of_joint), np.asarray(layout.gear)
    tau_s = limit = np.asarray(layout.effort_limit)
    target = d.qpos[joints_q].copy()
    line = [np.zeros(3)] * (delay + 1)
    base, speeds, energy = [], [], 0.0
    for _ in range(STEPS):
        base.append(d.qpos[:3].copy())
        q, w = d.qpos[joints_q], d.qvel[joints_v]
        speeds.append(w.copy())
        line = [np.clip(gains["p"] * (target - q) - gains["d"] * w, -limit, limit)] + line[:-1]
        commanded = line[delay]
        if motor == "dc":
            d.ctrl[act] = np.clip(commanded / tau_s + w / w0, -1, 1)
            torque = np.clip(commanded, tau_s * (-1 - w / w0), tau_s * (1 - w / w0))
            energy += m.opt.timestep * np.maximum(torque * w + torque**2 * w0 / tau_s, 0).sum()
        else:
            d.ctrl[act] = commanded / gear
            energy += m.opt.timestep * np.abs(commanded * w).sum()
        mujoco.mj_step(m, d)
    return np.array(base), np.array(speeds), energy


@pytest.fixture(scope="module", params=["chain", "mjx"])
def engine(request):
    return request.param


def core_hold_run(mj_model, engine: str, motor: str, delay: int = 0, gains=HOLD_GAINS, w0=None):
    sim = Sim(mj_model, engine=engine, motor=motor, delay_steps=delay)
    ctrl = hold(sim.layout, **gains)
    figures = sim.actuation.motor(len(G), no_load_speed=w0, delay_steps=delay) if w0 is not None else None
    final, traj = sim.run(gravity_vectors(G), ctrl, duration=STEPS * sim.layout.timestep, sensors=SENSORS,
                          qpos=dropped(sim), motor=figures)
    return sim, final, jax.tree_util.tree_map(np.asarray, traj)


def test_dc_motor_is_mujoco_cs_voltage_driven_motor_through_a_hard_landing(mj_model, engine):
    """The core's dc motor (the envelope clip on the hold law's torque) against MuJoCo C's actuator
    with gain tau_s and velocity bias -tau_s / w0, driven by u = clip(tau / tau_s + w / w0): the same
    motor, written in MuJoCo's own terms. The landing makes it matter: ideal motors land elsewhere."""
    w0 = np.full(3, SLOW)
    sim, final, traj = core_hold_run(mj_model, engine, "dc", gains=STIFF, w0=w0)
    _, _, ideal = core_hold_run(mj_model, engine, "ideal", gains=STIFF) if engine == "chain" else (None,) * 3
    qpos0 = dropped(sim)
    for i, g in enumerate(G):
        base, speeds, energy = c_hold_run(mj_model, sim.layout, "dc", g, qpos0, gains=STIFF, w0=w0)
        assert traj.contact.flag[i].any(), "the comparison must include the landing"
        err = np.abs(base - traj.qpos[i, :, :3]).max()
        assert err < 1e-3, f"g={g}: the {engine} core's dc motor and MuJoCo C's differ by {err:.2e} m"
        assert float(final.drive.energy[i]) == pytest.approx(energy, rel=2e-3)
        if g == 9.81:  # Earth's landing is the hard one: there the line binds and the motor shows
            assert np.abs(speeds).max() > 0.5 * SLOW, "the landing must drive the joints well up the line"
            if ideal is not None:
                assert np.abs(ideal.qpos[i, :, :3] - traj.qpos[i, :, :3]).max() > 5e-3


def test_a_joint_driving_itself_never_passes_the_no_load_speed(mj_model):
    """Full torque on the knee, the robot floating without gravity: the dc knee tends to its no-load
    speed and never passes it; the ideal knee (a torque source) does pass it."""
    top = {}
    for motor in ("ideal", "dc"):
        sim = Sim(mj_model, engine="chain", motor=motor)
        lay = sim.layout
        knee = 2
        ctrl = jnp.zeros(lay.nu).at[lay.actuator_of_joint[knee]].set(-lay.effort_limit[knee] / lay.gear[knee])
        push = Controller(name="push", init=lambda obs, params: (), act=lambda c, obs, g: (ctrl, c))
        qpos = np.array(sim.robot.stance_qpos)
        qpos[lay.joint_qpos[knee]] = lay.joint_range[knee][1] - 0.05  # as far from the knee's stop as it goes
        _, traj = sim.run(np.zeros((1, 3)), push, duration=0.04, sensors=SENSORS, qpos=qpos)
        top[motor] = np.abs(np.asarray(traj.qvel)[0, :, lay.joint_dof[knee]]).max()
    w0 = sim.layout.speed_limit[2]
    assert 0.9 * w0 < top["dc"] <= w0 * (1 + 1e-4)
    assert top["ideal"] > 1.2 * w0


def test_the_delay_applies_each_command_that_many_steps_late(mj_model):
    """A 10-step delay on ideal motors against MuJoCo C given each command 10 steps late (and no
    torque before the first arrives), at Earth, through the landing (200 ms past touchdown); the
    delay moves the landing measurably. Later, and in the Moon's 0.6 s of flight, the delayed hold
    loop oscillates and grows: an instability of the delayed loop, which then separates float32 from
    float64, so it is not compared."""
    sim, _, late = core_hold_run(mj_model, "chain", "ideal", delay=10)
    _, _, prompt = core_hold_run(mj_model, "chain", "ideal")
    base, _, _ = c_hold_run(mj_model, sim.layout, "ideal", G[0], dropped(sim), delay=10)
    through = np.argmax(late.contact.flag[0]) + 200
    assert late.contact.flag[0].any() and through < STEPS
    assert np.abs(base[:through] - late.qpos[0, :through, :3]).max() < 1e-3
    assert np.abs(prompt.qpos[0, :through, :3] - late.qpos[0, :through, :3]).max() > 5e-3


def test_the_envelope_is_the_torque_speed_line(mj_model):
    """Stall torque at rest, nothing at the no-load speed in the drive's direction, the current limit
    everywhere, and braking allowed beyond the line (a motor turned backwards can still resist)."""
    from hopper_mjx.model.layout import Layout

    lay = Layout.of(mj_model)
    motor = Actuation(lay, "dc").motor(1, torque_limit=np.asarray(lay.effort_limit) * 0.75)
    motor = jax.tree_util.tree_map(lambda a: a[0], motor)
    tau_s, w0 = np.asarray(lay.effort_limit), np.asarray(lay.speed_limit)
    low, high = (np.asarray(v) for v in envelope(motor, jnp.zeros(3)))
    np.testing.assert_allclose(high, 0.75 * tau_s, rtol=1e-6)
    np.testing.assert_allclose(low, -0.75 * tau_s, rtol=1e-6)
    low, high = (np.asarray(v) for v in envelope(motor, jnp.asarray(w0, jnp.float32)))
    np.testing.assert_allclose(high, 0.0, atol=1e-4)
    np.testing.assert_allclose(low, -0.75 * tau_s, rtol=1e-6)
    low, high = (np.asarray(v) for v in envelope(motor, jnp.asarray(0.5 * w0, jnp.float32)))
    np.testing.assert_allclose(high, 0.5 * tau_s, rtol=1e-5)


def test_pushes_change_the_base_velocity_by_their_speed_at_their_times(mj_model):
    """Floating limp without gravity, the base's horizontal velocity is constant except at each push,
    where it jumps by exactly the push speed, every `interval`, in directions that differ by instance;
    the same seed gives the same pushes."""
    from hopper_mjx.control.base import zero_torque
    from hopper_mjx.hardware.pushes import Pushes

    sim = Sim(mj_model, engine="chain", pushes=Pushes.of(0.05, 0.3, 1e-3))
    limp = zero_torque(sim.layout)
    runs = [jax.tree_util.tree_map(np.asarray, sim.run(np.zeros((3, 3)), limp, duration=0.2, sensors=SENSORS,
                                                       key=5)[1]) for _ in range(2)]
    np.testing.assert_array_equal(runs[0].qvel, runs[1].qvel)
    v = runs[0].qvel[:, :, :2]  # (N, T, 2): the state at t = k ms, before step k + 1
    jumps = np.linalg.norm(np.diff(v, axis=1), axis=-1)
    for i in range(3):
        steps = np.flatnonzero(jumps[i] > 1e-4) + 1
        np.testing.assert_array_equal(steps, [50, 100, 150])  # each push lands at t = 0.05, 0.10, 0.15 s
        np.testing.assert_allclose(jumps[i, steps - 1], 0.3, rtol=1e-5)
    first = v[:, 50] - v[:, 49]
    assert np.linalg.norm(first[0] - first[1]) > 1e-3  # instances are pushed their own ways
