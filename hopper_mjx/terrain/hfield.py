"""A terrain as a height grid, and the one mapping of that grid onto MuJoCo's height field.

The convention, shared by the generators, the loader, the engines and the height scan:
a `Terrain` is `heights` (nrow, ncol) in metres and half-extents `size` (hx, hy), centred
on the world origin, laid out as MuJoCo lays out an hfield: vertex (r, c) sits at
x = -hx + 2 hx c / (ncol - 1), y = -hy + 2 hy r / (nrow - 1) (rows along +y, columns along +x).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from hopper_mjx.shell.files import atomic_write, atomic_write_text

HFIELD = "terrain"  # the hfield asset's name in the compiled model
BASE_DEPTH = 0.1  # m of solid below the lowest vertex (MuJoCo's size[3]); contacts below it are missed
FLAT_SPAN = 1e-6  # m: MuJoCo refuses an hfield whose elevation range size[2] is 0; a level grid gets this


class Terrain(NamedTuple):
    heights: np.ndarray  # (nrow, ncol) float64, m
    size: tuple[float, float]  # (hx, hy) half-extents, m

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """(x of each column (ncol,), y of each row (nrow,)), m."""
        nrow, ncol = self.heights.shape
        return grid_line(self.size[0], ncol), grid_line(self.size[1], nrow)


def triangles(terrain: Terrain) -> np.ndarray:
    """(2 (nrow-1) (ncol-1) x 3, 3) m: the corners of MuJoCo's triangles, three rows a triangle, counter-
    clockwise seen from above; each cell split along its diagonal from vertex (r, c) to (r+1, c+1), as
    MuJoCo splits it (and `scan` reads it), so a drawing shows the ground the robots touch."""
    xs, ys = terrain.axes()
    x, y = np.meshgrid(xs, ys)
    points = np.stack([x, y, np.asarray(terrain.heights, dtype=np.float64)], axis=-1)
    a, b, c, d = points[:-1, :-1], points[:-1, 1:], points[1:, 1:], points[1:, :-1]  # (r,c) (r,c+1) (r+1,c+1) (r+1,c)
    return np.stack([np.stack([a, b, c], -2), np.stack([a, c, d], -2)], -3).reshape(-1, 3)


def grid_line(half: float, n: int) -> np.ndarray:
    """(n,) m: the coordinates of n grid lines from -half to half, to the nanometre. `linspace` leaves them a
    rounding off their decimal values (a 24 m ground's vertex at x = 0.6 m is 0.5999999999999996), and a feature's
    edge at such a value (a block from x = 0.6) then took the vertex on one ground size and not on another."""
    return np.round(np.linspace(-half, half, n), 9)


def vertices(size: tuple[float, float], shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of every vertex of a (nrow, ncol) grid of half-extents `size`, each (nrow, ncol)."""
    nrow, ncol = shape
    return np.meshgrid(grid_line(size[0], ncol), grid_line(size[1], nrow))


class HField(NamedTuple):
    """A terrain as MuJoCo's hfield takes it: the asset's fields and the geom's height."""

    nrow: int
    ncol: int
    size: tuple[float, float, float, float]  # (hx, hy, elevation range, base depth)
    data: np.ndarray  # (nrow * ncol,) row-major, normalised to [0, 1]
    z: float  # m: the geom's height, the grid's lowest vertex


def hfield(terrain: Terrain) -> HField:
    """MuJoCo's height of vertex (r, c) is z + data[r * ncol + c] * size[2]; this puts it at heights[r, c]."""
    h = np.asarray(terrain.heights, dtype=np.float64)
    low, span = float(h.min()), float(h.max() - h.min())
    data = (h - low) / span if span > 0 else np.zeros_like(h)
    nrow, ncol = h.shape
    return HField(nrow, ncol, (float(terrain.size[0]), float(terrain.size[1]), span if span > 0 else FLAT_SPAN,
                               BASE_DEPTH), data.ravel(), low)


def to_spec(spec, geom, terrain: Terrain) -> None:
    """Turns `geom` of the MjSpec `spec` into the terrain: an hfield geom over the asset `HFIELD`.
    Its contact pairs and name are kept."""
    import mujoco

    f = hfield(terrain)
    spec.add_hfield(name=HFIELD, nrow=f.nrow, ncol=f.ncol, size=list(f.size), userdata=f.data.tolist())
    geom.type = mujoco.mjtGeom.mjGEOM_HFIELD
    geom.hfieldname = HFIELD
    geom.pos = [0.0, 0.0, f.z]


def _floor(mj_model) -> tuple[int, int] | None:
    """(hfield id, its geom's id) of the compiled model's hfield `HFIELD`, or None without one."""
    import mujoco

    k = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_HFIELD, HFIELD)
    if k < 0:
        return None
    return k, int(np.flatnonzero((mj_model.geom_type == mujoco.mjtGeom.mjGEOM_HFIELD) & (mj_model.geom_dataid == k))[0])


def from_model(mj_model) -> Terrain | None:
    """The terrain of a compiled model's hfield `HFIELD` (None without one), heights as MuJoCo holds them:
    vertex height = the geom's z + data * elevation range. The one decoder of a model's ground."""
    found = _floor(mj_model)
    if found is None:
        return None
    k, geom = found
    nrow, ncol = int(mj_model.hfield_nrow[k]), int(mj_model.hfield_ncol[k])
    adr, size = int(mj_model.hfield_adr[k]), mj_model.hfield_size[k]
    data = np.asarray(mj_model.hfield_data[adr:adr + nrow * ncol], dtype=np.float64).reshape(nrow, ncol)
    return Terrain(mj_model.geom_pos[geom, 2] + data * size[2], (float(size[0]), float(size[1])))


def to_model_data(mj_model, heights):
    """`from_model`'s inverse on the compiled model's own grid: the hfield data (nrow * ncol,) that puts its
    vertices at `heights` (nrow, ncol) m, with the geom's z and the elevation range as compiled (static),
    whatever the data's range. NumPy or JAX arrays alike (an engine encodes traced per-instance heights)."""
    k, geom = _floor(mj_model)
    return ((heights - mj_model.geom_pos[geom, 2]) / mj_model.hfield_size[k, 2]).ravel()


def _exact(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def write_mjcf(spec, path) -> list[str]:
    """Writes `spec` as MJCF to `path`; an hfield's elevation goes beside it as MuJoCo's binary hfield file
    (int32 nrow, ncol, then float32 data), because the MJCF's decimal text would round it. Returns the
    paths written. `from_xml_path` of the file then holds exactly the compiled model's hfield_data."""
    import xml.etree.ElementTree as ET
    from pathlib import Path

    import mujoco

    path = Path(path)
    model = spec.compile()
    text = spec.to_xml()
    if model.nhfield == 0:  # nothing to move out: MuJoCo's own text as it is
        atomic_write_text(path, text)
        return [str(path)]
    root = ET.fromstring(text)
    written = []
    for element in root.iterfind("asset/hfield"):
        k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_HFIELD, element.get("name"))
        nrow, ncol, adr = int(model.hfield_nrow[k]), int(model.hfield_ncol[k]), int(model.hfield_adr[k])
        data = path.with_name(f"{path.stem}_{element.get('name')}.bin")
        head = np.array([nrow, ncol], dtype="<i4").tobytes()
        values = np.asarray(model.hfield_data[adr:adr + nrow * ncol], dtype="<f4").tobytes()
        atomic_write(data, lambda f, blob=head + values: f.write(blob))
        element.attrib.pop("elevation", None)
        element.attrib.pop("nrow", None)  # the file gives them
        element.attrib.pop("ncol", None)
        element.set("file", data.name)
        element.set("size", _exact(model.hfield_size[k]))  # MuJoCo's text keeps 6 digits
        for geom in root.iter("geom"):
            if geom.get("hfield") == element.get("name"):
                geom.set("pos", _exact(model.geom_pos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM,
                                                                         geom.get("name"))]))
        written.append(str(data))
    ET.indent(root)
    atomic_write_text(path, ET.tostring(root, encoding="unicode") + "\n")  # after its data: it names them
    return [str(path), *written]
