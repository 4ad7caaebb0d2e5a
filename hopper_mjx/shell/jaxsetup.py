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
"""

from __future__ import annotations

import hashlib
import os
import platform
from pathlib import Path

CACHE_DIR = Path(os.environ.get("HOPPER_MJX_CACHE", Path.home() / ".cache" / "hopper_mjx" / "jax"))


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


_configured: list = []  # set by the first `configure`: JAX takes the device count only before its first computation


def configure(*, devices: int | None = None, cache_dir: Path | str | None = CACHE_DIR) -> None:
    """Call before the first JAX computation of the process; later calls do nothing (a command's checks may
    need JAX, e.g. to read a trained policy, before its run does)."""
    if _configured:
        return
    _configured.append(True)
    # XLA's C++ log without its INFO lines; warnings and errors still print (a command's stderr
    # filter drops the known false alarms among them); TF_CPP_MIN_LOG_LEVEL=0 shows everything.
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "1")
    import jax  # here, not at module level: commands check their arguments before importing JAX

    if "xla_force_host_platform_device_count" not in os.environ.get("XLA_FLAGS", ""):
        jax.config.update("jax_num_cpu_devices", devices or os.cpu_count() or 1)
    if cache_dir is not None:
        jax.config.update("jax_compilation_cache_dir", str(cpu_cache_dir(cache_dir)))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    # gloo lets jax.distributed run collectives between CPU processes.
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
