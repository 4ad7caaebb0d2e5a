"""experiments/train.py: a tiny PPO run, its checkpoints, a restore, a resume, bad input (SAC: test_train_sac.py).

Tiny networks, 4 environments, 2 updates, 20-step episodes, no Brax evaluation (checkpoints only).
The restored params are read back by running the same tiny training again from the checkpoint with
a capture of Brax's step-0 params, so that run's compiled program is the one already compiled.
"""

import importlib
import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest
from test_tfevents import read_scalars

from hopper_mjx.shell import files
from training import evaluation, learners

train_script = importlib.import_module("train")  # experiments/ is on pytest's path (pyproject.toml)
# 40 environment steps per PPO update (batch 4 x 2 minibatches x unroll 5): two updates, a checkpoint after each.
TINY = ["--timesteps", "80", "--num-envs", "4", "--batch-size", "4", "--num-minibatches", "2",
        "--unroll-length", "5", "--updates-per-batch", "1", "--episode-length", "20", "--eval-every", "40",
        "--num-eval-envs", "2", "--policy-layers", "8,8", "--value-layers", "8,8", "--sac-min-replay", "16",
        "--sac-grad-updates", "1"]
# The robots the core runs (dc motors, drawn action and sensor delays and gyro noise, a push every 0.2 s of
# the 0.4 s episodes): the tiny run's program, shared by every test that reruns it.
ROBOT_IO = ["--motor", "dc", "--push", "0.2,0.3", "--randomize",
            "sensor_delay=0..10,gyro_noise=0..0.05,action_delay=0..10"]
PPO = ["--task", "hop", "--algo", "ppo", "--no-eval", *ROBOT_IO]


def _train(base, *args):
    cwd = os.getcwd()
    os.chdir(base)
    try:  # a relative --out, as on the command line (orbax itself needs absolute paths)
        record = train_script.train(train_script.parser().parse_args([*TINY, *args, "--out", "run"]))
    finally:
        os.chdir(cwd)
    return base / "run", record


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    return _train(tmp_path_factory.mktemp("ppo"), *PPO)


def _ppo_start_params(out, resume):
    """The params Brax's PPO starts from (its step-0 `policy_params_fn` call) when restoring the
    checkpoint `resume`. The same tiny run as `trained`, so the same compiled program."""
    args = train_script.parser().parse_args([*TINY, *PPO, "--out", str(out)])
    factory, _ = learners.networks(args)
    seen = {}
    learners.run_ppo(args, learners.task_config(args, train_script.check(args)), factory, args.timesteps, 0,
                         (resume, 0), progress=lambda *_: None,
                         save_checkpoint=lambda step, params: seen.setdefault(int(step), params))
    return seen[0]


def _leaves(tree):
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(tree)]


def _checkpoints(out):
    return sorted((out / "checkpoints").iterdir())


def _check_outputs(out, record):
    assert record["final_step"] >= 80
    steps = [p.name for p in _checkpoints(out)]
    assert steps[-1] == f"{record['final_step']:012d}" and len(steps) == 2
    assert (out / "reward_curve.png").stat().st_size > 1000
    assert len(record["history"]) >= 2 and record["wall_time"] > 0
    # TensorBoard's copy of the curve, as TensorBoard reads it: every history row's metrics at its step.
    assert len(list((out / "tensorboard").glob("events.out.tfevents.*"))) == 1
    board = read_scalars(out / "tensorboard")
    for tag, points in board.items():
        rows = [r for r in record["history"] if tag in r]
        assert [step for _, step, _ in points] == [r["step"] for r in rows]
        assert [value for *_, value in points] == pytest.approx([r[tag] for r in rows], rel=1e-6)  # float32
    assert set(board) == {k for r in record["history"] for k in r} - {"step", "wall_time"} != set()


def test_ppo_tiny_run_changes_the_params_and_restores_its_checkpoint_identically(trained):
    from brax.training import checkpoint

    out, record = trained
    _check_outputs(out, record)
    assert all("eval/episode_reward" not in r for r in record["history"])  # --no-eval
    first, last = (checkpoint.load(p) for p in _checkpoints(out))
    assert any(not np.array_equal(a, b) for a, b in zip(_leaves(first[1]), _leaves(last[1])))  # it learned
    restored = _ppo_start_params(out, resume=_checkpoints(out)[-1])
    for a, b in zip(_leaves(restored[:2]), _leaves(last[:2])):  # normaliser and policy, bit for bit
        np.testing.assert_array_equal(a, b)
    for a, b in zip(_leaves(last), _leaves(checkpoint.load(out / "policy"))):
        np.testing.assert_array_equal(a, b)


def test_the_policy_records_the_robots_it_trained_on_and_runs_them_in_the_core(trained):
    """hopper_env.json holds the motors, delays, noise and pushes; the core runs the policy with them."""
    from hopper_mjx.envs import policy
    from hopper_mjx.hardware.signals import SensorConfig
    from hopper_mjx.scenario import Physics, Scenario
    from hopper_mjx.sim import gravity_vectors
    from hopper_mjx.variation import spec

    out, _ = trained
    config = policy.read(out / "policy")[3]
    assert (config.motor, config.push, config.action_delay) == ("dc", (0.2, 0.3), 0.0)
    assert spec.Spec.parse(config.randomize) == spec.Spec.parse(ROBOT_IO[-1])
    physics = Physics(motor="dc", push=(0.2, 0.3), variation=spec.Spec.parse(config.randomize))
    sim, final, traj = Scenario(gravity=gravity_vectors([9.81, 1.62]), physics=physics,
                                controller=f"policy:{out}").run(0.3, SensorConfig())
    steps = np.asarray(final.step)  # the core counts its physics steps (pushes, noise), the policy its own
    assert steps.min() >= 300 and (np.asarray(final.cstate.tick) == steps).all()
    assert np.isfinite(traj.qpos).all() and not np.asarray(final.diverged).any()
    assert (np.asarray(final.drive.energy) > 0).all() and np.asarray(final.sense.gyro_noise).max() > 0


def test_a_rerun_resumes_from_the_last_checkpoint(trained, capsys):
    """Run again with the same total: it finds the newest checkpoint and has nothing left to train."""
    out, record = trained
    first = record["final_step"]
    (out / "checkpoints" / "000000000001.orbax-checkpoint-tmp").mkdir()  # a save cut short by a kill
    args = [*TINY, *PPO, "--out", str(out), "--timesteps", str(first)]
    again = train_script.train(train_script.parser().parse_args(args))
    assert f"resuming from {out / 'checkpoints' / f'{first:012d}'} (step {first:,})" in capsys.readouterr().out
    assert again["final_step"] == first and again["history"] == record["history"]


def test_a_minutes_budget_stops_at_the_first_evaluation_past_it(tmp_path, capsys):
    """A spent budget ends training after the evaluation that found it so, with that evaluation's
    checkpoint as the policy (the same tiny program as `trained`, ten updates asked for)."""
    out, record = _train(tmp_path, *PPO, "--timesteps", "400", "--minutes", "1e-9")
    assert "stopped: 1e-09 min of training (--minutes)" in capsys.readouterr().out
    assert [p.name for p in _checkpoints(out)] == ["000000000040"] and record["final_step"] == 40
    assert max(r["step"] for r in record["history"]) == 40


@pytest.mark.parametrize("args, message", [
    (["--task", "run"], "--task: unknown task 'run'; choose from: stand, hop, hop_velocity, hop_terrain"),
    (["--algo", "a2c"], "--algo 'a2c' is unknown; choose from ppo, sac"),
    (["--engine", "warp"], "--engine: unknown engine 'warp'; choose from: auto, chain, mjx"),
    (["--algo", "sac", "--no-eval"], "--no-eval is for --algo ppo"),
    (["--task", "hop_velocity", "--observe-gravity"],
     "holds a ppo policy of task 'hop' with 27 observations; this run differs in its task (--task hop_velocity) and "
     "its observations (28 here)"),
    # Only what differs is named: hop_velocity observes 27 numbers too, which read "with 27 ... needs 27".
    (["--task", "hop_velocity"], "holds a ppo policy of task 'hop' with 27 observations; this run differs in its task "
                                 "(--task hop_velocity): use another --out"),
    (["--task", "hop", "--algo", "sac"], "holds a ppo policy of task 'hop' with 27 observations; this run differs in "
                                        "its algorithm (--algo sac): use"),
    # hop_terrain reads a height scan: its 25 points count in the folder's check.
    (["--task", "hop_terrain"], "holds a ppo policy of task 'hop' with 27 observations; this run differs in its task "
                                "(--task hop_terrain) and its observations (52 here)"),
    (["--terrain", "rough:amp=0.02,seed=each"], "--terrain rough:amp=0.02,wavelength=0.4,seed=each,size=4x4,cell=0.04:"
                                                " training puts every instance on one ground; give a fixed seed"),
    (["--minutes", "0"], "--minutes must be finite and > 0, got 0"),
    # The folder's networks are 8-8 (TINY): Brax would restore them into networks of the default sizes.
    ([*ROBOT_IO], "holds networks with 8-8 hidden layers where --policy-layers asks 64-64-64: pass --policy-layers "
                  "8,8 to resume it"),
    ([*ROBOT_IO, "--policy-layers", "8,8"], "where --value-layers asks 64-64-64"),
])
def test_train_rejects_bad_input_in_one_line_before_anything_runs(trained, capsys, args, message):
    out, _ = trained
    before = [p.name for p in _checkpoints(out)]
    assert train_script.main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert [p.name for p in _checkpoints(out)] == before


@pytest.mark.parametrize("args, message", [
    (["--gravity-range", "1,inf"], "--gravity-range must be two finite numbers 'low,high', got '1,inf'"),
    (["--gravity-range", "1,x"], "--gravity-range must be comma-separated numbers, got '1,x'"),
    (["--episode-length", "0"], "--episode-length must be >= 1, got 0"),
    (["--eval-gravity", "9.81,abc"], "--eval-gravity must be comma-separated numbers, got '9.81,abc'"),
    (["--eval-gravity", "9.81,-1"], "--eval-gravity must be finite and > 0, got -1"),
    (["--select-gravity", "0.5,0"], "--select-gravity must be finite and > 0, got 0"),
    (["--select-gravity", "nan"], "--select-gravity must be finite and > 0, got nan"),
    (["--seed", "-1"], "--seed must be in 0..4294967295, got -1"),
    (["--desired-kl", "0"], "--desired-kl must be finite and > 0, got 0"),
    # Each of these trained: a discount above 1 sums returns that grow without end, a nan entropy cost nan losses.
    (["--discounting", "2"], "--discounting must be finite and > 0 and <= 1, got 2"),
    (["--entropy-cost", "nan"], "--entropy-cost must be finite and >= 0, got nan"),
    (["--config", "apex_scale=-1"], "--config: apex_scale must be finite and > 0 (a kernel's width), got -1.0"),
    # Zero epochs used to train a whole run that never updated its networks.
    (["--updates-per-batch", "0"], "--updates-per-batch must be >= 1, got 0"),
    (["--value-layers", "0,3"], "--value-layers must be comma-separated positive integers (hidden layer sizes), "
                                "got '0,3'"),
    (["--policy-layers", "64,x"], "--policy-layers must be comma-separated positive integers (hidden layer sizes), "
                                  "got '64,x'"),
    (["--algo", "sac", "--desired-kl", "0.01"], "--desired-kl is for --algo ppo (Brax's SAC has no adaptive learning "
                                               "rate)"),
    (["--learning-rate", "nan"], "--learning-rate must be finite and > 0, got nan"),
    (["--reward-scaling", "-0.1"], "--reward-scaling must be finite and > 0, got -0.1"),
    (["--max-grad-norm", "nan"], "--max-grad-norm must be finite and >= 0, got nan"),
    (["--algo", "sac", "--max-grad-norm", "1"], "--max-grad-norm is for --algo ppo (Brax's SAC does not clip its "
                                                "gradients)"),
    (["--sac-target-entropy", "-3"], "--sac-target-entropy is for --algo sac (PPO has no temperature; see "
                                     "--entropy-cost)"),
    (["--algo", "sac", "--sac-target-entropy", "inf"], "--sac-target-entropy must be a finite number of nats, got inf"),
    (["--sac-hold-policy", "1000"], "--sac-hold-policy is for --algo sac (PPO has no critic to wait for)"),
    (["--algo", "sac", "--sac-hold-policy", "-5"], "--sac-hold-policy must be >= 0 env steps, got -5"),
    (["--sac-policy-lr", "1e-5"], "--sac-policy-lr is for --algo sac (PPO's policy and value share --learning-rate)"),
    (["--algo", "sac", "--sac-policy-lr", "0"], "--sac-policy-lr must be finite and > 0, got 0"),
    (["--sac-anchor", "1"], "--sac-anchor is for --algo sac with --start-from (it pulls the policy towards its start)"),
    (["--algo", "sac", "--sac-anchor", "1"], "--sac-anchor is for --algo sac with --start-from (it pulls the policy "
                                             "towards its start)"),
    # The robots' motors, delays and pushes: on the training's own physics step (here a coarser 2 ms), within an
    # episode.
    (["--config", "timestep=0.002", "--action-delay", "3"],
     "--action-delay must be a whole number of the training's physics steps (2 ms), got 3 ms"),
    (["--config", "timestep=0.002", "--push", "0.001,0.3"],
     "--push: the push interval must be a whole number (>= 1) of physics steps (0.002 s), got 0.001 s in training"),
    (["--action-delay", "400", "--episode-length", "20"],
     "--action-delay 400 ms is not shorter than an episode (--episode-length 20 at 50 Hz) 0.4 s: no command would "
     "reach the motors"),
    (["--randomize", "sensor_delay=300..900", "--episode-length", "20"],
     "--randomize: sensor_delay drew 899 ms for instance 5, not shorter than an episode (--episode-length 20 at "
     "50 Hz) 0.4 s"),
    (["--motor", "ideal", "--randomize", "motor_no_load_speed=scale(0.8,1.2)"],
     "--randomize: motor_no_load_speed is a dc motor's figure; add --motor dc"),
    (["--policy-rate", "30"], "--policy-rate must divide the training's physics rate (1000 Hz) into whole steps, "
                              "got 30 Hz"),
    (["--policy-rate", "0"], "--policy-rate must divide the training's physics rate (1000 Hz) into whole steps, "
                             "got 0 Hz"),
    # The scan ablation's switch on the plane, where nothing is scanned: by --config or by --terrain flat.
    (["--config", "observe_scan=false"], "--config: observe_scan=false zeros the height scan, which a policy reads "
                                         "only on a terrain; this one trains on the flat plane"),
    (["--task", "hop_terrain", "--terrain", "flat", "--config", "observe_scan=false"],
     "observe_scan=false zeros the height scan, which a policy reads only on a terrain; this one trains on the flat "
     "plane"),
    (["--config", "scan_counts=9,5"], "--config: scan_counts shapes the height scan, which a policy reads only on a "
                                      "terrain; this one trains on the flat plane"),
    (["--task", "hop_terrain", "--terrain", "course:tile=2"],
     "--terrain: course: gap=0.3 m must be less than 0.2 m, the trenches' spacing or the room for one on a 2 m tile "
     "(without it the gaps tiles would be flat or one pit); lower gap or raise tile"),
    # The episode is counted in policy steps at the given rate: 20 steps at 100 Hz are 0.2 s.
    (["--policy-rate", "100", "--action-delay", "200", "--episode-length", "20"],
     "--action-delay 200 ms is not shorter than an episode (--episode-length 20 at 100 Hz) 0.2 s: no command would "
     "reach the motors"),
])
def test_a_new_run_is_refused_before_its_folder_is_made(tmp_path, capsys, args, message):
    """Every option, the evaluation's too, is checked before the run folder exists (a mistake in
    --eval-gravity used to surface after the whole training run)."""
    out = tmp_path / "run"
    assert train_script.main([*PPO, *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {message}\n"
    assert not out.exists()


def test_evaluation_kicks_are_the_sweeps():
    """The evaluation claims the sweep's kicks: replicate r gets the sweep's kick for replicate r."""
    from hopper_mjx.sweep.grid import KICK, SweepSpec, expand

    g, qvel = evaluation.evaluation_batch([9.81, 1.62], 3, seed=4, nv=9)
    sweep = expand(SweepSpec(kind="gravity", gravity=(9.81, 1.62), num=3, duration=10.0, height=0.1,
                             speed=(0.0, 0.0), seed=4), 9)
    np.testing.assert_array_equal(g, sweep.gravity)
    np.testing.assert_array_equal(qvel, sweep.qvel)
    np.testing.assert_array_equal(qvel[:3], qvel[3:])  # common random numbers across gravities
    assert 0 < np.abs(qvel[:, [0, 1, 3, 4]]).max() < 6 * KICK and not qvel[:, [2, 5, 6, 7, 8]].any()


def test_each_task_has_its_threshold():
    """--scan-checkpoints' bar: stand survives in place, hopping low if at all; hop and hop_velocity also hop
    to the apex, without drift (hop) or at the commanded speed (hop_velocity)."""
    row = {"survival": 1.0, "min_hops": 5, "apex_height": 0.086, "tracking_error": 0.1}
    meets = lambda task, **change: evaluation.meets_threshold(task, {**row, **change}, height=0.10)
    assert all(meets(task) for task in ("stand", "hop", "hop_velocity"))
    assert not any(meets(task, survival=63 / 64) for task in ("stand", "hop", "hop_velocity"))
    assert meets("stand", min_hops=0) and not meets("hop", min_hops=4) and not meets("hop_velocity", min_hops=4)
    # stand: up in place (drift within the bound), its hops (if any) small
    assert meets("stand", apex_height=None) and meets("stand", apex_height=0.10)
    assert not meets("stand", apex_height=0.11) and not meets("stand", tracking_error=0.11)
    for task in ("hop", "hop_velocity"):  # 5 lift-offs of a 2 cm buzz are not hops to a 10 cm apex
        assert not meets(task, apex_height=0.02) and not meets(task, apex_height=0.084)  # -16 %
        assert meets(task, apex_height=0.114) and not meets(task, apex_height=0.116)
        assert not meets(task, tracking_error=0.11) and not meets(task, apex_height=None)


def _rows(**by_gravity):
    """Scan rows per gravity from (survival, apex rise m, drift m/s) triples, 10 hops each."""
    return {g: {"survival": s, "min_hops": 10, "apex_height": a, "tracking_error": e}
            for g, (s, a, e) in by_gravity.items()}


def test_the_best_checkpoint_is_ranked_on_the_thresholds_measures():
    """Most gravities at the threshold first, then the worst survival, then the worst error over the bounds;
    a later checkpoint that falls or misses the apex is not chosen over an earlier one that does not."""
    from hopper_mjx.metrics import thresholds

    good = _rows(**{"9.81": (1.0, 0.101, 0.02), "1.62": (1.0, 0.095, 0.03)})  # worst: 5 % apex, 0.3 of 0.1 m/s
    better = _rows(**{"9.81": (1.0, 0.100, 0.01), "1.62": (1.0, 0.099, 0.02)})
    collapsed = _rows(**{"9.81": (1.0, 0.100, 0.01), "1.62": (0.9, 0.100, 0.01)})  # one gravity loses 10 %
    off_apex = _rows(**{"9.81": (1.0, 0.055, 0.01), "1.62": (1.0, 0.133, 0.01)})  # the issue's -45 / +33 %
    scanned = [{"step": 100, "evaluation": good}, {"step": 200, "evaluation": better},
               {"step": 300, "evaluation": collapsed}, {"step": 400, "evaluation": off_apex}]
    assert thresholds.best("hop", scanned, 0.10)["step"] == 200
    assert thresholds.rank("hop", good, 0.10) == (2, 1.0, pytest.approx(-1 / 3))
    assert thresholds.rank("hop", off_apex, 0.10)[0] == 0
    assert thresholds.best("hop", scanned[2:], 0.10)["step"] == 300  # one gravity at the bar beats none
    ties = [{"step": 500, "evaluation": good}, *scanned[:1]]
    assert thresholds.best("hop", ties, 0.10)["step"] == 100  # among equals, the earliest
    stand = [{"step": 1, "evaluation": collapsed}, {"step": 2, "evaluation": off_apex}]
    assert thresholds.best("stand", stand, 0.10)["step"] == 2  # stand: survival, then drift
    assert thresholds.best("hop", [], 0.10) is None


def test_the_selected_checkpoint_becomes_the_policy_and_the_choice_is_recorded(trained):
    """select_policy copies the chosen checkpoint into policy/ (its params, byte for byte) and writes
    selection.json with its step, measures and rank."""
    import json

    out, _ = trained
    steps = [int(p.name) for p in _checkpoints(out) if p.name.isdigit()]  # not a save cut short (resume test)
    first, last = steps[0], steps[-1]
    assert first != last
    rows = {first: _rows(**{"9.81": (1.0, 0.100, 0.01)}), last: _rows(**{"9.81": (0.5, 0.100, 0.01)})}
    args = train_script.parser().parse_args([*TINY, *PPO, "--out", str(out), "--eval-height", "0.10",
                                             "--select-gravity", "9.81"])
    chosen = evaluation.select_policy(args, [{"step": s, "wall_time": 1.0, "evaluation": rows[s]}
                                               for s in (first, last)])
    assert chosen["step"] == first and chosen["meets"]
    record = json.loads((out / evaluation.SELECTION).read_text())
    assert record["step"] == first and record["evaluation"]["9.81"]["survival"] == 1.0
    assert record["rank"] == [1, 1.0, pytest.approx(-0.1)]
    source = out / "checkpoints" / f"{first:012d}"
    for f in source.rglob("*"):
        if f.is_file():
            assert (out / "policy" / f.relative_to(source)).read_bytes() == f.read_bytes()


def test_the_threshold_is_met_at_the_evaluation_gravities_and_the_policy_chosen_at_the_selection_ones(trained):
    """The first checkpoint at the threshold is judged at --eval-gravity only; the policy kept is the best at
    every --select-gravity (the sweep's nine by default), so a checkpoint that meets the threshold at 9.81
    but rises 27 % high at 0.5 m/s² loses to a later one within 15 % at both."""
    out, _ = trained
    first, last = (s := [int(p.name) for p in _checkpoints(out) if p.name.isdigit()])[0], s[-1]
    early = _rows(**{"9.81": (1.0, 0.100, 0.01), "0.5": (1.0, 0.127, 0.01)})
    late = _rows(**{"9.81": (1.0, 0.110, 0.01), "0.5": (1.0, 0.105, 0.01)})
    scanned = [{"step": first, "wall_time": 1.0, "evaluation": early},
               {"step": last, "wall_time": 2.0, "evaluation": late}]
    options = [*TINY, *PPO, "--out", str(out), "--eval-height", "0.10", "--eval-gravity", "9.81"]
    args = train_script.parser().parse_args(options)
    assert args.select_gravity == "0.5,1,1.62,2.5,3.71,5,7.5,9.81,12"
    assert evaluation.first_at_threshold("hop", scanned, 0.10, args.eval_gravity)["step"] == first
    assert evaluation.first_at_threshold("hop", scanned, 0.10, "0.5")["step"] == last
    for select, kept in (("9.81,0.5", last), ("9.81", first)):  # at 9.81 alone the earlier, closer one wins
        args = train_script.parser().parse_args([*options, "--select-gravity", select])
        chosen = evaluation.select_policy(args, scanned)
        assert chosen["step"] == kept and chosen["gravities"] == select.split(",") and chosen["meets"]


SEEDED = [*TINY, "--task", "hop", "--algo", "ppo", "--seed", "3"]  # with Brax's evaluations: reward curves


@pytest.fixture(scope="module")
def seeded(tmp_path_factory):
    """A --seeds 2 run (seeds 3 and 4), and seed 3 alone again into another folder."""
    base = tmp_path_factory.mktemp("seeds")
    assert train_script.main([*SEEDED, "--seeds", "2", "--out", str(base / "seeds")]) == 0
    assert train_script.main([*SEEDED, "--out", str(base / "again")]) == 0
    return base


def test_seeds_train_one_folder_each_and_a_seed_reruns_bit_for_bit(seeded):
    """--seeds 2 --seed 3 trains seed-3/ and seed-4/ (different params); the same seed and arguments again,
    into another folder, give the same params bit for bit (on this machine)."""
    from brax.training import checkpoint

    assert sorted(p.name for p in (seeded / "seeds").iterdir()) == ["seed-3", "seed-4"]
    three, four = (checkpoint.load(seeded / "seeds" / f"seed-{s}" / "policy") for s in (3, 4))
    assert any(not np.array_equal(a, b) for a, b in zip(_leaves(three), _leaves(four)))
    again = checkpoint.load(seeded / "again" / "policy")
    for a, b in zip(_leaves(three), _leaves(again), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_run_builds_its_evaluation_program_once(tmp_path):
    """Brax's evaluator starts its episodes from states on no particular device and is handed the policy's
    parameters on the first device, with PPO's normaliser epsilon a weakly typed Python float until the first
    update: left so, the first of a run's evaluations built one program and every later one another
    (`learners.one_evaluation_program`). A run with three evaluations (steps 0, 40 and 80) builds it once."""
    built = []

    def record(event, start_time, end_time, fun_name="", **_):
        if event == "/jax/core/compile/backend_compile_duration":
            built.append(fun_name)

    jax.monitoring.register_event_time_span_listener(record)
    try:
        assert train_script.main([*SEEDED, "--out", str(tmp_path / "run")]) == 0
    finally:
        jax.monitoring.unregister_event_time_span_listener(record)
    history = json.loads((tmp_path / "run" / "metrics.json").read_text())["history"]
    assert [r["step"] for r in history if "eval/episode_reward" in r] == [0, 40, 80]
    assert built.count("jit(generate_eval_unroll)") == 1, built


def test_the_results_table_is_read_from_the_run_folders(seeded, tmp_path):
    """experiments/results.py over a --seeds parent: one hop x PPO row of 2 seeds whose env steps/s are the
    median [min-max] of each run's own median rate, every seed's curve in the plot's data, n/a for sweeps
    not run (no --sweep)."""
    import json
    import statistics

    results = importlib.import_module("results")
    out = tmp_path / "results.md"
    assert results.main([str(seeded / "seeds"), "--out", str(out)]) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    assert [r["seed"] for r in data["runs"]] == [3, 4]
    rates = []
    for seed in (3, 4):
        history = json.loads((seeded / "seeds" / f"seed-{seed}" / "metrics.json").read_text())["history"]
        rates.append(statistics.median(r["training/sps"] for r in history if r.get("training/sps")))
        run = next(r for r in data["runs"] if r["seed"] == seed)
        assert run["curve"] == [[r["wall_time"] / 60, r["eval/episode_reward"]] for r in history
                                if "eval/episode_reward" in r] and len(run["curve"]) >= 2
    row = next(line for line in out.read_text().splitlines() if line.startswith("| hop × PPO"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells[1] == "2" and cells[2] == "0 of 0 scanned" and cells[3:5] == ["n/a"] * 2
    assert cells[5] == f"{statistics.median(rates):,.0f} [{min(rates):,.0f}–{max(rates):,.0f}]"
    # No sweep: neither the core's nor training's.
    assert cells[6:] == ["n/a / n/a", "n/a / n/a", "n/a", "n/a", "n/a / n/a / n/a"]
    assert out.with_suffix(".png").stat().st_size > 10_000


def test_the_results_table_gives_the_gap_between_training_physics_and_the_core(tmp_path):
    """A policy's two sweeps (the core's, and `--as-trained` on its training physics), as summary.json holds
    them: the gap is the largest difference at Earth, Mars and the Moon (survival in points, the apex error as a
    fraction of the command), and the row says whether it is within 5 points and 5 %."""
    import json

    results = importlib.import_module("results")

    def sweep(folder, rows):
        folder.mkdir()
        groups = [{"gravity": g, "survival": s, "apex_height": a, "tracking_error": 0.01} for g, s, a in rows]
        (folder / "summary.json").write_text(json.dumps({"groups": groups}))

    run = tmp_path / "run"
    run.mkdir()
    args = {"task": "hop", "algo": "ppo", "seed": 0, "eval_height": 0.10, "eval_speed": [0.0, 0.0]}
    (run / "metrics.json").write_text(json.dumps({"args": args, "history": []}))
    sweep(run / results.TRAINED, [(9.81, 1.0, 0.100), (3.71, 1.0, 0.102), (1.62, 1.0, 0.098), (0.5, 1.0, 0.1)])
    sweep(run / results.SWEEP, [(9.81, 1.0, 0.101), (3.71, 0.875, 0.090), (1.62, 1.0, 0.099), (0.5, 0.0, None)])
    found = results.gap(run / results.SWEEP, run / results.TRAINED, 0.10)
    assert found["survival_gap"] == 0.125  # Mars; 0.5 m/s² is not compared
    assert abs(found["apex_gap"] - 0.12) < 1e-12  # Mars: 0.090 m in the core, 0.102 in training, of 0.10
    out = tmp_path / "results.md"
    assert results.main([str(run), "--out", str(out)]) == 0
    row = next(line for line in out.read_text().splitlines() if line.startswith("| hop × PPO"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells[6] == "100% / 0%"  # the worst gravity's survival: 0.5 m/s² in the core
    assert cells[9] == "12%, 12%: **over**: the training physics differs"
    assert cells[10] == "100% / 88% / 100%"  # the core's survival at Earth, Mars and the Moon, not the worst gravity's
    # The sweeps on each part alone (`sweep --as-trained=timestep`, `=solver`) say which part makes the gap.
    for part, like in (("timestep", results.TRAINED), ("solver", results.SWEEP)):
        (run / f"{results.TRAINED}-{part}").mkdir()
        (run / f"{results.TRAINED}-{part}" / "summary.json").write_text((run / like / "summary.json").read_text())
    assert results.main([str(run), "--out", str(out)]) == 0
    row = next(line for line in out.read_text().splitlines() if line.startswith("| hop × PPO"))
    assert row.split("|")[10].strip() == ("12%, 12%: **over**: from the step (step alone 12%, 12%; "
                                          "solver cap alone 0%, 0%)")
    sweep_core = run / results.SWEEP
    (sweep_core / "summary.json").write_text((run / results.TRAINED / "summary.json").read_text())
    assert results.gap(sweep_core, run / results.TRAINED, 0.10) == {"survival_gap": 0.0, "apex_gap": 0.0}
    # Every robot down in both: no apex to compare, so no apex gap (it read inf%); down in one only, an unbounded one.
    sweep(tmp_path / "down", [(9.81, 0.0, None), (3.71, 0.0, None), (1.62, 0.0, None)])
    sweep(tmp_path / "down-too", [(9.81, 0.0, None), (3.71, 0.0, None), (1.62, 0.0, None)])
    assert results.gap(tmp_path / "down", tmp_path / "down-too", 0.10) == {"survival_gap": 0.0, "apex_gap": None}
    assert results.gap(tmp_path / "down", sweep_core, 0.10) == {"survival_gap": 1.0, "apex_gap": float("inf")}


def test_a_course_runs_curriculum_level_is_filed_with_the_next_evaluation():
    """Brax's log of finished training episodes comes between evaluations; the mean curriculum level of their
    steps is kept for the next evaluation's history row, and an evaluation's own metrics pass on to the row, but for
    its own level."""
    from training import loop

    carried = {}
    assert loop.training_log({loop.TRAINING_LEVEL: 875.0, loop.TRAINING_LENGTH: 500.0, "episode/sps": 2e3}, carried)
    assert carried == {loop.LEVEL: 1.75}
    # Episodes of levels 1 and 3, 400 and 100 steps long: Brax's means of their summed level and of their length are
    # 350 and 250, and 1.4 is the level of their steps (the mean of their levels, 2, would count the fall as much).
    assert loop.training_log({loop.TRAINING_LEVEL: (400 + 300) / 2, loop.TRAINING_LENGTH: 250.0}, carried)
    assert carried == {loop.LEVEL: 1.4}
    # The same two episodes through Brax's own training log, as the env's metric and EpisodeWrapper's sums give it.
    from brax.training.logger import EpisodeMetricsLogger

    from hopper_mjx.envs.monoped import LEVEL_METRIC

    logged = []
    brax_log = EpisodeMetricsLogger(steps_between_logging=1, progress_fn=lambda step, m: logged.append(m))
    brax_log.update_episode_metrics({LEVEL_METRIC: np.array([400.0, 300.0]), "length": np.array([400.0, 100.0]),
                                     "sum_reward": np.zeros(2)}, np.array([1.0, 1.0]), {})
    brax_carried = {}
    assert loop.training_log(logged[-1], brax_carried) and brax_carried[loop.LEVEL] == pytest.approx(1.4)
    assert not loop.training_log({"eval/episode_reward": 12.0, "training/sps": 2e3}, carried)
    assert carried == {loop.LEVEL: 1.4}
    # The evaluation's own level is its first episodes' draw, the same at every evaluation: not filed.
    evaluation = {"eval/episode_reward": 12.0, loop.EVAL_LEVEL: 0.0, loop.EVAL_LEVEL + "_std": 0.0,
                  "training/sps": 2e3, "training/walltime": 9.0}
    assert loop.evaluation_metrics(evaluation) == {"eval/episode_reward": 12.0, "training/sps": 2e3}


def test_a_course_run_is_a_row_per_ground_it_is_judged_on(tmp_path):
    """A hop_terrain run trained on the course is judged on rough ground and on a block ahead
    (`curriculum.JUDGE_GROUNDS`): a row each, each with its own sweep's survival, the threshold's columns on both;
    the reference Raibert on each ground too."""
    import json

    from hopper_mjx.envs.curriculum import JUDGE_GROUNDS

    results = importlib.import_module("results")
    run = tmp_path / "run"
    run.mkdir()
    args = {"task": "hop_terrain", "algo": "ppo", "seed": 0, "eval_height": 0.10, "eval_speed": [0.5, 0.0],
            "terrain": "course:seed=1"}
    (run / "metrics.json").write_text(json.dumps({"args": args, "history": []}))
    for folder, alive in ((results.SWEEP, 1.0), (f"{results.SWEEP}-2", 0.25)):
        (run / folder).mkdir()
        groups = [{"gravity": g, "survival": alive, "apex_height": 0.1, "tracking_error": 0.05}
                  for g in (9.81, 3.71, 1.62)]
        (run / folder / "summary.json").write_text(json.dumps({"groups": groups}))
    out = tmp_path / "results.md"
    assert results.main([str(run), "--out", str(out)]) == 0
    rows = [line for line in out.read_text().splitlines() if line.startswith("| hop_terrain × PPO")]
    assert [row.split("|")[1].strip() for row in rows] == [f"hop_terrain × PPO, judged on {g}" for g in JUDGE_GROUNDS]
    assert [row.split("|")[7].strip() for row in rows] == ["n/a / 100%", "n/a / 25%"]
    references = json.loads(out.with_suffix(".json").read_text())["references"]
    assert list(references) == [f"hop_terrain, on {g}" for g in JUDGE_GROUNDS]


def test_the_results_table_puts_each_tasks_registered_reference_beside_it(tmp_path):
    """results.py takes each task's reference from the registry: Raibert at the runs' evaluation command for the
    hopping tasks, at stand's own small apex for stand (whose runs command none). Run folders as train.py writes
    their metrics.json (arguments and an empty history); no sweep, so no measures."""
    import json

    from hopper_mjx import registry

    results = importlib.import_module("results")
    runs = []
    for task in registry.TASKS:
        run = tmp_path / task
        run.mkdir()
        args = {"task": task, "algo": "sac", "seed": 0, "eval_height": 0.12, "eval_speed": [0.0, 0.0]}
        (run / "metrics.json").write_text(json.dumps({"args": args, "history": []}))
        runs.append(str(run))
    # hop's run met its threshold (as --scan-checkpoints writes it): the row gives its minutes and its steps
    (tmp_path / "hop" / "threshold.json").write_text(json.dumps({"step": 4_915_200, "wall_time": 204.0}))
    out = tmp_path / "results.md"
    assert results.main([*runs, "--out", str(out)]) == 0
    references = json.loads(out.with_suffix(".json").read_text())["references"]
    assert set(references) == set(registry.TASKS)
    for task, ref in registry.TASK_REFERENCES.items():
        height = 0.12 if ref.height is None else ref.height
        assert references[task]["controller"] == f"{ref.controller} at {height:g} m"
        assert references[task]["survival"] is None  # not swept
    assert references["stand"]["height"] == 0.05 and references["hop"]["height"] == 0.12
    assert "| stand × raibert at 0.05 m (reference) |" in out.read_text()
    hop = next(line for line in out.read_text().splitlines() if line.startswith("| hop × SAC"))
    assert [c.strip() for c in hop.split("|")[1:-1]][2:5] == ["1 of 1 scanned", "3.4", "4.92"]


def test_runs_whose_learner_settings_differ_are_rows_of_their_own(tmp_path):
    """Two hop x PPO seeds per learner setting, one with 8 epochs per batch and one with 2: two rows, each named
    by the setting they differ in (and by nothing they share), each with its own seeds' medians; a single
    setting's runs stay one row named as before."""
    import json

    results = importlib.import_module("results")
    runs = []
    for epochs, minutes in ((8, (4.0, 6.0)), (2, (2.0, 3.0))):
        for seed, wall in enumerate(minutes):
            run = tmp_path / f"e{epochs}-s{seed}"
            run.mkdir()
            args = {"task": "hop", "algo": "ppo", "seed": seed, "eval_height": 0.10, "eval_speed": [0.0, 0.0],
                    "updates_per_batch": epochs, "num_minibatches": 8, "learning_rate": 6e-4}
            (run / "metrics.json").write_text(json.dumps({"args": args, "history": []}))
            (run / "threshold.json").write_text(json.dumps({"step": 1_000_000 * (seed + 1), "wall_time": 60 * wall}))
            runs.append(str(run))
    out = tmp_path / "results.md"
    assert results.main([*runs, "--out", str(out)]) == 0
    rows = {c[0]: c for c in ([x.strip() for x in line.split("|")[1:-1]] for line in out.read_text().splitlines()
                               if line.startswith("| hop × PPO"))}
    assert set(rows) == {"hop × PPO, epochs per batch 2", "hop × PPO, epochs per batch 8"}
    assert rows["hop × PPO, epochs per batch 2"][1:5] == ["2", "2 of 2 scanned", "2.5 [2.0–3.0]", "1.50 [1.00–2.00]"]
    assert rows["hop × PPO, epochs per batch 8"][3] == "5.0 [4.0–6.0]"
    assert results.main([*runs[:2], "--out", str(out)]) == 0
    assert "| hop × PPO | 2 | 2 of 2 scanned | 5.0 [4.0–6.0] |" in out.read_text()


def test_a_sac_row_started_from_another_policy_says_so_even_alone(tmp_path):
    """SAC seeds started from a PPO run (--start-from) and SAC seeds from their own start are two rows, each
    named by its start; the started ones alone still say where they started (their steps are not SAC's alone)."""
    import json

    results = importlib.import_module("results")
    runs = []
    for start in ("runs/ppo-hop", None):
        for seed in (0, 1):
            run = tmp_path / f"{start is None}-{seed}"
            run.mkdir()
            args = {"task": "hop", "algo": "sac", "seed": seed, "eval_height": 0.10, "eval_speed": [0.0, 0.0],
                    "start_from": start}
            (run / "metrics.json").write_text(json.dumps({"args": args, "history": []}))
            runs.append(str(run))
    out = tmp_path / "results.md"
    named = lambda: {line.split("|")[1].strip() for line in out.read_text().splitlines()
                     if line.startswith("| hop × SAC")}
    assert results.main([*runs, "--out", str(out)]) == 0
    assert named() == {"hop × SAC, started from ppo-hop's policy", "hop × SAC, from its own start"}
    assert results.main([*runs[:2], "--out", str(out)]) == 0
    assert named() == {"hop × SAC, started from ppo-hop's policy"}
    assert results.main([*runs[2:], "--out", str(out)]) == 0
    assert named() == {"hop × SAC"}


def test_sac_rows_that_differ_in_the_policys_learning_rate_name_it(tmp_path):
    """SAC seeds with --sac-policy-lr and seeds without it are two rows, named by the rate or by its absence."""
    import json

    results = importlib.import_module("results")
    runs = []
    for rate in (3e-5, None):
        run = tmp_path / f"lr-{rate}"
        run.mkdir()
        args = {"task": "hop", "algo": "sac", "seed": 0, "eval_height": 0.10, "eval_speed": [0.0, 0.0],
                "sac_policy_lr": rate}
        (run / "metrics.json").write_text(json.dumps({"args": args, "history": []}))
        runs.append(str(run))
    out = tmp_path / "results.md"
    assert results.main([*runs, "--out", str(out)]) == 0
    assert {line.split("|")[1].strip() for line in out.read_text().splitlines() if line.startswith("| hop × SAC")} \
        == {"hop × SAC, SAC policy learning rate 3e-05", "hop × SAC, SAC policy at the critic's learning rate"}


def test_runs_whose_task_config_differs_are_rows_of_their_own(tmp_path):
    """The scan ablation: a hop_terrain seed trained blind (`--config observe_scan=false`) and one with its scan are
    rows of their own on each judging ground, the blind one named by its --config, the other by its task's own."""
    import json

    from hopper_mjx.envs.curriculum import JUDGE_GROUNDS

    results = importlib.import_module("results")
    runs = []
    for name, config, wall in (("scan", [], 30.0), ("blind", ["observe_scan=false"], 40.0)):
        run = tmp_path / name
        run.mkdir()
        args = {"task": "hop_terrain", "algo": "ppo", "seed": 0, "eval_height": 0.10, "eval_speed": [0.5, 0.0],
                "terrain": "course:seed=1", "config": config}
        (run / "metrics.json").write_text(json.dumps({"args": args, "history": []}))
        (run / "threshold.json").write_text(json.dumps({"step": 4_000_000, "wall_time": 60 * wall}))
        runs.append(str(run))
    out = tmp_path / "results.md"
    assert results.main([*runs, "--out", str(out)]) == 0
    rows = {c[0]: c for c in ([x.strip() for x in line.split("|")[1:-1]] for line in out.read_text().splitlines()
                               if line.startswith("| hop_terrain × PPO"))}
    assert set(rows) == {f"hop_terrain × PPO, {said}, judged on {g}" for g in JUDGE_GROUNDS
                         for said in ("--config observe_scan=false", "the task's own config")}
    assert rows[f"hop_terrain × PPO, --config observe_scan=false, judged on {JUDGE_GROUNDS[0]}"][3] == "40.0"
    assert rows[f"hop_terrain × PPO, the task's own config, judged on {JUDGE_GROUNDS[0]}"][3] == "30.0"


def test_a_run_off_its_tasks_own_config_or_ground_says_so_alone(tmp_path):
    """A row whose runs changed the task's config or trained on another course names both, with no other row to
    differ from; a run on the task's own course (its spec written another way) names neither."""
    import json

    from hopper_mjx.envs.curriculum import JUDGE_GROUNDS
    from hopper_mjx.terrain import spec

    results = importlib.import_module("results")
    tile3 = str(spec.parse("course:seed=1,tile=3"))
    for name, terrain, config, said in (("wide", "course:tile=3,seed=1", ["apex_range=0.93,1.13"],
                                         f", on {tile3}, --config apex_range=0.93,1.13"),
                                        ("own", str(spec.parse("course:seed=1")), [], "")):
        run = tmp_path / name
        run.mkdir()
        args = {"task": "hop_terrain", "algo": "ppo", "seed": 0, "eval_height": 0.10, "eval_speed": [0.5, 0.0],
                "terrain": terrain, "config": config}
        (run / "metrics.json").write_text(json.dumps({"args": args, "history": []}))
        out = tmp_path / f"{name}.md"
        assert results.main([str(run), "--out", str(out)]) == 0
        rows = {line.split("|")[1].strip() for line in out.read_text().splitlines()
                if line.startswith("| hop_terrain × PPO")}
        assert rows == {f"hop_terrain × PPO{said}, judged on {g}" for g in JUDGE_GROUNDS}


def test_train_rejects_an_out_it_cannot_make_in_one_line(tmp_path, capsys):
    """Under a file: one line, nothing made. A missing parent (runs/ on a fresh clone, as the docs' commands
    write) is made with the run, so the check passes and still makes nothing."""
    (tmp_path / "a_file").write_text("")
    for out in (tmp_path / "a_file" / "run", tmp_path / "a_file" / "deeper" / "run"):
        assert train_script.main(["--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "its folder " + str(tmp_path / "a_file") + " is not a folder" in err and err.count("\n") == 1
    train_script.check(train_script.parser().parse_args(["--out", str(tmp_path / "runs" / "run")]))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]


def test_a_damaged_history_is_refused_in_one_line(tmp_path, capsys):
    """A metrics.json cut short (what a kill mid-write left before writes were atomic) stops the resume
    with one line naming it, and is left as it was."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "metrics.json").write_text('{"history": [{"step": 4')
    assert train_script.main([*TINY, *PPO, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == f"error: --out: {out.resolve() / 'metrics.json'} is damaged (cut short?); move it away to train " \
                  "from the checkpoints without the old history, or use another --out\n"
    assert (out / "metrics.json").read_text() == '{"history": [{"step": 4'


def test_a_run_into_a_folder_another_run_holds_is_refused_in_one_line(tmp_path, capsys):
    """Two runs resuming one folder at once each wrote the same checkpoints. While another live process holds
    the folder (its lock, as a running train.py holds it), a run given it refuses in one line naming the holder,
    and writes nothing; the holder's death frees it."""
    out = tmp_path / "run"
    out.mkdir()
    code = ("import sys, time\nfrom hopper_mjx.shell import files\nwith files.hold(sys.argv[1], 'a test'):\n"
            "    print('held', flush=True)\n    time.sleep(300)\n")
    holder = subprocess.Popen([sys.executable, "-c", code, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        before = sorted(p.name for p in out.iterdir())
        assert train_script.main([*TINY, *PPO, "--out", str(out)]) == 2
        assert capsys.readouterr().err == (f"error: --out {out} is in use by another training run (pid {holder.pid}); "
                                           "wait for it to end, or use another --out\n")
        assert sorted(p.name for p in out.iterdir()) == before
    finally:
        holder.kill()
        holder.wait()
    with files.hold(out, "a test"):  # released with its holder's last breath
        pass


def test_the_robustness_table_gives_each_row_groups_median_and_range_over_its_seeds():
    """experiments/robustness.py's table from its sweeps' comparison.json groups: per gravity and column, the
    median [min-max] over a group's seeds of the survival and of the survivors' apex error (none: '–')."""
    robustness = importlib.import_module("robustness")
    args = robustness.parser().parse_args(["--policies", "a=x", "--out", "o", "--values", "9.81,1.62"])
    found = {"raibert": ["raibert"], "a": ["policy:s0", "policy:s1", "policy:s2"]}
    row = lambda g, alive, err: {"gravity": g, "survival": alive, "apex_error": err}
    done = {("urdf", "raibert"): {"groups": [row(9.81, 1.0, 0.001), row(1.62, 0.94, 0.031)]},
            ("randomized", "raibert"): {"groups": [row(9.81, 0.16, 0.033), row(1.62, 0.0, float("nan"))]},
            ("urdf", "a"): {"groups": [row(9.81, 0.45, 0.016), row(1.62, 0.06, 0.02), row(9.81, 0.58, 0.044),
                                       row(1.62, 0.2, 0.06), row(9.81, 0.98, 0.022), row(1.62, 0.56, 0.032)]},
            ("randomized", "a"): {"groups": [row(9.81, 0.0, float("nan")), row(1.62, 0.0, float("nan")),
                                             row(9.81, 0.5, 0.04), row(1.62, 0.0, float("nan")),
                                             row(9.81, 0.25, 0.02), row(1.62, 0.0, float("nan"))]}}
    lines = robustness.table(args, found, done).splitlines()[2:]
    assert lines == ["| 9.81 | raibert | 1 | 100 % | 0.001 | 16 % | 0.033 |",
                     "| 1.62 | raibert | 1 | 94 % | 0.031 | 0 % | – |",
                     "| 9.81 | a | 3 | 58 % [45 %–98 %] | 0.022 [0.016–0.044] | 25 % [0 %–50 %] "
                     "| 0.030 [0.020–0.040] |",
                     "| 1.62 | a | 3 | 20 % [6 %–56 %] | 0.032 [0.020–0.060] | 0 % [0 %–0 %] | – |"]


@pytest.mark.parametrize("code", [2, 1])
def test_robustness_passes_a_refused_sweeps_one_line_on(tmp_path, monkeypatch, capsys, code):
    """A sweep refused at run time (exit 2) has said why on its one line: robustness.py exits 2 and adds none.
    A sweep that failed otherwise gets robustness.py's line naming its folder and exit code."""
    import subprocess

    robustness = importlib.import_module("robustness")
    args = robustness.parser().parse_args(["--policies", "a=x", "--out", str(tmp_path / "o")])
    calls = []
    monkeypatch.setattr(robustness.subprocess, "run",
                        lambda command: calls.append(command) or subprocess.CompletedProcess(command, code))
    with pytest.raises(SystemExit) as exit_:
        robustness.run_sweeps(args, {"raibert": ["raibert"]})
    assert len(calls) == 1 and calls[0][1:3] == ["-m", "hopper_mjx.sweep"]
    err = capsys.readouterr().err.splitlines()
    assert err == ["urdf / raibert: 1 controller"]  # its progress line only
    if code == 2:
        assert exit_.value.code == 2
    else:
        assert exit_.value.code == f"error: the sweep into {tmp_path / 'o' / 'urdf' / 'raibert'} failed (exit 1)"


def test_a_policy_rate_sets_the_tasks_physics_steps_per_action_and_the_policy_keeps_it(tmp_path):
    """--policy-rate 100: 10 of the training's 1 ms steps per action (20 at the default 50 Hz), saved in the task's
    config, from which the policy controller in the core takes 10 of its 1 ms steps per action too."""
    from hopper_mjx.envs.task_config import MonopedConfig, decimation
    from hopper_mjx.model.layout import Layout

    frames = {}
    for rate in (None, "100"):
        args = train_script.parser().parse_args(["--task", "hop", "--out", str(tmp_path / "run"),
                                                 *(["--policy-rate", rate] if rate else [])])
        physics = train_script.check(args)
        env = learners.task_config(args, physics)
        frames[rate] = env.n_frames, decimation(Layout.of(physics.mj_model), env.config)
        assert MonopedConfig.from_dict(env.config.to_dict()) == env.config
    assert frames == {None: (20, 20), "100": (10, 10)}
