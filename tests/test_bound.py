"""The jump bound (`hardware.bound`): the most one stance can put into a jump, checked against MuJoCo C.

The check is a jump in MuJoCo C on the compiled model: the robot crouched at rest on its foot (knee at its stop,
the centre of mass over the foot), its knee given all its motor allows at each step (the effort limit, or the DC
line at the knee's speed), its hips held by PD on the bound's pose. No such push may fly higher than the bound,
and this simple one reaches most of it.
"""

from __future__ import annotations

import copy
import math

import mujoco
import numpy as np
import pytest

from hopper_mjx.hardware import bound
from hopper_mjx.model import loader
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import standing_height

GRAVITIES = (1.62, 3.71, 9.81)


@pytest.fixture(scope="module")
def model():
    return loader.load()


@pytest.fixture(scope="module")
def leg(model):
    return bound.stroke(model)


def push_in_mujoco(m: mujoco.MjModel, leg: bound.Stroke, motor: bound.KneeMotor, g: float) -> float:
    """m: the base's apex over standing of a full-torque knee push from the crouch, in MuJoCo C."""
    m = copy.copy(m)  # gravity set here only
    m.opt.gravity[:] = (0.0, 0.0, -g)
    lay = Layout.of(m)
    d = mujoco.MjData(m)
    haa, hfe, kfe = lay.joint_qpos
    d.qpos[[haa, hfe, kfe]] = (0.0, leg.hip[0], leg.knee[0])
    mujoco.mj_kinematics(m, d)
    d.qpos[2] -= d.geom_xpos[lay.foot_geom, 2] - m.geom_size[lay.foot_geom, 0] - 1e-4  # foot on the floor
    dof, act, gear = list(lay.joint_dof), list(lay.actuator_of_joint), np.asarray(lay.gear)
    effort = np.asarray(lay.effort_limit)
    top, flying = d.qpos[2], False
    while d.time < 10.0:
        w = max(d.qvel[dof[2]], 0.0)
        knee = 0.0 if flying else min(motor.stall_torque * (1.0 - w / motor.no_load_speed), motor.torque_limit)
        hip = 400.0 * (np.interp(d.qpos[kfe], leg.knee, leg.hip) - d.qpos[hfe]) - 15.0 * d.qvel[dof[1]]
        side = -400.0 * d.qpos[haa] - 18.0 * d.qvel[dof[0]]
        d.ctrl[act] = np.clip([side, hip, knee], -effort, effort) / gear
        mujoco.mj_step(m, d)
        flying = flying or (d.ncon == 0 and d.time > 0.01)
        top = max(top, d.qpos[2])
        if flying and d.qvel[2] < 0.0:
            break
    return float(top - standing_height(m))


@pytest.mark.parametrize("kind", ["ideal", "dc"])
def test_no_push_in_mujoco_c_flies_higher_than_the_bound_and_a_full_one_reaches_most_of_it(model, leg, kind):
    motor, standing = bound.knee_motor(model, kind), standing_height(model)
    for g in GRAVITIES:
        limit = bound.jump_bound(leg, motor, g, standing).apex_rise
        measured = push_in_mujoco(model, leg, motor, g)
        print(f"{kind} g={g}: full push {measured:.3f} m, bound {limit:.3f} m ({measured / limit:.0%})")
        assert measured <= limit + 1e-3
        assert measured >= 0.6 * limit  # the bound is one a push can come near, not a loose ceiling


def test_the_ideal_motors_work_is_its_effort_limit_over_the_knees_travel(model, leg):
    motor = bound.knee_motor(model, "ideal")
    for g in GRAVITIES:
        b = bound.jump_bound(leg, motor, g, standing_height(model))
        assert b.energy == pytest.approx(motor.stall_torque * (b.takeoff_knee - leg.knee[0]), rel=1e-9)
        # The COM leaves at takeoff_speed: its apex is v²/2g over its lift-off height.
        assert b.takeoff_speed > 0


def test_a_dc_line_with_no_speed_limit_is_the_ideal_motor(model, leg):
    ideal = bound.knee_motor(model, "ideal")
    fast = bound.KneeMotor(ideal.stall_torque, 1e15, ideal.torque_limit)
    for g in GRAVITIES:
        a = bound.jump_bound(leg, ideal, g, 0.0)
        b = bound.jump_bound(leg, fast, g, 0.0)
        np.testing.assert_allclose(b, a, rtol=1e-9)


def test_the_dc_motor_bounds_lower_and_the_apex_grows_as_gravity_falls(model):
    ideal = bound.bounds(model, "ideal", (0.28, *GRAVITIES))
    dc = bound.bounds(model, "dc", (0.28, *GRAVITIES))
    for g in ideal:
        assert dc[g].energy < ideal[g].energy
        assert dc[g].apex_rise < ideal[g].apex_rise
    for table in (ideal, dc):
        rises = [table[g].apex_rise for g in (9.81, 3.71, 1.62, 0.28)]
        assert all(a < b for a, b in zip(rises, rises[1:]))
        # The same stance energy, less weight: about 1/g, so the Moon's rise is several times Earth's.
        assert table[1.62].apex_rise > 4.0 * table[9.81].apex_rise


def test_a_stronger_knee_raises_the_bound_in_proportion_to_its_work(model, leg):
    motor = bound.knee_motor(model, "ideal")
    strong = motor._replace(stall_torque=2 * motor.stall_torque, torque_limit=2 * motor.torque_limit)
    a, b = (bound.jump_bound(leg, k, 9.81, 0.0) for k in (motor, strong))
    assert b.apex_rise > a.apex_rise
    assert b.energy > 1.5 * a.energy


def test_a_bound_refuses_what_bounds_nothing(model, leg):
    with pytest.raises(ValueError, match="downward gravity"):
        bound.jump_bound(leg, bound.knee_motor(model, "ideal"), 0.0, 0.0)
    m = loader.load()
    lay = Layout.of(m)
    m.actuator_ctrlrange[lay.actuator_of_joint[bound.KNEE]] = (-math.inf, math.inf)
    m.actuator_ctrllimited[lay.actuator_of_joint[bound.KNEE]] = 0
    with pytest.raises(ValueError, match="no effort limit"):
        bound.knee_motor(m, "ideal")


def test_a_command_past_the_bound_is_named_at_the_gravities_it_passes(model):
    """`apex_bounds`: nothing for a rise within every gravity's bound; each gravity's bound once the rise passes the
    lowest (the highest gravity's). simulate's note names the gravities whose bound the gait's --height passes,
    with their bounds, and none for a controller that hops to no height."""
    from hopper_mjx.scenario import Physics, Scenario
    from hopper_mjx.sim import gravity_vectors
    from hopper_mjx.simulate import apex_note

    per_g = bound.bounds(model, "ideal", (1.62, 9.81))
    earth, moon = per_g[9.81].apex_rise, per_g[1.62].apex_rise
    assert 0.1 < earth < moon  # the default command is within it; lower gravity, higher bound
    assert bound.apex_bounds(model, "ideal", (1.62, 9.81), 0.99 * earth) == {}
    between = (earth + moon) / 2  # past Earth's bound, within the Moon's
    assert bound.apex_bounds(model, "ideal", (1.62, 9.81), between) == {g: b.apex_rise for g, b in per_g.items()}
    batch = Scenario(gravity_vectors([9.81, 1.62]), physics=Physics(), controller="raibert", height=between)
    note = apex_note(batch)
    assert note.startswith(f"note: --height {between:g} m") and f"at most {earth:.2f} m at g = 9.81 m/s² (" in note
    assert "1.62" not in note
    assert apex_note(Scenario(gravity_vectors([9.81, 1.62]), physics=Physics(), controller="raibert")) is None
    assert apex_note(Scenario(gravity_vectors([9.81]), physics=Physics(), controller="hold", height=between)) is None
