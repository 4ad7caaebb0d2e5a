"""python -m hopper_mjx.ros.record: simulate monopeds and write their sensor streams as a ROS bag.

    python -m hopper_mjx.ros.record --gravity 9.81,1.62 --controller hold --duration 2 \
        --format ros1 --out run.bag
    python -m hopper_mjx.ros.record --gravity 3.71 --format mcap --out run_mcap   # a rosbag2 folder

Topics, as the seed's Gazebo monoped published them (one recorded instance):

    /monoped/imu/data               sensor_msgs/Imu             frame base
    /odom                           nav_msgs/Odometry           frame world, child base
    /monoped/joint_states           sensor_msgs/JointState      haa_joint, hfe_joint, kfe_joint
    /lowerleg_contactsensor_state   gazebo_msgs/ContactsState   frame world
    /clock                          rosgraph_msgs/Clock

With several recorded instances, instance i publishes under /monoped_<i>/ (e.g.
/monoped_3/imu/data, /monoped_3/odom) with frames prefixed monoped_<i>/; /clock
and the world frame are shared. Stamps are simulation time.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hopper_mjx import cli
from hopper_mjx.ros import msgdefs
from hopper_mjx.ros.messages import messages, typestore
from hopper_mjx.scenario import Scenario
from hopper_mjx.shell import files, jaxsetup, process

if TYPE_CHECKING:
    from hopper_mjx.hardware.signals import SensorConfig
    from hopper_mjx.sim import Trajectory

FORMATS = ("ros1", "mcap")


@dataclass(frozen=True)
class Recording:
    """One simulated batch, as the core returned it, with what the messages need besides."""

    traj: Trajectory  # arrays (N, T_stream, ...)
    gravity: np.ndarray  # (N, 3) m/s²
    sensors: SensorConfig  # the streams were sampled with
    joint_names: tuple[str, ...]  # haa, hfe, kfe
    joint_qpos: tuple[int, ...]  # their qpos addresses
    joint_dof: tuple[int, ...]  # their qvel addresses
    floor_normal: np.ndarray  # (3,) world frame, pointing from the floor to the foot
    clock_time: np.ndarray  # (T,) s, every instant at which some stream was sampled
    diverged: np.ndarray  # (N,) bool
    terrain: np.ndarray | None = None  # (3 K, 3) m: the corners of the ground's K triangles; None: a plane


# -- simulation --------------------------------------------------------------------------------
def rate_flags(args) -> dict[str, str]:
    """The option that set each stream's rate: its own --<stream>-rate, else --rate."""
    own = {"imu": "imu", "odom": "odom", "contact": "contact", "state": "joint"}
    return {s: f"--{o}-rate" if getattr(args, f"{o}_rate") is not None else "--rate" for s, o in own.items()}


def sensor_config(args):
    """Per-stream rates: each --<stream>-rate, else --rate (the seed's 50 Hz)."""
    from hopper_mjx.hardware.signals import SensorConfig

    rate = lambda own: args.rate if own is None else own
    return SensorConfig(
        imu_rate=rate(args.imu_rate),
        gyro_noise=args.gyro_noise,
        accel_noise=args.accel_noise,
        odom_rate=rate(args.odom_rate),
        contact_rate=rate(args.contact_rate),
        state_rate=rate(args.joint_rate),
        torque=True,  # the joint states' effort
    )


def recording(sim, traj, gravity, sensors, diverged) -> Recording:
    """What the messages need of a batch simulated by `sim` (a `hopper_mjx.sim.Sim`)."""
    import mujoco

    from hopper_mjx import model

    data = mujoco.MjData(sim.mj_model)
    mujoco.mj_kinematics(sim.mj_model, data)
    floor_normal = data.geom_xmat[sim.layout.floor_geom].reshape(3, 3)[:, 2].copy()  # a plane's normal is its z axis
    # Every stream's times are t0 + timestep * (whole steps), so equal instants are equal floats.
    clock_time = np.unique(np.concatenate(list(traj.time.values())))
    return Recording(
        traj=traj,
        gravity=gravity,
        sensors=sensors,
        joint_names=model.JOINTS,
        joint_qpos=sim.layout.joint_qpos,
        joint_dof=sim.layout.joint_dof,
        floor_normal=floor_normal,
        clock_time=clock_time,
        diverged=np.asarray(diverged),
        terrain=terrain_triangles(sim.mj_model),
    )


def terrain_triangles(mj_model) -> np.ndarray | None:
    """The corners of the model's ground triangles (None on a plane), as MuJoCo holds the heights."""
    from hopper_mjx import terrain

    ground = terrain.from_model(mj_model)
    return None if ground is None else terrain.triangles(ground)


def simulate_batch(args, batch: Scenario | None = None) -> Recording:
    """Runs the batch the arguments describe (the one batch-run path) at the bag's rates."""
    sensors = sensor_config(args)
    batch = batch or cli.check_batch(args)
    sim, final, traj = batch.run(args.duration, sensors)
    return recording(sim, traj, batch.gravity, sensors, final.diverged)


# -- bag files -------------------------------------------------------------------------------
def definition(store, msgtype: str, ros1: bool) -> dict:
    """add_connection's keywords: for ROS 1, ROS's own definition text (with its comments, which
    rosbags' generated text lacks) and the md5 sum, which ignores comments; for ROS 2, the type store."""
    if not ros1:
        return {"typestore": store}
    return {"msgdef": msgdefs.full_text(msgtype), "md5sum": store.generate_msgdef(msgtype, ros_version=1)[1]}


def check_output(out: str | Path, fmt: str) -> Path:
    """--out: new, in an existing folder; for mcap a folder name (rosbag2 writes a folder)."""
    out = cli.check_writable("--out", out, folder=fmt == "mcap", may_exist=False,
                             suffixes=() if fmt == "mcap" else (".bag",))
    if fmt == "mcap" and out.suffix == ".mcap":
        raise ValueError(f"--format mcap writes a ROS 2 bag folder (holding the .mcap file): "
                         f"give a folder name such as {out.stem}_mcap, not {out.name}")
    return out


def write(rec: Recording, out: str | Path, fmt: str, instances: list[int] | None = None) -> Path:
    """Writes the chosen instances (default: all) as a ROS 1 .bag file or a ROS 2 MCAP bag folder."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; choose from: {', '.join(FORMATS)}")
    n = rec.gravity.shape[0]
    instances = list(range(n)) if instances is None else list(instances)
    cli.check_indices("--instances", instances, n)
    out = check_output(out, fmt)
    store = typestore(fmt)
    ros1 = fmt == "ros1"
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(out)
        serialize = store.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        writer = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
        serialize = store.serialize_cdr
    # Bags are time-ordered files; the streams are generated topic by topic, so sort first.
    msgs = sorted(messages(rec, instances, store, ros1), key=lambda m: m[2])
    with files.partial(out), writer:  # a stopped run leaves no half-written bag
        connections = {}
        for topic, msgtype, t, msg in msgs:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, **definition(store, msgtype, ros1))
            writer.write(connections[topic], int(round(t * 1e9)), serialize(msg, msgtype))
    return out


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python -m hopper_mjx.ros.record", __doc__)
    cli.add_batch_options(p, gravity=(9.81,))
    p.add_argument("--rate", type=float, default=50.0, help="Hz of every stream without its own rate (the seed's 50)")
    for stream, what in (("imu", "/imu/data"), ("odom", "/odom"), ("contact", "contact state"),
                         ("joint", "/joint_states")):
        p.add_argument(f"--{stream}-rate", type=float, default=None, help=f"Hz of {what} (default: --rate)")
    p.add_argument("--instances", type=cli.parse_indices, default=None,
                   help="comma-separated instance indices to record (default: all)")
    p.add_argument("--format", choices=FORMATS, default="ros1",
                   help="ros1: a .bag file (ROS 1 Melodic/Noetic); mcap: a ROS 2 bag folder holding one .mcap")
    p.add_argument("--out", default=None, help="output path (default: monoped.bag or monoped_mcap/)")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    out = args.out or ("monoped.bag" if args.format == "ros1" else "monoped_mcap")
    try:
        check_output(out, args.format)
        for name in ("rate", "imu_rate", "odom_rate", "contact_rate", "joint_rate"):
            if getattr(args, name) is not None:
                cli.check_range(f"--{name.replace('_', '-')}", getattr(args, name), low=0, open_low=True)
        batch = cli.check_batch(args)
        if args.instances is not None:
            cli.check_indices("--instances", args.instances, len(batch.gravity))
        cli.say(cli.check_rates(rate_flags(args), sensor_config(args), batch, args.duration),
                cli.speed_note(batch, args.duration))
        jaxsetup.configure()
        rec = simulate_batch(args, batch)
        path = write(rec, out, args.format, args.instances)
    except ValueError as err:  # includes URDFError
        return cli.fail(err)
    cli.warn_diverged(rec.diverged)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
