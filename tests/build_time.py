"""A pytest plugin (tests/conftest.py loads it): how much of each test's time JAX spent building programs, so that
`make test`'s report tells the tests that are slow because they compile from those slow because they run, train
or wait on other processes.

Building is JAX tracing a function, lowering it and compiling it (or reading the compiled code back from the
persistent cache): the wall time covered by JAX's own compile events, overlaps counted once (a jit traced inside
another's trace). Only this process's: a test's subprocesses count as its other time.
"""

import jax.monitoring
import pytest

# The events JAX's dispatch records around each stage of making a program (jax/_src/dispatch.py).
BUILD_EVENTS = frozenset({"/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
                          "/jax/core/compile/backend_compile_duration"})
PROPERTY = "jax_build_s"
SHOWN = 12  # rows of each of the two tables

_spans: list[tuple[float, float]] = []  # (start, end) wall times of this phase's building
_phases: list[tuple[str, float, float]] = []  # (test and phase, seconds, building seconds), every worker's


def _record(event, start_time, end_time, **_):
    if event in BUILD_EVENTS:
        _spans.append((start_time, end_time))


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
    item.user_properties[:] = [p for p in item.user_properties if p[0] != PROPERTY]
    item.user_properties.append((PROPERTY, covered(_spans)))
    _spans.clear()


def pytest_runtest_logreport(report):
    built = dict(report.user_properties).get(PROPERTY)
    if built is not None:
        _phases.append((f"{report.nodeid} ({report.when})", report.duration, built))


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
