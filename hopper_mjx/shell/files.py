"""Writing results so that a kill or a power cut leaves either the old file or the whole new one.

An output still being written is listed (`partial`): a command stopped by a signal removes it
(`hopper_mjx.shell.process`), so an interrupted run leaves no half-written file behind. A write that fails
(a full disk, a file-size limit) removes its temporary file and names the file it was writing.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
from pathlib import Path

_partial: set[Path] = set()


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
