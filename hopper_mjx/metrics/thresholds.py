"""Each task's threshold and how checkpoints are ranked on its measures: one definition, used by the
checkpoint scan of experiments/train.py (time to threshold, the policy it keeps) and by the results table.

A *row* is one evaluation gravity's measures of a controller, as `experiments/train.py`'s `evaluate`
returns them: `survival` (fraction of instances up at the end), `min_hops`, `apex_height` (m of rise,
mean over survivors, None if none hopped) and `tracking_error` (m/s, mean over survivors).
"""

from __future__ import annotations

import math

MIN_HOPS = 5  # hops in the evaluation that count as hopping
APEX_TOLERANCE = 0.15  # the hopping tasks: apex rise within this fraction of the command
SPEED_TOLERANCE = 0.1  # m/s, every task: mean horizontal speed error (drift when hopping in place or standing)
# m, stand: the highest apex rise that is still standing (small hops allowed; the stand reward's band ends here).
STAND_MAX_RISE = 0.10


def describe(task: str) -> str:
    """The task's threshold in words (what it asks of every evaluation gravity)."""
    if task == "stand":
        return (f"every instance survives, drifting <= {SPEED_TOLERANCE} m/s (the mean speed over the last 5 s: a "
                f"bounded region) with any hops rising <= {STAND_MAX_RISE} m")
    speed = "mean speed error" if task in ("hop_velocity", "hop_terrain") else "mean drift"
    return (f"every instance survives with >= {MIN_HOPS} hops, apex rise within {APEX_TOLERANCE:.0%} of the "
            f"command and {speed} <= {SPEED_TOLERANCE} m/s")


def apex_error(row: dict, height: float) -> float:
    """Relative apex error |rise / command - 1| (inf when nothing hopped)."""
    return math.inf if row.get("apex_height") is None else abs(row["apex_height"] / height - 1)


def speed_error(row: dict) -> float:
    """Mean speed error, m/s (inf when nothing survived)."""
    return math.inf if row.get("tracking_error") is None else row["tracking_error"]


def stand_rise(row: dict) -> float:
    """The apex rise of stand's hops, m (0 when it never left the floor)."""
    return row.get("apex_height") or 0.0


def meets(task: str, row: dict, height: float) -> bool:
    """Does one gravity's row meet the task's threshold for a commanded rise `height` (stand: none)?"""
    alive = row["survival"] == 1
    if not alive:
        return False
    if task == "stand":  # up, in place, and hopping (if at all) low: standing, not touring
        return speed_error(row) <= SPEED_TOLERANCE and stand_rise(row) <= STAND_MAX_RISE
    if row["min_hops"] < MIN_HOPS:
        return False
    # Hops that miss the apex (buzzing on a stiff leg counts lift-offs too) or drift away are not the task.
    return apex_error(row, height) <= APEX_TOLERANCE and speed_error(row) <= SPEED_TOLERANCE


def shortfall(task: str, row: dict, height: float) -> float:
    """How far one gravity's row is from the threshold's error bounds, in units of each bound (<= 1: within
    both); for `stand`, its drift and its hops' rise over their bounds."""
    if task == "stand":
        return max(speed_error(row) / SPEED_TOLERANCE, stand_rise(row) / STAND_MAX_RISE)
    return max(apex_error(row, height) / APEX_TOLERANCE, speed_error(row) / SPEED_TOLERANCE)


def rank(task: str, rows: dict, height: float) -> tuple:
    """A key to maximise over checkpoints (`rows`: gravity -> row): first the gravities at the threshold,
    then the worst gravity's survival, then the worst gravity's `shortfall` (smaller is better)."""
    values = list(rows.values())
    return (sum(meets(task, r, height) for r in values), min(r["survival"] for r in values),
            -max(shortfall(task, r, height) for r in values))


def best(task: str, scanned: list[dict], height: float) -> dict | None:
    """The scanned checkpoint ({"step", "evaluation": rows, ...}) with the highest `rank`; the earliest among
    equals. None if nothing was scanned."""
    if not scanned:
        return None
    return max(scanned, key=lambda s: (rank(task, s["evaluation"], height), -s["step"]))
