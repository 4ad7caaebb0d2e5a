"""Terrain: generated height grids, their spec (`--terrain`), and their form as MuJoCo's height field.

    ground = terrain.parse("rough:amp=0.03,wavelength=0.4,seed=1")   # checked, nothing built
    model.load(terrain=ground.terrain())                             # the floor becomes an hfield

NumPy only here, so that a command can check a spec before JAX or MuJoCo is imported; the
height scan (JAX) is `hopper_mjx.terrain.scan`.
"""

from hopper_mjx.terrain.hfield import (
                                 BASE_DEPTH,
                                 FLAT_SPAN,
                                 HFIELD,
                                 HField,
                                 Terrain,
                                 from_model,
                                 hfield,
                                 to_model_data,
                                 to_spec,
                                 triangles,
                                 vertices,
                                 write_mjcf,
)
from hopper_mjx.terrain.spec import FLAT, Ground, TerrainError, parse

__all__ = ["BASE_DEPTH", "FLAT", "FLAT_SPAN", "HFIELD", "Ground", "HField", "Terrain", "TerrainError", "from_model",
           "hfield", "parse", "to_model_data", "to_spec", "triangles", "vertices", "write_mjcf"]
