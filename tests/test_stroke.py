"""The full stroke (`control.stroke`): its geometry and energy against the leg's own formulas, and when the jump takes
it. The apex it reaches, against the energy bound, is in test_jump.py (it shares the jump's compiled rollout)."""

import jax.numpy as jnp
import numpy as np
import pytest

from hopper_mjx.control import kinematics, raibert, stroke
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import Robot, stance_qpos

GRAVITY = (1.62, 3.71, 9.81)


def test_knee_at_inverts_the_virtual_leg(mj_model):
    leg = Robot.of(mj_model).leg
    knees = jnp.linspace(-1.55, -0.05, 31)
    np.testing.assert_allclose(stroke.knee_at(leg, kinematics.leg_length(leg, knees)), knees, atol=1e-5)


def test_the_thrust_gives_the_hops_energy_up_to_what_the_landing_can_brake(mj_model):
    """Force times the stroke to the release length is m·g·(z_apex - z); a hop higher than the stroke brakes from
    (the knee's effort limit over its travel, release to bottom) is cut to that."""
    robot = Robot.of(mj_model)
    leg, lay = robot.leg, Layout.of(mj_model)
    mass, effort, lowest = lay.total_mass, jnp.asarray(lay.effort_limit), lay.joint_range[2][0]
    length = kinematics.leg_length(leg, lowest + stroke.LOW_MARGIN)
    body = type("Bottom", (), {"length": length, "z": 0.75})()
    run = float(stroke.release_length(leg) - length)
    assert run > 5 * raibert.RaibertConfig().sag  # 0.16 m of virtual leg: more than five times the spring's sag
    low = stroke.thrust(leg, body, 0.75 + 0.5, 9.81, mass, lowest, effort)
    assert float(low) * run == pytest.approx(mass * 9.81 * 0.5, rel=1e-5)
    cap = float(stroke.absorbable(lowest, effort[2]))
    assert cap == pytest.approx(80.0 * (stroke.RELEASE_KNEE + 1.6 - stroke.LOW_MARGIN), rel=1e-6)
    high = stroke.thrust(leg, body, 0.75 + 50.0, 9.81, mass, lowest, effort)
    assert float(high) * run == pytest.approx(cap, rel=1e-5)


@pytest.mark.parametrize("g", GRAVITY)
def test_the_ordinary_hop_is_raiberts_and_a_hop_past_its_stroke_is_the_full_one(mj_model, g):
    """At touchdown from a 0.1 m hop, the default command needs far less than the ordinary stroke holds (so the jump
    is Raibert there); a 4 m command needs more than `FULL_MARGIN` times it."""
    robot = Robot.of(mj_model)
    lay = Layout.of(mj_model)
    gains = raibert.RaibertConfig()
    length = gains.leg_length
    z = robot.standing_height + 0.02
    body = type("Touchdown", (), {"z": z, "zdot": -np.sqrt(2 * g * 0.1)})()
    needs = lambda rise: bool(stroke.needs_full(robot.leg, body, gains, robot.standing_height + rise, g,
                                                 lay.total_mass, lay.effort_limit[2]))
    assert length > 0 and not needs(raibert.DEFAULT_HEIGHT)
    assert needs(4.0)


@pytest.mark.parametrize("hfe", (0.5, 0.8))
def test_the_hip_torques_turn_the_robot_at_the_rate_asked_in_mujoco_c(mj_model, hfe):
    """`stroke.hip_torques` (the static balance of the leg, -J'⁻¹Δτ at the foot) against MuJoCo C: from a stance with
    the whole weight pushed along the foot -> COM line, one step with those torques added turns the robot (its
    angular momentum about the COM) at the rate asked within 30 %, about the right axis; the knee is left alone."""
    import mujoco

    lay, leg = Layout.of(mj_model), Robot.of(mj_model).leg
    qpos = stance_qpos(mj_model, clearance=-0.002, hfe=hfe)  # the foot just into the floor: in contact
    q = jnp.asarray(qpos[7:10])
    jac = kinematics.jacobian(leg, q)
    to_com = np.asarray(kinematics.com_position(leg, q) - kinematics.foot_position(leg, q))
    hold = -np.asarray(jac).T @ (lay.total_mass * 9.81 * to_com / np.linalg.norm(to_com))

    def turning(torque):
        d = mujoco.MjData(mj_model)
        d.qpos[:] = qpos
        d.qfrc_applied[list(lay.joint_dof)] = torque
        mujoco.mj_step(mj_model, d)
        assert d.ncon >= 1
        return np.asarray(kinematics.angular_momentum(leg, jnp.asarray(d.qpos[7:10]), jnp.asarray(d.qvel[6:9]),
                                                      jnp.asarray(d.qvel[3:6])))[:2] / mj_model.opt.timestep

    still = turning(hold)
    for rate in ((0.0, 5.0), (3.0, 0.0), (-2.0, -4.0)):
        extra = np.asarray(stroke.hip_torques(jac, jnp.asarray(to_com), jnp.asarray(rate)))
        assert extra[2] == 0.0
        np.testing.assert_allclose(turning(hold + extra) - still, rate, rtol=0.3, atol=0.3 * max(map(abs, rate)))


def test_the_push_is_spent_on_the_dc_motors_speed_line_and_never_on_ideal_ones(mj_model):
    """The thrust ends at once (`release` 0 m) where the hip or knee reaches `SPENT` of its motor's no-load speed,
    the URDF's <limit velocity> for DC motors; ideal motors have no speed line, so their thrust runs to the
    release length whatever the speed."""
    from hopper_mjx.hardware.actuators import nominal_no_load

    lay, leg = Layout.of(mj_model), Robot.of(mj_model).leg
    dc, ideal = nominal_no_load(lay, "dc"), nominal_no_load(lay, "ideal")
    assert np.all(np.isfinite(dc)) and np.all(np.isinf(ideal))
    body = lambda hfe, kfe: type("Thrust", (), {"qd": jnp.array([0.0, hfe, kfe])})()
    share = stroke.SPENT
    cases = (((-0.9 * dc[1], 0.9 * dc[2]), False), ((-(share + 0.01) * dc[1], 0.5 * dc[2]), True),
             ((-0.5 * dc[1], (share + 0.01) * dc[2]), True))
    for (hfe, kfe), spent in cases:
        assert bool(stroke.spent(body(hfe, kfe), jnp.asarray(dc))) is spent
        release = float(stroke.release(leg, body(hfe, kfe), jnp.asarray(dc)))
        assert release == (0.0 if spent else float(stroke.release_length(leg)))
        assert not bool(stroke.spent(body(10 * hfe, 10 * kfe), jnp.asarray(ideal)))


def test_the_spin_loop_feeds_forward_what_the_leg_turned_beyond_what_was_asked():
    """One step on: the momentum's change over `dt` less the rate asked last step is the leg's own turning, and the
    rate asked now takes the momentum to zero at H / `SPIN_TIME` against it; off, the loop asks nothing."""
    jac, to_com = jnp.eye(3), jnp.array([0.02, 0.0, 0.6])
    dt, spin = 0.001, jnp.array([0.001, -0.003])
    loop = stroke.SpinLoop(spin=jnp.zeros(2), asked=jnp.array([0.5, 1.0]), unasked=jnp.zeros(2))
    torque, after = loop.step(spin, jnp.bool_(True), jac, to_com, dt)
    np.testing.assert_allclose(after.unasked, spin / dt - loop.asked, rtol=1e-5)
    np.testing.assert_allclose(after.asked, -spin / stroke.SPIN_TIME - after.unasked, rtol=1e-5)
    np.testing.assert_allclose(torque, stroke.hip_torques(jac, to_com, after.asked), rtol=1e-6)
    torque, off = loop.step(spin, jnp.bool_(False), jnp.zeros((3, 3)), to_com, dt)  # a J with no inverse
    assert not np.any(np.asarray(torque)) and not np.any(np.asarray(off.asked))


def test_with_dc_motors_the_full_stroke_leaves_the_floor_without_a_spin():
    """Asked for a 40 m rise at Ceres and the Moon with DC motors, the jump's first hop flies with the whole robot's
    angular momentum under 0.008 N·m·s about each axis (at Ceres 0.008 N·m·s turns the flying robot by about 0.4
    rad over its 18 s flight). Before the thrust steered the spin and ended where the motors' speed line runs out,
    it left with -0.013, -0.023 at Ceres and 0.020 about roll at the Moon."""
    from hopper_mjx.control import jump
    from hopper_mjx.model import loader
    from hopper_mjx.sim import Sim

    gravity = (0.28, 1.62)
    sim = Sim(loader.load(), motor="dc")
    params = raibert.raibert_params(len(gravity), height=40.0)
    _, traj = sim.run(jnp.asarray([[0.0, 0.0, -g] for g in gravity]), jump.jump(sim.robot, motor="dc"), params,
                      duration=4.0)
    qpos, qvel = np.asarray(traj.qpos), np.asarray(traj.qvel)
    leg = sim.robot.leg
    for i, g in enumerate(gravity):
        top = int(np.argmax(qpos[i, :, 2]))  # in the flight: the Moon's top, Ceres still rising
        assert qpos[i, top, 2] > sim.robot.standing_height + 1.0, g
        momentum = kinematics.angular_momentum(leg, jnp.asarray(qpos[i, top, 7:10]), jnp.asarray(qvel[i, top, 6:9]),
                                               jnp.asarray(qvel[i, top, 3:6]))
        assert np.abs(np.asarray(momentum)).max() < 0.008, (g, momentum)
