"""The chain engine's view of a compiled model: every number it needs, as Python constants.

`describe(mj_model)` reads the topology the chain engine is written for (a free base, a
serial chain of bodies each with at most one hinge, explicit sphere / box contact pairs with
a plane floor or a heightfield floor (there one sphere, the foot, and boxes on any body), Euler
with implicit joint damping, dry friction on the hinges only, Newton on a pyramidal cone) and
raises `NotChain` with one line saying why when the model is outside it. The result is a frozen dataclass of
floats and tuples: the step reads it at trace time, so every axis, offset, inertia and
solver parameter is a constant of the compiled function (a heightfield's heights are not:
`terrain.from_model`), and `instance` puts one instance's varied numbers (a per-instance robot)
in place of the constants.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import mujoco
import numpy as np

from hopper_mjx.engine.chain import algebra as al
from hopper_mjx.engine.chain.algebra import const_mat
from hopper_mjx.model.loader import FOOT_GEOM

Sym6 = tuple  # symmetric 3x3 as (xx, yy, zz, xy, xz, yz)


class NotChain(ValueError):
    """The model is outside the chain engine's topology."""


@dataclass(frozen=True)
class SolParams:
    solref: tuple[float, float]
    solimp: tuple[float, float, float, float, float]


@dataclass(frozen=True)
class Hinge:
    axis: tuple[float, float, float]  # body frame, unit
    pos: tuple[float, float, float]  # body frame
    qpos_adr: int
    dof: int
    qpos0: float
    limit: tuple[float, float, float] | None  # (lower, upper, margin) rad, None if unlimited
    sol: SolParams
    invweight: float  # dof_invweight0: the limit and friction rows' approximate inverse mass
    frictionloss: float = 0.0  # dry friction, N·m: a friction row when nonzero (or a run-time value)
    friction_sol: SolParams | None = None  # the friction row's dof_solref / dof_solimp


@dataclass(frozen=True)
class Link:
    """One body after the base: placed on its parent, optionally turned by a hinge."""

    pos: tuple[float, float, float]  # in the parent's frame
    rot: tuple  # 3x3 row-major, in the parent's frame
    hinge: Hinge | None
    mass: float
    com: tuple[float, float, float]  # body frame
    inertia: Sym6  # about the COM, body frame


@dataclass(frozen=True)
class ContactPair:
    """An explicit floor-geom pair: sphere (radius) or box (half sizes) on chain body `body`."""

    body: int  # 0 = base, k = links[k - 1]
    kind: str  # "sphere" or "box"
    size: tuple[float, float, float]
    pos: tuple[float, float, float]  # geom in body frame
    rot: tuple  # geom in body frame
    condim: int  # 1 (frictionless) or 3 (pyramid of 4 edges)
    friction: tuple[float, float]
    margin: float  # detection margin
    include_margin: float  # margin - gap: rows are built below this distance
    sol: SolParams
    invweight: float  # row's approximate inverse mass, MuJoCo's diagApprox rule
    is_foot: bool
    body_invweight: float  # the body's translational invweight0, from which `invweight` follows


def pyramid_invweight(body_invweight, mu, impratio: float):
    """MuJoCo's one approximate inverse mass for every edge of a condim-3 pyramid of friction mu
    (a float, or a run-time value for a varied friction)."""
    return body_invweight * (1 + mu * mu) * 2 * mu * mu / impratio


@dataclass(frozen=True)
class HeightGrid:
    """A heightfield floor's grid (its heights are a run-time input, `terrain.from_model`).

    Vertex (r, c) lies at x = origin_x - hx + dx c, y = origin_y - hy + dy r; each cell is
    two triangles split along the diagonal (c, r)-(c + 1, r + 1), each the top of a prism
    whose bottom lies `base` below the geom origin (MuJoCo's mjc_ConvexHField)."""

    nrow: int
    ncol: int
    hx: float
    hy: float
    base: float
    origin: tuple[float, float, float]  # the hfield geom's position, world
    dx: float
    dy: float
    block: tuple[int, int]  # (rows, cols) of cells around the foot that can hold its contacts
    max_contacts: int | None = None  # keep the deepest this many foot contacts (None: all, as C)
    boxes: tuple[BoxBlock, ...] = ()  # the box pairs (the base's, the leg links'), in pair order


@dataclass(frozen=True)
class BoxBlock:
    """A box pair on a heightfield floor: the cells it can reach and the contacts it keeps."""

    pair: int  # index in ChainModel.pairs
    radius: float  # its bounding radius (MuJoCo's geom_rbound)
    block: tuple[int, int]  # (rows, cols) of cells its bounding box can cover
    keep: int  # constraint rows for its deepest contacts
    candidates: int  # prisms of its block given the full collision test (`chain_hfield_box._candidates`)


@dataclass(frozen=True)
class ChainModel:
    nq: int
    nv: int
    base_mass: float
    base_com: tuple[float, float, float]
    base_inertia: Sym6
    links: tuple[Link, ...]
    damping: tuple[float, ...]  # (nv,)
    armature: tuple[float, ...]  # (nv,)
    actuators: tuple[tuple, ...]  # (dof, gear, gain, bias0, bias1, bias2, ctrl range|None, force range|None)
    actuator_qpos: tuple[int, ...]  # qpos address of each actuator's joint (affine bias)
    joint_force_range: tuple[tuple[int, float, float], ...]  # (dof, lo, hi) per limited hinge
    floor_normal: tuple[float, float, float]
    floor_point: tuple[float, float, float]
    contact_frame: tuple  # 3x3 rows: normal, tangent 1, tangent 2 (MuJoCo's mju_makeFrame)
    pairs: tuple[ContactPair, ...]
    terrain: HeightGrid | None  # None: the floor is the plane
    timestep: float
    iterations: int
    ls_iterations: int
    tolerance: float
    ls_tolerance: float  # the line search stops where |d cost / d alpha| < tolerance ls_tolerance |search| / scale
    cost_scale: float  # MuJoCo's 1 / (meaninertia * nv): the solver's cost and gradient scale
    impratio: float
    warmstart: bool
    refsafe: bool
    eulerdamp: bool


_ALLOWED_DISABLE = (
    mujoco.mjtDisableBit.mjDSBL_SENSOR | mujoco.mjtDisableBit.mjDSBL_WARMSTART
    | mujoco.mjtDisableBit.mjDSBL_REFSAFE | mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    | mujoco.mjtDisableBit.mjDSBL_MIDPHASE | mujoco.mjtDisableBit.mjDSBL_FILTERPARENT
    | mujoco.mjtDisableBit.mjDSBL_AUTORESET | mujoco.mjtDisableBit.mjDSBL_NATIVECCD
)


_SHAPES = {int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere", int(mujoco.mjtGeom.mjGEOM_BOX): "box"}
_BIASES = (int(mujoco.mjtBias.mjBIAS_NONE), int(mujoco.mjtBias.mjBIAS_AFFINE))


def _require(ok: bool, why: str) -> None:
    if not ok:
        raise NotChain(f"not a chain model: {why}")


def _sym(diag, quat) -> Sym6:
    r = np.array(const_mat(_quat_mat(quat))).reshape(3, 3)
    full = r @ np.diag(diag) @ r.T
    return tuple(float(full[i, j]) for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))


def _quat_mat(quat) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(quat, dtype=float))
    return out


def _vec(v) -> tuple[float, float, float]:
    return tuple(float(x) for x in v)


def _sol(solref, solimp) -> SolParams:
    return SolParams(tuple(float(x) for x in solref), tuple(float(x) for x in solimp))


def _make_frame(normal) -> tuple:
    """MuJoCo's mju_makeFrame for a contact normal: rows normal, tangent 1, tangent 2 (the
    pyramid's edges lie along the tangents, so they must be MuJoCo's)."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    y = np.array([0.0, 1.0, 0.0]) if abs(n[1]) < 0.5 else np.array([0.0, 0.0, 1.0])
    y = y - n * (n @ y)
    y /= np.linalg.norm(y)
    return tuple(float(x) for x in np.concatenate([n, y, np.cross(n, y)]))


def _check_options(m: mujoco.MjModel) -> None:
    opt = m.opt
    _require(opt.integrator == mujoco.mjtIntegrator.mjINT_EULER, "the integrator is not Euler")
    _require(opt.solver == mujoco.mjtSolver.mjSOL_NEWTON, "the solver is not Newton")
    _require(opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL, "the friction cone is not pyramidal")
    _require(opt.disableflags & ~int(_ALLOWED_DISABLE) == 0, f"disable flags {opt.disableflags} are set")
    _require(opt.enableflags == 0, f"enable flags {opt.enableflags} are set")
    _require(opt.noslip_iterations == 0, "noslip iterations are set")
    _require(opt.density == 0 and opt.viscosity == 0 and not np.any(opt.wind), "the medium is not empty")
    _require(m.neq == 0 and m.ntendon == 0 and m.nflex == 0, "it has equalities, tendons or flexes")
    _require(not np.any(m.dof_frictionloss[:6]), "its free joint has friction loss")
    _require(not np.any(m.dof_frictionloss < 0), "a joint has negative friction loss")  # C makes rows of it anyway
    _require(not np.any(m.jnt_stiffness), "it has springs")
    _require(not np.any(m.body_gravcomp) and m.nmocap == 0 and m.na == 0, "it has gravcomp, mocap or actuator state")


def _check_tree(m: mujoco.MjModel) -> None:
    _require(m.nbody >= 2 and all(m.body_parentid[b] == b - 1 for b in range(1, m.nbody)),
             "the bodies are not one serial chain from the world")
    _require(m.njnt >= 1 and m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE and m.jnt_bodyid[0] == 1,
             "the first body has no free joint")
    _require(not np.any(m.jnt_pos[0]), "the free joint is not at the base origin")
    _require(m.body_jntnum[1] == 1, "the base has more than its free joint")
    for j in range(1, m.njnt):
        _require(m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE, f"joint {m.joint(j).name!r} is not a hinge")
    _require(all(m.body_jntnum[b] <= 1 for b in range(2, m.nbody)), "a link has more than one joint")


def _hinge(m: mujoco.MjModel, j: int) -> Hinge:
    dof = int(m.jnt_dofadr[j])
    limit = None
    if m.jnt_limited[j]:
        lo, hi = (float(x) for x in m.jnt_range[j])
        margin = float(m.jnt_margin[j])
        _require(hi - lo > 2 * margin, f"joint {m.joint(j).name!r} has both limits active at once")
        limit = (lo, hi, margin)
    return Hinge(
        axis=_vec(m.jnt_axis[j]), pos=_vec(m.jnt_pos[j]), qpos_adr=int(m.jnt_qposadr[j]), dof=dof,
        qpos0=float(m.qpos0[m.jnt_qposadr[j]]), limit=limit, sol=_sol(m.jnt_solref[j], m.jnt_solimp[j]),
        invweight=float(m.dof_invweight0[dof]), frictionloss=float(m.dof_frictionloss[dof]),
        friction_sol=_sol(m.dof_solref[dof], m.dof_solimp[dof]),
    )


def _links(m: mujoco.MjModel) -> tuple[Link, ...]:
    links = []
    for b in range(2, m.nbody):
        joint = int(m.body_jntadr[b]) if m.body_jntnum[b] else None
        links.append(Link(
            pos=_vec(m.body_pos[b]), rot=const_mat(_quat_mat(m.body_quat[b])),
            hinge=None if joint is None else _hinge(m, joint), mass=float(m.body_mass[b]),
            com=_vec(m.body_ipos[b]), inertia=_sym(m.body_inertia[b], m.body_iquat[b]),
        ))
    return tuple(links)


def _pairs(m: mujoco.MjModel, floor: int) -> tuple[ContactPair, ...]:
    pairs = []
    for p in range(m.npair):
        g1, g2 = int(m.pair_geom1[p]), int(m.pair_geom2[p])
        _require(g1 == floor, f"contact pair {p} does not have the floor as its first geom")
        kind = _SHAPES.get(int(m.geom_type[g2]))
        _require(kind is not None, f"contact pair {p} is not with a sphere or a box")
        condim = int(m.pair_dim[p])
        _require(condim in (1, 3), f"contact pair {p} has condim {condim} (1 or 3 supported)")
        body = int(m.geom_bodyid[g2]) - 1
        invweight = body_invweight = float(m.body_invweight0[body + 1, 0])  # the floor is on the world: no share
        friction = (float(m.pair_friction[p, 0]), float(m.pair_friction[p, 1]))
        if condim == 3:  # MuJoCo's pyramid: one approximate inverse mass for all edges
            _require(friction[0] > 0 and friction[1] > 0, f"contact pair {p} has zero friction with condim 3")
            invweight = pyramid_invweight(invweight, friction[0], float(m.opt.impratio))
        margin, gap = float(m.pair_margin[p]), float(m.pair_gap[p])
        pairs.append(ContactPair(
            body=body, kind=kind, size=_vec(m.geom_size[g2]), pos=_vec(m.geom_pos[g2]),
            rot=const_mat(_quat_mat(m.geom_quat[g2])), condim=condim, friction=friction, margin=margin,
            include_margin=margin - gap, sol=_sol(m.pair_solref[p], m.pair_solimp[p]), invweight=invweight,
            is_foot=m.geom(g2).name == FOOT_GEOM, body_invweight=body_invweight,
        ))
    _require(sum(p.is_foot for p in pairs) == 1 and any(p.is_foot and p.kind == "sphere" for p in pairs),
             f"no sphere foot geom {FOOT_GEOM!r} paired with the floor")
    return tuple(pairs)


# The box pairs' (keep, candidates) below, for the base and for a leg link.
# The base box's contacts on a heightfield that become constraint rows (its deepest; C keeps up to
# mjMAXCONPAIR = 50). A fallen box on rough ground touches a few prisms; lying on a level patch, every
# prism under it, and then these carry its weight instead of C's dozens, so it sinks deeper (measured: 4.7 mm
# on a level step against C's 1.1 mm; with 24 rows 1.7 mm, but the step costs 1.4x at N = 1024: every slot's
# rows are in every solve).
BOX_CONTACTS = 8
# Of the box's block of prisms (288 on 4 cm cells), those given the full separating-axis test: the ones whose
# overlap with the box along z and the box's axes is largest. C's set whenever at most this many prisms pass that
# cheap test (a box lying on a level top has more; then these hold its deepest contacts). The full test on
# every prism cost ~60 times the rest of a step.
BOX_CANDIDATES = 24
# A leg link's box (4-5 cm thick) against a block's edge or a slope meets a few prisms; lying along level ground,
# a row of them, of which these keep the deepest. Each kept slot is a row in every solve (condim 1: one a slot).
LINK_CONTACTS = 4
LINK_CANDIDATES = 16

_FLOORS = (int(mujoco.mjtGeom.mjGEOM_PLANE), int(mujoco.mjtGeom.mjGEOM_HFIELD))


def _floor(m: mujoco.MjModel) -> int:
    planes = [g for g in range(m.ngeom) if int(m.geom_type[g]) in _FLOORS]
    _require(len(planes) == 1 and m.geom_bodyid[planes[0]] == 0,
             "there is not exactly one floor (plane or heightfield) on the world")
    for a in range(m.ngeom):
        for b in range(a + 1, m.ngeom):
            filtered = (m.geom_contype[a] & m.geom_conaffinity[b]) | (m.geom_contype[b] & m.geom_conaffinity[a])
            _require(not filtered, "geoms collide outside the explicit contact pairs")
    return planes[0]


def _terrain(m: mujoco.MjModel, floor: int, pairs: tuple[ContactPair, ...]) -> HeightGrid | None:
    """The heightfield floor's grid, or None on a plane; `NotChain` for what is not written yet."""
    if m.geom_type[floor] != mujoco.mjtGeom.mjGEOM_HFIELD:
        return None
    _require(np.allclose(m.geom_quat[floor], [1, 0, 0, 0], rtol=0, atol=0), "the heightfield floor is turned")
    others = [k for k, p in enumerate(pairs) if not p.is_foot]
    _require(all(pairs[k].kind == "box" for k in others), "a heightfield floor takes the foot sphere and boxes")
    _require(all(p.margin == 0 and p.include_margin == 0 for p in pairs), "a heightfield pair has a margin or gap")
    foot = next(p for p in pairs if p.is_foot)
    _require(not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_NATIVECCD,
             "native CCD is off (the heightfield contacts would be libccd's)")
    h = int(m.geom_dataid[floor])
    nrow, ncol = int(m.hfield_nrow[h]), int(m.hfield_ncol[h])
    hx, hy, _, base = (float(x) for x in m.hfield_size[h])
    dx, dy = 2 * hx / (ncol - 1), 2 * hy / (nrow - 1)
    # Cells a sphere of this radius can reach: its box spans at most floor(2r / d) + 2 of them.
    diameter = 2 * foot.size[0]
    block = (int(diameter // dy) + 2, int(diameter // dx) + 2)
    _require(nrow > block[0] and ncol > block[1], f"the heightfield grid {nrow}x{ncol} is smaller than the foot")
    boxes = []
    for k in others:
        radius = float(np.linalg.norm(pairs[k].size))
        rows, cols = int(2 * radius // dy) + 2, int(2 * radius // dx) + 2
        _require(nrow > rows and ncol > cols, f"the heightfield grid {nrow}x{ncol} is smaller than a box")
        keep, candidates = (BOX_CONTACTS, BOX_CANDIDATES) if pairs[k].body == 0 else (LINK_CONTACTS, LINK_CANDIDATES)
        boxes.append(BoxBlock(pair=k, radius=radius, block=(rows, cols), keep=keep,
                              candidates=min(candidates, 2 * rows * cols)))
    return HeightGrid(nrow=nrow, ncol=ncol, hx=hx, hy=hy, base=base, origin=_vec(m.geom_pos[floor]), dx=dx, dy=dy,
                      block=block, boxes=tuple(boxes))


def _actuators(m: mujoco.MjModel):
    acts, qadr = [], []
    for a in range(m.nu):
        _require(m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and m.actuator_trnid[a, 0] >= 1,
                 f"actuator {a} does not drive a hinge")
        _require(m.actuator_dyntype[a] == mujoco.mjtDyn.mjDYN_NONE
                 and m.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED
                 and int(m.actuator_biastype[a]) in _BIASES,
                 f"actuator {a} is not a plain motor or affine servo")
        joint = int(m.actuator_trnid[a, 0])
        ctrl = tuple(float(x) for x in m.actuator_ctrlrange[a]) if m.actuator_ctrllimited[a] else None
        force = tuple(float(x) for x in m.actuator_forcerange[a]) if m.actuator_forcelimited[a] else None
        bias = m.actuator_biasprm[a, :3] if m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE else np.zeros(3)
        acts.append((int(m.jnt_dofadr[joint]), float(m.actuator_gear[a, 0]), float(m.actuator_gainprm[a, 0]),
                     *(float(x) for x in bias), ctrl, force))
        qadr.append(int(m.jnt_qposadr[joint]))
    frc = tuple((int(m.jnt_dofadr[j]), float(m.jnt_actfrcrange[j, 0]), float(m.jnt_actfrcrange[j, 1]))
                for j in range(1, m.njnt) if m.jnt_actfrclimited[j])
    return tuple(acts), tuple(qadr), frc


def describe(m: mujoco.MjModel) -> ChainModel:
    """The chain engine's constants of `m`, or `NotChain` saying why the model is outside it."""
    _check_options(m)
    _check_tree(m)
    floor = _floor(m)
    normal = _quat_mat(m.geom_quat[floor]).reshape(3, 3)[:, 2]
    acts, act_qpos, frc = _actuators(m)
    pairs = _pairs(m, floor)
    opt = m.opt
    dis = mujoco.mjtDisableBit
    return ChainModel(
        nq=int(m.nq), nv=int(m.nv), base_mass=float(m.body_mass[1]), base_com=_vec(m.body_ipos[1]),
        base_inertia=_sym(m.body_inertia[1], m.body_iquat[1]), links=_links(m),
        damping=tuple(float(x) for x in m.dof_damping), armature=tuple(float(x) for x in m.dof_armature),
        actuators=acts, actuator_qpos=act_qpos, joint_force_range=frc,
        floor_normal=_vec(normal), floor_point=_vec(m.geom_pos[floor]), contact_frame=_make_frame(normal),
        pairs=pairs, terrain=_terrain(m, floor, pairs), timestep=float(opt.timestep), iterations=int(opt.iterations),
        ls_iterations=int(opt.ls_iterations), tolerance=float(opt.tolerance), ls_tolerance=float(opt.ls_tolerance),
        cost_scale=1.0 / (float(m.stat.meaninertia) * max(1, int(m.nv))), impratio=float(opt.impratio),
        warmstart=not opt.disableflags & dis.mjDSBL_WARMSTART,
        refsafe=not opt.disableflags & dis.mjDSBL_REFSAFE, eulerdamp=not opt.disableflags & dis.mjDSBL_EULERDAMP,
    )


def _key(field: str, index: tuple) -> str:
    return f"{field}{list(index)}"


def entries(cm: ChainModel, values: dict, settable: dict) -> dict:
    """One instance's numbers the chain reads from `values` ({model field: that field's array}): {"field[i, j]":
    scalar} of each entry `settable[field]` marks, and MuJoCo's derived constraint weights (`body_invweight0` of
    the bodies with a contact pair, `dof_invweight0` of the hinges with a limit or friction row:
    variation.draw.with_constants).
    Sliced once per rollout, so that the step reads scalars, not arrays; in field order, whatever the order of
    `settable` (a set's order changes with the process's string hashing, and with it the traced program and so its
    persistent-cache key: a program compiled afresh runs slower than one loaded, docs/performance.md)."""
    out = {_key(f, tuple(int(i) for i in index)): values[f][index]
           for f, mask in sorted(settable.items()) if f in values for index in zip(*np.nonzero(mask))}
    if "body_invweight0" in values:
        out |= {_key("body_invweight0", (p.body + 1, 0)): values["body_invweight0"][p.body + 1, 0] for p in cm.pairs}
    if "dof_invweight0" in values:  # of the hinges with a row: a limit, or friction (the model's or drawn)
        rowed = lambda h: h.limit is not None or h.frictionloss or "dof_frictionloss" in values
        out |= {_key("dof_invweight0", (link.hinge.dof,)): values["dof_invweight0"][link.hinge.dof]
                for link in cm.links if link.hinge is not None and rowed(link.hinge)}
    return out


def derive(cm: ChainModel, m: mujoco.MjModel, robot: dict) -> dict:
    """`robot` (`entries`) and what the step would otherwise recompute from it every step: each drawn body's
    inertia turned into its body frame (sym6) and each pair's row inverse mass, MuJoCo's pyramid rule applied
    to a drawn friction or body weight. Computed once per rollout (`ChainEngine.vary`), so that the step only
    loads them where the unvaried step reads constants."""

    def pick(field: str, index: tuple, constant):
        return robot.get(_key(field, index), constant)

    out = dict(robot)
    for b in range(1, m.nbody):
        diag = tuple(pick("body_inertia", (b, k), float(m.body_inertia[b, k])) for k in range(3))
        if all(map(al.is_const, diag)):
            continue
        r = _quat_mat(m.body_iquat[b]).reshape(3, 3)
        for k, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
            out[_key(_FRAME_INERTIA, (b, k))] = al.total(al.mul(float(r[i, a] * r[j, a]), diag[a]) for a in range(3))
    for p, pair in enumerate(cm.pairs):
        mu = (pick("pair_friction", (p, 0), pair.friction[0]), pick("pair_friction", (p, 1), pair.friction[1]))
        body_invweight = pick("body_invweight0", (pair.body + 1, 0), pair.body_invweight)
        if all(map(al.is_const, mu)) and body_invweight is pair.body_invweight:
            continue
        out[_key(_ROW_INVWEIGHT, (p,))] = body_invweight if pair.condim == 1 else pyramid_invweight(
            body_invweight, mu[0], cm.impratio)
    return out


_FRAME_INERTIA = "inertia in the body frame"  # derived keys (`derive`), apart from the model fields'
_ROW_INVWEIGHT = "pair row invweight"


def instance(cm: ChainModel, m: mujoco.MjModel, robot: dict) -> ChainModel:
    """`cm` as one instance's robot: each number of `robot` (`derive`) replaces the constant folded from `m`,
    the nominal model; every other number, zeros among them, stays a constant (so the algebra still folds it).
    Only loads: what follows from the drawn numbers alone was computed once, by `derive`."""

    def pick(field: str, index: tuple, constant):
        return robot.get(_key(field, index), constant)

    def vec(field: str, row: int, constant) -> tuple:
        return tuple(pick(field, (row, k), c) for k, c in enumerate(constant))

    def inertia(b: int, constant: Sym6) -> Sym6:
        return tuple(pick(_FRAME_INERTIA, (b, k), c) for k, c in enumerate(constant))

    def hinge(h: Hinge | None) -> Hinge | None:
        return h if h is None else dataclasses.replace(h, invweight=pick("dof_invweight0", (h.dof,), h.invweight),
                                                       frictionloss=pick("dof_frictionloss", (h.dof,), h.frictionloss))

    links = tuple(dataclasses.replace(
        link, pos=vec("body_pos", b, link.pos), hinge=hinge(link.hinge), mass=pick("body_mass", (b,), link.mass),
        com=vec("body_ipos", b, link.com), inertia=inertia(b, link.inertia)) for b, link in enumerate(cm.links, 2))
    pairs = []
    for p, pair in enumerate(cm.pairs):
        g = int(m.pair_geom2[p])
        size = (pick("geom_size", (g, 0), pair.size[0]),) + pair.size[1:]
        friction = (pick("pair_friction", (p, 0), pair.friction[0]), pick("pair_friction", (p, 1), pair.friction[1]))
        pairs.append(dataclasses.replace(
            pair, size=size, friction=friction, invweight=pick(_ROW_INVWEIGHT, (p,), pair.invweight),
            body_invweight=pick("body_invweight0", (pair.body + 1, 0), pair.body_invweight)))
    acts = tuple((a[0], pick("actuator_gear", (k, 0), a[1])) + a[2:] for k, a in enumerate(cm.actuators))
    return dataclasses.replace(
        cm, base_mass=pick("body_mass", (1,), cm.base_mass), base_com=vec("body_ipos", 1, cm.base_com),
        base_inertia=inertia(1, cm.base_inertia), links=links, pairs=tuple(pairs), actuators=acts,
        damping=tuple(pick("dof_damping", (i,), d) for i, d in enumerate(cm.damping)),
        armature=tuple(pick("dof_armature", (i,), a) for i, a in enumerate(cm.armature)),
    )
