"""Terrain height where the robot is, in JAX: the surface MuJoCo collides with, and the height scan.

MuJoCo splits each hfield cell into two triangles along the diagonal from vertex (r, c) to
(r + 1, c + 1) (engine_collision_convex.c, and MJX's `_hfield_collision`); `height_at` interpolates
on the same triangles, so that a scanned height is the height the foot lands on (bilinear
interpolation would disagree inside every cell that is not planar). The heights are a run-time
input (a traced array, one grid per instance if vmapped); the half-extents are static.
Off the grid, where MuJoCo has no ground, the grid's edge height is returned.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def _cell(heights: jnp.ndarray, size: tuple[float, float], x, y):
    """The cell under world (x, y): its four corner heights h<dc><dr>, the position (u, v) in it along
    +x and +y (0..1), and its extents (m) along x and y."""
    nrow, ncol = heights.shape
    fc = jnp.clip((x + size[0]) / (2 * size[0]) * (ncol - 1), 0.0, ncol - 1.0)
    fr = jnp.clip((y + size[1]) / (2 * size[1]) * (nrow - 1), 0.0, nrow - 1.0)
    c = jnp.clip(jnp.floor(fc), 0, ncol - 2).astype(jnp.int32)
    r = jnp.clip(jnp.floor(fr), 0, nrow - 2).astype(jnp.int32)
    corners = (heights[r, c], heights[r, c + 1], heights[r + 1, c], heights[r + 1, c + 1])  # h00 h10 h01 h11
    return corners, fc - c, fr - r, (2 * size[0] / (ncol - 1), 2 * size[1] / (nrow - 1))


def height_at(heights: jnp.ndarray, size: tuple[float, float], x, y):
    """Ground height (m) at world (x, y) (any matching shapes) on the grid `heights` (nrow, ncol) of
    half-extents `size`, on MuJoCo's triangles."""
    (h00, h10, h01, h11), u, v, _ = _cell(heights, size, x, y)
    upper = h00 + v * (h01 - h00) + u * (h11 - h01)  # triangle (0,0) (1,1) (0,1): v >= u
    lower = h00 + u * (h10 - h00) + v * (h11 - h10)  # triangle (0,0) (1,0) (1,1): u > v
    return jnp.where(v >= u, upper, lower)


def normal_at(heights: jnp.ndarray, size: tuple[float, float], x, y):
    """(..., 3) unit upward normal of MuJoCo's triangle under world (x, y): the normal of a contact on
    the triangle's face (on an edge or a vertex MuJoCo's contact normal may lean towards the foot's
    centre instead). Off the grid, the edge triangle's."""
    (h00, h10, h01, h11), u, v, (dx, dy) = _cell(heights, size, x, y)
    upper = v >= u
    slope_x = jnp.where(upper, h11 - h01, h10 - h00) / dx
    slope_y = jnp.where(upper, h01 - h00, h11 - h10) / dy
    n = jnp.stack([-slope_x, -slope_y, jnp.ones_like(slope_x)], -1)
    return n / jnp.linalg.norm(n, axis=-1, keepdims=True)


def check_grid(counts, spacing) -> None:
    """Raises ValueError unless `counts` are two whole numbers in 1..64 and `spacing` two finite lengths > 0 m."""
    if not (len(counts) == 2 and all(int(c) == c and 1 <= c <= 64 for c in counts)):
        raise ValueError(f"scan_counts must be two whole numbers in 1..64, got {tuple(counts)}")
    if not (len(spacing) == 2 and all(np.isfinite(s) and s > 0 for s in spacing)):
        raise ValueError(f"scan_spacing must be two finite lengths > 0 m, got {tuple(spacing)}")


def scan_points(counts: tuple[int, int] = (5, 5), spacing: tuple[float, float] = (0.1, 0.1)) -> np.ndarray:
    """(K, 2) points of a scan in the base's yaw frame: a grid of counts (along x ahead, along y left)
    at `spacing` m, centred under the base (legged_gym's measured_heights pattern). Counts may come as whole floats
    (a parsed option, a JSON file)."""
    counts = [int(c) for c in counts]
    xs = (np.arange(counts[0]) - (counts[0] - 1) / 2) * spacing[0]
    ys = (np.arange(counts[1]) - (counts[1] - 1) / 2) * spacing[1]
    return np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)


def yaw(quat) -> jnp.ndarray:
    """Heading (rad) of a [w, x, y, z] orientation: the rotation about world z of its x axis."""
    w, x, y, z = quat[..., 0], quat[..., 1], quat[..., 2], quat[..., 3]
    return jnp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def measured_heights(heights: jnp.ndarray, size: tuple[float, float], base_pos, base_quat, points) -> jnp.ndarray:
    """Ground heights (K,) (m, world z) under the scan `points` (K, 2) placed around the base at
    `base_pos` (3,) and turned with its yaw only (a tilted base scans the same ground)."""
    psi = yaw(base_quat)
    cos, sin = jnp.cos(psi), jnp.sin(psi)
    px, py = points[:, 0], points[:, 1]
    return height_at(heights, size, base_pos[0] + cos * px - sin * py, base_pos[1] + sin * px + cos * py)
