"""Constraint rows of the chain: joint dry friction, joint limits and floor contacts, with MuJoCo's equations.

Every row that can ever exist has a fixed slot (a dry-friction row per hinge with friction
loss; a limit per limited hinge; per contact pair one slot for a sphere, four for a box's
lowest corners; four pyramid edges or one frictionless row each). A row that does not exist
this step gets D = 0, which takes it out of the cost, gradient and Hessian exactly as if
MuJoCo had not created it.

Per row, as MuJoCo's mj_makeImpedance / mj_referenceConstraint:
    imp  = solimp's sigmoid of |pos - margin| / width
    R    = max(mjMINVAL, invweight0 * (1 - imp) / imp),   D = 1 / R
    aref = -B * (J qvel) - K * imp * (pos - margin),  K, B from solref (refsafe-clamped)

A hinge's dry friction (frictionloss f > 0, or a run-time value) is one two-sided row on its
dof, at pos = margin = 0 with the dof's solref / solimp; the solver bounds its force to
|force| <= f (`Rows.loss`). A run-time f of 0 gives a row whose force is always 0.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from hopper_mjx.engine.chain import algebra as al
from hopper_mjx.engine.chain import hfield as chain_hfield
from hopper_mjx.engine.chain import hfield_box as chain_hfield_box
from hopper_mjx.engine.chain.model import BoxBlock, ChainModel, ContactPair, SolParams
from hopper_mjx.engine.chain.smooth import Pose, dof_body
from hopper_mjx.engine.chain.stage import only_where, stored

MINVAL = 1e-15  # mujoco.mjMINVAL
MINIMP, MAXIMP = 0.0001, 0.9999  # mujoco.mjMINIMP, mjMAXIMP


class Block(NamedTuple):
    """Contact rows already stacked: a heightfield's dozens of slots are built as arrays, a pair at a time."""

    jac: jax.Array  # (nv, R)
    weight: jax.Array  # (R,) D, 0 where the row does not exist
    aref: jax.Array  # (R,)


class Rows(NamedTuple):
    jac: tuple  # per row: nv scalars (constant 0 where the row cannot reach the dof)
    weight: tuple  # per row: D, 0 when the row does not exist
    aref: tuple  # per row: reference acceleration
    loss: tuple  # per row: None (a one-sided row), or a friction row's (f, f R), its force bound and its
    #              residual's bound: the force is -D r inside |r| < f R and -+f beyond (MuJoCo's Huber cost)
    block: Block | None = None  # on a heightfield, the contact rows, after the rows above (all one-sided)


class FootContact(NamedTuple):
    touching: object  # () bool: foot-floor distance < 0
    pos: tuple  # contact point (the mean of several on a heightfield), world (zeros when not touching)
    rows: tuple  # indices of the foot's rows in Rows (a Block's rows counted after the per-row ones)
    directions: object  # per foot row: world direction of its force on the foot; (rows, 3) on a heightfield


def _stiffness_damping(cm: ChainModel, sol: SolParams) -> tuple[float, float, float, float]:
    """(K, B, dmin, dmax) of a row, constants of the model."""
    timeconst, dampratio = sol.solref
    dmin, dmax = (min(max(v, MINIMP), MAXIMP) for v in sol.solimp[:2])
    if timeconst > 0:
        if cm.refsafe:
            timeconst = max(timeconst, 2 * cm.timestep)
        k = 1 / (dmax * dmax * timeconst * timeconst * dampratio * dampratio)
        b = 2 / (dmax * timeconst)
    else:
        k, b = -timeconst / (dmax * dmax), -dampratio / dmax
    return k, b, dmin, dmax


def _impedance(sol: SolParams, dmin: float, dmax: float, violation):
    """MuJoCo's getimpedance: the sigmoid of solimp over |pos - margin| / width."""
    width, mid, power = sol.solimp[2], min(max(sol.solimp[3], MINIMP), MAXIMP), max(1.0, sol.solimp[4])
    if dmin == dmax or width <= MINVAL:
        return 0.5 * (dmin + dmax)
    x = jnp.abs(violation) / width
    powf = (lambda v: v * v) if power == 2 else (lambda v: v ** power)
    low = powf(x) / mid ** (power - 1)
    high = 1 - powf(1 - x) / (1 - mid) ** (power - 1)
    y = jnp.where(x <= mid, low, high)
    return jnp.where(x >= 1, dmax, dmin + y * (dmax - dmin))


def _row(cm, sol, invweight, jac, qvel, violation, exists):
    """(D, aref) of one row; violation = pos - margin."""
    k, b, dmin, dmax = _stiffness_damping(cm, sol)
    imp = _impedance(sol, dmin, dmax, violation)
    r = jnp.maximum(MINVAL, invweight * (1 - imp) / imp)
    vel = al.dot(jac, qvel)
    aref = al.sub(al.mul(-b, vel), k * imp * violation)
    return jnp.where(exists, 1 / r, 0.0), aref


def friction_rows(cm: ChainModel, qvel):
    """MuJoCo's mj_instantiateFriction for the hinges: its impedance at pos = 0 is a constant."""
    jac, weight, aref, loss = [], [], [], []
    for link in cm.links:
        h = link.hinge
        if h is None or (al.is_const(h.frictionloss) and not h.frictionloss):
            continue
        k, b, dmin, dmax = _stiffness_damping(cm, h.friction_sol)
        flat = dmin == dmax or h.friction_sol.solimp[2] <= MINVAL
        imp = 0.5 * (dmin + dmax) if flat else dmin  # getimpedance at zero violation
        r = al.mul(h.invweight, (1 - imp) / imp)
        r = max(MINVAL, r) if al.is_const(r) else jnp.maximum(MINVAL, r)
        row = [0.0] * cm.nv
        row[h.dof] = 1.0
        jac.append(tuple(row)), weight.append(1 / r), aref.append(al.mul(-b, qvel[h.dof]))
        loss.append((h.frictionloss, al.mul(h.frictionloss, r)))
    return jac, weight, aref, loss


def _limit_rows(cm: ChainModel, qpos, qvel):
    jac, weight, aref = [], [], []
    for link in cm.links:
        h = link.hinge
        if h is None or h.limit is None:
            continue
        lo, hi, margin = h.limit
        q = qpos[h.qpos_adr]
        to_lower, to_upper = q - lo, hi - q
        pos = jnp.minimum(to_lower, to_upper)
        row = [0.0] * cm.nv
        row[h.dof] = jnp.where(to_lower < to_upper, 1.0, -1.0)
        d, a = _row(cm, h.sol, h.invweight, tuple(row), qvel, pos - margin, pos < margin)
        jac.append(tuple(row)), weight.append(d), aref.append(a)
    return jac, weight, aref


def _point_jacobian(cm: ChainModel, pose: Pose, body: int, point, direction) -> tuple:
    """direction . (velocity of the body point at `point`) per dof (point relative to O)."""
    lever = al.cross(point, direction)
    return tuple(
        al.add(al.dot(direction, pose.dof_v[j]), al.dot(pose.dof_w[j], lever)) if b <= body else 0.0
        for j, b in enumerate(dof_body(cm))
    )


def _slots(pair: ContactPair, pose: Pose, normal, height):
    """Per contact slot of the pair: (distance, point relative to O)."""
    rot = al.matmul(pose.rot[pair.body], pair.rot)
    centre = al.vadd(pose.origin[pair.body], al.matvec(pose.rot[pair.body], pair.pos))
    centre_dist = al.add(al.dot(normal, centre), height)
    if pair.kind == "sphere":
        dist = centre_dist - pair.size[0]
        return [(dist, al.vsub(centre, al.vscale(pair.size[0] + 0.5 * dist, normal)))]
    slots = []
    sx, sy, sz = pair.size
    for k in range(4):  # corners k and 7 - k are opposite; MuJoCo keeps the lower of each pair
        corner = al.matvec(rot, ((sx if k & 1 else -sx), (sy if k & 2 else -sy), -sz))
        below = al.dot(normal, corner)
        sign = jnp.where(below <= 0, 1.0, -1.0)
        dist = centre_dist - jnp.abs(below)
        slots.append((dist, al.vsub(al.vadd(centre, al.vscale(sign, corner)), al.vscale(0.5 * dist, normal))))
    return slots


def _directions(cm: ChainModel, pair: ContactPair, friction, frame=None) -> tuple:
    """World directions of the pair's rows: the normal, or the pyramid's edges n +- mu t
    (`frame`: the contact's, by default the plane's)."""
    frame = cm.contact_frame if frame is None else frame
    normal = frame[0:3]
    if pair.condim == 1:
        return (normal,)
    out = []
    for t, mu in ((frame[3:6], friction[0]), (frame[6:9], friction[1])):
        # Folded: a run-time (drawn) mu leaves the components where the tangent is 0 constant.
        out.append(tuple(al.add(n, al.mul(mu, ti)) for n, ti in zip(normal, t)))
        out.append(tuple(al.sub(n, al.mul(mu, ti)) for n, ti in zip(normal, t)))
    return tuple(out)


def box_frame(pair: ContactPair, pose: Pose) -> tuple:
    """The box's centre (world) and its rotation (3x3 array, its axes as columns)."""
    centre = al.vadd(al.vadd(pose.origin[pair.body], al.matvec(pose.rot[pair.body], pair.pos)), pose.base_pos)
    rot = al.matmul(pose.rot[pair.body], pair.rot)
    as_array = lambda v: jnp.stack(jnp.broadcast_arrays(*(jnp.asarray(x) for x in v)))
    return as_array(centre), as_array(rot).reshape(3, 3)


def box_near(cm: ChainModel, box: BoxBlock, pose: Pose, terrain):
    """() bool: the box pair `box` (on a heightfield floor) may touch it this step."""
    pair = cm.pairs[box.pair]
    return chain_hfield_box.box_near(cm.terrain, box, terrain, *box_frame(pair, pose), pair.size)


def _terrain_slots(cm: ChainModel, p: int, pose: Pose, terrain, gate, boxes: dict) -> tuple:
    """Pair `p`'s heightfield contact slots, each field with the slots as leading axis: (exists, distance,
    point relative to O, contact frame); a box's contacts from `boxes` ({pair: its contacts}, `_box_contacts`)."""
    pair = cm.pairs[p]
    if pair.kind == "box":
        con = boxes[p]
    else:
        centre = al.vadd(pose.origin[pair.body], al.matvec(pose.rot[pair.body], pair.pos))
        con = chain_hfield.sphere_contacts(cm.terrain, terrain, al.vadd(centre, pose.base_pos), pair.size[0], gate)
    return con.exists, con.dist, al.vsub(con.pos, pose.base_pos), chain_hfield.make_frame(con.normal)


# The instances of a chunk whose box is near the ground that are gathered and collided alone (`only_where`); with
# more, the whole chunk is collided. A box's prism test costs some 14 µs an instance-step for the whole chunk of 256;
# robots flailing on the training course had a leg's box near the ground in 3 % of instances.
BOX_GATHER = 16


def _box_contacts(cm: ChainModel, pose: Pose, terrain, box_on) -> dict:
    """{pair: its `keep` contacts} of every box pair on the heightfield, collided by one loop over the boxes,
    so that the program holds the prism test once rather than once per box: each box's block is the largest
    (extra cells lie beyond its reach, and the deepest `keep` are the same), and each box's prisms are tested
    only for the instances where `box_on[pair]` (that box is near its ground: `box_near`)."""
    boxes = cm.terrain.boxes
    if not boxes:
        return {}
    shared = dataclasses.replace(boxes[0], block=tuple(max(b.block[i] for b in boxes) for i in range(2)),
                                 keep=max(b.keep for b in boxes), candidates=max(b.candidates for b in boxes))
    frames = [box_frame(cm.pairs[b.pair], pose) for b in boxes]
    dtype = frames[0][0].dtype
    each = (jnp.stack([f[0] for f in frames]), jnp.stack([f[1] for f in frames]),
            jnp.stack([jnp.asarray(cm.pairs[b.pair].size, dtype) for b in boxes]),
            jnp.asarray([b.radius for b in boxes], dtype), jnp.stack([box_on[b.pair] for b in boxes]))
    keep = shared.keep

    def one(args):
        centre, rot, half, radius, on = args
        collide = lambda c, r, h, rad, t: chain_hfield_box.box_contacts(cm.terrain, shared, t, c, r, h, rad)
        absent = lambda c, r, h, rad, t: chain_hfield.PrismContact(
            jnp.zeros(keep, bool), jnp.zeros(keep, dtype), (jnp.zeros(keep, dtype),) * 3,
            (jnp.zeros(keep, dtype),) * 2 + (jnp.ones(keep, dtype),))
        return only_where(on, collide, absent, (centre, rot, half, radius, terrain), BOX_GATHER)

    found = jax.lax.map(one, each)
    return {b.pair: jax.tree_util.tree_map(lambda x, g=g, k=b.keep: x[g, :k], found) for g, b in enumerate(boxes)}


def _all_slots(cm: ChainModel, pose: Pose, terrain, box_on=None, gate=None):
    """Per pair, per slot: (exists, distance, point relative to O, contact frame: None for the plane's); on a
    heightfield, per pair its slots as arrays (`_terrain_slots`)."""
    if cm.terrain is not None:
        boxes = _box_contacts(cm, pose, terrain, box_on)
        return tuple(_terrain_slots(cm, p, pose, terrain, gate, boxes) for p in range(len(cm.pairs)))
    normal = cm.contact_frame[0:3]
    height = al.dot(normal, al.vsub(pose.base_pos, cm.floor_point))  # base origin above the floor
    return tuple(tuple((dist <= pair.include_margin, dist, point, None)
                       for dist, point in _slots(pair, pose, normal, height)) for pair in cm.pairs)


def _foot(pose: Pose, slot, rows, directions) -> FootContact:
    """The foot's contact on the plane from its one slot (the foot is a sphere, `chain_model.describe`) and its
    rows' directions; on a heightfield `_terrain_block` gives it."""
    _, dist, point, _ = slot
    touching = dist < 0
    return FootContact(touching, tuple(jnp.where(touching, x, 0.0) for x in al.vadd(point, pose.base_pos)), rows,
                       directions)


def _assemble(cm: ChainModel, pose: Pose, qpos, qvel, slots) -> tuple[Rows, FootContact]:
    jac, weight, aref, loss = friction_rows(cm, qvel)
    limits = _limit_rows(cm, qpos, qvel)
    jac, weight, aref = jac + limits[0], weight + limits[1], aref + limits[2]
    if cm.terrain is not None:  # the contacts as one block after these rows
        block, foot = _terrain_block(cm, pose, qvel, slots, first=len(jac))
        loss += [None] * (len(jac) - len(loss))  # the limits are one-sided
        return Rows(tuple(jac), tuple(weight), tuple(aref), tuple(loss), block), foot
    foot = None
    for pair, pair_slots in zip(cm.pairs, slots):
        friction, invweight = pair.friction, pair.invweight  # constants, or an instance's (chain_model.instance)
        first, pair_directions = len(jac), ()
        for exists, dist, point, frame in pair_slots:
            directions = _directions(cm, pair, friction, frame)
            pair_directions += directions
            for direction in directions:
                row = _point_jacobian(cm, pose, pair.body, point, direction)
                d, a = _row(cm, pair.sol, invweight, row, qvel, dist - pair.include_margin, exists)
                jac.append(row), weight.append(d), aref.append(a)
        if pair.is_foot:
            foot = _foot(pose, pair_slots[0], tuple(range(first, len(jac))), pair_directions)
    loss += [None] * (len(jac) - len(loss))  # the limits and contacts are one-sided
    return Rows(tuple(jac), tuple(weight), tuple(aref), tuple(loss)), foot


def _terrain_block(cm: ChainModel, pose: Pose, qvel, slots, first: int) -> tuple[Block, FootContact]:
    """The heightfield contacts' rows, stacked: each pair's slots (arrays, `_terrain_slots`) go through the
    per-row arithmetic together, once per pyramid direction, so the program holds a pair's rows once rather
    than once per slot. Rows in MuJoCo's order, by slot then direction; `first`: the rows before them."""
    dtype = slots[0][1].dtype
    jac, weight, aref, foot = [], [], [], None
    for pair, (exists, dist, point, frame) in zip(cm.pairs, slots):
        n = exists.shape[0]
        wide = lambda x: jnp.broadcast_to(jnp.asarray(x, dtype), (n,))
        directions = _directions(cm, pair, pair.friction, frame)
        per = [(_point_jacobian(cm, pose, pair.body, point, d), d) for d in directions]
        built = [(row, d) + _row(cm, pair.sol, pair.invweight, row, qvel, dist - pair.include_margin, exists)
                 for row, d in per]
        # (nv, slots, directions) -> (nv, slots x directions): slot by slot, as MuJoCo orders them
        jac.append(jnp.stack([jnp.stack([wide(x) for x in row]) for row, _, _, _ in built], -1).reshape(cm.nv, -1))
        weight.append(jnp.stack([wide(w) for _, _, w, _ in built], -1).reshape(-1))
        aref.append(jnp.stack([wide(a) for _, _, _, a in built], -1).reshape(-1))
        if pair.is_foot:
            start = first + sum(x.shape[0] for x in weight[:-1])
            world = jnp.stack([jnp.stack([wide(x) for x in d], -1) for _, d, _, _ in built], 1).reshape(-1, 3)
            touching = dist < 0
            count = jnp.sum(touching.astype(dtype))
            pos = al.vadd(point, pose.base_pos)
            mean = tuple(1 / jnp.maximum(count, 1.0) * jnp.sum(jnp.where(touching, x, 0.0)) for x in pos)
            foot = FootContact(count > 0, mean, tuple(range(start, start + weight[-1].shape[0])), world)
    return Block(jnp.concatenate(jac, 1), jnp.concatenate(weight), jnp.concatenate(aref)), foot


def rows(cm: ChainModel, gate, pose: Pose, qpos, qvel, terrain=None) -> tuple[Rows, FootContact]:
    """All constraint rows (MuJoCo's order: friction, limits, then contacts by pair) and the foot's; `terrain`
    (chain_hfield.TerrainParams) for a heightfield floor, each of whose boxes (the base's, the leg links') is
    collided for the instances of the core's vmapped chunk where `box_near` holds for it (`chain_stage.only_where`)."""
    box_on = None
    if cm.terrain is not None:
        box_on = {b.pair: box_near(cm, b, pose, terrain) for b in cm.terrain.boxes}
    slots = stored(gate, lambda p, t, b, g: _all_slots(cm, p, t, b, g), pose, terrain, box_on, gate)
    return stored(gate, lambda *a: _assemble(cm, *a), pose, qpos, qvel, slots)
