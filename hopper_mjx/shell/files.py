"""Writing results so that a kill or a power cut leaves either the old file or the whole new one.

An output still being written is listed (`partial`): a command stopped by a signal removes it
(`hopper_mjx.shell.process`), so an interrupted run leaves no half-written file behind.
"""

from __future__ import annotations

import contextlib
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


def atomic_write(path: str | Path, write) -> None:
    """Calls `write(f)` on a binary temporary file beside `path`, then renames it into place."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with partial(tmp):
        with open(tmp, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)  # atomic on one filesystem


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write(path, lambda f: f.write(text.encode()))
