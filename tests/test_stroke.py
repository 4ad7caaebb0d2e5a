"""The full stroke (`control.stroke`): its geometry and energy against the leg's own formulas, and when the jump takes
it. The apex it reaches, against the energy bound, is in test_jump.py (it shares the jump's compiled rollout)."""

import jax.numpy as jnp
import numpy as np
import pytest

from hopper_mjx.control import kinematics, raibert, stroke
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import Robot

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
