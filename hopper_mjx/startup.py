"""What must happen before MuJoCo is first imported in the process (run by `hopper_mjx/__init__.py`).

- **Headless rendering by default.** MuJoCo picks its OpenGL backend once, when it
  is imported, from MUJOCO_GL. Without it MuJoCo tries GLFW, which needs a display,
  and `render` then dies with "OpenGL platform library has not been loaded". So on
  Linux we choose EGL (software Mesa on a CPU-only box) unless the user set
  MUJOCO_GL themselves; other systems keep MuJoCo's own default.
- **Clean stdout.** `mujoco.mjx` prints "Failed to import warp: ..." and "Failed to
  import mujoco_warp: ..." on stdout when the optional NVIDIA Warp backend is not
  installed (it never is here: we run MJX on JAX). Those two lines would corrupt
  output meant for pipes, e.g. `echo BAG TOPIC > file`. They are dropped; any
  other line that import prints goes to stderr.
"""

from __future__ import annotations

import contextlib
import io
import os
import platform
import sys

# Printed by mujoco/mjx/warp/__init__.py when the optional Warp backend is absent.
WARP_ABSENT_PREFIXES = ("Failed to import warp:", "Failed to import mujoco_warp:")


def choose_gl_backend() -> str | None:
    """Sets MUJOCO_GL=egl on Linux unless the user chose; returns the value in effect."""
    if platform.system() == "Linux":
        os.environ.setdefault("MUJOCO_GL", "egl")
    return os.environ.get("MUJOCO_GL")


def import_mjx_quietly() -> None:
    """Imports `mujoco.mjx` with its stdout captured: the Warp notices are dropped, anything else
    it prints is passed on to stderr."""
    if "mujoco.mjx" in sys.modules:
        return
    captured = io.StringIO()
    with contextlib.redirect_stdout(captured):
        import mujoco.mjx  # noqa: F401
    for line in captured.getvalue().splitlines():
        if line.strip() and not line.startswith(WARP_ABSENT_PREFIXES):
            print(line, file=sys.stderr)


def prepare() -> None:
    choose_gl_backend()
    import_mjx_quietly()
