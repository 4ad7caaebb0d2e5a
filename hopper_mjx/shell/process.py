"""What every command of the package sets up around its work: `run(main)` in each `__main__`.

- **Ctrl-C and SIGTERM stop the run within a second, at any moment**, with one line on
  stderr and exit code 130 (SIGINT) or 143 (SIGTERM). Python runs signal handlers only in
  the main thread, between bytecodes: during an XLA compile or a compiled loop the main
  thread is in C++ for tens of seconds, and a KeyboardInterrupt raised inside JAX's
  garbage-collection callback is printed and dropped (the run then went on to the end).
  So no exception is raised: the C-level handler writes the signal's number to a pipe
  (`signal.set_wakeup_fd`), a thread waiting on that pipe wakes at once, removes the
  outputs still being written (`files.partial`), prints the line and ends the process
  with `os._exit`. Results are written whole or not at all (`files.atomic_write`), so
  ending at any moment keeps the finished work: a sweep's chunks, training's checkpoints
  and metrics. A tool says what it keeps with `on_stop`.
  `python -m hopper_mjx.<command>` and the experiments' scripts arm this when the package
  is first imported (`arm_if_command`, from `startup`), so an interrupt during the imports
  is one line too; importing the package from Python changes no signal handler.
- **No false alarms on stderr.** XLA:CPU records LLVM's tuning preferences (+prefer-no-gather,
  +prefer-no-scatter) among the CPU features an executable was compiled for, and checks them
  against the host's ISA features at every load from the persistent cache: the check can
  never pass, even on the CPU that compiled it, and logs an error-level line warning of
  "SIGILL" per feature (openxla/xla#44565). PjRt also warns at every load that it "assumes
  version compatibility". `run` passes the process's stderr (file descriptor 2, where XLA's
  C++ logs) through a small process of its own (`errfilter`) that drops exactly those lines;
  every other line, a real missing ISA feature included, goes through, and so do the last
  lines of a process that XLA ends (a fatal log line, an abort), which a thread would lose
  with it. TF_CPP_MIN_LOG_LEVEL=0 turns the filter off.
- **A full disk is one line.** A write refused for want of room (`files.NO_ROOM`: ENOSPC,
  EDQUOT, or EFBIG under a file-size limit) ends the command with `error: cannot write FILE:
  ...` and what was kept, exit code 1; the half-written file is gone (`files.atomic_write`).
"""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

from hopper_mjx.shell import errfilter, files

# A path no file can have: a name longer than the file system takes, or a loop of symbolic links. Python's
# `Path.exists` and `is_file` raise these rather than answer False, so an input file's checks ended in a traceback.
UNNAMEABLE = (errno.ENAMETOOLONG, errno.ELOOP)
STOP_CODES = {signal.SIGINT: 130, signal.SIGTERM: 143}  # 128 + the signal's number, as a shell reports it
PACKAGE_ROOT = Path(__file__).resolve().parents[2]  # the checkout: hopper_mjx/ and experiments/

_said = ["stopped before its results were written"]  # what the line says was kept
_stopping = threading.Lock()
_armed = threading.Event()
_stderr: list = []  # (the real stderr's descriptor, the filter's process) while the filter runs
_real_stderr: list = []  # a copy of descriptor 2 as the process began, taken when armed


def on_stop(kept: str) -> None:
    """What an interrupt's line says was kept, from now on (e.g. where the finished chunks are)."""
    _said[0] = kept


def stop(signum: int) -> None:
    """Ends the process for `signum`: removes partial outputs, says so in one line, exits 128 + signum."""
    if not _stopping.acquire(blocking=False):
        return  # a second signal while the first is handled
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    # Descriptor 2 to nowhere, not back to the terminal, before the partial outputs go: the main thread runs on
    # meanwhile, inside XLA (a cache load at start-up) or writing into a folder removed under it, and its log lines
    # or traceback would otherwise reach the user beside the one line below.
    _end_filter(quiet=True)
    if _real_stderr:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 2)
        os.close(null)
    files.remove_partial()
    name = signal.Signals(signum).name
    # The copy taken when armed, not descriptor 2: a signal in the instant the filter takes descriptor 2
    # over, before it is on record in `_stderr`, would send the line into a pipe nobody drains.
    out = _real_stderr[0] if _real_stderr else 2
    start = "\n" if os.isatty(out) else ""  # off the terminal's ^C or progress bar
    os.write(out, f"{start}interrupted ({name}): {_said[0]}\n".encode())
    os._exit(STOP_CODES.get(signum, 128 + signum))


def _watch(fd: int) -> None:
    while True:
        try:
            got = os.read(fd, 1)
        except InterruptedError:
            continue
        if got and got[0] in STOP_CODES:
            stop(got[0])


def arm() -> None:
    """SIGINT and SIGTERM end the process via `stop`, from any moment on; call from the main thread."""
    if _armed.is_set():
        return
    _real_stderr.append(os.dup(2))
    read, write = os.pipe()
    os.set_blocking(write, False)  # the C-level handler must never block
    signal.set_wakeup_fd(write, warn_on_full_buffer=False)
    for signum in STOP_CODES:
        signal.signal(signum, lambda *_: None)  # the watcher acts; no KeyboardInterrupt in the main thread
    threading.Thread(target=_watch, args=(read,), name="stop-on-signal", daemon=True).start()
    _armed.set()


def is_command() -> bool:
    """This process runs one of the package's commands: `python -m hopper_mjx...` or a script of experiments/."""
    argv = getattr(sys, "orig_argv", [])
    if "-m" in argv[:-1]:
        return argv[argv.index("-m") + 1].split(".")[0] == "hopper_mjx"
    script = Path(sys.argv[0]).resolve() if sys.argv and sys.argv[0] else None
    return script is not None and script.parent == PACKAGE_ROOT / "experiments"


def arm_if_command() -> None:
    if is_command() and threading.current_thread() is threading.main_thread():
        arm()


def filter_stderr() -> None:
    """Passes file descriptor 2 through `errfilter` until `_end_filter` (both idempotent)."""
    if _stderr or os.environ.get("TF_CPP_MIN_LOG_LEVEL") == "0":
        return
    sys.stderr.flush()
    real = os.dup(2)
    read, write = os.pipe()
    # -I -S: the standard library only, whatever the environment's paths; started before descriptor 2 moves, so
    # that a failure to start it leaves stderr as it was.
    try:
        child = subprocess.Popen(errfilter.command(sys.executable), stdin=read, stdout=real, stderr=real,
                                 close_fds=True)
    except OSError:  # no Python to start (an embedding interpreter's sys.executable): stderr stays unfiltered
        for fd in (read, write, real):
            os.close(fd)
        return
    os.close(read)
    _stderr.extend([real, child])
    os.dup2(write, 2)
    os.close(write)


def _end_filter(quiet: bool = False) -> None:
    """Puts the real stderr back on descriptor 2 (`quiet`: /dev/null, for a process about to end) and lets the
    filter pass on what it holds."""
    if not _stderr:
        return
    real, child = _stderr
    target = os.open(os.devnull, os.O_WRONLY) if quiet else real
    os.dup2(target, 2)  # closes the pipe's last writer here: the filter reads to its end and stops
    if quiet:
        os.close(target)  # descriptor 2 holds /dev/null now
    try:
        child.wait(timeout=0.3)
    except subprocess.TimeoutExpired:
        pass  # a child process of the command still holds the pipe; the filter ends with it
    _stderr.clear()


def run(main) -> int:
    """`main()`'s exit code, with interrupts armed and stderr filtered: `sys.exit(command.run(main))`."""
    arm()
    filter_stderr()
    try:
        return main()
    except OSError as err:
        if err.errno in UNNAMEABLE:  # a path given that no file can have: the input's fault, wherever it is opened
            from hopper_mjx.shell import checks

            files.remove_partial()
            return checks.fail(f"{err.filename}: {err.strerror}")
        if err.errno not in files.NO_ROOM:
            raise
        files.remove_partial()
        print(f"error: cannot write {err.filename or 'an output'}: {err.strerror} (the disk is full, or a "
              f"file-size limit is met); {_said[0]}", file=sys.stderr)
        return 1
    finally:
        _await_stop()
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        _end_filter()


def _await_stop(longest: float = 30.0) -> None:
    """While a signal's `stop` is under way, the main thread waits for it to end the process: leaving `run` (with
    `main`'s own code, or its traceback as the partial outputs vanish under it) would race the one line and 130."""
    if _stopping.locked():
        threading.Event().wait(longest)  # `stop` ends in os._exit; the bound only guards against a stop that hangs
