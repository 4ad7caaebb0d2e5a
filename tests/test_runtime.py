"""Process settings: the compile cache is keyed by the CPU it compiled for, and its entries are written whole."""

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
    read a cut one forever. (conftest's `jaxsetup.configure` installed the whole writes.)"""
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


def test_a_cache_entry_is_found_whole_or_not_at_all_while_it_is_written(monkeypatch, tmp_path):
    """Runs side by side on one cache: while one writes an entry, another looking it up finds nothing (and compiles)
    rather than the part written so far, which it could not read. Once written, the entry is there whole, and
    nothing else is left in the folder."""
    from jax._src import lru_cache

    cache = lru_cache.LRUCache(str(tmp_path), max_size=-1)
    kind = type(cache.path)  # pathlib's, or etils' where it is installed
    write, seen = kind.write_bytes, []

    def half_then_look(path, data):
        write(path, data[: len(data) // 2])
        seen.append(cache.get("program"))  # another process looking it up now
        return write(path, data)

    monkeypatch.setattr(kind, "write_bytes", half_then_look)
    cache.put("program", b"z" * 1000)
    assert seen == [None]
    assert cache.get("program") == b"z" * 1000
    assert [p.name for p in tmp_path.iterdir()] == ["program-cache"]


def test_the_cycle_collector_skips_the_libraries_and_still_frees_garbage_cycles():
    """conftest's `jaxsetup.configure` froze what the process had imported (JAX among it) out of the cycle
    collector's walks and raised its young generation's threshold; a garbage cycle made since is still freed by
    the collector's own run, once that many new objects live."""
    import gc
    import weakref

    assert gc.get_freeze_count() > 10_000  # JAX's and NumPy's modules, functions and types
    threshold = gc.get_threshold()[0]
    assert threshold == 10_000

    class Node:
        pass

    gc.collect(0)  # an empty young generation to start from
    cycle = Node()
    cycle.itself = cycle  # reference counting alone never frees a cycle
    freed = weakref.ref(cycle)
    del cycle
    alive = [[] for _ in range(threshold // 2)]
    assert freed() is not None  # fewer new objects than the threshold: no collection yet (at 700 there was one)
    alive += [[] for _ in range(threshold)]
    assert freed() is None  # the collector ran by itself
