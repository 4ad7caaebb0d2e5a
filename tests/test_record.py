"""ROS recordings: bags written by `record` read back by independent readers, against `simulate`.

One module-wide simulation (two robots, Earth and Moon, dropped 5 cm onto the floor
under `hold`) is written as a ROS 1 bag, a ROS 2 MCAP bag and a single-robot bag;
the same run through `simulate` is the reference for every value.
"""

import dataclasses
import io
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from hopper_mjx import simulate, terrain
from hopper_mjx.model.layout import Layout
from hopper_mjx.ros import echo, msgdefs, plots, record
from hopper_mjx.ros.messages import MSGTYPES, topic_names

GRAVITY = "9.81,1.62"
DURATION = 0.4  # s: both robots touch down within it (Earth at ~0.1 s, Moon at ~0.25 s)
RATES = {"imu": 100, "odom": 50, "contact": 100, "joint_states": 25}  # Hz, different on purpose
REFERENCE_RATE = 100  # Hz of the simulate run; every recorded rate divides it
KINDS = ("imu", "odom", "joint_states", "contact")
TOL = 1e-6
HILLS = terrain.parse("rough:amp=0.03,wavelength=0.2,seed=3,size=0.5x0.3,cell=0.1")  # 4 x 6 vertices


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    args = record.parser().parse_args([
        "--gravity", GRAVITY, "--duration", str(DURATION), "--controller", "hold",
        "--imu-rate", str(RATES["imu"]), "--odom-rate", str(RATES["odom"]),
        "--contact-rate", str(RATES["contact"]), "--joint-rate", str(RATES["joint_states"]),
    ])
    rec = record.simulate_batch(args)
    folder = tmp_path_factory.mktemp("bags")
    hills = dataclasses.replace(rec, terrain=terrain.triangles(HILLS.terrain()))  # the format, not the physics
    return {
        "rec": rec,
        "terrain": record.write(hills, folder / "hills.bag", "ros1"),
        "terrain_mcap": record.write(hills, folder / "hills_mcap", "mcap"),
        "ros1": record.write(rec, folder / "both.bag", "ros1"),
        "mcap": record.write(rec, folder / "both_mcap", "mcap"),
        "single": record.write(rec, folder / "moon.bag", "ros1", instances=[1]),
    }


@pytest.fixture(scope="module")
def saved():
    """The same run as `python -m hopper_mjx.simulate` saves it."""
    args = simulate.parser().parse_args([
        "--gravity", GRAVITY, "--duration", str(DURATION), "--controller", "hold", "--rate", str(REFERENCE_RATE),
    ])
    return simulate.run(args)


# -- independent readers: topic -> msgtype, topic -> [(log time ns, message)] ----------------
def read_with_rosbags(path):
    from rosbags.highlevel import AnyReader

    messages = defaultdict(list)
    with AnyReader([Path(path)]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for connection, t, raw in reader.messages():
            messages[connection.topic].append((t, reader.deserialize(raw, connection.msgtype)))
    return types, messages


def read_with_ros_rosbag(path):
    """ROS's own Python rosbag library (genpy messages from the bag's embedded definitions)."""
    import rosbag

    messages = defaultdict(list)
    with rosbag.Bag(str(path)) as bag:
        types = {topic: info.msg_type for topic, info in bag.get_type_and_topic_info().topics.items()}
        for topic, msg, t in bag.read_messages():
            messages[topic].append((t.to_nsec(), msg))
    return types, messages


def read_with_mcap(path):
    """The MCAP project's reader and ROS 2 CDR decoder, on the .mcap file inside the bag folder."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    (mcap_file,) = Path(path).glob("*.mcap")
    types, messages = {}, defaultdict(list)
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages():
            types[channel.topic] = schema.name
            messages[channel.topic].append((message.log_time, msg))
    return types, messages


READERS = {
    "ros1-rosbags": ("ros1", read_with_rosbags),
    "ros1-ros-rosbag": ("ros1", read_with_ros_rosbag),
    "mcap-rosbags": ("mcap", read_with_rosbags),
    "mcap-mcap_ros2": ("mcap", read_with_mcap),
}


def stamp_ns(stamp) -> int:
    if hasattr(stamp, "secs"):  # genpy (ROS 1)
        return stamp.secs * 1_000_000_000 + stamp.nsecs
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def xyz(v):
    return [v.x, v.y, v.z]


def values(kind: str, msg) -> list[float]:
    """A message's numbers in the order of `expected`."""
    if kind == "imu":
        q = msg.orientation
        return [q.w, q.x, q.y, q.z] + xyz(msg.angular_velocity) + xyz(msg.linear_acceleration)
    if kind == "odom":
        q = msg.pose.pose.orientation
        return (xyz(msg.pose.pose.position) + [q.w, q.x, q.y, q.z] + xyz(msg.twist.twist.linear)
                + xyz(msg.twist.twist.angular))
    if kind == "joint_states":
        return list(msg.position) + list(msg.velocity) + list(msg.effort)
    state = msg.states[0] if msg.states else None
    if state is None:
        return [0.0] * 7
    assert len(state.wrenches) == len(state.contact_positions) == len(state.contact_normals) == 1
    return [1.0] + xyz(state.total_wrench.force) + xyz(state.contact_positions[0])


def expected(kind: str, saved: dict, layout: Layout, i: int) -> np.ndarray:
    """(T, k) reference values of instance i at the stream's own rate."""
    stride = REFERENCE_RATE // RATES[kind]
    pick = lambda name: np.asarray(saved[name][i, ::stride], dtype=float)
    if kind == "imu":
        columns = [pick("imu_quat"), pick("imu_gyro"), pick("imu_accel")]
    elif kind == "odom":
        columns = [pick("odom_pos"), pick("odom_quat"), pick("odom_linvel"), pick("odom_angvel")]
    elif kind == "joint_states":
        columns = [pick("qpos")[:, list(layout.joint_qpos)], pick("qvel")[:, list(layout.joint_dof)], pick("torque")]
    else:
        columns = [pick("contact")[:, None], pick("contact_force"), pick("contact_pos")]
    return np.concatenate(columns, axis=1)


# -- tests ---------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["ros1", "mcap"])
def test_every_topic_has_its_type_and_rate_times_duration_messages(recorded, fmt):
    types, messages = read_with_rosbags(recorded[fmt])
    want = {"/clock": (MSGTYPES["clock"], RATES["imu"] * DURATION)}  # /clock: the fastest stream
    for i in (0, 1):
        for kind, topic in topic_names(i).items():
            want[topic] = (MSGTYPES[kind], RATES[kind] * DURATION)
    assert set(types) == set(want)
    for topic, (msgtype, count) in want.items():
        assert types[topic] == msgtype, topic
        assert len(messages[topic]) == round(count), topic


def test_one_robot_is_published_under_the_seeds_names_and_frames(recorded):
    types, messages = read_with_ros_rosbag(recorded["single"])
    assert types == {
        "/monoped/imu/data": "sensor_msgs/Imu",
        "/odom": "nav_msgs/Odometry",
        "/monoped/joint_states": "sensor_msgs/JointState",
        "/lowerleg_contactsensor_state": "gazebo_msgs/ContactsState",
        "/clock": "rosgraph_msgs/Clock",
    }
    imu, odom = messages["/monoped/imu/data"][0][1], messages["/odom"][0][1]
    joints, contact = messages["/monoped/joint_states"][0][1], messages["/lowerleg_contactsensor_state"][0][1]
    assert imu.header.frame_id == "base"
    assert (odom.header.frame_id, odom.child_frame_id) == ("world", "base")
    assert joints.name == ["haa_joint", "hfe_joint", "kfe_joint"]
    assert contact.header.frame_id == "world"
    assert [m.header.seq for _, m in messages["/monoped/imu/data"]] == list(range(int(RATES["imu"] * DURATION)))


@pytest.mark.parametrize("reader", list(READERS))
def test_values_and_stamps_equal_the_simulate_run(recorded, saved, mj_model, reader):
    fmt, read = READERS[reader]
    _, messages = read(recorded[fmt])
    layout = Layout.of(mj_model)
    for i in (0, 1):
        for kind, topic in topic_names(i).items():
            msgs = [m for _, m in messages[topic]]
            want = expected(kind, saved, layout, i)
            got = np.array([values(kind, m) for m in msgs])
            assert got.shape == want.shape, topic
            err = np.abs(got - want).max()
            assert err <= TOL, f"{topic}: max |bag - simulate| = {err:g}"
            stride = REFERENCE_RATE // RATES[kind]
            want_ns = np.round(saved["time"][::stride] * 1e9).astype(np.int64)
            assert [stamp_ns(m.header.stamp) for m in msgs] == want_ns.tolist(), topic
            assert [t for t, _ in messages[topic]] == want_ns.tolist(), topic  # log time = stamp
    # Not vacuous: both robots landed, carrying their weight along the floor's normal.
    contact = saved["contact"][:, :: REFERENCE_RATE // RATES["contact"]]
    assert contact[:, -5:].any(axis=1).all()
    first_touch = [m for _, m in messages[topic_names(1)["contact"]] if m.states][0]
    assert xyz(first_touch.states[0].contact_normals[0]) == [0.0, 0.0, 1.0]


def test_earth_robot_standing_on_the_floor_reads_its_weight(recorded):
    """Physics through the whole chain: settled Earth robot, IMU ≈ (0, 0, g), contact ≈ m·g."""
    sig = plots.read_signals(recorded["mcap"], instance=0)
    assert sig["accel"][-1] == pytest.approx([0, 0, 9.81], abs=0.3)
    assert sig["force"][-1][2] == pytest.approx(6.8 * 9.81, rel=0.05)


def test_echo_prints_each_topics_first_message_as_rostopic_does(recorded):
    """For a ROS 1 bag the layout is compared with ROS's own genpy formatting (what rostopic echo prints)."""
    _, messages = read_with_ros_rosbag(recorded["ros1"])
    for topic, msgs in messages.items():
        out = io.StringIO()
        assert echo.echo(recorded["ros1"], topic, count=1, out=out) == 1
        assert out.getvalue() == f"{msgs[0][1]}\n---\n", topic


def test_echo_cli_stdout_is_genpys_formatting_byte_for_byte(recorded):
    """As a user pipes it: the whole of stdout (no library import notices) equals what ROS's genpy
    prints for every message of the topic, each closed by '---' as rostopic echo does."""
    _, messages = read_with_ros_rosbag(recorded["ros1"])
    for topic in ("/monoped_1/lowerleg_contactsensor_state", "/monoped_0/imu/data"):
        done = subprocess.run([sys.executable, "-m", "hopper_mjx.ros.echo", str(recorded["ros1"]), topic],
                              capture_output=True, timeout=120)
        assert done.returncode == 0, done.stderr.decode()[-2000:]
        want = "".join(f"{msg}\n---\n" for _, msg in messages[topic])
        assert done.stdout == want.encode(), topic


ROS_MSG_PACKAGES = ("std_msgs", "geometry_msgs", "sensor_msgs", "nav_msgs", "rosgraph_msgs", "visualization_msgs")


def genmsg_definitions(search: dict) -> dict:
    """msgtype -> (full text, md5) of every type we record, computed by ROS's genmsg from .msg files."""
    from genpy.genmsg import gentools, msg_loader

    out = {}
    for msgtype in MSGTYPES.values():
        context = msg_loader.MsgContext.create_default()
        spec = msg_loader.load_msg_by_type(context, msgdefs.ros1_name(msgtype), search)
        msg_loader.load_depends(context, spec, search)
        text, md5 = gentools.compute_full_text(context, spec), gentools.compute_md5(context, spec)
        out[msgdefs.ros1_name(msgtype)] = (text, md5)
    return out


def test_bag_definitions_are_ros_own_text_and_md5(recorded):
    """`rosbag check` asks for a migration when a bag's definition text differs from the installed
    one, even in comments only. Text and md5 of every connection against ROS's genmsg, on ROS's own
    .msg files (Debian's ros-*-msgs, installed by the Makefile) and, for gazebo_msgs, on ours."""
    import rosbag

    stored = {}
    for bag_file in (recorded["ros1"], recorded["terrain"]):
        with rosbag.Bag(str(bag_file)) as bag:
            stored |= {c.datatype: (c.msg_def, c.md5sum) for c in bag._connections.values()}
    ours = genmsg_definitions({p: [str(msgdefs.MSG_DIR / p)] for p in (*ROS_MSG_PACKAGES, "gazebo_msgs")})
    assert stored == ours
    assert stored["sensor_msgs/Imu"][1] == "6a62c6daae103f4ff57a132d6f95cec2"  # the md5 every ROS 1 tool knows
    assert "# This is a message to hold data from an IMU" in stored["sensor_msgs/Imu"][0]  # comments kept
    system = Path("/usr/share")
    if not all((system / p / "msg").is_dir() for p in ROS_MSG_PACKAGES):
        pytest.skip("ROS's message packages are not installed (make install installs them)")
    ros = genmsg_definitions({p: [str(system / p / "msg")] for p in ROS_MSG_PACKAGES}
                             | {"gazebo_msgs": [str(msgdefs.MSG_DIR / "gazebo_msgs")]})
    assert stored == ros


@pytest.mark.parametrize("reader", ["ros1-ros-rosbag", "mcap-mcap_ros2"])
def test_the_terrain_is_one_marker_of_mujocos_triangles(recorded, reader):
    """A terrain run's bag holds the ground once, at the first instant, as a TRIANGLE_LIST marker in the
    world frame: every triangle's corners lie on the ground as MuJoCo's triangles (the height scan,
    checked against MuJoCo C's rays) have it, and each faces up."""
    from hopper_mjx.terrain.scan import height_at

    fmt, read = READERS[reader]
    types, messages = read(recorded["terrain" if fmt == "ros1" else "terrain_mcap"])
    assert types["/terrain"] == ("visualization_msgs/Marker" if fmt == "ros1" else "visualization_msgs/msg/Marker")
    ((t, marker),) = messages["/terrain"]
    assert t == min(t for topic in messages for t, _ in messages[topic]) and marker.header.frame_id == "world"
    assert (marker.type, marker.action) == (11, 0)
    corners = np.array([[p.x, p.y, p.z] for p in marker.points]).reshape(-1, 3, 3)
    assert len(corners) == 2 * 3 * 5  # (4 - 1) x (6 - 1) cells, two triangles each
    ground = HILLS.terrain()
    centroid = corners.mean(axis=1)  # inside one triangle: the scan's height there is the plane's through it
    scanned = height_at(ground.heights, ground.size, centroid[:, 0], centroid[:, 1])  # float32: 1e-8 m
    np.testing.assert_allclose(centroid[:, 2], scanned, atol=1e-7)  # the other diagonal would be mm off
    np.testing.assert_allclose(np.sort(np.unique(corners[:, :, 2])), np.sort(np.unique(ground.heights)), atol=0)
    up = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, 2]
    assert (up > 0).all()


def test_a_terrain_recording_takes_its_ground_from_the_compiled_model():
    from hopper_mjx import model

    corners = record.terrain_triangles(model.load(terrain=HILLS.terrain()))
    np.testing.assert_allclose(corners, terrain.triangles(HILLS.terrain()), atol=1e-7)  # MuJoCo's float32 heights
    assert record.terrain_triangles(model.load()) is None


def test_echo_cli_on_an_mcap_bag(recorded, capsys):
    _, messages = read_with_rosbags(recorded["mcap"])
    for topic in messages:
        assert echo.main([str(recorded["mcap"]), topic, "-n", "1"]) == 0
        out = capsys.readouterr().out
        assert out.count("\n---\n") == 1 and out.endswith("---\n"), topic
    assert echo.main([str(recorded["mcap"]), "/monoped_0/imu/data", "-n", "1"]) == 0
    out = capsys.readouterr().out
    assert 'frame_id: "monoped_0/base"' in out and "nanosec:         0" not in out  # ROS 2 field names
    assert "  stamp: \n    sec: 0\n    nanosec: 0\n" in out


def test_signal_plot_png(recorded, tmp_path):
    out = plots.plot_bag(recorded["ros1"], tmp_path / "signals.png", instances=[0, 1])
    image = matplotlib.image.imread(out)
    assert out.stat().st_size < 300_000
    assert image.shape[1] > image.shape[0] * 0.8  # two columns
    assert image[..., :3].std() > 0.05  # not blank


def test_bad_requests_name_the_problem(recorded, tmp_path, capsys):
    rec = recorded["rec"]
    with pytest.raises(ValueError, match="out of range"):
        record.write(rec, tmp_path / "x.bag", "ros1", instances=[2])
    with pytest.raises(ValueError, match="unknown format"):
        record.write(rec, tmp_path / "x.bag", "ros2")
    with pytest.raises(ValueError, match="exists"):
        record.write(rec, recorded["ros1"], "ros1")
    with pytest.raises(ValueError, match="folder name such as run_mcap"):
        record.write(rec, tmp_path / "run.mcap", "mcap")
    with pytest.raises(ValueError, match="not in the bag; it has: /clock"):
        echo.echo(recorded["ros1"], "/imu", count=1, out=io.StringIO())
    with pytest.raises(ValueError, match="no such bag"):
        echo.echo(tmp_path / "missing.bag", "/clock")
    (tmp_path / "junk.bag").write_text("not a bag")
    with pytest.raises(ValueError, match="cannot read"):
        echo.echo(tmp_path / "junk.bag", "/clock")
    (mcap_file,) = Path(recorded["mcap"]).glob("*.mcap")
    (tmp_path / "lone").mkdir()
    lone = tmp_path / "lone" / mcap_file.name
    lone.write_bytes(mcap_file.read_bytes())  # the storage file without its folder's metadata.yaml
    with pytest.raises(ValueError, match="storage file without its bag folder"):
        echo.echo(lone, "/clock")
    with pytest.raises(ValueError, match="folder but not a ROS 2 bag"):
        echo.echo(tmp_path / "lone", "/clock")
    assert record.main(["--out", str(recorded["ros1"])]) == 2  # refused before simulating
    assert "exists" in capsys.readouterr().err


def test_simulate_options_reach_the_controller_unchanged():
    defaults = vars(simulate.parser().parse_args([]))
    ours = vars(record.parser().parse_args([]))
    for name, value in defaults.items():
        # record's own defaults (one robot, 50 Hz, a bag) and simulate's live run
        if name not in ("gravity", "default_gravity", "rate", "out", "scan", "foxglove", "speed_factor"):
            assert ours[name] == value, name


def test_a_bag_of_several_robots_plotted_as_one_says_which_it_holds(recorded, tmp_path, capsys):
    """Without --instances, plots reads the single robot's topics; on a bag of several it said only that
    /monoped/imu/data was missing. It names the robots the bag holds and the option that picks them."""
    assert plots.main([str(recorded["ros1"]), "--out", str(tmp_path / "p.png")]) == 2
    assert capsys.readouterr().err == ("error: the bag holds 2 robots, /monoped_0 to /monoped_1: choose with "
                                       "--instances, e.g. --instances 0,1\n")
    assert not (tmp_path / "p.png").exists()
    # a bag of one robot (its topics unnumbered) plots without --instances, as before
    assert plots.main([str(recorded["single"]), "--out", str(tmp_path / "p.png")]) == 0
