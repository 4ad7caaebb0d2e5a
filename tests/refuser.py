"""Runs commands as `python -m hopper_mjx.<command> ARGS` (or `python SCRIPT ARGS`) would, each in a fork of this one
process, which has already imported what the commands import before they check their arguments. The suite's two
hundred refusals (test_bad_inputs, test_hostile) then cost a fork each, not a Python start-up each.

A fork runs its command as its own `__main__`, from the case's folder, with stdin empty and stdout and stderr going
to files; it ends as Python ends a process: the exit code of `SystemExit`, 1 and a traceback for an uncaught
exception. No JAX backend is started here, so a fork starts its own as a fresh process would.

argv: TIMEOUT s, forks at once, the modules to import besides the commands' (comma-separated).
stdin: one case per line, JSON `[k, folder, command, args, stdout file, stderr file]`, then end of file.
stdout: a line per finished case, JSON `[k, exit code, CPU s]` (the fork's own, from `os.wait4`); a case running
longer than `TIMEOUT` s of wall time is killed and reported with the signal's exit code.
"""

import importlib
import importlib.util
import json
import os
import runpy
import sys
import time
import traceback

TIMEOUT = float(sys.argv[1])
AT_ONCE = int(sys.argv[2])  # forks running at once
ALSO = sys.argv[3].split(",")  # modules a command may import before it refuses (a policy folder's checks)


def module_name(command: str) -> str:
    return f"hopper_mjx.{command}"


def preload(commands) -> None:
    """Import each command's module (a package's `__main__`) for what it imports, then forget the command modules
    themselves, so that each fork runs its command afresh as `__main__` (as `-m` does, with no runpy warning)."""
    import threading

    for name in ["hopper_mjx", *ALSO]:  # hopper_mjx: what the scripts import first
        importlib.import_module(name)
    for command in commands:
        if command.endswith(".py"):
            continue
        name = module_name(command)
        package = importlib.util.find_spec(name).submodule_search_locations
        importlib.import_module(f"{name}.__main__" if package else name)
    for command in commands:
        if not command.endswith(".py"):
            for name in (module_name(command), f"{module_name(command)}.__main__"):
                sys.modules.pop(name, None)
    # A fork has only the thread that forked it: one whose parent ran others (a JAX backend's) may wait forever.
    assert threading.active_count() == 1, "an import started a thread; forks of this process could hang"


def run(folder: str, command: str, args: list[str], out: str, err: str) -> None:
    """In the fork: the command as its process would run it; never returns."""
    code = 1
    try:
        os.chdir(folder)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        for path, fd in ((out, 1), (err, 2)):
            os.dup2(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644), fd)
        if command.endswith(".py"):  # `python SCRIPT`: the script's folder first on the path
            sys.argv, sys.path[0] = [command, *args], os.path.dirname(command)
            runpy.run_path(command, run_name="__main__")
        else:  # `python -m`: the working folder first on the path
            sys.argv, sys.path[0] = [command, *args], os.getcwd()
            runpy.run_module(module_name(command), run_name="__main__", alter_sys=True)
        code = 0
    except SystemExit as stop:
        if stop.code is None or isinstance(stop.code, int):
            code = stop.code or 0
        else:
            print(stop.code, file=sys.stderr)
    except BaseException:  # noqa: BLE001  (as the interpreter does with an uncaught exception)
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001, S110  (a closed stream: nothing more to write)
                pass
        os._exit(code)


def main() -> None:
    cases = [json.loads(line) for line in sys.stdin if line.strip()]
    preload(sorted({case[2] for case in cases}))
    todo, running = list(cases), {}
    while todo or running:
        while todo and len(running) < AT_ONCE:
            k, folder, command, args, out, err = todo.pop(0)
            pid = os.fork()
            if pid == 0:
                run(folder, command, args, out, err)
            running[pid] = (k, time.monotonic())
        for pid, (k, started) in list(running.items()):
            done, status, usage = os.wait4(pid, os.WNOHANG)
            if done == 0 and time.monotonic() - started < TIMEOUT:
                continue
            if done == 0:  # hung: kill it, and the case fails by its exit code
                os.kill(pid, 9)
                done, status, usage = os.wait4(pid, 0)
            print(json.dumps([k, os.waitstatus_to_exitcode(status), usage.ru_utime + usage.ru_stime]), flush=True)
            del running[pid]
        time.sleep(0.005)


if __name__ == "__main__":
    main()
