"""A finished sweep's outputs: results.csv, summary.json, plots and a terminal table."""

from __future__ import annotations

import csv
import io
import json
import math
from importlib import metadata
from pathlib import Path

import numpy as np

from hopper_mjx.sweep.grid import PLANETS, Instances, SweepSpec

INTEGER_COLUMNS = {"replicate", "seed", "hops", "fell", "diverged"}


def rows(spec: SweepSpec, inst: Instances, table: np.ndarray, columns: tuple[str, ...]) -> tuple[list[str], list[list]]:
    header = ["gravity", "replicate", "seed"] + ([spec.param] if spec.kind == "gains" else []) + list(columns)
    out = []
    for i in range(len(inst)):
        row = [inst.gravity[i], inst.replicate[i], spec.seed]
        row += [inst.value[i]] if spec.kind == "gains" else []
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
    path.write_text(buf.getvalue())


def survived(table: np.ndarray, columns: tuple[str, ...]) -> np.ndarray:
    return (table[:, columns.index("fell")] == 0) & (table[:, columns.index("diverged")] == 0)


def group_summary(spec: SweepSpec, inst: Instances, table: np.ndarray, columns: tuple[str, ...]) -> list[dict]:
    """One record per grid point (gravity, or gain value x gravity), averaged over replicates."""
    values = spec.values if spec.kind == "gains" else (math.nan,)
    alive = survived(table, columns)
    groups = []
    for value in values:
        for g in spec.gravity:
            sel = (inst.gravity == g) & ((inst.value == value) | (np.isnan(inst.value) & math.isnan(value)))
            record = {"gravity": g, "label": PLANETS.get(g, "")}
            if spec.kind == "gains":
                record[spec.param] = value
            record.update(n=int(sel.sum()), survival=float(alive[sel].mean()),
                          diverged=int(table[sel, columns.index("diverged")].sum()))
            # Hop metrics describe steady hopping: the survivors' (a fallen run's last hops are its collapse).
            steady = sel & alive
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
            ("hops", "hops", "{:.1f}"), ("apex m", "apex_height", "{:.3f}"), ("arc m", "flight_rise", "{:.3f}"),
            ("flight s", "flight_time", "{:.3f}"), ("stance s", "stance_time", "{:.3f}"),
            ("period s", "hop_period", "{:.3f}"), ("duty", "duty_factor", "{:.2f}"), ("v m/s", "mean_speed", "{:+.2f}"),
            ("|v err|", "tracking_error", "{:.2f}"), ("CoT", "cost_of_transport", "{:.2f}")]
    if spec.kind == "gains":
        cols.insert(0, (spec.param, spec.param, "{:g}"))
    if label:
        cols.insert(0, ("controller", "controller", "{}"))
    cells = [[h for h, _, _ in cols]]
    for g in groups:
        cells.append(["-" if g.get(k) is None else f.format(g[k]) for _, k, f in cols])
    widths = [max(len(r[i]) for r in cells) for i in range(len(cols))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join([lines[0], "-" * len(lines[0])] + lines[1:])


def plot_gravity(path: Path, spec: SweepSpec, groups: list[dict], series: list | None = None) -> None:
    """Six panels against gravity; `series` [(label, groups)] draws several controllers in one figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = series or [("measured", groups)]
    panels = [("apex_height", "apex rise (m)"), ("flight_time", "flight time (s)"), ("hop_period", "hop period (s)"),
              ("duty_factor", "duty factor"), ("survival", "survival"), ("cost_of_transport", "cost of transport")]
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), constrained_layout=True)
    for ax, (key, label) in zip(axes.flat, panels):
        for name, rows_ in series:
            g = np.array([r["gravity"] for r in rows_])
            val = np.array([np.nan if r.get(key) is None else r[key] for r in rows_])
            err = np.array([np.nan if r.get(f"{key}_std") is None else r[f"{key}_std"] for r in rows_])
            ax.errorbar(g, val, yerr=None if key == "survival" else err, fmt="o-", capsize=3, label=name)
        ax.set_xlabel("gravity g (m/s²)")
        ax.set_ylabel(label)
        for gp, name in PLANETS.items():
            ax.axvline(gp, color="0.8", lw=0.8, zorder=0)
            ax.text(gp, 1.0, name, transform=ax.get_xaxis_transform(), ha="center", va="bottom", fontsize=7)
        ax.grid(alpha=0.3)
    axes[0, 0].axhline(spec.height, color="C3", ls="--", label="commanded")
    if len(series) == 1:
        g = np.array([r["gravity"] for r in groups])
        ballistic = np.array([np.nan if r.get("ballistic_flight_time") is None else r["ballistic_flight_time"]
                              for r in groups])
        axes[0, 1].plot(g, ballistic, "C3x--", label="ballistic 2√(2h/g), h = each hop's measured rise")
    axes[0, 0].legend(fontsize=8)
    axes[0, 1].legend(fontsize=8)
    axes[1, 1].set_ylim(-0.05, 1.05)
    who = "Raibert" if len(series) == 1 and spec.controller == "raibert" else " vs ".join(n for n, _ in series)
    if len(series) == 1 and spec.controller != "raibert":
        who = spec.controller
    fig.suptitle(f"{who} hopping vs gravity: {spec.num} replicates per g, {spec.duration:g} s each")
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_gains(path: Path, spec: SweepSpec, groups: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shape = (len(spec.values), len(spec.gravity))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), constrained_layout=True)
    for ax, key, label, cmap in ((axes[0], "survival", "survival", "viridis"),
                                 (axes[1], "tracking_error", "speed tracking error (m/s)", "magma_r")):
        grid = np.array([np.nan if r.get(key) is None else r[key] for r in groups]).reshape(shape)
        im = ax.imshow(grid, origin="lower", aspect="auto", cmap=cmap)
        ax.set_xticks(range(shape[1]), [f"{g:g}" for g in spec.gravity])
        ax.set_yticks(range(shape[0]), [f"{v:g}" for v in spec.values])
        ax.set_xlabel("gravity g (m/s²)")
        ax.set_ylabel(spec.param)
        ax.set_title(label)
        for (r, c), v in np.ndenumerate(grid):
            ax.text(c, r, "-" if np.isnan(v) else f"{v:.2f}", ha="center", va="center", fontsize=7, color="w")
        fig.colorbar(im, ax=ax)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write(out: Path, spec: SweepSpec, inst: Instances, table: np.ndarray, columns: tuple[str, ...], facts: dict) -> str:
    """Writes every output into OUT and returns the terminal table."""
    header, body = rows(spec, inst, table, columns)
    write_csv(out / "results.csv", header, body)
    groups = group_summary(spec, inst, table, columns)
    summary = {"groups": groups, "note": "survival over all replicates; every other aggregate over the survivors",
               "arguments": spec.to_json(), "versions": versions(), "run": facts}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    if spec.kind == "gravity":
        plot_gravity(out / "gravity.png", spec, groups)
    else:
        plot_gains(out / "gains.png", spec, groups)
    text = table_text(spec, groups)
    (out / "table.txt").write_text(text + "\n")
    return text


def write_comparison(out: Path, spec: SweepSpec, results: list[tuple[str, list[dict]]]) -> str:
    """One table (table.txt, comparison.json) and one plot (gravity.png) of several controllers'
    gravity sweeps: same gravities, kicks, commands and metrics."""
    rows_ = [{"controller": name, **g} for name, groups in results for g in groups]
    (out / "comparison.json").write_text(json.dumps({"groups": rows_, "arguments": spec.to_json()}, indent=1))
    plot_gravity(out / "gravity.png", spec, results[0][1], series=results)
    text = table_text(spec, rows_, label="controller")
    (out / "table.txt").write_text(text + "\n")
    return text
