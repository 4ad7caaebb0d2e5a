"""A finished sweep's outputs: results.csv, summary.json, plots and a terminal table."""

from __future__ import annotations

import csv
import io
import json
import math
from importlib import metadata
from pathlib import Path

import numpy as np

from hopper_mjx.shell.files import atomic_write, atomic_write_text
from hopper_mjx.sweep.grid import PLANETS, Instances, SweepSpec

INTEGER_COLUMNS = {"replicate", "seed", "hops", "fell", "diverged", "obstacles_cleared"}


def rows(spec: SweepSpec, inst: Instances, table: np.ndarray, columns: tuple[str, ...]) -> tuple[list[str], list[list]]:
    header = ["gravity", "replicate", "seed"] + ([spec.param] if spec.swept else []) + list(inst.robot)
    header += list(columns)
    out = []
    for i in range(len(inst)):
        row = [inst.gravity[i], inst.replicate[i], spec.seed]
        row += [inst.value[i]] if spec.swept else []
        row += [v[i] for v in inst.robot.values()]
        out.append(row + list(table[i]))
    return header, out


def _cell(name: str, value) -> str:
    value = float(value)
    if math.isnan(value):
        return "nan"
    return str(int(value)) if name in INTEGER_COLUMNS else f"{value:.6g}"


def write_csv(path: Path, header: list[str], body: list[list]) -> None:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    writer.writerows([_cell(h, v) for h, v in zip(header, row)] for row in body)
    atomic_write_text(path, buf.getvalue())


def survived(table: np.ndarray, columns: tuple[str, ...]) -> np.ndarray:
    return (table[:, columns.index("fell")] == 0) & (table[:, columns.index("diverged")] == 0)


def group_summary(spec: SweepSpec, inst: Instances, table: np.ndarray, columns: tuple[str, ...]) -> list[dict]:
    """One record per grid point (gravity, or gain value x gravity), averaged over replicates."""
    values = spec.values if spec.swept else (math.nan,)
    alive = survived(table, columns)
    groups = []
    for value in values:
        for g in spec.gravity:
            sel = (inst.gravity == g) & ((inst.value == value) | (np.isnan(inst.value) & math.isnan(value)))
            record = {"gravity": g, "label": PLANETS.get(g, "")}
            if spec.swept:
                record[spec.param] = value
            record.update(n=int(sel.sum()), survival=float(alive[sel].mean()),
                          diverged=int(table[sel, columns.index("diverged")].sum()))
            if "obstacles_cleared" in columns:  # over every replicate, as survival: a fall before it is a miss
                record["cleared"] = float((table[sel, columns.index("obstacles_cleared")] > 0).mean())
            # Hop metrics describe steady hopping: the survivors' (a fallen run's last hops are its collapse).
            steady = sel & alive
            error = np.abs(table[steady, columns.index("apex_height")] - spec.height)
            record["apex_error"] = float(error[np.isfinite(error)].mean()) if np.isfinite(error).any() else None
            for c, name in enumerate(columns):
                if name in ("fell", "diverged"):
                    continue
                finite = table[steady, c][np.isfinite(table[steady, c])]
                record[name] = float(finite.mean()) if finite.size else None
                record[f"{name}_std"] = float(finite.std()) if finite.size > 1 else None
            groups.append(record)
    return groups


def versions() -> dict:
    return {p: metadata.version(p) for p in ("hopper_mjx", "jax", "jaxlib", "mujoco", "mujoco-mjx", "brax", "numpy")}


def table_text(spec: SweepSpec, groups: list[dict], label: str | None = None) -> str:
    cols = [("g m/s²", "gravity", "{:.2f}"), ("", "label", "{}"), ("n", "n", "{}"), ("alive", "survival", "{:.0%}"),
            ("hops", "hops", "{:.1f}"), ("apex m", "apex_height", "{:.3f}"), ("|apex err|", "apex_error", "{:.3f}"),
            ("arc m", "flight_rise", "{:.3f}"),
            ("flight s", "flight_time", "{:.3f}"), ("stance s", "stance_time", "{:.3f}"),
            ("period s", "hop_period", "{:.3f}"), ("duty", "duty_factor", "{:.2f}"), ("v m/s", "mean_speed", "{:+.2f}"),
            ("|v err|", "tracking_error", "{:.2f}"), ("CoT", "cost_of_transport", "{:.2f}")]
    if spec.swept:
        cols.insert(0, (spec.param, spec.param, "{:g}"))
    if spec.grounds:  # a terrain sweep's own figures: over all replicates (cleared), and the survivors' travel
        cols += [("made good m", "distance_made_good", "{:+.2f}")]
        cols += [("cleared", "cleared", "{:.0%}")] if spec.kind == "obstacle" else []
    if label:
        cols.insert(0, ("controller", "controller", "{}"))
    cells = [[h for h, _, _ in cols]]
    for g in groups:
        cells.append(["-" if g.get(k) is None else f.format(g[k]) for _, k, f in cols])
    widths = [max(len(r[i]) for r in cells) for i in range(len(cols))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join([lines[0], "-" * len(lines[0])] + lines[1:])


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")  # files only, never a window
    import matplotlib.pyplot as plt

    return plt


def save(fig, path: Path) -> None:
    atomic_write(path, lambda f: fig.savefig(f, dpi=90, format=Path(path).suffix[1:] or None))
    _pyplot().close(fig)


def _column(groups: list[dict], key: str) -> np.ndarray:
    return np.array([np.nan if r.get(key) is None else r[key] for r in groups])


def gravity_figure(spec: SweepSpec, groups: list[dict], series: list | None = None):
    """The gravity sweep's figure (a matplotlib Figure; `write` saves it as gravity.png); `series`
    [(label, groups)] draws several controllers in one figure."""
    plt = _pyplot()
    # The x axis ascends whatever order --values had.
    series = [(name, sorted(rows_, key=lambda r: r["gravity"])) for name, rows_ in (series or [("measured", groups)])]
    # Hopping in place travels (almost) nowhere, so work / (m·g·distance) is empty or noise there;
    # the energy of one hop is meaningful either way.
    energy = (("cost_of_transport", "cost of transport") if any(spec.speed)
              else ("energy_per_hop", "motor work per hop (J/kg)"))
    panels = [("apex_height", "apex rise (m)"), ("flight_time", "flight time (s)"), ("hop_period", "hop period (s)"),
              ("duty_factor", "duty factor"), ("survival", "survival"), energy]
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), constrained_layout=True)
    for ax, (key, label) in zip(axes.flat, panels):
        for name, rows_ in series:
            ax.errorbar(_column(rows_, "gravity"), _column(rows_, key), fmt="o-", capsize=3, label=name,
                        yerr=None if key == "survival" else _column(rows_, f"{key}_std"))
        ax.set_xlabel("gravity g (m/s²)")
        ax.set_ylabel(label)
        for gp, name in PLANETS.items():
            ax.axvline(gp, color="0.8", lw=0.8, zorder=0)
            ax.text(gp, 1.0, name, transform=ax.get_xaxis_transform(), ha="center", va="bottom", fontsize=7)
        ax.grid(alpha=0.3)
    axes[0, 0].axhline(spec.height, color="C3", ls="--", label="commanded")
    if len(series) == 1:
        rows_ = series[0][1]
        axes[0, 1].plot(_column(rows_, "gravity"), _column(rows_, "ballistic_flight_time"), "C3x--",
                        label="ballistic 2√(2h/g), h = each hop's measured rise")
    axes[0, 0].legend(fontsize=8)
    axes[0, 1].legend(fontsize=8)
    axes[1, 1].set_ylim(-0.05, 1.05)
    if len(series) > 1:
        who = " vs ".join(name for name, _ in series)
    else:
        who = "Raibert" if spec.controller == "raibert" else spec.controller
    fig.suptitle(f"{who} hopping vs gravity: {spec.num} replicates per g, {spec.duration:g} s each")
    return fig


def _label_colour(rgba) -> str:
    """Dark text on a pale cell, white on a dark one (by the cell's relative luminance, WCAG)."""
    linear = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgba[:3]]
    luminance = 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2]
    return "k" if luminance > 0.18 else "w"  # 0.18: equal contrast against black and white


def gains_figure(spec: SweepSpec, groups: list[dict], second=None, panels: int = 2):
    """The gains sweep's figure (a matplotlib Figure; `write` saves it as gains.png): survival and `second`
    (key, title, colour map, limits; default the speed tracking error) against the value and gravity."""
    plt = _pyplot()
    gravity, values = sorted(spec.gravity), sorted(spec.values)  # both axes ascend
    at = {(r[spec.param], r["gravity"]): r for r in groups}
    fig, axes = plt.subplots(1, panels, figsize=(6 * panels, 4.5), constrained_layout=True)
    # Survival is a fraction: a fixed 0-1 scale, so that all-survived reads as the top colour.
    second = second or ("tracking_error", "speed tracking error (m/s)", "magma_r", (None, None))
    heatmaps = ((axes[0], "survival", "survival", "viridis", (0.0, 1.0)), (axes[1], *second))
    for ax, key, label, cmap, limits in heatmaps:
        grid = np.array([[np.nan if at[v, g].get(key) is None else at[v, g][key] for g in gravity] for v in values])
        im = ax.imshow(grid, origin="lower", aspect="auto", cmap=cmap, vmin=limits[0], vmax=limits[1])
        ax.set_xticks(range(len(gravity)), [f"{g:g}" for g in gravity])
        ax.set_yticks(range(len(values)), [f"{v:g}" for v in values])
        ax.set_xlabel("gravity g (m/s²)")
        ax.set_ylabel(spec.param)
        ax.set_title(label)
        for (r, c), v in np.ndenumerate(grid):
            ax.text(c, r, "-" if np.isnan(v) else f"{v:.2f}", ha="center", va="center", fontsize=8,
                    color="k" if np.isnan(v) else _label_colour(im.cmap(im.norm(v))))
        fig.colorbar(im, ax=ax)
    return fig


def terrain_figure(spec: SweepSpec, groups: list[dict]):
    """An obstacle or terrain sweep's figure (saved as obstacle.png or terrain.png): survival, the share that
    cleared the obstacle (or the speed tracking error), and the ground of every value along +x at y = 0."""
    from hopper_mjx.terrain import parse

    fig = gains_figure(spec, groups, second=("cleared", "share that cleared the obstacle", "viridis", (0.0, 1.0))
                       if spec.kind == "obstacle" else None, panels=3)
    ax = fig.axes[2]
    for value, text in sorted(zip(spec.values, spec.grounds)):
        t = parse(text).instance(spec.seed, 0).terrain()  # a seed=each sweep: replicate 0's draw
        xs, _ = t.axes()
        ax.plot(xs, t.heights[t.heights.shape[0] // 2], label=f"{spec.param} {value:g}")
    ax.set_xlabel("x (m), the start at 0" + (", approached at {:g} m/s".format(spec.speed[0]) if spec.speed[0] else ""))
    ax.set_ylabel("ground height at y = 0 (m)")
    ax.set_title("the ground" + (" (replicate 0's draw)" if spec.kind == "terrain" else ""))
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    return fig


def write(out: Path, spec: SweepSpec, inst: Instances, table: np.ndarray, columns: tuple[str, ...], facts: dict) -> str:
    """Writes every output into OUT and returns the terminal table."""
    header, body = rows(spec, inst, table, columns)
    write_csv(out / "results.csv", header, body)
    groups = group_summary(spec, inst, table, columns)
    summary = {"groups": groups, "note": "survival over all replicates; every other aggregate over the survivors",
               "arguments": spec.to_json(), "versions": versions(), "run": facts}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1))
    figure = {"gravity": gravity_figure, "gains": gains_figure, "param": gains_figure}.get(spec.kind, terrain_figure)
    save(figure(spec, groups), out / f"{spec.kind}.png")
    text = table_text(spec, groups)
    atomic_write_text(out / "table.txt", text + "\n")
    return text


def write_comparison(out: Path, spec: SweepSpec, results: list[tuple[str, list[dict]]]) -> str:
    """One table (table.txt, comparison.json) and one plot (gravity.png) of several controllers'
    gravity sweeps: same gravities, kicks, commands and metrics."""
    rows_ = [{"controller": name, **g} for name, groups in results for g in groups]
    atomic_write_text(out / "comparison.json", json.dumps({"groups": rows_, "arguments": spec.to_json()}, indent=1))
    save(gravity_figure(spec, results[0][1], series=results), out / "gravity.png")
    text = table_text(spec, rows_, label="controller")
    atomic_write_text(out / "table.txt", text + "\n")
    return text
