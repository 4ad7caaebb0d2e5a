"""The seed's ROS topics, live over the Foxglove WebSocket protocol (foxglove-sdk).

    stream = FoxgloveStream.start(port, instances=[0, 1, 2])   # before any model is built
    stream.attach(batch)                                       # a hopper_mjx.live.LiveBatch
    LiveRun(batch, sinks=[stream]) ...

The channels are the topics `record` writes (`/monoped/imu/data`, `/odom`,
`/monoped/joint_states`, `/lowerleg_contactsensor_state`, `/clock`, or `/monoped_<i>/...` for
several instances), each with its ROS 1 message definition as the schema (`ros1msg`) and
ROS 1-serialised messages, so Foxglove decodes them as it decodes a ROS 1 bag or a live
rosbridge. Messages are built from the played chunks by `record.messages` and published as
their stamps fall due, with the server's time (the Time capability) following simulated time.
A chunk is serialised only while some client is subscribed to one of its channels.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hopper_mjx import record

DEFAULT_PORT = 8765


class PortError(ValueError):
    """The port cannot be listened on (in use, or not allowed)."""


def _floor_normal(mj_model, layout) -> np.ndarray:
    import mujoco

    data = mujoco.MjData(mj_model)
    mujoco.mj_kinematics(mj_model, data)
    return data.geom_xmat[layout.floor_geom].reshape(3, 3)[:, 2].copy()  # a plane's normal is its z axis


class FoxgloveStream:
    """A Foxglove WebSocket server publishing the chosen instances' topics."""

    def __init__(self, server, context, instances: list[int]):
        self.server, self.context, self.instances = server, context, list(instances)
        self.store = record.typestore("ros1")
        self.channels: dict[str, object] = {}
        self.template: record.Recording | None = None
        self._messages: dict[int, list[tuple[float, str, bytes]]] = {}  # id(chunk) -> its messages

    @classmethod
    def start(cls, port: int, instances: list[int], host: str = "127.0.0.1") -> FoxgloveStream:
        """Listens on `port` (0: any free port); raises PortError if that is impossible."""
        import foxglove
        from foxglove.websocket import Capability

        if not 0 <= port <= 65535:
            raise PortError(f"--foxglove port must be in 0..65535, got {port}")
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

        from hopper_mjx import model

        sim = batch.sim
        bad = [i for i in self.instances if not 0 <= i < batch.n]
        if bad:
            raise ValueError(f"instances {bad} out of range: the batch has {batch.n}")
        self.template = record.Recording(
            traj=None, gravity=batch.gravity, sensors=batch.sensors,
            joint_names=model.JOINTS,
            joint_qpos=sim.layout.joint_qpos, joint_dof=sim.layout.joint_dof,
            floor_normal=_floor_normal(sim.mj_model, sim.layout), clock_time=None, diverged=None,
        )
        single = len(self.instances) == 1
        names = [record.topic_names(None if single else i) for i in self.instances]
        topics = {t: record.MSGTYPES[kind] for n in names for kind, t in n.items()}
        topics["/clock"] = record.MSGTYPES["clock"]
        for topic, msgtype in topics.items():
            text, _ = self.store.generate_msgdef(msgtype, ros_version=1)
            schema = foxglove.Schema(name=msgtype.replace("/msg/", "/"), encoding="ros1msg", data=text.encode())
            self.channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding="ros1",
                                                    context=self.context)

    def _chunk_messages(self, chunk) -> list[tuple[float, str, bytes]]:
        key = id(chunk)
        if key not in self._messages:
            self._messages = {}  # only the chunk playing is kept
            rec = dataclasses.replace(self.template, traj=chunk.traj, clock_time=chunk.clock,
                                      diverged=chunk.diverged)
            out = [(t, topic, bytes(self.store.serialize_ros1(msg, msgtype)))
                   for topic, msgtype, t, msg in record.messages(rec, self.instances, self.store, ros1=True)]
            out.sort(key=lambda m: m[0])
            self._messages[key] = out
        return self._messages[key]

    def __call__(self, chunk, t_from: float, t_to: float) -> None:
        """Publishes the messages of `chunk` stamped in [t_from, t_to) (a LiveRun sink)."""
        self.server.broadcast_time(int(round(t_from * 1e9)))
        if not any(channel.has_sinks() for channel in self.channels.values()):
            return
        eps = 1e-9  # stamps are t0 + k·timestep: equal instants are equal floats, but be safe
        for t, topic, data in self._chunk_messages(chunk):
            if t_from - eps <= t < t_to - eps:
                self.channels[topic].log(data, log_time=int(round(t * 1e9)))

    def close(self) -> None:
        self.server.stop()
