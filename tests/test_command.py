"""What a command's process sets up (hopper_mjx.shell.process): stderr without XLA's false alarms, and only those.

A healthy run from a warm compile cache prints no error- or warning-level line: XLA:CPU checks the
tuning preferences it compiled with (+prefer-no-gather, +prefer-no-scatter) as if they were CPU
features, at every load from the cache, and logs an error warning of "SIGILL" for each.
"""

import os
import re
import select
import subprocess
import sys
import threading

import numpy as np
import pytest
from test_bad_inputs import ENV

from hopper_mjx.shell import errfilter, process

ALARM = re.compile(r"^[EWF]\d{4} |SIGILL", re.M)  # an XLA C++ log line of level warning and up, or the alarm
FALSE = ("E1124 20:17:20.346371   10668 cpu_aot_loader.cc:220] Loading XLA:CPU AOT result. Target machine feature "
         "+prefer-no-gather is not  supported on the host machine. ... This could lead to execution errors such as "
         "SIGILL.")
REAL = FALSE.replace("+prefer-no-gather", "+avx512f")  # compiled for an ISA this CPU lacks: a real alarm


def forwarded(text: bytes) -> bytes:
    """What `errfilter.forward` passes on of `text`, written in two pieces (a line split between reads)."""
    read, write = os.pipe()
    out_read, out_write = os.pipe()
    thread = threading.Thread(target=errfilter.forward, args=(read, out_write))
    thread.start()
    os.write(write, text[:50])
    os.write(write, text[50:])
    os.close(write)
    thread.join()
    os.close(out_write)
    with os.fdopen(out_read, "rb") as f:
        return f.read()


def test_the_filter_drops_the_false_alarms_and_nothing_else():
    note = "W1124 20:17:20.152611   10660 pjrt_executable.cc:642] Assume version compatibility. PjRt-IFRT does not"
    lines = ["wrote o.npz", FALSE, FALSE.replace("gather", "scatter"), note, REAL, "error: a real one", "no newline"]
    assert forwarded("\n".join(lines).encode()) == "\n".join([lines[0], REAL, lines[5], lines[6]]).encode()


def test_the_last_lines_of_a_command_xla_ends_still_reach_stderr(tmp_path):
    """XLA ends the process from C++ on a flag it does not know, with a fatal log line that names it. The filter ran
    as a thread of the command and went with it: the command exited 1 with stderr empty. It now runs as a process
    of its own, which reads on until the command is gone."""
    run = simulate(tmp_path, XLA_FLAGS="--xla_no_such_flag=true")
    assert run.returncode != 0
    assert "Unknown flag in XLA_FLAGS: --xla_no_such_flag=true" in run.stderr, run.stderr[-3000:]


@pytest.mark.parametrize("variable, value, message", [
    # On this CPU-only install JAX failed at the first array with an AssertionError's traceback.
    ("JAX_PLATFORMS", "cuda", "JAX_PLATFORMS=cuda: hopper_mjx runs on the CPU (one JAX device a core); unset "
                              "JAX_PLATFORMS or set it to cpu"),
    # XLA failed on 0 with a traceback, and answered `abc` with the help of its every flag.
    ("XLA_FLAGS", "--xla_force_host_platform_device_count=0",
     "XLA_FLAGS --xla_force_host_platform_device_count=0: the JAX devices to run on must be a whole number >= 1 "
     "(without it, one a core)")])
def test_jax_settings_the_commands_cannot_run_with_are_refused_in_one_line(tmp_path, variable, value, message):
    out = tmp_path / "run.npz"
    run = simulate(tmp_path / "cache", out=out, **{variable: value})
    assert run.returncode == 2 and not out.exists()
    assert run.stderr == f"error: {message}\n", run.stderr[-3000:]


@pytest.mark.parametrize("command, env, message", [
    # `import mujoco` raised a RuntimeError's traceback in every command
    (["hopper_mjx.simulate", "--num", "1"], {"MUJOCO_GL": "bogus"},
     "MUJOCO_GL=bogus: MuJoCo's OpenGL backend here is one of egl, osmesa, glfw, glx; unset it to use egl"),
    # MuJoCo's FatalError ("an OpenGL platform library has not been loaded"), a traceback
    (["hopper_mjx.render", "--still", "s.png"], {"MUJOCO_GL": "glfw", "DISPLAY": "", "WAYLAND_DISPLAY": ""},
     "MUJOCO_GL=glfw needs a display, and DISPLAY is unset: unset MUJOCO_GL to render headless with EGL"),
    # mujoco without its Renderer: "module 'mujoco' has no attribute 'Renderer'"
    (["hopper_mjx.render", "--still", "s.png"], {"PYOPENGL_PLATFORM": "bogus"},
     "PYOPENGL_PLATFORM=bogus disagrees with MUJOCO_GL=egl: unset PYOPENGL_PLATFORM, or set it to egl")])
def test_opengl_settings_the_commands_cannot_draw_with_are_refused_in_one_line(tmp_path, command, env, message):
    if sys.platform != "linux":
        pytest.skip("the backends named are Linux's")
    run = subprocess.run([sys.executable, "-m", *command], env={**ENV, "MUJOCO_GL": "egl", **env}, cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 2 and run.stderr == f"error: {message}\n", run.stderr[-3000:]
    assert list(tmp_path.iterdir()) == []


def test_a_headless_backend_without_its_library_is_refused_in_one_line(tmp_path, monkeypatch):
    """MUJOCO_GL=osmesa without libOSMesa made `import mujoco` itself fail in every command ("'NoneType' object has
    no attribute 'glGetError'", a traceback); render on EGL without libEGL would have no Renderer. Both are one
    line naming the library and the package that has it. The libraries are hidden from the check here; where this
    machine lacks OSMesa (Debian's Mesa packages do not pull it in), a command is refused end to end too."""
    import ctypes.util

    from hopper_mjx import render
    from hopper_mjx.shell import startup

    installed = ctypes.util.find_library("OSMesa") is not None
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    assert startup.missing_gl_library("osmesa") == (
        "MUJOCO_GL=osmesa needs the OSMesa library (libOSMesa.so), which is not installed: install it (Debian, Ubuntu: "
        "sudo apt-get install libosmesa6), or unset MUJOCO_GL to render with EGL")
    assert startup.missing_gl_library("glfw") is None
    monkeypatch.setenv("MUJOCO_GL", "egl")
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    with pytest.raises(ValueError, match=r"^MUJOCO_GL=egl needs the EGL library \(libEGL.so\), which is not "
                                         r"installed: install it \(Debian, Ubuntu: sudo apt-get install libegl1\)$"):
        render.check_gl()
    monkeypatch.undo()
    render.check_gl()  # this machine renders with EGL (the suite's render tests)
    if sys.platform != "linux" or installed:
        return
    out = tmp_path / "run.npz"
    run = simulate(tmp_path / "cache", out=out, MUJOCO_GL="osmesa")
    assert run.returncode == 2 and not out.exists()
    assert run.stderr == f"error: {startup.missing_gl_library('osmesa')}\n", run.stderr[-3000:]


def test_float64_or_no_jit_from_the_shell_is_overridden_with_a_note_and_the_same_results(tiny, tmp_path):
    """JAX_ENABLE_X64=1 failed the step's first trace (a conditional's branches typed float32 and float64), and
    JAX_DISABLE_JIT=1 ran it eagerly for minutes; with both set the tiny run now gives the same bytes, saying so."""
    cache, plain_run, plain_out = tiny
    both = simulate(cache, out=tmp_path / "both.npz", JAX_ENABLE_X64="1", JAX_DISABLE_JIT="true")
    assert both.returncode == 0, both.stderr[-3000:]
    assert "note: JAX_ENABLE_X64=1 is ignored: the commands run in float32\n" in both.stderr
    assert "note: JAX_DISABLE_JIT=true is ignored: the commands run compiled\n" in both.stderr
    assert "note:" not in plain_run.stderr
    plain, other = np.load(plain_out), np.load(tmp_path / "both.npz")
    assert plain.files == other.files
    assert all(np.array_equal(plain[k], other[k]) and plain[k].dtype == other[k].dtype for k in plain.files)


def test_a_line_cut_short_passes_at_once_unless_it_may_start_a_log_line():
    """An interactive Python writes its prompt to stderr with no newline: it must not wait for the next line. The
    start of an XLA log line is held until its end, so that a false alarm written in two pieces is still dropped."""
    read, write = os.pipe()
    out_read, out_write = os.pipe()
    thread = threading.Thread(target=errfilter.forward, args=(read, out_write), daemon=True)
    thread.start()
    os.write(write, b">>> ")
    assert select.select([out_read], [], [], 10)[0] and os.read(out_read, 100) == b">>> "
    os.write(write, FALSE[:40].encode())
    assert not select.select([out_read], [], [], 0.5)[0]  # held: it may be, and is, a false alarm
    os.write(write, FALSE[40:].encode() + b"\n>>> ")
    assert select.select([out_read], [], [], 10)[0] and os.read(out_read, 100) == b">>> "
    os.close(write)
    thread.join()
    os.close(out_write)
    assert os.read(out_read, 100) == b""


LIBRARY = """import sys
import jax.numpy as jnp
from hopper_mjx import configure
configure(cache_dir=sys.argv[1], quiet=sys.argv[2] == "quiet")
print(float(jax.jit(lambda x: jnp.sin(x) * 2)(1.0)))
""".replace("import jax.numpy", "import jax\nimport jax.numpy")


def test_a_script_that_configures_the_package_gets_its_stderr_filtered_too(tmp_path):
    """README's Python example calls `configure()`: each program it loaded from the cache printed XLA's false alarms,
    3 kB a program, as the commands did before their filter. The first run compiles; the second loads."""
    runs = [subprocess.run([sys.executable, "-c", LIBRARY, str(tmp_path), mode], env=ENV, capture_output=True,
                           text=True, timeout=300) for mode in ("quiet", "quiet", "loud")]
    assert all(r.returncode == 0 and abs(float(r.stdout) - 1.6829419) < 1e-6 for r in runs), runs[-1].stderr[-3000:]
    assert not ALARM.search(runs[1].stderr), runs[1].stderr[-3000:]
    assert "Assume version compatibility" in runs[2].stderr  # unfiltered, the same load does print


def simulate(cache, out=os.devnull, **env):
    """A tiny limp run (the smallest program to compile: no controller) on the compile cache `cache`."""
    command = [sys.executable, "-m", "hopper_mjx.simulate", "--num", "1", "--duration", "0.05", "--controller", "none",
               "--out", str(out)]
    return subprocess.run(command, env={**ENV, "HOPPER_MJX_CACHE": str(cache), **env}, capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The tiny run once on a fresh cache (it compiles and fills it): the cache, the run, and its output."""
    folder = tmp_path_factory.mktemp("tiny")
    run = simulate(folder / "cache", out=folder / "plain.npz")
    assert run.returncode == 0, run.stderr[-3000:]
    return folder / "cache", run, folder / "plain.npz"


def test_a_run_from_a_warm_cache_prints_no_alarm(tiny):
    """The same tiny run on the cache it filled: it loads from it without an alarm; with the filter off
    (TF_CPP_MIN_LOG_LEVEL=0) the load does print XLA's warnings, so that run was a load, and the filter is what keeps
    its stderr clean. Which warnings depends on the host: every load logs "Assume version compatibility"; the SIGILL
    alarm for +prefer-no-gather comes only where LLVM tunes for that CPU (27 Nov's machine did, 28 Nov's AMD family
    25 model 1 did not)."""
    cache, cold, _ = tiny
    assert not ALARM.search(cold.stderr), cold.stderr[-3000:]
    assert any(p.is_file() for p in cache.rglob("*"))  # the compiled program is in the cache
    warm = simulate(cache)
    assert warm.returncode == 0 and not ALARM.search(warm.stderr), warm.stderr[-3000:]
    unfiltered = simulate(cache, TF_CPP_MIN_LOG_LEVEL="0")
    assert unfiltered.returncode == 0 and ALARM.search(unfiltered.stderr), unfiltered.stderr[-3000:]


def test_only_the_packages_commands_arm_the_signals(monkeypatch):
    """Importing the package from Python (here: pytest) changes no signal handler."""
    monkeypatch.setattr(sys, "orig_argv", [sys.executable, "-m", "hopper_mjx.sweep", "gravity"])
    assert process.is_command()
    monkeypatch.setattr(sys, "orig_argv", [sys.executable, "-m", "pytest", "-q"])
    monkeypatch.setattr(sys, "argv", ["pytest", "-q"])
    assert not process.is_command()
    monkeypatch.setattr(sys, "orig_argv", [sys.executable, str(process.PACKAGE_ROOT / "experiments" / "train.py")])
    monkeypatch.setattr(sys, "argv", [str(process.PACKAGE_ROOT / "experiments" / "train.py")])
    assert process.is_command()
    assert not process._armed.is_set()  # this test process was never armed


def test_every_command_runs_its_main_through_the_process_shell():
    """Each command of the package and each script of experiments/ runs `main` through `process.run`, which
    keeps XLA's false alarms off stderr: results.py and robustness.py, which sweep in-process and so load
    programs from the cache, had called `main` bare and printed two alarms of 3 kB for each load."""
    root = process.PACKAGE_ROOT
    sources = [p for p in [*(root / "hopper_mjx").rglob("*.py"), *(root / "experiments").glob("*.py")]
               if 'if __name__ == "__main__":' in p.read_text()]
    bare = [str(p.relative_to(root)) for p in sources
            if not re.search(r'if __name__ == "__main__":\n    sys\.exit\(process\.run\(main\)\)\n', p.read_text())]
    assert len(sources) >= 15 and bare == [], bare


def test_an_empty_cache_variable_is_the_default_cache_not_the_working_folder(tmp_path):
    """HOPPER_MJX_CACHE= (set, empty) made the cache Path(""), the working folder: a run there wrote its compiled
    programs into the checkout it ran in."""
    from pathlib import Path

    probe = "from hopper_mjx.shell import jaxsetup; print(jaxsetup.CACHE_DIR)"
    run = subprocess.run([sys.executable, "-c", probe], env={**ENV, "HOPPER_MJX_CACHE": ""}, cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == str(Path.home() / ".cache" / "hopper_mjx" / "jax")


# A command whose main fails while a signal's stop removes its partial outputs (slowly here, as a big folder's
# removal is): the folder it writes into went under it.
FAILING_UNDER_A_STOP = """
import os, signal, sys, time
from hopper_mjx.shell import files, process

remove = files.remove_partial
files.remove_partial = lambda: (time.sleep(1.0), remove())


def main():
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.2)  # the stop has begun
    raise FileNotFoundError("the run's folder was removed under it")


sys.exit(process.run(main))
"""


def test_a_main_failing_while_a_stop_runs_waits_for_its_one_line_and_code():
    """The main thread, meeting the error a stop's removal causes, left `run` with its own exit code before the stop
    printed its line: the user saw no "interrupted" line, and code 1."""
    run = subprocess.run([sys.executable, "-c", FAILING_UNDER_A_STOP], env=ENV, capture_output=True, text=True,
                         timeout=60)
    assert (run.returncode, run.stderr) == (130, "interrupted (SIGINT): stopped before its results were written\n")
