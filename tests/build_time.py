"""A pytest plugin (tests/conftest.py loads it): how much of each test's time JAX spent building programs, so that
`make test`'s report tells the tests that are slow because they compile from those slow because they run, train
or wait on other processes.

Building is JAX tracing a function, lowering it and compiling it (or reading the compiled code back from the
persistent cache): the wall time covered by JAX's own compile events, overlaps counted once (a jit traced inside
another's trace). Only this process's: a test's subprocesses count as its other time.

A third table names the programs: each function JAX built, by the name JAX gives it, with how many times it was
traced and compiled (or read back) across the suite and the seconds of each stage, so that a program built again and
again by different tests shows as one row.
"""

import re
from collections import defaultdict

import jax.monitoring
import pytest

# The events JAX's dispatch records around each stage of making a program (jax/_src/dispatch.py), by stage.
STAGES = {"/jax/core/compile/jaxpr_trace_duration": "trace", "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
          "/jax/core/compile/backend_compile_duration": "compile"}
PROPERTY, PROGRAMS = "jax_build_s", "jax_programs"
SHOWN = 12  # rows of each table

_spans: list[tuple[float, float]] = []  # (start, end) wall times of this phase's building
_phases: list[tuple[str, float, float]] = []  # (test and phase, seconds, building seconds), every worker's
_built: list[tuple[str, str, float]] = []  # (program, stage, seconds) of this phase's building
_programs: defaultdict = defaultdict(lambda: defaultdict(lambda: [0, 0.0]))  # program -> stage -> [times, s], all


def program(name: str) -> str:
    """A function's name as JAX's stages give it (its trace `f`, its compile `jit(f)`, a module `jit_f`): `f`."""
    found = re.fullmatch(r"(?:jit|pmap)(?:\((.*)\)|_(.*))", name or "?")
    return next(n for n in found.groups() if n is not None) if found else (name or "?")


def _record(event, start_time, end_time, fun_name="", **_):
    if event in STAGES:
        _spans.append((start_time, end_time))
        _built.append((program(fun_name), STAGES[event], end_time - start_time))


jax.monitoring.register_event_time_span_listener(_record)


def covered(spans) -> float:
    """The length of the union of the (start, end) intervals."""
    total, reach = 0.0, float("-inf")
    for start, end in sorted(spans):
        if end > reach:
            total += end - max(start, reach)
            reach = end
    return total


@pytest.hookimpl(tryfirst=True)  # before pytest makes the report from the item
def pytest_runtest_makereport(item, call):
    # Each phase (setup, call, teardown) carries its own building: a worker's reports reach the main process.
    item.user_properties[:] = [p for p in item.user_properties if p[0] not in (PROPERTY, PROGRAMS)]
    item.user_properties.append((PROPERTY, covered(_spans)))
    item.user_properties.append((PROGRAMS, list(_built)))
    _spans.clear()
    _built.clear()


def pytest_runtest_logreport(report):
    properties = dict(report.user_properties)
    built = properties.get(PROPERTY)
    if built is not None:
        _phases.append((f"{report.nodeid} ({report.when})", report.duration, built))
    for name, stage, seconds in properties.get(PROGRAMS, ()):
        _programs[name][stage][0] += 1
        _programs[name][stage][1] += seconds


def pytest_terminal_summary(terminalreporter):
    if not _phases:
        return
    write = terminalreporter.write_line
    total, built = sum(p[1] for p in _phases), sum(p[2] for p in _phases)
    terminalreporter.section("JAX program building: tracing, lowering, compiling or reading compiled code back")
    write(f"{built:.0f} s of the tests' {total:.0f} s built programs (the test processes' sums; a test's own "
          "subprocesses count as its other time)")
    tables = (("building the most", lambda p: p[2]), ("the most time besides building", lambda p: p[1] - p[2]))
    for title, key in tables:
        write(f"{title}:   building s   total s")
        for name, seconds, building in sorted(_phases, key=key, reverse=True)[:SHOWN]:
            write(f"  {building:8.1f} {seconds:9.1f}   {name}")
    write("the programs built the most (a nested jit's seconds are its caller's too):   traced  compiled   "
          "trace s  lower s  compile s")
    for name, stages in sorted(_programs.items(), key=lambda p: -sum(s for _, s in p[1].values()))[:SHOWN]:
        write(f"  {stages['trace'][0]:6d} {stages['compile'][0]:9d} {stages['trace'][1]:9.1f} "
              f"{stages['lower'][1]:8.1f} {stages['compile'][1]:10.1f}   {name}")
