"""`--terrain SPEC`: a generator's name and its keys, `name:key=value,...`, parsed and checked whole
before anything is built (NumPy only: no JAX, no MuJoCo).

    rough:amp=0.03,wavelength=0.4,seed=1
    rough:amp=0.03,seed=each          # each instance its own draw (a fixed seed: every instance the same ground)
    obstacle:height=0.15,x=0.6
    heightmap:ground.png,size=4x4,height=0.3

Every generator but `flat` and `heightmap` also takes `size=LxW` (full extents of the grid, m; one
number for a square) and `cell` (the grid's spacing, m). A `heightmap` takes its grid from the image.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from hopper_mjx import registry
from hopper_mjx.terrain import generators
from hopper_mjx.terrain.hfield import Terrain, vertices

DEFAULT_SIZE = (4.0, 4.0)  # m, full extents: a hopping robot stays on it for seconds (no contact off the grid)
DEFAULT_CELL = 0.04  # m: a fifth of the foot's approach in a hop, and ~100 x 100 vertices on 4 m
MAX_VERTICES = 4096 * 4096  # per grid: 128 MiB of float64 heights; a larger grid is not a terrain for a monoped
MAX_SEED = 2**32 - 1
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class Key(NamedTuple):
    name: str  # as the user types it
    default: float
    kind: str  # "length" (> 0), "height" (>= 0), "position" (any, m along +x), "count" (integer >= 1), "seed"
    arg: str = ""  # the generator's keyword, when it differs from `name`


GRID_KEYS = (Key("size", DEFAULT_SIZE[0], "length"), Key("cell", DEFAULT_CELL, "length"))
KEYS = {
    "flat": (),
    "rough": (Key("amp", 0.03, "height"), Key("wavelength", 0.4, "length"), Key("seed", 0, "seed")),
    "steps": (Key("height", 0.05, "height"), Key("depth", 0.5, "length"), Key("x", 0.5, "position", "x0")),
    "stairs": (Key("height", 0.05, "height"), Key("depth", 0.3, "length"), Key("n", 4, "count"),
               Key("x", 0.5, "position", "x0")),
    "gaps": (Key("width", 0.1, "length"), Key("spacing", 0.5, "length"), Key("depth", 0.2, "length"),
             Key("x", 0.5, "position", "x0")),
    "obstacle": (Key("height", 0.15, "height"), Key("x", 0.6, "position", "x0"), Key("length", 0.1, "length")),
    "crater": (Key("radius", 0.5, "length"), Key("depth", 0.1, "height"), Key("rim", 0.03, "height"),
               Key("x", 0.0, "position", "x0")),
    # The training course: its size is its tiles' (`course_size`), not a key.
    "course": (Key("levels", 5, "count"), Key("tile", 5.0, "length"), Key("amp", 0.04, "height"),
               Key("step", 0.08, "height"), Key("gap", 0.3, "length"), Key("block", 0.15, "height"),
               Key("seed", 0, "seed")),
    "heightmap": (Key("size", DEFAULT_SIZE[0], "length"), Key("height", 0.3, "height")),
}
assert list(KEYS) == list(registry.TERRAINS)  # one list of names


class TerrainError(ValueError):
    """A --terrain spec that cannot describe a terrain; the message is one line."""


@dataclass(frozen=True)
class Ground:
    """A parsed terrain spec: the generator, every key's value (defaults filled in), the heightmap's PNG."""

    name: str = "flat"
    values: tuple[tuple[str, float], ...] = ()
    size: tuple[float, float] = DEFAULT_SIZE  # full extents, m
    cell: float = DEFAULT_CELL
    path: str | None = None
    each: bool = False  # seed=each: every instance draws its own ground (`instance`); the model holds instance 0's

    def __str__(self) -> str:
        items = [self.path] if self.path else []
        items += [f"{k}=each" if k == "seed" and self.each else f"{k}={v:g}" for k, v in self.values]
        if self.name not in ("flat", "course"):  # a course's size is its tiles'
            items.append(f"size={self.size[0]:g}x{self.size[1]:g}")
        if self.name not in ("flat", "heightmap"):
            items.append(f"cell={self.cell:g}")
        return self.name + (":" + ",".join(items) if items else "")

    @property
    def is_flat(self) -> bool:
        return self.name == "flat"

    @property
    def shape(self) -> tuple[int, int]:
        """(nrow, ncol) of the grid; (0, 0) for the flat plane."""
        if self.is_flat:
            return (0, 0)
        if self.path:
            width, height = png_header(self.path)[:2]
            return (height, width)
        return (round(self.size[1] / self.cell) + 1, round(self.size[0] / self.cell) + 1)

    def instance(self, seed: int, index: int) -> Ground:
        """The ground of instance `index` of a batch (or replicate of a sweep) with `seed`: its own draw under
        seed=each (a seed from both, the same at every grid point), otherwise this very ground."""
        if not self.each:
            return self
        drawn = int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1)[0])
        return replace(self, values=tuple((k, drawn if k == "seed" else v) for k, v in self.values), each=False)

    def grids(self, seed: int, indices) -> np.ndarray | None:
        """(len(indices), nrow, ncol) m: the instances' own heights under seed=each; None otherwise (every
        instance on the model's ground)."""
        if not self.each:
            return None
        return np.stack([self.instance(seed, i).terrain().heights for i in indices])

    def start_height(self, reach: float = 0.1) -> float:
        """The highest vertex within `reach` m (in x and y; at least the cell around it) of the origin, where
        every instance starts."""
        if self.each:  # any draw may peak near the start: the worst case, rough ground's peak |height|
            return float(dict(self.values)["amp"])
        t = self.terrain()
        if t is None:
            return 0.0
        xs, ys = t.axes()
        near_x, near_y = np.abs(xs) <= max(reach, xs[1] - xs[0]), np.abs(ys) <= max(reach, ys[1] - ys[0])
        return float(t.heights[near_y[:, None] & near_x[None, :]].max())

    def obstacles(self) -> np.ndarray:
        """(B, 3) rows (x start, x end, height) m: the bands across the ground a robot hopping along +x must
        get over: a step's platform, a block, a flight of stairs (its top), each trench on the grid (its
        depth negative). Empty for ground without such bands (flat, rough, crater, heightmap)."""
        v = dict(self.values)
        if self.name == "steps":
            rows = [(v["x"], v["x"] + v["depth"], v["height"])]
        elif self.name == "obstacle":
            rows = [(v["x"], v["x"] + v["length"], v["height"])]
        elif self.name == "stairs":
            rows = [(v["x"], v["x"] + (2 * v["n"] + 1) * v["depth"], v["n"] * v["height"])]
        elif self.name == "gaps":
            starts = np.arange(v["x"], self.size[0] / 2, v["spacing"])
            rows = [(x, x + v["width"], -v["depth"]) for x in starts]
        else:
            rows = []
        return np.array(rows, dtype=float).reshape(-1, 3)

    def terrain(self) -> Terrain | None:
        """The height grid (None for flat: the ground stays MuJoCo's infinite plane); under seed=each, instance
        0's (the compiled model's)."""
        if self.is_flat:
            return None
        if self.each:
            return self.instance(0, 0).terrain()
        half = (self.size[0] / 2, self.size[1] / 2)
        values = dict(self.values)
        if self.path:
            return Terrain(generators.heightmap(read_png(self.path), height=values["height"]), half)
        x, y = vertices(half, self.shape)
        args = {k.arg or k.name: (int(values[k.name]) if k.kind in ("count", "seed") else values[k.name])
                for k in KEYS[self.name]}
        return Terrain(getattr(generators, self.name)(x, y, **args), half)


FLAT = Ground()
MIN_TILE = 2.0  # m: the smallest course tile


def grid_keys(name: str) -> tuple[str, ...]:
    """The grid keys a generator takes: a course's size follows from its tiles."""
    return ("cell",) if name == "course" else tuple(k.name for k in GRID_KEYS)


def _check_on_grid(ground: Ground) -> None:
    """A feature placed at x (a step, stairs, a block, trenches, a crater) lies at least partly on the grid, which
    spans -size/2..size/2 along x: one wholly beyond it left the ground flat under a name that says otherwise."""
    v = dict(ground.values)
    if "x" not in v or ground.name == "course":
        return
    half = ground.size[0] / 2
    if ground.name == "crater":
        spans = [(v["x"] - v["radius"], v["x"] + v["radius"])]
    else:
        spans = [(start, end) for start, end, _ in ground.obstacles()]
    if not any(start < half and end > -half for start, end in spans):
        raise TerrainError(f"{ground.name}: x={v['x']:g} m puts it beyond the ground, which spans {-half:g} to "
                           f"{half:g} m along x (size={ground.size[0]:g}x{ground.size[1]:g}); give an x within it "
                           "or a larger size")


def _check_course(values: dict, cell: float) -> None:
    """A course whose every kind of ground is there at every level above the flat level 0: the tile holds its pad, a
    ring and its edge; the widest trench fits between the pad's ramp and the edge and stays apart from the next; the
    grid resolves the rough ground's waves."""
    g = generators
    tile, gap = values["tile"], values["gap"]
    if tile < MIN_TILE:
        raise TerrainError(f"course: tile={tile:g} m is too small; a tile needs at least {MIN_TILE:g} m (its pad, "
                           "a ring of ground and its edge)")
    room = tile / 2 - g.COURSE_PAD - g.COURSE_RAMP - g.COURSE_EDGE  # where a tile's trenches lie
    if gap >= min(room, g.COURSE_GAP_SPACING):
        raise TerrainError(f"course: gap={gap:g} m must be less than {min(room, g.COURSE_GAP_SPACING):g} m, the "
                           f"trenches' spacing or the room for one on a {tile:g} m tile (without it the gaps tiles "
                           "would be flat or one pit); lower gap or raise tile")
    if cell > g.COURSE_WAVELENGTH / 2:
        raise TerrainError(f"course: cell={cell:g} m cannot hold its rough ground's {g.COURSE_WAVELENGTH:g} m "
                           f"waves; at most {g.COURSE_WAVELENGTH / 2:g} m")


def course_size(values: dict) -> tuple[float, float]:
    """m, full extents of a course: a column of tiles per kind of ground, a row per level, and the border a tile wide
    on every side."""
    return ((len(generators.COURSE_KINDS) + 2) * values["tile"], (values["levels"] + 2) * values["tile"])


def tile_centres(ground: Ground) -> np.ndarray:
    """(levels, kinds, 2) m: the world (x, y) of each course tile's centre, where its episodes start."""
    v = dict(ground.values)
    levels, kinds, tile = int(v["levels"]), len(generators.COURSE_KINDS), v["tile"]
    x = (np.arange(kinds) + 0.5) * tile - kinds * tile / 2
    y = (np.arange(levels) + 0.5) * tile - levels * tile / 2
    return np.stack(np.meshgrid(x, y), axis=-1)


def _number(key: Key, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise TerrainError(f"{key.name}={text} is not a number") from None
    if key.kind in ("count", "seed"):
        if not (math.isfinite(value) and value == int(value)):
            raise TerrainError(f"{key.name}={text} must be a whole number")
        top = MAX_SEED if key.kind == "seed" else 10_000
        low = 0 if key.kind == "seed" else 1
        if not low <= value <= top:
            raise TerrainError(f"{key.name}={text} must be in {low}..{top}")
        return int(value)
    if not math.isfinite(value):
        raise TerrainError(f"{key.name}={text} must be finite")
    if key.kind == "length" and value <= 0:
        raise TerrainError(f"{key.name}={text} must be > 0 m")
    if key.kind == "height" and value < 0:
        raise TerrainError(f"{key.name}={text} must be >= 0 m")
    return value


def _size(text: str) -> tuple[float, float]:
    parts = text.lower().split("x")
    if len(parts) not in (1, 2):
        raise TerrainError(f"size={text} must be LxW or one length, in m")
    lengths = tuple(_number(GRID_KEYS[0], p) for p in parts)
    return lengths * 2 if len(lengths) == 1 else lengths


def parse(text: str) -> Ground:
    """The Ground a spec describes; TerrainError (one line) for a mistake. A heightmap's PNG is opened
    and its header read (not its pixels)."""
    name, _, rest = text.strip().partition(":")
    try:
        registry.check("terrain", registry.TERRAINS, name)
    except ValueError as err:
        raise TerrainError(str(err)) from None
    keys = {k.name: k for k in KEYS[name]}
    grid = {} if name in ("flat", "heightmap") else {k.name: k for k in GRID_KEYS if k.name in grid_keys(name)}
    known = [*keys, *(k for k in grid if k not in keys)]
    values, size, cell, path, seen, each = {}, DEFAULT_SIZE, DEFAULT_CELL, None, set(), False
    for item in filter(None, (i.strip() for i in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq and name == "heightmap" and path is None:
            path = check_png(item)
            continue
        if not eq:
            raise TerrainError(f"{item!r} is not key=value" + (f"; {name} takes {', '.join(known)}" if known else ""))
        if key not in keys and key not in grid:
            raise TerrainError(f"{name} has no key {key!r}" + (f"; it takes {', '.join(known)}" if known
                                                               else "; it takes none"))
        if key in seen:
            raise TerrainError(f"{key} is given twice")
        seen.add(key)
        if key == "size":
            size = _size(value.strip())
        elif key == "cell":
            cell = _number(grid["cell"], value.strip())
        elif key == "seed" and value.strip() == "each":
            values[key], each = 0, True
        else:
            values[key] = _number(keys[key], value.strip())
    if name == "heightmap" and path is None:
        raise TerrainError("heightmap needs a PNG file: heightmap:FILE.png,size=4x4,height=0.3")
    filled = tuple((k.name, values.get(k.name, k.default)) for k in KEYS[name] if k.name != "size")
    if name == "course":
        size = course_size(dict(filled))
        _check_course(dict(filled), cell)
    ground = Ground(name, filled, size, cell, path, each)
    if name not in ("flat", "heightmap"):
        for extent in size:
            if cell > extent:
                raise TerrainError(f"cell={cell:g} m is larger than the grid's extent {extent:g} m")
    if name == "rough" and dict(filled)["wavelength"] < 2 * cell:  # (1e-300 made every height NaN)
        raise TerrainError(f"rough: wavelength={dict(filled)['wavelength']:g} m is shorter than two cells "
                           f"({2 * cell:g} m): the grid cannot hold such waves; raise wavelength or lower cell")
    if name == "gaps" and dict(filled)["width"] >= dict(filled)["spacing"]:
        raise TerrainError(f"gaps: width={dict(filled)['width']:g} must be less than spacing="
                           f"{dict(filled)['spacing']:g}")
    _check_on_grid(ground)
    # Counted in floats first: size=1e308 would overflow the integer rounding of `shape`.
    nrow, ncol = png_header(path)[1::-1] if path else (size[1] / cell + 1, size[0] / cell + 1)
    if nrow * ncol > MAX_VERTICES:
        from hopper_mjx.shell.budget import size as in_bytes

        def count(v: float, sep: str = ",") -> str:
            return f"{v:{sep}.0f}" if v < 1e15 else f"{v:.3g}" if math.isfinite(v) else ">1e308"

        raise TerrainError(f"a {count(nrow, '')} x {count(ncol, '')} grid has {count(nrow * ncol)} vertices, about "
                           f"{in_bytes(8.0 * nrow * ncol) if nrow * ncol < 1e30 else '>1e18 TiB'} of heights; "
                           f"at most {MAX_VERTICES:,} ({in_bytes(8 * MAX_VERTICES)}): a larger cell or a smaller image")
    nrow, ncol = ground.shape
    if path and (nrow < 2 or ncol < 2):
        raise TerrainError(f"{path} is {ncol} x {nrow} pixels; a height field needs at least 2 x 2")
    return ground


def png_header(path: str) -> tuple[int, int, int, int]:
    """(width, height, bit depth, colour type) from a PNG's IHDR; TerrainError if it is not a PNG."""
    try:
        with open(path, "rb") as f:
            head = f.read(33)
    except OSError as err:
        raise TerrainError(f"cannot read the heightmap {path}: {err.strerror}") from None
    if head[:8] != PNG_SIGNATURE or head[12:16] != b"IHDR" or len(head) < 33:
        raise TerrainError(f"{path} is not a PNG image")
    return struct.unpack(">IIBB", head[16:26])


def check_png(text: str) -> str:
    path = Path(text)
    if not path.is_file():
        raise TerrainError(f"heightmap {text}: {'is a folder, not a file' if path.is_dir() else 'no such file'}")
    width, height, depth, colour = png_header(text)
    if depth not in (8, 16) or colour not in (0, 2, 4, 6):  # grey, RGB, grey + alpha, RGBA; no palettes
        raise TerrainError(f"{text}: a heightmap must be an 8- or 16-bit greyscale (or RGB) PNG")
    return text


def read_png(path: str) -> np.ndarray:
    """A PNG's pixels as grey values in [0, 1] (rows top to bottom); colour is averaged. TerrainError if
    the file is damaged."""
    import imageio.v3 as iio

    try:
        image = np.asarray(iio.imread(path, extension=".png"))
    except Exception as err:  # imageio and Pillow raise many kinds for a damaged file
        raise TerrainError(f"{path} is not a readable PNG image: {str(err).splitlines()[0] if str(err) else err}")\
            from None
    top = 65535.0 if image.dtype == np.uint16 else 255.0
    if image.ndim == 3:
        image = image[..., : 3 if image.shape[-1] >= 3 else 1].mean(-1)
    return image.astype(np.float64) / top


def terrain_help(default: str = "flat") -> str:
    """The --terrain option's help text, from the registry; `default`: what the tool does without it."""
    return (f"the ground: NAME[:KEY=VALUE,...], NAME one of {registry.listed(registry.TERRAINS)}; e.g. "
            "rough:amp=0.03,wavelength=0.4,seed=1, obstacle:height=0.15,x=0.6, heightmap:ground.png,size=4x4,"
            f"height=0.3 (keys: docs/terrain.md; default {default})")


def refuse_each(ground: Ground, tool: str) -> None:
    """For a tool that puts every instance on the model's one ground: seed=each refused in one line."""
    if ground.each:
        raise ValueError(f"--terrain {ground}: {tool} puts every instance on one ground; give a fixed seed")


def check_terrain(text: str, n: int = 1) -> Ground:
    """--terrain parsed, and its grid checked to fit in memory for `n` instances (each may hold its own copy
    of the heights once terrain varies per instance); ValueError '--terrain: ...' in one line."""
    from hopper_mjx.shell import budget

    try:
        ground = parse(text)
    except TerrainError as err:
        raise ValueError(f"--terrain: {err}") from None
    nrow, ncol = ground.shape
    if not ground.is_flat:  # the plane holds nothing per instance: the batch's own size is checked where it is laid out
        budget.check_memory(f"--terrain {text}" + (", --num" if n > 1 else ""), n, held_floats=nrow * ncol)
    if ground.path:  # decoded now, once it is known to fit: a damaged image is refused before anything is built
        try:
            read_png(ground.path)
        except TerrainError as err:
            raise ValueError(f"--terrain: {err}") from None
    return ground
