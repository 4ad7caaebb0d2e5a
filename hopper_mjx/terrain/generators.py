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
