"""The stderr filter a command's process runs beside it (`hopper_mjx.shell.process.filter_stderr`): copies its
standard input to its standard output, line by line, but for XLA's false alarms.

It runs as a process of its own, without the package (`python -I -S -c`, importing this file alone: the standard
library only), not as a thread of the command: a command ended from XLA's C++ (a fatal log line such as
`Unknown flag in XLA_FLAGS`, an abort) takes its threads with it, and with them the last lines it wrote, which are
the ones that say why. This process reads on until every writer is gone, so those lines still arrive.
"""

import os
import re
import signal

# An XLA log line that is not an alarm: a tuning preference taken for a missing CPU feature, and PjRt's note.
FALSE_ALARMS = re.compile(r"cpu_aot_loader\.cc.*Target machine feature \+(prefer|tuning|fast|slow|false-deps)-"
                          r"|pjrt_executable\.cc.*Assume version compatibility")


# The start of a C++ log line of level warning or error (`E1205 22:58:02.337611 ...`), the only lines that can be
# false alarms: a line cut between reads is held back only if it may be one.
LOG_START = re.compile(rb"[EW]\d{0,4}(?: |$)")


def forward(read: int, real: int) -> None:
    """Copies lines from descriptor `read` to `real`, but the false alarms, until `read` ends; closes `read`. The
    rest of a line cut between reads passes at once, unless it may start a log line: an interactive Python's
    prompt (`>>> `, on stderr, with no newline) must not wait for the next line."""
    pending = b""
    while True:
        chunk = os.read(read, 65536)
        if not chunk:
            break
        lines = (pending + chunk).split(b"\n")
        pending = lines.pop()
        kept = [line + b"\n" for line in lines if not FALSE_ALARMS.search(line.decode(errors="replace"))]
        if pending and not LOG_START.match(pending):
            kept.append(pending)
            pending = b""
        if kept:
            os.write(real, b"".join(kept))
    if pending:
        os.write(real, pending)
    os.close(read)


def main() -> None:
    """The filter's process: standard input to standard output."""
    # Ctrl-C reaches the whole foreground group; the command says the one line, and this process passes on
    # what is left when the command has gone.
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_IGN)
    forward(0, 1)


def command(python: str) -> list[str]:
    """The filter's command line: `python` importing this file alone (not the package, which imports much more)."""
    folder = os.path.dirname(os.path.abspath(__file__))
    return [python, "-I", "-S", "-c", f"import sys; sys.path.insert(0, {folder!r}); import errfilter; errfilter.main()"]
