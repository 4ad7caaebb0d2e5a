"""What every sweep figure shares: matplotlib off-screen, an atomic save, and the subtitle that says the run's
physics."""

from __future__ import annotations

from pathlib import Path

from hopper_mjx.shell.files import atomic_write
from hopper_mjx.sweep.grid import KICK, SweepSpec


def pyplot():
    import matplotlib

    matplotlib.use("Agg")  # files only, never a window
    import matplotlib.pyplot as plt

    return plt


def save(fig, path: Path) -> None:
    atomic_write(path, lambda f: fig.savefig(f, dpi=90, format=Path(path).suffix[1:] or None))
    pyplot().close(fig)


def physics_label(spec: SweepSpec) -> str:
    """The run's command (apex rise, speed) and physics in words (a plot's subtitle): `Physics.described`, and the
    kick where not the default, so that two different experiments never look alike. What the sweep varies is left
    to its axis."""
    words = spec.physics.described()
    if spec.param == "action_delay":
        del words["action_delay"]
    elif spec.sweeps_robot:
        words["variation"] += f" but its {spec.param}"
    if spec.grounds:  # a terrain sweep's ground is its axis
        del words["ground"]
    return "; ".join([f"command: apex rise {spec.height:g} m, speed {spec.speed[0]:g},{spec.speed[1]:g} m/s",
                      *words.values()] + ([f"kick std {spec.kick:g}"] if spec.kick != KICK else []))
