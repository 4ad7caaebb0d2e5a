"""Hop metrics of a batch, computed with array operations from a recorded `Trajectory`.

Events come from the contact stream: a *lift-off* is the first sample without
foot contact after one with it, a *touchdown* the reverse. A *hop* is one
complete flight (its lift-off and touchdown both recorded) together with the
stance before it, when that stance began inside the record. Per-hop values:

- apex rise: highest base height in the flight minus the standing height (m);
- flight rise: the same apex minus the base height at lift-off (m), the height of
  the ballistic arc; `ballistic_flight_time` is 2·√(2·flight_rise/g) of each hop
  (averaged like the rest), the flight time a point mass would need for that arc;
- flight time (lift-off -> touchdown), stance time (touchdown -> lift-off),
  hop period (touchdown -> touchdown) in s, and duty factor = stance / period.

A *fall* is the first sample where the base is below `FALL_HEIGHT` or |roll| or
|pitch| exceeds `FALL_TILT`. Everything after a fall is ignored: per-hop means
are over the last `last_hops` hops before it, the speed window ends at it.

Undefined values are NaN: an instance that never completes a hop has NaN apex
and timing metrics (and hops = 0); a cost of transport needs the motors' work
and a displacement of at least `MIN_TRANSPORT`.

Gravity enters through its downward part g = -g_z (the floor is level: a
sideways part pushes the robot along but does not change its hops). With g = 0
(the seed's zero-gravity world) the robot floats: `floating` is True, and the
values defined through g (ballistic flight time, cost of transport) are NaN
rather than a division by zero.

Energy, from the motors' work W (J, e.g. the Raibert controller's ∫Σ|τ·q̇|dt over
the whole record): `mechanical_power` = W / (mass · record length) in W/kg, and
`energy_per_hop` = that power times the mean hop period, in J/kg. Both are
meaningful when the robot hops in place, where the cost of transport is not.
"""

from __future__ import annotations

import numpy as np

FALL_HEIGHT = 0.4  # m: the base centre this low means the leg folded or the robot lies on the floor
# (the deepest upright crouch, knee at its -1.6 rad limit, keeps the base above 0.7 m)
FALL_TILT = 0.8  # rad of |roll| or |pitch|: far past any recoverable hopping attitude
MIN_TRANSPORT = 0.05  # m of net horizontal travel below which the cost of transport is NaN


def standing_height(mj_model) -> float:
    """Base height (m) of a model standing still in the core's default stance, foot on the floor."""
    from hopper_mjx.sim import stance_qpos

    return float(stance_qpos(mj_model, clearance=0.0)[2])


def tilt(quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(roll, pitch) in rad of [w, x, y, z] quaternions (..., 4), ZYX Euler angles."""
    w, x, y, z = np.moveaxis(np.asarray(quat, dtype=float), -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    return roll, pitch


def _events(flag: np.ndarray, rising: bool) -> np.ndarray:
    """(N, T) bool, True at the first sample after each contact change of that kind."""
    before, after = flag[:, :-1], flag[:, 1:]
    change = (~before & after) if rising else (before & ~after)
    return np.concatenate([np.zeros((flag.shape[0], 1), bool), change], axis=1)


def _padded_times(events: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, H) event times in order, NaN-padded."""
    n, count = events.shape[0], events.sum(axis=1)
    width = max(int(count.max(initial=0)), 1)
    order = np.sort(np.where(events, np.arange(events.shape[1]), events.shape[1]), axis=1)[:, :width]
    times = np.append(t, np.nan)[order]
    return np.where(np.arange(width) < count[:, None], times, np.nan).reshape(n, width)


def _nearest_after(after: np.ndarray, times: np.ndarray, first: bool) -> np.ndarray:
    """For each `times[i, j]`, the first (or last, `first=False`) `after[i, k]` > (<) it; NaN if none."""
    a, b = after[:, None, :], times[:, :, None]
    with np.errstate(invalid="ignore"):
        if first:
            out = np.where(a > b, a, np.inf).min(axis=2)
        else:
            out = np.where(a < b, a, -np.inf).max(axis=2)
    return np.where(np.isfinite(out), out, np.nan)


def _last_mean(values: np.ndarray, keep: np.ndarray, last: int) -> np.ndarray:
    """Mean of the last `last` kept entries of each row (NaN if none)."""
    rank_from_end = np.cumsum(keep[:, ::-1], axis=1)[:, ::-1]
    use = keep & (rank_from_end <= last)
    total = np.where(use, values, 0.0).sum(axis=1)
    count = use.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def hop_metrics(
    traj,
    gravity,
    *,
    command_speed=(0.0, 0.0),
    standing_height: float,
    work=None,
    mass: float | None = None,
    last_hops: int = 5,
    speed_window: float = 5.0,
) -> dict[str, np.ndarray]:
    """Per-instance hop metrics, each an (N,) array (see the module docstring).

    traj: a `hopper_mjx.sim.Trajectory` (uses its state and contact streams);
    gravity: (N, 3) vectors or (N,) magnitudes, m/s²; command_speed: (2,) or (N, 2) m/s;
    standing_height: m (`standing_height(mj_model)`); work: (N,) J the motors did
    (e.g. the Raibert controller state's `work`) and mass: kg, for the cost of transport;
    last_hops: hops averaged; speed_window: s of speed averaging before the end or fall.
    """
    qpos = np.asarray(traj.qpos, dtype=float)
    flag = np.asarray(traj.contact.flag, dtype=bool)
    t_state = np.asarray(traj.time["state"], dtype=float)
    t_contact = np.asarray(traj.time["contact"], dtype=float)
    n = qpos.shape[0]
    g = np.asarray(gravity, dtype=float)
    g = -g[:, 2] if g.ndim == 2 and g.shape[1:] == (3,) else g.reshape(-1)  # downward part, m/s²
    if g.shape != (n,):
        raise ValueError(f"gravity must be (N, 3) or (N,) with N={n}, got {np.shape(gravity)}")
    floating = ~(g > 0)
    g_or_nan = np.where(floating, np.nan, g)  # nothing that divides by g is defined while floating
    command = np.broadcast_to(np.asarray(command_speed, dtype=float), (n, 2))
    if last_hops < 1 or speed_window <= 0:
        raise ValueError("last_hops must be >= 1 and speed_window > 0")

    # -- falls -----------------------------------------------------------------
    z = qpos[:, :, 2]
    roll, pitch = tilt(qpos[:, :, 3:7])
    down = (z < FALL_HEIGHT) | (np.abs(roll) > FALL_TILT) | (np.abs(pitch) > FALL_TILT)
    fell = down.any(axis=1)
    fall_index = np.where(fell, down.argmax(axis=1), len(t_state) - 1)
    t_fall = np.where(fell, t_state[fall_index], np.inf)
    upright = np.arange(len(t_state)) <= fall_index[:, None]

    # -- hops ------------------------------------------------------------------
    liftoff = _padded_times(_events(flag, rising=False), t_contact)  # (N, H)
    touchdowns = _padded_times(_events(flag, rising=True), t_contact)
    landing = _nearest_after(touchdowns, liftoff, first=True)  # touchdown ending each flight
    stance_start = _nearest_after(touchdowns, liftoff, first=False)  # touchdown before each lift-off
    complete = np.isfinite(landing) & np.isfinite(stance_start) & (landing < t_fall[:, None])
    flight_time = landing - liftoff
    stance_time = liftoff - stance_start
    period = landing - stance_start

    # Apex of each flight: the highest state sample while the contact stream says
    # airborne, labelled by how many lift-offs came before it.
    at = np.clip(np.searchsorted(t_contact, t_state, side="right") - 1, 0, len(t_contact) - 1)
    flight_id = np.cumsum(_events(flag, rising=False), axis=1)[:, at] - 1
    airborne = ~flag[:, at] & (flight_id >= 0)
    width = liftoff.shape[1]
    slot = np.where(airborne, np.arange(n)[:, None] * width + flight_id, n * width)
    apex = np.full(n * width + 1, -np.inf)
    np.maximum.at(apex, slot.ravel(), z.ravel())
    apex = apex[:-1].reshape(n, width)
    rise = np.where(np.isfinite(apex), apex - standing_height, np.nan)
    # Lift-off height, interpolated: the base moves fast there and the state stream may be coarse.
    z_liftoff = np.stack([np.interp(liftoff[i], t_state, z[i]) for i in range(n)])
    arc = np.where(np.isfinite(apex), apex - z_liftoff, np.nan)

    mean = lambda v: _last_mean(v, complete, last_hops)
    hops = complete.sum(axis=1)

    # -- speed over the last window before the end (or the fall) --------------
    end = fall_index
    start = np.searchsorted(t_state, t_state[end] - speed_window)
    span = t_state[end] - t_state[start]
    rows = np.arange(n)
    with np.errstate(invalid="ignore", divide="ignore"):
        velocity = (qpos[rows, end, :2] - qpos[rows, start, :2]) / np.where(span > 0, span, np.nan)[:, None]

    # -- energy and cost of transport -------------------------------------------
    travel = np.linalg.norm(qpos[rows, end, :2] - qpos[:, 0, :2], axis=1)
    if work is None:
        cost = power = np.full(n, np.nan)
    else:
        if mass is None or not mass > 0:
            raise ValueError("the cost of transport needs the robot's mass (kg) along with the work")
        work = np.asarray(work, float)
        record_length = t_state[-1] - t_state[0]
        power = work / (mass * record_length) if record_length > 0 else np.full(n, np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            cost = np.where(travel >= MIN_TRANSPORT, work / (mass * g_or_nan * travel), np.nan)
    hop_period = mean(period)

    return {
        "hops": hops,
        "apex_height": mean(rise),
        "flight_rise": mean(arc),
        "ballistic_flight_time": mean(2 * np.sqrt(np.maximum(arc, 0.0) * 2 / g_or_nan[:, None])),
        "flight_time": mean(flight_time),
        "stance_time": mean(stance_time),
        "hop_period": hop_period,
        "duty_factor": mean(stance_time / period),
        "mean_speed": velocity[:, 0],
        "mean_speed_y": velocity[:, 1],
        "tracking_error": np.linalg.norm(velocity - command, axis=1),
        "max_roll": np.where(upright, np.abs(roll), 0.0).max(axis=1),
        "max_pitch": np.where(upright, np.abs(pitch), 0.0).max(axis=1),
        "fell": fell,
        "fall_time": np.where(fell, t_fall, np.nan),
        "hops_before_fall": hops,
        "cost_of_transport": cost,
        "mechanical_power": power,
        "energy_per_hop": power * hop_period,
        "floating": floating,
    }
