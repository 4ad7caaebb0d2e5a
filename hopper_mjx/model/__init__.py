"""The robot description: the shipped monoped URDF and its compiler to MuJoCo."""

from hopper_mjx.model.loader import (
    DEFAULT_TIMESTEP,
    DEFAULT_URDF,
    FLOOR_GEOM,
    FOOT_GEOM,
    IMU_SITE,
    JOINTS,
    LEG_CONTACT_GROUP,
    ROOT_JOINT,
    URDFError,
    build_spec,
    describe,
    load,
)

__all__ = [
    "DEFAULT_TIMESTEP", "DEFAULT_URDF", "FLOOR_GEOM", "FOOT_GEOM", "IMU_SITE", "JOINTS", "LEG_CONTACT_GROUP",
    "ROOT_JOINT", "URDFError", "build_spec", "describe", "load",
]
