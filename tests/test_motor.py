"""Motor models: the DC motor's torque-speed envelope, and a joint under its own drive in the batched core."""

import jax.numpy as jnp
import numpy as np
import pytest

from hopper_mjx import signals
from hopper_mjx.control import motor
from hopper_mjx.control.base import Controller, to_ctrl
from hopper_mjx.model import loader


def test_the_envelope_is_the_torque_speed_line():
    stall, w0 = 80.0, 20.0
    speed = jnp.array([0.0, 10.0, 20.0, 30.0, -10.0, -20.0, -30.0])
    low, high = (np.asarray(x) for x in motor.envelope(stall, w0, speed))
    np.testing.assert_allclose(high, [80, 40, 0, 0, 80, 80, 80])  # drive along the motion falls to 0 at w0
    np.testing.assert_allclose(low, [-80, -80, -80, -80, -40, 0, 0])  # and against it, mirrored


def test_dc_motors_pass_commands_inside_the_envelope_and_clip_the_rest(mj_model):
    from hopper_mjx.model.layout import Layout

    lay = Layout.of(mj_model)
    leg = loader.describe(loader.DEFAULT_URDF.read_text())
    params = motor.dc_params(leg.transmissions, lay, 1)
    np.testing.assert_array_equal(params[motor.STALL][0], lay.effort_limit)  # the URDF's effort and velocity
    np.testing.assert_array_equal(params[motor.NO_LOAD][0], [20.0, 20.0, 20.0])
    one = {k: jnp.asarray(v[0]) for k, v in params.items()}
    rng = np.random.default_rng(0)
    for _ in range(200):
        torque, qvel = rng.uniform(-100, 100, 3), rng.uniform(-30, 30, lay.nv)
        ctrl = np.asarray(motor.limit(lay, one, to_ctrl(lay, jnp.asarray(torque)), jnp.asarray(qvel)))
        applied = ctrl[list(lay.actuator_of_joint)] * np.asarray(lay.gear)
        low, high = (np.asarray(x) for x in motor.envelope(one[motor.STALL], one[motor.NO_LOAD],
                                                         jnp.asarray(qvel[list(lay.joint_dof)])))
        assert (applied >= low - 1e-4).all() and (applied <= high + 1e-4).all()
        np.testing.assert_allclose(applied, np.clip(torque, low, high), atol=1e-4)


def test_simulate_records_the_motors_it_ran(tmp_path):
    from hopper_mjx import simulate

    out = tmp_path / "dc.npz"
    assert simulate.main(["--gravity", "1.62", "--num", "3", "--duration", "0.05", "--motor", "dc",
                          "--out", str(out)]) == 0
    saved = np.load(out)
    np.testing.assert_array_equal(saved[motor.STALL], np.tile([40.0, 80.0, 80.0], (3, 1)))
    np.testing.assert_array_equal(saved[motor.NO_LOAD], np.full((3, 3), 20.0))


@pytest.mark.parametrize("engine", ["chain", "mjx"])
def test_a_joint_under_its_own_drive_does_not_pass_its_no_load_speed(mj_model, engine):
    """Full torque on the hip in the air (no gravity): an ideal motor spins the leg past 20 rad/s within a few
    ms; a DC motor at the URDF's limits approaches its no-load speed and stays below it."""
    from hopper_mjx.sim import Sim

    sim = Sim(mj_model, engine=engine)
    lay = sim.layout
    push = Controller(name="push", init=lambda obs, params: (),
                      act=lambda cs, obs, gravity: (to_ctrl(lay, jnp.array([0.0, 80.0, 0.0])), cs))
    leg = loader.describe(loader.DEFAULT_URDF.read_text())
    dc = motor.dc_params(leg.transmissions, lay, 2)
    hfe = lay.joint_dof[1]
    speeds = {}
    for name, motors in (("ideal", None), ("dc", dc)):
        state = sim.reset(np.zeros((2, 3)), controller=push, motor=motors)
        _, traj = sim.rollout(state, push, steps=40, sensors=signals.SensorConfig.uniform(1000))
        speeds[name] = np.asarray(traj.qvel)[:, :, hfe]
    w0 = dc[motor.NO_LOAD][0, 1]
    assert speeds["ideal"].max() > 2 * w0
    assert speeds["dc"].max() <= w0 * 1.001 and speeds["dc"].max() > 0.9 * w0
