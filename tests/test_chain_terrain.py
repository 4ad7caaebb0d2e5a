"""The chain engine on a heightfield floor against MuJoCo C, stage by stage and over trajectories.

The foot sphere meets the terrain's triangle prisms as C's mjc_ConvexHField does. C finds each
contact with GJK + EPA to `opt.ccd_tolerance`; the chain computes the point EPA converges to.
So: at C's default tolerance the distances agree to within it; with C's tolerance tightened
(1e-14) every stage agrees in float64 to ~1e-9. Trajectories through touchdown (float64, the
model's own options) stay within 1e-3 m of C. A new terrain is a new input, not a new compile.
The models here have no base-box pairs (test_chain_terrain_box.py has the box against the terrain).
The engines keep the foot's deepest `chain.FOOT_CONTACTS` prisms, as the tools make them (every contact
of these states; half the compile of a slot per prism); the contact tests below keep every prism.
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

from hopper_mjx.engine import chain
from hopper_mjx.engine.chain import constraint as chain_constraint
from hopper_mjx.engine.chain import hfield as chain_hfield
from hopper_mjx.engine.chain import smooth as chain_smooth
from hopper_mjx.metrics import hops
from hopper_mjx.model.robot import stance_qpos
from hopper_mjx.terrain import from_model

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
        every = chain_constraint._all_slots(cm, pose, params.terrain, None, params.gate)
        exists, dist, point, _ = every[0]  # the foot's slots, as arrays
        n = exists.shape[0]
        # The rows from these slots, as `rows` assembles them (it would collide the foot a second time).
        block = chain_constraint._assemble(cm, pose, qpos, qvel, every)[0].block
        first = block.weight.shape[0] - 4 * n
        return {
            "exists": exists, "dist": dist, "pos": jnp.stack(point, -1) + q[:3],
            "jac": block.jac[:, first:].T.reshape(n, 4, cm.nv),
            "D": block.weight[first:].reshape(n, 4), "aref": block.aref[first:].reshape(n, 4),
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
    with jax.enable_x64(True):
        engine = chain.make(converged(models["rough"], 20), chain.FOOT_CONTACTS)
        contacts, stages = chain_contacts_fn(engine), chain_stages(engine)
        for name, (states, default, c_tight, c_stages) in cases.items():
            params = engine.with_heights(from_model(models[name]).heights)
            ours = chain_contacts(contacts, params, states[0], states[1])
            args = [jnp.asarray(x, jnp.float64) for x in states]
            ours_stages = {k: np.asarray(v) for k, v in stages(params, *args, jnp.zeros_like(args[1])).items()}
            out[name] = (ours, default, c_tight, ours_stages, c_stages)
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


def _step_fn(engine: chain.ChainEngine, axis_name: str | None = None):
    """A compiled, vmapped step (forward + integrate), each instance on its own terrain: (qpos, qvel, qacc,
    foot touching, qfrc_constraint). `axis_name`: the core's (chain.BATCH_AXIS) to vmap as it does."""
    def one(params, qpos, qvel, ctrl, gravity, warm):
        data = engine.make_data(qpos, qvel).replace(ctrl=ctrl, qacc_warmstart=warm)
        data = engine.forward(params, data, gravity)
        after = engine.integrate(params, data, gravity)
        return after.qpos, after.qvel, data.qacc, data.foot_touching, data.qfrc_constraint

    axes = chain.ChainParams(gate=None, terrain=chain.TerrainParams(0, 0))
    return jax.jit(jax.vmap(one, in_axes=(axes, 0, 0, 0, 0, 0), axis_name=axis_name))


@pytest.fixture(scope="module")
def step64(models):
    """The rough model's engine (the tools' foot contacts) and its compiled float64 step, one instance per
    trajectory: `trajectories` and the new-terrain test run the same program (it compiles once)."""
    engine = chain.make(models["rough"], chain.FOOT_CONTACTS)
    return engine, _step_fn(engine)


@pytest.fixture(scope="module")
def trajectories(models, step64):
    """1.5 s from 3 cm above the terrain at three gravities, limp and holding the stance by PD,
    on the three terrains: the chain (float64, the model's own options, one compiled step with
    each instance's terrain as its input) and C side by side. In float32 the limp falls off
    the step's edge grow apart from C's float64 by 1e-2 m within the 1.5 s (an unstable
    motion amplifies rounding: 2.4e-7 m at 0.2 s, 8e-5 m at 0.7 s); in float64 the chain
    stays on C's path."""
    cases = [(name, g, hold) for name in TERRAINS for g in GRAVITIES for hold in (False, True)]
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
    qvel, warm = np.zeros((n, 9)), np.zeros((n, 9))
    ours, theirs, touched = [], [], []
    engine, step = step64
    with jax.enable_x64(True):
        params = engine.with_heights(np.stack([from_model(models[name]).heights for name, _, _ in cases]))
        for _ in range(TRAJ_STEPS):
            ctrl = np.where(hold[:, None], HOLD_P * (q0[7:] - qpos[:, 7:]) - HOLD_D * qvel[:, 6:], 0.0)
            out = step(params, *(jnp.asarray(x) for x in (qpos, qvel, ctrl, gravity, warm)))
            qpos, qvel, warm, touching, _ = (np.asarray(x) for x in out)
            touched.append(touching)
            for m, d, h in zip(cmodels, cdata, hold):
                d.ctrl[:] = np.where(h, HOLD_P * (q0[7:] - d.qpos[7:]) - HOLD_D * d.qvel[6:], 0.0)
                mujoco.mj_step(m, d)
            ours.append(qpos)
            theirs.append(np.array([d.qpos.copy() for d in cdata]))
    return cases, np.array(ours), np.array(theirs), np.array(touched)


def test_trajectories_on_terrain_match_mujoco_c(trajectories):
    """Base paths over the whole 1.5 s, through the touchdowns (and, limp, the falls: the
    base then passes through the terrain in both, these models having no base pairs)."""
    cases, ours, theirs, touched = trajectories
    assert touched.any(axis=0).all(), "every run includes the touchdown"
    err = np.abs(ours[:, :, :3] - theirs[:, :, :3]).max(axis=(0, 2))
    fell = hops.fallen(theirs).any(axis=0)
    for name in TERRAINS:
        worst = max(e for (t, _, _), e in zip(cases, err) if t == name)
        falls = sum(f for (t, _, _), f in zip(cases, fell) if t == name)
        print(f"\n{name}: base path max |chain - C| {worst:.2e} m ({falls} of 6 runs fall)")
    assert err.max() < 1e-3, f"base position differs from MuJoCo C by {err.max():.2e} m"


def test_a_new_terrain_is_an_input_not_a_recompile(models, step64):
    """The rough model's engine, given the step's heights, gives the step model's own answer,
    from the same compiled function (one trace: the trajectories' step)."""
    engine, step = step64
    own = chain.make(models["step"], chain.FOOT_CONTACTS)
    n = len(TERRAINS) * len(GRAVITIES) * 2  # the trajectories' batch: the same program
    states = [*terrain_states(models["step"], n, seed=5)]
    heights = {name: np.stack([from_model(models[name]).heights] * n) for name in ("rough", "step")}
    t = own.chain.terrain

    with jax.enable_x64(True):  # the trajectories' float64 program
        args = [jnp.asarray(x) for x in (*states, np.zeros_like(states[1]))]
        on_rough, on_step, reference = [[np.asarray(x) for x in step(params, *args)] for params in (
            engine.with_heights(heights["rough"]), engine.with_heights(heights["step"]),
            own.with_heights(heights["step"], np.full(n, t.origin[2] - t.base)))]  # own.model's, per instance
    assert step._cache_size() == 1, "the step model's own engine has the same grid: the same compiled function"
    for a, b in zip(on_step, reference):
        np.testing.assert_array_equal(a, b)
    assert np.abs(on_rough[2] - on_step[2]).max() > 1.0, "the terrain changes the answer"


def _deep_states(m: mujoco.MjModel, n: int, seed: int) -> np.ndarray:
    """Foot centres (n, 3) over the terrain's middle, 0-6 cm below the highest vertex within a
    foot radius: contacts on prism edges and walls, not only faces."""
    rng = np.random.default_rng(seed)
    x, y = _grid()
    heights = from_model(m).heights
    radius = m.geom_size[m.geom("foot").id, 0]
    centres = []
    for _ in range(n):
        cx, cy = rng.uniform(-0.2, 0.2, 2)
        near = np.hypot(x - cx, y - cy) < radius
        top = heights[near].max() if near.any() else heights.max()
        centres.append((cx, cy, top + radius - rng.uniform(0.0, 0.06)))
    return np.array(centres)


def _c_sphere_contacts(m: mujoco.MjModel, centre) -> list:
    """C's contacts of the foot geom placed at `centre` (the base moved under it)."""
    d = mujoco.MjData(m)
    d.qpos[:] = stance_qpos(m)
    mujoco.mj_kinematics(m, d)
    d.qpos[:3] += centre - d.geom_xpos[m.geom("foot").id]
    mujoco.mj_kinematics(m, d)
    mujoco.mj_collision(m, d)
    return [(c.dist, c.pos.copy(), c.frame[:3].copy()) for c in d.contact[:d.ncon]]


def _sphere_contacts(t, params, centre, radius: float):
    """Every contact slot of a sphere of `radius` at `centre` on the terrain `t` with `params`' heights, stacked:
    (exists, dist, pos, normal)."""
    out = chain_hfield.sphere_contacts(t, params.terrain, tuple(centre[i] for i in range(3)), radius)
    return out.exists, out.dist, jnp.stack(out.pos, -1), jnp.stack(out.normal, -1)


def test_deep_contacts_within_ccd_tolerance(models):
    """Deeper feet reach prism edges and walls, where C's EPA stops within `ccd_tolerance`:
    contact counts agree, distances within the tolerance, and with C's tolerance tightened
    the distances to 1e-9 and the normals to 1e-6 (C converges to the chain's values)."""
    err, err_tight = np.zeros(3), np.zeros(3)
    with jax.enable_x64(True):
        engine = chain.make(models["rough"])  # every prism a slot; each terrain is its heights input (one compile)
        radius = float(models["rough"].geom_size[models["rough"].geom("foot").id, 0])

        fn = jax.jit(jax.vmap(lambda c, p: _sphere_contacts(engine.chain.terrain, p, c, radius), in_axes=(0, None)))
        for seed, name in enumerate(TERRAINS):
            m = models[name]
            tight = copy.deepcopy(m)
            tight.opt.ccd_tolerance, tight.opt.ccd_iterations = TIGHT_CCD, 2000
            centres = _deep_states(m, 100, seed)
            exists, dist, pos, normal = (np.asarray(x) for x in fn(
                jnp.asarray(centres), engine.with_heights(from_model(m).heights)))
            for i, centre in enumerate(centres):
                ours = [(dist[i, k], pos[i, k], normal[i, k]) for k in np.flatnonzero(exists[i])]
                for reference, worst in ((_c_sphere_contacts(m, centre), err), (_c_sphere_contacts(tight, centre),
                                                                                 err_tight)):
                    assert len(ours) == len(reference), f"{name}: {len(ours)} contacts, C has {len(reference)}"
                    for a, b in _match(ours, reference):
                        worst[:] = np.maximum(worst, [abs(a[0] - b[0]), np.abs(a[1] - b[1]).max(),
                                                      np.abs(a[2] - b[2]).max()])
    print(f"\ndeep contacts, max |chain - C| dist, pos, normal: default tolerance {err}, tight {err_tight}")
    assert err[0] <= models_tolerance(), f"distances differ by {err[0]:.2e}, beyond C's ccd_tolerance"
    assert err[1] <= 1e-3 and err[2] <= 1e-3
    assert err_tight[0] <= 1e-9 and err_tight[1] <= 1e-6 and err_tight[2] <= 1e-6, err_tight


def test_max_foot_contacts_keeps_the_deepest(models):
    """With `max_foot_contacts`, the foot keeps its deepest contacts: all of them (C's set)
    when there are at most that many, else exactly the deepest that many."""
    keep = 4
    full = chain.make(models["bump"])
    few = chain.make(models["bump"], max_foot_contacts=keep)
    assert few.chain.terrain.max_contacts == keep and full.chain.terrain.max_contacts is None
    radius = float(models["bump"].geom_size[models["bump"].geom("foot").id, 0])

    def contacts(engine, c):
        return _sphere_contacts(engine.chain.terrain, engine.model, c, radius)[:2]

    centres = jnp.asarray(_deep_states(models["bump"], 64, seed=9) + np.array([0, 0, 0.04]), jnp.float32)
    everything = jax.jit(jax.vmap(lambda c: contacts(full, c)))(centres)
    kept = jax.jit(jax.vmap(lambda c: contacts(few, c)))(centres)
    assert kept[0].shape[1] == keep and everything[0].shape[1] == 2 * np.prod(full.chain.terrain.block)
    counts = np.asarray(everything[0]).sum(axis=1)
    assert (counts <= keep).any() and (counts > keep).any(), counts
    for exists, dist, k_exists, k_dist in zip(*(np.asarray(x) for x in everything + kept)):
        expected = np.sort(dist[exists])[:keep]
        np.testing.assert_array_equal(np.sort(k_dist[k_exists]), expected)
    with pytest.raises(ValueError, match="heightfield"):
        chain.make(_plane_model(), max_foot_contacts=keep)


def _plane_model() -> mujoco.MjModel:
    from hopper_mjx import model

    return model.load()
