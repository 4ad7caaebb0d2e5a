"""Every command's --help works: each `python -m hopper_mjx.*` tool and each script in experiments/.

A `%` in a help string that argparse reads as a format, or an import that fails, crashes --help;
no other test runs it. The commands are found from the source, so a new one is covered too."""

import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def commands() -> list[list[str]]:
    found = []
    for path in sorted((ROOT / "hopper_mjx").rglob("*.py")):
        if path.name == "__main__.py" or 'if __name__ == "__main__"' in path.read_text():
            parts = path.relative_to(ROOT).with_suffix("").parts
            module = ".".join(parts[:-1] if parts[-1] == "__main__" else parts)
            found.append(["-m", module])
    found += [[str(p)] for p in sorted((ROOT / "experiments").glob("*.py"))]
    return found


def test_every_command_is_found():
    names = {" ".join(c) for c in commands()}
    for expected in ("-m hopper_mjx.simulate", "-m hopper_mjx.sweep", "-m hopper_mjx.model", "-m hopper_mjx.view",
                     "-m hopper_mjx.perf.bench", "-m hopper_mjx.ros.record", str(ROOT / "experiments/train.py")):
        assert expected in names


def test_python_m_hopper_mjx_lists_every_command_and_only_those():
    """`python -m hopper_mjx` lists registry.COMMANDS: a command added without its line there fails here."""
    from hopper_mjx import registry

    found = {c[1] if c[0] == "-m" else str(Path(c[0]).relative_to(ROOT)) for c in commands()} - {"hopper_mjx"}
    assert found == set(registry.COMMANDS)
    listed = subprocess.run([sys.executable, "-m", "hopper_mjx"], capture_output=True, text=True, timeout=120,
                            cwd=ROOT)
    assert listed.returncode == 0 and listed.stderr == "", listed.stderr[-2000:]
    for name, what in registry.COMMANDS.items():
        typed = f"python {name}" if name.endswith(".py") else f"python -m {name}"
        assert re.search(rf"^  {re.escape(typed)} +{re.escape(what)}$", listed.stdout, re.M), (name, listed.stdout)


def run_help(command: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *command, "--help"], capture_output=True, text=True, timeout=120,
                          cwd=ROOT)


@pytest.fixture(scope="module")
def helps():
    with ThreadPoolExecutor(4) as pool:  # start-ups wait on imports from disk as well as on the cores
        return dict(zip(map(" ".join, commands()), pool.map(run_help, commands())))


@pytest.mark.parametrize("command", [" ".join(c) for c in commands()])
def test_help_exits_0_with_a_usage(helps, command):
    done = helps[command]
    assert done.returncode == 0, done.stderr[-2000:]
    # The usage names the command as it is typed, which every refusal's "(see ... --help)" repeats: the scripts
    # in experiments/ are not executable, so "experiments/train.py --help" alone did not run.
    words = command.split()
    typed = f"python -m {words[1]}" if words[0] == "-m" else f"python {Path(words[0]).relative_to(ROOT)}"
    assert done.stdout.startswith(f"usage: {typed} "), done.stdout[:200]
    assert "Traceback" not in done.stderr
