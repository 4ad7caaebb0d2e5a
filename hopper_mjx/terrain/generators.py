"""The terrain generators: each a pure function of the vertices' (x, y) and its parameters (and a seed),
returning heights in metres. Shapes lie ahead of the start along +x; the ground at the origin, where
every instance starts, is z = 0 unless the shape is centred there (a crater) or covers it (rough ground)."""

from __future__ import annotations

import numpy as np

ROUGH_WAVES = 24  # plane waves summed for rough ground: enough for no visible direction, few enough to be cheap


def flat(x, y):
    return np.zeros_like(x)


def rough(x, y, *, amp, wavelength, seed):
    """Smooth random ground: a sum of plane waves in random directions with wavelengths within 30 % of
    `wavelength` and random phases, made zero-mean and scaled to a peak |height| of `amp`."""
    rng = np.random.default_rng(int(seed))
    angle = rng.uniform(0.0, 2 * np.pi, ROUGH_WAVES)
    k = 2 * np.pi / (wavelength * rng.uniform(0.7, 1.3, ROUGH_WAVES))
    phase = rng.uniform(0.0, 2 * np.pi, ROUGH_WAVES)
    h = np.zeros_like(x)
    for kx, ky, p in zip(k * np.cos(angle), k * np.sin(angle), phase):  # one wave at a time: one grid of memory
        h += np.cos(kx * x + ky * y + p)
    h -= h.mean()
    peak = np.abs(h).max()
    return h * (amp / peak) if peak > 0 else h


def steps(x, y, *, height, depth, x0):
    """Up a step of `height` at x0 onto a platform `depth` long, and down again at x0 + depth."""
    return np.where((x >= x0) & (x < x0 + depth), height, 0.0)


def stairs(x, y, *, height, depth, n, x0):
    """`n` steps of `height` up, each tread `depth` long, from x0; a landing `depth` long; `n` steps down."""
    up = np.clip(np.floor((x - x0) / depth) + 1, 0, n)
    down = np.clip(np.floor((x - x0 - (n + 1) * depth) / depth) + 1, 0, n)
    return height * (up - down)


def gaps(x, y, *, width, spacing, depth, x0):
    """Trenches `width` wide and `depth` deep across the ground, one every `spacing` from x0 on."""
    inside = (x >= x0) & (np.mod(x - x0, spacing) < width)
    return np.where(inside, -depth, 0.0)


def obstacle(x, y, *, height, x0, length):
    """A block of `height` across the ground from x0, `length` long along +x."""
    return np.where((x >= x0) & (x < x0 + length), height, 0.0)


def crater(x, y, *, radius, depth, rim, x0):
    """A bowl of `radius` and `depth` centred at (x0, 0), its edge raised into a rim of `rim` that falls off
    outside over a quarter of the radius."""
    r = np.hypot(x - x0, y) / radius
    bowl = np.where(r < 1, -depth * (1 - r**2), 0.0)
    ring = rim * np.exp(-(((r - 1) / 0.25) ** 2))
    return bowl + ring


def heightmap(grey, *, height):
    """A greyscale image (rows top to bottom, values in [0, 1]) as heights: black 0, white `height`, its
    top row at +y (as Gazebo's <heightmap> and MuJoCo's PNG hfield lay it)."""
    return height * np.asarray(grey, dtype=np.float64)[::-1]


# The training course (`course`): a grid of square tiles, one column per kind of ground and one row per level of
# difficulty, as legged_gym's terrain curriculum lays its sub-terrains out. Every tile has a flat pad at its centre
# (where an episode starts) and its shape in square rings around it, so a robot meets it going any way. A flat
# border a tile wide surrounds the grid: a 10 s episode from an outer tile's pad at 0.5 m/s ends up to half a tile
# beyond the grid, and it should meet flat ground there, not the height field's edge (4 % of a trained policy's
# level-0 episodes walked off it before the border, 6 Dec 2026).
COURSE_KINDS = ("rough", "steps", "gaps", "blocks")  # the columns, west to east
COURSE_PAD = 0.4  # m: the half-width of the flat pad at a tile's centre
COURSE_RAMP = 0.3  # m over which rough ground rises from the pad (and from the edge) to its full amplitude
COURSE_WAVELENGTH = 0.4  # m: the rough tiles' waves
COURSE_STEP_DEPTH = 0.3  # m: the tread of the steps' rings
COURSE_GAP_SPACING = 0.8  # m between the gaps' trenches, edge to edge of their starts
COURSE_GAP_DEPTH = 0.2  # m
COURSE_EDGE = 0.1  # m of flat ground inside a tile's edge (steps end there too, at z = 0)
COURSE_BLOCKS = 24  # blocks scattered on a blocks tile
COURSE_BLOCK_SIDE = (0.2, 0.6)  # m: the range of a block's sides


def course_difficulty(level, levels):
    """The share of the hardest ground a level gets: level / (levels - 1), from flat at level 0 to the hardest at the
    top, as legged_gym's rows start at difficulty 0 (a one-level course is the hardest). Level 0 is flat so that a
    policy learns to hop at its commanded speed before it meets anything: with level 0 at a fifth of the hardest,
    its 6 cm trenches (the foot's width, under the scan's 0.1 m spacing) felled 63 % of a trained policy's episodes
    on the gaps tiles, and its curriculum never rose (docs/learning-notebook.md, 6 Dec 2026)."""
    return np.asarray(level) / (levels - 1) if levels > 1 else np.ones_like(np.asarray(level, float))


def course(x, y, *, levels, tile, amp, step, gap, block, seed):
    """The training course: `levels` rows of tiles `tile` m square (row 0 at -y), one column per `COURSE_KINDS`;
    the grid is centred on the origin, in a flat border a tile wide. A tile of level i has `course_difficulty` f of
    the hardest ground:
    rough ground of peak `amp`·f (`COURSE_WAVELENGTH`); rings of steps `step`·f high, up three treads and down again
    to the tile's edge; trenches `gap`·f wide and `COURSE_GAP_DEPTH` deep; blocks `block`·f high. Its centre is a
    flat pad at z = 0, and so is its edge, where it meets the next tile."""
    width, height = len(COURSE_KINDS) * tile, levels * tile
    col = np.clip(np.floor((x + width / 2) / tile), 0, len(COURSE_KINDS) - 1)
    row = np.clip(np.floor((y + height / 2) / tile), 0, levels - 1)
    u, v = x + width / 2 - (col + 0.5) * tile, y + height / 2 - (row + 0.5) * tile  # from the tile's centre
    out = np.maximum(np.abs(u), np.abs(v)) - COURSE_PAD  # m beyond the pad's edge, in square rings
    f = course_difficulty(row, levels)
    room = tile / 2 - COURSE_PAD  # m from the pad to the tile's edge
    rings = int(room // COURSE_STEP_DEPTH)
    tread = np.where(out >= 0, np.floor(out / COURSE_STEP_DEPTH) + 1, 0)
    steps_h = step * f * np.clip(np.minimum(tread, rings - tread), 0, None)
    start = np.maximum(out - COURSE_RAMP, 0.0)
    trench = (out >= COURSE_RAMP) & (np.mod(start, COURSE_GAP_SPACING) < gap * f) \
        & (out - np.mod(start, COURSE_GAP_SPACING) + gap * f < room - COURSE_EDGE)
    ramp = np.clip(np.minimum(out, room - COURSE_EDGE - out) / COURSE_RAMP, 0, 1)  # 0 on the pad and the edge
    ground = {"rough": amp * f * ramp * rough(x, y, amp=1.0, wavelength=COURSE_WAVELENGTH, seed=seed),
              "steps": steps_h, "gaps": np.where(trench, -COURSE_GAP_DEPTH, 0.0),
              "blocks": _course_blocks(u, v, row, levels, tile, block, seed)}
    tiles = np.select([col == i for i in range(len(COURSE_KINDS))], [ground[k] for k in COURSE_KINDS])
    return np.where((np.abs(x) < width / 2) & (np.abs(y) < height / 2), tiles, 0.0)  # the border


def _course_blocks(u, v, row, levels, tile, block, seed):
    """The blocks of every level's blocks tile (u, v from each tile's centre): `COURSE_BLOCKS` of them at a
    level's own draw, beyond the pad and within the tile's edge, `block`·f high."""
    h = np.zeros_like(u)
    for level in range(levels):
        rng = np.random.default_rng([int(seed), level])
        sides = rng.uniform(*COURSE_BLOCK_SIDE, (COURSE_BLOCKS, 2))
        reach = tile / 2 - COURSE_BLOCK_SIDE[1] / 2 - COURSE_EDGE
        centres = rng.uniform(-reach, reach, (COURSE_BLOCKS, 2))
        # Pushed out of the pad: a block's near side at least 0.2 m beyond the pad's edge.
        clear = COURSE_PAD + 0.2 + sides / 2
        inside = np.all(np.abs(centres) < clear, axis=1)
        centres[inside, 0] = np.sign(centres[inside, 0] + 1e-9) * clear[inside, 0]
        here = row == level
        for (cu, cv), (su, sv) in zip(centres, sides):
            on = here & (np.abs(u - cu) < su / 2) & (np.abs(v - cv) < sv / 2)
            h = np.where(on, block * course_difficulty(level, levels), h)
    return h
