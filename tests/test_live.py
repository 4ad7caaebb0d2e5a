"""Live runs: the batch played in chunks, the Foxglove stream decoded by ROS's own genpy, and the
viewer driven by key presses under Xvfb, its screenshot checked against the floor-only background.

One batch (Earth, Mars and Moon robots dropped 5 cm under `hold`) is compiled once: the
in-process stream tests compile it, the `view` subprocess loads it from the persistent cache.
"""

import json
import os
import queue
import shutil
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from hopper_mjx import cli, live, simulate
from hopper_mjx.ros.foxglove import FoxgloveStream

pytestmark = pytest.mark.serial  # wall-clock bounds: `make test` runs this file alone

GRAVITY = (9.81, 3.71, 1.62)
ARGS = ["--gravity", ",".join(map(str, GRAVITY)), "--controller", "hold"]
SETTLED = 1.0  # s: the dropped robots stand still by then (touchdown <= 0.25 s)
LANDED = 0.3  # s: every robot is on the floor
QUICK_RETRY = 5.0  # s after which a key press the viewer's status does not show is pressed again
QUIT_WITHIN = 5.0  # s from ctrl+q to the viewer's exit (0.5-0.8 s measured; 10.3-10.8 s before 7 Dec's fix)
PERIOD_NS = 20_000_000  # the seed's 50 Hz on every stream
ROBOT_BLUE = np.array([51, 97, 166])  # model.scene.LINK_COLOURS["base"] in 8-bit RGB


@pytest.fixture(scope="module")
def batch():
    return live.LiveBatch.build(cli.check_batch(simulate.parser().parse_args(ARGS)))


# -- pacing and hop counting, without physics ----------------------------------------------
class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_pacer_maps_simulated_time_to_wall_time_at_the_factor_and_falls_back_when_behind():
    clock = FakeClock()
    pacer = live.Pacer(2.0, clock=clock)
    pacer.rebase(1.0)
    assert pacer.wait(1.5) == pytest.approx(0.25)  # 0.5 s simulated at x2
    clock.now += 0.25
    assert pacer.wait(1.5) == pytest.approx(0.0) and pacer.due() == pytest.approx(1.5)
    for k in range(11):  # play 1 simulated second over 0.5 s of wall time
        clock.now = 100.25 + 0.05 * k
        pacer.played(1.5 + 0.1 * k, 1000 * k)
    factor, steps = pacer.reached()
    assert factor == pytest.approx(2.0) and steps == pytest.approx(20_000)
    clock.now += 1.0  # the batch fell behind: it plays on from where it is, and the factor shows the lag
    assert pacer.wait(2.5) == pytest.approx(-1.0)  # due: 1.0 + 1.75 s x2
    pacer.fall_back(2.5)
    assert pacer.wait(3.0) == pytest.approx(0.25)
    clock.now += 0.25
    pacer.played(3.0, 15_000)
    assert pacer.reached()[0] == pytest.approx((3.0 - 1.5) / 1.75)  # measured on over the stall
    pacer.rebase(3.0)  # a resume or a new factor starts the measurement afresh
    assert pacer.reached()[0] != pacer.reached()[0]  # nan


def test_hops_count_completed_flights_not_the_initial_drop_and_a_fall_latches():
    counter = live.HopCounter(3)
    standing = np.array([[0.0, 0, 0.9, 1, 0, 0, 0]] * 3)
    # robot 0: drop, land, hop, land; robot 1: drop and land; robot 2: lies on the floor
    flags = np.array([[0, 0, 1, 1, 0, 0, 1], [0, 0, 1, 1, 1, 1, 1], [0, 1, 1, 1, 1, 1, 1]], bool)
    lying = standing.copy()
    lying[2, 2] = 0.2
    status = counter.update(flags[:, :4], standing, np.zeros(3, bool))
    assert counter.hops.tolist() == [0, 0, 0] and status == ("standing",) * 3
    status = counter.update(flags[:, 4:], lying, np.array([False, False, False]))
    assert counter.hops.tolist() == [1, 0, 0]
    assert status == ("hopping", "standing", "fallen")
    status = counter.update(np.ones((3, 2), bool), standing, np.array([False, True, False]))
    assert status == ("hopping", "diverged", "fallen")  # a fall latches until the reset


# -- commands and kicks (no rollout) -----------------------------------------------------------
def test_arrow_key_commands_reach_every_raibert_instance_and_survive_a_reset():
    args = simulate.parser().parse_args(["--gravity", "9.81,1.62", "--num", "2", "--controller", "raibert",
                                         "--height", "0.1", "--speed", "0.2,0"])
    raibert = live.LiveBatch.build(cli.check_batch(args))
    assert raibert.command() == {"speed": pytest.approx((0.2, 0.0)), "height": pytest.approx(0.1)}
    assert raibert.change_command(speed_step=(live.SPEED_STEP, 0.0))
    assert raibert.change_command(height_step=-2 * live.HEIGHT_STEP)
    raibert.reset()
    params = raibert.state.cstate.params
    np.testing.assert_allclose(np.asarray(params.speed), [[0.3, 0.0]] * 4, atol=1e-6)
    np.testing.assert_allclose(np.asarray(params.height), [0.06] * 4, atol=1e-6)


def test_hold_takes_no_commands_and_a_kick_changes_one_base_velocity(batch):
    assert not batch.change_command(speed_step=(0.1, 0.0))
    before = np.asarray(batch.state.data.qvel).copy()
    batch.kick(1)
    after = np.asarray(batch.state.data.qvel)
    want = before.copy()
    want[1, 1] += live.KICK_SPEED
    np.testing.assert_array_equal(after, want)
    batch.reset()
    assert not np.asarray(batch.state.data.qvel).any()


def test_a_slow_caller_lowers_the_frame_rate_not_the_real_time_factor(batch):
    """Polled every 0.4525 s of (fake) wall time, as by a window drawing 2 frames a second, the run
    still plays all the 0.905 s of simulated time due at x2, over several chunks per poll."""
    clock = FakeClock()
    batch.reset()
    run = live.LiveRun(batch, factor=2.0, clock=clock)
    dt = batch.sim.layout.timestep
    with run:
        while run.poll() is None:  # the first chunk: play starts at simulated time 0
            time.sleep(0.01)
        for frame in (1, 2):
            clock.now += 0.4525
            while batch.steps_done * dt < 0.905 * frame + live.CHUNK_TIME:  # the producer catches up
                time.sleep(0.01)
            chunk, index = run.poll()
            assert chunk.clock[index] == pytest.approx(0.9 * frame)  # the last instant due (every 20 ms)
            assert run.played_until == pytest.approx(0.9 * frame + 0.02)  # played up to the next one
    assert run.error is None
    assert run.chunk_seconds and len(run.chunk_seconds) >= 19


# -- Foxglove stream ---------------------------------------------------------------------
def xyz(v):
    return [v.x, v.y, v.z]


def compose(frames: dict, child: str) -> np.ndarray:
    """World position (m) of a frame's origin, chaining the TransformStamped parents up to world."""
    from scipy.spatial.transform import Rotation

    point = np.zeros(3)
    while child != "world":
        t = frames[child].transform
        rotation = Rotation.from_quat([t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w])
        point = rotation.apply(point) + xyz(t.translation)
        child = frames[child].header.frame_id
    return point


def decoder(channel: dict):
    """The genpy message class for an advertised channel, from its ros1msg schema."""
    import genpy.dynamic

    return genpy.dynamic.generate_dynamic(channel["schemaName"], channel["schema"])[channel["schemaName"]]


class Client:
    """A minimal Foxglove WebSocket client: subscribes to topics, collects (log time, message)."""

    def __init__(self, port: int, topics: list[str]):
        from websockets.sync.client import connect

        # close_timeout: the server does not always answer a client's close frame, and websockets waits 10 s for it
        # by default (the second client of the client-leaving test spent that long in close()); a leaver need not wait.
        self.ws = connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], open_timeout=30, close_timeout=1,
                          legacy=True)  # closed by close(), not by a with-block
        self.topics, self.channels, self.types = topics, {}, {}
        self.messages = {t: [] for t in topics}

    def collect(self, until, timeout: float = 180.0) -> None:
        """Receives until `until(self)` holds (or fails after `timeout` s)."""
        deadline = time.monotonic() + timeout
        while not until(self):
            assert time.monotonic() < deadline, "the stream stopped sending"
            frame = self.ws.recv(timeout=timeout)
            if isinstance(frame, str):
                self._control(json.loads(frame))
            elif frame[0] == 1:  # message data: opcode, subscription id, log time, payload
                sub, log_time = struct.unpack_from("<IQ", frame, 1)
                topic = self.channels[sub]["topic"]
                msg = self.types[sub]()
                msg.deserialize(frame[13:])
                self.messages[topic].append((log_time, msg))

    def _control(self, msg: dict) -> None:
        if msg["op"] != "advertise":
            return
        subscriptions = []
        for channel in msg["channels"]:
            if channel["topic"] in self.topics:
                sub = len(self.channels)
                self.channels[sub], self.types[sub] = channel, decoder(channel)
                subscriptions.append({"id": sub, "channelId": channel["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def collect_until_closed(self, timeout: float = 180.0) -> None:
        """Receives until the server goes away (the streaming process ended)."""
        from websockets.exceptions import ConnectionClosed

        try:
            self.collect(lambda c: False, timeout=timeout)
        except ConnectionClosed:
            pass

    def latest(self, topic: str) -> float:
        return self.messages[topic][-1][0] * 1e-9 if self.messages[topic] else -1.0

    def close(self) -> None:
        self.ws.close()


@pytest.fixture
def streaming(batch):
    """The batch played at 4x real time into a Foxglove stream on a free port, in a thread. Per test:
    its player must have stopped before another test steps the same batch's Sim from another thread
    (two threads compiling and dispatching on it at once aborted the process once)."""
    stream = FoxgloveStream.start(0, [0, 1, 2])
    batch.reset()
    stream.attach(batch)
    stop = threading.Event()
    run = live.LiveRun(batch, factor=4.0, sinks=[stream])

    def play():
        with run:
            while not stop.is_set():
                run.poll()
                time.sleep(run.seconds_to_next())

    player = threading.Thread(target=play, daemon=True)
    player.start()
    yield stream, run
    stop.set()
    player.join(timeout=60)
    stream.close()
    assert run.error is None


def test_foxglove_stream_carries_the_recorded_topics_decoded_by_genpy(streaming, mj_model):
    from hopper_mjx.model.layout import Layout

    stream, run = streaming
    kinds = {"imu": "/monoped_0/imu/data", "contact": "/monoped_0/lowerleg_contactsensor_state",
             "odom": "/monoped_0/odom", "joints": "/monoped_0/joint_states", "clock": "/clock", "tf": "/tf"}
    mars_contact = "/monoped_1/lowerleg_contactsensor_state"
    client = Client(stream.port, [*kinds.values(), mars_contact])
    try:
        client.collect(lambda c: all(c.latest(t) >= SETTLED + 0.2 for t in c.topics))
    finally:
        client.close()
    types = {c["topic"]: c["schemaName"] for c in client.channels.values()}
    assert types[kinds["imu"]] == "sensor_msgs/Imu" and types["/clock"] == "rosgraph_msgs/Clock"
    assert types[kinds["contact"]] == "gazebo_msgs/ContactsState"
    for topic, msgs in client.messages.items():  # every stream at 50 Hz, stamped in simulated time
        log_times = np.array([t for t, _ in msgs])
        assert (np.diff(log_times) == PERIOD_NS).all(), topic
        assert log_times[-1] - log_times[0] > 3 * live.CHUNK_TIME * 1e9  # several chunks
        headers = [None if topic == "/clock" else m.transforms[0].header if topic == "/tf" else m.header
                   for _, m in msgs]
        stamps = [m.clock if topic == "/clock" else h.stamp for h, (_, m) in zip(headers, msgs)]
        assert [s.to_nsec() for s in stamps] == log_times.tolist(), topic
        if topic != "/clock":  # ROS seq counts on from chunk to chunk
            assert np.diff([h.seq for h in headers]).tolist() == [1] * (len(msgs) - 1), topic

    mass = Layout.of(mj_model).total_mass
    for topic, g in ((kinds["contact"], GRAVITY[0]), (mars_contact, GRAVITY[1])):
        settled = [m for t, m in client.messages[topic] if t * 1e-9 >= SETTLED]
        assert all(m.states for m in settled), "the robot stands on the floor"
        force_z = np.array([m.states[0].total_wrench.force.z for m in settled])
        np.testing.assert_allclose(force_z, mass * g, rtol=0.02)  # the floor carries the weight
    imu = [m for t, m in client.messages[kinds["imu"]] if t * 1e-9 >= SETTLED]
    accel = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for m in imu])
    np.testing.assert_allclose(np.linalg.norm(accel, axis=1), GRAVITY[0], rtol=0.02)  # specific force = g at rest
    assert (accel[:, 2] > 0.95 * GRAVITY[0]).all()  # pointing up in the upright base frame

    # /tf: world -> base is the odometry's pose, and the chain down to the foot ends over the contact point.
    t, tf = next((t, m) for t, m in client.messages["/tf"] if t * 1e-9 >= SETTLED)
    odom = dict(client.messages[kinds["odom"]])[t]
    contact = dict(client.messages[kinds["contact"]])[t].states[0].contact_positions[0]
    frames = {f.child_frame_id: f for f in tf.transforms}
    assert {f.header.frame_id for f in tf.transforms} >= {"world", "monoped_0/base", "monoped_2/lowerleg"}
    foot = compose(frames, "monoped_0/foot")
    base = frames["monoped_0/base"].transform.translation
    assert [base.x, base.y, base.z] == xyz(odom.pose.pose.position)
    assert np.hypot(foot[0] - contact.x, foot[1] - contact.y) < 0.01 and 0 < foot[2] - contact.z < 0.1


def test_a_client_leaving_does_not_stop_the_simulation(streaming):
    stream, run = streaming
    first = Client(stream.port, ["/clock"])
    first.collect(lambda c: len(c.messages["/clock"]) >= 3)
    left_at = first.latest("/clock")
    first.close()
    time.sleep(0.5)
    second = Client(stream.port, ["/clock"])
    try:
        second.collect(lambda c: c.latest("/clock") >= left_at + 1.0)
    finally:
        second.close()
    assert run.time >= left_at + 1.0


def wait_for_line(proc, prefix: str, timeout: float = 240.0) -> str:
    """The first line a process prints on stdout that starts with `prefix`."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if line.startswith(prefix):
            return line
        if not line and proc.poll() is not None:
            break
    pytest.fail(f"{proc.args[2:4]} never printed {prefix!r}: {proc.stderr.read()[-2000:]}")


def test_simulate_streams_live_what_it_saves(tmp_path, batch, monkeypatch):
    """`simulate --foxglove` plays the batch live: every value a client receives is in the .npz.
    Run in this process on this module's compiled batch (the same arguments build the same one)."""
    from hopper_mjx.scenario import Built, Scenario
    from hopper_mjx.shell import jaxsetup

    monkeypatch.setattr(Scenario, "build", lambda self: Built(batch.sim, batch.controller, batch.params))
    monkeypatch.setattr(jaxsetup, "configure", lambda: None)  # done once for the test process
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    out, result = tmp_path / "live.npz", {}
    argv = [*ARGS, "--rate", "50", "--duration", "0.6", "--speed-factor", "2", "--foxglove", str(port),
            "--out", str(out)]
    command = threading.Thread(target=lambda: result.update(code=simulate.main(argv)), daemon=True)
    command.start()
    while command.is_alive():  # until the server listens
        with socket.socket() as probe:
            if probe.connect_ex(("127.0.0.1", port)) == 0:
                break
        time.sleep(0.05)
    client = Client(port, ["/monoped_0/imu/data", "/monoped_2/odom"])
    client.collect_until_closed()
    command.join(timeout=60)
    assert result == {"code": 0}
    saved = np.load(out)
    np.testing.assert_array_equal(saved["time"], np.arange(30) * 0.02)
    imu, odom = client.messages["/monoped_0/imu/data"], client.messages["/monoped_2/odom"]
    assert len(imu) >= 10 and len(odom) >= 10
    for log_time, msg in imu:
        k = round(log_time / PERIOD_NS)
        assert xyz(msg.linear_acceleration) == saved["imu_accel"][0, k].tolist()
    for log_time, msg in odom:
        k = round(log_time / PERIOD_NS)
        assert xyz(msg.pose.pose.position) == saved["odom_pos"][2, k].tolist()


# -- the command line ------------------------------------------------------------------------
@pytest.mark.parametrize("tool", ["view", "simulate"])
def test_a_busy_foxglove_port_is_one_line_on_stderr(tool, capsys):
    import importlib

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code = importlib.import_module(f"hopper_mjx.{tool}").main([*ARGS, "--foxglove", str(port)])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --foxglove cannot listen on 127.0.0.1:") and str(port) in err
    assert len(err.strip().splitlines()) == 1


def test_without_a_display_view_says_so_and_names_render(monkeypatch, capsys):
    from hopper_mjx import view

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert view.main(ARGS) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: view needs a display") and "python -m hopper_mjx.render" in err
    assert len(err.splitlines()) == 1


def test_view_draws_each_robot_over_its_own_copy_of_the_terrain():
    """On a terrain the viewer's display model has one copy of the ground per shown robot, at that robot's
    offset on the display grid: a ray cast down at any (x, y) of a copy (its offset added) meets the height the
    simulated model's ray meets at (x, y), so each robot is drawn on the ground it stands on."""
    import mujoco

    from hopper_mjx import view

    physics = cli.check_batch(simulate.parser().parse_args(
        [*ARGS, "--terrain", "rough:amp=0.05,wavelength=0.3,seed=2,size=2x2"])).physics
    m, qpos_adr, first_body, _ = view.display_model(physics, 4)
    offsets = view.grid_offsets(4, view.spacing(physics))
    grounds = np.flatnonzero(m.geom_type == mujoco.mjtGeom.mjGEOM_HFIELD)
    assert len(grounds) == 4 and view.spacing(physics) == 2.5
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(d.geom_xpos[grounds, :2], offsets)
    sim_model = physics.mj_model
    sim_data = mujoco.MjData(sim_model)
    sim_data.qpos[:2] = 100.0  # the robot out of the rays' way
    mujoco.mj_forward(sim_model, sim_data)
    d.qpos[qpos_adr[:, None] + np.arange(2)] = 100.0
    mujoco.mj_forward(m, d)

    def ground(model, data, x, y):
        geom = np.array([-1], np.int32)
        return 5.0 - mujoco.mj_ray(model, data, np.array([x, y, 5.0]), np.array([0.0, 0, -1]), None, 1, -1, geom)

    rng = np.random.default_rng(0)
    for (ox, oy) in offsets:
        for x, y in rng.uniform(-0.95, 0.95, (10, 2)):
            assert ground(m, d, ox + x, oy + y) == pytest.approx(ground(sim_model, sim_data, x, y), abs=1e-9)
    heights = [ground(sim_model, sim_data, x, y) for x, y in rng.uniform(-0.95, 0.95, (10, 2))]
    assert np.ptp(heights) > 0.02  # rough ground, not a plane


# -- the viewer under Xvfb ------------------------------------------------------------------
def read_xwd(path: Path) -> np.ndarray:
    """(height, width, 3) uint8 RGB of an X window dump (Xvfb -fbdir keeps the screen in one)."""
    raw = path.read_bytes()
    h = struct.unpack(">25I", raw[:100])
    header_size, width, height, byte_order, bits_per_pixel, bytes_per_line, ncolors = (
        h[0], h[4], h[5], h[7], h[11], h[12], h[19])
    assert bits_per_pixel == 32
    pixels = np.frombuffer(raw, np.uint8, count=bytes_per_line * height, offset=header_size + 12 * ncolors)
    pixels = pixels.reshape(height, bytes_per_line)[:, : 4 * width].reshape(height, width, 4)
    return pixels[..., [2, 1, 0]] if byte_order == 0 else pixels[..., [1, 2, 3]]


def blue_mask(img: np.ndarray) -> np.ndarray:
    """Where the image shows the robots' base colour."""
    return np.abs(img.astype(int) - ROBOT_BLUE).max(axis=-1) < 30


def robot_blue(img: np.ndarray) -> int:
    """Pixels of the robots' base colour."""
    return int(blue_mask(img).sum())


def screen_when(screen: Path, ready, timeout: float = 90.0, press=None) -> np.ndarray:
    """The first screen for which `ready(pixels)` holds: the window draws a few frames a second
    in software GL on a busy machine, so a key's effect shows a frame or more later. `press`
    presses the key again once, after a third of `timeout` (a synthetic key press can be lost)."""
    start = time.monotonic()
    while not ready(pixels := read_xwd(screen)):
        waited = time.monotonic() - start
        assert waited < timeout, f"the screen never changed as expected ({robot_blue(pixels)} robot pixels)"
        if press is not None and waited > timeout / 3:
            press, _ = None, press()
        time.sleep(0.1)
    return pixels


@pytest.fixture
def xvfb(tmp_path):
    if not (shutil.which("Xvfb") and shutil.which("xdotool")):
        pytest.skip("needs Debian's xvfb and xdotool (make installs them when run as root)")
    read, write = os.pipe()
    server = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", "1280x800x24",
                               "-fbdir", str(tmp_path), "-nolisten", "tcp"], pass_fds=[write],
                              stderr=subprocess.DEVNULL)
    os.close(write)
    with os.fdopen(read) as f:
        display = f":{f.readline().strip()}"
    yield display, tmp_path / "Xvfb_screen0"
    server.terminate()
    server.wait(timeout=10)


class Viewer:
    """`python -m hopper_mjx.view` on an Xvfb display, driven with xdotool key presses."""

    def __init__(self, display: str, args: list[str]):
        self.env = {**os.environ, "DISPLAY": display}
        self.proc = subprocess.Popen([sys.executable, "-u", "-m", "hopper_mjx.view", *args], env=self.env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.window = None
        self.lines: queue.Queue = queue.Queue()  # stdout, read on a thread so that a wait can time out
        self.reader = threading.Thread(target=lambda: [self.lines.put(line) for line in self.proc.stdout],
                                       daemon=True)
        self.reader.start()

    def wait_for(self, prefix: str, timeout: float = 240.0) -> str | None:
        """The next stdout line starting with `prefix`, or None after `timeout` seconds."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=left)
            except queue.Empty:
                break
            if line.startswith(prefix):
                return line
        if self.proc.poll() is not None:
            pytest.fail(f"the viewer exited: {self.proc.stderr.read()[-2000:]}")
        return None

    def rest(self) -> str:
        """Everything it printed on stdout since the last line read (after it has exited)."""
        self.reader.join(timeout=30)
        lines = []
        while not self.lines.empty():
            lines.append(self.lines.get())
        return "".join(lines)

    def find_window(self) -> str:
        """The viewer's X window (looked up once: the search takes a while on a loaded machine)."""
        if self.window is None:
            found = subprocess.run(["xdotool", "search", "--sync", "--name", "MuJoCo"], env=self.env,
                                   capture_output=True, text=True, timeout=60)
            self.window = found.stdout.split()[0]
        return self.window

    def key(self, *keys: str) -> None:
        self.find_window()
        for key in keys:
            subprocess.run(["xdotool", "key", "--window", self.window, key], env=self.env, check=True)
            time.sleep(0.3)

    def status(self) -> dict:
        """The viewer's status line (F8), pressed again if a press is lost."""
        for _ in range(5):
            while not self.lines.empty():  # drop a late answer to an earlier press
                self.lines.get()
            self.key("F8")
            if (line := self.wait_for("{", timeout=30.0)) is not None:
                return json.loads(line)
        pytest.fail("the viewer answered none of five status keys")

    def press_until(self, key: str, ready, retry_after: float = 45.0, timeout: float = 240.0,
                    received=None) -> dict:
        """Presses `key`, then the first status for which `ready(status)` holds. A key whose effect has not
        shown after `retry_after` seconds is pressed again: Xvfb has once dropped a synthetic key press
        on a loaded CI machine (the step key, 1 Dec), and a lost press is the X server's, not the viewer's.
        `received(status)`: the viewer has the press though its effect has not shown yet; a press it shows is
        waited for, never pressed again (a second Enter would play a second instant)."""
        deadline = time.monotonic() + timeout
        arrived = ready if received is None else (lambda s: ready(s) or received(s))
        while True:
            self.key(key)
            try:
                status = self.status_when(arrived, timeout=min(retry_after, deadline - time.monotonic()))
            except AssertionError:
                if time.monotonic() >= deadline:
                    raise
                continue
            return status if ready(status) else self.status_when(ready, timeout=deadline - time.monotonic())

    def status_when(self, ready, timeout: float = 240.0) -> dict:
        """The first status for which `ready(status)` holds (simulated time, not wall time:
        a loaded machine plays slower than real time)."""
        deadline = time.monotonic() + timeout
        while not ready(status := self.status()):
            assert time.monotonic() < deadline, f"view stuck at {status}"
            time.sleep(0.2)
        return status


def test_view_shows_the_robots_labelled_with_their_gravity_and_obeys_its_keys(xvfb, tmp_path):
    display, screen = xvfb
    # At real time: `hold` keeps a robot up for about 3 s at Earth, so the pause after LANDED must come within that
    # (at 4x real time it had 0.7 s of wall time, and a loaded machine once took longer: the robot showed "fallen").
    viewer = Viewer(display, ARGS)
    try:
        assert viewer.wait_for("view: running") is not None, "the viewer never started"
        viewer.find_window()  # before the race, not in it
        viewer.status_when(lambda s: s["time"] >= LANDED)
        # The status shows a press at once (paused, or an Enter queued), so one it does not show after a few
        # seconds was lost: in `make test`'s serial phase the Enter was lost in each of 4 runs (7 Dec), and
        # waited 45 s for its second press.
        paused = viewer.press_until("space", lambda s: s["paused"], retry_after=QUICK_RETRY)
        stepped = viewer.press_until("Return", lambda s: s["time"] != paused["time"],  # one recorded instant
                                     retry_after=QUICK_RETRY, received=lambda s: s["steps_pending"] > 0)
        shown = screen_when(screen, lambda img: robot_blue(img) > 300)
        viewer.key("2")  # MuJoCo's geom group 2: the robots
        background = screen_when(screen, lambda img: robot_blue(img) == 0, press=lambda: viewer.key("2"))
        viewer.key("2", "Next", "Insert")  # robots back; select instance 1, kick it
        viewer.press_until("space", lambda s: not s["paused"], retry_after=QUICK_RETRY)  # run
        kicked = viewer.status_when(lambda s: s["time"] >= stepped["time"] + 0.4)  # queued chunks, then the kick
        viewer.key("ctrl+q")
        asked_to_quit = time.monotonic()
        viewer.proc.wait(timeout=60)
        quit_in = time.monotonic() - asked_to_quit
        out, err = viewer.rest(), viewer.proc.stderr.read()
    finally:
        if viewer.proc.poll() is None:
            viewer.proc.kill()
    assert viewer.proc.returncode == 0, err[-2000:]
    assert "real-time factor x" in out and "frames/s; per frame: poll" in out
    # Closed, it waits for the window's threads only: it waited 10 s on the process's signal watcher as well.
    assert quit_in < QUIT_WITHIN, f"{quit_in:.1f} s from ctrl+q to the viewer's exit"


    assert paused["paused"] and stepped["time"] == pytest.approx(paused["time"] + 0.02, abs=1e-6)
    assert [i["gravity"] for i in paused["instances"]] == list(GRAVITY)
    labels = [f"{'> ' if k == 0 else ''}g {g:.2f}  {i['hops']} hops"  # landing bounces count as hops
              for k, (g, i) in enumerate(zip(GRAVITY, paused["instances"]))]
    assert [i["label"] for i in paused["instances"]] == labels

    # Where the screen differs from the floor-only background in the robots' colour: three separate
    # figures (the colour leaves out the overlay's numbers, which change between the two screens).
    import matplotlib.image

    matplotlib.image.imsave(tmp_path / "view.png", shown)
    changed = (np.abs(shown.astype(int) - background).max(axis=-1) > 40) & blue_mask(shown)
    columns = np.flatnonzero(changed.sum(axis=0) > 5)
    figures = np.split(columns, np.flatnonzero(np.diff(columns) > 15) + 1)  # apart by more than 15 pixels
    assert len(figures) == len(GRAVITY), f"robot figures at columns {[f.tolist() for f in figures]}"
    assert all(10 <= f[-1] - f[0] <= 60 for f in figures)  # a robot's width at this distance

    vy = [i["base_velocity"][1] for i in kicked["instances"]]
    assert kicked["selected"] == 1 and vy[1] > 0.2 and abs(vy[0]) < 0.05 and abs(vy[2]) < 0.05


def test_the_stream_advertises_the_ground_as_one_marker_a_client_decodes(mj_model):
    """On a terrain, attach advertises /terrain and serialises its marker once: decoded with the
    advertised ROS 1 schema (genpy), it holds MuJoCo's triangles of the compiled ground."""
    import types

    import genpy.dynamic

    from hopper_mjx import model, terrain
    from hopper_mjx.ros import messages, record

    ground = terrain.parse("crater:radius=0.2,depth=0.05,rim=0.01,size=0.6,cell=0.1").terrain()
    hills = model.load(terrain=ground)
    stream = FoxgloveStream.start(0, [0])
    try:
        stream.attach(types.SimpleNamespace(n=1, sim=types.SimpleNamespace(mj_model=hills)))
        channel = stream.channels[messages.TERRAIN_TOPIC]
        text, _ = stream.store.generate_msgdef(messages.MSGTYPES["terrain"], ros_version=1)
        marker = genpy.dynamic.generate_dynamic("visualization_msgs/Marker", text)["visualization_msgs/Marker"]()
        marker.deserialize(stream._terrain)
        flat = FoxgloveStream.start(0, [0])
        flat.attach(types.SimpleNamespace(n=1, sim=types.SimpleNamespace(mj_model=mj_model)))
        assert messages.TERRAIN_TOPIC not in flat.channels and flat._terrain is None
        flat.close()
    finally:
        stream.close()
    assert channel is not None and (marker.type, marker.header.frame_id) == (11, "world")
    corners = np.array([[p.x, p.y, p.z] for p in marker.points])
    np.testing.assert_array_equal(corners, record.terrain_triangles(hills))
    assert len(corners) == 3 * 2 * 6 * 6 and corners[:, 2].min() < -0.04  # 7 x 7 vertices; the bowl's floor
