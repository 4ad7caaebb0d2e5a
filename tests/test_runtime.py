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


def test_a_cache_entry_whose_write_fails_is_not_left_cut_short(tmp_path):
    """A full disk (here a file-size limit, SIGXFSZ ignored so that the write fails with EFBIG) while JAX writes a
    cache entry: the entry is removed, so that a later run compiles and writes it whole instead of failing to
    read a cut one forever. (conftest's `jaxsetup.configure` installed the removal.)"""
    import resource
    import signal

    import pytest
    from jax._src import lru_cache

    cache = lru_cache.LRUCache(str(tmp_path), max_size=-1)
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    before = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (1000, hard))
    try:
        with pytest.raises(OSError):
            cache.put("big", b"x" * 5000)
        cache.put("small", b"y" * 10)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, before)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small-cache"]
    assert cache.get("small") == b"y" * 10 and cache.get("big") is None
