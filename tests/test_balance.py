"""The `balance` controller (the stand task's reference): its equilibrium and linearisation against
MuJoCo C, its design (what is and is not controllable, a stable closed loop), and kicked robots kept up."""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import pytest

from hopper_mjx.control import balance as bal
from hopper_mjx.metrics import hops
from hopper_mjx.model.layout import Layout
from hopper_mjx.sim import gravity_vectors

GRAVITIES = (9.81, 1.62)


@pytest.fixture(scope="module")
def c_linear(mj_model):
    return {g: bal.c_linearisation(mj_model, g) for g in GRAVITIES}


def test_equilibrium_is_at_rest_in_mujoco_c(mj_model):
    for g in GRAVITIES:
        qpos, torque = bal.equilibrium(mj_model, g)
        m = copy.deepcopy(mj_model)
        m.opt.gravity[:] = (0.0, 0.0, -g)
        d = mujoco.MjData(m)
        d.qpos[:] = qpos
        d.ctrl[:] = torque / np.asarray(Layout.of(m).gear)
        mujoco.mj_forward(m, d)
        assert np.abs(d.qacc).max() < 1e-6
        # the floor carries the whole weight, and the knee holds it (the hip sits above the foot)
        assert d.ncon == 1
        assert np.isclose(-d.qfrc_smooth[2], d.qfrc_constraint[2], rtol=1e-6)
        assert np.isclose(d.qfrc_constraint[2], Layout.of(m).total_mass * g, rtol=1e-6)


def test_riccati_by_doubling_solves_the_dare():
    rng = np.random.default_rng(0)
    a = np.eye(6) + 0.01 * rng.normal(size=(6, 6))  # slow, some modes unstable: the 1 kHz step's regime
    b = 0.01 * rng.normal(size=(6, 2))
    q, r = np.diag(rng.uniform(1, 10, 6)), np.diag(rng.uniform(0.1, 1, 2))
    p = bal.riccati(a, b, q, r)
    residual = q + a.T @ p @ a - a.T @ p @ b @ np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a) - p
    assert np.abs(residual).max() < 1e-8 * np.abs(p).max()
    assert np.all(np.linalg.eigvalsh(p) > 0)


def test_stance_falls_unaided_and_lqr_stabilises_it(mj_model, c_linear):
    """The open loop is unstable; the full state is not stabilisable (horizontal position and yaw are
    uncontrollable integrators); without them the LQR's closed loop has spectral radius < 1."""
    lay = Layout.of(mj_model)
    for g, lin in c_linear.items():
        d = bal.design(lin, lay)
        assert d.open_loop > 1.003, g  # the inverted pendulum: the stance falls by itself
        assert d.pbh > 1e-7 and d.closed_loop < 0.999, (g, d.pbh, d.closed_loop)
        assert bal.pbh(lin.a, lin.b) < 1e-9  # the whole state: not stabilisable
        without_yaw = np.array([i for i in range(2 * lay.nv) if i not in (bal.YAW, lay.nv + bal.YAW)])
        assert bal.pbh(lin.a[np.ix_(without_yaw, without_yaw)], lin.b[without_yaw]) < 1e-9  # x, y: rolling


def test_the_controller_holds_the_equilibrium_in_the_core(sim):
    """Started at rest at its equilibrium (no kick), 2 s at Earth and Moon gravity in the batched core
    (float32, the interpolated gain): upright to 1 mrad, at the equilibrium height to 1 mm. The sweep's
    kicks (std 0.03 m/s, rad/s) are another matter: docs/control.md measures them."""
    from hopper_mjx import control

    controller, params = control.make("balance", sim.robot, 2, mj_model=sim.mj_model)
    start = np.stack([bal.equilibrium(sim.mj_model, g)[0] for g in GRAVITIES])
    _, traj = sim.run(gravity_vectors(np.array(GRAVITIES)), controller, params, duration=2.0, qpos=start)
    qpos = np.asarray(traj.qpos)
    assert not hops.fallen(qpos).any()
    roll, pitch = hops.roll_pitch(qpos[:, :, 3:7])
    assert np.abs(roll).max() < 1e-3 and np.abs(pitch).max() < 1e-3
    assert np.abs(qpos[:, :, 2] - start[:, None, 2]).max() < 1e-3
