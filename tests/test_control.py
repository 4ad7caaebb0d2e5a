"""Joint PID (ros_control semantics), leg kinematics and the Raibert hopping controller.

The Raibert checks share ONE batched rollout (3 gravities x 4 commands, 20 s,
one compile); the robustness batch is a second, marked slow.
"""

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hopper_mjx import model
from hopper_mjx.control import kinematics, pid, raibert
from hopper_mjx.hardware import signals
from hopper_mjx.metrics import hops
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import LegGeometry
from hopper_mjx.sim import Sim, gravity_vectors

GRAVITIES = (9.81, 3.71, 1.62)
COMMANDS = ((0.0, 0.0), (0.5, 0.0), (0.0, 0.3), (0.0, -0.3))  # m/s
HEIGHT = 0.10  # m of commanded apex rise
DURATION = 20.0  # s
RATE = 200  # Hz of the state and contact streams (the oracle fits flight parabolas)

# PID step response of a fixed-base leg with the shipped gains (docs/control.md).
STEP = 0.1  # rad
SETTLE_TIME = 0.3  # s to stay within SETTLE_BAND of the target
SETTLE_BAND = 0.01  # rad
MAX_OVERSHOOT = 0.10  # fraction of the step


# -- PID ----------------------------------------------------------------------
def test_load_gains_reads_the_shipped_file():
    gains = pid.load_gains()
    assert set(gains) == {"haa_joint", "hfe_joint", "kfe_joint"}
    assert all(set(g) == {"p", "i", "d", "i_clamp"} and g["p"] > 0 for g in gains.values())


# The seed's config/monoped.yaml as ros_control tutorials lay it out: a namespace, comment
# banners, a joint_state_controller, and gains without i_clamp.
SEED_YAML = """\
monoped:
  # Publish all joint states -----------------------------------
  joint_state_controller:
    type: joint_state_controller/JointStateController
    publish_rate: 50

  # Position Controllers ---------------------------------------
  haa_joint_position_controller:
    type: effort_controllers/JointPositionController
    joint: haa_joint
    pid: {p: 100.0, i: 0.01, d: 10.0}
  hfe_joint_position_controller:
    type: effort_controllers/JointPositionController
    joint: hfe_joint
    pid: {p: 100.0, i: 0.01, d: 10.0}
  kfe_joint_position_controller:
    type: effort_controllers/JointPositionController
    joint: kfe_joint
    pid: {p: 100.0, i: 0.01, d: 10.0}
"""


@pytest.mark.parametrize("name", ["monoped.yaml", "monoped.yml"])
def test_the_seeds_file_loads_as_is_under_either_spelling(tmp_path, name):
    package = tmp_path / "my_legged_robots_sims"
    (package / "config").mkdir(parents=True)
    (package / "config" / name).write_text(SEED_YAML)
    expected = {j: {"p": 100.0, "i": 0.01, "d": 10.0, "i_clamp": 0.0} for j in ("haa_joint", "hfe_joint", "kfe_joint")}
    for path in (package / "config" / name, package / "config", package):  # the file, or a folder holding it
        assert pid.load_gains(path) == expected
    with pytest.raises(ValueError, match="no monoped.yaml or monoped.yml in the folder"):
        pid.load_gains(tmp_path)


@pytest.mark.parametrize(
    "text, message",
    [
        ("a: [", "not valid YAML"),
        (b"\xff\xfe\x00binary", "is not a text"),
        ("x_position_controller: {type: effort_controllers/JointPositionController, joint: elbow, "
         "pid: {p: 1}}", "unknown joint"),
        ("haa_joint_position_controller: {type: effort_controllers/JointPositionController, "
         "joint: haa_joint, pid: {p: -1}}", "pid.p must be finite and >= 0"),
        ("haa_joint_position_controller: {type: effort_controllers/JointPositionController, "
         "joint: haa_joint, pid: {p: 1}}", "no effort_controllers/JointPositionController for joint"),
        ("7: {type: effort_controllers/JointPositionController, joint: haa_joint, pid: {p: 1}}",
         "no effort_controllers/JointPositionController for joint"),  # an integer key: read, not a crash
        ("a_controller: {type: effort_controllers/JointPositionController, joint: haa_joint, pid: {p: 1}}\n"
         "b_controller: {type: effort_controllers/JointPositionController, joint: haa_joint, pid: {p: 2}}",
         "'b_controller' drives haa_joint, which 'a_controller' drives already"),
        ("#" * (2 << 20), "is over 1 MiB: not a PID gains file"),
    ],
)
def test_load_gains_rejects_bad_files(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_bytes(text) if isinstance(text, bytes) else path.write_text(text)
    with pytest.raises(ValueError, match=message) as err:
        pid.load_gains(path)
    assert "\n" not in str(err.value)


def test_load_gains_refuses_an_endless_file_without_reading_it_whole():
    with pytest.raises(ValueError, match="/dev/zero is over 1 MiB: not a PID gains file"):
        pid.load_gains("/dev/zero")


@pytest.fixture(scope="module")
def fixed_leg():
    """The monoped with its base welded 1 m above the floor, and a Layout for it."""
    spec = model.build_spec()
    spec.delete(spec.joint(model.ROOT_JOINT))
    spec.body("base").pos = [0, 0, 1.0]
    m = spec.compile()
    layout = dataclasses.replace(Layout.of(model.load()), nq=3, nv=3, joint_qpos=(0, 1, 2), joint_dof=(0, 1, 2))
    return m, layout


class JointData(NamedTuple):  # the part of mjx.Data the PID reads
    qpos: np.ndarray
    qvel: np.ndarray


def _run_pid(fixed_leg, start, target, seconds):
    """Native MuJoCo steps of the fixed leg under the batched PID's act (one instance)."""
    m, layout = fixed_leg
    controller = pid.pid(layout)
    params = jax.tree_util.tree_map(lambda x: x[0], pid.pid_params(1, target))
    d = mujoco.MjData(m)
    d.qpos[:] = start
    state = controller.init(JointData(d.qpos, d.qvel), params)
    act = jax.jit(controller.act)
    q, ctrl = [], []
    for _ in range(int(round(seconds / m.opt.timestep))):
        u, state = act(state, JointData(d.qpos, d.qvel), jnp.zeros(3))
        d.ctrl[:] = np.asarray(u)
        mujoco.mj_step(m, d)
        q.append(d.qpos.copy())
        ctrl.append(d.ctrl.copy())
    return np.array(q), np.array(ctrl), m.opt.timestep


def test_pid_step_response_settles(fixed_leg):
    start = np.array([0.0, 0.5, -0.95])
    target = start + STEP * np.array([1.0, 1.0, -1.0])
    q, ctrl, dt = _run_pid(fixed_leg, start, target, 1.0)
    error = target - q
    outside = np.abs(error) > SETTLE_BAND
    settle = (np.where(outside.any(axis=1))[0].max() + 1) * dt  # last time outside the band
    overshoot = np.max(-error * np.sign(target - start), axis=0) / STEP
    assert settle < SETTLE_TIME, f"settled after {settle:.3f} s"
    assert np.all(overshoot < MAX_OVERSHOOT), f"overshoot {overshoot}"
    assert np.all(np.abs(error[-1]) < 0.003)  # gravity's pull, 1-2 N·m, is being integrated away
    print(f"settle {settle:.3f} s, overshoot {np.round(overshoot, 3)}, error at 1 s {np.round(error[-1], 4)} rad")


def test_pid_saturates_at_the_effort_limits(fixed_leg):
    start = np.array([0.0, 0.0, -0.5])
    target = np.array([1.0, -1.0, -1.5])  # p·e is 400 N·m: far beyond every limit
    q, ctrl, _ = _run_pid(fixed_leg, start, target, 0.3)
    limit = np.array(fixed_leg[1].effort_limit)
    assert np.all(np.abs(ctrl) <= limit + 1e-6)
    np.testing.assert_allclose(np.abs(ctrl[0]), limit)  # saturated at the first step
    assert np.all(np.abs(target - q[-1]) < 0.05)  # and still gets there


# -- kinematics ---------------------------------------------------------------
def test_kinematics_match_mujoco(mj_model):
    leg = LegGeometry.of(mj_model)
    d = mujoco.MjData(mj_model)
    rng = np.random.default_rng(0)
    haa = mj_model.joint("haa_joint").id
    for _ in range(5):
        d.qpos[:] = mj_model.qpos0  # identity base orientation: base frame = world frame
        q = rng.uniform([-0.4, -0.8, -1.5], [0.4, 0.8, -0.1])
        d.qpos[7:10] = q
        d.qvel[:] = rng.normal(size=mj_model.nv)
        mujoco.mj_forward(mj_model, d)
        mujoco.mj_subtreeVel(mj_model, d)
        foot = kinematics.foot_position(leg, jnp.asarray(q))
        np.testing.assert_allclose(foot, d.geom_xpos[mj_model.geom("foot").id] - d.xanchor[haa], atol=1e-5)
        np.testing.assert_allclose(kinematics.com_position(leg, jnp.asarray(q)), d.subtree_com[1] - d.xanchor[haa],
                                   atol=1e-5)
        np.testing.assert_allclose(kinematics.inverse(leg, foot), q, atol=1e-4)
        h = kinematics.angular_momentum(leg, jnp.asarray(q), jnp.asarray(d.qvel[6:9]), jnp.asarray(d.qvel[3:6]))
        np.testing.assert_allclose(h, d.subtree_angmom[1], rtol=1e-4, atol=1e-5)


def test_raibert_params_validate():
    p = raibert.raibert_params(3, height=[0.1, 0.2, 0.0], speed=(0.5, 0.0), speed_gain=[0.1, 0.2, 0.3])
    assert p.height.shape == (3,) and p.speed.shape == (3, 2)
    assert p.gains.speed_gain.tolist() == pytest.approx([0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="unknown Raibert gain"):
        raibert.raibert_params(2, height=0.1, not_a_gain=1.0)
    with pytest.raises(ValueError, match="speed must be"):
        raibert.raibert_params(2, height=0.1, speed=(1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="height"):
        raibert.raibert_params(2, height=-0.1)


# -- Raibert: one shared rollout --------------------------------------------------
def _hop(sim, height=HEIGHT, commands=COMMANDS, qvel=None):
    """The shared batch (3 gravities x 4 commands, DURATION s) on `sim`'s engine, with its metrics
    (the same shapes whatever the commands and kicks: one compiled program)."""
    gravity = np.repeat(GRAVITIES, len(commands))
    speed = np.tile(np.array(commands), (len(GRAVITIES), 1))
    controller = raibert.raibert(sim.robot)
    params = raibert.raibert_params(len(gravity), height=height, speed=speed)
    state = sim.reset(gravity_vectors(gravity), controller=controller, params=params, qvel=qvel)
    sensors = signals.SensorConfig(state_rate=RATE, contact_rate=RATE)
    final, traj = sim.rollout(state, controller, steps=int(DURATION / sim.layout.timestep), sensors=sensors)
    met = hops.hop_metrics(traj, gravity, command_speed=speed, standing_height=sim.robot.standing_height,
                              work=final.cstate.work, mass=sim.layout.total_mass)
    return gravity, speed, final, traj, met


@pytest.fixture(scope="module")
def hopping(sim):
    return _hop(sim)


def test_hops_alike_on_the_chain_and_mjx_engines(sim, mj_model, hopping):
    """The same batch on generic MJX: every hop count within 1 % and every apex within 1 %
    (the engines agree to float32 rounding per step; 20 s of hopping lets it grow)."""
    assert sim.engine.name == "chain"
    met, ref = hopping[4], _hop(Sim(mj_model, engine="mjx"))[4]
    assert (met["fell"] == ref["fell"]).all()
    np.testing.assert_allclose(met["hops"], ref["hops"], rtol=0.01)
    np.testing.assert_allclose(met["apex_height"], ref["apex_height"], rtol=0.01)


def _report(met, rows):
    keys = ("fell", "hops", "apex_height", "hop_period", "mean_speed", "mean_speed_y", "max_roll", "max_pitch")
    return "\n".join(str({k: round(float(met[k][i]), 3) for k in keys}) for i in rows)


def _rows(gravity, speed, g, moving):
    same_g = np.isclose(gravity, g)
    return np.flatnonzero(same_g & ((speed != 0).any(axis=1) if moving else (speed == 0).all(axis=1)))


@pytest.mark.parametrize("g", GRAVITIES)
def test_hops_in_place(hopping, g):
    gravity, speed, final, traj, met = hopping
    rows = _rows(gravity, speed, g, moving=False)
    assert not final.diverged.any()
    assert not met["fell"][rows].any(), _report(met, rows)
    assert np.all(met["hops"][rows] >= 5)
    np.testing.assert_allclose(met["apex_height"][rows], HEIGHT, rtol=0.15, err_msg=_report(met, rows))


@pytest.mark.parametrize("g", GRAVITIES)
def test_tracks_forward_and_sideways_speed(hopping, g):
    gravity, speed, final, traj, met = hopping
    rows = _rows(gravity, speed, g, moving=True)
    assert not met["fell"][rows].any(), _report(met, rows)
    velocity = np.stack([met["mean_speed"], met["mean_speed_y"]], axis=1)[rows]
    assert np.all(np.abs(velocity - speed[rows]) < 0.1), _report(met, rows)
    assert np.all(met["max_roll"][rows] < 0.3) and np.all(met["max_pitch"][rows] < 0.3), _report(met, rows)


def test_flight_follows_the_instances_own_gravity(hopping, mj_model):
    """Oracle: in flight the whole-robot COM is a parabola with curvature -g, and
    the flight time is 2·sqrt(2Δh/g) for its rise Δh above the lift-off/touchdown mean."""
    gravity, speed, final, traj, met = hopping
    qpos, flag = np.asarray(traj.qpos), np.asarray(traj.contact.flag)
    t = np.asarray(traj.time["state"])
    d = mujoco.MjData(mj_model)
    checked = 0
    for i in range(len(gravity)):
        com = []
        for q in qpos[i]:
            d.qpos[:] = q
            mujoco.mj_kinematics(mj_model, d)
            mujoco.mj_comPos(mj_model, d)
            com.append(d.subtree_com[1, 2])
        com = np.array(com)
        edges = np.flatnonzero(np.diff(flag[i].astype(int)))
        upright_until = np.nan_to_num(met["fall_time"][i], nan=np.inf)  # after a fall the base may touch down
        for lo, td in zip(edges[:-1], edges[1:]):
            if flag[i, lo] and not flag[i, lo + 1] and td - lo > 10 and t[td + 1] < upright_until:
                inner = slice(lo + 2, td)  # strictly airborne samples
                a, b, c = np.polyfit(t[inner], com[inner], 2)
                assert -2 * a == pytest.approx(gravity[i], rel=0.05)
                # Flight time from the fitted parabola's crossings of the lift-off/touchdown heights.
                flight = t[td + 1] - t[lo + 1]
                apex = c - b * b / (4 * a)
                rise = apex - 0.5 * (np.polyval((a, b, c), t[lo + 1]) + np.polyval((a, b, c), t[td + 1]))
                assert flight == pytest.approx(2 * np.sqrt(2 * rise / gravity[i]), rel=0.05)
                checked += 1
    assert checked >= 30


def test_metrics_of_the_hops_are_consistent(hopping):
    gravity, speed, final, traj, met = hopping
    ok = ~met["fell"]
    assert ok[np.isin(gravity, (9.81, 3.71)) & (speed == 0).all(axis=1)].all()  # Earth and Mars in place
    np.testing.assert_allclose(met["hop_period"][ok], met["flight_time"][ok] + met["stance_time"][ok], rtol=1e-6)
    assert np.all((met["duty_factor"][ok] > 0) & (met["duty_factor"][ok] < 1))
    assert np.all(np.isfinite(met["fall_time"]) == met["fell"])


# -- robustness (slow) -----------------------------------------------------------
# The kicks of the documented full-size run (docs/control.md: 1032 instances x 20 s,
# `sweep gravity --kick 0.3`, 96.0 % survive), on a CI-sized batch.
ROBUST_N = 256
ROBUST_SECONDS = 10.0  # the falls come in the first flight, before the first touchdown
KICK = 0.3  # std of the initial kick: m/s on vx and vy, rad/s on the roll and pitch rates


@pytest.mark.slow
def test_survives_random_kicks_over_gravities(sim, mj_model):
    rng = np.random.default_rng(7)
    gravity = rng.uniform(1.0, 12.0, ROBUST_N)
    qvel = np.zeros((ROBUST_N, sim.layout.nv))
    qvel[:, [0, 1, 3, 4]] = rng.normal(0.0, KICK, (ROBUST_N, 4))
    controller = raibert.raibert(sim.robot)
    params = raibert.raibert_params(ROBUST_N, height=HEIGHT)
    state = sim.reset(gravity_vectors(gravity), controller=controller, params=params, qvel=qvel)
    final, traj = sim.rollout(state, controller, steps=int(ROBUST_SECONDS / sim.layout.timestep))
    met = hops.hop_metrics(traj, gravity, standing_height=sim.robot.standing_height)
    survived = np.mean(~met["fell"] & ~np.asarray(final.diverged))
    print(f"{survived:.1%} of {ROBUST_N} survived; fell at g = {np.round(np.sort(gravity[met['fell']]), 2)}")
    assert survived >= 0.95, f"{survived:.1%} survived; fell at g = {np.round(gravity[met['fell']], 2)}"


def test_every_task_has_a_reference_that_meets_its_threshold(sim):
    """The registry names a reference controller for every task; stand's (Raibert at a small apex, the
    task redefined because standing still under kicks is ill-posed) keeps the kicked robots up, in place,
    hopping low: stand's threshold at Earth, Mars and Moon (4 kicked instances each, 20 s; the documented
    64-instance sweep is in docs/control.md). Same shapes as `hopping`: no new compile."""
    from hopper_mjx import registry
    from hopper_mjx.metrics import thresholds
    from hopper_mjx.sweep.grid import SweepSpec, expand

    assert set(registry.TASK_REFERENCES) == set(registry.TASKS)
    for task, ref in registry.TASK_REFERENCES.items():
        assert ref.controller in registry.CONTROLLERS and ref.controller in registry.SWEEP_CONTROLLERS, task
    stand = registry.TASK_REFERENCES["stand"]
    n = len(COMMANDS)
    kicks = expand(SweepSpec(kind="gravity", gravity=GRAVITIES, num=n, duration=DURATION, height=stand.height,
                             speed=(0.0, 0.0), seed=0), sim.layout.nv).qvel
    assert np.abs(kicks).max() > 0
    gravity, _, final, traj, met = _hop(sim, height=stand.height, commands=((0.0, 0.0),) * n, qvel=kicks)
    assert not final.diverged.any()
    for g in GRAVITIES:
        rows = np.isclose(gravity, g)
        row = {"survival": float(np.mean(~met["fell"][rows])), "min_hops": int(met["hops"][rows].min()),
               "apex_height": float(met["apex_height"][rows].mean()),
               "tracking_error": float(met["tracking_error"][rows].mean())}
        assert thresholds.meets("stand", row, 0.0), (g, row)
        assert row["min_hops"] >= 5 and row["apex_height"] == pytest.approx(stand.height, rel=0.15), (g, row)
