"""Bad input, typed as a user types it: each command refuses it in one line on stderr, with exit code 2,
before building or compiling anything, without a traceback and without writing a file.

"Before anything is compiled" is held by the refusing command's CPU time: under `MAX_CPU` s, where a compile alone
takes 15 s or more. (CPU rather than wall time, because the machine may be shared.)

Every case runs as `python -m hopper_mjx.<command>` would, in a fresh folder that holds a few prepared inputs (a
file, a folder, a garbled world, a binary URDF, a lone .mcap file, a bag-less folder): as a fork of one process that
has imported every library a refusal may need (tests/refuser.py), a few at once. A case then costs a fork, not a
Python start-up and JAX's import (0.5-5 s of CPU each). That the commands check their arguments before importing
JAX at all is held apart (`test_the_commands_check_their_arguments_without_importing_jax`).
"""

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import pytest

from hopper_mjx import cli, control, registry
from hopper_mjx.model import loader, world

LOW_GRAVITY = str(world.LOW_GRAVITY_WORLD)
# The commands run from another folder: this checkout's package first, whatever is installed.
ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT),
                                                    os.environ.get("PYTHONPATH", "")])}
MAX_CPU = 5.0  # s of CPU time a refusal may take beyond the imports (a fork pays none)
# Everything a command may import before it refuses (a policy folder's checks load its parameters).
HEAVY_IMPORTS = "hopper_mjx.envs.policy,brax.training.agents.ppo.train"
TIMEOUT = 60.0  # s of wall time before a case counts as hung
WORKERS = 2  # forks at once, one per core

# (command, arguments, what the one line must say)
CASES = [
    ("simulate", ["--duration", "0"], "--duration must be finite and > 0, got 0"),
    ("simulate", ["--duration", "-1"], "--duration must be finite and > 0, got -1"),
    ("simulate", ["--out", "nodir/o.npz"], "--out nodir/o.npz: its folder nodir does not exist"),
    ("simulate", ["--out", "a_file/o.npz"], "--out a_file/o.npz: its folder a_file is not a folder"),
    ("simulate", ["--out", "a_folder"], "--out a_folder is a folder; give a file"),
    ("simulate", ["--gravity", "9.81,nan"], "--gravity: gravity must be finite"),
    ("simulate", ["--gravity", "-1"], "--gravity: gravity magnitudes point down and must be >= 0"),
    ("simulate", ["--num", "0"], "--num must be >= 1, got 0"),
    ("simulate", ["--num", "abc"], "argument --num: invalid int value: 'abc'"),
    ("simulate", ["--controller", "leap"], "--controller: unknown controller 'leap'; choose from: none, hold, pid, "
                                             "raibert, jump, balance, policy:PATH"),
    ("simulate", ["--rate", "7"], "--rate 7 must divide the physics rate 1000 Hz (a sample every whole number of "
                                  "steps), e.g. 5, 8, 10, 20, 25, 40, 50, 100"),
    ("render", ["--video", "h.gif", "--fps", "15"], "--fps 15 must divide the physics rate 1000 Hz"),
    ("ros.record", ["--rate", "100", "--odom-rate", "30", "--out", "r.bag"], "--odom-rate 30 must divide the physics"),
    ("sweep", ["gravity", "--gravity", "1,x", "--out", "s"], "--gravity/--values must be comma-separated numbers, "
                                                              "got '1,x'"),
    ("simulate", ["--timestep", "0.5"], "--timestep must be finite and > 0 and <= 0.01, got 0.5"),
    ("simulate", ["--urdf", "binary.urdf"], "--urdf: binary.urdf is not a text (UTF-8) URDF file"),
    ("simulate", ["--world", "missing.world"], "--world missing.world: no such file"),
    ("simulate", ["--world", "garbled.world"], "garbled.world is not well-formed XML"),
    ("simulate", ["--world", LOW_GRAVITY, "--gravity", "1.62"], "give --gravity or --world, not both"),
    ("simulate", ["--world", LOW_GRAVITY, "--timestep", "0.002"], "contradicts the world's <max_step_size> 0.001"),
    ("simulate", ["--controller", "pid", "--gains", "a_folder"], "--gains: no monoped.yaml or monoped.yml in"),
    ("simulate", ["--gains", "a_file"], "--gains sets the pid controller's gains; --controller is hold"),
    ("model", ["--export", "nodir/m.xml"], "--export nodir/m.xml: its folder nodir does not exist"),
    ("model", ["--export", "m.xml", "--urdf", "missing.urdf"], "--urdf missing.urdf: no such file"),
    ("model", ["--export-urdf", "nodir/m.urdf"], "--export-urdf nodir/m.urdf: its folder nodir does not exist"),
    ("model", ["--export-urdf", "a_folder"], "--export-urdf a_folder is a folder; give a file"),
    ("model", ["--export-urdf", "-", "--urdf", "binary.urdf"], "--urdf: binary.urdf is not a text (UTF-8) URDF"),
    ("ros.record", ["--instances", "5"], "--instances [5] out of range: the batch has 1 instance(s), 0..0"),
    ("ros.record", ["--out", "a_file"], "--out a_file exists; remove it or choose another"),
    ("ros.record", ["--format", "mcap", "--out", "run.mcap"], "give a folder name such as run_mcap"),
    ("ros.record", ["--duration", "-1"], "--duration must be finite and > 0"),
    ("ros.echo", ["lone/x.mcap", "/clock"], "lone/x.mcap is a ROS 2 storage file without its bag folder"),
    ("ros.echo", ["a_folder", "/clock"], "a_folder is a folder but not a ROS 2 bag"),
    ("ros.echo", ["missing.bag", "/clock"], "no such bag: missing.bag"),
    ("ros.echo", ["a_file", "/clock", "-n", "0"], "-n must be >= 1, got 0"),
    ("render", [], "nothing to do: give --still PATH and/or --video PATH"),
    ("render", ["--video", "h.gif", "--duration", "-1"], "--duration must be finite and > 0"),
    ("render", ["--video", "h.avi"], "--video must end in .mp4 or .gif, got h.avi"),
    # a still drew the stance and let the bad index pass; the batch's options are checked for a still too
    ("render", ["--still", "s.png", "--instance", "-1"], "--instance [-1] out of range: the batch has 1 instance(s)"),
    ("render", ["--still", "nodir/m.png"], "--still nodir/m.png: its folder nodir does not exist"),
    ("render", ["--video", "h.gif", "--gravity", "9.81,1.62", "--instance", "2"], "--instance [2] out of range"),
    # argparse named only the missing subcommand's name, not what it may be
    ("sweep", [], "the following arguments are required: kind; kind is one of gravity, gains, param, compare, "
                  "obstacle, gaps, terrain"),
    ("sweep", ["gravity", "--out", "a_file"], "--out a_file is a file; give a folder"),
    ("sweep", ["gravity", "--values", "0,9.81", "--out", "s"], "gravity values must be finite and > 0"),
    ("sweep", ["gravity", "--world", LOW_GRAVITY, "--out", "s"], "is not a downward pull"),
    ("sweep", ["gains", "--param", "bogus", "--values", "1,2", "--out", "s"], "unknown gain 'bogus'"),
    ("sweep", ["gravity", "--num-processes", "2", "--process-id", "2", "--out", "s"], "--process-id must be in"),
    ("perf.bench", ["--steps", "30"], "--steps must be a multiple of 20"),
    ("perf.bench", ["--plot", "p.png"], "--plot draws the --scaling records"),
    ("perf.bench", ["--controller", "pid"], "--controller: unknown controller 'pid'; choose from: none, hold, raibert"),
    ("perf.bench", ["--engine", "warp"], "--engine: unknown engine 'warp'"),
    ("sweep", ["gravity", "--engine", "warp", "--out", "s"], "--engine: unknown engine 'warp'"),
    ("simulate", ["--engine", "warp"], "--engine: unknown engine 'warp'"),
    ("perf.bench", ["--json", "nodir/b.json"], "--json nodir/b.json: its folder nodir does not exist"),
    # Sizes that cannot run: refused up front with what the run would need and what this machine has.
    ("simulate", ["--num", "100000000"], "--num: 300,000,000 instances would need about"),
    ("simulate", ["--num", "20000", "--duration", "10000"], "--num, --duration: 60,000 instances would need"),
    ("simulate", ["--duration", "1e9"], "--duration: 1e+09 s at a 0.001 s step is 1e+12 physics steps"),
    ("simulate", ["--seed", str(2**70)], "--seed must be in 0..4294967295"),
    ("perf.bench", ["--num", "100000000"], "--num: 100,000,000 instances would need about"),
    ("sweep", ["gravity", "--num", "100000000", "--out", "s"], "--num: 900,000,000 instances would need about"),
    ("sweep", ["gravity", "--duration", "1e9", "--out", "s"], "--duration: 1e+09 s at a 0.001 s step is"),
    ("ros.record", ["--num", "100000000", "--out", "r.bag"], "would need about"),
    # Motor models and delays.
    ("simulate", ["--motor", "stepper"], "--motor: unknown motor 'stepper'; choose from: ideal, dc"),
    ("simulate", ["--action-delay", "-2"], "--action-delay must be finite and >= 0, got -2"),
    ("simulate", ["--action-delay", "0.5"], "--action-delay must be a whole number of physics steps (1 ms)"),
    ("sweep", ["gravity", "--action-delay", "20000", "--out", "s"], "--action-delay 20000 ms is not shorter than"),
    ("simulate", ["--motor", "dc", "--urdf", "no_speed.urdf"], "--motor dc: the URDF gives no <limit velocity>"),
    ("perf.bench", ["--motor", "dc"], "--motor: perf.bench times ideal motors without delay or pushes"),
    ("simulate", ["--push", "2"], "--push takes INTERVAL,SPEED (s, m/s), got 1 value(s)"),
    ("simulate", ["--push", "0,0.3"], "--push interval must be finite and > 0, got 0"),
    ("simulate", ["--push", "0.0005,0.3"], "--push: the push interval must be a whole number (>= 1) of physics"),
    ("sweep", ["gravity", "--push", "1,-0.2", "--out", "s"],
     "--push speed must be finite and >= 0 and <= 340, got -0.2"),
    # Per-instance controller, motor, delay and sensor parameters, and the parameter sweep.
    ("simulate", ["--randomize", "kp=1"], "--randomize: unknown parameter 'kp'; choose from: body_mass,"),
    ("simulate", ["--randomize", "motor_stall_torque=scale(0.8,1.2)"], "motor_stall_torque is a dc motor's figure; "
                                                                        "add --motor dc"),
    ("simulate", ["--controller", "balance", "--randomize", "kp_scale=0.5..1"], "kp_scale scales joint PD gains, "
                                                                                  "which --controller balance has not"),
    ("simulate", ["--randomize", "sensor_delay=normal(0,5)"], "--randomize: sensor_delay drew a value of -"),
    ("sweep", ["gravity", "--randomize", "action_delay=5..900", "--duration", "0.5", "--out", "s"],
     "--randomize: action_delay drew"),
    # a gain Raibert refuses: it was refused by the first chunk, a traceback under the progress bar
    ("sweep", ["gains", "--param", "leg_length", "--values", "0.6,0", "--out", "s"],
     "--values 0: leg_length must be > 0 m"),
    ("sweep", ["param", "--param", "tilt_lead", "--values", "2", "--out", "s"],
     "--values 2: tilt_lead must be in [0, 1]"),
    ("sweep", ["param", "--param", "bogus", "--values", "1", "--out", "s"], "unknown --param 'bogus'; choose a "
                                                                              "Raibert gain"),
    ("sweep", ["param", "--param", "kp_scale", "--values=-1,1", "--out", "s"], "--values: kp_scale=-1 sets a value "
                                                                                    "of -1; it must be >= 0"),
    # Terrain specs: a name, its keys and their values, the heightmap's file, the grid's memory at N.
    ("simulate", ["--terrain", "hills"], "--terrain: unknown terrain 'hills'; choose from: flat, rough, steps,"),
    ("simulate", ["--terrain", "rough:amp=0.03,bumps=2"], "--terrain: rough has no key 'bumps'; it takes amp,"),
    ("simulate", ["--terrain", "rough:amp=nan"], "--terrain: amp=nan must be finite"),
    ("render", ["--still", "s.png", "--terrain", "obstacle:height=-0.1"], "--terrain: height=-0.1 must be >= 0 m"),
    ("view", ["--terrain", "crater:radius=0"], "--terrain: radius=0 must be > 0 m"),
    ("ros.record", ["--terrain", "steps:size=4xq", "--out", "r.bag"], "--terrain: size=q is not a number"),
    ("model", ["--export", "m.xml", "--terrain", "heightmap:a_file,size=4x4"], "--terrain: a_file is not a PNG image"),
    # a feature wholly beyond the grid left the ground flat under its name
    ("model", ["--export", "m.xml", "--terrain", "obstacle:height=0.1,x=5"],
     "--terrain: obstacle: x=5 m puts it beyond the ground, which spans -2 to 2 m along x (size=4x4); give an x "
     "within it or a larger size"),
    ("sweep", ["obstacle", "--heights", "0.1", "--x", "-5", "--out", "s"],
     "obstacle: x=-5 m puts it beyond the ground"),
    ("simulate", ["--terrain", "crater:x=3"], "crater: x=3 m puts it beyond the ground"),
    # seed=each draws a ground per instance; the model held instance 0's and said seed=each
    ("model", ["--export", "m.xml", "--terrain", "rough:amp=0.02,seed=each"],
     "--terrain rough:amp=0.02,wavelength=0.4,seed=each,size=4x4,cell=0.04: model --export puts every instance on one "
     "ground; give a fixed seed"),
    ("model", ["--map", "m.png", "--terrain", "rough:seed=each"], "model --map puts every instance on one ground"),
    ("model", ["--export", "m.xml", "--terrain", "heightmap:corrupt.png"], "corrupt.png is not a readable PNG image"),
    ("model", ["--export", "m.xml", "--terrain", "heightmap:nothere.png"], "heightmap nothere.png: no such file"),
    ("model", ["--export-urdf", "-", "--terrain", "rough"], "--terrain goes with --export"),
    ("simulate", ["--terrain", "rough:cell=0.002", "--num", "30000"], "--terrain rough:cell=0.002, --num: 90,000 "
                                                                       "instances would need about"),
    ("simulate", ["--terrain", "rough:cell=0.0001"], "--terrain: a 40001 x 40001 grid has 1,600,080,001 vertices"),
    ("sweep", ["gains", "--param", "speed_gain", "--values", "1,2", "--terrain", "rough", "--out", "s"],
     "--terrain: a gains sweep runs on the flat ground only, for now; a gravity, obstacle or terrain sweep takes"),
    ("sweep", ["gravity", "--terrain", "rough:seed=each", "--out", "s"], "a gravity sweep puts every instance on one "
     "ground; give a fixed seed"),
    ("sweep", ["obstacle", "--heights", "0.1,-0.05", "--out", "s"], "--terrain: height=-0.05 must be >= 0 m"),
    ("sweep", ["obstacle", "--controller", "balance", "--out", "s"], "--controller balance: obstacle sweeps measure a "
     "hopping gait on terrain: use jump, raibert or policy:PATH"),
    ("sweep", ["gaps", "--controller", "balance", "--out", "s"], "--controller balance: gaps sweeps measure a hopping "
     "gait on terrain"),
    ("sweep", ["obstacle", "--controller", "jump,raibert,jump", "--out", "s"],
     "--controller lists one twice: jump,raibert,jump"),
    ("sweep", ["gaps", "--controller", "jump,balance", "--out", "s"], "--controller balance: gaps sweeps measure a "
     "hopping gait on terrain"),
    ("sweep", ["obstacle", "--heights", "0.3", "--x", "0", "--out", "s"], "the ground within 0.1 m of the start "
     "rises to 0.300 m"),
    ("sweep", ["obstacle", "--heights", "0.2,2.5", "--motor", "dc", "--gravity", "1.62,9.81", "--out", "s"],
     "--heights 2.5: taller than any block the dc motors can lift the robot over at g=1.62 m/s² (2.19 m"),
    ("sweep", ["gaps", "--widths", "0.2,3.5", "--out", "s"], "--widths 3.5: a gap must be > 0 m and end 0.5 m before "
     "the ground's end (4 m ahead with --x 0.6): at most 2.9 m here"),
    ("sweep", ["gaps", "--x", "nan", "--out", "s"], "--x must be finite, got nan"),
    ("sweep", ["gaps", "--terrain", "rough", "--out", "s"], "--terrain: a gaps sweep makes its own ground per value "
     "(--widths); drop --terrain"),
    ("sweep", ["terrain", "--terrain", "rough", "--out", "s"], "--terrain: a terrain sweep makes its own ground per "
     "value (--amps); drop --terrain"),
    ("sweep", ["terrain", "--amps", "0.01,0.01", "--out", "s"], "--amps must be one or more different values"),
    ("perf.bench", ["--terrain", "rough:seed=each"], "--terrain rough:amp=0.03,wavelength=0.4,seed=each,size=4x4,"
     "cell=0.04: perf.bench puts every instance on one ground; give a fixed seed"),
    ("simulate", ["--terrain", "rough:seed=every"], "--terrain: seed=every is not a number"),
    ("simulate", ["--scan", "5x0,0.1"], "--scan '5x0,0.1' must be NXxNY,SPACING with 1..64 points per axis"),
    ("perf.profile", ["--terrain", "crater:rim=-1", "--engine", "mjx"], "--terrain: rim=-1 must be >= 0 m"),
    ("perf.profile", ["--settle", "50"], "--settle must be a multiple of 20 (the streams' period at this timestep), "
     "got 50"),
    ("simulate", ["--terrain", "obstacle:height=0.2,x=-0.05"], "--terrain obstacle:height=0.2,x=-0.05: the ground "
                                                               "within 0.1 m of the start rises to 0.200 m"),
    # A variation that cannot be drawn, or drew a robot that cannot be.
    ("simulate", ["--randomize", "wing_mass=1"], "--randomize: unknown parameter 'wing_mass'; choose from: body_mass,"),
    ("simulate", ["--randomize", "foot_friction=uniform(1.0,0.4)"],
     "--randomize: foot_friction: uniform(1,0.4): bounds reversed (1 > 0.4)"),
    ("simulate", ["--randomize", "base_mass=scale(0.9,inf)"],
     "--randomize: base_mass: scale(0.9,inf) has a non-finite bound"),
    ("simulate", ["--randomize", "base_mass=normal(5,5)", "--num", "16"],
     "--randomize: base_mass drew a value of -"),
    ("simulate", ["--randomize", "foot_friction=-0.2..0.5", "--num", "16"],
     "--randomize: foot_friction=uniform(-0.2,0.5) can draw a value of -0.2; it must be >= 0 and <= 10"),
    ("render", ["--video", "h.gif", "--randomize", "base_mass=0"], "--randomize: base_mass=0 sets a value of 0 kg"),
    ("simulate", ["--randomize", "thigh_length=0.2..2", "--num", "16"],
     "--randomize: thigh_length=uniform(0.2,2) can draw a value of 2 m; it must be > 0 and <= 1"),
    ("simulate", ["--randomize", "foot_radius=0", "--num", "4"],
     "--randomize: foot_radius=0 sets a value of 0 m; it must be > 0 and <= 0.1"),
    ("simulate", ["--randomize", "shank_length=uniform(0.01,0.02),thigh_length=0.05", "--num", "4"],
     "--randomize: the leg of instance 0 (thigh 0.05 m, shank 0.0"),
    ("ros.record", ["--randomize", "base_mass=5,base_mass=6"], "--randomize: base_mass given twice"),
    ("sweep", ["gravity", "--motor", "stepper", "--out", "s"], "--motor: unknown motor 'stepper'; choose from: ideal"),
    ("sweep", ["gravity", "--randomize", "base_mass=uniform(6,5)", "--out", "s"],
     "--randomize: base_mass: uniform(6,5): bounds reversed"),
]


def prepare(folder: Path) -> None:
    """The inputs the cases name (everything else they name does not exist)."""
    (folder / "a_file").write_text("a file\n")
    (folder / "no_speed.urdf").write_text(re.sub(r' velocity="[^"]*"', "", loader.DEFAULT_URDF.read_text()))
    (folder / "a_folder").mkdir()
    (folder / "garbled.world").write_text("<sdf><world><gravity>0 0 -9.8</world></sdf>")
    (folder / "binary.urdf").write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00")
    (folder / "lone").mkdir()
    (folder / "lone" / "x.mcap").write_bytes(b"\x89MCAP0\r\n")
    # a PNG whose header says 64 x 64 grey, cut off before its pixels
    (folder / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x00@\x00\x00\x00@\x08\x00"
                                         b"\x00\x00\x00\xe5\xb7\xcc\x1b\x00\x00\x00\x05IDATxx")


def listing(folder: Path) -> dict[str, tuple[int, int]]:
    """Each path's size and modification time: a file rewritten, even with the same bytes, differs. Taken while a
    run writes (test_interrupt), an atomic write's temporary file may be renamed away between the listing and its
    stat: it was never a result, and is left out."""
    out = {}
    for p in sorted(folder.rglob("*")):
        try:
            stat = p.stat()
        except FileNotFoundError:
            continue
        out[str(p.relative_to(folder))] = (stat.st_size, stat.st_mtime_ns)
    return out


class Refusal(NamedTuple):
    returncode: int
    stdout: str
    stderr: str
    cpu: float  # s of the process's own CPU time
    unchanged: bool  # its folder holds what it held before
    budget: float  # s of CPU time it may take (MAX_CPU)


def command_line(command: str) -> list[str]:
    """A package command by its module's name (`sweep`), or a script's path (experiments/train.py)."""
    return [str(ROOT / command)] if command.endswith(".py") else ["-m", f"hopper_mjx.{command}"]


def refuse_all(base: Path, cases, prepare_folder=prepare) -> dict[int, Refusal]:
    """Every case, each in its own fresh folder made by `prepare_folder`, run as a fork of one process that has
    imported what the commands import before their checks (tests/refuser.py), a few at a time; `os.wait4` gives
    each its own CPU time."""
    folders, befores, lines = {}, {}, []
    for k, (command, args, _) in enumerate(cases):
        folders[k] = base / f"case{k}"
        folders[k].mkdir()
        prepare_folder(folders[k])
        befores[k] = listing(folders[k])  # before the case runs, so that nothing it writes is counted as there
        script = str(ROOT / command) if command.endswith(".py") else command
        lines.append(json.dumps([k, str(folders[k]), script, args, str(base / f"{k}.out"), str(base / f"{k}.err")]))
    server = subprocess.run([sys.executable, str(Path(__file__).with_name("refuser.py")), str(TIMEOUT), str(WORKERS),
                             HEAVY_IMPORTS],
                            input="\n".join(lines) + "\n", env=ENV, capture_output=True, text=True,
                            timeout=TIMEOUT * (1 + len(cases) / WORKERS))
    assert server.returncode == 0, server.stderr[-2000:]
    done = {}
    for line in server.stdout.splitlines():
        k, code, cpu = json.loads(line)
        done[k] = Refusal(code, (base / f"{k}.out").read_text(), (base / f"{k}.err").read_text(), cpu,
                          listing(folders[k]) == befores[k], MAX_CPU)
    assert sorted(done) == list(range(len(cases))), server.stderr[-2000:]
    return done


def assert_refused(done: Refusal, message: str) -> None:
    """Exit code 2, one line `error: ...` holding `message`, nothing on stdout, nothing written, no compile."""
    lines = done.stderr.splitlines()
    assert done.returncode == 2, done.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], done.stderr[-2000:]
    assert done.stdout == ""
    assert done.unchanged  # nothing written, nothing created
    assert done.cpu < done.budget, f"refused after {done.cpu:.1f} s of CPU time (allowed {done.budget:.1f})"
    if "would need about" in message:  # a size refusal says what this machine has
        assert " of memory (" in lines[0] and lines[0].endswith(" available"), lines[0]


@pytest.fixture(scope="module")
def refusals(tmp_path_factory) -> dict[int, Refusal]:
    return refuse_all(tmp_path_factory.mktemp("refusals"), CASES)


@pytest.mark.parametrize("k", range(len(CASES)), ids=[f"{c}:{' '.join(a)[:40]}" for c, a, _ in CASES])
def test_refused_in_one_line_before_anything_is_built(refusals, k):
    assert_refused(refusals[k], CASES[k][2])


def test_the_seeds_gains_folder_is_taken_as_is(tmp_path):
    """`--gains` names the seed's package, whose config/ spells the file monoped.yml (its launch file's name)."""
    from test_control import SEED_YAML

    from hopper_mjx import simulate

    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "monoped.yml").write_text(SEED_YAML)
    batch = cli.check_batch(simulate.parser().parse_args(["--controller", "pid", "--gains", str(tmp_path)]))
    assert batch.gains["kfe_joint"] == {"p": 100.0, "i": 0.01, "d": 10.0, "i_clamp": 0.0}


def test_the_checks_know_what_the_library_accepts(sim):
    """cli checks names against the registry, without importing the heavy modules: every registered
    name must build, and nothing else; its copy of the default timestep must agree."""
    from hopper_mjx.envs import tasks

    for name in registry.CONTROLLERS:
        assert control.make(name, sim.robot, 2, mj_model=sim.mj_model)[0].name == name
    with pytest.raises(ValueError,
                       match="unknown controller 'bogus'; choose from: none, hold, pid, raibert, jump, balance"):
        control.make("bogus", sim.robot, 2)
    assert list(tasks.TASKS) == list(registry.TASKS)
    assert cli.DEFAULT_TIMESTEP == loader.DEFAULT_TIMESTEP


def test_the_commands_check_their_arguments_without_importing_jax():
    """Every package command the cases run imports neither JAX nor Brax before its checks: a refusal then
    costs a Python start-up (about 0.5 s of CPU), not JAX's import (1.5 s more), and the suite starts about
    two hundred of them. A module the checks reach that imports JAX at its top fails this."""
    modules = sorted({f"hopper_mjx.{c}" for c, _, _ in CASES if not c.endswith(".py")})
    code = ("import importlib, importlib.util, sys\n"
            f"for name in {modules!r}:\n"
            "    main = name + '.__main__'  # a package runs its __main__ (which only runs under -m)\n"
            "    importlib.import_module(main if importlib.util.find_spec(name).submodule_search_locations else name)\n"
            "print(sorted(k for k in ('jax', 'brax', 'mujoco.mjx') if k in sys.modules))\n")
    done = subprocess.run([sys.executable, "-c", code], env=ENV, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert len(modules) >= 8 and done.stdout.strip() == "[]", (modules, done.stdout)
