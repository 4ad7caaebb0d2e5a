"""The monoped's URDF as a viewer such as Foxglove's 3D panel draws it.

    text = display_urdf(urdf=None)   # the shipped seed monoped, or the URDF `view`/`simulate` loaded

The robot is the one the loader reads, link for link and joint for joint; only what a viewer
needs to draw it is added: a <visual> copied from the <collision> of a link that has none, the
pictures' link colours (`scene.LINK_COLOURS`) on visuals without a material, and mesh files as
absolute file:// URLs (a viewer does not know the folder the URDF came from; package:// URLs
stay, for the viewer's ROS package path). A frame prefix renames the links as a tf_prefix would,
for viewers (such as Foxglove's URDF layer) that cannot prefix a robot's frames themselves.
"""

from __future__ import annotations

import copy
import os
import xml.etree.ElementTree as ET
from pathlib import Path

from hopper_mjx.model.loader import DEFAULT_URDF, URDFError, describe, read_text
from hopper_mjx.model.scene import LINK_COLOURS


def _absolute_meshes(element: ET.Element, folder: Path) -> None:
    for mesh in element.iter("mesh"):
        name = mesh.get("filename", "")
        if name and "://" not in name:
            mesh.set("filename", (folder / name).resolve().as_uri())


def _visuals(link: ET.Element) -> list[ET.Element]:
    """The link's visuals; a link drawn by nothing gets copies of its collision shapes."""
    visuals = link.findall("visual")
    if not visuals:
        for collision in link.findall("collision"):
            visual = copy.deepcopy(collision)
            visual.tag = "visual"
            visual.attrib.pop("name", None)
            link.append(visual)
            visuals.append(visual)
    return visuals


def _prefix_links(robot: ET.Element, prefix: str) -> None:
    """Renames every link `prefix` + name (the joints follow), as tf_prefix names the frames."""
    for link in robot.findall("link"):
        link.set("name", prefix + link.get("name"))
    for joint in robot.findall("joint"):
        for end in (joint.find("parent"), joint.find("child")):
            end.set("link", prefix + end.get("link"))


def display_urdf(urdf: str | os.PathLike | None = None, frame_prefix: str = "") -> str:
    """The URDF text of the monoped at `urdf` (default: the shipped one), ready for a viewer, its
    links named `frame_prefix` + name (e.g. "monoped_3/", to match a stream's /tf frames).
    Raises URDFError if the file is not a monoped the loader accepts."""
    path = Path(urdf) if urdf is not None else DEFAULT_URDF
    text = read_text(path, "URDF file", URDFError)
    describe(text, str(path))  # the same checks as the loader: the robot drawn is the robot simulated
    robot = ET.fromstring(text)
    for link in robot.findall("link"):
        rgba = LINK_COLOURS.get(link.get("name"))
        for visual in _visuals(link):
            if rgba is not None and visual.find("material") is None:
                material = ET.SubElement(visual, "material", name=f"{link.get('name')}_colour")
                ET.SubElement(material, "color", rgba=" ".join(f"{c:g}" for c in rgba))
        _absolute_meshes(link, path.parent.resolve())
    _prefix_links(robot, frame_prefix)
    ET.indent(robot)
    return (f'<?xml version="1.0"?>\n<!-- {path.name} for display, written by python -m hopper_mjx.model -->\n'
            + ET.tostring(robot, encoding="unicode") + "\n")
