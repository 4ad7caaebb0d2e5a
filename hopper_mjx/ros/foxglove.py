"""The seed's ROS topics, live over the Foxglove WebSocket protocol (foxglove-sdk).

    stream = FoxgloveStream.start(port, instances=[0, 1, 2])   # before any model is built
    stream.attach(batch)                                       # a hopper_mjx.live.LiveBatch
    LiveRun(batch, sinks=[stream]) ...

The channels are the topics `record` writes (`/monoped/imu/data`, `/odom`,
`/monoped/joint_states`, `/lowerleg_contactsensor_state`, `/clock`, or `/monoped_<i>/...` for
several instances), each with its ROS 1 message definition as the schema (`ros1msg`) and
ROS 1-serialised messages, so Foxglove decodes them as it decodes a ROS 1 bag or a live
rosbridge. `/tf` adds what robot_state_publisher and the odometry's frame would give a ROS
user: world -> base and each link from its parent (the URDF's link frames, tf-prefixed like
the topics), at the joint-state rate, so that Foxglove's 3D panel can pose the URDF. On a
terrain, `/terrain` carries the ground as one triangle-list marker (visualization_msgs/Marker),
sent again with every chunk so that a client that joins late draws it too.
Messages are built from the played chunks by `messages.messages` and published as their
stamps fall due, with the server's time (the Time capability) following simulated time.
A chunk is serialised only while some client is subscribed to one of its channels.
"""

from __future__ import annotations

import dataclasses
from contextlib import contextmanager

import numpy as np

from hopper_mjx import cli
from hopper_mjx.ros import messages, record

TF_TOPIC = "/tf"
TF_MSGTYPE = "tf2_msgs/msg/TFMessage"
TF_DEFINITION = "geometry_msgs/TransformStamped[] transforms\n"  # ROS 1 tf2_msgs, not in rosbags' store


class PortError(ValueError):
    """The port cannot be listened on (in use, or not allowed)."""


def link_transforms(mj_model, data, qpos: np.ndarray) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """(parent frame, child frame, position m, quaternion [w, x, y, z]) of every robot link
    relative to its parent ("world" for the base) at `qpos` (nq,), computed in `data` (an
    MjData of `mj_model`): MuJoCo's body frames are the URDF's link frames."""
    import mujoco

    data.qpos[:] = qpos
    mujoco.mj_kinematics(mj_model, data)
    out = []
    for body in range(1, mj_model.nbody):
        parent = mj_model.body_parentid[body]
        pos, quat = data.xpos[body].copy(), data.xquat[body].copy()
        if parent:
            inverse = np.zeros(4)
            mujoco.mju_negQuat(inverse, data.xquat[parent])
            mujoco.mju_rotVecQuat(pos, data.xpos[body] - data.xpos[parent], inverse)
            mujoco.mju_mulQuat(quat, inverse, data.xquat[body])
        out.append((mj_model.body(parent).name if parent else "world", mj_model.body(body).name, pos, quat))
    return out


class FoxgloveStream:
    """A Foxglove WebSocket server publishing the chosen instances' topics."""

    def __init__(self, server, context, instances: list[int]):
        from rosbags.typesys import get_types_from_msg

        self.server, self.context, self.instances = server, context, list(instances)
        self.store = messages.typestore("ros1")
        self.store.register(get_types_from_msg(TF_DEFINITION, TF_MSGTYPE))
        self.channels: dict[str, object] = {}
        self.batch = None
        self._messages: dict[int, list[tuple[float, str, bytes]]] = {}  # id(chunk) -> its messages
        self._terrain: bytes | None = None  # the ground's marker, serialised once (tens of thousands of points)

    @classmethod
    def start(cls, port: int, instances: list[int], host: str = "127.0.0.1") -> FoxgloveStream:
        """Listens on `port` (0: any free port); raises PortError if that is impossible."""
        import foxglove
        from foxglove.websocket import Capability

        context = foxglove.Context()
        try:
            server = foxglove.start_server(name="hopper_mjx", host=host, port=port, context=context,
                                           capabilities=[Capability.Time])
        except RuntimeError as err:
            reason = str(err).split(": ", 1)[-1]
            raise PortError(f"--foxglove cannot listen on {host}:{port}: {reason}") from None
        return cls(server, context, instances)

    @property
    def port(self) -> int:
        return self.server.port

    def attach(self, batch) -> None:
        """Advertises the channels of `batch` (a LiveBatch) for the instances chosen at start."""
        import foxglove

        bad = [i for i in self.instances if not 0 <= i < batch.n]
        if bad:
            raise ValueError(f"instances {bad} out of range: the batch has {batch.n}")
        self.batch = batch
        single = len(self.instances) == 1
        names = [messages.topic_names(None if single else i) for i in self.instances]
        topics = {t: messages.MSGTYPES[kind] for n in names for kind, t in n.items()}
        topics["/clock"] = messages.MSGTYPES["clock"]
        topics[TF_TOPIC] = TF_MSGTYPE
        corners = record.terrain_triangles(batch.sim.mj_model)
        if corners is not None:
            msgtype = messages.MSGTYPES["terrain"]
            build = messages._Builder(self.store, ros1=True)
            marker = build.terrain(build.header(0, 0.0, "world"), corners)
            self._terrain = bytes(self.store.serialize_ros1(marker, msgtype))
            topics[messages.TERRAIN_TOPIC] = msgtype
        for topic, msgtype in topics.items():
            text, _ = self.store.generate_msgdef(msgtype, ros_version=1)
            schema = foxglove.Schema(name=msgtype.replace("/msg/", "/"), encoding="ros1msg", data=text.encode())
            self.channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding="ros1",
                                                    context=self.context)

    def _chunk_messages(self, chunk) -> list[tuple[float, str, bytes]]:
        key = id(chunk)
        if key not in self._messages:
            self._messages = {}  # only the chunk playing is kept
            batch = self.batch
            rec = record.recording(batch.sim, chunk.traj, batch.gravity, batch.sensors, chunk.diverged)
            rec = dataclasses.replace(rec, terrain=None)  # sent from its serialised copy below
            out = [(t, topic, bytes(self.store.serialize_ros1(msg, msgtype)))
                   for topic, msgtype, t, msg in messages.messages(rec, self.instances, self.store, ros1=True,
                                                                    first_seq=chunk.first_seq)]
            out += self._tf_messages(chunk)
            if self._terrain is not None:
                out.append((float(rec.clock_time[0]), messages.TERRAIN_TOPIC, self._terrain))
            out.sort(key=lambda m: m[0])
            self._messages[key] = out
        return self._messages[key]

    def _tf_messages(self, chunk) -> list[tuple[float, str, bytes]]:
        """One /tf message per joint-state instant, holding every streamed instance's links."""
        import mujoco

        build = messages._Builder(self.store, ros1=True)
        types = self.store.types
        mj_model = self.batch.sim.mj_model
        data = mujoco.MjData(mj_model)
        out = []
        for k, t in enumerate(chunk.traj.time["state"]):
            seq = chunk.first_seq["state"] + k
            transforms = []
            for i in self.instances:
                prefix = messages.frame_prefix(None if len(self.instances) == 1 else i)
                for parent, child, pos, quat in link_transforms(mj_model, data, chunk.traj.qpos[i, k]):
                    transform = types["geometry_msgs/msg/Transform"](
                        translation=build.vector(pos), rotation=build.quaternion(quat))
                    frame = "world" if parent == "world" else prefix + parent
                    transforms.append(types["geometry_msgs/msg/TransformStamped"](
                        header=build.header(seq, t, frame), child_frame_id=prefix + child, transform=transform))
            msg = types[TF_MSGTYPE](transforms=transforms)
            out.append((float(t), TF_TOPIC, bytes(self.store.serialize_ros1(msg, TF_MSGTYPE))))
        return out

    def __call__(self, chunk, t_from: float, t_to: float) -> None:
        """Publishes the messages of `chunk` stamped in [t_from, t_to) (a LiveRun sink)."""
        self.server.broadcast_time(round(t_from * 1e9))
        if not any(channel.has_sinks() for channel in self.channels.values()):
            return
        eps = 1e-9  # stamps are whole steps x timestep: equal instants are equal floats, but be safe
        for t, topic, data in self._chunk_messages(chunk):
            if t_from - eps <= t < t_to - eps:
                self.channels[topic].log(data, log_time=round(t * 1e9))

    def close(self) -> None:
        self.server.stop()


@contextmanager
def listening(args, instances: list[int]):
    """The stream `--foxglove` asks for (None without it), listening while the block runs.
    Checks the live options first; a busy port raises PortError before anything is built."""
    cli.check_live(args)
    if args.foxglove is None:
        yield None
        return
    stream = FoxgloveStream.start(args.foxglove, instances)
    try:
        yield stream
    finally:
        stream.close()
