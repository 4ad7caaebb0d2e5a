"""python -m hopper_mjx.record: simulate monopeds and write their sensor streams as a ROS bag.

    python -m hopper_mjx.record --gravity 9.81,1.62 --controller hold --duration 2 \
        --format ros1 --out run.bag
    python -m hopper_mjx.record --gravity 3.71 --format mcap --out run_mcap   # a rosbag2 folder

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
from typing import Iterator

import numpy as np

from hopper_mjx import msgdefs, runtime, simulate

FORMATS = ("ros1", "mcap")
ROBOT = "monoped"
CONTACT_LINK = "lowerleg"  # the seed's contact sensor sits on the lower leg; the foot is fixed to it
GROUND_COLLISION = "ground_plane::link::collision"

# gazebo_msgs is not among rosbags' built-in types; its definitions come from ROS's own .msg files.
GAZEBO_MSGS = ("gazebo_msgs/msg/ContactState", "gazebo_msgs/msg/ContactsState")

MSGTYPES = {
    "imu": "sensor_msgs/msg/Imu",
    "odom": "nav_msgs/msg/Odometry",
    "joint_states": "sensor_msgs/msg/JointState",
    "contact": "gazebo_msgs/msg/ContactsState",
    "clock": "rosgraph_msgs/msg/Clock",
}


@dataclass(frozen=True)
class Recording:
    """One simulated batch, as the core returned it, with what the messages need besides."""

    traj: object  # hopper_mjx.sim.Trajectory, arrays (N, T_stream, ...)
    gravity: np.ndarray  # (N, 3) m/s²
    sensors: object  # hopper_mjx.signals.SensorConfig the streams were sampled with
    joint_names: tuple[str, ...]  # haa, hfe, kfe
    joint_qpos: tuple[int, ...]  # their qpos addresses
    joint_dof: tuple[int, ...]  # their qvel addresses
    floor_normal: np.ndarray  # (3,) world frame, pointing from the floor to the foot
    clock_time: np.ndarray  # (T,) s, every instant at which some stream was sampled
    diverged: np.ndarray  # (N,) bool


def topic_names(instance: int | None) -> dict[str, str]:
    """Topic of each stream; `instance` None gives the seed's names for a single recorded robot."""
    ns = ROBOT if instance is None else f"{ROBOT}_{instance}"
    return {
        "imu": f"/{ns}/imu/data",
        "odom": "/odom" if instance is None else f"/{ns}/odom",
        "joint_states": f"/{ns}/joint_states",
        "contact": "/lowerleg_contactsensor_state" if instance is None else f"/{ns}/lowerleg_contactsensor_state",
    }


def frame_prefix(instance: int | None) -> str:
    return "" if instance is None else f"{ROBOT}_{instance}/"


# -- simulation --------------------------------------------------------------------------------
def sensor_config(args):
    """Per-stream rates: each --<stream>-rate, else --rate (the seed's 50 Hz)."""
    from hopper_mjx.signals import SensorConfig

    rate = lambda own: args.rate if own is None else own
    return SensorConfig(
        imu_rate=rate(args.imu_rate),
        gyro_noise=args.gyro_noise,
        accel_noise=args.accel_noise,
        odom_rate=rate(args.odom_rate),
        contact_rate=rate(args.contact_rate),
        state_rate=rate(args.joint_rate),
    )


def simulate_batch(args) -> Recording:
    """Runs the core (`Sim.rollout`) as `python -m hopper_mjx.simulate` would, at the bag's rates."""
    import math

    import jax
    import mujoco

    from hopper_mjx import model
    from hopper_mjx.sim import Sim, gravity_vectors

    if args.num < 1:
        raise ValueError(f"--num must be >= 1, got {args.num}")
    if not args.duration > 0:
        raise ValueError(f"--duration must be > 0 s, got {args.duration}")
    gravity = gravity_vectors(np.repeat(args.gravity, args.num))
    mj_model = model.load(args.urdf, timestep=args.timestep)
    sim = Sim(mj_model, chunk=args.chunk)
    controller, params = simulate.build_controller(args.controller, sim.layout, args)
    sensors = sensor_config(args)
    periods = sensors.periods(sim.layout.timestep)
    whole = math.lcm(*periods.values())  # steps must hold a whole number of every stream's period
    steps = max(whole, int(round(args.duration / sim.layout.timestep / whole)) * whole)
    state = sim.reset(gravity, key=args.seed, controller=controller, params=params)
    final, traj = sim.rollout(state, controller, steps=steps, sensors=sensors)
    traj = jax.tree_util.tree_map(np.asarray, traj)

    data = mujoco.MjData(mj_model)
    mujoco.mj_kinematics(mj_model, data)
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
        diverged=np.asarray(final.diverged),
    )


# -- messages --------------------------------------------------------------------------------
def typestore(fmt: str):
    """rosbags' message types for the format (ROS 1 Noetic, wire-identical to Melodic, or ROS 2 Jazzy)
    with gazebo_msgs added."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if fmt == "ros1" else Stores.ROS2_JAZZY)
    types = {}
    for name in GAZEBO_MSGS:
        types.update(get_types_from_msg(msgdefs.text(name), name))
    store.register(types)
    return store


class _Builder:
    """Makes rosbags message objects from one typestore; ROS 1 headers carry a sequence number."""

    def __init__(self, store, ros1: bool):
        self.t = store.types
        self.ros1 = ros1

    def stamp(self, seconds: float):
        ns = int(round(seconds * 1e9))
        return self.t["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def header(self, seq: int, seconds: float, frame: str):
        extra = {"seq": seq} if self.ros1 else {}
        return self.t["std_msgs/msg/Header"](stamp=self.stamp(seconds), frame_id=frame, **extra)

    def vector(self, v):
        return self.t["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quaternion(self, wxyz):
        # Our arrays are [w, x, y, z]; geometry_msgs/Quaternion names its fields x, y, z, w.
        return self.t["geometry_msgs/msg/Quaternion"](
            x=float(wxyz[1]), y=float(wxyz[2]), z=float(wxyz[3]), w=float(wxyz[0])
        )

    def imu(self, header, quat, gyro, accel, cov: dict):
        return self.t["sensor_msgs/msg/Imu"](
            header=header,
            orientation=self.quaternion(quat),
            orientation_covariance=cov["orientation"],
            angular_velocity=self.vector(gyro),
            angular_velocity_covariance=cov["gyro"],
            linear_acceleration=self.vector(accel),
            linear_acceleration_covariance=cov["accel"],
        )

    def odometry(self, header, child: str, pos, quat, linvel, angvel, cov: dict):
        t = self.t
        point = t["geometry_msgs/msg/Point"](x=float(pos[0]), y=float(pos[1]), z=float(pos[2]))
        pose = t["geometry_msgs/msg/Pose"](position=point, orientation=self.quaternion(quat))
        twist = t["geometry_msgs/msg/Twist"](linear=self.vector(linvel), angular=self.vector(angvel))
        return t["nav_msgs/msg/Odometry"](
            header=header,
            child_frame_id=child,
            pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov["pose"]),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov["twist"]),
        )

    def joint_state(self, header, names, position, velocity):
        # effort stays empty (allowed by sensor_msgs/JointState): the core does not record torques.
        return self.t["sensor_msgs/msg/JointState"](
            header=header,
            name=list(names),
            position=np.asarray(position, dtype=np.float64),
            velocity=np.asarray(velocity, dtype=np.float64),
            effort=np.zeros(0),
        )

    def contacts(self, header, touching: bool, force, pos, normal, collision1: str, seconds: float):
        t = self.t
        states = []
        if touching:
            wrench = t["geometry_msgs/msg/Wrench"](force=self.vector(force), torque=self.vector((0, 0, 0)))
            states.append(t["gazebo_msgs/msg/ContactState"](
                info=f"Debug:  i:(0/1)     my geom:{collision1}   other geom:{GROUND_COLLISION}   "
                     f"time:{seconds:.9f}",
                collision1_name=collision1,
                collision2_name=GROUND_COLLISION,
                wrenches=[wrench],
                total_wrench=wrench,
                contact_positions=[self.vector(pos)],
                contact_normals=[self.vector(normal)],
                depths=np.zeros(0),  # not recorded by the core
            ))
        return t["gazebo_msgs/msg/ContactsState"](header=header, states=states)

    def clock(self, seconds: float):
        return self.t["rosgraph_msgs/msg/Clock"](clock=self.stamp(seconds))


def _covariances(sensors) -> dict:
    """Diagonal covariances from the noise standard deviations, as gazebo_ros_imu/p3d fill them."""
    diag3 = lambda std: np.diag([std**2] * 3).reshape(-1)
    diag6 = lambda lin, ang: np.diag([lin**2] * 3 + [ang**2] * 3).reshape(-1)
    return {
        "orientation": diag3(sensors.orientation_noise),
        "gyro": diag3(sensors.gyro_noise),
        "accel": diag3(sensors.accel_noise),
        # p3d has no orientation noise of its own; its pose orientation is exact here too.
        "pose": diag6(sensors.odom_pos_noise, 0.0),
        "twist": diag6(sensors.odom_vel_noise, sensors.odom_vel_noise),
    }


def messages(rec: Recording, instances: list[int], store, ros1: bool) -> Iterator[tuple[str, str, float, object]]:
    """(topic, msgtype, time s, message) of every stream of the chosen instances, then /clock."""
    b = _Builder(store, ros1)
    traj, cov = rec.traj, _covariances(rec.sensors)
    collision1 = f"{ROBOT}::{CONTACT_LINK}::foot_collision"
    for i in instances:
        topics = topic_names(None if len(instances) == 1 else i)
        prefix = frame_prefix(None if len(instances) == 1 else i)
        base = prefix + "base"
        for k, t in enumerate(traj.time["imu"]):
            header = b.header(k, t, base)
            msg = b.imu(header, traj.imu.quat[i, k], traj.imu.gyro[i, k], traj.imu.accel[i, k], cov)
            yield topics["imu"], MSGTYPES["imu"], t, msg
        for k, t in enumerate(traj.time["odom"]):
            o = traj.odom
            msg = b.odometry(b.header(k, t, "world"), base, o.pos[i, k], o.quat[i, k], o.linvel[i, k],
                             o.angvel[i, k], cov)
            yield topics["odom"], MSGTYPES["odom"], t, msg
        qadr, dadr = list(rec.joint_qpos), list(rec.joint_dof)
        for k, t in enumerate(traj.time["state"]):
            msg = b.joint_state(b.header(k, t, ""), rec.joint_names,
                                traj.qpos[i, k, qadr], traj.qvel[i, k, dadr])
            yield topics["joint_states"], MSGTYPES["joint_states"], t, msg
        for k, t in enumerate(traj.time["contact"]):
            c = traj.contact
            msg = b.contacts(b.header(k, t, "world"), bool(c.flag[i, k]), c.force[i, k], c.pos[i, k],
                             rec.floor_normal, collision1, t)
            yield topics["contact"], MSGTYPES["contact"], t, msg
    for t in rec.clock_time:
        yield "/clock", MSGTYPES["clock"], t, b.clock(t)


# -- bag files -------------------------------------------------------------------------------
def definition(store, msgtype: str, ros1: bool) -> dict:
    """add_connection's keywords: for ROS 1, ROS's own definition text (with its comments, which
    rosbags' generated text lacks) and the md5 sum, which ignores comments; for ROS 2, the type store."""
    if not ros1:
        return {"typestore": store}
    return {"msgdef": msgdefs.full_text(msgtype), "md5sum": store.generate_msgdef(msgtype, ros_version=1)[1]}


def write(rec: Recording, out: str | Path, fmt: str, instances: list[int] | None = None) -> Path:
    """Writes the chosen instances (default: all) as a ROS 1 .bag file or a ROS 2 MCAP bag folder."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; choose from: {', '.join(FORMATS)}")
    n = rec.gravity.shape[0]
    instances = list(range(n)) if instances is None else list(instances)
    if not instances:
        raise ValueError("no instances chosen to record")
    bad = [i for i in instances if not 0 <= i < n]
    if bad:
        raise ValueError(f"instances {bad} out of range: the batch has {n} (0..{n - 1})")
    if len(set(instances)) != len(instances):
        raise ValueError(f"instances listed twice: {instances}")
    out = Path(out)
    if out.exists():
        raise ValueError(f"{out} exists; remove it or choose another --out")
    if fmt == "mcap" and out.suffix == ".mcap":
        raise ValueError(f"--format mcap writes a ROS 2 bag folder (holding the .mcap file): "
                         f"give a folder name such as {out.stem}_mcap, not {out.name}")
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
    with writer:
        connections = {}
        for topic, msgtype, t, msg in msgs:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, **definition(store, msgtype, ros1))
            writer.write(connections[topic], int(round(t * 1e9)), serialize(msg, msgtype))
    return out


def parse_indices(text: str) -> list[int]:
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--instances must be comma-separated integers, got {text!r}") from None


def parser() -> argparse.ArgumentParser:
    # Built on simulate's options, so that controller options added there work here too.
    p = argparse.ArgumentParser(prog="python -m hopper_mjx.record", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                parents=[simulate.parser()], conflict_handler="resolve")
    p.add_argument("--gravity", type=lambda s: simulate.parse_floats(s, "--gravity"), default=[9.81],
                   help="gravity magnitudes in m/s², pointing down, one instance each (x --num)")
    p.add_argument("--duration", type=float, default=2.0, help="simulated time, s")
    p.add_argument("--rate", type=float, default=50.0, help="Hz of every stream without its own rate (the seed's 50)")
    for stream, what in (("imu", "/imu/data"), ("odom", "/odom"), ("contact", "contact state"),
                         ("joint", "/joint_states")):
        p.add_argument(f"--{stream}-rate", type=float, default=None, help=f"Hz of {what} (default: --rate)")
    p.add_argument("--instances", type=parse_indices, default=None,
                   help="comma-separated instance indices to record (default: all)")
    p.add_argument("--format", choices=FORMATS, default="ros1",
                   help="ros1: a .bag file (ROS 1 Melodic/Noetic); mcap: a ROS 2 bag folder holding one .mcap")
    p.add_argument("--out", default=None, help="output path (default: monoped.bag or monoped_mcap/)")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    out = args.out or ("monoped.bag" if args.format == "ros1" else "monoped_mcap")
    runtime.configure()
    try:
        if Path(out).exists():  # before the simulation, not after it
            raise ValueError(f"{out} exists; remove it or choose another --out")
        rec = simulate_batch(args)
        path = write(rec, out, args.format, args.instances)
    except ValueError as err:  # includes URDFError
        print(f"error: {err}", file=sys.stderr)
        return 2
    simulate.warn_diverged(rec.diverged)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
