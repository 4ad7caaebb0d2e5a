"""The base box against a heightfield floor on the chain engine, against MuJoCo C.

Per prism, the chain's contact is the box's exact penetration of the prism (separating axes). C's
convex routine (native GJK + EPA, its tolerance tightened) gives the same depth, normal and point
on each prism written as a mesh. C's heightfield routine runs that routine over the same prisms and
finds the same contacts, but for about half of them returns a shallower depth along another
direction (not a tolerance effect: the same at 1e-6 and 1e-14); the count is compared, the
agreement printed. Trajectories: limp drops onto the three test terrains, the base box falling
onto the ground, follow C within 1e-3 m until the box first touches, and the gap after is printed.
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from hfield_model import hfield_model
from test_chain_terrain import GRAVITIES, HALF, TERRAINS, _first_contact_height, _step_fn, terrain

from hopper_mjx.engine import chain
from hopper_mjx.engine.chain import constraint as chain_constraint
from hopper_mjx.engine.chain import hfield_box as chain_hfield_box
from hopper_mjx.engine.chain import smooth as chain_smooth
from hopper_mjx.engine.chain.hfield import block_start
from hopper_mjx.model.robot import stance_qpos
from hopper_mjx.terrain import from_model

TIGHT_CCD = 1e-14
N_POSES = 24


@pytest.fixture(scope="module")
def rough():
    m = hfield_model(terrain("rough"), HALF, HALF)
    m.opt.ccd_tolerance, m.opt.ccd_iterations = TIGHT_CCD, 2000
    return m


def base_box(engine: chain.ChainEngine):
    """The base box's pair on the heightfield (`chain_model.BoxBlock`): the one on body 0."""
    return next(b for b in engine.chain.terrain.boxes if engine.chain.pairs[b.pair].body == 0)


def sunk(m: mujoco.MjModel, d: mujoco.MjData, q: np.ndarray, g: int, rng) -> np.ndarray:
    """`q` lowered so that box geom `g`'s lowest corner lies 0-6 mm below the ground under it (at the nearest
    vertex)."""
    heights = from_model(m).heights
    cell = 2 * HALF / (heights.shape[0] - 1)
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    rot, half = d.geom_xmat[g].reshape(3, 3), m.geom_size[g]
    corners = np.array([d.geom_xpos[g] + rot @ (half * (2 * np.array(s) - 1)) for s in np.ndindex(2, 2, 2)])
    low = corners[corners[:, 2].argmin()]
    r, c = (int(round((v + HALF) / cell)) for v in (low[1], low[0]))
    q = q.copy()
    q[2] += heights[r, c] - low[2] - rng.uniform(0.0, 0.006)
    return q


def box_poses(m: mujoco.MjModel, n: int, seed: int) -> np.ndarray:
    """qpos with the base turned at random over the terrain, its lowest corner 0-6 mm below the ground
    under it (at the nearest vertex)."""
    rng = np.random.default_rng(seed)
    d = mujoco.MjData(m)
    out = []
    for _ in range(n):
        q = stance_qpos(m).copy()
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
        q[:2] = rng.uniform(-0.5, 0.5, 2)
        out.append(sunk(m, d, q, int(m.pair_geom2[0]), rng))
    return np.array(out)


def _mesh_penetration(top: np.ndarray, bottom: float, centre, rot, half) -> list:
    """C's native convex collision of the box and one prism written as a mesh: (depth, normal prism to box,
    pos) per contact."""
    verts = np.concatenate([top, np.c_[top[:, :2], np.full(3, bottom)]])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.asarray(rot, float).ravel())
    f = lambda v: " ".join(repr(float(x)) for x in np.ravel(v))
    xml = f"""<mujoco><option><flag multiccd="disable"/></option>
    <asset><mesh name="prism" vertex="{f(verts)}"/></asset><worldbody>
      <geom type="mesh" mesh="prism"/>
      <body pos="{f(centre)}" quat="{f(quat)}"><freejoint/><geom type="box" size="{f(half)}"/></body>
    </worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    m.opt.ccd_tolerance, m.opt.ccd_iterations = TIGHT_CCD, 2000
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    # The mesh is geom 0: C's normal points from it to the box.
    return [(-c.dist, c.frame[:3].copy(), c.pos.copy()) for c in d.contact[:d.ncon]]


@pytest.fixture(scope="module")
def per_prism(rough):
    """Per pose: the box frame, the block's prisms and the chain's per-prism answer (float64)."""
    engine = chain.make(rough)
    cm, t = engine.chain, engine.chain.terrain
    box = base_box(engine)
    pair = cm.pairs[box.pair]
    poses = box_poses(rough, N_POSES, seed=0)
    with jax.enable_x64(True):
        params = engine.with_heights(from_model(rough).heights)

        def one(q):
            pose = chain_smooth.kinematics(cm, params.gate, tuple(q[i] for i in range(cm.nq)))
            centre, rot = chain_constraint.box_frame(pair, pose)
            row, col = block_start(t, centre, box.radius, box.block)
            tops = chain_hfield_box._prisms(t, box.block, params.terrain, row, col, centre.dtype)
            axes, half = rot.T, jnp.asarray(pair.size)
            return centre, rot, tops, chain_hfield_box._box_prism(t, centre, axes, half, tops, params.terrain.bottom)

        out = jax.jit(jax.vmap(one))(jnp.asarray(poses))
        out = jax.tree_util.tree_map(np.asarray, out)
        bottom = float(params.terrain.bottom)
    return poses, out, bottom, np.asarray(pair.size)


def test_each_box_prism_contact_is_c_convex_penetration(per_prism):
    """Every contact the chain finds, and a sample of the prisms it finds none with, against C's convex
    routine on that prism (one witness pair: multiccd off). MuJoCo stores a mesh's vertices in float32, so
    the prism C sees is the chain's to ~1e-9 m: depth within 5e-8 m, normal 5e-7, point 5e-8 m."""
    poses, (centre, rot, tops, (exists, depth, normal, pos)), bottom, half = per_prism
    found = err_depth = err_normal = err_pos = 0
    rng = np.random.default_rng(1)
    for i in range(len(poses)):
        for k in np.flatnonzero(exists[i]):
            theirs = _mesh_penetration(tops[i, k], bottom, centre[i], rot[i], half)
            assert theirs, f"pose {i} prism {k}: C finds no contact"
            assert len(theirs) == 1
            d, n, p = theirs[0]
            n = -n  # C's normal points from the box (geom 2) to the mesh here
            err_depth = max(err_depth, abs(d - depth[i, k]))
            err_normal = max(err_normal, np.abs(n - normal[i, k]).max())
            err_pos = max(err_pos, np.abs(p - pos[i, k]).max())
            found += 1
        reaching = np.flatnonzero(~exists[i] & (tops[i, :, :, 2].max(1) > centre[i][2] - 0.3))
        for k in rng.choice(reaching, size=min(3, len(reaching)), replace=False):
            assert not _mesh_penetration(tops[i, k], bottom, centre[i], rot[i], half), f"pose {i} prism {k}"
    print(f"\n{found} box-prism contacts: max |chain - C convex| depth {err_depth:.1e} m, normal {err_normal:.1e},"
          f" point {err_pos:.1e} m")
    assert found >= 2 * N_POSES
    assert err_depth <= 5e-8 and err_normal <= 5e-7 and err_pos <= 5e-8


def test_box_contacts_on_the_heightfield_against_c(rough, per_prism):
    """The chain's contact set (its `keep` deepest) has C's heightfield count; C's own depths agree
    for part of them (printed; see the module's note)."""
    poses, (_, _, _, (exists, depth, normal, pos)), _, _ = per_prism
    keep = base_box(chain.make(rough)).keep
    d = mujoco.MjData(rough)
    g = int(rough.pair_geom2[0])
    same = total = 0
    for i, q in enumerate(poses):
        d.qpos[:] = q
        mujoco.mj_forward(rough, d)
        theirs = [(-c.dist, c.frame[:3], c.pos) for c in d.contact[:d.ncon] if c.geom2 == g]
        assert len(theirs) == exists[i].sum(), f"pose {i}: C has {len(theirs)}, the chain {exists[i].sum()}"
        ours = [(depth[i, k], normal[i, k], pos[i, k]) for k in np.flatnonzero(exists[i])]
        for c in theirs:
            total += 1
            same += any(abs(c[0] - o[0]) < 1e-6 and np.abs(c[1] - o[1]).max() < 1e-5 for o in ours)
    kept = sum(min(e.sum(), keep) for e in exists)
    print(f"\nC's heightfield routine: {total} box contacts over {len(poses)} poses, {same} with the chain's depth"
          f" and normal (1e-6); the chain keeps {kept} as rows ({keep} a step at most)")
    assert total >= 2 * N_POSES


DROP_STEPS = 1200  # 1.2 s: the limp robot lands on its foot, topples and lands on its base box (0.4-0.8 s in C)
ROLL = 4.0  # rad/s about x at the start, so that it topples


@pytest.fixture(scope="module")
def falls():
    """Limp drops from 3 cm above the first contact, rolling at 4 rad/s, onto the three test terrains at three
    gravities, the models with their base-box pairs: the chain (float64, its tools' foot contacts) and C."""
    models = {name: hfield_model(terrain(name), HALF, HALF) for name in TERRAINS}
    cases = [(name, g) for name in TERRAINS for g in GRAVITIES]
    n = len(cases)
    q0 = stance_qpos(models["rough"])
    qpos = np.tile(q0, (n, 1))
    for i, (name, _) in enumerate(cases):
        qpos[i, :2] = (0.07, 0.02)
        qpos[i, 2] += _first_contact_height(models[name], qpos[i]) + 0.03
    gravity = np.array([[0, 0, -g] for _, g in cases])
    cmodels = [copy.deepcopy(models[name]) for name, _ in cases]
    cdata = []
    qvel, warm, ctrl = np.zeros((n, 9)), np.zeros((n, 9)), np.zeros((n, 3))
    qvel[:, 3] = ROLL
    for m, q, v, g in zip(cmodels, qpos, qvel, gravity):
        m.opt.gravity[:] = g
        cdata.append(mujoco.MjData(m))
        cdata[-1].qpos[:], cdata[-1].qvel[:] = q, v
    box = int(cmodels[0].pair_geom2[0])
    ours, theirs, box_down = [], [], []
    with jax.enable_x64(True):
        engine = chain.make_for_tools(models["rough"])
        params = engine.with_heights(np.stack([from_model(models[name]).heights for name, _ in cases]))
        step = _step_fn(engine, chain.BATCH_AXIS)
        for _ in range(DROP_STEPS):
            out = step(params, *(jnp.asarray(x) for x in (qpos, qvel, ctrl, gravity, warm)))
            qpos, qvel, warm, _, _ = (np.asarray(x) for x in out)
            for m, d in zip(cmodels, cdata):
                mujoco.mj_step(m, d)
            ours.append(qpos)
            theirs.append(np.array([d.qpos.copy() for d in cdata]))
            box_down.append([any(c.geom2 == box for c in d.contact[:d.ncon]) for d in cdata])
        # Beside the runs: the same step, a batch standing and the same batch with one fallen instance.
        standing = stance_qpos(models["rough"]).copy()
        standing[2] += _first_contact_height(models["rough"], standing)
        batches = np.tile(standing, (2, n, 1))
        batches[1, -1] = box_poses(models["rough"], 1, seed=5)[0]
        rough_params = engine.with_heights(np.stack([from_model(models["rough"]).heights] * n))
        zeros = jnp.zeros((n, 9))
        args = lambda q: (jnp.asarray(q), zeros, jnp.zeros((n, 3)), jnp.asarray(gravity), zeros)
        beside = [jax.tree_util.tree_map(np.asarray, step(rough_params, *args(q))) for q in batches]
        # The batch with the fallen instance once more, its box collided for the instances in need alone (at most
        # 2 of the chunk gathered), where the chunk of 9 is otherwise collided whole.
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(chain_constraint, "BOX_GATHER", 2)
            gathered_engine = chain.make_for_tools(models["rough"])
            step = _step_fn(gathered_engine, chain.BATCH_AXIS)
            gathered = jax.tree_util.tree_map(np.asarray, step(gathered_engine.with_heights(
                np.stack([from_model(models["rough"]).heights] * n)), *args(batches[1])))
    return cases, np.array(ours), np.array(theirs), np.array(box_down), (*beside, gathered)


def test_drops_onto_the_base_box_follow_c_until_it_lands(falls):
    cases, ours, theirs, box_down, _ = falls
    err = np.linalg.norm(ours[:, :, :3] - theirs[:, :, :3], axis=2)  # (T, cases)
    landed = box_down.any(axis=0)
    assert landed.sum() >= len(cases) // 2, "most drops end on the base box"
    first = np.where(landed, box_down.argmax(axis=0), len(err))
    before = max(err[:f, i].max() for i, f in enumerate(first))
    for i, (name, g) in enumerate(cases):
        at = f"{first[i] * 1e-3:.3f} s" if landed[i] else "never"
        print(f"\n{name} at {g}: box lands {at}; base path max |chain - C| before {err[:first[i], i].max():.1e} m,"
              f" 50 ms after {err[:first[i] + 50, i].max():.1e} m, over {DROP_STEPS} steps {err[:, i].max():.1e} m")
    assert before < 1e-3, f"before the box lands the base paths differ by {before:.2e} m"


def test_the_fallen_box_rests_on_the_ground(falls):
    """At the end the fallen robots lie on the ground: C's own collision of the chain's states finds the box at
    most 6 mm deeper in the terrain than in C's, each averaged over the last 0.2 s (MuJoCo's soft contact, ~1 mm).
    The chain's BOX_CONTACTS rows carry what C spreads over dozens: lying on a level top 4.7 mm against 1.1; across
    the step's edge, fewer prisms under it, the robots still rock at 1.2 s and the depth swings with them (the
    step at 9.81 m/s^2, one instance from 0.8 s to 3 s: 2.6-6.4 mm, whichever the rows' summation order)."""
    cases, ours, theirs, _, _ = falls
    models = {name: hfield_model(terrain(name), HALF, HALF) for name in TERRAINS}

    def box_depth(m, q):
        d = mujoco.MjData(m)
        d.qpos[:] = q
        mujoco.mj_forward(m, d)
        return max([-c.dist for c in d.contact[:d.ncon] if c.geom2 == m.pair_geom2[0]], default=-np.inf)

    def mean_depth(states, i):
        depths = [box_depth(models[cases[i][0]], q[i]) for q in states[-200::20]]
        return np.mean(depths) if np.isfinite(depths).all() else -np.inf  # off the box at any of them: not resting

    ours_depth = [mean_depth(ours, i) for i in range(len(cases))]
    c_depth = [mean_depth(theirs, i) for i in range(len(cases))]
    print("\nmean box depth in the ground over the last 0.2 s, chain:", np.round(ours_depth, 4), "C:",
          np.round(c_depth, 4))
    assert np.isfinite(ours_depth).sum() >= len(cases) // 2, "most chain runs end on the base box"
    assert max(ours_depth) <= max(c_depth) + 6e-3


def test_a_fallen_instance_does_not_change_the_others(falls):
    """The box's prisms are collided for the instances of a chunk whose box nears the ground (`only_where` under
    the core's vmap): standing instances step bit for bit the same beside a fallen one."""
    alone, beside, _ = falls[-1]
    for a, b in zip(alone, beside):
        np.testing.assert_array_equal(a[:-1], b[:-1])
    assert np.abs(beside[4][-1]).max() > 1.0, "the fallen instance's box meets the ground"
    assert np.abs(alone[4][-1] - beside[4][-1]).max() > 1.0


def test_the_instances_in_need_collided_alone_step_as_in_the_whole_chunk(falls):
    """The fallen instance's box collided alone (gathered from the chunk, `chain_stage.only_where`) and with the
    whole chunk: every instance's next state, accelerations and constraint forces bit for bit the same."""
    _, whole, alone = falls[-1]
    assert np.abs(whole[4][-1]).max() > 1.0, "the fallen instance's box meets the ground"
    for a, b in zip(whole, alone):
        np.testing.assert_array_equal(a, b)
