"""Ctrl-C (SIGINT) and SIGTERM, sent as a user's terminal sends them, to simulate, sweep, training and
ros.record: during the imports (0.5 s, once the package has armed its handler), during start-up and
compilation (3 s) and mid-run. Each stops within a second of the signal, with exactly one line on stderr
and exit code 130 (143 for SIGTERM), no traceback and no half-written output; finished work is kept: a
rerun of the sweep resumes and gives the same bytes as an uninterrupted sweep, and a rerun of training
resumes from its last checkpoint.

The cases run a few at a time, from the shared persistent compile cache, with small batches.
"""

import filecmp
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import pytest
from test_bad_inputs import ENV, command_line, listing

pytestmark = pytest.mark.serial  # wall-clock bounds: `make test` runs this file alone

MAX_LATENCY = 1.0  # s from the signal to the process's exit
TIMEOUT = 240.0  # s a case may take to reach its moment, or a run to finish
WORKERS = 6
MID_RUN = 20.0  # s: past start-up and compilation from a warm cache, well before the run's end
# s of simulated time for simulate and ros.record: a 2-core machine ran 20 s of two robots in 17 s with the
# compile, so a signal at MID_RUN found the run over and the process in its exit (where Python's default acts);
# later, idle and from a warm cache, 120 s in 12.9 s (6 Dec), before MID_RUN came.
LONG = "600"

SWEEP = ["sweep", "gravity", "--values", "9.81,1.62", "--num", "4", "--chunk", "2", "--duration", "2",
         "--no-progress", "--out", "s"]
# Training: the tiny PPO of test_train, ten updates with a checkpoint after each.
TRAIN = ["experiments/train.py", "--task", "hop", "--algo", "ppo", "--no-eval", "--timesteps", "400",
         "--num-envs", "4", "--batch-size", "4", "--num-minibatches", "2", "--unroll-length", "5",
         "--updates-per-batch", "1", "--episode-length", "20", "--eval-every", "40", "--num-eval-envs", "2",
         "--policy-layers", "8,8", "--value-layers", "8,8", "--out", "run"]
TOOLS = {
    "simulate": ["simulate", "--num", "2", "--duration", LONG, "--out", "o.npz"],
    "sweep": SWEEP,
    "train": TRAIN,
    "record": ["ros.record", "--num", "2", "--duration", LONG, "--out", "r.bag"],
}


def first_chunk(folder: Path) -> bool:
    return any((folder / "s" / "chunks").glob("*.npy"))


def first_checkpoint(folder: Path) -> bool:
    return any((folder / "run" / "checkpoints").glob("*/hopper_env.json"))


def after(seconds: float):
    return lambda folder, started: time.monotonic() - started >= seconds


# (tool, signal, when: (folder, start time) -> the moment has come, what the moment is)
CASES = [(tool, signal.SIGINT, after(0.5), "imports") for tool in TOOLS]
CASES += [(tool, signal.SIGINT, after(3.0), "start-up") for tool in TOOLS]
CASES += [("simulate", signal.SIGINT, after(MID_RUN), "mid-run"),
          ("record", signal.SIGINT, after(MID_RUN), "mid-run"),
          ("sweep", signal.SIGINT, lambda folder, _: first_chunk(folder), "mid-run"),
          ("train", signal.SIGINT, lambda folder, _: first_checkpoint(folder), "mid-run"),
          ("simulate", signal.SIGTERM, after(MID_RUN), "mid-run"),
          ("sweep", signal.SIGTERM, after(3.0), "start-up")]


class Stopped(NamedTuple):
    returncode: int
    stderr: str
    latency: float  # s from the signal to the exit
    folder: Path
    before: dict  # the folder's listing just before the signal
    after: dict  # and once the process ended


def armed(pid: int) -> bool:
    """The process has armed its signal handling: `hopper_mjx.shell.process.arm` started the watcher thread, the
    first thread besides the main one. Before that, the interpreter is still starting up (on a loaded
    machine this can outlast 0.5 s) and a signal ends it as Python's default handler does."""
    lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    return any(int(line.split()[1]) >= 2 for line in lines if line.startswith("Threads:"))


def run_to_end(argv, folder: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *command_line(argv[0]), *argv[1:]], cwd=folder, env=ENV,
                          capture_output=True, text=True, timeout=TIMEOUT)


def interrupt(argv, folder: Path, signum, when) -> Stopped:
    folder.mkdir(parents=True, exist_ok=True)
    proc = subprocess.Popen([sys.executable, *command_line(argv[0]), *argv[1:]], cwd=folder, env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    started = time.monotonic()
    while not (when(folder, started) and armed(proc.pid)):
        assert proc.poll() is None, f"ended before its moment: {proc.returncode}, {proc.stderr.read()[-2000:]}"
        assert time.monotonic() - started < TIMEOUT, "its moment never came"
        time.sleep(0.02)
    before = listing(folder)
    sent = time.monotonic()
    proc.send_signal(signum)
    try:
        _, err = proc.communicate(timeout=TIMEOUT)
        latency = time.monotonic() - sent
    finally:
        proc.kill()  # a process that did not stop
    return Stopped(proc.returncode, err, latency, folder, before, listing(folder))


@pytest.fixture(scope="module")
def stops(tmp_path_factory):
    """Every case's stop, an uninterrupted sweep's folder (run beside them), and the reruns of the sweep
    and the training stopped mid-run (listed before their reruns changed them)."""
    base = tmp_path_factory.mktemp("interrupts")
    with ThreadPoolExecutor(WORKERS) as pool:
        (base / "whole").mkdir()
        whole = pool.submit(run_to_end, SWEEP, base / "whole")
        futures = [pool.submit(interrupt, TOOLS[tool], base / f"case{k}", signum, when)
                   for k, (tool, signum, when, _) in enumerate(CASES)]
        done = [f.result() for f in futures]
        assert whole.result().returncode == 0, whole.result().stderr[-2000:]
        # The reruns, beside each other: the sweep's and training's.
        reruns = {tool: pool.submit(run_to_end, TOOLS[tool], done[_case(tool, "mid-run")].folder)
                  for tool in ("sweep", "train")}
        return done, base / "whole", {tool: f.result() for tool, f in reruns.items()}


@pytest.mark.parametrize("k", range(len(CASES)),
                         ids=[f"{tool}-{signal.Signals(s).name}-{moment}" for tool, s, _, moment in CASES])
def test_a_signal_stops_the_run_at_once_in_one_line(stops, k):
    done = stops[0][k]
    signum = CASES[k][1]
    lines = done.stderr.splitlines()
    assert done.returncode == 128 + signum, done.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith(f"interrupted ({signal.Signals(signum).name}): "), done.stderr
    assert done.latency < MAX_LATENCY, f"stopped {done.latency:.2f} s after the signal"
    left = done.after
    assert not [p for p in left if p.endswith(".tmp")]  # no half-written file
    assert not {"o.npz", "r.bag"} & set(left)  # simulate's and record's outputs: whole or absent
    finished = {p for p in done.before if p.endswith((".npy", "hopper_env.json", "metrics.json", "manifest.json"))}
    assert set(left) >= finished  # finished work is kept: chunks, checkpoints, records


def _case(tool: str, moment: str) -> int:
    return next(k for k, (t, s, _, m) in enumerate(CASES) if (t, s, m) == (tool, signal.SIGINT, moment))


def test_a_rerun_of_an_interrupted_sweep_gives_the_same_bytes(stops):
    done, whole, reruns = stops
    stopped, rerun = done[_case("sweep", "mid-run")], reruns["sweep"]
    assert "finished chunks are saved in s; rerun the same command to resume" in stopped.stderr
    kept = [p for p in stopped.after if p.startswith("s/chunks/") and p.endswith(".npy")]
    assert 1 <= len(kept) < 4  # stopped mid-run: some chunks done, not all
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    compared = ["results.csv", "table.txt"] + [f"chunks/{k:05d}.npy" for k in range(4)]
    assert all(filecmp.cmp(whole / "s" / name, stopped.folder / "s" / name, shallow=False) for name in compared)


def test_a_rerun_of_interrupted_training_resumes(stops):
    done, _, reruns = stops
    stopped, rerun = done[_case("train", "mid-run")], reruns["train"]
    saved = sorted(Path(p).parent.name for p in stopped.after if p.startswith("run/checkpoints/")
                   and p.endswith("/hopper_env.json"))
    assert saved and "rerun the same command to resume" in stopped.stderr
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    last = stopped.folder / "run" / "checkpoints" / saved[-1]
    assert f"resuming from {last.resolve()} (step {int(saved[-1]):,})" in rerun.stdout
    assert (stopped.folder / "run" / "policy" / "hopper_env.json").exists()
