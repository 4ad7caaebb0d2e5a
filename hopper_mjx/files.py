"""Writing results so that a kill or a power cut leaves either the old file or the whole new one."""

from __future__ import annotations

import os
from pathlib import Path


def atomic_write(path: str | Path, write) -> None:
    """Calls `write(f)` on a binary temporary file beside `path`, then renames it into place."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)  # atomic on one filesystem


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write(path, lambda f: f.write(text.encode()))
