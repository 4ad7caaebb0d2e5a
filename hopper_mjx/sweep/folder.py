"""A sweep's output folder: claimed by its manifest, resumed only by the same sweep, never another's.

The manifest (the sweep's arguments) marks a folder as a sweep's. A folder that exists without
one, even an empty one, is someone else's, and a sweep refuses it rather than write (and
overwrite `results.csv`) there. A power cut leaves a damaged manifest or chunk behind: the manifest is refused in one
line; a chunk that cannot be read is recomputed. Reads JSON and NumPy only, so that the command
line checks the folder before anything is compiled.

One sweep process writes a folder at a time (`hold`, `shell.files.hold`): a second one given the same --out
refuses in one line rather than interleave its chunks and tables with the first's.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from hopper_mjx.shell import files
from hopper_mjx.shell.checks import make_folder
from hopper_mjx.shell.files import atomic_write, partial
from hopper_mjx.sweep.grid import SweepSpec

MANIFEST = "manifest.json"


class ManifestMismatch(ValueError):
    """The output folder holds a different sweep, or is not a sweep's."""


def check(out: Path, spec: SweepSpec) -> None:
    """Raises ManifestMismatch unless OUT is new (or empty), or holds this very sweep."""
    out = Path(out)
    path = out / MANIFEST
    if not path.exists():
        if out.exists():  # even empty: a sweep's own folder is never without its manifest (`claim`)
            raise ManifestMismatch(f"--out {out} exists and is not a sweep's folder (no {MANIFEST}); "
                                   "a sweep writes only into a folder it made: use another --out")
        return
    try:
        saved = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise ManifestMismatch(f"--out {out}: its {MANIFEST} is damaged (cut short?); the chunks in it cannot "
                               "be trusted: use another --out") from None
    if not isinstance(saved, dict):
        raise ManifestMismatch(f"--out {out}: its {MANIFEST} is not a sweep's (a JSON {type(saved).__name__}, "
                               "not an object): use another --out")
    wanted = json.loads(json.dumps(spec.to_json()))  # tuples -> lists, as saved
    if saved != wanted:
        diff = {k: (saved.get(k), v) for k, v in wanted.items() if saved.get(k) != v}
        changes = ", ".join(f"{k}: {a!r} -> {b!r}" for k, (a, b) in diff.items())
        raise ManifestMismatch(f"{out} holds a different sweep (differs in {changes}); "
                               "use another --out, or the same arguments to resume")


def claim(out: Path, spec: SweepSpec) -> None:
    """Creates OUT with the spec as its manifest, or checks that OUT holds this very sweep. The folder
    appears with its manifest in it (made beside it, then renamed), so a stop at any moment never leaves
    a folder of ours that looks like someone else's."""
    out = Path(out)
    check(out, spec)
    if (out / MANIFEST).exists():
        return
    make_folder("--out", out.parent)
    made = out.with_name(f"{out.name}.claim-{os.getpid()}")
    with partial(made):
        shutil.rmtree(made, ignore_errors=True)
        try:
            made.mkdir()
            atomic_write(made / MANIFEST, lambda f: f.write(json.dumps(spec.to_json(), indent=1).encode()))
        except BaseException as err:  # a full disk: nothing of ours is left behind
            shutil.rmtree(made, ignore_errors=True)
            if isinstance(err, OSError):  # named as the user knows it, not by the folder made beside it
                raise OSError(err.errno, err.strerror, str(out / MANIFEST)) from None
            raise
        try:
            os.rename(made, out)
        except OSError:  # another process of this sweep claimed it first (a shared filesystem)
            shutil.rmtree(made, ignore_errors=True)
            check(out, spec)


def hold(out: Path, process: int = 0):
    """Locks OUT for this process while the block runs (`files.hold`); FolderInUse (one line) if another live
    process holds it. Each process of a multi-process sweep (`process`, its id) holds its own lock: they write
    different chunks."""
    return files.hold(out, "another sweep", f".lock-{process}")


def chunk_path(out: Path, k: int) -> Path:
    return Path(out) / "chunks" / f"{k:05d}.npy"


def read_chunk(out: Path, k: int, rows: int, columns: int) -> np.ndarray | None:
    """Chunk k's saved metrics (rows, columns), or None when it is missing or damaged (to be recomputed)."""
    try:
        saved = np.load(chunk_path(out, k))
    except (OSError, ValueError, EOFError):
        return None
    return saved if saved.shape == (rows, columns) else None
