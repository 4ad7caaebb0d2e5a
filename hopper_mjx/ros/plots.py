"""python -m hopper_mjx.ros.plots BAG: PNG plots of a recording's IMU, odometry and contact signals.

    python -m hopper_mjx.ros.plots monoped.bag --out signals.png
    python -m hopper_mjx.ros.plots run.bag --instances 0,2 --out signals.png   # a multi-robot bag

The plots show what the bag holds (as the seed's figures 5.2-5.4 showed the
published topics), read back with rosbags, one column per recorded robot.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from hopper_mjx import cli
from hopper_mjx.ros import echo, messages
from hopper_mjx.shell import process
from hopper_mjx.shell.files import atomic_write

AXES = ("x", "y", "z")


def _xyz(vector) -> list[float]:
    return [vector.x, vector.y, vector.z]


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def _check_one_robot(reader, topic: str) -> None:
    """A bag of several robots read as one robot's: say which robots it holds and the option that picks them."""
    topics = {c.topic for c in reader.connections}
    robots = sorted({int(m.group(1)) for t in topics if (m := re.match(rf"/{messages.ROBOT}_(\d+)/", t))})
    if topic in topics or not robots:
        return
    raise ValueError(f"the bag holds {len(robots)} robots, /{messages.ROBOT}_{robots[0]} to /{messages.ROBOT}_"
                     f"{robots[-1]}: choose with --instances, e.g. --instances {','.join(map(str, robots[:2]))}")


def read_signals(path: str | Path, instance: int | None = None) -> dict[str, np.ndarray]:
    """One robot's streams from a bag written by `record`, as arrays with their own stamps (s)."""
    topics = messages.topic_names(instance)
    out: dict[str, list] = {k: [] for k in ("imu_t", "gyro", "accel", "odom_t", "pos", "linvel",
                                            "contact_t", "contact", "force")}
    with echo.open_bag(path) as reader:
        if instance is None:
            _check_one_robot(reader, topics["imu"])
        for _, msg in echo.messages(reader, topics["imu"]):
            out["imu_t"].append(_stamp(msg))
            out["gyro"].append(_xyz(msg.angular_velocity))
            out["accel"].append(_xyz(msg.linear_acceleration))
        for _, msg in echo.messages(reader, topics["odom"]):
            out["odom_t"].append(_stamp(msg))
            out["pos"].append(_xyz(msg.pose.pose.position))
            out["linvel"].append(_xyz(msg.twist.twist.linear))
        for _, msg in echo.messages(reader, topics["contact"]):
            out["contact_t"].append(_stamp(msg))
            out["contact"].append(bool(msg.states))
            forces = [_xyz(s.total_wrench.force) for s in msg.states]
            out["force"].append(np.sum(forces, axis=0) if forces else np.zeros(3))
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


def _contact_shading(ax, t, touching) -> None:
    """Grey bands where the foot touches the floor."""
    edges = np.diff(np.concatenate([[0], touching.astype(int), [0]]))
    dt = np.median(np.diff(t)) if len(t) > 1 else 0.0
    for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        ax.axvspan(t[start], t[stop - 1] + dt, color="0.85", lw=0)


def figure(signals: list[tuple[str, dict]]):
    """A matplotlib figure: rows IMU rate, IMU specific force, position, velocity, contact force;
    one column per (title, signals) pair."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = (  # the frame each vector is in, and its unit in parentheses (as every plot here gives it)
        ("imu_t", "gyro", "IMU angular velocity,\nbody frame (rad/s)"),
        ("imu_t", "accel", "IMU specific force,\nbody frame (m/s²)"),
        ("odom_t", "pos", "odometry position,\nworld frame (m)"),
        ("odom_t", "linvel", "odometry velocity,\nworld frame (m/s)"),
        ("contact_t", "force", "contact force of the\nfloor on the foot (N)"),
    )
    fig, axes = plt.subplots(len(rows), len(signals), sharex=True, squeeze=False,
                             figsize=(4.2 * len(signals) + 1.2, 9.0))
    for col, (title, sig) in enumerate(signals):
        for row, (time_key, key, label) in enumerate(rows):
            ax = axes[row, col]
            _contact_shading(ax, sig["contact_t"], sig["contact"] > 0)
            for i, axis in enumerate(AXES):
                ax.plot(sig[time_key], sig[key][:, i], lw=1.2, label=axis)
            ax.grid(alpha=0.3)
            if col == 0:
                ax.set_ylabel(label, fontsize=9)
        axes[0, col].set_title(title, fontsize=10)
        axes[-1, col].set_xlabel("simulation time (s)")
    axes[0, 0].legend(loc="upper right", fontsize=8, ncol=3)
    fig.text(0.99, 0.005, "grey: foot in contact", ha="right", va="bottom", fontsize=8, color="0.4")
    fig.tight_layout()
    return fig


def plot_bag(path: str | Path, out: str | Path, instances: list[int] | None = None, dpi: int = 80,
             labels: list[str] | None = None) -> Path:
    """Writes the PNG of the chosen robots of a bag (default: the single robot of the seed's topics),
    each column titled by its namespace or by `labels`."""
    chosen = [None] if instances is None else instances
    names = [f"/{messages.ROBOT}" if i is None else f"/{messages.ROBOT}_{i}" for i in chosen]
    if labels is not None and len(labels) != len(chosen):
        raise ValueError(f"{len(labels)} labels for {len(chosen)} plotted robots")
    fig = figure([(title, read_signals(path, i)) for title, i in zip(labels or names, chosen)])
    atomic_write(out, lambda f: fig.savefig(f, dpi=dpi, format=Path(out).suffix[1:] or None))
    return Path(out)


MAX_DPI = 1000


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python -m hopper_mjx.ros.plots", __doc__)
    p.add_argument("bag", help="a bag written by python -m hopper_mjx.ros.record (.bag file or MCAP folder)")
    p.add_argument("--instances", type=cli.parse_indices, default=None,
                   help="robots of a multi-robot bag to plot, e.g. 0,2 (default: the single robot)")
    p.add_argument("--labels", type=lambda s: s.split(","), default=None,
                   help="comma-separated column titles, one per plotted robot (default: namespaces)")
    p.add_argument("--out", default="signals.png", help="output PNG")
    p.add_argument("--dpi", type=int, default=80)
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        cli.check_writable("--out", args.out, suffixes=cli.PLOT_SUFFIXES)
        if not 1 <= args.dpi <= MAX_DPI:  # a column is 4.2 x 9 inches: 10^5 dpi asked for terapixels
            raise ValueError(f"--dpi must be in 1..{MAX_DPI}, got {args.dpi}")
        if args.instances is not None:
            if not args.instances or min(args.instances) < 0:
                raise ValueError(f"--instances: robots are numbered from 0, got {args.instances}")
            if len(set(args.instances)) != len(args.instances):
                raise ValueError(f"--instances lists a robot twice: {args.instances}")
        echo.bag_path(args.bag)  # exists and is a bag (folder), before anything is read
        path = plot_bag(args.bag, args.out, args.instances, args.dpi, args.labels)
    except ValueError as err:
        return cli.fail(err)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
