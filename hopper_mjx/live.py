"""The batch running live: the core advances in compiled chunks, played back against the wall clock.

    batch = LiveBatch.build(scenario)      # Sim, controller, gravities, as simulate builds them
    with LiveRun(batch, factor=1.0, sinks=[stream]) as run:
        while ...:
            sample = run.poll()            # the latest state due now, or None

A producer thread calls `Sim.rollout` for `CHUNK_TIME` of simulated time at a time (one
compile, reused), paced by the wall clock: it stays a chunk ahead of the simulated time due
(`factor` x the wall time since the start). `LiveRun.poll` plays every recorded instant due
since its last call, so how often it is called (the frame rate) does not change the pace.
A rollout call costs ~20 ms of dispatch whatever its length, so the chunks are long
(0.1 s) and the recorded streams carry the motion between them.

User actions (reset, kick, commands) are queued to the producer and act on the state
between two chunks, so they show after the chunks already computed (<= 0.2 s of simulated
time); pause and step act on the playing at once.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

CHUNK_TIME = 0.1  # s of simulated time per compiled call
SHOWN = 16  # instances a live run draws or streams at most
AHEAD = 1  # chunks computed ahead of the simulated time due
MAX_LAG = 0.25  # s of simulated time: a batch further behind the clock plays on at its own pace
KICK_SPEED = 0.5  # m/s, sideways (+y) base velocity impulse of a kick
SPEED_STEP = 0.1  # m/s per arrow key press
HEIGHT_STEP = 0.02  # m per arrow key press


@dataclass(frozen=True)
class Chunk:
    """CHUNK_TIME of the batch, as numpy, with each instance's live status at its end."""

    epoch: int  # bumped by every reset: chunks of an older epoch are stale
    traj: Any  # hopper_mjx.sim.Trajectory, arrays (N, T_stream, ...)
    clock: np.ndarray  # (T,) s, every instant at which some stream was sampled
    hops: np.ndarray  # (N,) int, completed hops (a lift-off followed by a touchdown) since reset
    status: tuple[str, ...]  # per instance: "standing", "hopping", "fallen" or "diverged"
    diverged: np.ndarray  # (N,) bool
    command: dict | None  # {"speed": (vx, vy) m/s, "height": m} of every instance, or None
    first_seq: dict  # stream -> samples of it in the earlier chunks of the run (resets included): ROS seq


def read_command(controller, cstate) -> dict | None:
    """Instance 0's commanded {"speed": (vx, vy) m/s, "height": apex rise m} (all instances share
    them live), or None when the controller takes no commands (none, hold, pid)."""
    if controller.commands is None:
        return None
    speed, rise = controller.commands.read(cstate)
    return {"speed": tuple(float(v) for v in np.asarray(speed[0])), "height": float(rise[0])}


def set_command(controller, cstate, speed, height: float):
    """The controller state with commanded `speed` (vx, vy) m/s and apex rise `height` m for every instance."""
    return controller.commands.write(cstate, speed, max(float(height), 0.0))


def spread(n: int, count: int) -> list[int]:
    """`count` instances spread evenly over a batch of n (gravity-major, so every gravity shows)."""
    return sorted(set(np.linspace(0, n - 1, min(count, n)).round().astype(int).tolist()))


STREAM_OF_FIELD = {"imu": "imu", "odom": "odom", "contact": "contact", "qpos": "state", "qvel": "state",
                   "torque": "state", "ground": "contact"}


def joined(chunks: list[Chunk], end: float):
    """One Trajectory of consecutive chunks, cut before simulated time `end` (s)."""
    import jax

    times = {k: np.concatenate([c.traj.time[k] for c in chunks]) for k in chunks[0].traj.time}
    keep = {k: t < end - 1e-9 for k, t in times.items()}
    fields = {
        field: jax.tree_util.tree_map(lambda *parts, s=stream: np.concatenate(parts, axis=1)[:, keep[s]],
                                      *[getattr(c.traj, field) for c in chunks])
        for field, stream in STREAM_OF_FIELD.items()
    }
    return chunks[0].traj._replace(**fields, time={k: t[keep[k]] for k, t in times.items()})


class HopCounter:
    """Completed hops and status per instance, carried from chunk to chunk."""

    def __init__(self, n: int):
        self.hops = np.zeros(n, dtype=int)
        self.airborne = np.zeros(n, dtype=bool)  # a lift-off was seen and no touchdown yet
        self.last_flag: np.ndarray | None = None  # contact at the last sample seen
        self.fallen = np.zeros(n, dtype=bool)

    def update(self, contact_flag: np.ndarray, qpos_end: np.ndarray, diverged: np.ndarray) -> tuple[str, ...]:
        from hopper_mjx.metrics import hops

        flags = np.asarray(contact_flag, bool)
        if self.last_flag is not None:
            flags = np.concatenate([self.last_flag[:, None], flags], axis=1)
        landed, self.airborne = hops.landings(flags, self.airborne)
        self.hops += np.where(self.fallen, 0, landed)
        self.last_flag = flags[:, -1]
        self.fallen |= hops.fallen(qpos_end)
        return tuple("diverged" if d else "fallen" if f else "hopping" if h else "standing"
                     for d, f, h in zip(diverged, self.fallen, self.hops > 0))


class LiveBatch:
    """A batch of the core and its controller, advanced one chunk at a time."""

    def __init__(self, sim, controller, params, gravity: np.ndarray, *, seed: int = 0, sensors=None,
                 variation: dict | None = None, instances: dict | None = None):
        """variation: each instance's robot ({model field: (N, ...)}); instances: its motors and sensors
        (`Sim.per_instance`), both kept over resets."""
        from hopper_mjx.hardware import signals
        from hopper_mjx.sim import steps_for

        self.sim, self.controller, self.params = sim, controller, params
        self.gravity = np.asarray(gravity, dtype=float)
        self.seed = seed
        self.variation = variation  # each instance's robot, kept over resets
        self.instances = instances or {}
        self.sensors = sensors or signals.SensorConfig()  # the seed's 50 Hz on every stream, as record
        self.steps = steps_for(CHUNK_TIME, sim.layout.timestep, self.sensors)
        self.epoch = 0
        self.samples = {stream: 0 for stream in self.sensors.periods(sim.layout.timestep)}  # over the whole run
        self.reset()

    @classmethod
    def build(cls, scenario, sensors=None) -> LiveBatch:
        """The batch of a `Scenario` (e.g. `cli.check_batch`'s), streams at `sensors`' rates."""
        built = scenario.build()
        return cls(*built, scenario.gravity, seed=scenario.seed, sensors=sensors,
                   variation=scenario.varied(built.sim.mj_model),
                   instances=built.sim.per_instance(scenario.controls(built.sim.mj_model)))

    @property
    def n(self) -> int:
        return len(self.gravity)

    def reset(self) -> None:
        command = self.command() if self.epoch else None
        self.state = self.sim.reset(self.gravity, key=self.seed, controller=self.controller, params=self.params,
                                    variation=self.variation, **self.instances)
        if command is not None:  # a reset keeps the commands the user set
            self._set_command(command["speed"], command["height"])
        self.hop_counter = HopCounter(self.n)
        self.steps_done = 0  # physics steps since the reset
        self.epoch += 1

    def kick(self, instance: int, velocity=(0.0, KICK_SPEED, 0.0)) -> None:
        """Adds `velocity` (m/s, world frame) to the base of one instance."""
        qvel = self.state.data.qvel.at[instance, :3].add(np.asarray(velocity, np.float32))
        self.state = self.state._replace(data=self.state.data.replace(qvel=qvel))

    def command(self) -> dict | None:
        return read_command(self.controller, self.state.cstate)

    def _set_command(self, speed, height: float) -> None:
        cstate = set_command(self.controller, self.state.cstate, speed, height)
        self.state = self.state._replace(cstate=cstate)

    def change_command(self, *, speed_step=(0.0, 0.0), height_step: float = 0.0) -> bool:
        """Shifts every instance's commanded speed and apex rise; False if the controller has none."""
        now = self.command()
        if now is None:
            return False
        self._set_command(np.add(now["speed"], speed_step), now["height"] + height_step)
        return True

    def advance(self) -> Chunk:
        import jax

        self.state, traj = self.sim.rollout(self.state, self.controller, steps=self.steps, sensors=self.sensors)
        # Stamps from a whole step count: the state's float32 clock drifts by microseconds per chunk.
        dt = self.sim.layout.timestep
        periods = self.sensors.periods(dt)
        traj = jax.tree_util.tree_map(np.asarray, traj)._replace(
            time={k: (self.steps_done + np.arange(0, self.steps, p)) * dt for k, p in periods.items()})
        self.steps_done += self.steps
        first_seq = dict(self.samples)
        for stream, stamps in traj.time.items():
            self.samples[stream] += len(stamps)
        diverged = np.asarray(self.state.diverged)
        status = self.hop_counter.update(traj.contact.flag, np.asarray(self.state.data.qpos), diverged)
        return Chunk(
            epoch=self.epoch,
            traj=traj,
            clock=np.unique(np.concatenate(list(traj.time.values()))),
            hops=self.hop_counter.hops.copy(),
            status=status,
            diverged=diverged,
            command=self.command(),
            first_seq=first_seq,
        )


class Pacer:
    """Maps simulated time to wall time at `factor` x real time, and measures what is reached."""

    def __init__(self, factor: float, clock: Callable[[], float] = time.monotonic, span: float = 2.0):
        self.clock = clock
        self.factor = factor
        self.span = span  # s of wall time the reached factor is measured over
        self.window: list[tuple[float, float, int]] = []  # (wall, sim time, steps) of recent instants
        self.rebase(0.0)

    def rebase(self, sim_time: float) -> None:
        """Simulated `sim_time` is due now (at a start, a resume, a reset or a new factor)."""
        self.origin = (self.clock(), sim_time)
        self.window.clear()

    def fall_back(self, sim_time: float) -> None:
        """The batch is behind: `sim_time` is due now, and the measurement goes on (it shows the lag)."""
        self.origin = (self.clock(), sim_time)

    def due(self) -> float:
        """The simulated time due now, s."""
        wall0, sim0 = self.origin
        return sim0 + (self.clock() - wall0) * self.factor

    def wait(self, sim_time: float) -> float:
        """Seconds of wall time until `sim_time` is due (< 0: it is late by that much)."""
        return (sim_time - self.due()) / self.factor

    def played(self, sim_time: float, steps: int) -> None:
        now = self.clock()
        self.window.append((now, sim_time, steps))
        while now - self.window[0][0] > self.span:
            self.window.pop(0)

    def reached(self) -> tuple[float, float]:
        """(real-time factor, instance-steps per second) over the last `span` of play."""
        if len(self.window) < 2:
            return math.nan, math.nan
        (w0, t0, s0), (w1, t1, s1) = self.window[0], self.window[-1]
        if w1 <= w0:
            return math.nan, math.nan
        return (t1 - t0) / (w1 - w0), (s1 - s0) / (w1 - w0)


class LiveRun:
    """Plays a LiveBatch: a producer thread computes chunks, `poll` hands out the instants due.

    The producer keeps the batch up to AHEAD chunks ahead of the simulated time due by the wall
    clock, whatever the caller does between polls; `poll` plays every instant due since the last
    call, over as many chunks as that takes. So a caller that polls seldom (a slow renderer)
    lowers its own frame rate, not the real-time factor; only a batch slower than asked does.

    `sinks` are called as sink(chunk, t_from, t_to) for every played span of simulated time
    [t_from, t_to) (e.g. the Foxglove stream publishing the messages stamped in it).
    """

    def __init__(self, batch: LiveBatch, *, factor: float = 1.0, sinks=(), paused: bool = False,
                 clock: Callable[[], float] = time.monotonic):
        self.batch = batch
        self.pacer = Pacer(factor, clock)
        self.sinks = list(sinks)
        self.paused = paused
        self.steps_pending = 0  # instants to play while paused (the step key)
        self._actions: queue.Queue = queue.Queue()
        self._chunks: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._produce, name="live-batch", daemon=True)
        self.error: BaseException | None = None
        self.chunk: Chunk | None = None  # the chunk playing
        self._next = 0  # index into chunk.clock of the next instant to play
        self.steps_played = 0  # instance-steps since the start
        self.played_until = 0.0  # s: every instant before this simulated time has been played
        self.epoch = batch.epoch
        self.chunk_seconds: list[float] = []  # wall time of each chunk's computation

    # -- lifecycle -----------------------------------------------------------------
    def __enter__(self) -> LiveRun:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=30)

    def _ahead(self) -> bool:
        """Whether the batch is AHEAD chunks past what is due (paused: past what is played)."""
        if self.batch.epoch != self.epoch:  # a reset is queued or has just run: its chunks are due at once
            return False
        produced = self.batch.steps_done * self.batch.sim.layout.timestep
        due = self.played_until if self.paused or self.chunk is None else self.pacer.due()
        return produced - due > AHEAD * CHUNK_TIME

    def _produce(self) -> None:
        try:
            while not self._stop.is_set():
                while True:
                    try:
                        self._actions.get_nowait()(self.batch)
                    except queue.Empty:
                        break
                if self._ahead():
                    self._stop.wait(0.005)
                    continue
                start = time.perf_counter()
                chunk = self.batch.advance()
                self.chunk_seconds.append(time.perf_counter() - start)
                self._chunks.put(chunk)
        except BaseException as err:  # surfaced by poll() on the main thread
            self.error = err

    # -- user actions ----------------------------------------------------------------
    def act(self, action: Callable[[LiveBatch], Any]) -> None:
        """Runs `action(batch)` on the producer thread between two chunks."""
        self._actions.put(action)

    def reset(self) -> None:
        self.act(LiveBatch.reset)
        self.epoch += 1

    def toggle_pause(self) -> None:
        self.paused = not self.paused
        if not self.paused and self.chunk is not None:
            self.pacer.rebase(self.time)

    def step(self) -> None:
        """While paused: play the next recorded instant at once."""
        if self.paused:
            self.steps_pending += 1

    def set_factor(self, factor: float) -> None:
        self.pacer.factor = factor
        if self.chunk is not None:
            self.pacer.rebase(self.time)

    @property
    def time(self) -> float:
        """Simulated time of the last instant played, s."""
        if self.chunk is None:
            return 0.0
        return float(self.chunk.clock[max(self._next - 1, 0)])

    # -- playing ---------------------------------------------------------------------
    def _take_chunk(self) -> bool:
        """Moves on to the next computed chunk of the current epoch; False if none is ready."""
        while True:
            try:
                chunk = self._chunks.get_nowait()
            except queue.Empty:
                return False
            if chunk.epoch >= self.epoch:  # older ones were computed before a reset
                break
        restarted = self.chunk is None or chunk.epoch != self.chunk.epoch
        self.chunk, self._next = chunk, 0
        if restarted:
            self.pacer.rebase(float(chunk.clock[0]))
        return True

    def _due_end(self, chunk: Chunk, start: int) -> int:
        """Index past the instants of `chunk` from `start` that are due now."""
        end = start
        while end < len(chunk.clock) and self.pacer.wait(float(chunk.clock[end])) <= 0:
            end += 1
        return end

    def poll(self) -> tuple[Chunk, int] | None:
        """Plays every instant now due, over as many chunks as needed; returns (chunk, index of the
        last played instant), or None if nothing was due. A batch more than MAX_LAG behind the
        clock plays on from where it is instead of racing to catch up."""
        if self.error is not None:
            raise RuntimeError(f"the live batch stopped: {self.error}") from self.error
        stepping = self.paused and self.steps_pending > 0
        if self.paused and not stepping:
            return None
        last = None
        while True:
            exhausted = self.chunk is None or self._next >= len(self.chunk.clock) or self.chunk.epoch < self.epoch
            if exhausted and not self._take_chunk():
                if self.chunk is not None and -self.pacer.wait(self.played_until) * self.pacer.factor > MAX_LAG:
                    self.pacer.fall_back(self.played_until)
                return last
            chunk, start = self.chunk, self._next
            end = start + 1 if stepping else self._due_end(chunk, start)
            if end == start:
                return last
            self._play(chunk, start, end)
            last = (chunk, end - 1)
            if stepping:
                self.steps_pending -= 1
                return last
            if end < len(chunk.clock):  # the rest of this chunk is not due yet
                return last

    def _play(self, chunk: Chunk, start: int, end: int) -> None:
        dt = self.batch.sim.layout.timestep
        t_to = float(chunk.clock[end]) if end < len(chunk.clock) else float(chunk.clock[0]) + self.batch.steps * dt
        for sink in self.sinks:
            sink(chunk, float(chunk.clock[start]), t_to)
        self._next = end
        self.played_until = t_to
        self.steps_played += self.batch.n * round((t_to - float(chunk.clock[start])) / dt)
        self.pacer.played(t_to, self.steps_played)

    def seconds_to_next(self) -> float:
        """How long the caller may sleep before the next instant is due (<= 0.02 s)."""
        if self.paused or self.chunk is None or self._next >= len(self.chunk.clock):
            return 0.005
        return float(np.clip(self.pacer.wait(float(self.chunk.clock[self._next])), 0.0, 0.02))
