"""Checks of the files that describe the robot, as a command line gives them (one line, no MuJoCo compile)."""

from __future__ import annotations

from pathlib import Path

from hopper_mjx.model import loader
from hopper_mjx.shell.checks import check_readable_file


def check_urdf(path: str | Path | None) -> loader.LegDescription:
    """--urdf exists and describes a monoped (checked as XML, before MuJoCo compiles anything); its
    description (the shipped monoped's for None)."""
    if path is not None:
        path = check_readable_file("--urdf", path)
    source = path or loader.DEFAULT_URDF
    try:
        return loader.describe(loader.read_text(source, "URDF file", loader.URDFError), str(source))
    except loader.URDFError as err:
        raise ValueError(f"--urdf: {err}") from None
