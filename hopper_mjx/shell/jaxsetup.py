"""Process-wide JAX settings for the command-line entry points (never applied on import).

- One host device per CPU core, so the core's `shard_map` uses every core
  (XLA does not spread these small ops over cores by itself). Skipped when the
  user already chose with XLA_FLAGS=--xla_force_host_platform_device_count=N.
- JAX's persistent compilation cache, so a second run skips the ~20 s compile.
  One sub-folder per CPU feature set (`cpu_cache_dir`): an XLA:CPU executable is
  machine code for the CPU that compiled it, and JAX's cache key does not include
  the CPU's features. A home folder shared between machines (or a virtual machine
  moved to another CPU) would otherwise load code using instructions this CPU
  lacks, which XLA reports on every load as "Target machine feature ... is not
  supported on the host machine ... This could lead to execution errors such as
  SIGILL" (and which would crash if such an instruction ran). XLA prints the same
  alarm on the very CPU that compiled, for two tuning preferences it takes for
  features: `hopper_mjx.shell.process` drops exactly those lines from a command's stderr.
- The cache is an optimisation, never a failure: a folder that cannot be created or
  written is one warning line and the run compiles without it; entries JAX cannot read
  (damaged, cut short) or write (a full disk) are compiled afresh, and JAX's own warning
  for them (two lines each, one per program) becomes one line per process. Entries are written whole
  (beside their place, then renamed into it), so that no reader, in this run or a later one, meets one cut short.
- The shell's JAX settings that the commands cannot run with: a JAX_PLATFORMS without `cpu`, or an XLA_FLAGS device
  count below 1, is refused in one line (`_refuse_environment`); JAX_ENABLE_X64 and JAX_DISABLE_JIT, set for other
  work or to debug, are overridden with a note (the step's conditionals are typed float32, and run eagerly a step
  takes minutes).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import platform
import re
import sys
import tempfile
import threading
import warnings
from pathlib import Path

# An empty HOPPER_MJX_CACHE counts as unset: as Path("") it was the working folder, and a run there left its
# compiled programs (a cpu-<hash>/ folder) in whatever checkout it ran in.
CACHE_DIR = Path(os.environ.get("HOPPER_MJX_CACHE") or Path.home() / ".cache" / "hopper_mjx" / "jax")


def cpu_features() -> str:
    """The host CPU's identity for the cache: its model and instruction-set flags (Linux), else
    what `platform` knows."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        lines = []
    wanted = ("model name", "flags", "Features")  # Features: the flags' name on ARM
    found = sorted({line.split(":", 1)[1].strip() for line in lines if line.split(":", 1)[0].strip() in wanted})
    return " | ".join([platform.machine(), platform.processor(), *found])


def cpu_cache_dir(base: Path | str) -> Path:
    """`base`/cpu-<hash of the CPU features>: compiled code is only ever reused on the same kind of CPU."""
    return Path(base) / f"cpu-{hashlib.sha256(cpu_features().encode()).hexdigest()[:12]}"


# JAX's warning when a cache entry cannot be read or written (jax/_src/compiler.py); it then compiles afresh.
CACHE_WARNING = re.compile(r"Error (reading|writing) persistent compilation cache entry")


def cache_problem(folder: Path) -> str | None:
    """Why `folder` cannot hold the compile cache (it is created if need be), or None when it can."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        return err.strerror or type(err).__name__
    return None


def _cache_warnings_in_one_line() -> None:
    """JAX's cache warnings (a line and its source line each, again for every program) as one line per process."""
    show, said = warnings.showwarning, []

    def showwarning(message, category, filename, lineno, file=None, line=None):
        if not CACHE_WARNING.search(str(message)):
            return show(message, category, filename, lineno, file, line)
        if not said:
            said.append(True)
            first = str(message).splitlines()[0] if str(message) else category.__name__
            print(f"warning: compile cache: {first[:300]}; compiling instead (the cache only saves time)",
                  file=sys.stderr)

    warnings.showwarning = showwarning


def _whole_cache_entries() -> None:
    """JAX writes a cache entry in place (jax/_src/lru_cache.py `put`). Another process reading it meanwhile read it
    cut short (a warning, then a compile: seen with runs side by side on one cache), and one cut short by a full
    disk or a kill stayed there for every later run to trip on (`put` skips a key that exists). Each entry is now
    written beside its place and renamed into it: a reader finds it whole or not at all, and a failed write leaves
    no entry."""
    from jax._src import lru_cache

    put = lru_cache.LRUCache.put
    if getattr(put, "writes_whole", False):
        return

    def put_whole(self, key, value):
        if self.eviction_enabled or not key:  # JAX's own: under its lock, with a size limit (none is set here)
            return put(self, key, value)
        entry = self.path / f"{key}{lru_cache._CACHE_SUFFIX}"
        if entry.exists():
            return None
        part = self.path / f".{key}.{os.getpid()}.{threading.get_ident()}.part"
        try:
            part.write_bytes(value)
            os.replace(part, entry)
        finally:
            with contextlib.suppress(OSError):
                part.unlink()  # only where the write or the rename failed
        return None

    put_whole.writes_whole = True
    lru_cache.LRUCache.put = put_whole


_configured: list = []  # set by the first `configure`: JAX takes the device count only before its first computation


def configure(*, devices: int | None = None, cache_dir: Path | str | None = CACHE_DIR, quiet: bool = True) -> None:
    """Call before the first JAX computation of the process; later calls do nothing (a command's checks may
    need JAX, e.g. to read a trained policy, before its run does). `quiet`: this process's stderr without XLA's
    false alarms, as a command's (`process.filter_stderr`; a script or notebook calling this gets the same)."""
    if _configured:
        return
    _configured.append(True)
    _refuse_environment()
    if quiet:
        from hopper_mjx.shell import process

        process.filter_stderr()
    # XLA's C++ log without its INFO lines; warnings and errors still print (a command's stderr
    # filter drops the known false alarms among them); TF_CPP_MIN_LOG_LEVEL=0 shows everything.
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "1")
    import jax  # here, not at module level: commands check their arguments before importing JAX

    if "xla_force_host_platform_device_count" not in os.environ.get("XLA_FLAGS", ""):
        jax.config.update("jax_num_cpu_devices", devices or os.cpu_count() or 1)
    problem = None if cache_dir is None else cache_problem(cpu_cache_dir(cache_dir))
    if problem is not None:
        print(f"warning: compile cache {cache_dir}: cannot use it ({problem}); compiling without it (set "
              "HOPPER_MJX_CACHE to a writable folder)", file=sys.stderr)
    elif cache_dir is not None:
        jax.config.update("jax_compilation_cache_dir", str(cpu_cache_dir(cache_dir)))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        _cache_warnings_in_one_line()
        _whole_cache_entries()
    # gloo lets jax.distributed run collectives between CPU processes.
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    _shell_settings(jax)
    _collector_for_tracing()


# JAX settings a shell may hold that the commands override, and why: the core and its controllers are float32 (with
# float64 on, a `lax.cond`'s two branches disagree on their types and the first trace fails), and compiled (eagerly,
# one 1 ms step of a batch takes minutes).
OVERRIDDEN = {"jax_enable_x64": ("JAX_ENABLE_X64", "the commands run in float32"),
              "jax_disable_jit": ("JAX_DISABLE_JIT", "the commands run compiled")}


def _refuse_environment() -> None:
    """A JAX_PLATFORMS that leaves out the CPU (cuda, tpu, ...), or an XLA_FLAGS device count that is not a whole
    number >= 1, is one line and exit code 2, before JAX starts. JAX failed on the first with an AssertionError's
    traceback, or a backend's, at the first array; XLA on a count of 0 with a traceback, on `abc` with the help of
    its every flag."""
    from hopper_mjx.shell import checks

    platforms = [p.strip() for p in os.environ.get("JAX_PLATFORMS", "").split(",") if p.strip()]
    if platforms and "cpu" not in platforms:
        raise SystemExit(checks.fail(f"JAX_PLATFORMS={os.environ['JAX_PLATFORMS']}: hopper_mjx runs on the CPU (one "
                                     "JAX device a core); unset JAX_PLATFORMS or set it to cpu"))
    for count in re.findall(r"--xla_force_host_platform_device_count=(\S*)", os.environ.get("XLA_FLAGS", "")):
        if not (count.isdigit() and int(count) >= 1):
            raise SystemExit(checks.fail(f"XLA_FLAGS --xla_force_host_platform_device_count={count}: the JAX devices "
                                         "to run on must be a whole number >= 1 (without it, one a core)"))


def _shell_settings(jax) -> None:
    """Turns off the settings in OVERRIDDEN that the environment turned on, with a note for each."""
    for flag, (variable, why) in OVERRIDDEN.items():
        if getattr(jax.config, flag):
            jax.config.update(flag, False)
            print(f"note: {variable}={os.environ.get(variable, '')} is ignored: {why}", file=sys.stderr)


def _collector_for_tracing() -> None:
    """Python's cycle collector tuned for tracing. A trace makes hundreds of thousands of objects that live on
    (jaxprs, their equations, avals, cached traces), and each full collection walks every live object again
    (a sixth of two core test files' time with a warm cache, docs/performance.md). The libraries imported so far
    are frozen out of the walks (they are never garbage), and the young generation is collected every 10,000 new
    objects, not every 700."""
    import gc

    gc.freeze()
    gc.set_threshold(10_000, 10, 10)
