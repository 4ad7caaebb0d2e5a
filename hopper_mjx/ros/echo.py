"""python -m hopper_mjx.ros.echo BAG TOPIC: print a topic's messages laid out as `rostopic echo` does.

    python -m hopper_mjx.ros.echo monoped.bag /monoped/imu/data -n 1     # a bag of one robot
    python -m hopper_mjx.ros.echo drop.bag /monoped_0/imu/data -n 1      # robot 0 of a bag of several
    python -m hopper_mjx.ros.echo monoped_mcap /odom

BAG is a ROS 1 .bag file or a ROS 2 bag folder (or the .mcap file inside it).
Messages are decoded with the definitions stored in the bag, so any bag works.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np
import yaml

from hopper_mjx import cli
from hopper_mjx.shell import process

TIME_TYPES = ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration")
ROS2_METADATA = "metadata.yaml"  # what makes a folder a rosbag2 bag


def bag_path(path: str | Path) -> Path:
    """The path rosbags opens: a .bag file or a rosbag2 folder (given the folder or a file in it)."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"no such bag: {path}")
    if path.is_file() and path.suffix in (".mcap", ".db3", ".yaml"):
        if not (path.parent / ROS2_METADATA).is_file():
            raise ValueError(f"{path} is a ROS 2 storage file without its bag folder: no {ROS2_METADATA} "
                             f"beside it (give the bag folder that rosbag2 wrote)")
        return path.parent
    if path.is_dir() and not (path / ROS2_METADATA).is_file():
        raise ValueError(f"{path} is a folder but not a ROS 2 bag: it has no {ROS2_METADATA}")
    return path


@contextmanager
def open_bag(path: str | Path):
    """rosbags' AnyReader over one bag, with a clear error for a file that is not one."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    try:
        reader = AnyReader([bag_path(path)])
        reader.open()
    except (AnyReaderError, OSError) as err:  # rosbags' YAML errors run to several lines: the first says what
        raise ValueError(f"cannot read {path} as a ROS bag: {str(err).splitlines()[0] if str(err) else err}") \
            from None
    try:
        yield reader
    finally:
        reader.close()


def messages(reader, topic: str) -> Iterator[tuple[int, object]]:
    """(bag time ns, decoded message) of every message on `topic` of an open bag, in time order."""
    connections = [c for c in reader.connections if c.topic == topic]
    if not connections:
        topics = sorted({c.topic for c in reader.connections})
        raise ValueError(f"topic {topic} is not in the bag; it has: {', '.join(topics)}")
    for connection, timestamp, raw in reader.messages(connections=connections):
        yield timestamp, reader.deserialize(raw, connection.msgtype)


def _is_message(value) -> bool:
    return dataclasses.is_dataclass(value) and hasattr(value, "__msgtype__")


def _scalar(value) -> str:
    if isinstance(value, str):
        # Like rostopic: YAML double-quoted (and folded) strings, two single quotes for an empty one.
        return yaml.dump(value, default_style='"').rstrip("\n") if value else "''"
    if isinstance(value, np.generic):
        value = value.item()
    return str(value)


def _time(value, indent: str) -> str:
    return f"\n{indent}secs: {value.sec}\n{indent}nsecs: {value.nanosec:9d}"


def format_value(value, indent: str, ros1: bool) -> str:
    """One field's value; nested messages and lists of messages start on a new line."""
    if _is_message(value):
        if ros1 and value.__msgtype__ in TIME_TYPES:
            return _time(value, indent)  # rostopic shows ROS 1 time as secs / nsecs
        return "\n" + format_message(value, indent, ros1)
    if isinstance(value, (list, tuple, np.ndarray)):
        items = list(value)
        if not items:
            return "[]"
        if _is_message(items[0]):
            return "".join(f"\n{indent}- {format_value(item, indent + '  ', ros1)}" for item in items)
        if isinstance(items[0], str):  # a YAML block list, as Noetic's rostopic prints it
            return "".join(f"\n{indent}{line}" for line in yaml.dump(items).splitlines())
        return "[" + ", ".join(_scalar(v) for v in items) + "]"
    return _scalar(value)


def format_message(msg, indent: str = "", ros1: bool = True) -> str:
    """A decoded rosbags message as `rostopic echo` lays it out (without the closing ---)."""
    return "\n".join(
        f"{indent}{field.name}: {format_value(getattr(msg, field.name), indent + '  ', ros1)}"
        for field in dataclasses.fields(msg)
        if not field.name.startswith("__")
    )


def echo(path: str | Path, topic: str, count: int | None = None, out=None) -> int:
    """Prints up to `count` messages (all when None) of `topic` to `out` (default stdout);
    returns how many were printed."""
    if count is not None and count < 1:
        raise ValueError(f"-n must be >= 1, got {count}")
    out = out or sys.stdout
    printed = 0
    with open_bag(path) as reader:
        for _, msg in messages(reader, topic):
            print(format_message(msg, ros1=not reader.is2), file=out)
            print("---", file=out)
            printed += 1
            if printed == count:
                break
    return printed


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python -m hopper_mjx.ros.echo", __doc__)
    p.add_argument("bag", help="a ROS 1 .bag file or a ROS 2 bag folder")
    p.add_argument("topic", help="e.g. /monoped/imu/data in a bag of one robot; in a bag of several, robot i's "
                                 "topics are /monoped_<i>/..., e.g. /monoped_0/imu/data")
    p.add_argument("-n", dest="count", type=int, default=None, help="print only the first COUNT messages")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        echo(args.bag, args.topic, args.count)
    except ValueError as err:
        return cli.fail(err)
    except BrokenPipeError:  # e.g. piped into head
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
