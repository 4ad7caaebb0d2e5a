"""Checks of the files that describe the robot, as a command line gives them (one line, no MuJoCo compile)."""

from __future__ import annotations

from pathlib import Path

from hopper_mjx.checks import check_readable_file
from hopper_mjx.model import loader


def check_urdf(path: str | Path | None) -> None:
    """--urdf exists and describes a monoped (checked as XML, before MuJoCo compiles anything)."""
    if path is None:
        return
    path = check_readable_file("--urdf", path)
    try:
        loader.describe(loader.read_text(path, "URDF file", loader.URDFError), str(path))
    except loader.URDFError as err:
        raise ValueError(f"--urdf: {err}") from None
