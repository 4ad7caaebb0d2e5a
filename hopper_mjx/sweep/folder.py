"""A sweep's output folder: claimed by its manifest, resumed only by the same sweep, never another's.

The manifest (the sweep's arguments) marks a folder as a sweep's. A folder that exists without
one is someone else's, and a sweep refuses it rather than write (and overwrite `results.csv`)
there. A power cut leaves a damaged manifest or chunk behind: the manifest is refused in one
line; a chunk that cannot be read is recomputed. Reads JSON and NumPy only, so that the command
line checks the folder before anything is compiled.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hopper_mjx.files import atomic_write
from hopper_mjx.sweep.grid import SweepSpec

MANIFEST = "manifest.json"


class ManifestMismatch(ValueError):
    """The output folder holds a different sweep, or is not a sweep's."""


def check(out: Path, spec: SweepSpec) -> None:
    """Raises ManifestMismatch unless OUT is new (or empty), or holds this very sweep."""
    out = Path(out)
    path = out / MANIFEST
    if not path.exists():
        if out.is_dir() and any(out.iterdir()):
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
    """Creates OUT with the spec as its manifest, or checks that OUT holds this very sweep."""
    out = Path(out)
    check(out, spec)
    if not (out / MANIFEST).exists():
        out.mkdir(parents=True, exist_ok=True)
        atomic_write(out / MANIFEST, lambda f: f.write(json.dumps(spec.to_json(), indent=1).encode()))


def chunk_path(out: Path, k: int) -> Path:
    return Path(out) / "chunks" / f"{k:05d}.npy"


def read_chunk(out: Path, k: int, rows: int, columns: int) -> np.ndarray | None:
    """Chunk k's saved metrics (rows, columns), or None when it is missing or damaged (to be recomputed)."""
    try:
        saved = np.load(chunk_path(out, k))
    except (OSError, ValueError, EOFError):
        return None
    return saved if saved.shape == (rows, columns) else None
