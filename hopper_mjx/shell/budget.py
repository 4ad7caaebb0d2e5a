"""What a run would need, said before it starts: memory against what this machine has, and steps
against what one compiled loop counts. A run that cannot fit is refused in one line naming the
flags to change, instead of ending in a MemoryError, an overflow or a swapping machine."""

from __future__ import annotations

import os

MAX_LOOP_STEPS = 2**31 - 1  # a compiled scan counts its steps in int32
# Bytes one instance holds while it runs, besides what it records: its state and its share of a chunk's
# stage outputs. bench measured 0.9 GB (chain) to 1.3 GB (MJX) peak RSS at N = 16384 with native MuJoCo's
# MjData beside each instance and ~0.6 GB of JAX and compiled code: under 45 KB an instance for both sides.
INSTANCE_BYTES = 32 << 10
FLOAT_BYTES = 4  # the core computes in float32
COPIES = 3  # a recorded value lives on the device, in the host's copy and in the written file's buffer
USABLE = 0.8  # of the memory available: the rest is the OS's and the compiler's


def available_bytes() -> int:
    """Memory this machine can give now (Linux's MemAvailable), else its physical memory."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def size(n: float) -> str:
    for unit, scale in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n / 1024:.0f} KiB"


def check_steps(flags: str, duration: float, timestep: float) -> int:
    """The physics steps of `duration` s; refused beyond what one compiled loop counts."""
    steps = duration / timestep
    if steps > MAX_LOOP_STEPS:
        raise ValueError(f"{flags}: {duration:g} s at a {timestep:g} s step is {steps:.3g} physics steps; "
                         f"one run takes at most {MAX_LOOP_STEPS:,} ({MAX_LOOP_STEPS * timestep:.3g} s)")
    return int(steps)


def whole_steps(duration: float, timestep: float, whole: int) -> int:
    """The physics steps of a run of `duration` s: the closest number that holds whole samples of every stream
    (`whole` steps hold one of each), and at least one."""
    return max(1, int(round(duration / timestep / whole))) * whole


def run_time(duration: float, timestep: float, whole: int) -> float:
    """The s a run of `duration` s takes (`whole_steps`): `duration` itself where it is whole samples to within
    rounding (700 steps of 1 ms are 0.7000000000000001 s), else those steps' time."""
    ran = whole_steps(duration, timestep, whole) * timestep
    return duration if abs(ran - duration) <= 1e-9 * max(duration, 1.0) else round(ran, 9)


def duration_note(duration: float, timestep: float, whole: int) -> str | None:
    """A line saying how long a run of `duration` s really runs (`run_time`), where that is not `duration`."""
    ran = run_time(duration, timestep, whole)
    if ran == duration:
        return None
    return (f"note: --duration {duration:g} s runs {ran:g} s ({whole_steps(duration, timestep, whole):,} steps of "
            f"{timestep * 1e3:g} ms): whole samples of every stream, one each {whole * timestep * 1e3:g} ms")


def check_memory(flags: str, n: int, recorded_floats: float = 0.0, *, states: int = 1, held_floats: float = 0) -> None:
    """`n` instances each recording `recorded_floats` values and holding `held_floats` more (a terrain's
    heights), all held `states` times (e.g. by a benchmark's two sides): refused when they would not fit in
    this machine's memory."""
    run = n * states * (INSTANCE_BYTES + held_floats * FLOAT_BYTES)
    record = n * recorded_floats * FLOAT_BYTES * COPIES
    have = available_bytes()
    if run + record > USABLE * have:
        raise ValueError(f"{flags}: {n:,} instances would need about {size(run + record)} of memory "
                         f"({size(run)} to run, {size(record)} to record); this machine has {size(have)} available")
