"""Energy per hop against the leg's lengths, relative to the URDF's leg (docs/img/leg_energy.png).

    python experiments/leg_energy.py SHORT_SHANKS SHANKS THIGHS [--out docs/img/leg_energy.png]

Each argument is the folder of a `python -m hopper_mjx.sweep param` run (`--param shank_length` for the first
two, `--param thigh_length` for the third, each holding the URDF's 0.35 m among its values; docs/variation.md
gives the commands). Reads their summary.json only.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

URDF_LENGTH = 0.35  # m, the seed's thigh and shank
PLANETS = ((9.81, "Earth"), (3.71, "Mars"), (1.62, "Moon"))


def groups(param: str, folders: list[str]) -> list[dict]:
    """The sweeps' grid points; raises ValueError for a folder that is not a sweep of `param` with the URDF's length."""
    out = []
    for f in folders:
        path = Path(f) / "summary.json"
        if not path.is_file():
            raise ValueError(f"{f}: no summary.json (not a finished sweep's folder)")
        rows = json.loads(path.read_text())["groups"]
        if not rows or param not in rows[0]:
            raise ValueError(f"{f}: not a sweep of {param}")
        out += rows
    if not any(abs(r[param] - URDF_LENGTH) < 1e-9 for r in out):
        raise ValueError(f"the {param} sweeps hold no {URDF_LENGTH} m (the URDF's), which the plot is relative to")
    return out


def panel(ax, param: str, groups: list[dict]) -> None:
    for g, name in PLANETS:
        cells = sorted({r[param]: r for r in groups if r["gravity"] == g}.values(), key=lambda r: r[param])
        ref = next(r["energy_per_hop"] for r in cells if abs(r[param] - URDF_LENGTH) < 1e-9)
        ax.plot([r[param] for r in cells], [100 * (r["energy_per_hop"] / ref - 1) for r in cells], "o-",
                label=f"{name} ({ref:.2f} J/kg at {URDF_LENGTH} m)")
    ax.axvline(URDF_LENGTH, color="0.6", ls=":")
    ax.set_xlabel(f"{param} (m)")
    ax.set_ylabel("energy per hop vs the URDF's leg (%)")
    ax.set_title(f"{param}: 100 % up, apex 0.100 m at every value")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("short_shanks")
    p.add_argument("shanks")
    p.add_argument("thighs")
    p.add_argument("--out", default="docs/img/leg_energy.png")
    args = p.parse_args(argv)
    try:  # every input checked before anything is drawn or written
        shanks = groups("shank_length", [args.short_shanks, args.shanks])
        thighs = groups("thigh_length", [args.thighs])
    except (ValueError, OSError, KeyError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    panel(axes[0], "shank_length", shanks)
    panel(axes[1], "thigh_length", thighs)
    fig.savefig(args.out, dpi=100)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
