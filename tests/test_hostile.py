"""Hostile input, one case per kind of trouble a user or a damaged disk brings: input files whose values
are wrong, sizes that cannot run, run folders that are not what they seem, a policy folder copied, edited
or cut short. Each is refused as test_bad_inputs holds a refusal (whose helpers run the cases): exit code
2, one line naming the file, tag or flag at fault, no traceback, nothing written or overwritten, and
within 2 s of CPU beyond the imports it needs (before anything is compiled). Interrupts are
tests/test_interrupt.py's.
"""

import json
import shutil
import struct
import zlib
from pathlib import Path

import pytest
from test_bad_inputs import assert_refused, prepare, refuse_all
from test_policy import trained  # noqa: F401  (a fixture: an untrained policy folder, laid out as training saves one)

from hopper_mjx.model import loader

URDF = Path(loader.__file__).with_name("monoped.urdf").read_text()
WORLD = Path(loader.__file__).with_name("low_gravity.world").read_text().replace("<gravity>0 0 0<",
                                                                               "<gravity>0 0 -9.81<")
PID = """{name}_position_controller:
  type: effort_controllers/JointPositionController
  joint: {name}
  pid: {{p: 100.0, i: 0.01, d: 10.0}}
"""
GAINS = "".join(PID.format(name=j) for j in ("haa_joint", "hfe_joint", "kfe_joint"))


def png_header(width: int, height: int) -> bytes:
    """A PNG's signature and IHDR chunk (8-bit grey) declaring `width` x `height` pixels, and no pixels."""
    ihdr = b"IHDR" + struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + ihdr + struct.pack(">I", zlib.crc32(ihdr))


def laughs(levels: int = 9) -> str:
    """A scenario whose gravity list nests aliases nine deep: 9^9 values once expanded ("billion laughs")."""
    items = ["&a0 [" + ",".join(["9.81"] * 9) + "]"]
    items += [f"&a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, levels)]
    return f"gravity: [{', '.join(items)}]\n"


def urdf(old: str, new: str, count: int = 1) -> str:
    assert old in URDF
    return URDF.replace(old, new, count)


def world(old: str, new: str) -> str:
    assert old in WORLD
    return WORLD.replace(old, new)


# Files a case's folder holds besides test_bad_inputs' (name: text).
FILES = {
    "notes.npz": "a text file named as a recording\n",
    # URDF values
    "reduction_neg.urdf": urdf("<mechanicalReduction>1<", "<mechanicalReduction>-2<"),
    "reduction_inf.urdf": urdf("<mechanicalReduction>1<", "<mechanicalReduction>inf<"),
    "reduction_text.urdf": urdf("<mechanicalReduction>1<", "<mechanicalReduction>one<"),
    "limit_nan.urdf": urdf('lower="-1.6"', 'lower="nan"'),
    "limit_equal.urdf": urdf('lower="-1.6" upper="1.6"', 'lower="0.5" upper="0.5"'),
    "rpy_inf.urdf": urdf('<origin xyz="0 0 -0.15" rpy="0 0 0"/>', '<origin xyz="0 0 -0.15" rpy="0 inf 0"/>'),
    "foot_zero.urdf": urdf('<sphere radius="0.03"/>', '<sphere radius="0"/>', 2),
    "mass_neg.urdf": urdf('<mass value="0.1"/>', '<mass value="-0.1"/>'),
    "effort_nan.urdf": urdf('effort="40"', 'effort="nan"'),
    # gains YAML
    "list.yaml": "- 1\n- 2\n",
    "float_key.yaml": GAINS + "1.5: {type: effort_controllers/JointPositionController, joint: kfe_joint}\n",
    "p_inf.yaml": GAINS.replace("p: 100.0", "p: .inf", 1),
    "i_text.yaml": GAINS.replace("i: 0.01", "i: lots", 1),
    "same_key.yaml": GAINS + PID.format(name="kfe_joint"),  # a controller's entry given twice
    "tabs.yaml": "monoped:\n\tkfe: 1\n",
    # world files
    "step_zero.world": world("<max_step_size>0.001<", "<max_step_size>0<"),
    "step_nan.world": world("<max_step_size>0.001<", "<max_step_size>nan<"),
    "gravity_inf.world": world("<gravity>0 0 -9.81<", "<gravity>0 0 -inf<"),
    "gravity_two.world": world("<gravity>0 0 -9.81<", "<gravity>0 -9.81<"),
    "nested.world": "<sdf>" * 2000 + "</sdf>" * 2000,
    # scenario files
    "typo.yaml": "gravity: 9.81\nnumm: 3\n",
    "tag.yaml": "gravity: !!python/object/apply:os.system ['touch obeyed']\n",
    "laughs.yaml": laughs(),
    "itself.yaml": "gravity: &a [9.81, *a]\n",
    # a heightmap that is a JPEG renamed
    "photo.png": "\xff\xd8\xff\xe0 JFIF",
}


def _env(folder: Path, text: str) -> None:
    (folder / "hopper_env.json").write_text(text)


def _task(folder: Path, task: str) -> None:
    config = json.loads((folder / "hopper_env.json").read_text())
    _env(folder, json.dumps({**config, "task": task}))


def _observations(folder: Path, size: int) -> None:
    net = json.loads((folder / "ppo_network_config.json").read_text())
    (folder / "ppo_network_config.json").write_text(json.dumps({**net, "observation_size": size}))


def _no_params(folder: Path) -> None:
    for path in folder.iterdir():
        if path.suffix != ".json":
            shutil.rmtree(path) if path.is_dir() else path.unlink()


def _cut(file: Path) -> None:
    """Cuts a file to half its length, as an interrupted copy leaves it."""
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])


def _cut_params(folder: Path) -> None:
    _cut(max((p for p in (folder / "d").iterdir()), key=lambda p: p.stat().st_size))  # the parameters' data


# Policy folders a user copied and then edited or cut short: name -> damage.
POLICIES = {
    "pol_empty_env": lambda f: _env(f, ""),
    "pol_binary_env": lambda f: (f / "hopper_env.json").write_bytes(b"\xff\xfe\x00{"),
    "pol_task": lambda f: _task(f, "fly"),
    "pol_net_list": lambda f: (f / "ppo_network_config.json").write_text("[]"),
    "pol_obs": lambda f: _observations(f, 7),
    "pol_no_params": _no_params,
    # cut short: orbax failed inside its event loop and printed ~100 lines of tracebacks at exit
    "pol_cut_params": _cut_params,
    "pol_cut_manifest": lambda f: _cut(f / "manifest.ocdbt"),
}
POLICY = []  # the intact policy folder, once the fixture made it


def prepare_hostile(folder: Path) -> None:
    prepare(folder)
    for name, damage in POLICIES.items():
        shutil.copytree(POLICY[0], folder / name)
        damage(folder / name)
    for name, text in FILES.items():
        (folder / name).write_text(text)
    (folder / "huge.png").write_bytes(png_header(100_000, 100_000))  # 10^10 pixels declared, none there
    (folder / "scenario.yaml").mkdir()  # a folder named as a scenario file
    (folder / "unrelated").mkdir()  # a folder of the user's, holding a results.csv of theirs
    (folder / "unrelated" / "results.csv").write_text("mine\n")
    (folder / "empty").mkdir()  # made by the user, not by a sweep
    (folder / "notes").mkdir()
    (folder / "notes" / "todo.txt").write_text("mine\n")
    cut = folder / "cut_sweep"  # a sweep's folder after a power cut: its manifest cut short
    cut.mkdir()
    (cut / "manifest.json").write_text('{"kind": "gravity", "grav')
    listed = folder / "list_sweep"  # a manifest that is JSON but not a sweep's
    listed.mkdir()
    (listed / "manifest.json").write_text("[1, 2, 3]")
    tagged = folder / "tagged_bag"  # a ROS 2 bag folder whose metadata would run a command if it were obeyed
    tagged.mkdir()
    (tagged / "metadata.yaml").write_text("rosbag2_bagfile_information: !!python/object/apply:os.system "
                                          "['touch obeyed']\n")
    (tagged / "tagged_bag_0.mcap").write_bytes(b"\x89MCAP0\r\n")
    run = folder / "run"  # a training run whose metrics.json was cut short
    (run / "checkpoints").mkdir(parents=True)
    (run / "metrics.json").write_text('{"history": [{"step": 1')


SIM = ["--out", "o.npz"]
SWEEP = ["gravity", "--out", "s"]
TRAIN = "experiments/train.py"
RESULTS = "experiments/results.py"
APEX = "experiments/apex_reward.py"

# (command, arguments, what the one line must say)
CASES = [
    # URDF values
    ("simulate", ["--urdf", "reduction_neg.urdf", *SIM], "<mechanicalReduction> must be a finite number > 0, got -2"),
    ("simulate", ["--urdf", "reduction_inf.urdf", *SIM], "<mechanicalReduction> must be a finite number > 0, got inf"),
    ("sweep", [*SWEEP, "--urdf", "reduction_text.urdf"], "<mechanicalReduction>"),
    ("simulate", ["--urdf", "limit_nan.urdf", *SIM], "joint 'haa_joint' <limit>"),
    ("render", ["--still", "m.png", "--urdf", "limit_equal.urdf"], "joint 'haa_joint' <limit>"),
    ("simulate", ["--urdf", "rpy_inf.urdf", *SIM], "<origin rpy> must be three finite numbers"),
    ("ros.record", ["--urdf", "foot_zero.urdf", "--out", "r.bag"], "the foot's radius must be > 0, got 0"),
    ("simulate", ["--urdf", "mass_neg.urdf", *SIM], "link 'foot' has mass -0.1"),
    ("simulate", ["--urdf", "effort_nan.urdf", *SIM], "'effort' is not finite"),
    ("model", ["--export", "m.xml", "--urdf", "reduction_neg.urdf"], "<mechanicalReduction>"),
    # gains YAML
    ("simulate", ["--controller", "pid", "--gains", "list.yaml", *SIM], "list.yaml: expected a mapping"),
    ("simulate", ["--controller", "pid", "--gains", "float_key.yaml", *SIM], "float_key.yaml"),
    ("simulate", ["--controller", "pid", "--gains", "p_inf.yaml", *SIM], "pid.p must be finite and >= 0, got inf"),
    ("simulate", ["--controller", "pid", "--gains", "i_text.yaml", *SIM], "pid.i must be a number, got 'lots'"),
    ("simulate", ["--controller", "pid", "--gains", "same_key.yaml", *SIM],
     "same_key.yaml is not valid YAML: the key 'kfe_joint_position_controller' is given twice (lines 9 and 13)"),
    ("simulate", ["--controller", "pid", "--gains", "tabs.yaml", *SIM], "tabs.yaml is not valid YAML"),
    ("simulate", ["--controller", "pid", "--gains", "/dev/urandom", *SIM], "/dev/urandom"),
    # world files
    ("simulate", ["--world", "step_zero.world", *SIM], "step_zero.world: <physics><max_step_size>"),
    ("simulate", ["--world", "step_nan.world", *SIM], "step_nan.world: <physics><max_step_size>"),
    ("sweep", [*SWEEP, "--world", "gravity_inf.world"], "gravity_inf.world"),
    ("render", ["--still", "m.png", "--world", "gravity_two.world"], "gravity_two.world"),
    ("simulate", ["--world", "nested.world", *SIM], "nested.world"),
    ("simulate", ["--world", "/dev/zero", *SIM], "/dev/zero"),
    # sizes that cannot run: what the run would need, and what this machine has
    ("render", ["--video", "h.gif", "--gravity", "9.81", "--num", "400000000"], "would need about"),
    ("ros.record", ["--duration", "1e12", "--out", "r.bag"], "physics steps"),
    ("sweep", ["gains", "--param", "speed_gain", "--values", ",".join(map(str, range(1, 2001))), "--num", "100000",
               "--out", "s"], "would need about"),
    ("sweep", [*SWEEP, "--num", "1", "--chunk", "100000000", "--duration", "1e6"], "would need about"),
    ("perf.bench", ["--num", "30000000", "--engine", "mjx"], "would need about"),
    ("simulate", ["--num", "1", "--duration", "3e6", *SIM], "physics steps"),
    ("sweep", [*SWEEP, "--seed", str(2**32)], "--seed must be in 0..4294967295"),
    # run folders that are not what they seem
    ("sweep", ["gravity", "--out", "unrelated"], "--out unrelated exists and is not a sweep's folder"),
    ("sweep", ["gravity", "--out", "notes"], "--out notes exists and is not a sweep's folder"),
    ("sweep", ["gains", "--param", "speed_gain", "--values", "0.1,0.2", "--out", "empty"],
     "--out empty exists and is not a sweep's folder"),
    ("sweep", ["compare", "--controllers", "raibert", "--out", "empty"], "--out empty exists and is not"),
    ("sweep", ["compare", "--controllers", "raibert", "--out", "notes"], "--out notes exists and is not"),
    ("sweep", ["gravity", "--out", "cut_sweep"], "--out cut_sweep: its manifest.json is damaged"),
    ("sweep", ["gravity", "--out", "list_sweep"], "--out list_sweep: its manifest.json is not a sweep's"),
    ("sweep", ["gravity", "--values", "1.62,3.71,1.62", "--out", "s"], "gravity values must differ"),
    ("sweep", ["gains", "--param", "speed_gain", "--values", "0.1,0.1", "--out", "s"], "--values must differ"),
    (TRAIN, ["--out", "run", "--timesteps", "1000"], "run/metrics.json is damaged"),
    (RESULTS, ["run", "--out", "r.md"], "run/metrics.json: cannot be read"),
    # NumPy's own messages said nothing of the file (one asked to unpickle it)
    (APEX, ["notes.npz"], "run notes.npz: cannot be read as a simulate --out recording (.npz)"),
    (APEX, ["o.npz"], "run o.npz: no such file"),
    # results.py writes Markdown (and its .json and .png beside it): another suffix would hide it under that name
    (RESULTS, ["run", "--out", "r.txt"], "--out r.txt: this tool writes .md files; give a name ending in .md"),
    (RESULTS, ["run", "--out", "/dev/null"], "--out /dev/null: results.py writes its .json and .png beside the table"),
    (TRAIN, ["--out", "new", "--gravity-range", "nan,9.81"], "--gravity-range"),
    (TRAIN, ["--out", "new", "--episode-length", "-5"], "--episode-length"),
    (TRAIN, ["--out", "new", "--num-envs", "0"], "--num-envs"),
    (TRAIN, ["--out", "new", "--eval-gravity", "9.81,,x"], "--eval-gravity"),
    (TRAIN, ["--out", "a_file"], "--out a_file"),
    # a folder the checks may let through (root passes os.access on /proc) that the system refuses to create
    (TRAIN, ["--out", "/proc/hopper_mjx_no/run"], "--out /proc/hopper_mjx_no"),
    (TRAIN, ["--out", "/proc/hopper_mjx_no/run", "--seeds", "2"], "--out /proc/hopper_mjx_no"),
    ("sweep", ["gravity", "--out", "/proc/hopper_mjx_no/s"], "--out /proc/hopper_mjx_no"),
    # a file there: refused before the run, where it ended in a traceback when the file was written
    ("simulate", ["--gravity", "9.81", "--num", "1", "--duration", "0.05", "--out", "/proc/x.npz"],
     "--out /proc/x.npz: cannot write in /proc"),
    ("model", ["--export", "/proc/m.xml"], "--export /proc/m.xml: cannot write in /proc"),
    ("ros.record", ["--out", "/sys/r.bag"], "--out /sys/r.bag: cannot write in /sys"),
    # a name longer than the file system's 255 bytes: the existence check raised ENAMETOOLONG, a traceback
    ("simulate", ["--num", "1", "--duration", "0.05", "--out", "a" * 300 + ".npz"], "a.npz: File name too long"),
    ("sweep", ["gravity", "--out", "s" * 300], "ss: File name too long"),
    (TRAIN, ["--out", "r" * 300], "rr: File name too long"),
    # an input of such a name: Path.is_file raised it too, wherever a command opened its inputs
    ("simulate", ["--urdf", "u" * 300 + ".urdf", "--out", "o.npz"], "uu.urdf: File name too long"),
    ("simulate", ["--controller", "policy:" + "p" * 300, "--out", "o.npz"], "pp: File name too long"),
    ("ros.plots", ["b" * 300 + ".bag"], "bb.bag: File name too long"),
    (TRAIN, ["--out", "new", "--seed", "-3"], "--seed must be in 0..4294967295"),
    (TRAIN, ["--out", "new", "--randomize", "kp_scale=0.8..1.2,sensor_delay=300..900", "--episode-length", "10"],
     "--randomize: sensor_delay drew"),
    # policy folders copied, edited or cut short
    ("simulate", ["--controller", "policy:pol_empty_env", *SIM], "hopper_env.json is not valid JSON"),
    ("simulate", ["--controller", "policy:pol_binary_env", *SIM], "hopper_env.json is not valid JSON"),
    ("sweep", ["gravity", "--controller", "policy:pol_task", "--out", "s"], "hopper_env.json: unknown task 'fly'"),
    ("simulate", ["--controller", "policy:pol_net_list", *SIM], "ppo_network_config.json must hold a JSON object"),
    ("ros.record", ["--controller", "policy:pol_obs", "--out", "r.bag"], "the policy takes 7 observations"),
    ("simulate", ["--controller", "policy:pol_no_params", *SIM], "its parameters cannot be read"),
    ("render", ["--video", "h.gif", "--controller", "policy:a_file"],
     "a_file is not a trained policy: a file, not a training run's folder"),
    ("simulate", ["--controller", "policy:pol_cut_params", *SIM], "its parameters cannot be read (OUT_OF_RANGE"),
    ("sweep", ["gravity", "--controller", "policy:pol_cut_manifest", "--out", "s"], "its parameters cannot be read"),
    # a bag's metadata with a Python tag: refused (never obeyed) in one line
    ("ros.echo", ["tagged_bag", "/odom"], "could not determine a constructor for the tag"),
    ("ros.plots", ["tagged_bag"], "tagged_bag/metadata.yaml: could not determine a constructor"),
    # a robot twice was plotted twice; 10^5 dpi asked for a terapixel image
    ("ros.plots", ["tagged_bag", "--instances", "0,0"], "--instances lists a robot twice: [0, 0]"),
    ("ros.plots", ["tagged_bag", "--dpi", "100000"], "--dpi must be in 1..1000, got 100000"),
    # terrain specs and heightmaps
    ("simulate", ["--terrain", "rough:size=1e308"], "--terrain: a >1e308 x >1e308 grid has >1e308 vertices"),
    ("simulate", ["--terrain", "rough:size=1e6"], "625,000,050,000,001 vertices, about 4547.5 TiB of heights; at most"),
    ("simulate", ["--terrain", "rough:ampl=0.02"], "--terrain: rough has no key 'ampl'; it takes amp,"),
    ("simulate", ["--terrain", "rough:wavelength=1e-300"], "--terrain: rough: wavelength=1e-300 m is shorter than two "
                                                           "cells (0.08 m)"),
    ("sweep", [*SWEEP, "--terrain", "obstacle:height=inf"], "--terrain: height=inf must be finite"),
    ("render", ["--still", "m.png", "--terrain", "heightmap:huge.png"], "--terrain: a 100000 x 100000 grid has "
                                                                         "10,000,000,000 vertices, about 74.5 GiB"),
    ("simulate", ["--terrain", "heightmap:photo.png"], "--terrain: photo.png is not a PNG image"),
    # scenario files
    ("simulate", ["--scenario", "typo.yaml", *SIM], "--scenario typo.yaml: unknown option(s) numm; known:"),
    ("simulate", ["--scenario", "tag.yaml", *SIM], "--scenario tag.yaml: not YAML (could not determine a constructor"),
    ("simulate", ["--scenario", "laughs.yaml", *SIM], "--scenario laughs.yaml: not YAML (it expands to over 100,000"),
    ("ros.record", ["--scenario", "itself.yaml", "--out", "r.bag"], "--scenario itself.yaml: not YAML (it expands"),
    ("simulate", ["--scenario", "scenario.yaml", *SIM], "--scenario scenario.yaml: is a folder, not a file"),
    # randomisation, motors, delays and pushes
    ("simulate", ["--randomize", "base_mass=1e300", *SIM], "--randomize: base_mass=1e+300 sets a value of 1e+300 kg; "
                                                           "it must be > 0 (and within ±3.4e+38"),
    ("simulate", ["--randomize", "body_mas=scale(0.9,1.1)", *SIM], "--randomize: unknown parameter 'body_mas'"),
    ("simulate", ["--randomize", "foot_friction=uniform(nan,1)", *SIM], "uniform(nan,1) has a non-finite bound"),
    ("simulate", ["--randomize", "body_mass=scale(1e30,1e30)", *SIM],
     "--randomize: body_mass: scale(1e+30,1e+30): a factor outside 0.01..100 of the URDF's value builds no robot"),
    ("simulate", ["--push", "1,1e300", *SIM], "--push speed must be finite and >= 0 and <= 340, got 1e+300"),
    ("simulate", ["--push", "nan,0.3", *SIM], "--push interval must be finite and > 0, got nan"),
    ("simulate", ["--action-delay", "nan", *SIM], "--action-delay must be finite and >= 0, got nan"),
    # sweep values the robot cannot stand at
    ("sweep", ["gravity", "--gravity", "9.81,1e6", "--out", "s"],
     "--gravity 1e+06 m/s²: the robot cannot stand there; its kfe_joint motor (80 N·m) holds the standing pose"),
    ("sweep", ["param", "--param", "base_mass", "--values", "5,50", "--out", "s"],
     "--values base_mass=50: 9.81 m/s²: the robot cannot stand there"),
    # outputs of a type the tool cannot write
    ("simulate", ["--out", "o.txt"], "--out o.txt: this tool writes .npz files; give a name ending in .npz"),
    ("render", ["--still", "m.txt"], "--still m.txt: this tool writes .png or .jpg or .jpeg files"),
    ("ros.record", ["--out", "r.txt"], "--out r.txt: this tool writes .bag files"),
    ("model", ["--export", "m.obj"], "--export m.obj: this tool writes .xml files"),
    ("perf.bench", ["--json", "b.csv"], "--json b.csv: this tool writes .json files"),
]


@pytest.fixture(scope="module")
def refusals(tmp_path_factory, trained):  # noqa: F811
    POLICY[:] = [trained[0] / "policy"]
    return refuse_all(tmp_path_factory.mktemp("hostile"), CASES, prepare_hostile)


@pytest.mark.parametrize("k", range(len(CASES)), ids=[f"{c}:{' '.join(a)[:40]}" for c, a, _ in CASES])
def test_hostile_input_is_refused_in_one_line(refusals, k):
    assert_refused(refusals[k], CASES[k][2])


def test_a_chunk_larger_than_the_grid_runs_as_the_grid(tmp_path):
    """`--chunk 100000000` padded every chunk to that size; a chunk is now never larger than the grid."""
    from hopper_mjx.sweep.__main__ import check, parser

    args = parser().parse_args(["gravity", "--values", "1.62,9.81", "--num", "3", "--chunk", "100000000",
                                "--out", str(tmp_path / "s")])
    specs, _ = check(args)
    assert [s.chunk for s in specs] == [6]
    assert not (tmp_path / "s").exists()


def test_apex_reward_reads_only_a_recording_it_can_judge(tmp_path):
    """experiments/apex_reward.py names the file and what it lacks: an .npz of other arrays raised a bare KeyError
    ('time is not a file in the archive'), and one of a single sample an IndexError traceback."""
    import importlib

    import numpy as np

    apex = importlib.import_module("apex_reward")  # experiments/ is on pytest's path
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    arrays = {k: np.zeros(s) for k, s in (("time", 1), ("gravity", (1, 3)), ("qpos", (1, 1, 7)), ("qvel", (1, 1, 6)),
                                          ("contact", (1, 1)))}
    np.savez(tmp_path / "one.npz", **arrays)
    with pytest.raises(ValueError, match="other.npz: not a simulate --out recording: no time, gravity, qpos, qvel, "
                                         "contact$"):
        apex.read_run(str(tmp_path / "other.npz"))
    with pytest.raises(ValueError, match="one.npz: holds 1 sample"):
        apex.read_run(str(tmp_path / "one.npz"))
    np.savez(tmp_path / "two.npz", **{**arrays, "time": np.arange(2) * 0.002})
    assert apex.read_run(str(tmp_path / "two.npz"))["time"].size == 2
