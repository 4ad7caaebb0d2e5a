"""A box (the base's, a leg link's) against a heightfield floor, as MuJoCo C's mjc_ConvexHField finds it.

C collides the box with the prism under each triangle of the cells its bounding box covers
(`chain_hfield` describes the prisms), skipping a prism whose top lies wholly below the box's
lowest point, and keeps one contact per penetrated prism from its convex penetration routine
(GJK + EPA, native CCD): the direction of least penetration, prism towards box, its depth, and
the midpoint of the two deepest points. For two convex polyhedra that is the separating-axis
answer: the least overlap over the faces' normals of both and the cross products of their
edges, here 29 axes per prism, most shared by every prism of the grid.

The deepest points: a face's axis meets a vertex of the other body (unique in general), an
edge pair's axis the two edges' nearest points. Where the other body's feature is an edge
or a face lying parallel (a box face flat on a level cell), EPA's point is some point of the
overlap that depends on its polytope; here it is the point of the box's feature nearest the
prism's centroid (or the mean of the prism's parallel vertices), a point of that overlap.

Arrays, not the chain's scalar tuples: one instance's block of prisms is a leading axis that
XLA vectorises. Each box pair has its own block (`chain_model.BoxBlock`), fixed at trace time from the
box's bounding radius; of its prisms' contacts the deepest `keep` become constraint rows (C keeps up to 50).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from hopper_mjx.engine.chain.hfield import PrismContact, TerrainParams, block_start
from hopper_mjx.engine.chain.model import BoxBlock, HeightGrid

PARALLEL = 1e-6  # |cos| below which a box axis counts as lying in a face (its feature is an edge or a face)


def _prisms(t: HeightGrid, block: tuple[int, int], terrain: TerrainParams, row, col, dtype):
    """The (rows, cols) block's prisms' top triangles (P, 3, 3), in C's order: by row, by column, lower
    triangle first."""
    rows, cols = block
    block = jax.lax.dynamic_slice(terrain.heights, (row, col), (rows + 1, cols + 1))
    x = t.origin[0] - t.hx + t.dx * (col.astype(dtype) + jnp.arange(cols + 1, dtype=dtype))
    y = t.origin[1] - t.hy + t.dy * (row.astype(dtype) + jnp.arange(rows + 1, dtype=dtype))
    vert = jnp.stack(jnp.broadcast_arrays(x[None, :], y[:, None], block), axis=-1)  # (rows+1, cols+1, 3)
    a, b, c, d = vert[:-1, :-1], vert[:-1, 1:], vert[1:, :-1], vert[1:, 1:]
    lower = jnp.stack([a, c, d], axis=-2)
    upper = jnp.stack([a, d, b], axis=-2)
    return jnp.stack([lower, upper], axis=2).reshape(rows * cols * 2, 3, 3)


def _dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _cross(u, v):
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def _add(u, v, scale=1.0):
    return tuple(a + scale * b for a, b in zip(u, v))


def _pick(index, options):
    """options[index] per prism, for a short Python list of options (vectors of (P,) components)."""
    out = options[0]
    for k, option in enumerate(options[1:], 1):
        out = tuple(jnp.where(index == k, o, x) for o, x in zip(option, out))
    return out


def _closest_on_lines(p, u, q, v):
    """The points of lines p + s u and q + t v nearest each other (not parallel)."""
    w = _add(p, q, -1.0)
    a, b, c, d, e = _dot(u, u), _dot(u, v), _dot(v, v), _dot(u, w), _dot(v, w)
    den = a * c - b * b
    den = jnp.where(den > 0, den, 1.0)
    s, t = (b * e - c * d) / den, (a * e - b * d) / den
    return _add(p, u, s), _add(q, v, t)


def _contact_point(c, box, half, v, w, n, d, best):
    """The middle of the two deepest points of the box and each prism, given the axis `best` (in `_box_prism`'s
    order) of least overlap `d` along `n`: a face meets the other body's deepest vertex (or, lying parallel, the
    middle of its deepest feature), an edge pair the two edges' nearest points."""
    dtype = d.dtype
    P = d.shape[0]
    # The box's deepest feature along -n: each axis at its far side, or (lying parallel) at the prism's
    # centroid, clipped to the box.
    centroid = tuple((v[0][k] + v[1][k] + v[2][k] + w[0][k] + w[1][k] + w[2][k]) / 6 for k in range(3))
    offset = _add(centroid, c, -1.0)
    local = []
    for i in range(3):
        cos = _dot(n, box[i])
        local.append(jnp.where(jnp.abs(cos) > PARALLEL, -jnp.sign(cos) * half[i],
                               jnp.clip(_dot(offset, box[i]), -half[i], half[i])))
    box_point = c
    for i in range(3):
        box_point = _add(box_point, box[i], local[i])
    on_box_face = _add(box_point, n, 0.5 * d)
    # The prism's deepest feature along +n: the mean of its vertices at the top of the projection.
    pv = [_dot(p, n) for p in v + w]
    highest = pv[0]
    for x in pv[1:]:
        highest = jnp.maximum(highest, x)
    tol = PARALLEL * (1.0 + jnp.abs(highest))
    level = [(x >= highest - tol).astype(dtype) for x in pv]
    count = sum(level)
    prism_point = tuple(sum(lv * p[k] for lv, p in zip(level, v + w)) / count for k in range(3))
    on_prism_face = _add(prism_point, n, -0.5 * d)
    # An edge pair's axis: the box edge along box[i] through the box's feature, and the prism's edge.
    kind, shared_pair = best - 19, (best >= 7) & (best < 19)
    pair_i = jnp.where(shared_pair, (best - 7) // 4, jnp.where(kind >= 1, (kind - 1) // 3, 0))
    box_dir = _pick(pair_i, box)
    box_edge_point = c
    for i in range(3):
        box_edge_point = _add(box_edge_point, box[i], jnp.where(pair_i == i, 0.0, local[i]))
    # The prism's edge: shared axes pair the box with the bottom edges (x, y, diagonal) or the vertical ones,
    # the prism's own with its top edges; its edge of that family highest along n.
    fam = jnp.where(shared_pair, (best - 7) % 4, 4 + (kind - 1) % 3)  # 0-2 bottom, 3 vertical, 4-6 top edge 0-2
    # Bottom edge j runs under top edge j: which j runs along x, y, the diagonal in the lower / upper triangle.
    lower = (jnp.arange(P) % 2) == 0
    bottom_edge = jnp.where(lower, jnp.array([1, 0, 2])[jnp.clip(fam, 0, 2)], jnp.array([2, 1, 0])[jnp.clip(fam, 0, 2)])
    horizontal = [v[j][0] * n[0] + v[j][1] * n[1] for j in range(3)]
    vertical = jnp.where((horizontal[1] > horizontal[0]) & (horizontal[1] >= horizontal[2]), 1,
                         jnp.where(horizontal[2] > horizontal[0], 2, 0))
    edge_j = jnp.where(fam <= 2, bottom_edge, jnp.where(fam == 3, vertical, fam - 4))
    nxt = [v[1], v[2], v[0]]
    nxt_w = [w[1], w[2], w[0]]
    start = _pick(jnp.where(fam <= 3, 3 + edge_j, edge_j), v + w)
    end = _pick(jnp.where(fam <= 2, 3 + edge_j, jnp.where(fam == 3, edge_j + 6, edge_j)), nxt + nxt_w + v)
    on_box_edge, on_prism_edge = _closest_on_lines(box_edge_point, box_dir, start, _add(end, start, -1.0))
    edge_pair = shared_pair | (best >= 20)
    prism_face = (best >= 3) & (best < 7) | (best == 19)
    pos = tuple(jnp.where(edge_pair, 0.5 * (a + b), jnp.where(prism_face, f, g))
                for a, b, f, g in zip(on_box_edge, on_prism_edge, on_box_face, on_prism_face))
    return pos


def _box_prism(t: HeightGrid, centre, axes, half, tops, bottom):
    """Per prism: (penetrates, depth, normal prism -> box, contact point), all (P, ...). Vectors are
    tuples of (P,) or (P, axes) components, so that the prisms (not x, y, z) are the arrays' minor axis."""
    dtype = tops.dtype
    P = tops.shape[0]
    v = [tuple(tops[:, j, k] for k in range(3)) for j in range(3)]  # the top triangle
    w = [(x, y, jnp.broadcast_to(bottom, x.shape)) for x, y, _ in v]  # the bottom one
    box = [tuple(axes[i, k] for k in range(3)) for i in range(3)]
    c = tuple(centre[k] for k in range(3))
    edges = [_add(v[(j + 1) % 3], v[j], -1.0) for j in range(3)]  # top edges v0v1, v1v2, v2v0
    top_normal = _cross(edges[0], edges[1])
    top_normal = tuple(x * jnp.where(top_normal[2] < 0, -1.0, 1.0) for x in top_normal)
    # Every triangle of a regular grid has its edges along x, y and the diagonal: the walls' directions.
    flat = [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (t.dx, t.dy, 0.0)]
    z = (0.0, 0.0, 1.0)
    walls = [(d[1], -d[0], 0.0) for d in flat]
    cand = ([*box, z, *walls] + [_cross(a, d) for a in box for d in (*flat, z)]
            + [top_normal] + [_cross(a, e) for a in box for e in edges])  # 29 axes, in `kind`'s order below
    ux, uy, uz = (jnp.stack([jnp.broadcast_to(jnp.asarray(a[k], dtype), (P,)) for a in cand], 1) for k in range(3))
    norm = jnp.sqrt(ux * ux + uy * uy + uz * uz)
    usable = norm > PARALLEL * jnp.maximum(1.0, jnp.max(norm, axis=1, keepdims=True))
    inv = 1 / jnp.where(norm > 0, norm, 1.0)
    u = (ux * inv, uy * inv, uz * inv)
    proj = [_dot(tuple(x[:, None] for x in p), u) for p in v + w]
    p_max, p_min = proj[0], proj[0]
    for x in proj[1:]:
        p_max, p_min = jnp.maximum(p_max, x), jnp.minimum(p_min, x)
    reach = _dot(c, u)
    radius = sum(half[i] * jnp.abs(_dot(box[i], u)) for i in range(3))
    up, down = p_max - (reach - radius), (reach + radius) - p_min  # overlap if the box leaves along +u / -u
    depth = jnp.where(usable, jnp.minimum(up, down), jnp.inf)
    best = jnp.argmin(depth, axis=1)
    take = lambda x: jnp.take_along_axis(x, best[:, None], 1)[:, 0]
    d = take(depth)
    sign = jnp.where(take(up) <= take(down), 1.0, -1.0)
    n = tuple(sign * take(x) for x in u)

    pos = _contact_point(c, box, half, v, w, n, d, best)
    # C skips a prism whose top lies wholly below the box's lowest point.
    lowest = c[2] - sum(half[i] * jnp.abs(box[i][2]) for i in range(3))
    reaches = (v[0][2] >= lowest) | (v[1][2] >= lowest) | (v[2][2] >= lowest)
    return reaches & (d > 0), d, jnp.stack(n, -1), jnp.stack(pos, -1)


def _candidates(t: HeightGrid, box: BoxBlock, terrain: TerrainParams, row, col, centre, axes, half):
    """The block's `box.candidates` prisms most likely to hold a contact, and whether each may: the least overlap of
    the box and the prism along z and the box's three axes, an upper bound of the penetration (a prism
    separated along one of them holds none). The block's 2 x rows x cols prisms get this cheap test, only
    these few the full one (separating axes over 29 directions)."""
    rows, cols = box.block
    dtype = centre.dtype
    block = jax.lax.dynamic_slice(terrain.heights, (row, col), (rows + 1, cols + 1))
    x = t.origin[0] - t.hx + t.dx * (col.astype(dtype) + jnp.arange(cols + 1, dtype=dtype))
    y = t.origin[1] - t.hy + t.dy * (row.astype(dtype) + jnp.arange(rows + 1, dtype=dtype))
    grid = jnp.broadcast_arrays(x[None, :], y[:, None], block)

    def corner(dr, dc):  # per cell, one corner's (x, y, z), each (rows * cols,)
        return tuple(g[dr:dr + rows, dc:dc + cols].reshape(-1) for g in grid)

    a, b, c, d = corner(0, 0), corner(0, 1), corner(1, 0), corner(1, 1)
    pair = lambda lower, upper: tuple(jnp.stack([p, q], 1).reshape(-1) for p, q in zip(lower, upper))
    v0, v1, v2 = pair(a, a), pair(c, d), pair(d, b)  # the triangles (a, c, d) and (a, d, b), in `_prisms`' order
    lowest = centre[2] - jnp.sum(half * jnp.abs(axes[:, 2]))
    score = jnp.maximum(jnp.maximum(v0[2], v1[2]), v2[2]) - lowest
    for i in range(3):
        n = axes[i]
        top = [v[0] * n[0] + v[1] * n[1] + v[2] * n[2] for v in (v0, v1, v2)]
        low = [v[0] * n[0] + v[1] * n[1] + terrain.bottom * n[2] for v in (v0, v1, v2)]
        reach = jnp.dot(centre, n)
        p_max = jnp.maximum(jnp.maximum(jnp.maximum(top[0], top[1]), jnp.maximum(top[2], low[0])),
                            jnp.maximum(low[1], low[2]))
        p_min = jnp.minimum(jnp.minimum(jnp.minimum(top[0], top[1]), jnp.minimum(top[2], low[0])),
                            jnp.minimum(low[1], low[2]))
        score = jnp.minimum(score, jnp.minimum(p_max - (reach - half[i]), (reach + half[i]) - p_min))
    best, idx = jax.lax.top_k(score, box.candidates)
    tops = jnp.stack([jnp.stack(v, -1) for v in (v0, v1, v2)], 1)  # (P, 3, 3)
    return tops[idx], best > 0


def box_contacts(t: HeightGrid, box: BoxBlock, terrain: TerrainParams, centre, rot, half, radius) -> PrismContact:
    """The deepest `box.keep` of the box's prism contacts (absent slots where fewer), deepest first, as (keep,)
    arrays. `centre` (3,) world, `rot` (3, 3) the box's axes as columns, `half` its half
    sizes, `radius` its bounding radius (a run-time value: the boxes share this code, each on the largest block,
    `chain_constraint._box_contacts`)."""
    keep = box.keep
    centre, rot = jnp.asarray(centre), jnp.asarray(rot)
    dtype = centre.dtype
    half = jnp.asarray(half, dtype)
    axes = rot.T
    row, col = block_start(t, centre, radius, box.block)
    tops, may = _candidates(t, box, terrain, row, col, centre, axes, half)
    exists, depth, normal, pos = _box_prism(t, centre, axes, half, tops, jnp.asarray(terrain.bottom, dtype))
    score = jnp.where(exists & may, depth, -jnp.inf)
    top, idx = jax.lax.top_k(score, keep)
    found = jnp.isfinite(top)
    up = jnp.array([0.0, 0.0, 1.0], dtype)
    pos, normal = jnp.where(found[:, None], pos[idx], 0.0), jnp.where(found[:, None], normal[idx], up)
    return PrismContact(found, jnp.where(found, -top, 0.0), tuple(pos[:, k] for k in range(3)),
                        tuple(normal[:, k] for k in range(3)))


def box_near(t: HeightGrid, box: BoxBlock, terrain: TerrainParams, centre, rot, half):
    """() bool: the box's lowest point is within reach of the highest vertex of the cells under its
    horizontal bounding box (else it has no contact, and its prisms need not be collided). Those vertices
    lie within a cell of that bounding box; a leg link's block is mostly ground away from it."""
    centre, rot = jnp.asarray(centre), jnp.asarray(rot)
    half = jnp.asarray(half, centre.dtype)
    dtype = centre.dtype
    row, col = block_start(t, centre, box.radius, box.block)
    rows, cols = box.block
    block = jax.lax.dynamic_slice(terrain.heights, (row, col), (rows + 1, cols + 1))
    x = t.origin[0] - t.hx + t.dx * (col.astype(dtype) + jnp.arange(cols + 1, dtype=dtype))
    y = t.origin[1] - t.hy + t.dy * (row.astype(dtype) + jnp.arange(rows + 1, dtype=dtype))
    reach = jnp.abs(rot) @ half  # the box's half extents along x, y, z
    under = (jnp.abs(y - centre[1])[:, None] <= reach[1] + t.dy) & (jnp.abs(x - centre[0])[None, :] <= reach[0] + t.dx)
    return centre[2] - reach[2] <= jnp.max(jnp.where(under, block, -jnp.inf))
