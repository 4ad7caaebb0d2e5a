"""The thigh's and the shank's contact boxes against a heightfield floor, on both engines, against MuJoCo C.

On a terrain the loader pairs a box around each leg link's cylinder with the floor (condim 1, massless).
Stage by stage: at random poses where a link's box reaches 0-6 mm into rough ground, each box-prism contact
of the chain is C's convex routine's on that prism written as a mesh (as tests/test_chain_terrain_box.py does
for the base box), and C's heightfield routine finds as many. Along a trajectory: the limp robot, launched
in zero gravity with its leg trailing, sweeps its shank into a block's edge; the block stops the shank on
both engines (without the pairs it goes through), and both base paths stay within 1e-3 m of C's.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from hfield_model import hfield_model
from test_chain_terrain import HALF, _step_fn, terrain
from test_chain_terrain_box import _mesh_penetration, sunk

from hopper_mjx import model
from hopper_mjx import terrain as terrains
from hopper_mjx.engine import chain
from hopper_mjx.engine.chain import constraint as chain_constraint
from hopper_mjx.engine.chain import hfield_box as chain_hfield_box
from hopper_mjx.engine.chain import smooth as chain_smooth
from hopper_mjx.engine.chain.hfield import block_start
from hopper_mjx.engine.chain.model import describe
from hopper_mjx.terrain import from_model
from hopper_mjx.terrain.scan import height_at

LINKS = ("upperleg_contact", "lowerleg_contact")
N_POSES = 12  # per link


@pytest.fixture(scope="module")
def rough():
    m = hfield_model(terrain("rough"), HALF, HALF)
    m.opt.ccd_tolerance, m.opt.ccd_iterations = 1e-14, 2000
    return m


def test_the_leg_boxes_are_contact_only(rough):
    """The boxes bound the cylinders and add no mass; the plane has none of them."""
    flat = model.load()
    assert not any(flat.geom(g).name in LINKS for g in range(flat.ngeom))
    for name in ("body_mass", "body_inertia", "body_ipos", "body_iquat", "body_invweight0", "dof_invweight0"):
        assert np.array_equal(getattr(flat, name), getattr(rough, name)), name
    for name in LINKS:
        g = rough.geom(name)
        cyl = next(k for k in range(rough.ngeom) if rough.geom_bodyid[k] == g.bodyid[0]
                   and rough.geom_type[k] == mujoco.mjtGeom.mjGEOM_CYLINDER)
        r, half = rough.geom_size[cyl, :2]
        np.testing.assert_array_equal(g.size, [r, r, half])
        np.testing.assert_array_equal(g.pos, rough.geom_pos[cyl])
        pair = int(np.flatnonzero(rough.pair_geom2 == g.id)[0])
        assert rough.pair_dim[pair] == 1 and rough.pair_geom1[pair] == rough.geom("floor").id


def link_poses(m: mujoco.MjModel, g: int, n: int, seed: int) -> np.ndarray:
    """qpos turned at random (base and joints) over the terrain, box `g`'s lowest corner 0-6 mm below the
    ground under it (at the nearest vertex)."""
    rng = np.random.default_rng(seed)
    d = mujoco.MjData(m)
    out = []
    for _ in range(n):
        q = m.qpos0.copy()
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
        q[7:] = [rng.uniform(*m.jnt_range[j]) for j in range(1, 4)]
        q[:2] = rng.uniform(-0.4, 0.4, 2)
        out.append(sunk(m, d, q, g, rng))
    return np.array(out)


@pytest.fixture(scope="module")
def per_prism(rough):
    """Per link, per pose: the box frame, its block's prisms and the chain's per-prism answer (float64, eager:
    no program of its own; the chain model alone, not an engine, whose step would be traced)."""
    cm = describe(rough)
    t = cm.terrain
    out = {}
    with jax.enable_x64(True):
        params = chain.ChainParams(gate=jnp.array(True), terrain=chain.TerrainParams(
            jnp.asarray(from_model(rough).heights), jnp.asarray(t.origin[2] - t.base)))
        for k, name in enumerate(LINKS):
            box = next(b for b in t.boxes if rough.pair_geom2[b.pair] == rough.geom(name).id)
            pair = cm.pairs[box.pair]
            poses = link_poses(rough, rough.geom(name).id, N_POSES, seed=k)
            rows = []
            for q in poses:
                pose = chain_smooth.kinematics(cm, params.gate, tuple(jnp.asarray(x) for x in q))
                centre, rot = chain_constraint.box_frame(pair, pose)
                row, col = block_start(t, centre, box.radius, box.block)
                tops = chain_hfield_box._prisms(t, box.block, params.terrain, row, col, centre.dtype)
                found = chain_hfield_box._box_prism(t, centre, rot.T, jnp.asarray(pair.size), tops,
                                                    params.terrain.bottom)
                rows.append(jax.tree_util.tree_map(np.asarray, (centre, rot, tops, found)))
            out[name] = poses, rows, np.asarray(pair.size)
        bottom = float(params.terrain.bottom)
    return out, bottom


def test_each_leg_prism_contact_is_c_convex_penetration(per_prism):
    """Every contact the chain finds for a leg box, against C's convex routine on that prism (float32 mesh
    vertices: ~1e-9 m): depth within 5e-8 m, normal 5e-7, point 5e-8 m."""
    out, bottom = per_prism
    found, err = 0, np.zeros(3)
    for name, (poses, rows, half) in out.items():
        for i, (centre, rot, tops, (exists, depth, normal, pos)) in enumerate(rows):
            for k in np.flatnonzero(exists):
                theirs = _mesh_penetration(tops[k], bottom, centre, rot, half)
                assert len(theirs) == 1, f"{name} pose {i} prism {k}: C finds {len(theirs)} contacts"
                d, n, p = theirs[0]
                err = np.maximum(err, [abs(d - depth[k]), np.abs(-n - normal[k]).max(), np.abs(p - pos[k]).max()])
                found += 1
    print(f"\n{found} leg box-prism contacts: max |chain - C convex| depth {err[0]:.1e} m, normal {err[1]:.1e},"
          f" point {err[2]:.1e} m")
    assert found >= 2 * N_POSES
    assert err[0] <= 5e-8 and err[1] <= 5e-7 and err[2] <= 5e-8


def test_leg_contacts_on_the_heightfield_against_c(rough, per_prism):
    """Per pose, C's heightfield routine finds as many contacts for the leg box as the chain's prisms hold."""
    out, _ = per_prism
    d = mujoco.MjData(rough)
    same = total = 0
    for name, (poses, rows, _) in out.items():
        g = rough.geom(name).id
        for i, (q, (_, _, _, (exists, depth, normal, _))) in enumerate(zip(poses, rows)):
            d.qpos[:] = q
            mujoco.mj_forward(rough, d)
            theirs = [(-c.dist, c.frame[:3]) for c in d.contact[:d.ncon] if c.geom2 == g]
            assert len(theirs) == exists.sum(), f"{name} pose {i}: C has {len(theirs)}, the chain {exists.sum()}"
            ours = [(depth[k], normal[k]) for k in np.flatnonzero(exists)]
            total += len(theirs)
            same += sum(any(abs(c[0] - o[0]) < 1e-6 and np.abs(c[1] - o[1]).max() < 1e-5 for o in ours)
                        for c in theirs)
    print(f"\nC's heightfield routine: {total} leg box contacts, {same} with the chain's depth and normal (1e-6)")
    assert total >= 2 * N_POSES


# The sweep: a 15 cm block from x = 0.15 m, 5 cm cells (its face a slope one cell wide). The robot floats in zero
# gravity 2 cm above the ground before it, its straight leg trailing (hfe 0.6 rad, haa 0.3 rad: no face of the
# shank's box parallel to the block's edge), and moves at 0.8 m/s along +x: the shank meets the block's edge
# after ~50 ms, and the block turns the limp leg back.
SWEEP = "obstacle:height=0.15,x=0.15,length=0.3,size=2,cell=0.05"
SWEEP_STEPS = 400
SPEED = 0.8


def _sweep_start(m: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    d = mujoco.MjData(m)
    d.qpos[:] = m.qpos0
    d.qpos[7:] = (0.3, 0.6, 0.0)
    d.qpos[0] = 0.42
    mujoco.mj_kinematics(m, d)
    d.qpos[2] += 0.07 - d.geom_xpos[m.geom(model.FOOT_GEOM).id, 2]
    d.qvel[0] = SPEED
    return d.qpos.copy(), d.qvel.copy()


def _c_run(m: mujoco.MjModel, q0, v0) -> tuple[np.ndarray, int]:
    """C's qpos (steps, nq) and the number of steps with a leg box contact."""
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = q0, v0
    legs = [m.geom(name).id for name in LINKS if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name) >= 0]
    out, touching = [], 0
    for _ in range(SWEEP_STEPS):
        mujoco.mj_step(m, d)
        out.append(d.qpos.copy())
        touching += any(c.geom2 in legs for c in d.contact[:d.ncon])
    return np.array(out), touching


@pytest.fixture(scope="module")
def sweep():
    """The sweep on C (with and without the leg pairs), on the chain (float64) and on MJX (float32, one scan)."""
    from mujoco import mjx

    t = terrains.parse(SWEEP).terrain()
    m = model.load(terrain=t)
    m.opt.gravity[:] = 0.0
    spec = model.build_spec(terrain=t)
    for pair in list(spec.pairs):
        if pair.geomname2 in LINKS:
            spec.delete(pair)
    bare = spec.compile()
    bare.opt.gravity[:] = 0.0
    q0, v0 = _sweep_start(m)
    c, touching = _c_run(m, q0, v0)
    through, _ = _c_run(bare, q0, v0)
    with jax.enable_x64(True):
        engine = chain.make(m, chain.FOOT_CONTACTS)  # as the tools make it (make_for_tools traces twice)
        params = engine.with_heights(from_model(m).heights[None])
        step = _step_fn(engine, chain.BATCH_AXIS)
        qpos, qvel, warm, ours = q0[None], v0[None], np.zeros((1, m.nv)), []
        for _ in range(SWEEP_STEPS):
            out = step(params, *(jnp.asarray(x) for x in (qpos, qvel, np.zeros((1, m.nu)), np.zeros((1, 3)), warm)))
            qpos, qvel, warm = (np.asarray(x) for x in out[:3])
            ours.append(qpos[0])
    mm = mjx.put_model(m)
    start = mjx.make_data(m).replace(qpos=jnp.asarray(q0, jnp.float32), qvel=jnp.asarray(v0, jnp.float32))

    def one(data, _):
        data = mjx.step(mm, data)
        return data, data.qpos

    roll = jax.jit(lambda data: jax.lax.scan(one, data, None, length=SWEEP_STEPS)[1])

    return m, t, {"C": c, "C without the leg pairs": through, "chain": np.array(ours),
                  "mjx": np.asarray(roll(start), np.float64)}, touching


def shank_depth(m: mujoco.MjModel, t: terrains.Terrain, qpos: np.ndarray) -> float:
    """Max over the states of how far below the ground (MuJoCo's triangles, vertically) the shank box's four long
    edges dip, sampled every 9 mm: the shank passing into the block, whatever a collision routine says."""
    d = mujoco.MjData(m)
    g = m.geom("lowerleg_contact").id
    sx, sy, sz = m.geom_size[g]
    local = np.array([(x, y, z) for x in (-sx, sx) for y in (-sy, sy) for z in np.linspace(-sz, sz, 41)])
    worst = -np.inf
    for q in qpos:
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        points = d.geom_xpos[g] + local @ d.geom_xmat[g].reshape(3, 3).T
        ground = np.asarray(height_at(t.heights, t.size, points[:, 0], points[:, 1]))
        worst = max(worst, float(np.max(ground - points[:, 2])))
    return worst


def test_the_block_stops_the_shank(sweep):
    """In C the shank's box touches the block for tens of steps and its edges dip 7.5 mm into the block's
    72-degree face, measured vertically (MuJoCo's soft contact; less along the face's normal), on both engines
    too; without the leg pairs they pass 41 mm into the block, until the foot meets it."""
    m, t, paths, touching = sweep
    depth = {name: shank_depth(m, t, q) for name, q in paths.items()}
    print("\nthe shank's lowest dip below the ground:", ", ".join(f"{k} {v * 1e3:.1f} mm" for k, v in depth.items()))
    assert touching >= 20
    assert depth["C without the leg pairs"] > 0.03
    for name in ("C", "chain", "mjx"):
        assert depth[name] < 0.01, name


def test_the_sweep_follows_c_on_both_engines(sweep):
    m, _, paths, _ = sweep
    c = paths["C"][:, :3]
    assert np.abs(c - paths["C without the leg pairs"][:, :3]).max() > 0.01, "the leg's contact moves the base"
    err = {name: np.linalg.norm(paths[name][:, :3] - c, axis=1).max() for name in ("chain", "mjx")}
    shown = ", ".join(f"{k} {v:.1e} m" for k, v in err.items())
    print(f"\nsweep: max |base path - C| over {SWEEP_STEPS} steps: {shown}")
    assert max(err.values()) < 1e-3
