"""The foot sphere against a heightfield floor, as MuJoCo C's mjc_ConvexHField finds it.

C cuts every grid cell under the sphere's bounding box into two triangles (split along the
diagonal (c, r)-(c + 1, r + 1)), extrudes each down to the floor's bottom into a prism, and
asks its convex penetration routine (GJK + EPA) for the sphere's penetration of each prism:
one contact per penetrated prism, with
    normal = the direction of least penetration, prism towards sphere,
    dist   = -(the penetration depth along it),
    pos    = the midpoint of the two deepest points (one on each body).
For a sphere against a convex prism that is analytic, and EPA converges to it:
- centre outside the prism at distance d < r from its closest point q:
  normal (p - q) / d, depth r - d, pos (q + p - r normal) / 2;
- centre inside, delta under the nearest face (outward normal n): normal n,
  depth delta + r, pos p + (delta - r) n / 2.
The closest point of the prism is the nearest of a few boundary points, each exact on its
part of the boundary: the top face and the bottom face (when the projection falls on them),
the three top edges, and the three walls (the point of the wall nearest in the horizontal,
its height clipped to the wall: exact inside the wall, on its bottom edge and on its
vertical edges; its slanted top edge is a top edge).

The grid is regular, so the cells the sphere can reach are a fixed block (its size known at
trace time) whose corner follows the sphere: each of its 2 x rows x cols prisms is a contact
slot, present when the sphere penetrates it (or, with `HeightGrid.max_contacts`, the deepest
few of them fill that many slots). The heights are a run-time input.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx.engine.chain import algebra as al
from hopper_mjx.engine.chain.model import HeightGrid
from hopper_mjx.engine.chain.stage import stored


class TerrainParams(NamedTuple):
    """The heightfield floor's run-time data: vertex heights (nrow, ncol) m, world, and the
    prisms' bottom (world z), which the convention puts `base` below the lowest vertex."""

    heights: jax.Array
    bottom: jax.Array


class PrismContact(NamedTuple):
    """A body's contacts with its prisms, one slot each: every field has the slots as its leading axis (the
    constraint rows are then built for all of a pair's slots at once), or is a scalar for one prism."""

    exists: object  # bool: the body penetrates this prism
    dist: object  # -depth
    pos: tuple  # world, x y z
    normal: tuple  # unit, floor to body, x y z


def _safe_unit(v):
    norm = jnp.sqrt(al.dot(v, v))
    inv = 1 / jnp.where(norm > 0, norm, 1.0)
    return norm, tuple(x * inv for x in v)


def _segment_point(p, a, b):
    """The point of segment ab nearest p."""
    e = al.vsub(b, a)
    t = jnp.clip(al.dot(al.vsub(p, a), e) / al.dot(e, e), 0.0, 1.0)
    return al.vadd(a, al.vscale(t, e)), t


def _prism_contact(p, top, bottom, radius) -> PrismContact:
    """The sphere (centre p, radius) against the prism under triangle `top` (3 vertices)."""
    v0, v1, v2 = top
    _, n = _safe_unit(al.cross(al.vsub(v1, v0), al.vsub(v2, v0)))
    n = tuple(jnp.where(n[2] < 0, -x, x) for x in n)  # the top face's outward normal points up
    above = al.dot(n, al.vsub(p, v0))
    edges = ((v0, v1, v2), (v1, v2, v0), (v2, v0, v1))  # (a, b, the opposite vertex)
    walls = []
    for a, b, o in edges:
        ex, ey = b[0] - a[0], b[1] - a[1]
        out = jnp.where(ey * (o[0] - a[0]) - ex * (o[1] - a[1]) > 0, -1.0, 1.0)  # away from o
        inv = out / jnp.sqrt(ex * ex + ey * ey)
        m = (ey * inv, -ex * inv, 0.0)
        walls.append((m, m[0] * (p[0] - a[0]) + m[1] * (p[1] - a[1])))

    def in_triangle(x, y):  # horizontally inside the triangle
        ok = True
        for (m, _), (a, _, _) in zip(walls, edges):
            ok = ok & (m[0] * (x - a[0]) + m[1] * (y - a[1]) <= 0)
        return ok

    # Boundary points: (point, valid) -> the nearest valid one is the prism's closest point.
    on_top = al.vsub(p, al.vscale(above, n))
    candidates = [(on_top, in_triangle(on_top[0], on_top[1])),
                  ((p[0], p[1], bottom), in_triangle(p[0], p[1]) & (p[2] < bottom))]
    for a, b, _ in edges:
        candidates.append((_segment_point(p, a, b)[0], True))
        flat, t = _segment_point((p[0], p[1], a[2]), a, (b[0], b[1], a[2]))
        candidates.append(((flat[0], flat[1], jnp.clip(p[2], bottom, a[2] + t * (b[2] - a[2]))), True))
    best, best_d2 = None, None
    for q, valid in candidates:
        diff = al.vsub(p, q)
        d2 = jnp.where(valid, al.dot(diff, diff), jnp.inf)
        if best is None:
            best, best_d2 = q, d2
        else:
            closer = d2 < best_d2
            best = tuple(jnp.where(closer, x, y) for x, y in zip(q, best))
            best_d2 = jnp.minimum(d2, best_d2)
    dist_out, out_normal = _safe_unit(al.vsub(p, best))

    # Inside: the face of least depth.
    depth_in, in_normal = -above, n
    for m, h in walls:
        nearer = -h < depth_in
        depth_in = jnp.where(nearer, -h, depth_in)
        in_normal = tuple(jnp.where(nearer, x, y) for x, y in zip(m, in_normal))
    nearer = p[2] - bottom < depth_in
    depth_in = jnp.where(nearer, p[2] - bottom, depth_in)
    in_normal = tuple(jnp.where(nearer, x, y) for x, y in zip((0.0, 0.0, -1.0), in_normal))
    inside = depth_in >= 0

    normal = tuple(jnp.where(inside, i, o) for i, o in zip(in_normal, out_normal))
    depth = jnp.where(inside, depth_in + radius, radius - dist_out)
    # The midpoint of the prism's point (q = p - dist normal, or p + delta n) and the sphere's (p - r normal).
    shift = jnp.where(inside, 0.5 * (depth_in - radius), -0.5 * (dist_out + radius))
    pos = al.vadd(p, al.vscale(shift, normal))
    return PrismContact(inside | (dist_out < radius), -depth, pos, normal)


def block_start(t: HeightGrid, centre, radius, block):
    """The first (row, col) of a block of (rows, cols) cells around a body of bounding `radius`:
    the cell under its bounding box's low corner, clamped so the block lies in the grid (then it
    still covers every cell the box reaches)."""
    rows, cols = block
    x = centre[0] - t.origin[0] + t.hx - radius
    y = centre[1] - t.origin[1] + t.hy - radius
    col = jnp.clip(jnp.floor(x / t.dx).astype(jnp.int32), 0, t.ncol - 1 - cols)
    row = jnp.clip(jnp.floor(y / t.dy).astype(jnp.int32), 0, t.nrow - 1 - rows)
    return row, col


def prism_vertices(rows: int, cols: int) -> tuple:
    """Per vertex of the prisms' top triangles, the (row, col) of every prism of a (rows, cols) block in C's
    order (by row, by column, the lower triangle (a, c, d) first, then (a, d, b)): three pairs of (P,) int
    arrays, P = 2 rows cols."""
    r, c = (g.reshape(-1) for g in np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij"))

    def vertex(lower, upper):  # its (row, col) offset from the cell's corner in the lower and the upper triangle
        interleave = lambda base, k: np.stack([base + lower[k], base + upper[k]], 1).reshape(-1)
        return interleave(r, 0), interleave(c, 1)

    return vertex((0, 0), (0, 0)), vertex((1, 0), (1, 1)), vertex((1, 1), (0, 1))


def sphere_contacts(t: HeightGrid, terrain: TerrainParams, centre, radius: float,
                    gate=None) -> PrismContact:
    """One contact slot per prism of the block around the sphere (world centre `centre`), as (P,) arrays; with
    `HeightGrid.max_contacts`, the deepest that many. The prisms are tested together, each coordinate a
    vector over the block's prisms (one operation for all of them, where one per prism made this stage a
    fifth of the rough step's program), and stored once behind `gate` (chain_stage.stored): fused into
    the choice of the deepest, every prism's test ran once per slot kept."""
    rows, cols = t.block
    row, col = block_start(t, centre, radius, t.block)
    block = jax.lax.dynamic_slice(terrain.heights, (row, col), (rows + 1, cols + 1))
    dtype = block.dtype
    x0 = t.origin[0] - t.hx + t.dx * col.astype(dtype)
    y0 = t.origin[1] - t.hy + t.dy * row.astype(dtype)

    def prisms(centre, block, x0, y0, bottom):
        def vertex(r, c):  # C's vertex (x0 + dx c, y0 + dy r, height), each (P,)
            return (x0 + np.asarray(t.dx * c, dtype), y0 + np.asarray(t.dy * r, dtype), block[r, c])

        found = _prism_contact(centre, tuple(vertex(r, c) for r, c in prism_vertices(rows, cols)), bottom, radius)
        size = 2 * rows * cols
        wide = lambda x: jnp.broadcast_to(jnp.asarray(x, dtype), (size,))
        return PrismContact(jnp.broadcast_to(found.exists, (size,)), wide(found.dist), tuple(map(wide, found.pos)),
                            tuple(map(wide, found.normal)))

    found = stored(jnp.array(True) if gate is None else gate, prisms, tuple(centre), block, x0, y0, terrain.bottom)
    if t.max_contacts is not None and t.max_contacts < found.exists.shape[0]:
        return deepest(found, t.max_contacts)
    return found


def deepest(contacts: PrismContact, keep: int) -> PrismContact:
    """The `keep` deepest present contacts of the (P,) slots `contacts` (absent slots where fewer exist),
    deepest first, the earlier slot first among equals: fewer constraint rows, the same contacts as C
    whenever at most `keep` exist."""
    depth = jnp.where(contacts.exists, -contacts.dist, -jnp.inf)
    fields = jnp.stack([contacts.dist, *contacts.pos, *contacts.normal], 1)  # (P, 7)
    top, idx = jax.lax.top_k(depth, keep)
    found = jnp.isfinite(top)
    picked = jnp.where(found[:, None], fields[idx], jnp.array([0.0, 0, 0, 0, 0, 0, 1], fields.dtype))
    return PrismContact(found, picked[:, 0], tuple(picked[:, k] for k in range(1, 4)),
                        tuple(picked[:, k] for k in range(4, 7)))


def make_frame(normal) -> tuple:
    """MuJoCo's mju_makeFrame of a traced unit normal: rows normal, tangent 1, tangent 2."""
    use_y = jnp.abs(normal[1]) < 0.5
    y = (0.0, jnp.where(use_y, 1.0, 0.0), jnp.where(use_y, 0.0, 1.0))
    y = al.vsub(y, al.vscale(al.dot(normal, y), normal))
    _, y = _safe_unit(y)
    return tuple(normal) + tuple(y) + tuple(al.cross(normal, y))
