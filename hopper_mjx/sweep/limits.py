"""What a block or gaps sweep answers: the highest block (widest gap) the robots got past at each gravity, beside
the bound the motors put on it (`hardware.bound`), and what getting past it asked of the landing and the knee."""

from __future__ import annotations

import math

import numpy as np

from hopper_mjx.shell.checks import counted
from hopper_mjx.sweep.grid import BAND_KINDS, PASSED, PLANETS, SweepSpec
from hopper_mjx.sweep.plotting import physics_label, pyplot

# A band sweep's answer: (its bound's results.csv column, the answer in words, the quantity on its axis).
ANSWER = {"obstacle": ("height_bound", "highest block", "block height"),
          "gaps": ("width_bound", "widest gap", "gap width")}

# What the jump past a band asked, its medians over the replicates that got past (`past_medians`): the landing
# beyond it (`hops.landing_metrics`) and the knee's peaks over the run (`hops.actuator_metrics`).
PAST_COLUMNS = ("past_tilt", "past_impact", "peak_torque_kfe", "peak_power_kfe", "line_use_kfe")


def past_medians(table: np.ndarray, columns: tuple[str, ...]) -> dict[str, float | None]:
    """{PAST_COLUMNS name: its median over the rows that got past the band (fallen later or not), None if none}."""
    got = table[:, columns.index("obstacles_cleared")] > 0
    out = {}
    for name in PAST_COLUMNS:
        values = table[got, columns.index(name)]
        values = values[np.isfinite(values)]
        out[name] = float(np.median(values)) if values.size else None
    return out


def bound_columns(spec: SweepSpec) -> dict[str, dict[float, float]]:
    """A block or gaps sweep's bounds per gravity (`hardware.bound`, the model's robot with the sweep's motors):
    apex_bound, m of apex rise over standing, and the tallest block (height_bound) or widest gap (width_bound) it
    allows, m; a gravity sweep's, where it asks for more than the motors give (`apex_bounds`); {} for other sweeps."""
    if spec.kind == "gravity":
        return apex_bounds(spec)
    if spec.kind not in BAND_KINDS:
        return {}
    from hopper_mjx.hardware import bound
    from hopper_mjx.model.robot import standing_height

    m = spec.physics.mj_model
    per_g = bound.bounds(m, spec.physics.motor, spec.gravity)
    if spec.kind == "obstacle":
        standing, drop = standing_height(m), bound.tucked_drop(m)
        past = {g: bound.highest_block(b, standing, drop) for g, b in per_g.items()}
    else:
        reach = bound.leg_reach(m)
        past = {g: bound.widest_gap(b, reach) for g, b in per_g.items()}
    return {"apex_bound": {g: b.apex_rise for g, b in per_g.items()}, ANSWER[spec.kind][0]: past}


_last_apex: list = []  # (spec, its apex_bounds): a sweep asks for its columns and bounds several times over


def apex_bounds(spec: SweepSpec) -> dict[str, dict[float, float]]:
    """A gravity sweep's {"apex_bound": {g: m of apex rise over standing}}, the motors' bound for the model's robot,
    when its command asks for a higher rise than that at one of its gravities at least; else {} (nor where the knee's
    motor bounds nothing: its URDF gives no limit). The last spec's is kept: each takes 0.1-0.2 s to integrate."""
    if _last_apex and _last_apex[0][0] is spec:
        return _last_apex[0][1]
    out = _apex_bounds(spec)
    _last_apex[:] = [(spec, out)]
    return out


def _apex_bounds(spec: SweepSpec) -> dict[str, dict[float, float]]:
    from hopper_mjx.hardware import bound

    past = bound.apex_bounds(spec.physics.mj_model, spec.physics.motor, spec.gravity, spec.height)
    return {"apex_bound": past} if past else {}


def apex_lines(spec: SweepSpec, groups: list[dict], bounds: dict) -> list[str]:
    """A gravity sweep asked past the bound: per gravity the highest hop before any fall, the median replicate's
    (`highest_median`) and the best's (`highest_best`), beside the bound's apex rise; then the median tilt its
    landing had (`highest_tilt_median`)."""
    if not bounds:
        return []
    from hopper_mjx.model.robot import standing_height

    standing = standing_height(spec.physics.mj_model)
    out = [f"asked for a {spec.height:g} m rise: the highest hop before any fall (the median replicate's, the "
             f"best's) beside the bound the {spec.physics.motor} motors put on it (docs/sweeps.md; standing height "
             f"{standing:.3g} m):"]
    for r in sorted(groups, key=lambda r: r["gravity"]):
        g, limit, got, best = (r["gravity"], bounds["apex_bound"][r["gravity"]], r.get("highest_median"),
                               r.get("highest_best"))
        reached = "none" if got is None else (f"{got:.2f} m ({got / limit:.0%} of the bound; {got / standing:.2f} "
                                              f"standing heights), the best {best:.2f} m ({best / limit:.0%})")
        tilt = r.get("highest_tilt_median")
        landed = "" if tilt is None else f"; landed {tilt:.1f}° off upright"
        out.append(f"  {PLANETS.get(g, ''):5} g {g:g} m/s²: {reached}; bound {limit:.2f} m{landed}")
    return out


def best_passed(spec: SweepSpec, groups: list[dict]) -> dict[float, float]:
    """{g: the highest block (widest gap) at least half the replicates got past, m; NaN for none of the grid's}."""
    out = {}
    for g in spec.gravity:
        passed = [r[spec.param] for r in groups if r["gravity"] == g and r.get("cleared", 0) >= 0.5]
        out[float(g)] = max(passed) if passed else math.nan
    return out


def lines(spec: SweepSpec, groups: list[dict], bounds: dict) -> list[str]:
    """A block or gaps sweep's answer, per gravity: the highest block (widest gap) at least half the replicates got
    past, in m and in standing heights, beside the bound's (`bound_columns`); then what getting past it asked
    (`past_medians`), where the groups carry it. A gravity sweep's is `apex_lines`."""
    if spec.kind == "gravity":
        return apex_lines(spec, groups, bounds)
    if not bounds:
        return []
    from hopper_mjx.model.robot import standing_height

    m = spec.physics.mj_model
    standing, mass = standing_height(m), float(m.body_mass.sum())
    name, what, _ = ANSWER[spec.kind]
    out = [f"the {what} at least half the replicates {PASSED[spec.kind]}, beside the bound the {spec.physics.motor} "
             f"motors put on it (docs/sweeps.md; standing height {standing:.3g} m):"]
    asked = []
    for g, best in best_passed(spec, groups).items():
        got = f"{best:g} m ({best / standing:.2f} standing heights)" if np.isfinite(best) else "none of the grid's"
        limit = bounds[name][g]
        out.append(f"  {PLANETS.get(g, ''):5} g {g:g} m/s²: {got}; bound {limit:.2f} m ({limit / standing:.2f}), "
                     f"from an apex rise of {bounds['apex_bound'][g]:.2f} m")
        past = _at_answer(spec, groups, g, best)
        if past.get("past_tilt") is not None:
            asked.append(f"  {PLANETS.get(g, ''):5} g {g:g} m/s²: landed tilted {past['past_tilt']:.1f}°, impact "
                         f"{past['past_impact']:.0f} N ({past['past_impact'] / (mass * g):.1f} body weights); "
                         f"knee {past['peak_torque_kfe']:.0f} N·m, {past['peak_power_kfe']:.0f} W, "
                         f"{past['line_use_kfe']:.2f} of its motor's line")
    if asked:
        out += ["what getting past it asked, medians of the replicates that did: the body's tilt and the foot's "
                  "impact at the first landing beyond it, the knee's peak torque, power and share of its line "
                  "over the run:", *asked]
    return out


def _at_answer(spec: SweepSpec, groups: list[dict], g: float, best: float) -> dict:
    """`past_medians` at gravity g's answer (the group of value `best`); {} without one."""
    return next((r.get("past") or {} for r in groups if r["gravity"] == g and r[spec.param] == best), {})


def figure(spec: SweepSpec, groups: list[dict], bounds: dict):
    """limits.png of a block or gaps sweep: the highest block (widest gap) half the replicates got past against
    gravity, beside the motors' bound, in m and in standing heights; and at that answer, what getting past asked
    (`past_medians`): the landing's tilt and impact, the knee's peak power."""
    from hopper_mjx.model.robot import standing_height

    plt = pyplot()
    m = spec.physics.mj_model
    standing, mass = standing_height(m), float(m.body_mass.sum())
    name, answer, what = ANSWER[spec.kind]
    best = best_passed(spec, groups)
    g = np.array(sorted(best))
    fig, axes = plt.subplots(2, 2, figsize=(11.0, 8.0))
    ax = axes[0, 0]
    ax.plot(g, [bounds[name][v] for v in g], "k--", label=f"bound: the {spec.physics.motor} motors' best jump")
    ax.plot(g, [best[v] for v in g], "C0o-", label=f"{PASSED[spec.kind]} by ≥ half the replicates (grid's values)")
    ax.plot(g, np.full(len(g), max(spec.values)), ":", color="0.5", label="the grid's largest value")
    ax.set_ylabel(f"{what} (m)")
    twin = ax.secondary_yaxis("right", functions=(lambda v: v / standing, lambda h: h * standing))
    twin.set_ylabel("in standing heights (1)")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(f"the {answer} vs gravity", fontsize=9)
    past = [_at_answer(spec, groups, v, best[v]) for v in g]
    value = lambda key, scale=lambda v, x: x: np.array([np.nan if p.get(key) is None else scale(v, p[key])
                                                        for v, p in zip(g, past)])
    axes[0, 1].plot(g, value("past_tilt"), "C1o-", label="the body's tilt at the landing beyond it")
    axes[0, 1].axhline(9.7, color="0.5", ls=":", label="SpaceHopper on hardware, 9.7°")
    axes[0, 1].set_ylabel("landing tilt (°)")
    axes[1, 0].plot(g, value("past_impact"), "C3o-", label="the foot's peak force, that landing's first 50 ms")
    axes[1, 0].plot(g, mass * g, ":", color="0.5", label="the robot's weight")
    axes[1, 0].set_ylabel("impact (N)")
    axes[1, 0].set_yscale("log")
    axes[1, 1].plot(g, value("peak_power_kfe"), "C2o-", label="the knee's peak power, driving or braking")
    axes[1, 1].set_ylabel("knee power (W)")
    axes[1, 1].set_ylim(bottom=0.0)
    for panel in (axes[0, 1], axes[1, 0], axes[1, 1]):
        panel.set_title(f"getting past the {answer}: medians of the replicates that did", fontsize=9)
        panel.legend(fontsize=8)
    for panel in axes.flat:
        panel.set_xscale("log")
        panel.minorticks_off()
        panel.set_xticks(g, [f"{v:g}" for v in g])
        panel.set_xlabel("gravity (m/s²)")
        panel.grid(alpha=0.3)
    fig.suptitle(f"{spec.controller}, {counted(spec.num, 'replicate')} per point\n{physics_label(spec)}", fontsize=9)
    fig.tight_layout()
    return fig


def comparison_lines(spec: SweepSpec, results: list[tuple[str, list[dict]]], bounds: dict) -> list[str]:
    """Several controllers' block or gaps sweeps on the same grid: each gravity's highest block (widest gap) at least
    half the replicates got past, controller by controller, beside the motors' bound."""
    name, what, _ = ANSWER[spec.kind]
    best = {label: best_passed(spec, groups) for label, groups in results}
    out = [f"the {what} at least half the replicates {PASSED[spec.kind]}, by controller, beside the bound the "
           f"{spec.physics.motor} motors put on it (docs/sweeps.md):"]
    for g in sorted(spec.gravity):
        got = ", ".join(f"{label} {best[label][g]:g} m" if np.isfinite(best[label][g]) else f"{label} none"
                        for label, _ in results)
        bound = f"; bound {bounds[name][g]:.2f} m" if bounds else ""
        out.append(f"  {PLANETS.get(g, ''):5} g {g:g} m/s²: {got}{bound}")
    return out


def comparison_figure(spec: SweepSpec, results: list[tuple[str, list[dict]]]):
    """OUT/obstacle.png (gaps.png) of several controllers' block or gaps sweeps: a panel per gravity, the share of
    replicates that got past the band (solid; a cross where none reached it) and the share up at the end (dashed)
    against its size, a colour per controller; the dotted line is the answer's half of the replicates."""
    plt = pyplot()
    _, answer, what = ANSWER[spec.kind]
    gravity = sorted(spec.gravity)
    fig, axes = plt.subplots(1, len(gravity), figsize=(1.0 + 4.0 * len(gravity), 4.4), sharey=True, squeeze=False,
                             constrained_layout=True)
    for ax, g in zip(axes[0], gravity):
        for k, (label, groups) in enumerate(results):
            rows = sorted((r for r in groups if r["gravity"] == g), key=lambda r: r[spec.param])
            size = np.array([r[spec.param] for r in rows])
            unreached = np.array([r.get("reached") == 0 for r in rows], bool)  # its 0 % past measures nothing
            past = np.array([100.0 * r["cleared"] for r in rows])
            ax.plot(size, np.where(unreached, np.nan, past), "o-", color=f"C{k}",
                    label=f"{label}: {PASSED[spec.kind]} the {BAND_KINDS[spec.kind]}")
            if unreached.any():
                ax.plot(size[unreached], past[unreached], "x", color=f"C{k}", ms=8,
                        label=f"{label}: no replicate reached the {BAND_KINDS[spec.kind]}")
            ax.plot(size, [100.0 * r["survival"] for r in rows], "s--", color=f"C{k}", alpha=0.6, ms=4,
                    label=f"{label}: up at the end")
        ax.axhline(50.0, color="0.5", ls=":", lw=1.0)
        ax.set_title(f"{PLANETS.get(g, '')} g = {g:g} m/s²".strip(), fontsize=10)
        ax.set_xlabel(f"{what} (m)")
        ax.set_ylim(-3.0, 103.0)
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("% of replicates")
    seen = {}  # every panel's lines, each label once: a cross may be in one panel only
    for ax in axes[0]:
        seen.update({label: handle for handle, label in zip(*ax.get_legend_handles_labels()) if label not in seen})
    axes[0, -1].legend(seen.values(), seen.keys(), fontsize=7, loc="best")
    fig.suptitle(f"the {answer} by controller: {spec.kind} sweep, {counted(spec.num, 'replicate')} per point, "
                 f"{spec.duration:g} s each\n{physics_label(spec)}", fontsize=10)
    return fig
