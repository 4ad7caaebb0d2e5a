"""The core's traced programs kept on disk (`shell.programs`): a later process runs the stored program without
tracing the step again, with the same numbers; another configuration, a damaged entry or a controller that
cannot name what it closed over is traced anew."""

import numpy as np
import pytest

from hopper_mjx import control, model
from hopper_mjx.control.base import hold
from hopper_mjx.hardware.signals import SensorConfig
from hopper_mjx.model.world import gravity_vectors
from hopper_mjx.shell import programs
from hopper_mjx.sim import Sim

STEPS = 40


class Traced(Exception):
    pass


def _run(mj_model, name="hold", sensors=SensorConfig()):
    """A fresh core (nothing compiled in this process's Sim) and one rollout: (final qpos, recorded IMU)."""
    sim = Sim(mj_model)
    ctrl, params = control.make(name, sim.robot, 3)
    state = sim.reset(gravity_vectors([9.81, 3.71, 1.62]), key=3, controller=ctrl, params=params,
                      qvel=np.full(sim.layout.nv, 0.2))
    final, traj = sim.rollout(state, ctrl, steps=STEPS, sensors=sensors)
    return np.asarray(final.data.qpos), np.asarray(traj.imu.accel)


@pytest.fixture
def store(tmp_path, monkeypatch):
    monkeypatch.setattr(programs, "folder", lambda: tmp_path)
    return tmp_path


def _no_tracing(monkeypatch):
    def refuse(self, *args):
        raise Traced
    monkeypatch.setattr(programs.Stored, "_trace", refuse)


def test_a_stored_program_runs_untraced_with_the_same_numbers(store, monkeypatch, mj_model):
    first = _run(mj_model)
    stored = sorted(store.iterdir())
    assert len(stored) == 1 and stored[0].stat().st_size > 10_000  # one program, the whole rollout
    _no_tracing(monkeypatch)
    again = _run(mj_model)  # a new core, as a later process would build it: read back, not traced
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    assert np.abs(first[0][:, :3]).max() > 0  # a real run: the bases moved


def test_another_configuration_or_a_damaged_entry_is_traced_anew(store, monkeypatch, mj_model):
    first = _run(mj_model)
    with monkeypatch.context() as m:
        _no_tracing(m)
        with pytest.raises(Traced):  # another model (a 2 ms step): another program
            _run(model.load(model.DEFAULT_URDF, timestep=0.002))
        with pytest.raises(Traced):  # another controller
            _run(mj_model, "none")
    (entry,) = store.iterdir()
    entry.write_bytes(entry.read_bytes()[:-100] + bytes(100))  # damaged: traced again, the same numbers
    again = _run(mj_model)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)


def test_a_rate_written_as_a_whole_number_is_the_same_program(store, monkeypatch, mj_model):
    """A sweep writes its rates as whole numbers (100), `simulate` as floats (100.0): equal configurations, one
    stored program, read back without tracing. Another rate is another program."""
    first = _run(mj_model)  # the default record: 50.0 Hz
    _no_tracing(monkeypatch)
    again = _run(mj_model, sensors=SensorConfig(imu_rate=50, odom_rate=50, contact_rate=50, state_rate=50))
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(Traced):
        _run(mj_model, sensors=SensorConfig(imu_rate=100))


def test_a_controller_without_a_key_is_never_stored(store, mj_model):
    sim = Sim(mj_model)
    ctrl = hold(sim.layout)
    unnamed = type(ctrl)(name="hold", init=ctrl.init, act=ctrl.act)  # built by hand: no key
    state = sim.reset(gravity_vectors([9.81]), controller=unnamed)
    sim.rollout(state, unnamed, steps=STEPS)
    assert not any(store.iterdir())


def test_raiberts_inertia_facts_are_worked_out_once_and_read_back_bit_for_bit(store, monkeypatch, mj_model):
    """`programs.remembered`: the first Raibert computes its facts and keeps them; later ones read them back
    without computing, equal to the last bit; a damaged entry is computed again."""
    from hopper_mjx.control import raibert
    from hopper_mjx.model.robot import Robot

    robot, facts, computed = Robot.of(mj_model), raibert.inertia_facts, []

    def counting(leg, *args):
        computed.append(True)
        return facts(leg, *args)

    monkeypatch.setattr(raibert, "inertia_facts", counting)
    raibert.raibert(robot)
    raibert.raibert(robot)
    assert len(computed) == 1 and len(list(store.iterdir())) == 1
    kept = programs.remembered(f"raibert inertia facts|{robot!r}", lambda: None)  # read back: never computed
    for a, b in zip(kept, facts(robot.leg)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.asarray(kept.robot).shape == (3,) and (np.asarray(kept.robot) > 0).all()  # kg·m² about each axis
    for entry in store.iterdir():
        entry.write_bytes(entry.read_bytes()[:-5] + b"xxxxx")
    raibert.raibert(robot)
    assert len(computed) == 2
