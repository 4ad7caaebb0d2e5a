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


def forward(read: int, real: int) -> None:
    """Copies lines from descriptor `read` to `real`, but the false alarms, until `read` ends; closes `read`."""
    pending = b""
    while True:
        chunk = os.read(read, 65536)
        if not chunk:
            break
        lines = (pending + chunk).split(b"\n")
        pending = lines.pop()
        kept = [line for line in lines if not FALSE_ALARMS.search(line.decode(errors="replace"))]
        if kept:
            os.write(real, b"\n".join(kept) + b"\n")
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
