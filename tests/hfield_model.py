"""A monoped on a heightfield floor, built the way the model convention says a terrain is
exported (one function, so the terrain loader can replace it).

A terrain is a height grid `heights (nrow, ncol)` m with half extents (hx, hy), centred at
the origin: vertex (r, c) at x = -hx + 2 hx c / (ncol - 1), y = -hy + 2 hy r / (nrow - 1).
The floor geom keeps its name and its explicit pairs but becomes an hfield geom on the asset
"terrain": size (hx, hy, max - min, base), data (h - min) / (max - min), geom z = min(h).
"""

from __future__ import annotations

import mujoco
import numpy as np

from hopper_mjx.model import loader
from hopper_mjx.terrain import HFIELD, Terrain


def hfield_model(heights, hx: float, hy: float, base: float = 0.1, urdf=None,
                 base_pairs: bool = True) -> mujoco.MjModel:
    """The monoped with its floor replaced by the terrain `heights`; `base_pairs=False` drops
    the base box's and the leg links' floor pairs (the foot's pair is kept)."""
    heights = np.asarray(heights, dtype=float)
    low, zrange = float(heights.min()), float(np.ptp(heights))
    # The loader's terrain model (its pairs: the base's and the leg links' boxes too), on this grid.
    spec = loader.build_spec(urdf, terrain=Terrain(heights, (hx, hy)))
    nrow, ncol = heights.shape
    data = (heights - low) / zrange if zrange > 0 else np.zeros_like(heights)
    spec.delete(spec.hfield(HFIELD))
    spec.add_hfield(name="terrain", nrow=nrow, ncol=ncol, size=[hx, hy, max(zrange, 1e-9), base],
                    userdata=data.ravel().tolist())
    floor = next(g for g in spec.geoms if g.name == loader.FLOOR_GEOM)
    floor.type = mujoco.mjtGeom.mjGEOM_HFIELD
    floor.hfieldname = "terrain"
    floor.pos = [0.0, 0.0, low]
    if not base_pairs:
        for pair in list(spec.pairs):
            if pair.geomname2 != loader.FOOT_GEOM:
                spec.delete(pair)
    return spec.compile()
