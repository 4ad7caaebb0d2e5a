"""Every plot kind reads alone (issue #55): each Axes that draws data names both its axes with a unit in
parentheses, the convention every plot here follows ("gravity g (m/s²)", "survival (% of replicates)"), each image
has a labelled colour bar, and a plot of a physics run names its physics. The figures are built in-process from
small synthetic inputs: nothing is simulated or compiled."""

import json

import numpy as np
import pytest

from hopper_mjx.scenario import Physics

# A label's unit: one comma-separated part of a parenthesised group ("x (m), the start at 0", "duty factor
# (stance / period, 1)"); "1" for a pure number, "% of ..." for a share.
UNITS = {"m", "s", "m/s", "m/s²", "rad/s", "N", "J/kg", "1", "min", "°", "W", "steps/s", "instances", "policy steps"}
CHANGED = Physics(motor="dc", action_delay=0.004, push=(2.0, 0.3))  # what a run's subtitle must then say
CHANGED_WORDS = ("dc motors", "action delay 4 ms", "pushes of 0.3 m/s every 2 s")


def _groups(label: str) -> list[str]:
    """The top-level parenthesised groups of `label`, nested ones kept inside their group."""
    found, depth = [], 0
    for ch in label:
        if ch == ")":
            depth -= 1
        if depth:
            found[-1] += ch
        if ch == "(":
            depth += 1
            found += [""] if depth == 1 else []
    return found


def _has_unit(label: str) -> bool:
    parts = [p.strip() for group in _groups(label) for p in group.split(",")]
    return any(p in UNITS or p == "%" or p.startswith("% ") for p in parts)


def _axis_label(ax, which: str) -> str:
    """The label of `ax`'s x or y axis: its own, or that of the axes heading its column (x) or row (y) in the same
    grid, as shared axes show it once."""
    own = getattr(ax, f"get_{which}label")()
    spec = ax.get_subplotspec()
    if own or spec is None:
        return own
    for other in ax.figure.axes:
        place = other.get_subplotspec()
        if place is None or place.get_gridspec() is not spec.get_gridspec():
            continue
        if (place.rowspan == spec.rowspan) if which == "y" else (place.colspan == spec.colspan):
            if getattr(other, f"get_{which}label")():
                return getattr(other, f"get_{which}label")()
    return ""


def assert_reads_alone(fig) -> None:
    bars = {}
    for ax in fig.axes:
        for image in ax.images + ax.collections:
            if getattr(image, "colorbar", None) is not None:
                bars[image.colorbar.ax] = image.colorbar
    for ax in fig.axes:
        for image in ax.images:
            assert image.colorbar is not None, f"an image without a colour bar in {ax.get_title()!r}"
        if ax in bars:
            label = bars[ax].ax.get_ylabel() or bars[ax].ax.get_xlabel()
            assert _has_unit(label), f"colour bar label {label!r}"
            continue
        if not (ax.lines or ax.images or ax.collections):
            continue
        for which in "xy":
            label = _axis_label(ax, which)
            assert _has_unit(label), f"{which} label {label!r} of {ax.get_title()!r} names no unit in parentheses"


def _titles(fig) -> str:
    return " ".join([fig._suptitle.get_text() if fig._suptitle else ""] + [ax.get_title() for ax in fig.axes])


def test_the_unit_rule_itself():
    assert _has_unit("cost of transport (work / (m·g·distance), 1)") and _has_unit("survival (% of replicates)")
    assert _has_unit("x (m), the start at 0") and _has_unit("environment steps (policy steps, 50 Hz)")
    assert not _has_unit("odometry position (world)") and not _has_unit("steps/s") and not _has_unit("")


def _spec(**kw):
    from hopper_mjx.sweep.grid import SweepSpec

    return SweepSpec(**{"kind": "gravity", "gravity": (9.81, 1.62), "num": 4, "duration": 5.0, "height": 0.1,
                        "speed": (0.0, 0.0), "seed": 0, **kw})


def test_sweep_plots():
    from hopper_mjx import terrain
    from hopper_mjx.sweep import limits, report

    rows = [{"gravity": g, "survival": 1.0, "apex_height": 0.1, "apex_height_std": 0.01, "flight_time": 0.3,
             "hop_period": 0.5, "duty_factor": 0.4, "energy_per_hop": 0.4 * g, "ballistic_flight_time": 0.3}
            for g in (9.81, 1.62)]
    assert_reads_alone(report.gravity_figure(_spec(physics=CHANGED), rows))
    gains = _spec(kind="param", param="speed_gain", values=(0.1, 0.6))
    assert_reads_alone(report.gains_figure(gains, [dict(r, speed_gain=v, tracking_error=0.02) for r in rows
                                                   for v in gains.values]))
    grounds = tuple(str(terrain.parse(f"obstacle:height={h},x=0.6,size=2x1")) for h in (0.05, 0.2))
    obstacle = _spec(kind="obstacle", param="obstacle_height", values=(0.05, 0.2), speed=(0.3, 0.0),
                     grounds=grounds, physics=Physics(ground=terrain.parse(grounds[0])))
    assert_reads_alone(report.terrain_figure(obstacle, [dict(r, obstacle_height=v, cleared=0.5, reached=1.0,
                                                             distance_made_good=0.9, mean_speed=0.2)
                                                        for r in rows for v in obstacle.values]))
    passed = [dict(r, obstacle_height=v, cleared=0.5) for r in rows for v in obstacle.values]
    fig = limits.figure(obstacle, passed, limits.bound_columns(obstacle))
    assert_reads_alone(fig)
    assert "the URDF's robot" in _titles(fig)  # the physics subtitle


def test_signal_plot_of_a_bag():
    from hopper_mjx.ros import plots

    t = np.linspace(0.0, 1.0, 51)
    xyz = np.stack([np.sin(t), np.cos(t), t], axis=1)
    signals = {"imu_t": t, "gyro": xyz, "accel": xyz, "odom_t": t, "pos": xyz, "linvel": xyz, "contact_t": t,
               "contact": (t > 0.5).astype(float), "force": xyz}
    fig = plots.figure([("Earth 9.81 m/s²", signals), ("Moon 1.62 m/s²", signals)])
    assert_reads_alone(fig)
    assert "grey: foot in contact" in [text.get_text() for text in fig.texts]  # the shading named


def test_scaling_plot_names_its_physics():
    from hopper_mjx.perf import bench

    records = [{"engine": engine, "num": n, "core_steps_per_s": 1e5 * k, "native_steps_per_s": 2e5,
                "ratio": 0.5 * k, "devices": 2, "native_threads": 2, "steps": 200, "controller": "hold",
                "terrain": "rough:amp=0.02,seed=1", "randomize": "foot_friction=0.4..1", "timestep": 5e-4,
                "core_runs_s": [1.0, 1.1]}
               for k, engine in enumerate(("chain", "mjx"), 1) for n in (64, 256)]
    fig = bench.scaling_figure(records)
    assert_reads_alone(fig)
    for part in ("best of 2 timed runs", "terrain rough:amp=0.02", "randomised foot_friction", "timestep 0.5 ms"):
        assert part in _titles(fig), part


def test_training_curves_name_their_physics_and_band():
    import results

    from training import loop

    history = [{"step": s, "wall_time": s / 1e4, "eval/episode_reward": s / 1e3, "eval/episode_reward_std": 5.0}
               for s in (0, 100_000, 200_000)]
    fig = loop.reward_figure(history, "PPO on hop", CHANGED, 25.0, 64)
    assert_reads_alone(fig)
    assert fig.axes[0].get_xlabel() == "environment steps (policy steps, 25 Hz)"
    assert "± 1 standard deviation over them" in fig.axes[0].get_legend_handles_labels()[1]
    assert all(part in _titles(fig) for part in CHANGED_WORDS)
    # The seeds' plot: the physics every run shared in the subtitle, a run's own beside its name.
    args = {"task": "hop", "motor": "dc", "action_delay": 4.0, "push": [2.0, 0.3]}
    records = [{"task": task, "algo": "ppo", "curve": [(0.5, 10.0), (1.0, 20.0)],
                "physics": list(results.physics_of({**args, "terrain": terrain}).described().values())}
               for task, terrain in (("hop", None), ("hop_terrain", "rough:amp=0.02,seed=1"))]
    fig = results.figure(records)
    assert_reads_alone(fig)
    assert all(part in fig.axes[0].get_title() for part in CHANGED_WORDS)
    assert [label.split(",")[0] for label in fig.axes[0].get_legend_handles_labels()[1]] == [
        "hop × PPO; flat ground", "hop_terrain × PPO; terrain rough:amp=0.02"]


def test_the_seeds_plot_keeps_long_row_names_below_its_axes_on_lines_of_their_own():
    """Rows named by many settings (a SAC row started from another run) get a legend of short lines below the
    axes: it covers no curve and leaves the axes their width."""
    import results

    args = {"task": "hop", "algo": "sac", "start_from": "runs/ppo-hop", "sac_hold_policy": 250_000,
            "sac_target_entropy": -10.0, "sac_grad_updates": 32, "batch_size": 256}
    records = [{"task": "hop", "algo": "sac", "curve": [(0.5, 10.0), (1.0, 20.0)], "training": "1 ms step",
                "learner": {k: args.get(k) for k in results.LEARNER} | {"sac_hold_policy": hold},
                "physics": list(results.physics_of(args).described().values())} for hold in (250_000, None)]
    fig = results.figure(records)
    fig.canvas.draw()
    ax, legend = fig.axes[0], fig.axes[0].get_legend()
    labels = [t.get_text() for t in legend.get_texts()]
    assert len(labels) == 2 and all(len(line) <= 100 for label in labels for line in label.splitlines())
    assert any("\n" in label for label in labels)
    assert legend.get_window_extent().y1 <= ax.get_window_extent().y0
    assert ax.get_window_extent().width >= 0.7 * fig.bbox.width


def test_the_seeds_plot_draws_a_course_runs_curve_once_for_all_its_grounds():
    """A course's run is a table row per ground it is judged on (rough ground, a block ahead), but it trained once:
    the plot draws each run's curve once, named without the ground, and another run beside it as its own line."""
    import results

    from hopper_mjx.envs.curriculum import JUDGE_GROUNDS

    args = {"task": "hop_terrain", "terrain": "course:seed=1"}
    physics = list(results.physics_of(args).described().values())
    records = [{"run": f"runs/{name}", "task": "hop_terrain", "algo": "ppo", "ground": ground, "config": config,
                "curve": [(0.5, 10.0 + shift), (1.0, 20.0 + shift)], "physics": physics}
               for name, config, shift in (("scan", [], 0.0), ("blind", ["observe_scan=false"], 5.0))
               for ground in JUDGE_GROUNDS]
    assert len(results.rows_of(records)) == 4  # the table: a row per run and ground
    fig = results.figure(records)
    assert_reads_alone(fig)
    lines = fig.axes[0].get_lines()
    assert sorted([float(y) for y in line.get_ydata()] for line in lines) == [[10.0, 20.0], [15.0, 25.0]]
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert len(labels) == 2 and not any("judged on" in label for label in labels)
    assert any("observe_scan=false" in label for label in labels)


def test_leg_energy_plot_says_what_its_sweeps_ran():
    import leg_energy

    from hopper_mjx import terrain

    spec = _spec(kind="param", param="shank_length", values=(0.3, 0.35), gravity=(9.81, 3.71, 1.62),
                 physics=Physics(ground=terrain.parse("rough:amp=0.02,seed=1")))
    arguments = json.loads(json.dumps(spec.to_json()))  # as summary.json holds them
    assert Physics.from_json(arguments) == spec.physics

    def cells(param):
        return [{param: v, "gravity": g, "survival": 1.0, "apex_height": 0.1, "energy_per_hop": v * g}
                for v in (0.3, 0.35) for g in (9.81, 3.71, 1.62)]

    fig = leg_energy.figure(cells("shank_length"), cells("thigh_length"), arguments)
    assert_reads_alone(fig)
    assert "terrain rough:amp=0.02" in _titles(fig) and "100 % up, apex rise 0.100 m" in _titles(fig)
    with pytest.raises(ValueError, match="other settings than the first sweep \\(duration\\)"):
        leg_energy.same_settings(arguments, dict(arguments, duration=20.0, values=[0.4]), "thighs")
