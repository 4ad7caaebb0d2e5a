"""The ROS messages of a recording: topics, types (with gazebo_msgs) and message objects.

One recorded instance publishes under the seed's names; with several, instance i
publishes under /monoped_<i>/ with frames prefixed monoped_<i>/ (see `topic_names`).
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from hopper_mjx.ros import msgdefs

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
    "terrain": "visualization_msgs/msg/Marker",
}
TERRAIN_TOPIC = "/terrain"  # the ground as one triangle-list marker in the world frame (rviz and Foxglove draw it)
TERRAIN_COLOUR = (0.55, 0.47, 0.36, 1.0)  # RGBA: earth


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

    def joint_state(self, header, names, position, velocity, effort=()):
        # effort: the torques the motors applied (N·m); empty where none were recorded, as JointState allows.
        return self.t["sensor_msgs/msg/JointState"](
            header=header,
            name=list(names),
            position=np.asarray(position, dtype=np.float64),
            velocity=np.asarray(velocity, dtype=np.float64),
            effort=np.asarray(effort, dtype=np.float64),
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

    def terrain(self, header, corners: np.ndarray):
        """The ground's triangles (`corners` (3 K, 3) m, world) as a visualization_msgs/Marker TRIANGLE_LIST."""
        t = self.t
        cls = t["visualization_msgs/msg/Marker"]
        point = t["geometry_msgs/msg/Point"]
        identity = t["geometry_msgs/msg/Pose"](position=point(x=0.0, y=0.0, z=0.0),
                                                 orientation=self.quaternion((1.0, 0.0, 0.0, 0.0)))
        extra = {}  # ROS 2's Marker has texture and mesh-file fields that ROS 1's lacks: left empty
        if "texture" in cls.__dataclass_fields__:
            empty = np.zeros(0, dtype=np.uint8)
            extra = {"texture_resource": "", "uv_coordinates": [],
                     "texture": t["sensor_msgs/msg/CompressedImage"](header=header, format="", data=empty),
                     "mesh_file": t["visualization_msgs/msg/MeshFile"](filename="", data=empty)}
        return cls(
            header=header, ns="terrain", id=0, type=11, action=0, pose=identity,  # 11: TRIANGLE_LIST, 0: ADD
            scale=self.vector((1.0, 1.0, 1.0)), color=t["std_msgs/msg/ColorRGBA"](*TERRAIN_COLOUR),
            lifetime=t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False,
            points=[point(x=float(x), y=float(y), z=float(z)) for x, y, z in corners], colors=[], text="",
            mesh_resource="", mesh_use_embedded_materials=False, **extra)

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


def messages(rec, instances: list[int], store, ros1: bool,
             first_seq: dict[str, int] | None = None) -> Iterator[tuple[str, str, float, object]]:
    """(topic, msgtype, time s, message) of every stream of the chosen instances, then /clock.
    `first_seq`: the ROS 1 header seq of each stream's first sample ("imu", "odom", "state",
    "contact"; 0 if absent), so that a run published in pieces counts on from piece to piece."""
    b = _Builder(store, ros1)
    seq0 = {"imu": 0, "odom": 0, "state": 0, "contact": 0, **(first_seq or {})}
    traj, cov = rec.traj, _covariances(rec.sensors)
    collision1 = f"{ROBOT}::{CONTACT_LINK}::foot_collision"
    for i in instances:
        topics = topic_names(None if len(instances) == 1 else i)
        prefix = frame_prefix(None if len(instances) == 1 else i)
        base = prefix + "base"
        for k, t in enumerate(traj.time["imu"]):
            header = b.header(seq0["imu"] + k, t, base)
            msg = b.imu(header, traj.imu.quat[i, k], traj.imu.gyro[i, k], traj.imu.accel[i, k], cov)
            yield topics["imu"], MSGTYPES["imu"], t, msg
        for k, t in enumerate(traj.time["odom"]):
            o = traj.odom
            msg = b.odometry(b.header(seq0["odom"] + k, t, "world"), base, o.pos[i, k], o.quat[i, k], o.linvel[i, k],
                             o.angvel[i, k], cov)
            yield topics["odom"], MSGTYPES["odom"], t, msg
        qadr, dadr = list(rec.joint_qpos), list(rec.joint_dof)
        torque = not isinstance(getattr(traj, "torque", ()), tuple)  # a trajectory of the core records it
        for k, t in enumerate(traj.time["state"]):
            msg = b.joint_state(b.header(seq0["state"] + k, t, ""), rec.joint_names,
                                traj.qpos[i, k, qadr], traj.qvel[i, k, dadr], traj.torque[i, k] if torque else ())
            yield topics["joint_states"], MSGTYPES["joint_states"], t, msg
        for k, t in enumerate(traj.time["contact"]):
            c = traj.contact
            msg = b.contacts(b.header(seq0["contact"] + k, t, "world"), bool(c.flag[i, k]), c.force[i, k], c.pos[i, k],
                             rec.floor_normal, collision1, t)
            yield topics["contact"], MSGTYPES["contact"], t, msg
    if rec.terrain is not None:  # once, at the first instant: the ground does not move
        t0 = float(rec.clock_time[0])
        yield TERRAIN_TOPIC, MSGTYPES["terrain"], t0, b.terrain(b.header(0, t0, "world"), rec.terrain)
    for t in rec.clock_time:
        yield "/clock", MSGTYPES["clock"], t, b.clock(t)


