"""ROS 1 message definitions as ROS itself spells them, for the connection headers of our bags.

A ROS 1 bag stores, per connection, the message definition: the type's .msg
text followed by that of every type it embeds (genmsg's "full text"). ROS's
tools compare it with the installed definitions, and `rosbag check` asks for a
migration when the text differs, even if only in comments. So the .msg files
under `msg/<package>/` are ROS's own: std_msgs, geometry_msgs, sensor_msgs,
nav_msgs and rosgraph_msgs from ROS's Debian packages (ros-*-msgs, the Noetic
releases), gazebo_msgs from gazebo_ros_pkgs' noetic-devel branch. Their md5 sums
(which ignore comments) are what rosbags computes from its own type store.
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

MSG_DIR = Path(__file__).with_name("msg")
SEPARATOR = "=" * 80 + "\n"
BUILTIN_TYPES = frozenset({
    "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
    "float32", "float64", "string", "time", "duration",
})


def ros1_name(msgtype: str) -> str:
    """'sensor_msgs/msg/Imu' (rosbags, ROS 2) or 'sensor_msgs/Imu' -> 'sensor_msgs/Imu'."""
    package, *_, name = msgtype.split("/")
    return f"{package}/{name}"


@cache
def text(msgtype: str) -> str:
    """The .msg file's text, exactly."""
    package, name = ros1_name(msgtype).split("/")
    path = MSG_DIR / package / f"{name}.msg"
    if not path.is_file():
        raise KeyError(f"no stored ROS definition for {msgtype}")
    return path.read_text(encoding="utf-8")


def _field_types(msgtype: str) -> list[str]:
    """Non-builtin field types of a message, resolved to pkg/Type, in field order."""
    package = ros1_name(msgtype).split("/")[0]
    out = []
    for line in text(msgtype).splitlines():
        declaration = line.split("#", 1)[0].strip()
        if not declaration or "=" in declaration:  # blank, comment or constant (constants are builtins)
            continue
        kind = re.sub(r"\[\d*\]$", "", declaration.split()[0])
        if kind in BUILTIN_TYPES:
            continue
        out.append("std_msgs/Header" if kind == "Header" else kind if "/" in kind else f"{package}/{kind}")
    return out


def dependencies(msgtype: str) -> list[str]:
    """Every embedded type, depth first in field order, each once (genmsg's order)."""
    order = []

    def visit(kind: str) -> None:
        for dep in _field_types(kind):
            if dep not in order:
                order.append(dep)
            visit(dep)

    visit(ros1_name(msgtype))
    return order


def full_text(msgtype: str) -> str:
    """The message definition a ROS 1 connection header carries (genmsg's compute_full_text)."""
    parts = [text(msgtype) + "\n"]
    parts += [f"{SEPARATOR}MSG: {dep}\n{text(dep)}\n" for dep in dependencies(msgtype)]
    return "".join(parts)[:-1]
