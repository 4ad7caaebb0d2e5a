"""Faults a long research job meets, as subprocess cases: a full disk, kill -9 mid-sweep, two processes given
the same --out, a damaged or impossible compile cache, a Foxglove port already taken. Each loses nothing: one
line on stderr, no half-written or temporary file, and a rerun gives the same bytes as an uninterrupted run.

The full disk is a file-size limit (`RLIMIT_FSIZE`, with SIGXFSZ ignored, so that a write fails with EFBIG as
it would with ENOSPC): it needs no special rights. The sweeps are the smallest (2 gravities x 2 replicates,
0.2 s, two chunks) and run with a compile cache of their own, which the cases damage.
"""

import os
import resource
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_bad_inputs import ENV, command_line

SWEEP = ["sweep", "gravity", "--values", "9.81,1.62", "--num", "4", "--chunk", "2", "--duration", "1",
         "--no-progress", "--out", "s"]
CHUNKS = [f"chunks/{k:05d}.npy" for k in range(4)]
NO_COMPILE = 15.0  # s of CPU: a refusal imports JAX (3-5 s); compiling the sweep takes 30 s or more
TIMEOUT = 900.0  # s of wall time a sweep may take on a loaded 2-core machine (each compiles once)


def start(argv, folder: Path, cache: Path, *, limit: int | None = None) -> subprocess.Popen:
    """`python -m hopper_mjx.<argv>` in `folder` with compile cache `cache`; `limit`: no file may grow beyond
    that many bytes (stdout and stderr are pipes, which the limit does not touch)."""

    def limited():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write beyond the limit fails (EFBIG), as on a full disk
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    folder.mkdir(parents=True, exist_ok=True)
    return subprocess.Popen([sys.executable, *command_line(argv[0]), *argv[1:]], cwd=folder,
                            env={**ENV, "HOPPER_MJX_CACHE": str(cache)}, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=limited if limit else None)


def finish(proc: subprocess.Popen) -> tuple[int, str, float]:
    """(exit code, stderr, s of the process's own CPU time) of a started case, its output read as it ends (the
    outputs are small: a pipe never fills)."""
    err = proc.stderr.read()
    proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, err, usage.ru_utime + usage.ru_stime


def wait_for(proc: subprocess.Popen, path: Path) -> None:
    started = time.monotonic()
    while not path.exists():
        assert proc.poll() is None, f"ended before {path.name} appeared: {proc.stderr.read()[-2000:]}"
        assert time.monotonic() - started < TIMEOUT
        time.sleep(0.05)


def leftovers(folder: Path) -> list[str]:
    """Temporary files and claim folders a write in progress leaves behind."""
    return [str(p.relative_to(folder)) for p in folder.rglob("*") if p.name.endswith(".tmp") or ".claim-" in p.name]


def cache_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if "cache" in line]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """An uninterrupted sweep (from a fresh cache of its own, which it fills); the same sweep started without a
    usable cache (a file where the cache's folder would be), a second process started on its --out while it
    runs, then the first killed with SIGKILL after its first chunk; the killed one rerun from the cache with
    every entry damaged; and, before that damage, a new run whose every file may hold only a few KiB (the disk
    full)."""
    base = tmp_path_factory.mktemp("faults")
    cache = base / "cache"
    (base / "a_file").write_text("not a folder\n")
    whole = start(SWEEP, base / "whole", cache)
    killed = start(SWEEP, base / "killed", base / "a_file" / "cache")  # beside `whole`: both compile
    wait_for(killed, base / "killed" / "s" / ".lock-0")
    second = start(SWEEP, base / "killed", cache)
    second_result = finish(second)
    wait_for(killed, base / "killed" / "s" / "chunks" / "00000.npy")
    killed.send_signal(signal.SIGKILL)
    killed_stderr = finish(killed)[1]
    kept = sorted(p.name for p in (base / "killed" / "s" / "chunks").glob("*.npy"))
    whole_result = finish(whole)
    assert whole_result[0] == 0, whole_result[1][-2000:]
    # On the healthy cache, so that it compiles nothing (a damaged entry is not replaced: it would compile again).
    full = finish(start(SWEEP, base / "full", cache, limit=16 * 1024))  # results.csv fits; the plot does not
    entries = [p for p in cache.rglob("*") if p.is_file()]
    for entry in entries:  # every compiled program in the cache damaged: its second half zeroed
        data = entry.read_bytes()
        entry.write_bytes(data[: len(data) // 2] + bytes(len(data) - len(data) // 2))
    resumed = finish(start(SWEEP, base / "killed", cache))
    return dict(base=base, whole=whole_result, second=second_result, killed_pid=killed.pid,
                killed_stderr=killed_stderr, kept=kept, entries=len(entries), resumed=resumed, full=full)


def test_kill_9_mid_sweep_then_a_rerun_gives_the_same_bytes(runs):
    base = runs["base"]
    assert 1 <= len(runs["kept"]) < len(CHUNKS)  # killed mid-run: some chunks done, not all
    code, err, _ = runs["resumed"]
    assert code == 0, err[-2000:]
    for name in ("results.csv", "table.txt", *CHUNKS):
        assert (base / "killed" / "s" / name).read_bytes() == (base / "whole" / "s" / name).read_bytes()
    assert not leftovers(base / "killed")


def test_a_second_process_on_the_same_out_refuses_in_one_line(runs):
    code, err, cpu = runs["second"]
    assert code == 2 and cpu < NO_COMPILE, err[-2000:]
    assert err.splitlines() == [f"error: --out s is in use by another sweep (pid {runs['killed_pid']}); wait for it "
                                "to end, or use another --out"]


def test_a_damaged_or_impossible_compile_cache_is_one_line_and_changes_nothing(runs):
    """The cache is an optimisation: without it, or with every entry damaged, the same bytes, one line about it."""
    assert runs["entries"] >= 1
    impossible = cache_lines(runs["killed_stderr"])
    assert len(impossible) == 1 and impossible[0].startswith("warning: compile cache ") and "a_file" in impossible[0]
    assert "Traceback" not in runs["killed_stderr"]
    code, err, _ = runs["resumed"]
    damaged = cache_lines(err)
    assert code == 0 and len(damaged) == 1 and damaged[0].startswith("warning: compile cache: Error reading"), err
    assert len(err.splitlines()) == 1  # nothing else on stderr: JAX's own two-line warning is gone


def test_a_full_disk_mid_sweep_is_one_line_and_leaves_no_partial_file(runs):
    base = runs["base"]
    code, err, _ = runs["full"]
    lines = [line for line in err.splitlines() if line not in cache_lines(err) or line.startswith("error:")]
    assert code == 1 and len(lines) == 1, err[-2000:]
    assert lines[0].startswith("error: cannot write s/gravity.png: File too large (the disk is full") and \
        lines[0].endswith("finished chunks are saved in s; rerun the same command to resume"), lines[0]
    assert len(cache_lines(err)) <= 1
    assert not (base / "full" / "s" / "gravity.png").exists() and not leftovers(base / "full")
    # what was written is whole: the table and every chunk, byte for byte the uninterrupted run's
    for name in ("results.csv", *CHUNKS):
        assert (base / "full" / "s" / name).read_bytes() == (base / "whole" / "s" / name).read_bytes()


def test_a_full_disk_before_a_sweep_starts_leaves_nothing(tmp_path):
    """Not even the manifest fits: refused before anything is compiled, and no folder of ours is left."""
    code, err, cpu = finish(start(SWEEP, tmp_path, tmp_path / "cache", limit=64))
    assert cpu < NO_COMPILE
    assert code == 1 and err.splitlines() == ["error: cannot write s/manifest.json: File too large (the disk is full, "
                                              "or a file-size limit is met); stopped before its results were written"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache"]


@pytest.mark.parametrize("tool", ["simulate", "view"])
def test_a_taken_foxglove_port_is_one_line_before_anything_is_built(tool, tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code, err, cpu = finish(start([tool, "--num", "1", "--foxglove", str(port)], tmp_path, tmp_path / "cache"))
    assert code == 2 and cpu < NO_COMPILE
    assert err.splitlines() == [f"error: --foxglove cannot listen on 127.0.0.1:{port}: Failed to bind port: "
                                "Address already in use (os error 98)"]
    assert not list(tmp_path.iterdir())


def test_an_output_that_is_a_device_is_written_into_never_replaced(tmp_path):
    """`--out /dev/null`: renaming the temporary file over it (as root) left a plain file where the device was;
    a named pipe stands in for the device here."""
    import stat
    import threading

    from hopper_mjx.shell.files import atomic_write

    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    got = []
    reader = threading.Thread(target=lambda: got.append(pipe.read_bytes()))
    reader.start()
    atomic_write(pipe, lambda f: f.write(b"results"))
    reader.join(timeout=10)
    assert got == [b"results"] and stat.S_ISFIFO(pipe.stat().st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]
