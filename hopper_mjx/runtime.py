"""Process-wide JAX settings for the command-line entry points (never applied on import).

- One host device per CPU core, so the core's `shard_map` uses every core
  (XLA does not spread these small ops over cores by itself). Skipped when the
  user already chose with XLA_FLAGS=--xla_force_host_platform_device_count=N.
- JAX's persistent compilation cache, so a second run skips the ~20 s compile.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

CACHE_DIR = Path(os.environ.get("HOPPER_MJX_CACHE", Path.home() / ".cache" / "hopper_mjx" / "jax"))


def configure(*, devices: int | None = None, cache_dir: Path | str | None = CACHE_DIR) -> None:
    """Call before the first JAX computation of the process."""
    if "xla_force_host_platform_device_count" not in os.environ.get("XLA_FLAGS", ""):
        jax.config.update("jax_num_cpu_devices", devices or os.cpu_count() or 1)
    if cache_dir is not None:
        jax.config.update("jax_compilation_cache_dir", str(cache_dir))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    # gloo lets jax.distributed run collectives between CPU processes.
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
