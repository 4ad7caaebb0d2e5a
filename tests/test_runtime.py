"""Process settings: the compile cache is keyed by the CPU it compiled for."""

import jax

from hopper_mjx.shell import jaxsetup


def test_compile_cache_is_one_folder_per_cpu_kind(monkeypatch, tmp_path):
    here = jaxsetup.cpu_cache_dir(tmp_path)
    assert here.parent == tmp_path and here.name.startswith("cpu-")
    assert jaxsetup.cpu_cache_dir(tmp_path) == here  # stable for one machine
    # conftest configured this process: its cache is this CPU's folder of the default base.
    assert jax.config.jax_compilation_cache_dir == str(jaxsetup.cpu_cache_dir(jaxsetup.CACHE_DIR))
    real = jaxsetup.cpu_features()
    assert "avx" in real or "asimd" in real or real.split(" | ")[0] not in ("x86_64", "aarch64")
    monkeypatch.setattr(jaxsetup, "cpu_features", lambda: real.replace("avx2", "").replace("asimd", "") + " other")
    assert jaxsetup.cpu_cache_dir(tmp_path) != here  # another instruction set, another folder
