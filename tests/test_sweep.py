"""The sweep: outputs, physics of its numbers, resume after a kill, and a two-process run."""

import csv
import json
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from hopper_mjx.sweep.__main__ import main

# Tiny but real: 2 gravities x 3 replicates, 3 chunks of 2 (one compile), 3 s of hopping.
TINY = ["--values", "3.71,9.81", "--num", "3", "--duration", "3", "--chunk", "2", "--seed", "5", "--no-progress"]
EXPECTED_COLUMNS = ["gravity", "replicate", "seed", "apex_height", "flight_rise", "flight_time",
                    "ballistic_flight_time", "stance_time", "hop_period", "duty_factor", "mean_speed",
                    "tracking_error", "max_roll", "max_pitch", "hops", "fell", "diverged", "cost_of_transport",
                    "highest_apex"]


def _sweep_cmd(out, *extra):
    return [sys.executable, "-m", "hopper_mjx.sweep", "gravity", *TINY, "--out", str(out), *extra]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "tiny"
    assert main(["gravity", *TINY, "--out", str(out)]) == 0
    return out


def _read(out):
    with open(out / "results.csv") as f:
        return list(csv.DictReader(f))


def test_tiny_sweep_writes_every_output(tiny):
    for name in ("results.csv", "summary.json", "gravity.png", "table.txt", "manifest.json"):
        assert (tiny / name).stat().st_size > 0, name
    rows = _read(tiny)
    assert len(rows) == 6
    assert set(EXPECTED_COLUMNS) <= set(rows[0])
    assert sorted({float(r["gravity"]) for r in rows}) == [3.71, 9.81]
    summary = json.loads((tiny / "summary.json").read_text())
    assert [g["gravity"] for g in summary["groups"]] == [3.71, 9.81]
    assert summary["groups"][0]["label"] == "Mars" and summary["groups"][1]["label"] == "Earth"
    assert summary["versions"]["mujoco"] == summary["versions"]["mujoco-mjx"]
    assert summary["run"]["steps_per_s"] > 0
    # One row per instance, in the grid's order (gravity-major), with the run's seed.
    assert [(float(r["gravity"]), int(r["replicate"]), int(r["seed"])) for r in rows] == [
        (g, k, 5) for g in (3.71, 9.81) for k in range(3)]
    for r in rows:
        # The default kick is small: every replicate hops upright near the commanded 0.10 m apex rise.
        assert r["fell"] == "0" and r["diverged"] == "0", r
        assert int(r["hops"]) >= 3 and float(r["apex_height"]) == pytest.approx(0.10, rel=0.2), r
        assert float(r["max_roll"]) < 0.3 and float(r["max_pitch"]) < 0.3, r


def test_sweep_numbers_are_physical(tiny):
    """Hopping instances fly ballistically: flight time follows the measured rise of the arc and g."""
    rows = [r for r in _read(tiny) if int(r["hops"]) >= 2 and r["fell"] == "0"]
    assert len(rows) >= 3, "at least half of the tiny sweep must hop"
    for r in rows:
        flight = float(r["flight_time"])
        assert flight == pytest.approx(float(r["ballistic_flight_time"]), rel=0.05)
        # Each hop's period is its stance plus its flight, so their means add up too.
        assert float(r["hop_period"]) == pytest.approx(flight + float(r["stance_time"]), rel=1e-3)
    # Lower gravity, longer flights.
    by_g = {g: np.mean([float(r["flight_time"]) for r in rows if float(r["gravity"]) == g]) for g in (3.71, 9.81)}
    assert by_g[3.71] > by_g[9.81] * 1.3


def test_rerun_with_other_arguments_is_refused(tiny, capsys):
    assert main(["gravity", *TINY[:-3], "--no-progress", "--seed", "6", "--out", str(tiny)]) == 2
    assert "holds a different sweep" in capsys.readouterr().err


def test_killed_sweep_resumes_to_identical_results(tiny, tmp_path):
    out = tmp_path / "killed"
    proc = subprocess.Popen(_sweep_cmd(out), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 600
    while not (out / "chunks" / "00000.npy").exists():
        assert proc.poll() is None, "the sweep ended before it could be killed"
        assert time.time() < deadline
        time.sleep(0.2)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done_before = sorted(p.name for p in (out / "chunks").glob("*.npy"))
    assert 1 <= len(done_before) < 3
    assert main(["gravity", *TINY, "--out", str(out)]) == 0
    assert (out / "results.csv").read_bytes() == (tiny / "results.csv").read_bytes()


def test_a_damaged_chunk_is_recomputed_to_identical_results(tiny, tmp_path):
    """What a power cut leaves: an empty chunk file, and one cut short."""
    import shutil

    out = tmp_path / "damaged"
    shutil.copytree(tiny, out)
    (out / "chunks" / "00001.npy").write_bytes(b"")
    cut = (out / "chunks" / "00002.npy").read_bytes()
    (out / "chunks" / "00002.npy").write_bytes(cut[: len(cut) // 2])
    (out / "results.csv").unlink()
    assert main(["gravity", *TINY, "--out", str(out)]) == 0
    assert (out / "results.csv").read_bytes() == (tiny / "results.csv").read_bytes()


@pytest.mark.parametrize("damage", ["foreign", "truncated manifest"])
def test_a_folder_that_is_not_this_sweeps_is_refused_and_left_as_it_was(tiny, tmp_path, capsys, damage):
    out = tmp_path / "theirs"
    out.mkdir()
    if damage == "foreign":
        (out / "results.csv").write_text("someone's data\n")
        message = f"--out {out} exists and is not a sweep's folder (no manifest.json)"
    else:
        text = (tiny / "manifest.json").read_text()
        (out / "manifest.json").write_text(text[: len(text) // 2])
        message = f"--out {out}: its manifest.json is damaged (cut short?)"
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main(["gravity", *TINY, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {message}") and err.count("\n") == 1
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_two_processes_give_the_rows_of_one(tiny, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "distributed"
    # Each process keeps the one-process run's local devices, so it runs the very same program.
    procs = [subprocess.Popen(_sweep_cmd(out, "--coordinator", f"127.0.0.1:{port}", "--num-processes", "2",
                                         "--process-id", str(i)), stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True) for i in range(2)]
    logs = [p.communicate(timeout=900)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], logs
    assert (out / "results.csv").read_bytes() == (tiny / "results.csv").read_bytes()


@pytest.mark.parametrize(
    "args, message",
    [(["gravity", "--values", ""], "empty"), (["gravity", "--values", "1,abc"], "comma-separated numbers"),
     (["gravity", "--values", "0,9.81"], "> 0"), (["gravity", "--values", "-3.7"], "> 0"),
     (["gains", "--param", "bogus", "--values", "1,2"], "unknown gain 'bogus'"),
     (["gravity", "--num", "0"], "--num"),
     (["gravity", "--controller", "hold"], "a sweep runs raibert, jump, balance or policy:PATH"),
     (["compare", "--controllers", "raibert,raibert"], "lists one twice"),
     # The flag as typed, and how to make the folder (the tour's compare line comes before its training line).
     (["compare", "--controllers", "raibert,policy:/nonexistent"],
      "--controllers policy:/nonexistent: /nonexistent is not a trained policy: no such folder (train one: python "
      "experiments/train.py --out /nonexistent)"),
     (["obstacle", "--controller", "policy:/nonexistent"], "--controller policy:/nonexistent: /nonexistent is not a "
      "trained policy"),
     (["gravity", "--values", "9.81,9.81"], "gravity values must differ, got [9.81, 9.81]"),
     (["gravity", "--seed", "-1"], "--seed must be in 0..4294967295, got -1")],
)
def test_bad_input_gets_a_clear_error(args, message, capsys, tmp_path):
    try:
        code = main(args + ["--out", str(tmp_path / "x")])
    except SystemExit as exit_:  # argparse rejects unparsable values itself
        code = exit_.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


# -- pictures (figures from synthetic summaries: no simulation) ----------------------------------
def _spec(**kw):
    from hopper_mjx.sweep.grid import SweepSpec

    return SweepSpec(**{"kind": "gravity", "gravity": (9.81, 1.62, 3.71), "num": 4, "duration": 5.0, "height": 0.1,
                        "speed": (0.0, 0.0), "seed": 0, **kw})


def test_gains_heatmap_reads_at_a_glance():
    """Survival in % on a fixed 0-100 scale, as the table prints it (all survived is the top colour, not the middle
    of 90-110), labels dark on pale cells and light on dark ones, both axes ascending, each with its unit, each
    colour bar labelled."""
    from hopper_mjx.sweep import plotting, report

    spec = _spec(kind="gains", param="speed_gain", values=(0.6, 0.1))
    groups = [{"speed_gain": v, "gravity": g, "survival": 1.0, "tracking_error": 0.01 * g} for v in spec.values
              for g in spec.gravity]
    fig = report.gains_figure(spec, groups)
    survival, tracking = fig.axes[0], fig.axes[1]
    assert survival.images[0].get_clim() == (0.0, 100.0)
    assert {t.get_text() for t in survival.texts} == {"100 %"}
    assert survival.get_xlabel() == "gravity g (m/s²)" and survival.get_ylabel() == "speed_gain (1)"
    assert [a.get_ylabel() for a in fig.axes[2:]] == ["survival (% of replicates)", "speed tracking error (m/s)"]
    assert [t.get_text() for t in survival.get_xticklabels()] == ["1.62", "3.71", "9.81"]
    assert [t.get_text() for t in survival.get_yticklabels()] == ["0.1", "0.6"]
    assert {t.get_color() for t in survival.texts} == {"k"}  # every cell pale yellow (viridis at 1)
    colours = {t.get_text(): t.get_color() for t in tracking.texts}
    assert colours["0.02"] == "k" and colours["0.10"] == "w"  # magma_r: pale at the low end, black at the top
    plotting.save(fig, "/dev/null")


def test_gravity_figure_shows_energy_per_hop_in_place_and_cot_with_a_speed_command():
    from hopper_mjx.sweep import plotting, report

    groups = [{"gravity": g, "survival": 1.0, "energy_per_hop": 0.4 * g, "cost_of_transport": None}
              for g in (9.81, 1.62, 3.71)]
    in_place = report.gravity_figure(_spec(), groups)
    energy = in_place.axes[5]
    assert energy.get_ylabel() == "motor work per hop (J/kg)"
    x, y = energy.lines[0].get_data()
    assert list(x) == [1.62, 3.71, 9.81] and np.allclose(y, [0.648, 1.484, 3.924])  # ascending g, values follow
    plotting.save(in_place, "/dev/null")
    moving = report.gravity_figure(_spec(speed=(0.5, 0.0)), groups)
    assert moving.axes[5].get_ylabel() == "cost of transport (work / (m·g·distance), 1)"
    plotting.save(moving, "/dev/null")
    # Survival in % as the table prints it; the bars named; the defaults said, so that runs never look alike.
    survival = in_place.axes[4]
    assert survival.get_ylabel() == "survival (% of replicates)" and list(survival.lines[0].get_ydata()) == [100] * 3
    assert "mean ± std over survivors" in in_place.axes[0].get_legend_handles_labels()[1]
    assert "± 1 standard deviation" in in_place.get_supxlabel()
    assert "ideal motors; no delay; no pushes; the URDF's robot; flat ground" in in_place.get_suptitle()
    # A panel with no value (here no hop measured) says so, where it drew an empty axis of -0.04..0.04.
    said = {i: [t.get_text() for t in ax.texts if t.get_text().startswith("no value")] for i, ax in
            enumerate(in_place.axes)}
    assert said == {0: ["no value: no replicate still up\nfinished a hop in 5 s"], 1: said[0], 2: said[0],
                    3: said[0], 4: [], 5: []}


def test_a_plots_title_carries_every_physics_option_the_run_changed():
    from hopper_mjx import terrain
    from hopper_mjx.scenario import Physics
    from hopper_mjx.sweep import plotting
    from hopper_mjx.variation.spec import Spec

    physics = Physics(motor="dc", action_delay=0.005, push=(2.0, 0.3), variation=Spec.parse("foot_friction=0.4..1"),
                      ground=terrain.parse("rough:amp=0.02,seed=1"))
    title = plotting.physics_label(_spec(physics=physics, speed=(0.3, 0.0), kick=0.3))
    for part in ("dc motors", "action delay 5 ms", "pushes of 0.3 m/s every 2 s", "randomised foot_friction",
                 "terrain rough:amp=0.02", "kick std 0.3", "speed 0.3,0 m/s"):
        assert part in title, (part, title)
    assert "ideal motors" not in title and "no delay" not in title
    # What the sweep varies is its axis, not a setting: an action delay sweep's title claims no delay.
    delays = plotting.physics_label(_spec(kind="param", param="action_delay", values=(0.0, 5.0)))
    assert "delay" not in delays and "ideal motors; no pushes; the URDF's robot; flat ground" in delays


def test_a_randomized_sweep_records_each_replicates_robot_the_same_at_every_gravity(tmp_path, capsys):
    out = tmp_path / "rough"
    # The sizes of the README tour's randomised line as tests/test_tour.py runs it (16 instances of 2 s): one program.
    args = ["gravity", "--values", "1.62,9.81", "--num", "8", "--duration", "2", "--chunk", "16", "--seed", "2",
            "--no-progress", "--randomize", "foot_friction=uniform(0.4,1.0),base_mass=scale(0.9,1.1)"]
    assert main([*args, "--out", str(out)]) == 0
    assert "engine auto uses mjx" not in capsys.readouterr().err  # the chain takes friction and masses per instance
    rows = _read(out)
    drawn = {(float(r["gravity"]), int(r["replicate"])): (float(r["foot_friction"]), float(r["base_mass"]))
             for r in rows}
    for k in range(8):  # common random numbers: replicate k is one robot, at both gravities
        assert drawn[(1.62, k)] == drawn[(9.81, k)]
    friction, mass = np.array([drawn[(1.62, k)] for k in range(8)]).T
    assert len(set(friction)) == 8 and 0.4 <= friction.min() and friction.max() <= 1.0
    assert 4.5 <= mass.min() and mass.max() <= 5.5 and len(set(mass)) == 8  # the URDF's 5 kg base x U(0.9, 1.1)
    # Another variation into the same folder is another experiment.
    assert main([*args[:-1], "foot_friction=0.5", "--out", str(out)]) == 2
    assert "holds a different sweep (differs in variation" in capsys.readouterr().err


def test_a_parameter_sweep_gives_each_value_its_own_robots_and_keeps_the_others_draws(mj_model):
    """`sweep param`: value x gravity x replicate; a swept parameter is fixed at its value after the other
    parameters' draws, which stay the replicate's at every value (common random numbers)."""
    from hopper_mjx.scenario import Physics
    from hopper_mjx.sweep.grid import SweepSpec, expand
    from hopper_mjx.sweep.runner import robots
    from hopper_mjx.variation.spec import Spec

    physics = Physics(variation=Spec.parse("foot_friction=0.4..1.0,kp_scale=0.9..1.1"))
    spec = SweepSpec(kind="param", param="action_delay", values=(0.0, 4.0, 10.0), gravity=(1.62, 9.81), num=3,
                     duration=1.0, height=0.1, speed=(0.0, 0.0), seed=7, physics=physics)
    inst = expand(spec, 9)
    assert len(inst) == 18 and list(inst.robot_row[:6]) == [0, 1, 2, 0, 1, 2] and inst.robot_row[-1] == 8
    drawn, controls, columns = robots(spec, mj_model)
    np.testing.assert_array_equal(controls["action_delay"], np.repeat([0.0, 4.0, 10.0], 3))
    friction = drawn["pair_friction"][:, 0, 0]
    np.testing.assert_array_equal(friction[:3], friction[3:6])
    np.testing.assert_array_equal(friction[:3], friction[6:])
    assert "action_delay" not in columns  # the value has its own column; every other draw, one per element:
    assert {"foot_friction", "kp_scale_haa", "kp_scale_hfe", "kp_scale_kfe"} <= set(columns)
    np.testing.assert_array_equal(columns["kp_scale_hfe"][:3], columns["kp_scale_hfe"][6:])
    assert 0.9 <= columns["kp_scale_hfe"].min() and columns["kp_scale_hfe"].max() <= 1.1
    assert spec.robot_physics.longest_delay("action_delay") == 10  # the delay line holds the longest value
    with pytest.raises(ValueError, match="drawn by --randomize too"):
        SweepSpec(kind="param", param="foot_friction", values=(0.5,), gravity=(9.81,), num=1, duration=1.0,
                  height=0.1, speed=(0.0, 0.0), seed=0, physics=physics)


def test_a_terrain_sweep_runs_end_to_end_and_raibert_hops_on_its_rough_ground(tmp_path):
    """The help's `sweep terrain`, scaled down: flat and 2 cm rough ground at three gravities. Its report asked
    every sweep with ground of its own how many replicates reached a block, and a rough ground has none: the
    command ended in a traceback after its run. Raibert, which reads no ground, keeps every robot up on both and
    hops at every gravity: on the flat ground near its 0.10 m apex rise, on the rough one at that rise in the
    median (a bump under the foot moves a single hop by more than its 2 cm)."""
    out = tmp_path / "terrain"
    assert main(["terrain", "--amps", "0,0.02", "--num", "2", "--duration", "1.5", "--no-progress",
                 "--out", str(out)]) == 0
    groups = json.loads((out / "summary.json").read_text())["groups"]
    assert sorted((g["roughness"], g["gravity"]) for g in groups) == [
        (a, g) for a in (0.0, 0.02) for g in (1.62, 3.71, 9.81)]
    assert all(g["survival"] == 1.0 and "reached" not in g for g in groups), groups
    rows = _read(out)
    assert len(rows) == 12 and all(int(r["hops"]) >= 1 for r in rows), rows
    flat = [float(r["apex_height"]) for r in rows if float(r["roughness"]) == 0]
    rough = [float(r["apex_height"]) for r in rows if float(r["roughness"]) == 0.02]
    assert flat == pytest.approx([0.10] * 6, rel=0.2) and np.median(rough) == pytest.approx(0.10, abs=0.02), rows
    assert "made good m" in (out / "table.txt").read_text()
    assert (out / "terrain.png").stat().st_size > 10_000


def test_an_obstacle_sweeps_figure_shows_the_share_cleared_and_each_ground():
    from hopper_mjx import terrain
    from hopper_mjx.scenario import Physics
    from hopper_mjx.sweep import plotting, report

    grounds = tuple(str(terrain.parse(f"obstacle:height={h},x=0.6,size=2x1")) for h in (0.05, 0.2))
    spec = _spec(kind="obstacle", param="obstacle_height", values=(0.05, 0.2), speed=(0.3, 0.0), grounds=grounds,
                 physics=Physics(ground=terrain.parse(grounds[0])))
    assert spec.to_json()["grounds"] == grounds and "grounds" not in _spec().to_json()
    groups = [{"obstacle_height": v, "gravity": g, "survival": 1.0, "cleared": 0.5, "distance_made_good": 0.2,
               "mean_speed": 0.06} for v in spec.values for g in spec.gravity]
    fig = report.terrain_figure(spec, groups)
    cleared, ground = fig.axes[1], fig.axes[2]
    assert cleared.get_title() == "cleared the block (% of replicates)" and cleared.images[0].get_clim() == (0, 100)
    assert cleared.get_ylabel() == "obstacle_height (m)"
    # The approach: commanded, and as measured (where each gravity's robots got, at what speed).
    assert "0.3 m/s commanded, 0.06-0.06 m/s measured" in ground.get_title()
    assert "g 9.81: made 0.20 m good at 0.06 m/s" in ground.get_legend_handles_labels()[1]
    profiles = [line.get_ydata() for line in ground.lines[:2]]  # then where the robots got, dotted
    assert [p.max() for p in profiles] == pytest.approx([0.05, 0.2])  # each value's block, at y = 0
    x = ground.lines[1].get_xdata()
    assert x[profiles[1] > 0].min() == pytest.approx(0.6, abs=0.04)  # where the block starts
    plotting.save(fig, "/dev/null")


def _table(spec, inst, **values):
    from hopper_mjx.sweep.runner import columns

    cols = columns(spec)
    table = np.zeros((len(inst), len(cols)))
    for name, value in values.items():
        table[:, cols.index(name)] = value
    return table, cols


def test_a_sweep_says_why_its_robots_fell_past_the_delay_raibert_takes():
    """The README's delay sweeps fall at 5 and 10 ms: the output says so, with the measured figure and where it
    comes from; falls at a delay Raibert takes get no such excuse."""
    from hopper_mjx.sweep import report
    from hopper_mjx.sweep.grid import expand

    spec = _spec(kind="param", param="action_delay", values=(0.0, 2.0, 5.0, 10.0), gravity=(9.81,), num=2)
    inst = expand(spec, 9)
    table, cols = _table(spec, inst, fell=inst.value >= 5)
    said = report.notes(spec, inst, table, cols, report.group_summary(spec, inst, table, cols))
    assert said == [f"note: 4 of the 4 fallen robots ran 5-10 ms of action delay; {report.RAIBERT_DELAY_FIGURE}"]
    assert "docs/variation.md" in said[0] and "none from 6 ms" in said[0]
    table, cols = _table(spec, inst, fell=inst.value < 2)
    assert report.notes(spec, inst, table, cols, report.group_summary(spec, inst, table, cols)) == []
    # The LQR stance falls under a sweep's kicks wherever it runs (docs/control.md): said as well.
    spec = _spec(controller="balance", num=2)
    inst = expand(spec, 9)
    table, cols = _table(spec, inst, fell=1)
    said = report.notes(spec, inst, table, cols, report.group_summary(spec, inst, table, cols))
    assert said == [f"note: 6 of 6 robots fell; {report.BALANCE_FIGURE}"] and "docs/control.md" in said[0]


def test_a_block_sweep_of_several_controllers_runs_each_in_its_folder_and_draws_them_side_by_side(tmp_path):
    """`sweep obstacle --controller jump,raibert`: a folder each in --out, then one table whose answer names each
    controller's highest block at every gravity, and one plot with a panel per gravity, a colour per controller."""
    from hopper_mjx import terrain
    from hopper_mjx.scenario import Physics
    from hopper_mjx.sweep import __main__ as sweep
    from hopper_mjx.sweep import limits, plotting

    args = sweep.parser().parse_args(["obstacle", "--controller", "jump,raibert", "--out", str(tmp_path)])
    assert sweep.controller_names(args) == ["jump", "raibert"] and sweep.several(args)
    single = sweep.parser().parse_args(["obstacle", "--out", str(tmp_path)])
    assert sweep.controller_names(single) == ["jump"] and not sweep.several(single)
    grounds = tuple(str(terrain.parse(f"obstacle:height={h},x=0.6,size=4x2")) for h in (0.1, 0.3))
    spec = _spec(kind="obstacle", param="obstacle_height", values=(0.1, 0.3), speed=(0.3, 0.0), grounds=grounds,
                 physics=Physics(ground=terrain.parse(grounds[0])), controller="jump")
    assert sweep.folder_of(args, tmp_path, spec) == tmp_path / "jump"
    assert sweep.folder_of(single, tmp_path, spec) == tmp_path

    def groups(passed):  # {(height, g): share past the block}; half of those that got past stay up; Mars's robots
        return [{"obstacle_height": h, "gravity": g, "cleared": passed.get((h, g), 0.0),  # never reach the block
                 "survival": passed.get((h, g), 0.0) / 2, "reached": float(g != 3.71)}
                for h in spec.values for g in spec.gravity]

    results = [("jump", groups({(0.1, 1.62): 1.0, (0.3, 1.62): 0.75, (0.1, 9.81): 0.5, (0.3, 9.81): 0.25})),
               ("raibert", groups({(0.1, 1.62): 0.5}))]
    lines = limits.comparison_lines(spec, results, {})
    assert lines[1:] == ["  Moon  g 1.62 m/s²: jump 0.3 m, raibert 0.1 m",
                         "  Mars  g 3.71 m/s²: jump none, raibert none",
                         "  Earth g 9.81 m/s²: jump 0.1 m, raibert none"]
    fig = limits.comparison_figure(spec, results)
    moon = fig.axes[0]
    assert len(fig.axes) == 3 and moon.get_title() == "Moon g = 1.62 m/s²" and moon.get_xlabel() == "block height (m)"
    assert [t.get_text() for t in fig.axes[2].get_legend().get_texts()] == [
        "jump: cleared the block", "jump: up at the end", "raibert: cleared the block", "raibert: up at the end",
        "jump: no replicate reached the block", "raibert: no replicate reached the block"]
    np.testing.assert_allclose(moon.lines[0].get_ydata(), [100.0, 75.0])  # jump's share past, in %
    np.testing.assert_allclose(moon.lines[3].get_ydata(), [25.0, 0.0])  # raibert's share up
    mars = fig.axes[1]  # no robot reached the block: no line of its 0 % past, a cross at each height
    assert np.isnan(mars.lines[0].get_ydata()).all() and mars.lines[1].get_marker() == "x"
    plotting.save(fig, "/dev/null")


def test_an_obstacle_no_robot_reached_is_a_warning_with_the_duration_that_would():
    """The issue's run: 4 s at 0.3 m/s commanded, 0.23 m made good at 0.06 m/s, the block at 0.6-0.7 m."""
    from hopper_mjx import terrain
    from hopper_mjx.scenario import Physics
    from hopper_mjx.sweep import report
    from hopper_mjx.sweep.grid import expand

    grounds = tuple(str(terrain.parse(f"obstacle:height={h},x=0.6,size=4x4")) for h in (0.05, 0.15))
    spec = _spec(kind="obstacle", param="obstacle_height", values=(0.05, 0.15), speed=(0.3, 0.0), grounds=grounds,
                 physics=Physics(ground=terrain.parse(grounds[0])), duration=4.0, gravity=(1.62, 9.81))
    inst = expand(spec, 9)
    table, cols = _table(spec, inst, distance_made_good=0.23, mean_speed=0.06, tracking_error=0.24)
    groups = report.group_summary(spec, inst, table, cols)
    assert {g["reached"] for g in groups} == {0.0} and {g["cleared"] for g in groups} == {0.0}
    said = report.notes(spec, inst, table, cols, groups)
    # 4 s + (0.7 m far end + 0.1 m - 0.23 m made good) / 0.06 m/s = 13.5 s
    assert said[0] == ("warning: no replicate reached the block at x = 0.6 m at any grid point: 'cleared' there means "
                       "nothing; they made 0.23 m good at 0.06 m/s against 0.3 commanded; --duration 14 would carry "
                       "them past it at that speed")
    assert said[1] == ("warning: the speed is more than 0.1 m/s from its command (+0.30,+0.00 m/s) at every grid "
                       "point (0.24 to 0.24 m/s): each survivor's mean (vx, vy) over its last 5 s, its distance from "
                       "the command averaged")
    assert "reached" in report.table_text(spec, groups).splitlines()[0]
    # Robots that got within 0.1 m of the block reached it (the foot lands ahead of the base): no warning.
    table, cols = _table(spec, inst, distance_made_good=np.where(inst.gravity == 9.81, 0.55, 0.1), mean_speed=0.3)
    groups = report.group_summary(spec, inst, table, cols)
    said = report.notes(spec, inst, table, cols, groups)
    assert said == ["warning: no replicate reached the block at x = 0.6 m at g=1.62 obstacle_height=0.05, g=1.62 "
                    "obstacle_height=0.15: 'cleared' there means nothing; they made 0.10 m good at 0.30 m/s against "
                    "0.3 commanded; --duration 7 would carry them past it at that speed"]


def test_a_gaps_sweep_lays_one_gap_per_width_with_ground_to_land_on_beyond_it():
    from hopper_mjx import terrain
    from hopper_mjx.sweep import __main__ as sweep

    args = sweep.parser().parse_args(["gaps", "--widths", "0.1,0.35", "--x", "0.8", "--depth", "0.25",
                                      "--duration", "6"])
    grounds = sweep.terrain_grounds(args)
    for width, text in zip((0.1, 0.35), grounds):
        ground = terrain.parse(text)
        np.testing.assert_allclose(ground.obstacles(), [[0.8, 0.8 + width, -0.25]])  # one gap, no second one
        t = ground.terrain()
        xs, _ = t.axes()
        row = t.heights[t.heights.shape[0] // 2]
        assert row[(xs > 0.8 + 0.02) & (xs < 0.8 + width - 0.02)].max() == pytest.approx(-0.25)
        assert row[xs > 0.8 + width + 0.05].min() == 0.0  # level ground beyond, to its end
    # 0.3 m/s for 6 s and a metre to spare, both ways: a 6 m ground, its end 3 m ahead; a gap must end 0.5 m before.
    args.widths = [0.2, 1.8]
    with pytest.raises(ValueError, match=r"--widths 1.8: a gap must be > 0 m and end 0.5 m before the ground's end "
                                         r"\(3 m ahead with --x 0.8\): at most 1.7 m here"):
        sweep.terrain_grounds(args)


def _band_spec(kind, values, motor="dc"):
    from hopper_mjx import terrain
    from hopper_mjx.scenario import Physics

    if kind == "obstacle":
        grounds = tuple(str(terrain.parse(f"obstacle:height={v},x=0.6,size=4x2")) for v in values)
        param = "obstacle_height"
    else:
        grounds = tuple(str(terrain.parse(f"gaps:width={v},spacing=4,depth=0.3,x=0.6,size=4x2")) for v in values)
        param = "gap_width"
    return _spec(kind=kind, param=param, values=values, speed=(0.3, 0.0), grounds=grounds,
                 physics=Physics(ground=terrain.parse(grounds[0]), motor=motor))


@pytest.mark.parametrize("kind", ["obstacle", "gaps"])
def test_a_block_or_gaps_sweep_answers_beside_the_motors_bound(kind):
    """results.csv carries each row's bound (by its gravity); the table's last lines give, per gravity, the
    largest value at least half the replicates got past, in m and standing heights, beside the bound's; so does
    limits.png, with units on both axes."""
    from hopper_mjx.hardware import bound
    from hopper_mjx.model.robot import standing_height
    from hopper_mjx.sweep import limits, report
    from hopper_mjx.sweep.grid import expand

    spec = _band_spec(kind, (0.1, 0.2, 0.3))
    m = spec.physics.mj_model
    per_g = bound.bounds(m, "dc", spec.gravity)
    bounds = limits.bound_columns(spec)
    name = "height_bound" if kind == "obstacle" else "width_bound"
    assert set(bounds) == {"apex_bound", name}
    for g, b in per_g.items():
        assert bounds["apex_bound"][g] == b.apex_rise
        past = (bound.highest_block(b, standing_height(m), bound.tucked_drop(m)) if kind == "obstacle"
                else bound.widest_gap(b, bound.leg_reach(m)))
        assert bounds[name][g] == past
    inst = expand(spec, m.nv)
    table, cols = _table(spec, inst)
    header, body = report.rows(spec, inst, table, cols, bounds)
    assert header[-2:] == ["apex_bound", name]
    for g, row in zip(inst.gravity, body):
        assert row[-2] == bounds["apex_bound"][float(g)]
    # Half or more past 0.1 and 0.2 m at the Moon, 0.1 m at Mars, none at Earth.
    share = {(1.62, 0.1): 1.0, (1.62, 0.2): 0.5, (1.62, 0.3): 0.25, (3.71, 0.1): 0.75, (3.71, 0.2): 0.25}
    groups = [{spec.param: v, "gravity": g, "cleared": share.get((g, v), 0.0), "survival": 1.0}
              for v in spec.values for g in spec.gravity]
    lines = limits.lines(spec, groups, bounds)
    standing = standing_height(m)
    assert lines[1] == (f"  Earth g 9.81 m/s²: none of the grid's; bound {bounds[name][9.81]:.2f} m "
                        f"({bounds[name][9.81] / standing:.2f}), from an apex rise of {per_g[9.81].apex_rise:.2f} m")
    assert lines[2].startswith(f"  Moon  g 1.62 m/s²: 0.2 m ({0.2 / standing:.2f} standing heights); bound")
    assert lines[3].startswith("  Mars  g 3.71 m/s²: 0.1 m (")
    ax = limits.figure(spec, groups, bounds).axes[0]
    assert ax.get_xlabel() == "gravity (m/s²)" and ax.get_ylabel().endswith("(m)")
    assert ax.child_axes[0].get_ylabel() == "in standing heights (1)"
    np.testing.assert_allclose(ax.lines[0].get_ydata(), [bounds[name][g] for g in sorted(spec.gravity)])
    np.testing.assert_allclose(ax.lines[1].get_ydata(), [0.2, 0.1, np.nan])
    assert limits.bound_columns(_spec()) == {} and limits.lines(_spec(), groups, {}) == []
    # What getting past the answer asked, where the groups carry it: the Moon's at 0.2 m, not its 0.1 m's.
    asked = {"past_tilt": 12.5, "past_impact": 300.0, "peak_torque_kfe": 70.0, "peak_power_kfe": 900.0,
             "line_use_kfe": 0.9}
    for r in groups:
        r["past"] = asked if (r["gravity"], r[spec.param]) == (1.62, 0.2) else dict(asked, past_tilt=40.0)
    lines = limits.lines(spec, groups, bounds)
    weight = float(m.body_mass.sum()) * 1.62
    assert lines[4].startswith("what getting past it asked") and len(lines) == 7
    assert lines[5] == (f"  Moon  g 1.62 m/s²: landed tilted 12.5°, impact 300 N ({300.0 / weight:.1f} body weights); "
                        f"knee 70 N·m, 900 W, 0.90 of its motor's line")
    assert lines[6].startswith("  Mars  g 3.71 m/s²: landed tilted 40.0°")
    fig = limits.figure(spec, groups, bounds)
    np.testing.assert_allclose(fig.axes[1].lines[0].get_ydata(), [12.5, 40.0, np.nan])
    np.testing.assert_allclose(fig.axes[2].lines[0].get_ydata(), [300.0, 300.0, np.nan])
    np.testing.assert_allclose(fig.axes[3].lines[0].get_ydata(), [900.0, 900.0, np.nan])
    assert [ax.get_ylabel() for ax in fig.axes[1:]] == ["landing tilt (°)", "impact (N)", "knee power (W)"]


def test_a_gravity_sweep_asked_past_the_motors_bound_reports_the_highest_hop_beside_it():
    """Asked for a rise above the bound at some gravity, a gravity sweep carries the bound per gravity (the
    model's robot, its motors: `bound.bounds`), ends its table with each gravity's median highest hop against it, and
    draws both in the apex panel; asked for less than the lowest bound (the highest gravity's), nothing of it."""
    from hopper_mjx.hardware import bound
    from hopper_mjx.scenario import Physics
    from hopper_mjx.sweep import limits, report

    spec = _spec(height=1.0, physics=Physics(motor="dc"))  # above Earth's 0.28 m and Mars's 0.80 m, below the Moon's
    per_g = bound.bounds(spec.physics.mj_model, "dc", spec.gravity)
    bounds = limits.bound_columns(spec)
    assert bounds == {"apex_bound": {g: b.apex_rise for g, b in per_g.items()}}
    assert limits.bound_columns(_spec(height=0.2, physics=Physics(motor="dc"))) == {}
    # Such a sweep's rows carry how its highest hop landed; one asked for less, not (`make sweep`'s columns stay).
    from hopper_mjx.sweep.runner import LIMIT_COLUMNS, columns

    assert columns(spec)[-1:] == LIMIT_COLUMNS
    assert not set(LIMIT_COLUMNS) & set(columns(_spec(height=0.2, physics=Physics(motor="dc"))))
    groups = [{"gravity": g, "highest_median": h, "highest_best": b, "highest_tilt_median": t}
              for g, h, b, t in ((9.81, 0.25, 0.27, 4.25), (1.62, 1.5, 1.6, 12.0), (3.71, None, None, None))]
    lines = limits.apex_lines(spec, groups, bounds)
    assert lines[0].startswith("asked for a 1 m rise: the highest hop before any fall")
    assert lines[1].startswith(f"  Moon  g 1.62 m/s²: 1.50 m ({1.5 / per_g[1.62].apex_rise:.0%} of the bound;")
    assert f"the best 1.60 m ({1.6 / per_g[1.62].apex_rise:.0%}); bound" in lines[1]
    assert lines[1].endswith("; landed 12.0° off upright")
    assert lines[2] == f"  Mars  g 3.71 m/s²: none; bound {per_g[3.71].apex_rise:.2f} m"
    assert lines[3].startswith(f"  Earth g 9.81 m/s²: 0.25 m ({0.25 / per_g[9.81].apex_rise:.0%}")
    assert limits.apex_lines(spec, groups, {}) == []
    rows = [dict(r, apex_height=0.1, apex_height_std=0.0, survival=0.5) for r in groups]
    fig = report.gravity_figure(spec, rows, bounds=bounds)
    drawn = {line.get_label(): line.get_ydata() for line in fig.axes[0].lines}
    np.testing.assert_allclose(drawn["bound: the dc motors' best jump"],
                               [per_g[g].apex_rise for g in (1.62, 3.71, 9.81)])
    np.testing.assert_allclose(drawn["highest hop before any fall (median of every replicate)"], [1.5, np.nan, 0.25])
    tilt = fig.axes[3]  # in place of the duty factor: how the highest hop landed, beside SpaceHopper's 9.7°
    assert "landing tilt" in tilt.get_ylabel()
    np.testing.assert_allclose(tilt.lines[0].get_ydata(), [12.0, np.nan, 4.25])
    assert any(np.allclose(line.get_ydata(), 9.7) for line in tilt.lines)


def test_a_duration_between_samples_runs_whole_samples_and_says_so(tmp_path):
    """A sweep runs whole 10 ms samples of its streams, as its runner steps them: --duration 0.015 runs 0.02 s, and
    its spec (so its rows, folder and report) says 0.02 s, with a note naming both; 10 s and 3 s stay, silently."""
    from hopper_mjx.shell import budget
    from hopper_mjx.sim import steps_for
    from hopper_mjx.sweep import runner
    from hopper_mjx.sweep.__main__ import check, parser

    def spec(duration):
        args = parser().parse_args(["gravity", "--gravity", "9.81", "--duration", duration, "--out",
                                    str(tmp_path / duration)])
        return check(args)[0][0]

    assert [spec(d).duration for d in ("0.015", "1e-9", "3", "10", "0.7")] == [0.02, 0.01, 3.0, 10.0, 0.7]
    assert steps_for(spec("0.015").duration, 1e-3, runner.recorded(1e-3)) == 20 == steps_for(0.015, 1e-3,
                                                                                              runner.recorded(1e-3))
    assert budget.duration_note(0.015, 1e-3, 10) == ("note: --duration 0.015 s runs 0.02 s (20 steps of 1 ms): whole "
                                                     "samples of every stream, one each 10 ms")
    assert budget.duration_note(1e-9, 5e-4, 20) == ("note: --duration 1e-09 s runs 0.01 s (20 steps of 0.5 ms): "
                                                    "whole samples of every stream, one each 10 ms")
    assert budget.duration_note(10.0, 1e-3, 10) is None and budget.duration_note(3.0, 1e-3, 20) is None
    assert budget.duration_note(0.7, 1e-3, 10) is None  # 700 steps of 1 ms: 0.7000000000000001 s in floats
