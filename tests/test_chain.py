"""The chain engine against MuJoCo C and generic MJX, stage by stage and over trajectories.

Random states include foot contact, a joint past its limit, a tilted base and (a few) the
base box touching the floor. In float64 (jax x64, scoped to one fixture) every stage agrees
with C to 1e-9 once both solve their constraints to convergence; in float32, at the model's
own solver options, to 1e-4 relative. Trajectories through touchdown stay within 1e-3 m of C.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from hopper_mjx import model
from hopper_mjx.engine import chain
from hopper_mjx.engine.chain import constraint as chain_constraint
from hopper_mjx.engine.chain import smooth as chain_smooth
from hopper_mjx.engine.chain.model import NotChain, describe
from hopper_mjx.engine.mjx import MjxEngine
from hopper_mjx.model.robot import stance_qpos

SECOND_URDF = Path(__file__).parent / "data" / "long_shin_hopper.urdf"
SECOND_FRICTION = (0.4, 1.5, 0.8)  # N·m of dry friction its haa, hfe, kfe get, as <dynamics friction> (constants)
N_STATES = 12
HOLD_P, HOLD_D = np.array([400.0, 400.0, 200.0]), np.array([18.0, 15.0, 4.0])
GRAVITIES = (9.81, 3.71, 1.62)
TRAJ_STEPS = 1000  # 1 s


def converged(m: mujoco.MjModel, ls_iterations: int) -> mujoco.MjModel:
    """A copy whose Newton solve runs to convergence (the reference for constraint forces)."""
    m = copy.deepcopy(m)
    m.opt.iterations, m.opt.ls_iterations, m.opt.tolerance = 100, ls_iterations, 1e-15
    return m


def _lowest(m, d, geom_ids) -> float:
    """Lowest point of the geoms above the floor (spheres and boxes), m."""
    mujoco.mj_kinematics(m, d)
    low = np.inf
    for g in geom_ids:
        if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE:
            low = min(low, d.geom_xpos[g, 2] - m.geom_size[g, 0])
        else:
            corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * m.geom_size[g]
            low = min(low, (d.geom_xpos[g] + corners @ d.geom_xmat[g].reshape(3, 3).T)[:, 2].min())
    return low


def random_states(m: mujoco.MjModel, n: int, seed: int):
    """(qpos, qvel, ctrl, gravity) batches: tilted bases with the foot 0-5 mm into the floor,
    every third state with a joint 5-30 mrad past its lower limit, and the last two fallen
    over (base nearly upside down, its box 0-5 mm into the floor, the leg in the air)."""
    rng = np.random.default_rng(seed)
    foot = [m.geom("foot").id]
    base = [g for g in range(m.ngeom) if m.geom_bodyid[g] == 1]
    d = mujoco.MjData(m)
    qpos = np.tile(stance_qpos(m), (n, 1))
    for i in range(n):
        fallen = i >= n - 2
        axis = np.r_[rng.normal(size=2), 0.0 if fallen else rng.normal()]
        angle = np.pi - rng.uniform(0.1, 0.3) if fallen else rng.uniform(0.05, 0.35)
        qpos[i, 3:7] = np.r_[np.cos(angle / 2), np.sin(angle / 2) * axis / np.linalg.norm(axis)]
        qpos[i, 7:] += rng.normal(size=3) * 0.2
        if i % 3 == 0:
            joint = 1 + (i // 3) % 3
            qpos[i, 6 + joint] = m.jnt_range[joint, 0] - rng.uniform(0.005, 0.03)
        d.qpos[:] = qpos[i]
        qpos[i, 2] -= _lowest(m, d, base if fallen else foot) + rng.uniform(0, 0.005)
    qvel = np.concatenate([rng.normal(size=(n, 6)) * 0.5, rng.normal(size=(n, 3))], axis=1)
    ctrl = rng.uniform(-30, 30, size=(n, m.nu))
    gravity = np.stack([np.zeros(n), np.zeros(n), -rng.uniform(1.0, 12.0, n)], axis=1)
    return qpos, qvel, ctrl, gravity


FRICTION_ROWS = ("friction_jac", "friction_D", "friction_aref", "friction_loss", "friction_bound")


def _friction_rows(m, d) -> dict:
    """C's joint dry-friction rows: J, D, aref, the force bound f and the residual's bound f R; their states."""
    at = d.efc_type == mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF
    jac = d.efc_J.reshape(d.nefc, m.nv)[at]
    return dict(zip(FRICTION_ROWS + ("friction_state",), (jac, d.efc_D[at], d.efc_aref[at], d.efc_frictionloss[at],
                                                          d.efc_frictionloss[at] * d.efc_R[at], d.efc_state[at])))


def mujoco_c(m: mujoco.MjModel, qpos, qvel, ctrl, gravity) -> dict:
    """MuJoCo C's stages for each state: forward, then one step."""
    m = copy.deepcopy(m)
    out = {k: [] for k in ("xpos", "xmat", "mass", "qacc", "qfrc_constraint", "qpos", "qvel", "ncon",
                           "foot_force", "qfrc_smooth", "solver_niter", *FRICTION_ROWS, "friction_state")}
    for q, v, u, g in zip(qpos, qvel, ctrl, gravity):
        m.opt.gravity[:] = g
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:], d.ctrl[:] = q, v, u
        mujoco.mj_forward(m, d)
        out["foot_force"].append(_foot_force(m, d))
        for key, value in _friction_rows(m, d).items():
            out[key].append(value)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        for key, value in (("xpos", d.xpos[1:]), ("xmat", d.xmat[1:]), ("mass", full), ("qfrc_smooth", d.qfrc_smooth),
                           ("qacc", d.qacc), ("qfrc_constraint", d.qfrc_constraint), ("ncon", d.ncon),
                           ("solver_niter", d.solver_niter[0])):
            out[key].append(np.array(value))
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:], d.ctrl[:] = q, v, u
        mujoco.mj_step(m, d)
        out["qpos"].append(d.qpos.copy())
        out["qvel"].append(d.qvel.copy())
    return {k: np.array(v) for k, v in out.items()}


def _foot_force(m, d) -> np.ndarray:
    """Floor-on-foot force in the world frame from MuJoCo's contact forces."""
    total, wrench = np.zeros(3), np.zeros(6)
    for i in range(d.ncon):
        if d.contact[i].geom[1] == m.geom("foot").id:
            mujoco.mj_contactForce(m, d, i, wrench)
            total += d.contact[i].frame.reshape(3, 3).T @ wrench[:3]
    return total


def chain_stages(engine: chain.ChainEngine):
    """A compiled, vmapped function: the chain's stages for a batch of states and warm starts."""
    cm = engine.chain
    upper = [(i, j) for i in range(cm.nv) for j in range(i, cm.nv)]

    def one(params, qpos, qvel, ctrl, gravity, warmstart):
        pose = chain_smooth.kinematics(engine.instance(params), params.gate, tuple(qpos[i] for i in range(cm.nq)))
        data = engine.make_data(qpos, qvel).replace(ctrl=ctrl, qacc_warmstart=warmstart)
        data = engine.forward(params, data, gravity)
        after = engine.integrate(params, data, gravity)
        vec = lambda v: jnp.stack([jnp.asarray(x, qpos.dtype) for x in v])
        mass = jnp.zeros((cm.nv, cm.nv), qpos.dtype).at[tuple(np.array(upper).T)].set(data.mass)
        jac, weight, aref, loss = chain_constraint.friction_rows(engine.instance(params), tuple(qvel))
        rows = [[vec(j) for j in jac], weight, aref, [f for f, _ in loss], [b for _, b in loss]]
        friction = {k: vec(v) if v else jnp.zeros((0, cm.nv) if k == "friction_jac" else 0, qpos.dtype)
                    for k, v in zip(FRICTION_ROWS, rows)}
        return friction | {
            "xpos": jnp.stack([vec(o) for o in pose.origin]) + qpos[:3],
            "xmat": jnp.stack([vec(r) for r in pose.rot]),
            "mass": mass + jnp.triu(mass, 1).T, "qfrc_smooth": data.qfrc_smooth, "qacc": data.qacc,
            "qfrc_constraint": data.qfrc_constraint, "qpos": after.qpos, "qvel": after.qvel,
            "foot_touching": data.foot_touching, "foot_force": data.foot_force, "solver_niter": data.solver_niter,
        }

    return jax.jit(jax.vmap(one, in_axes=(None, 0, 0, 0, 0, 0)))


def run_chain(engine, states, dtype, fn=None) -> dict:
    fn = fn or chain_stages(engine)
    args = [jnp.asarray(x, dtype) for x in states]
    out = fn(engine.model, *args, jnp.zeros_like(args[1]))
    return {k: np.asarray(v) for k, v in out.items()}


@pytest.fixture(scope="module")
def seed_model():
    return model.load()


@pytest.fixture(scope="module")
def seed_states(seed_model):
    return random_states(seed_model, N_STATES, seed=7)


def at_rest(states):
    """Every other state with its hinges at rest and weak motors: dry friction that sticks as well as slips."""
    qpos, qvel, ctrl, gravity = (np.array(x) for x in states)
    qvel[::2, 6:] = 0.0
    ctrl[::2] *= 0.02
    return qpos, qvel, ctrl, gravity


def with_joint_friction(out: Path, losses) -> Path:
    """The second URDF, written to `out`, with its joints' <dynamics friction> `losses`, in order."""
    losses = iter(losses)
    out.write_text(re.sub(r'friction="0"', lambda _: f'friction="{next(losses)}"', SECOND_URDF.read_text()))
    return out


@pytest.fixture(scope="module")
def second_model(tmp_path_factory):
    """The second URDF with dry joint friction (its <dynamics friction>): rows the chain folds as constants."""
    return model.load(with_joint_friction(tmp_path_factory.mktemp("urdf") / "rubbing.urdf", SECOND_FRICTION))


@pytest.fixture(scope="module")
def float64_results(seed_model, seed_states, second_model):
    """Chain in float64 (x64 only inside this fixture) for the seed and the second URDF (with joint
    friction, half its states at rest), both solving to convergence, with MuJoCo C's converged answers."""
    second = second_model
    second_states = at_rest(random_states(second, 6, seed=11))
    c_seed = mujoco_c(converged(seed_model, 50), *seed_states)
    c_second = mujoco_c(converged(second, 50), *second_states)
    with jax.enable_x64(True):
        seed = run_chain(chain.make(converged(seed_model, 20)), seed_states, jnp.float64)
        other = run_chain(chain.make(converged(second, 20)), second_states, jnp.float64)
    return {"seed": (seed, c_seed), "second": (other, c_second)}


@pytest.fixture(scope="module")
def own_engine(seed_model):
    return chain.make(seed_model)


@pytest.fixture(scope="module")
def own_stages(own_engine):
    return chain_stages(own_engine)


@pytest.fixture(scope="module")
def float32_results(seed_model, seed_states, own_engine, own_stages):
    """Chain in float32 at the model's own solver options, with C at the same options."""
    return run_chain(own_engine, seed_states, jnp.float32, own_stages), mujoco_c(seed_model, *seed_states)


def test_states_cover_contacts_limits_and_tilt(seed_model, seed_states, float32_results):
    _, c = float32_results
    qpos = seed_states[0]
    assert (c["ncon"] >= 1).all(), "every state touches the floor"
    assert (c["ncon"][-2:] >= 1).all() and (qpos[-2:, 3] < 0.2).all(), "the last states lie on the base box"
    assert (np.abs(qpos[:, 4:7]).max(axis=1) > 0.02).all(), "every base is tilted"
    assert (qpos[:, 7:] < seed_model.jnt_range[1:, 0]).any(axis=1).sum() >= N_STATES // 3


STAGES = ("xpos", "xmat", "mass", "qfrc_smooth", "qacc", "qfrc_constraint", "qpos", "qvel")


def test_a_urdfs_joint_friction_reaches_the_chain(second_model, float64_results):
    """<dynamics friction> is MuJoCo's dof_frictionloss, which the chain folds into one row per hinge, sticking
    (C's quadratic state) in some states and slipping in others; the seed robot has none."""
    np.testing.assert_array_equal(second_model.dof_frictionloss, (0,) * 6 + SECOND_FRICTION)
    hinges = [link.hinge for link in describe(second_model).links if link.hinge is not None]
    assert tuple(h.frictionloss for h in hinges) == SECOND_FRICTION
    ours, c = float64_results["second"]
    assert c["friction_state"].shape == (6, 3) and float64_results["seed"][1]["friction_state"].size == 0
    stick = c["friction_state"] == mujoco.mjtConstraintState.mjCNSTRSTATE_QUADRATIC
    assert 2 <= stick.sum() < stick.size - 2
    np.testing.assert_array_equal(np.abs(c["friction_jac"]).sum(axis=2), 1)  # a unit row per hinge


@pytest.mark.parametrize("urdf", ["seed", "second"])
@pytest.mark.parametrize("stage", STAGES + FRICTION_ROWS)
def test_float64_stages_match_mujoco_c(float64_results, urdf, stage):
    ours, c = float64_results[urdf]
    err = np.abs(ours[stage] - c[stage]).max(initial=0.0)
    assert err <= 1e-9, f"{urdf} {stage}: chain and MuJoCo C differ by {err:.2e}"


def test_newton_iterations_match_mujoco_c(seed_model):
    """At the model's own solver options, in float64, the chain runs as many Newton iterations as C
    (solver_niter) in each of 64 states: none where the start is already the minimum, up to the cap."""
    states = random_states(seed_model, 64, seed=7)
    c = mujoco_c(seed_model, *states)["solver_niter"]
    with jax.enable_x64(True):
        ours = run_chain(chain.make(seed_model), states, jnp.float64)["solver_niter"]
    counts = np.bincount(c, minlength=seed_model.opt.iterations + 1)
    print("\nC's Newton iterations per state (0, 1, ...):", counts)
    assert counts[0] >= 1 and counts[1:].min() >= 1, "the states take every count from none to the cap"
    np.testing.assert_array_equal(ours, c)


@pytest.mark.parametrize("stage", STAGES)
def test_float32_stages_at_the_models_own_iterations_match_mujoco_c(float32_results, stage):
    ours, c = float32_results
    scale = np.maximum(np.abs(c[stage]).reshape(N_STATES, -1).max(axis=1), 1.0)
    err = (np.abs(ours[stage] - c[stage]).reshape(N_STATES, -1).max(axis=1) / scale).max()
    assert err <= 1e-4, f"{stage}: relative difference {err:.2e}"


def _base_depth(m: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """How deep (m, > 0 inside) the base box reaches into the floor, per state."""
    base = [g for g in range(m.ngeom) if m.geom_bodyid[g] == 1]
    d = mujoco.MjData(m)
    depth = []
    for q in qpos:
        d.qpos[:] = q
        depth.append(-_lowest(m, d, base))
    return np.array(depth)


@pytest.fixture(scope="module")
def mjx_float32_results(seed_model, seed_states):
    """Generic MJX (the `mjx` engine) on the same states, float32, at the model's own options."""
    engine = MjxEngine(seed_model)

    def one(qpos, qvel, ctrl, gravity):
        data = engine.forward(engine.model, engine.make_data(qpos, qvel).replace(ctrl=ctrl), gravity)
        after = engine.integrate(engine.model, data, gravity)
        return {"xpos": data.xpos[1:], "xmat": data.xmat[1:], "mass": mjx.full_m(engine.model, data),
                "qfrc_smooth": data.qfrc_smooth, "qacc": data.qacc, "qfrc_constraint": data.qfrc_constraint,
                "qpos": after.qpos, "qvel": after.qvel, "foot_force": engine.foot_contact(engine.model, data)[1]}

    out = jax.jit(jax.vmap(one))(*[jnp.asarray(x, jnp.float32) for x in seed_states])
    return {k: np.asarray(v) for k, v in out.items()}


@pytest.mark.parametrize("stage", STAGES + ("foot_force",))
def test_float32_stages_match_the_mjx_engine(seed_model, seed_states, float32_results, mjx_float32_results, stage):
    """Chain against generic MJX, stage by stage. Excluded: states whose base box lies more than
    2 cm inside the floor (one of the 12, 35 cm deep), where MJX's box-floor contacts are not
    MuJoCo C's (qacc differs from C by ~5e3 m/s² there) and the chain's are."""
    ours, c = float32_results
    shallow = _base_depth(seed_model, seed_states[0]) < 0.02
    assert shallow.sum() >= N_STATES - 2
    mjx_out = mjx_float32_results[stage].reshape(N_STATES, -1)[shallow]
    chain_out = ours[stage].reshape(N_STATES, -1)[shallow]
    scale = np.maximum(np.abs(chain_out).max(axis=1), 1.0)
    err = (np.abs(mjx_out - chain_out).max(axis=1) / scale).max()
    assert err <= 1e-4, f"{stage}: chain and MJX differ by {err:.2e} relative"


def test_foot_force_matches_mujoco_c(float32_results):
    ours, c = float32_results
    foot = np.abs(c["foot_force"]).max(axis=1) > 0
    assert foot.sum() >= N_STATES - 2 and (ours["foot_touching"] == foot).all()
    err = np.abs(ours["foot_force"] - c["foot_force"]).max() / np.abs(c["foot_force"]).max()
    assert err <= 1e-4, f"foot force: relative difference {err:.2e}"


@pytest.fixture(scope="module")
def trajectories(seed_model, own_engine, own_stages):
    """1 s from 5 and 12 cm above the floor at three gravities, limp and holding the stance by PD,
    chain (float32, the compiled stages reused, warm-started like C) and C side by side."""
    n = N_STATES  # the batch size of the float32 stage test: the same compiled function
    cases = [(g, hold, drop) for g in GRAVITIES for hold in (False, True) for drop in (0.05, 0.12)]
    gravity = np.array([[0, 0, -g] for g, _, _ in cases])
    hold = np.array([h for _, h, _ in cases])
    q0 = stance_qpos(seed_model)
    qpos = np.tile(q0, (n, 1))
    qpos[:, 2] += np.array([drop - 0.05 for _, _, drop in cases])
    m = copy.deepcopy(seed_model)
    cdata = [mujoco.MjData(m) for _ in range(n)]
    for d, q in zip(cdata, qpos):
        d.qpos[:] = q
    qvel, warm = np.zeros((n, 9)), np.zeros((n, 9))
    ours, theirs, touched = [], [], np.zeros(n, bool)
    f32 = lambda x: jnp.asarray(x, jnp.float32)
    for _ in range(TRAJ_STEPS):
        ctrl = np.where(hold[:, None], HOLD_P * (q0[7:] - qpos[:, 7:]) - HOLD_D * qvel[:, 6:], 0.0)
        out = own_stages(own_engine.model, f32(qpos), f32(qvel), f32(ctrl), f32(gravity), f32(warm))
        qpos, qvel, warm = np.asarray(out["qpos"]), np.asarray(out["qvel"]), np.asarray(out["qacc"])
        touched |= np.asarray(out["foot_touching"])
        for i, d in enumerate(cdata):
            m.opt.gravity[:] = gravity[i]
            d.ctrl[:] = np.where(hold[i], HOLD_P * (q0[7:] - d.qpos[7:]) - HOLD_D * d.qvel[6:], 0.0)
            mujoco.mj_step(m, d)
        ours.append(qpos)
        theirs.append(np.array([d.qpos.copy() for d in cdata]))
    return np.array(ours), np.array(theirs), touched


def test_trajectories_through_touchdown_match_mujoco_c(trajectories):
    ours, theirs, touched = trajectories
    assert touched.all(), "every run must include the touchdown"
    base_err = np.abs(ours[:, :, :3] - theirs[:, :, :3]).max()
    joint_err = np.abs(ours[:, :, 7:] - theirs[:, :, 7:]).max()
    assert base_err < 1e-3, f"base position differs from MuJoCo C by {base_err:.2e} m"
    assert joint_err < 1e-2, f"joint angles differ from MuJoCo C by {joint_err:.2e} rad"


def test_models_outside_the_topology_are_refused_with_one_line(seed_model):
    rk4 = copy.deepcopy(seed_model)
    rk4.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    elliptic = copy.deepcopy(seed_model)
    elliptic.opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    rubbing_base = copy.deepcopy(seed_model)
    rubbing_base.dof_frictionloss[3] = 0.1
    negative = copy.deepcopy(seed_model)
    negative.dof_frictionloss[7] = -0.1
    for bad, why in ((rk4, "integrator"), (elliptic, "cone"), (rubbing_base, "free joint has friction loss"),
                     (negative, "negative friction loss")):
        with pytest.raises(NotChain, match=why) as err:
            describe(bad)
        assert "\n" not in str(err.value)
    spec = mujoco.MjSpec()
    spec.worldbody.add_body(name="lonely").add_geom(size=[0.1, 0, 0])
    with pytest.raises(NotChain, match="free joint"):
        describe(spec.compile())


# Every parameter the chain takes at run time: masses, inertias, centre of mass, armature, gear, friction,
# damping, and the leg's morphology (thigh, shank, foot radius).
CHAIN_ROBOT = ("body_mass=scale(0.7,1.3),body_inertia=scale(0.7,1.3),base_com=-0.03..0.03,dof_armature=0.001..0.02,"
               "actuator_gear=scale(0.7,1.3),foot_friction=0.3..1,dof_damping=0..1,thigh_length=0.3..0.4,"
               "shank_length=0.3..0.42,foot_radius=0.02..0.045")


@pytest.mark.parametrize("text", ["foot_friction=0.3,dof_damping=0.02", CHAIN_ROBOT + ",dof_frictionloss=0..3"])
def test_float64_stages_with_a_run_time_robot_match_mujoco_c(seed_model, text):
    """The chain takes an instance's robot as run-time values (per-instance robots, hopper_mjx.variation.draw):
    every stage agrees with MuJoCo C given a model holding those values, with mj_setConst's constants. Dry joint
    friction (half the states at rest): its rows, sticking and slipping, and what the solver makes of them."""
    from hopper_mjx.variation import draw
    from hopper_mjx.variation.spec import Spec

    spec = Spec.parse(text)
    values = draw.with_constants(seed_model, draw.draw(spec, seed_model, 1, seed=2))
    varied = draw.instance_model(seed_model, values, 0)
    states = at_rest(random_states(varied, N_STATES, seed=7))  # contacts and limits of this robot
    c = mujoco_c(converged(varied, 50), *states)
    with jax.enable_x64(True):
        engine = chain.make(converged(seed_model, 20), varies=spec.fields)  # nominal: the values come at run time
        params = engine.vary(engine.model, {k: jnp.asarray(v[0], jnp.float64) for k, v in values.items()})
        args = [jnp.asarray(x, jnp.float64) for x in states]
        out = chain_stages(engine)(params, *args, jnp.zeros_like(args[1]))
    assert (c["ncon"] >= 1).all()
    if "dof_frictionloss" in spec.fields:
        stick = c["friction_state"] == mujoco.mjtConstraintState.mjCNSTRSTATE_QUADRATIC
        assert stick.shape == (N_STATES, 3) and 2 <= stick.sum() <= stick.size - 2
    for stage in STAGES + FRICTION_ROWS:
        err = np.abs(np.asarray(out[stage]) - c[stage]).max(initial=0.0)
        assert err <= 1e-9, f"{stage}: chain and MuJoCo C differ by {err:.2e}"
    nominal = mujoco_c(converged(seed_model, 50), *states)
    assert np.abs(nominal["qacc"] - c["qacc"]).max() > 1e-2  # the values change the answer
