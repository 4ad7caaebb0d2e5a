"""The chain engine on a heightfield floor against MuJoCo C, stage by stage and over trajectories.

The foot sphere meets the terrain's triangle prisms as C's mjc_ConvexHField does. C finds each
contact with GJK + EPA to `opt.ccd_tolerance`; the chain computes the point EPA converges to.
So: at C's default tolerance the distances agree to within it; with C's tolerance tightened
(1e-14) every stage agrees in float64 to ~1e-9. Trajectories through touchdown (float32, the
model's own options) stay within 1e-3 m of C. A new terrain is a new input, not a new compile.
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from hfield_model import hfield_model
from test_chain import HOLD_D, HOLD_P, STAGES, chain_stages, converged, mujoco_c

from hopper_mjx.engine import chain, chain_constraint, chain_smooth
from hopper_mjx.engine.chain_model import NotChain, describe
from hopper_mjx.model.robot import stance_qpos

HALF = 1.0  # m: the terrains span 2 m x 2 m
GRID = 41  # vertices a side: 5 cm cells, so the 3 cm foot reaches up to 3 x 3 cells
GRAVITIES = (9.81, 3.71, 1.62)
N_STATES = 12
TIGHT_CCD = 1e-14  # C's convex-collision tolerance for the float64 comparison


def _grid():
    x = np.linspace(-HALF, HALF, GRID)
    return np.meshgrid(x, x)  # X[r, c] = x of column c, Y[r, c] = y of row r


def terrain(name: str) -> np.ndarray:
    """Heights (GRID, GRID) m: rough ground, a 5 cm step up at x = 0, and a 6 cm bump at x = 0.1 m."""
    x, y = _grid()
    if name == "rough":
        return np.random.default_rng(3).uniform(0.0, 0.03, x.shape)
    if name == "step":
        return np.where(x > -0.01, 0.05, 0.0)
    return 0.06 * np.exp(-((x - 0.1) ** 2 + y ** 2) / (2 * 0.04 ** 2))


TERRAINS = ("rough", "step", "bump")


@pytest.fixture(scope="module")
def models():
    return {name: hfield_model(terrain(name), HALF, HALF, base_pairs=False) for name in TERRAINS}


def _foot_contacts(m, d):
    mujoco.mj_kinematics(m, d)
    mujoco.mj_collision(m, d)
    return d.ncon


def terrain_states(m: mujoco.MjModel, n: int, seed: int):
    """(qpos, qvel, ctrl, gravity): tilted bases over random points of the terrain, the foot
    lowered to its first contact (bisection on C's collision) and then 0-6 mm further."""
    rng = np.random.default_rng(seed)
    d = mujoco.MjData(m)
    qpos = np.tile(stance_qpos(m), (n, 1))
    for i in range(n):
        axis = rng.normal(size=3)
        angle = rng.uniform(0.05, 0.3)
        qpos[i, 3:7] = np.r_[np.cos(angle / 2), np.sin(angle / 2) * axis / np.linalg.norm(axis)]
        qpos[i, 7:] += rng.normal(size=3) * 0.15
        qpos[i, 0:2] = rng.uniform(-0.25, 0.25, 2)
        lo, hi = -0.3, 0.3  # base height offsets: in contact, not
        for _ in range(50):
            d.qpos[:] = qpos[i]
            d.qpos[2] += 0.5 * (lo + hi)
            lo, hi = (0.5 * (lo + hi), hi) if _foot_contacts(m, d) else (lo, 0.5 * (lo + hi))
        qpos[i, 2] += lo - rng.uniform(0.0005, 0.006)
    qvel = np.concatenate([rng.normal(size=(n, 6)) * 0.5, rng.normal(size=(n, 3))], axis=1)
    ctrl = rng.uniform(-30, 30, size=(n, m.nu))
    gravity = np.stack([np.zeros(n), np.zeros(n), -rng.choice(GRAVITIES, n)], axis=1)
    return qpos, qvel, ctrl, gravity


def c_contacts(m: mujoco.MjModel, qpos, qvel, ctrl, gravity) -> list:
    """Per state, MuJoCo C's foot contacts: (dist, pos, normal, efc J, D, aref of its rows)."""
    m = copy.deepcopy(m)
    out = []
    for q, v, u, g in zip(qpos, qvel, ctrl, gravity):
        m.opt.gravity[:] = g
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:], d.ctrl[:] = q, v, u
        mujoco.mj_forward(m, d)
        contacts = []
        for i in range(d.ncon):
            con = d.contact[i]
            rows = slice(con.efc_address, con.efc_address + 4)
            contacts.append((con.dist, con.pos.copy(), con.frame[:3].copy(), d.efc_J.reshape(d.nefc, m.nv)[rows].copy(),
                             d.efc_D[rows].copy(), d.efc_aref[rows].copy()))
        out.append(contacts)
    return out


def chain_contacts_fn(engine: chain.ChainEngine):
    """A compiled, vmapped function: per state, the chain's foot contact slots and their rows."""
    cm = engine.chain

    def one(params, q, v):
        qpos, qvel = tuple(q[i] for i in range(cm.nq)), tuple(v[i] for i in range(cm.nv))
        pose = chain_smooth.kinematics(cm, params.gate, qpos)
        slots = chain_constraint._all_slots(cm, pose, params.terrain)[0]
        rows, _ = chain_constraint.rows(cm, params.gate, pose, qpos, qvel, params.terrain)
        first = len(rows.jac) - 4 * len(slots)
        vec = lambda x: jnp.stack([jnp.asarray(e, q.dtype) for e in x])
        return {
            "exists": jnp.stack([s[0] for s in slots]), "dist": jnp.stack([s[1] for s in slots]),
            "pos": jnp.stack([vec(s[2]) + q[:3] for s in slots]),
            "jac": jnp.stack([vec(j) for j in rows.jac[first:]]).reshape(len(slots), 4, cm.nv),
            "D": vec(rows.weight[first:]).reshape(len(slots), 4),
            "aref": vec(rows.aref[first:]).reshape(len(slots), 4),
        }

    return jax.jit(jax.vmap(one, in_axes=(None, 0, 0)))


def chain_contacts(fn, params, qpos, qvel) -> list:
    """Per state, the chain's present foot contacts in `c_contacts`' form."""
    out = {k: np.asarray(v) for k, v in fn(params, jnp.asarray(qpos), jnp.asarray(qvel)).items()}
    per_state = []
    for i in range(len(qpos)):
        # A row's translational Jacobian is its direction n +- mu t: the first two average to n.
        normal = lambda k: (out["jac"][i, k, 0, :3] + out["jac"][i, k, 1, :3]) / 2
        per_state.append([(out["dist"][i, k], out["pos"][i, k], normal(k), out["jac"][i, k],
                           out["D"][i, k], out["aref"][i, k]) for k in np.flatnonzero(out["exists"][i])])
    return per_state


def _match(ours: list, theirs: list) -> list:
    """Pairs (ours, theirs) matched by distance and position (the order of contacts differs)."""
    left = list(range(len(ours)))
    pairs = []
    for t in theirs:
        k = min(left, key=lambda k: abs(ours[k][0] - t[0]) + np.abs(ours[k][1] - t[1]).sum())
        left.remove(k)
        pairs.append((ours[k], t))
    return pairs


@pytest.fixture(scope="module")
def float64_contacts(models):
    """For each terrain: the chain's contacts and stages (float64; one engine, the terrains given
    as its heights input) and C's, at its default and at a tight convex-collision tolerance."""
    cases = {}
    for seed, name in enumerate(TERRAINS):
        m = models[name]
        states = terrain_states(m, N_STATES, seed=seed)
        tight = copy.deepcopy(m)
        tight.opt.ccd_tolerance, tight.opt.ccd_iterations = TIGHT_CCD, 2000
        c_stages = mujoco_c(converged(tight, 50), *states)
        cases[name] = (states, c_contacts(m, *states), c_contacts(tight, *states), c_stages)
    out = {}
    jax.config.update("jax_enable_x64", True)
    try:
        engine = chain.make(converged(models["rough"], 20))
        contacts, stages = chain_contacts_fn(engine), chain_stages(engine)
        for name, (states, default, c_tight, c_stages) in cases.items():
            params = engine.with_heights(chain.terrain_heights(models[name]))
            ours = chain_contacts(contacts, params, states[0], states[1])
            args = [jnp.asarray(x, jnp.float64) for x in states]
            ours_stages = {k: np.asarray(v) for k, v in stages(params, *args, jnp.zeros_like(args[1])).items()}
            out[name] = (ours, default, c_tight, ours_stages, c_stages)
    finally:
        jax.config.update("jax_enable_x64", False)
    return out


def test_states_touch_the_terrain_with_several_contacts(float64_contacts):
    for name, (_, default, *_) in float64_contacts.items():
        counts = [len(c) for c in default]
        assert min(counts) >= 1, f"{name}: every state touches the terrain"
        assert max(counts) >= 2, f"{name}: some states touch several prisms"


CONTACT_FIELDS = ("dist", "pos", "normal", "jac", "D", "aref")


@pytest.mark.parametrize("name", TERRAINS)
def test_float64_contacts_match_mujoco_c(float64_contacts, name):
    """Contact count, dist, pos, normal and the efc rows (J, D, aref) per contact, against C at
    a tight convex-collision tolerance (1e-9), and the distances against C at its default one
    (within opt.ccd_tolerance)."""
    ours, default, tight, _, _ = float64_contacts[name]
    err = dict.fromkeys(CONTACT_FIELDS, 0.0)
    err_default = 0.0
    for o, d, t in zip(ours, default, tight):
        assert len(o) == len(t) == len(d), f"{name}: {len(o)} contacts, C has {len(t)} (default tolerance {len(d)})"
        for a, b in _match(o, t):
            for k, field in enumerate(CONTACT_FIELDS):
                scale = max(1.0, np.abs(b[k]).max()) if field in ("D", "aref") else 1.0
                err[field] = max(err[field], np.abs(np.asarray(a[k]) - b[k]).max() / scale)
        err_default = max([err_default] + [abs(a[0] - b[0]) for a, b in _match(o, d)])
    print(f"\n{name}: max |chain - C| (tight CCD):", {k: f"{v:.1e}" for k, v in err.items()},
          f"dist at the default tolerance {err_default:.1e}")
    bounds = {"dist": 1e-9, "pos": 1e-7, "normal": 1e-9, "jac": 1e-7, "D": 1e-9, "aref": 1e-7}
    for field, bound in bounds.items():
        assert err[field] <= bound, f"{name} {field}: chain and MuJoCo C differ by {err[field]:.2e}"
    assert err_default <= float(models_tolerance()), f"{name}: distances differ by {err_default:.2e}"


@pytest.mark.parametrize("name", TERRAINS)
def test_float64_stages_match_mujoco_c(float64_contacts, name):
    """qacc, the constraint forces, the foot force and the step after, both solving to
    convergence, against C with its convex-collision tolerance tightened."""
    _, _, _, ours, c = float64_contacts[name]
    errors = {stage: np.abs(ours[stage] - c[stage]).max() for stage in STAGES + ("foot_force",)}
    print(f"\n{name}:", {k: f"{v:.1e}" for k, v in errors.items()})
    for stage, err in errors.items():
        assert err <= 1e-9, f"{name} {stage}: chain and MuJoCo C differ by {err:.2e}"


def test_the_base_box_on_a_heightfield_is_refused_in_one_line():
    with pytest.raises(NotChain, match="base box") as err:
        describe(hfield_model(terrain("rough"), HALF, HALF))
    assert "\n" not in str(err.value)


def models_tolerance() -> float:
    """C's default convex-collision tolerance (opt.ccd_tolerance) of the terrain models."""
    return float(hfield_model(terrain("rough"), HALF, HALF, base_pairs=False).opt.ccd_tolerance)


def _first_contact_height(m: mujoco.MjModel, qpos: np.ndarray) -> float:
    """The base height offset at which the foot first touches the terrain (bisection on C)."""
    d = mujoco.MjData(m)
    lo, hi = -0.3, 0.3  # in contact, not
    for _ in range(50):
        d.qpos[:] = qpos
        d.qpos[2] += 0.5 * (lo + hi)
        lo, hi = (0.5 * (lo + hi), hi) if _foot_contacts(m, d) else (lo, 0.5 * (lo + hi))
    return hi


TRAJ_STEPS = 1500  # 1.5 s
START_XY = {"rough": (0.0, 0.0), "step": (0.0, 0.0), "bump": (0.07, 0.02)}  # the foot lands on the slopes
DROP = 0.03  # m above the first contact


def _step_fn(engine: chain.ChainEngine):
    """A compiled, vmapped step (forward + integrate), each instance on its own terrain."""
    def one(params, qpos, qvel, ctrl, gravity, warm):
        data = engine.make_data(qpos, qvel).replace(ctrl=ctrl, qacc_warmstart=warm)
        data = engine.forward(params, data, gravity)
        after = engine.integrate(params, data, gravity)
        return after.qpos, after.qvel, data.qacc, data.foot_touching

    axes = chain.ChainParams(gate=None, terrain=chain.TerrainParams(0, 0))
    return jax.jit(jax.vmap(one, in_axes=(axes, 0, 0, 0, 0, 0)))


@pytest.fixture(scope="module")
def trajectories(models):
    """1.5 s from 3 cm above the terrain at three gravities, limp and holding the stance by PD,
    on the three terrains: the chain (float32, the model's own options, one compiled step with
    each instance's terrain as its input) and C side by side."""
    cases = [(name, g, hold) for name in TERRAINS for g in GRAVITIES for hold in (False, True)]
    engine = chain.make(models["rough"])
    params = engine.with_heights(np.stack([chain.terrain_heights(models[name]) for name, _, _ in cases]))
    n = len(cases)
    q0 = stance_qpos(models["rough"])
    qpos = np.tile(q0, (n, 1))
    for i, (name, _, _) in enumerate(cases):
        qpos[i, :2] = START_XY[name]
        qpos[i, 2] += _first_contact_height(models[name], qpos[i]) + DROP
    gravity = np.array([[0, 0, -g] for _, g, _ in cases])
    hold = np.array([h for _, _, h in cases])
    cmodels = [copy.deepcopy(models[name]) for name, _, _ in cases]
    cdata = []
    for m, q, g in zip(cmodels, qpos, gravity):
        m.opt.gravity[:] = g
        cdata.append(mujoco.MjData(m))
        cdata[-1].qpos[:] = q
    step = _step_fn(engine)
    qvel, warm = np.zeros((n, 9)), np.zeros((n, 9))
    ours, theirs, touched = [], [], np.zeros(n, bool)
    f32 = lambda x: jnp.asarray(x, jnp.float32)
    for _ in range(TRAJ_STEPS):
        ctrl = np.where(hold[:, None], HOLD_P * (q0[7:] - qpos[:, 7:]) - HOLD_D * qvel[:, 6:], 0.0)
        out = step(params, f32(qpos), f32(qvel), f32(ctrl), f32(gravity), f32(warm))
        qpos, qvel, warm, touching = (np.asarray(x) for x in out)
        touched |= touching
        for m, d, h in zip(cmodels, cdata, hold):
            d.ctrl[:] = np.where(h, HOLD_P * (q0[7:] - d.qpos[7:]) - HOLD_D * d.qvel[6:], 0.0)
            mujoco.mj_step(m, d)
        ours.append(qpos)
        theirs.append(np.array([d.qpos.copy() for d in cdata]))
    return cases, np.array(ours), np.array(theirs), touched


def test_trajectories_on_terrain_match_mujoco_c(trajectories):
    cases, ours, theirs, touched = trajectories
    assert touched.all(), "every run must include the touchdown"
    base_err = np.abs(ours[:, :, :3] - theirs[:, :, :3]).max(axis=(0, 2))
    for name in TERRAINS:
        worst = max(e for (t, _, _), e in zip(cases, base_err) if t == name)
        print(f"\n{name}: base path max |chain - C| {worst:.2e} m")
    assert base_err.max() < 1e-3, f"base position differs from MuJoCo C by {base_err.max():.2e} m"


def test_a_new_terrain_is_an_input_not_a_recompile(models):
    """The rough model's engine, given the step's heights, gives the step model's own answer,
    from the same compiled function (one trace)."""
    traces = []

    def forward(params, qpos, qvel):
        traces.append(1)
        data = engine.forward(params, engine.make_data(qpos, qvel), jnp.array([0.0, 0.0, -9.81]))
        return data.qacc, data.foot_force

    engine = chain.make(models["rough"])
    fn = jax.jit(jax.vmap(forward, in_axes=(None, 0, 0)))
    qpos, qvel, _, _ = terrain_states(models["step"], 4, seed=5)
    args = jnp.asarray(qpos, jnp.float32), jnp.asarray(qvel, jnp.float32)
    on_rough = fn(engine.model, *args)
    on_step = fn(engine.with_heights(chain.terrain_heights(models["step"])), *args)
    assert len(traces) == 1
    own = chain.make(models["step"])
    reference = fn(own.model, *args)
    assert len(traces) == 1, "the step model's own engine has the same grid: the same compiled function"
    for a, b in zip(on_step, reference):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.abs(np.asarray(on_rough[0]) - np.asarray(on_step[0])).max() > 1.0, "the terrain changes the answer"

