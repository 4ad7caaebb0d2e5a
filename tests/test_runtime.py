"""Process settings: the compile cache is keyed by the CPU it compiled for."""

import jax

from hopper_mjx import runtime


def test_compile_cache_is_one_folder_per_cpu_kind(monkeypatch, tmp_path):
    here = runtime.cpu_cache_dir(tmp_path)
    assert here.parent == tmp_path and here.name.startswith("cpu-")
    assert runtime.cpu_cache_dir(tmp_path) == here  # stable for one machine
    # conftest configured this process: its cache is this CPU's folder of the default base.
    assert jax.config.jax_compilation_cache_dir == str(runtime.cpu_cache_dir(runtime.CACHE_DIR))
    real = runtime.cpu_features()
    assert "avx" in real or "asimd" in real or real.split(" | ")[0] not in ("x86_64", "aarch64")
    monkeypatch.setattr(runtime, "cpu_features", lambda: real.replace("avx2", "").replace("asimd", "") + " other")
    assert runtime.cpu_cache_dir(tmp_path) != here  # another instruction set, another folder
