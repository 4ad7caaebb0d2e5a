"""A finished sweep's outputs: results.csv, summary.json, plots and a terminal table."""

from __future__ import annotations

import csv
import io
import json
import math
from importlib import metadata
from pathlib import Path

import numpy as np

from hopper_mjx import registry
from hopper_mjx.metrics.thresholds import SPEED_TOLERANCE
from hopper_mjx.shell.checks import counted
from hopper_mjx.shell.files import atomic_write_text
from hopper_mjx.sweep import limits
from hopper_mjx.sweep.grid import BAND_KINDS, PASSED, PLANETS, Instances, SweepSpec
from hopper_mjx.sweep.plotting import physics_label, pyplot, save

INTEGER_COLUMNS = {"replicate", "seed", "hops", "fell", "diverged", "obstacles_cleared"}
# The action delay Raibert stops taking: docs/variation.md measured it (`sweep param --param action_delay --values
# 0,2,4,6,8,10 --gravity 9.81,3.71,1.62 --num 16 --duration 20`): the first falls at 2 ms (the Moon), none up from 6.
RAIBERT_DELAY_LIMIT_MS = 2.0
RAIBERT_DELAY_FIGURE = ("Raibert keeps every robot up at 0 ms, Earth and Mars at 2 ms (the Moon 31 %), 0-12 % at 4 ms "
                        "and none from 6 ms: its stance servo was tuned for prompt torques (docs/variation.md, 16 "
                        "robots per cell at Earth, Mars and Moon, 20 s); --controller jump acts on what its delay "
                        "will meet (docs/control.md)")
# docs/control.md (`sweep gravity --controller balance --gravity 9.81,3.71,1.62 --num 64 --duration 10`): the LQR
# stance keeps none of the sweep's kicked robots up; Raibert hopping in place at --height 0.05 keeps them all.
BALANCE_FIGURE = ("balance, an LQR stance, keeps none of a sweep's kicked robots up (0 % at Earth, Mars and Moon, 64 "
                  "per gravity, 10 s: docs/control.md); raibert --height 0.05 hops in place and keeps them all")
REACH = 0.1  # m: a base this close to an obstacle's near edge has reached it (its foot lands ahead of it)
UNITS = {"obstacle_height": "m", "gap_width": "m", "roughness": "m, peak |height|"}  # a terrain sweep's value


def rows(spec: SweepSpec, inst: Instances, table: np.ndarray, columns: tuple[str, ...],
         bounds: dict | None = None) -> tuple[list[str], list[list]]:
    """results.csv's header and rows; `bounds` (`bound_columns`) adds a column per bound."""
    bounds = {name: [per_g[float(g)] for g in inst.gravity] for name, per_g in (bounds or {}).items()}
    header = ["gravity", "replicate", "seed"] + ([spec.param] if spec.swept else []) + list(inst.robot)
    header += list(columns) + list(bounds)
    out = []
    for i in range(len(inst)):
        row = [inst.gravity[i], inst.replicate[i], spec.seed]
        row += [inst.value[i]] if spec.swept else []
        row += [v[i] for v in inst.robot.values()]
        out.append(row + list(table[i]) + [v[i] for v in bounds.values()])
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
            if spec.kind in BAND_KINDS:  # a block or a gap to reach; a terrain sweep's rough ground has neither
                record["reached"] = float(reached(spec, table[sel], columns).mean())
            highest = table[sel, columns.index("highest_apex")]  # over every replicate: a fall ends the count
            highest = highest[np.isfinite(highest)]
            record["highest_median"] = float(np.median(highest)) if highest.size else None
            record["highest_best"] = float(highest.max()) if highest.size else None
            if "highest_landing_tilt" in columns:  # of every replicate whose highest hop landed before a fall
                tilt = table[sel, columns.index("highest_landing_tilt")]
                tilt = tilt[np.isfinite(tilt)]
                record["highest_tilt_median"] = float(np.median(tilt)) if tilt.size else None
            if "past_tilt" in columns:
                record["past"] = limits.past_medians(table[sel], columns)
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


def obstacle_band(spec: SweepSpec) -> tuple[float, float] | None:
    """m, the near and far edge of an obstacle sweep's block (a gaps sweep's gap) along +x, its first value's (every
    value's starts there), else None."""
    if spec.kind not in BAND_KINDS:
        return None
    from hopper_mjx.terrain import parse

    bands = parse(spec.grounds[0]).obstacles()
    return (float(bands[0, 0]), float(bands[0, 1])) if len(bands) else None


def reached(spec: SweepSpec, table: np.ndarray, columns: tuple[str, ...]) -> np.ndarray:
    """(n,) bool: each row's robot came within REACH of the obstacle (or cleared it) before the end or its fall."""
    x = obstacle_band(spec)[0]
    made_good = table[:, columns.index("distance_made_good")]
    return (table[:, columns.index("obstacles_cleared")] > 0) | (made_good >= x - REACH)


def action_delays(spec: SweepSpec, inst: Instances) -> np.ndarray:
    """(n,) ms, each instance's action delay: drawn (--randomize), swept (--param action_delay) or --action-delay."""
    if "action_delay" in inst.robot:
        return np.asarray(inst.robot["action_delay"], dtype=float)
    if spec.param == "action_delay":
        return np.asarray(inst.value, dtype=float)
    return np.full(len(inst), spec.physics.action_delay * 1e3)


def notes(spec: SweepSpec, inst: Instances, table: np.ndarray, columns: tuple[str, ...],
          groups: list[dict]) -> list[str]:
    """One line per figure the table prints that means less than it seems, or per fall with a known cause:
    a delay past what the controller takes, an obstacle no replicate reached, a speed far from its command."""
    out = []
    fell = ~survived(table, columns)
    late = fell & (action_delays(spec, inst) >= RAIBERT_DELAY_LIMIT_MS)
    if spec.controller == "raibert" and late.any():
        delays = action_delays(spec, inst)[late]
        span = f"{delays.min():g}" + (f"-{delays.max():g}" if delays.max() > delays.min() else "")
        out.append(f"note: {late.sum()} of the {fell.sum()} fallen robots ran {span} ms of action delay; "
                   f"{RAIBERT_DELAY_FIGURE}")
    if spec.controller == "balance" and fell.any():
        out.append(f"note: {fell.sum()} of {len(fell)} robots fell; {BALANCE_FIGURE}")
    band = obstacle_band(spec)
    missed = [g for g in groups if g.get("reached") == 0]
    if band is not None and missed:
        out.append(_not_reached(spec, band, missed, len(missed) == len(groups)))
    commanded = np.array(spec.speed)
    far = [g for g in groups if g.get("tracking_error") is not None and g["tracking_error"] > SPEED_TOLERANCE]
    if far:
        errors = [g["tracking_error"] for g in far]
        if len(far) == len(groups):
            where = f"every grid point ({min(errors):.2f} to {max(errors):.2f} m/s)"
        else:
            listed = ", ".join(f"{_point(spec, g)}: {g['tracking_error']:.2f} m/s" for g in far[:4])
            where = f"{len(far)} of {len(groups)} grid points ({listed}{', ...' if len(far) > 4 else ''})"
        # Each robot's own drift: pushes in random directions leave the group's mean velocity on the command.
        out.append(f"warning: the speed is more than {SPEED_TOLERANCE:g} m/s from its command "
                   f"({commanded[0]:+.2f},{commanded[1]:+.2f} m/s) at {where}: each survivor's mean (vx, vy) over its "
                   "last 5 s, its distance from the command averaged")
    return out


def _point(spec: SweepSpec, g: dict) -> str:
    return f"g={g['gravity']:g}" + (f" {spec.param}={g[spec.param]:g}" if spec.swept else "")


def _not_reached(spec: SweepSpec, band: tuple[float, float], missed: list[dict], everywhere: bool) -> str:
    """The warning for grid points whose replicates all stopped short of the obstacle, with the --duration that
    would reach it at the speed they measured (after the run's own, at their last 5 s's speed)."""
    made = np.nanmean([np.nan if g.get("distance_made_good") is None else g["distance_made_good"] for g in missed])
    speed = np.nanmean([np.nan if g.get("mean_speed") is None else g["mean_speed"] for g in missed])
    where = "at any grid point" if everywhere else "at " + ", ".join(_point(spec, g) for g in missed)
    line = (f"warning: no replicate reached the {BAND_KINDS[spec.kind]} at x = {band[0]:g} m {where}: "
            f"'{PASSED[spec.kind]}' there means nothing; "
            f"they made {made:.2f} m good at {speed:.2f} m/s against {spec.speed[0]:g} commanded")
    if np.isfinite(speed) and speed > 0.01 and np.isfinite(made):
        need = math.ceil(spec.duration + (band[1] + REACH - made) / speed)
        return line + f"; --duration {need} would carry them past it at that speed"
    easier = "lower the block" if spec.kind == "obstacle" else "narrow the gap"
    return line + f"; they hardly moved forward: raise --speed or {easier}"


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
        if spec.kind in BAND_KINDS:
            cols += [("reached", "reached", "{:.0%}"), (PASSED[spec.kind], "cleared", "{:.0%}"),
                     ("landing tilt °", "landing_tilt", "{:.1f}"), ("impact N", "impact_force", "{:.0f}"),
                     ("knee N·m", "peak_torque_kfe", "{:.0f}"), ("knee W", "peak_power_kfe", "{:.0f}"),
                     ("knee line", "line_use_kfe", "{:.2f}")]
    if label:
        cols.insert(0, ("controller", "controller", "{}"))
    cells = [[h for h, _, _ in cols]]
    for g in groups:
        cells.append(["-" if g.get(k) is None else f.format(g[k]) for _, k, f in cols])
    widths = [max(len(r[i]) for r in cells) for i in range(len(cols))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join([lines[0], "-" * len(lines[0])] + lines[1:])


def param_label(name: str) -> str:
    """A swept value's axis label with its unit."""
    from hopper_mjx.control.raibert import GAIN_UNITS

    known = registry.PARAMETERS.get(name) or registry.CONTROL_PARAMETERS.get(name)
    unit = known.unit if known else UNITS.get(name, GAIN_UNITS.get(name, "1"))
    return f"{name} ({unit})"


SPACEHOPPER_TILT = 9.7  # deg off upright at landing: SpaceHopper's, on hardware, beside the highest hop's


def _column(groups: list[dict], key: str) -> np.ndarray:
    return np.array([np.nan if r.get(key) is None else r[key] for r in groups])


def gravity_figure(spec: SweepSpec, groups: list[dict], series: list | None = None, bounds: dict | None = None):
    """The gravity sweep's figure (a matplotlib Figure; `write` saves it as gravity.png); `series`
    [(label, groups)] draws several controllers in one figure; `bounds` (`limits.apex_bounds`), a command past the
    motors' bound: its apex panel draws the bound and the highest hop before any fall."""
    plt = pyplot()
    # The x axis ascends whatever order --gravity had.
    series = [(name, sorted(rows_, key=lambda r: r["gravity"])) for name, rows_ in (series or [("measured", groups)])]
    # Hopping in place travels (almost) nowhere, so work / (m·g·distance) is empty or noise there;
    # the energy of one hop is meaningful either way.
    energy = (("cost_of_transport", "cost of transport (work / (m·g·distance), 1)") if any(spec.speed)
              else ("energy_per_hop", "motor work per hop (J/kg)"))
    panels = [("apex_height", "apex rise (m)"), ("flight_time", "flight time (s)"), ("hop_period", "hop period (s)"),
              ("duty_factor", "duty factor (stance / period, 1)"), ("survival", "survival (% of replicates)"), energy]
    if bounds:  # asked past the bound the robots may all fall: how the highest hop landed says more than the duty
        panels[3] = ("highest_tilt_median", "the highest hop's landing tilt (° from upright)")
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), constrained_layout=True)
    for ax, (key, label) in zip(axes.flat, panels):
        for name, rows_ in series:
            scale = 100.0 if key == "survival" else 1.0  # the table prints survival in %
            over = ("median of every replicate whose highest hop landed" if key == "highest_tilt_median"
                    else f"{'mean' if name == 'measured' else name} ± std over survivors")
            ax.errorbar(_column(rows_, "gravity"), scale * _column(rows_, key), fmt="o-", capsize=3, label=over,
                        yerr=None if key in ("survival", "highest_tilt_median") else _column(rows_, f"{key}_std"))
        ax.set_xlabel("gravity g (m/s²)")
        ax.set_ylabel(label)
        if not any(np.isfinite(_column(rows_, key)).any() for _, rows_ in series):
            # A short run, or every robot down: say so, where an empty panel showed an axis of -0.04..0.04.
            ax.text(0.5, 0.3, f"no value: no replicate still up\nfinished a hop in {spec.duration:g} s",
                    transform=ax.transAxes, ha="center", va="center", fontsize=9, color="0.4")
            ax.set_yticks([])
        for gp, name in PLANETS.items():
            ax.axvline(gp, color="0.8", lw=0.8, zorder=0)
            ax.text(gp, 1.0, name, transform=ax.get_xaxis_transform(), ha="center", va="bottom", fontsize=7)
        ax.grid(alpha=0.3)
    axes[0, 0].axhline(spec.height, color="C3", ls="--", label="commanded")
    if len(series) == 1:
        rows_ = series[0][1]
        axes[0, 1].plot(_column(rows_, "gravity"), _column(rows_, "ballistic_flight_time"), "C3x--",
                        label="ballistic 2√(2h/g), h = each hop's measured rise")
    if bounds:
        rows_ = sorted(groups, key=lambda r: r["gravity"])
        g = _column(rows_, "gravity")
        axes[0, 0].plot(g, [bounds["apex_bound"][v] for v in g], "k:", label=f"bound: the {spec.physics.motor} "
                        "motors' best jump")
        axes[0, 0].plot(g, _column(rows_, "highest_median"), "C2s-", label="highest hop before any fall (median of "
                        "every replicate)")
        axes[0, 0].plot(g, _column(rows_, "highest_best"), "C2^:", label="the same, the best replicate")
        # The bound goes as about 1/g: on log axes a line, and the Earth's tenths of a metre beside Ceres's metres.
        axes[0, 0].set_xscale("log")
        axes[0, 0].set_yscale("log")
        low, high = axes[0, 0].get_ylim()
        axes[0, 0].set_ylim(low, high * (high / low))  # the upper half for the legend
        axes[1, 0].axhline(SPACEHOPPER_TILT, color="0.4", ls="--",
                           label=f"SpaceHopper on hardware, {SPACEHOPPER_TILT}°")
        axes[1, 0].set_ylim(bottom=0.0)
        axes[1, 0].legend(fontsize=8)
    axes[0, 0].legend(fontsize=7 if bounds else 8, loc="upper right" if bounds else "best")
    axes[0, 1].legend(fontsize=8)
    axes[1, 1].set_ylim(-5, 105)
    if len(series) > 1:
        who = " vs ".join(name for name, _ in series)
    else:
        who = "Raibert" if spec.controller == "raibert" else spec.controller
    fig.suptitle(f"{who} hopping vs gravity: {counted(spec.num, 'replicate')} per g, {spec.duration:g} s each\n"
                 f"{physics_label(spec)}", fontsize=11)
    fig.supxlabel("points: the mean over the replicates still up at the end; bars: ± 1 standard deviation over them; "
                  "survival: the share of all replicates up at the end", fontsize=8, color="0.3")
    return fig


def _label_colour(rgba) -> str:
    """Dark text on a pale cell, white on a dark one (by the cell's relative luminance, WCAG)."""
    linear = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgba[:3]]
    luminance = 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2]
    return "k" if luminance > 0.18 else "w"  # 0.18: equal contrast against black and white


def gains_figure(spec: SweepSpec, groups: list[dict], second=None, panels: int = 2):
    """The gains sweep's figure (a matplotlib Figure; `write` saves it as gains.png): survival and `second`
    (key, title, colour map, limits; default the speed tracking error) against the value and gravity."""
    plt = pyplot()
    gravity, values = sorted(spec.gravity), sorted(spec.values)  # both axes ascend
    at = {(r[spec.param], r["gravity"]): r for r in groups}
    fig, axes = plt.subplots(1, panels, figsize=(6 * panels, 4.5), constrained_layout=True)
    # Shares are in % as the table prints them, on a fixed 0-100 scale, so that all-survived reads as the top colour.
    second = second or ("tracking_error", "speed tracking error (m/s)", "magma_r", (None, None))
    heatmaps = ((axes[0], "survival", "survival (% of replicates)", "viridis", (0.0, 100.0)), (axes[1], *second))
    for ax, key, label, cmap, span in heatmaps:
        scale = 100.0 if span[1] == 100.0 else 1.0
        grid = np.array([[np.nan if at[v, g].get(key) is None else scale * at[v, g][key] for g in gravity]
                         for v in values])
        im = ax.imshow(grid, origin="lower", aspect="auto", cmap=cmap, vmin=span[0], vmax=span[1])
        ax.set_xticks(range(len(gravity)), [f"{g:g}" for g in gravity])
        ax.set_yticks(range(len(values)), [f"{v:g}" for v in values])
        ax.set_xlabel("gravity g (m/s²)")
        ax.set_ylabel(param_label(spec.param))
        ax.set_title(label)
        for (r, c), v in np.ndenumerate(grid):
            empty = "none up" if at[values[r], gravity[c]].get("survival") == 0 else "-"  # why a cell has no figure
            text = empty if np.isnan(v) else f"{v:.0f} %" if scale == 100.0 else f"{v:.2f}"
            ax.text(c, r, text, ha="center", va="center", fontsize=8,
                    color="k" if np.isnan(v) else _label_colour(im.cmap(im.norm(v))))
        fig.colorbar(im, ax=ax, label=label)
    fig.suptitle(f"{spec.kind} sweep of {spec.controller}: {spec.param} x gravity, {counted(spec.num, 'replicate')} "
                 f"per cell, {spec.duration:g} s each\n{physics_label(spec)}", fontsize=11)
    return fig


def terrain_figure(spec: SweepSpec, groups: list[dict]):
    """An obstacle, gaps or terrain sweep's figure (obstacle.png, gaps.png or terrain.png): survival, the share that
    cleared the obstacle (or the speed tracking error), and the ground of every value along +x at y = 0."""
    from hopper_mjx.terrain import parse

    second = None
    if spec.kind in BAND_KINDS:
        second = ("cleared", f"{PASSED[spec.kind]} the {BAND_KINDS[spec.kind]} (% of replicates)", "viridis",
                  (0.0, 100.0))
    fig = gains_figure(spec, groups, second=second, panels=3)
    ax = fig.axes[2]
    for value, text in sorted(zip(spec.values, spec.grounds)):
        t = parse(text).instance(spec.seed, 0).terrain()  # a seed=each sweep: replicate 0's draw
        xs, _ = t.axes()
        ax.plot(xs, t.heights[t.heights.shape[0] // 2], label=f"{spec.param} {value:g} m")
    # Where the robots got, per gravity: the survivors' mean travel, at the speed they measured.
    for k, g in enumerate(sorted(spec.gravity)):
        made = _column([r for r in groups if r["gravity"] == g], "distance_made_good")
        speed = _column([r for r in groups if r["gravity"] == g], "mean_speed")
        if np.isfinite(made).any():
            ax.axvline(np.nanmean(made), color=f"C{k + 3}", ls=":", lw=1.2,
                       label=f"g {g:g}: made {np.nanmean(made):.2f} m good at {np.nanmean(speed):.2f} m/s")
    measured = _column(groups, "mean_speed")
    measured = (f"{np.nanmin(measured):.2f}-{np.nanmax(measured):.2f} m/s measured" if np.isfinite(measured).any()
                else "none measured")
    commanded = f"{spec.speed[0]:g} m/s commanded" if spec.speed[0] else "no speed commanded"
    ax.set_xlabel("x (m), the start at 0")
    ax.set_ylabel("ground height at y = 0 (m)")
    ax.set_title(f"the ground{' (replicate 0' + chr(39) + 's draw)' if spec.kind == 'terrain' else ''}; where the "
                 f"robots got (dotted)\napproach: {commanded}, {measured}", fontsize=10)
    band = obstacle_band(spec)
    if band is not None:  # the block and the way to it, not the whole ground
        made = _column(groups, "distance_made_good")
        ax.set_xlim(-0.5, max(band[1] + 0.8, np.nanmax(made, initial=0.0) + 0.3))
        # A cell no replicate reached says so: its 0 % cleared is no measurement of the block.
        gravity, values = sorted(spec.gravity), sorted(spec.values)
        at = {(r[spec.param], r["gravity"]): r for r in groups}
        for text, (v, g) in zip(fig.axes[1].texts, [(v, g) for v in values for g in gravity]):
            if at[v, g].get("reached") == 0:
                text.set_text("not reached")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    return fig


def write(out: Path, spec: SweepSpec, inst: Instances, table: np.ndarray, columns: tuple[str, ...],
          facts: dict) -> tuple[str, list[str]]:
    """Writes every output into OUT; returns the terminal table and its notes (`notes`, in table.txt below it)."""
    bounds = limits.bound_columns(spec)
    header, body = rows(spec, inst, table, columns, bounds)
    write_csv(out / "results.csv", header, body)
    groups = group_summary(spec, inst, table, columns)
    said = notes(spec, inst, table, columns, groups)
    summary = {"groups": groups, "note": "survival over all replicates; every other aggregate over the survivors",
               **({"bounds": {k: {f"{g:g}": v for g, v in per_g.items()} for k, per_g in bounds.items()}}
                  if bounds else {}),
               "notes": said, "arguments": spec.to_json(), "versions": versions(), "run": facts}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1))
    if spec.kind == "gravity":
        save(gravity_figure(spec, groups, bounds=bounds), out / "gravity.png")
    else:
        save({"gains": gains_figure, "param": gains_figure}.get(spec.kind, terrain_figure)(spec, groups),
             out / f"{spec.kind}.png")
    if bounds and spec.kind in BAND_KINDS:
        save(limits.figure(spec, groups, bounds), out / "limits.png")
    text = "\n".join([table_text(spec, groups), *limits.lines(spec, groups, bounds)])
    atomic_write_text(out / "table.txt", "\n".join([text, *said]) + "\n")
    return text, said


def write_comparison(out: Path, spec: SweepSpec, results: list[tuple[str, list[dict]]]) -> str:
    """One table (table.txt, comparison.json) and one plot of several controllers' sweeps on the same grid, kicks,
    commands and metrics: gravity.png for gravity sweeps; a block or gaps sweep's obstacle.png or gaps.png, with
    each gravity's highest block (widest gap) controller by controller below the table."""
    rows_ = [{"controller": name, **g} for name, groups in results for g in groups]
    atomic_write_text(out / "comparison.json", json.dumps({"groups": rows_, "arguments": spec.to_json()}, indent=1))
    text = table_text(spec, rows_, label="controller")
    if spec.kind in BAND_KINDS:
        save(limits.comparison_figure(spec, results), out / f"{spec.kind}.png")
        text = "\n".join([text, *limits.comparison_lines(spec, results, limits.bound_columns(spec))])
    else:
        save(gravity_figure(spec, results[0][1], series=results), out / "gravity.png")
    atomic_write_text(out / "table.txt", text + "\n")
    return text
