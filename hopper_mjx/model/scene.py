"""What only pictures add to the monoped: a checkered floor, a sky and colours for the links.

Shared by the offscreen renderer (`hopper_mjx.render`) and the live viewer (`hopper_mjx.view`);
the simulation never sees it.
"""

from __future__ import annotations

import mujoco

from hopper_mjx.model.loader import FLOOR_GEOM

# The URDF has no colours; these tell the links apart (RGBA).
LINK_COLOURS = {
    "base": (0.20, 0.38, 0.65, 1),
    "hipassembly": (0.85, 0.45, 0.10, 1),
    "upperleg": (0.85, 0.85, 0.82, 1),
    "lowerleg": (0.85, 0.45, 0.10, 1),
    "foot": (0.12, 0.12, 0.12, 1),
}


def dress(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """Adds the pictures' floor texture, sky and link colours to a monoped spec (in place)."""
    spec.add_texture(name="checker", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
                     rgb1=[0.82, 0.84, 0.86], rgb2=[0.62, 0.66, 0.70], width=256, height=256)
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=[0.55, 0.70, 0.90], rgb2=[0.95, 0.97, 1.0], width=256, height=256)
    floor = spec.add_material(name="floor", texrepeat=[4, 4], texuniform=True)
    floor.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "checker"
    spec.geom(FLOOR_GEOM).material = "floor"
    for body, rgba in LINK_COLOURS.items():
        if spec.body(body) is not None:  # another URDF may name its links differently
            for geom in spec.body(body).geoms:
                geom.rgba = rgba
    spec.visual.headlight.ambient = [0.4, 0.4, 0.4]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]
    spec.visual.global_.offwidth = 1920
    spec.visual.global_.offheight = 1080
    return spec
