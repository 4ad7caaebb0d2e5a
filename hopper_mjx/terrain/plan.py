"""A terrain's plan view: its heights from above, in colour, in metres (`python -m hopper_mjx.model --map`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hopper_mjx.terrain import generators
from hopper_mjx.terrain.spec import Ground, tile_centres


def figure(ground: Ground):
    """The plan view of `ground` (not flat): heights over x and y, the start (the origin) marked; on a course, each
    tile's kind over its column and level beside its row."""
    import matplotlib

    matplotlib.use("Agg")  # files only, never a window
    import matplotlib.pyplot as plt

    t = ground.terrain()
    xs, ys = t.axes()
    span = max(float(np.abs(t.heights).max()), 1e-3)
    width = 8.0 * min(1.5, max(1.0, (xs[-1] - xs[0]) / (ys[-1] - ys[0])))
    fig, ax = plt.subplots(figsize=(width, 7.0), layout="constrained")
    image = ax.imshow(t.heights, origin="lower", extent=(xs[0], xs[-1], ys[0], ys[-1]), cmap="BrBG_r",
                      vmin=-span, vmax=span, interpolation="nearest")
    fig.colorbar(image, ax=ax, label="ground height (m)", shrink=0.8, pad=0.12)
    ax.plot(0.0, 0.0, "k+", markersize=10, label="the core's start (origin)")
    if ground.name == "course":
        centres = tile_centres(ground)
        for kind, name in enumerate(generators.COURSE_KINDS):
            ax.text(centres[-1, kind, 0], ys[-1], name, ha="center", va="bottom", fontsize=9)
        levels = ax.secondary_yaxis("right")
        levels.set_yticks(centres[:, 0, 1], labels=[f"level {i}" for i in range(centres.shape[0])])
        ax.plot(*centres.reshape(-1, 2).T, "k.", markersize=4, label="tile centres (episode starts)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    name, _, keys = str(ground).partition(":")
    ax.set_title(f"{name}:\n{keys}", fontsize=9, pad=18 if ground.name == "course" else 6)
    fig.legend(loc="outside lower center", ncols=2, fontsize=8)
    return fig


def save_map(ground: Ground, path: str | Path) -> None:
    from hopper_mjx.shell.files import atomic_write

    fig = figure(ground)
    atomic_write(path, lambda f: fig.savefig(f, dpi=90, format=Path(path).suffix[1:] or None))
    import matplotlib.pyplot as plt

    plt.close(fig)
