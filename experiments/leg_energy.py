"""Energy per hop against the leg's lengths, relative to the URDF's leg (docs/img/leg_energy.png).

    python experiments/leg_energy.py SHORT_SHANKS SHANKS THIGHS [--out docs/img/leg_energy.png]

Each argument is the folder of a `python -m hopper_mjx.sweep param` run (`--param shank_length` for the first
two, `--param thigh_length` for the third, each holding the URDF's 0.35 m among its values; docs/variation.md
gives the commands), all run alike but for the parameter and its values. Reads their summary.json only.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from hopper_mjx.shell import checks, process  # noqa: E402

URDF_LENGTH = 0.35  # m, the seed's thigh and shank
PLANETS = ((9.81, "Earth"), (3.71, "Mars"), (1.62, "Moon"))
SWEPT = ("param", "values")  # what may differ between the sweeps compared


def groups(param: str, folders: list[str]) -> tuple[list[dict], dict]:
    """The sweeps' grid points and their shared arguments; raises ValueError for a folder that is not a sweep of
    `param` with the URDF's length, or that was run otherwise than the others."""
    out, arguments = [], None
    for f in folders:
        path = Path(f) / "summary.json"
        if not path.is_file():
            raise ValueError(f"{f}: no summary.json (not a finished sweep's folder)")
        summary = json.loads(path.read_text())
        rows = summary["groups"]
        if not rows or param not in rows[0]:
            raise ValueError(f"{f}: not a sweep of {param}")
        arguments = same_settings(arguments, summary["arguments"], f)
        out += rows
    if not any(abs(r[param] - URDF_LENGTH) < 1e-9 for r in out):
        raise ValueError(f"the {param} sweeps hold no {URDF_LENGTH} m (the URDF's), which the plot is relative to")
    return out, arguments


def same_settings(first: dict | None, other: dict, folder: str) -> dict:
    """`first` (or `other`, the first sweep's): the plot compares sweeps that differ in their swept values only."""
    if first is None:
        return other
    differ = sorted(k for k in first.keys() | other.keys() if k not in SWEPT and first.get(k) != other.get(k))
    if differ:
        raise ValueError(f"{folder}: run with other settings than the first sweep ({', '.join(differ)})")
    return first


def _span(values, fmt: str) -> str:
    low, high = format(min(values), fmt), format(max(values), fmt)
    return low if low == high else f"{low}-{high}"


def panel(ax, param: str, groups: list[dict]) -> None:
    for g, name in PLANETS:
        cells = sorted({r[param]: r for r in groups if r["gravity"] == g}.values(), key=lambda r: r[param])
        ref = next(r["energy_per_hop"] for r in cells if abs(r[param] - URDF_LENGTH) < 1e-9)
        ax.plot([r[param] for r in cells], [100 * (r["energy_per_hop"] / ref - 1) for r in cells], "o-",
                label=f"{name} ({ref:.2f} J/kg at {URDF_LENGTH} m)")
    ax.axvline(URDF_LENGTH, color="0.6", ls=":")
    ax.set_xlabel(f"{param} (m)")
    ax.set_ylabel("energy per hop vs the URDF's leg (%)")
    # What the cells measured, so that the curves are known to be steady hopping at the command.
    apex = [r["apex_height"] for r in groups if r.get("apex_height") is not None]
    ax.set_title(f"{param}: {_span([100 * r['survival'] for r in groups], '.0f')} % up, "
                 f"apex rise {_span(apex, '.3f') if apex else '-'} m", fontsize=11)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def figure(shanks: list[dict], thighs: list[dict], arguments: dict):
    """The two panels (a matplotlib Figure); the subtitle the sweeps' shared settings and physics."""
    from hopper_mjx.scenario import Physics

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), constrained_layout=True)
    panel(axes[0], "shank_length", shanks)
    panel(axes[1], "thigh_length", thighs)
    words = Physics.from_json(arguments).described()
    words["variation"] += ", but for the swept length"
    a = arguments
    fig.suptitle(f"{a['controller']}, {a['num']} replicates per cell, {a['duration']:g} s each; command: apex "
                 f"rise {a['height']:g} m, speed {a['speed'][0]:g},{a['speed'][1]:g} m/s; points: the survivors' "
                 f"mean\n{'; '.join(words.values())}", fontsize=10)
    return fig


def main(argv=None) -> int:
    p = checks.parser("python experiments/leg_energy.py", __doc__)  # one-line refusals, as every command's
    p.add_argument("short_shanks")
    p.add_argument("shanks")
    p.add_argument("thighs")
    p.add_argument("--out", default="docs/img/leg_energy.png")
    args = p.parse_args(argv)
    try:  # every input checked before anything is drawn or written
        shanks, settings = groups("shank_length", [args.short_shanks, args.shanks])
        thighs, others = groups("thigh_length", [args.thighs])
        same_settings(settings, others, args.thighs)
    except (ValueError, OSError, KeyError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    figure(shanks, thighs, settings).savefig(args.out, dpi=100)
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
