"""The core's lowered programs kept on disk, so that a later process runs the step without tracing it again.

JAX's persistent cache (`jaxsetup`) keeps XLA's compiled code, but every process still traces the step under
`vmap`, `scan` and `shard_map` before it can look the compiled code up: about 10 s of a one-instance run. A
`Stored` program is traced once per configuration and serialised with `jax.export`; a later process with
the same configuration deserialises it (milliseconds) and hands it to XLA, whose persistent cache then holds
its compiled code too.

The configuration is the key, and it must name everything the trace depends on: the caller's description of
what it closed over (the model's bytes, the engine, the motors, the controller's own key, the record rates),
the package's source, the versions of JAX, jaxlib and MuJoCo, and the shapes and dtypes of the arguments. A
caller that cannot name what it closed over (a controller without a `key`) does not use it. A stored file
that is missing, damaged or from another version is traced again and rewritten: the store only ever saves
time, never changes a result.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import pickle
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1]
FOLDER = "programs"  # beside XLA's own entries in the persistent cache's folder
MAGIC = b"hopper_mjx program 1\n"


@functools.cache
def source_digest() -> str:
    """sha256 of the package's Python source: a program traced from other code is another program."""
    h = hashlib.sha256()
    for path in sorted(PACKAGE.rglob("*.py")):
        h.update(str(path.relative_to(PACKAGE)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def folder() -> Path | None:
    """Where programs are kept: in JAX's persistent cache folder (`jaxsetup.configure`), None when it is off."""
    import jax

    cache = jax.config.jax_compilation_cache_dir
    return None if not cache else Path(cache) / FOLDER


def model_digest(mj_model) -> str:
    """sha256 of a compiled MuJoCo model's every number (MuJoCo's own binary form)."""
    import mujoco
    import numpy as np

    buffer = np.zeros(mujoco.mj_sizeModel(mj_model), dtype=np.uint8)
    mujoco.mj_saveModel(mj_model, None, buffer)
    return hashlib.sha256(buffer.tobytes()).hexdigest()


class Stored:
    """`fn` (a pure function of array pytrees, traced as a `jax.jit` with `compiler_options`) called through a
    program kept on disk under `key` (a string naming everything `fn` closed over); each call's argument shapes
    complete the key. Calls with the same shapes reuse the program in this process too."""

    def __init__(self, fn, key: str, compiler_options: dict | None = None):
        self.fn, self.options, self.key = fn, compiler_options, key
        self.loaded: dict[str, tuple] = {}
        self.version = versions()

    def __call__(self, *args):
        import jax

        run, out_tree, leaves = self._entry(args)
        return jax.tree_util.tree_unflatten(out_tree, run(*leaves))

    def lower(self, *args):
        """The program these arguments run, lowered (`jax.stages.Lowered`), as a jit's `lower`."""
        run, _, leaves = self._entry(args)
        return run.lower(*leaves)

    def _entry(self, args) -> tuple:
        """(runner, output tree, argument leaves) of the program for these arguments: loaded or traced once."""
        import jax

        leaves, treedef = jax.tree_util.tree_flatten(args)
        avals = [(tuple(x.shape), str(x.dtype), str(getattr(x, "sharding", ""))) for x in leaves]
        digest = hashlib.sha256(repr((self.version, self.key, str(treedef), avals)).encode()).hexdigest()
        if digest not in self.loaded:
            self.loaded[digest] = self._load(digest) or self._trace(digest, leaves, treedef)
        run, out_tree = self.loaded[digest]
        return run, out_tree, leaves

    def _runner(self, exported):
        import jax

        return jax.jit(exported.call, compiler_options=self.options)

    def _load(self, digest: str):
        """(runner, output tree) of the stored program, or None (none stored, or unreadable: traced again)."""
        import jax

        kept = _read(digest)
        if kept is None:
            return None
        try:
            serialized, out_tree = kept
            return self._runner(jax.export.deserialize(serialized)), out_tree
        except Exception:  # a damaged or foreign entry is only a miss
            return None

    def _trace(self, digest: str, leaves, treedef):
        import jax

        out_tree = []

        def flat(*leaves):
            out, tree = jax.tree_util.tree_flatten(self.fn(*jax.tree_util.tree_unflatten(treedef, leaves)))
            out_tree.append(tree)
            return out

        exported = jax.export.export(jax.jit(flat, compiler_options=self.options))(*leaves)
        _keep(digest, (exported.serialize(), out_tree[0]))
        return self._runner(exported), out_tree[0]


def versions() -> str:
    """What a stored entry was made with besides its key: JAX, jaxlib, MuJoCo, the package's source, x64."""
    import jax

    return "|".join([jax.__version__, _version("jaxlib"), _version("mujoco"), source_digest(),
                     f"x64={jax.config.jax_enable_x64}"])


def remembered(key: str, compute):
    """`compute()`'s result (a pytree of NumPy arrays), kept on disk under `key` (naming everything it depends
    on) and the `versions`, and read back by later processes instead of computed: for numbers a process would
    otherwise work out afresh each time, eagerly and slowly (Raibert's inertia facts: about 80 small programs)."""
    digest = hashlib.sha256(repr((versions(), "value", key)).encode()).hexdigest()
    kept = _read(digest)
    if kept is not None:
        return kept
    value = compute()
    _keep(digest, value)
    return value


def _read(digest: str):
    """The object kept under `digest`, or None (none kept, or damaged or foreign: a miss)."""
    path = folder()
    if path is None or not (path / digest).is_file():
        return None
    try:
        blob = (path / digest).read_bytes()
        head, check, payload = blob[:len(MAGIC)], blob[len(MAGIC):len(MAGIC) + 32], blob[len(MAGIC) + 32:]
        if head != MAGIC or hashlib.sha256(payload).digest() != check:
            return None
        return pickle.loads(payload)  # our own file, checked whole above
    except Exception:
        return None


def _keep(digest: str, value) -> None:
    path = folder()
    if path is not None:
        payload = pickle.dumps(value)
        _write(path / digest, MAGIC + hashlib.sha256(payload).digest() + payload)


def _version(package: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(package)
    except PackageNotFoundError:
        return "?"


def _write(path: Path, blob: bytes) -> None:
    """Writes `blob` whole or not at all; a store that cannot be written is no failure (nothing is saved)."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")  # two processes may store the same program at once
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(blob)
        os.replace(tmp, path)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
