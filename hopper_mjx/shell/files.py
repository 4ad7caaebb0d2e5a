"""Writing results so that a kill or a power cut leaves either the old file or the whole new one.

An output still being written is listed (`partial`): a command stopped by a signal removes it
(`hopper_mjx.shell.process`), so an interrupted run leaves no half-written file behind. A write that fails
(a full disk, a file-size limit) removes its temporary file and names the file it was writing.

One process writes an output folder at a time (`hold`): a second one given the same folder refuses in one line
rather than interleave its files with the first's. The lock is the kernel's (`flock`), so a process killed with
SIGKILL releases it with its last breath; the lock file keeps its owner's pid.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import shutil
from pathlib import Path

_partial: set[Path] = set()
_held: set[Path] = set()  # the lock files this process holds


class OutputError(ValueError):
    """An output the system refused to create after the checks let it through (tools catch this one alone
    around their work, so that a real error inside stays a traceback)."""


class FolderInUse(OutputError):
    """Another live process is writing the folder."""


@contextlib.contextmanager
def partial(path: str | Path):
    """Marks `path` (a file or a folder) as being written until the block ends."""
    path = Path(path)
    _partial.add(path)
    try:
        yield path
    finally:
        _partial.discard(path)


def remove_partial() -> None:
    """Removes every output still being written (called as the process is stopped)."""
    for path in list(_partial):
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                path.unlink()


# A write refused for want of room: the disk (or the user's quota) is full, or a file-size limit (ulimit -f) is met.
NO_ROOM = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def is_device(path: Path) -> bool:
    """`path` is /dev/null (even where it was replaced by a plain file), another device, or a pipe."""
    return str(path) == os.devnull or (path.exists() and not path.is_file() and not path.is_dir())


def atomic_write(path: str | Path, write) -> None:
    """Calls `write(f)` on a binary temporary file beside `path`, then renames it into place; on failure the
    temporary file is removed and `path` left as it was (an OSError then names `path`)."""
    path = Path(path)
    if is_device(path):  # written into, never replaced (a rename over /dev/null, as root, made it a plain file)
        with open(path, "wb") as f:
            write(f)
        return
    tmp = path.with_name(path.name + ".tmp")
    with partial(tmp):
        try:
            with open(tmp, "wb") as f:
                write(f)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)  # atomic on one filesystem
        except BaseException as err:
            with contextlib.suppress(OSError):
                tmp.unlink()
            if isinstance(err, OSError) and err.errno in NO_ROOM and not err.filename:  # a write() names no file
                raise OSError(err.errno, err.strerror, str(path)) from None
            raise


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write(path, lambda f: f.write(text.encode()))


@contextlib.contextmanager
def hold(folder: str | Path, writer: str, lock: str = ".lock"):
    """Locks the existing `folder` for this process while the block runs (its file `lock`); FolderInUse (one
    line, naming the `writer` it would have met: "another sweep") if another live process holds it."""
    path = (Path(folder) / lock).resolve()
    if path in _held:  # this process holds it already (a library caller's nested run)
        yield
        return
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        owner = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
        os.close(fd)
        raise FolderInUse(f"--out {folder} is in use by {writer} (pid {owner}); wait for it to end, or use "
                          "another --out") from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    _held.add(path)
    try:
        yield
    finally:
        _held.discard(path)
        os.close(fd)  # releases the lock; the file stays (removing it would race a process opening it)
