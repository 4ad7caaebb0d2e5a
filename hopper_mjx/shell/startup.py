"""What must be settled before MuJoCo is first imported in the process (run by `hopper_mjx/__init__.py`).

- **Headless rendering by default.** MuJoCo picks its OpenGL backend once, when it
  is imported, from MUJOCO_GL. Without it MuJoCo tries GLFW, which needs a display,
  and `render` then dies with "OpenGL platform library has not been loaded". So on
  Linux we choose EGL (software Mesa on a CPU-only box) unless the user set
  MUJOCO_GL themselves; other systems keep MuJoCo's own default.
- **Clean stdout.** `mujoco.mjx` prints "Failed to import warp: ..." and "Failed to
  import mujoco_warp: ..." on stdout when the optional NVIDIA Warp backend is not
  installed (it never is here: we run MJX on JAX). Those two lines would corrupt
  output meant for pipes, e.g. `echo BAG TOPIC > file`. An import hook runs that
  one module with its stdout captured, whenever something first imports it: the
  two notices are dropped, any other line goes to stderr.

- **Interrupts from the first import on.** A command (`python -m hopper_mjx...`, a script
  of experiments/) arms `hopper_mjx.shell.process`'s signal handling here, so that Ctrl-C while
  its modules are still being imported is one line too, not a traceback.

Nothing here imports MuJoCo or JAX, so that a command can refuse a bad argument
before paying for those imports.
"""

from __future__ import annotations

import contextlib
import importlib.abc
import importlib.machinery
import io
import os
import platform
import sys

from hopper_mjx.shell import process

WARP_MODULE = "mujoco.mjx.warp"  # prints the notices when it is executed
# Printed by mujoco/mjx/warp/__init__.py when the optional Warp backend is absent.
WARP_ABSENT_PREFIXES = ("Failed to import warp:", "Failed to import mujoco_warp:")


# MUJOCO_GL's values MuJoCo takes (mujoco/rendering/classic/gl_context.py): a backend of this system, or a word
# that turns rendering on or off. Any other makes `import mujoco` raise, in every command.
GL_BACKENDS = {"Linux": ("egl", "osmesa", "glfw", "glx"), "Windows": ("glfw", "wgl"), "Darwin": ("cgl", "glfw")}
# The library PyOpenGL loads for each headless backend, and the Debian package that has it.
GL_LIBRARIES = {"egl": ("EGL", "libegl1"), "osmesa": ("OSMesa", "libosmesa6")}
GL_SWITCHES = ("", "disable", "disabled", "off", "false", "0", "enable", "enabled", "on", "true", "1")


def choose_gl_backend() -> str | None:
    """Sets MUJOCO_GL=egl on Linux unless the user chose; returns the value in effect. A command given a value
    MuJoCo refuses is one line and exit code 2 (MuJoCo's import raised a RuntimeError's traceback)."""
    if platform.system() == "Linux":
        os.environ.setdefault("MUJOCO_GL", "egl")
    value = os.environ.get("MUJOCO_GL")
    if value is None or not process.is_command():
        return value
    chosen, backends = value.lower().strip(), GL_BACKENDS.get(platform.system(), ("glfw",))
    default = "egl" if platform.system() == "Linux" else "MuJoCo's default"
    problem = (f"MUJOCO_GL={value}: MuJoCo's OpenGL backend here is one of {', '.join(backends)}; unset it to use "
               f"{default}" if chosen not in backends + GL_SWITCHES
               else missing_gl_library(chosen) if chosen == "osmesa"  # then `import mujoco` itself fails
               else None)
    if problem:
        from hopper_mjx.shell import checks  # here: it imports NumPy, which a good value never needs yet

        raise SystemExit(checks.fail(problem))
    return value


def missing_gl_library(backend: str) -> str | None:
    """Why MuJoCo's headless `backend` (egl or osmesa) cannot draw here: the library PyOpenGL loads for it is not
    installed (PyOpenGL's import then ended in "'NoneType' object has no attribute 'glGetError'"); None if it is, or
    for another backend."""
    import ctypes.util  # here: it runs ldconfig, and only these backends need it

    if backend not in GL_LIBRARIES or ctypes.util.find_library(GL_LIBRARIES[backend][0]):
        return None
    library, package = GL_LIBRARIES[backend]
    other = "" if backend == "egl" else ", or unset MUJOCO_GL to render with EGL"
    return (f"MUJOCO_GL={backend} needs the {library} library (lib{library}.so), which is not installed: install it "
            f"(Debian, Ubuntu: sudo apt-get install {package}){other}")


def pass_on_unexpected(printed: str) -> None:
    """Lines a quietly imported module printed: the Warp notices are dropped, the rest go to stderr."""
    for line in printed.splitlines():
        if line.strip() and not line.startswith(WARP_ABSENT_PREFIXES):
            print(line, file=sys.stderr)


class QuietWarpImport(importlib.abc.MetaPathFinder):
    """Finds `mujoco.mjx.warp` as Python would, and executes it with stdout captured."""

    def find_spec(self, name, path, target=None):
        if name != WARP_MODULE:
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path, target)
        if spec is None or spec.loader is None:
            return spec
        execute = spec.loader.exec_module  # this module's own loader object

        def exec_quietly(module):
            captured = io.StringIO()
            try:
                with contextlib.redirect_stdout(captured):
                    execute(module)
            finally:
                pass_on_unexpected(captured.getvalue())

        spec.loader.exec_module = exec_quietly
        return spec


def prepare() -> None:
    process.arm_if_command()
    choose_gl_backend()
    if WARP_MODULE not in sys.modules and not any(isinstance(f, QuietWarpImport) for f in sys.meta_path):
        sys.meta_path.insert(0, QuietWarpImport())
