"""Hop metrics of a batch, computed with array operations from a recorded `Trajectory`.

Events come from the contact stream: a *lift-off* is the first sample without
foot contact after one with it, a *touchdown* the reverse. A *hop* is one
complete flight (its lift-off and touchdown both recorded) together with the
stance before it, when that stance began inside the record. Per-hop values:

- apex rise: highest base height in the flight minus the standing height (m); `highest_apex` is the
  highest of all hops before the fall, the rest are means over the last hops; `highest_landing_tilt` is the
  body's tilt from upright (deg) at the landing of that highest hop: how well the longest flight was held level;
- flight rise: the same apex minus the base height at lift-off (m), the height of
  the ballistic arc; `ballistic_flight_time` is 2·√(2·flight_rise/g) of each hop
  (averaged like the rest), the flight time a point mass would need for that arc;
- flight time (lift-off -> touchdown), stance time (touchdown -> lift-off),
  hop period (touchdown -> touchdown) in s, and duty factor = stance / period.

A *fall* is the first sample where the base is below `FALL_HEIGHT` or |roll| or
|pitch| exceeds `FALL_ROLL_PITCH`. Everything after a fall is ignored: per-hop means
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

from typing import NamedTuple

import numpy as np

FALL_HEIGHT = 0.4  # m: the base centre this low means the leg folded or the robot lies on the floor
# (the deepest upright crouch, knee at its -1.6 rad limit, keeps the base above 0.7 m)
FALL_ROLL_PITCH = 0.8  # rad of |roll| or |pitch| (each): far past any recoverable hopping attitude
MIN_TRANSPORT = 0.05  # m of net horizontal travel below which the cost of transport is NaN


def roll_pitch(quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(roll, pitch) in rad of [w, x, y, z] quaternions (..., 4), ZYX Euler angles."""
    w, x, y, z = np.moveaxis(np.asarray(quat, dtype=float), -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    return roll, pitch


def fallen(qpos: np.ndarray) -> np.ndarray:
    """(...) bool: the base of these (..., nq) states is down (the fall test of `hop_metrics`)."""
    roll, pitch = roll_pitch(qpos[..., 3:7])
    return _down(qpos[..., 2], roll, pitch)


def _down(z, roll, pitch) -> np.ndarray:
    return (z < FALL_HEIGHT) | (np.abs(roll) > FALL_ROLL_PITCH) | (np.abs(pitch) > FALL_ROLL_PITCH)


def landings(flag: np.ndarray, airborne: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(landings (N,), airborne (N,)) of a (N, T) contact record: touchdowns that end a flight seen
    to start (a lift-off), for counting hops chunk by chunk. `airborne` carries a flight in progress
    from the record before, whose last sample is `flag`'s first column."""
    lift, land = _events(flag, rising=False), _events(flag, rising=True)
    count = np.zeros(flag.shape[0], dtype=int)
    for k in range(1, flag.shape[1]):
        count += land[:, k] & airborne
        airborne = (airborne | lift[:, k]) & ~land[:, k]
    return count, airborne


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


def _highest(values: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The largest kept entry of each row (NaN if none)."""
    out = np.where(keep, values, -np.inf).max(axis=1)
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
    standing_height,
    work=None,
    mass=None,
    last_hops: int = 5,
    speed_window: float = 5.0,
) -> dict[str, np.ndarray]:
    """Per-instance hop metrics, each an (N,) array (see the module docstring).

    traj: a `hopper_mjx.sim.Trajectory` (uses its state and contact streams);
    gravity: (N, 3) vectors or (N,) magnitudes, m/s²; command_speed: (2,) or (N, 2) m/s;
    standing_height: m (`Robot.standing_height`), or (N,) each instance's own; work: (N,) J the motors did
    (e.g. the Raibert controller state's `work`) and mass: kg (or (N,) kg, each instance's robot), for
    the cost of transport;
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
    g = np.where(floating, np.nan, g)  # nothing that divides by g is defined while floating
    command = np.broadcast_to(np.asarray(command_speed, dtype=float), (n, 2))
    if last_hops < 1 or speed_window <= 0:
        raise ValueError("last_hops must be >= 1 and speed_window > 0")

    fall = _falls(qpos, t_state)
    hops = _hops(flag, t_contact, fall.t_fall)
    rise, arc = _apexes(qpos[:, :, 2], flag, t_state, t_contact, hops.liftoff, standing_height)
    mean = lambda v: _last_mean(v, hops.complete, last_hops)
    velocity = _mean_velocity(qpos, t_state, fall.index, speed_window)
    power = _mechanical_power(n, t_state, work, mass)
    return {
        "hops": hops.complete.sum(axis=1),
        "apex_height": mean(rise),
        "highest_apex": _highest(rise, hops.complete),
        "highest_landing_tilt": _highest_landing_tilt(qpos, t_state, hops, rise),
        "flight_rise": mean(arc),
        "ballistic_flight_time": mean(2 * np.sqrt(np.maximum(arc, 0.0) * 2 / g[:, None])),
        "flight_time": mean(hops.flight_time),
        "stance_time": mean(hops.stance_time),
        "hop_period": mean(hops.period),
        "duty_factor": mean(hops.stance_time / hops.period),
        "mean_speed": velocity[:, 0],
        "mean_speed_y": velocity[:, 1],
        "tracking_error": np.linalg.norm(velocity - command, axis=1),
        "max_roll": np.where(fall.upright, np.abs(fall.roll), 0.0).max(axis=1),
        "max_pitch": np.where(fall.upright, np.abs(fall.pitch), 0.0).max(axis=1),
        "fell": fall.fell,
        "fall_time": np.where(fall.fell, fall.t_fall, np.nan),
        "cost_of_transport": _cost_of_transport(qpos, fall.index, g, work, mass),
        "mechanical_power": power,
        "energy_per_hop": power * mean(hops.period),
        "floating": floating,
    }


def terrain_metrics(traj, *, command_speed=(0.0, 0.0), obstacles=None) -> dict[str, np.ndarray]:
    """Per-instance metrics of a run over ground, each (N,) (the fall test is `hop_metrics`'):

    - distance_made_good: m, the base's net horizontal travel from the start to the end of the record (or its
      fall), along the commanded direction when a speed is commanded, else in whichever direction;
    - obstacles_cleared: how many of `obstacles` the foot touched down beyond (their far end) before any fall
      (not the base: a robot that trips on a block and topples forward carries its base past the block before
      the fall test sees it down);
    - highest_cleared: m, the highest of those (NaN when none; a trench counts as its negative depth);
    - fall_x, fall_y: m, where the base was at its fall (NaN without one).

    obstacles: (B, 3) or (N, B, 3) rows (x start, x end, height) m of bands across the ground along +x
    (`terrain.Ground.obstacles`), NaN rows ignored; None: no obstacles.
    """
    qpos = np.asarray(traj.qpos, dtype=float)
    t_state = np.asarray(traj.time["state"], dtype=float)
    n = qpos.shape[0]
    fall = _falls(qpos, t_state)
    rows = np.arange(n)
    travel = qpos[rows, fall.index, :2] - qpos[:, 0, :2]
    command = np.broadcast_to(np.asarray(command_speed, dtype=float), (n, 2))
    speed = np.linalg.norm(command, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        along = (travel * command).sum(axis=1) / speed
    made_good = np.where(speed > 0, along, np.linalg.norm(travel, axis=1))
    given = np.zeros((0, 3)) if obstacles is None else np.asarray(obstacles, dtype=float)
    bands = np.broadcast_to(given, (n, *given.shape[-2:]))
    # The farthest foothold before any fall.
    landed = np.asarray(traj.contact.flag, dtype=bool) & (np.asarray(traj.time["contact"])[None, :]
                                                         <= fall.t_fall[:, None])
    farthest = np.where(landed, np.asarray(traj.contact.pos, dtype=float)[:, :, 0], -np.inf).max(axis=1)
    with np.errstate(invalid="ignore"):
        cleared = np.isfinite(bands[:, :, 1]) & (farthest[:, None] > bands[:, :, 1])
    highest = np.where(cleared, bands[:, :, 2], -np.inf).max(axis=1, initial=-np.inf)
    return {
        "distance_made_good": made_good,
        "obstacles_cleared": cleared.sum(axis=1),
        "highest_cleared": np.where(np.isfinite(highest), highest, np.nan),
        "fall_x": np.where(fall.fell, qpos[rows, fall.index, 0], np.nan),
        "fall_y": np.where(fall.fell, qpos[rows, fall.index, 1], np.nan),
    }


IMPACT_WINDOW = 0.05  # s after a touchdown over which its impact force is read


def landing_metrics(traj, obstacles=None) -> dict[str, np.ndarray]:
    """Per-instance landing measures, each (N,), over the touchdowns before any fall (NaN without one):

    - landing_tilt: deg, the largest tilt of the body from upright (the angle of its z axis from the vertical) at a
      touchdown: how well the flights before them were held level;
    - impact_force: N, the largest foot contact force (its norm) within IMPACT_WINDOW of a touchdown: what a landing
      asks of the leg and its motors;
    - past_tilt, past_impact: the same at the first touchdown whose foot is beyond the first of `obstacles` (its far
      end; rows as `terrain_metrics`'): the landing of the jump that got past it, NaN where none did.

    Uses the state stream for the tilt (the sample at or before each touchdown) and the contact stream's force.
    """
    qpos = np.asarray(traj.qpos, dtype=float)
    flag = np.asarray(traj.contact.flag, dtype=bool)
    force = np.linalg.norm(np.asarray(traj.contact.force, dtype=float), axis=-1)
    t_state = np.asarray(traj.time["state"], dtype=float)
    t_contact = np.asarray(traj.time["contact"], dtype=float)
    fall = _falls(qpos, t_state)
    down = _events(flag, rising=True) & (t_contact[None, :] <= fall.t_fall[:, None])
    tilt = _tilt(qpos)[:, _state_at(t_state, t_contact)]  # at each contact sample
    out = _landings(down, tilt, force, t_contact, fall.t_fall)
    n = qpos.shape[0]
    given = np.full((1, 3), np.nan) if obstacles is None else np.asarray(obstacles, dtype=float)
    far = np.broadcast_to(given, (n, *given.shape[-2:]))[:, 0, 1]
    with np.errstate(invalid="ignore"):
        beyond = down & (np.asarray(traj.contact.pos, dtype=float)[:, :, 0] > far[:, None])
    first = beyond & (np.cumsum(beyond, axis=1) == 1)
    past = _landings(first, tilt, force, t_contact, fall.t_fall)
    return {"landing_tilt": out[0], "impact_force": out[1], "past_tilt": past[0], "past_impact": past[1]}


def _highest_landing_tilt(qpos, t_state, hops: "_Hops", rise) -> np.ndarray:
    """(N,) deg: the body's tilt from upright at the landing that ends each instance's highest hop before any fall
    (the hop `highest_apex` counts), NaN where none; the state sample at or before that touchdown."""
    keep = hops.complete & np.isfinite(rise)
    rows = np.arange(qpos.shape[0])
    best = np.where(keep, rise, -np.inf).argmax(axis=1)
    landing = np.nan_to_num(hops.liftoff[rows, best] + hops.flight_time[rows, best])  # rows with none: masked below
    return np.where(keep.any(axis=1), _tilt(qpos)[rows, _state_at(t_state, landing)], np.nan)


def _tilt(qpos: np.ndarray) -> np.ndarray:
    """(N, T) deg: the angle of the body's z axis from the vertical ([w, x, y, z] quaternions)."""
    x, y = qpos[..., 4], qpos[..., 5]
    return np.degrees(np.arccos(np.clip(1.0 - 2.0 * (x * x + y * y), -1.0, 1.0)))


def _state_at(t_state: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The index of the state sample at or before each time `t`."""
    return np.clip(np.searchsorted(t_state, t, side="right") - 1, 0, len(t_state) - 1)


def _landings(down, tilt, force, t_contact, t_fall) -> tuple[np.ndarray, np.ndarray]:
    """(N,) the largest tilt at the touchdowns `down` marks, and the largest force within IMPACT_WINDOW of one,
    before the fall; NaN where none."""
    landing_tilt = np.where(down, tilt, -np.inf).max(axis=1)
    # Each contact sample's most recent touchdown time, then the force while within the window after it.
    last = np.maximum.accumulate(np.where(down, np.arange(len(t_contact))[None, :], -1), axis=1)
    since = t_contact[None, :] - np.where(last >= 0, t_contact[np.maximum(last, 0)], np.inf)
    near = (last >= 0) & (since <= IMPACT_WINDOW) & (t_contact[None, :] <= t_fall[:, None])
    impact = np.where(near, force, -np.inf).max(axis=1)
    return (np.where(np.isfinite(landing_tilt), landing_tilt, np.nan),
            np.where(np.isfinite(impact), impact, np.nan))


JOINT_NAMES = ("haa", "hfe", "kfe")  # the joints in the columns' names, joint order


def actuator_metrics(traj, joint_dof, stall_torque, no_load_speed, torque_limit) -> dict[str, np.ndarray]:
    """What the run asked of each joint's motor, per instance, over the state samples before any fall:

    - peak_torque_<joint>: N·m, the largest |τ| applied;
    - peak_power_<joint>: W, the largest |τ·q̇|, the mechanical power through the joint (driving or braking);
    - line_use_<joint>: the largest |τ| over the torque the motor can give at that speed in τ's direction
      (`actuators.envelope`: 1 is on its torque-speed line or at its current limit).

    Uses the state stream (`traj.torque`, the applied torques, and `qvel` at the same instants). The motor's
    figures are (N, 3) each, joint order (ideal motors: stall torque = limit = the effort limit, no-load speed inf);
    joint_dof: each joint's index in qvel.
    """
    torque = np.asarray(traj.torque, dtype=float)
    speed = np.asarray(traj.qvel, dtype=float)[..., list(joint_dof)]
    t_state = np.asarray(traj.time["state"], dtype=float)
    upright = _falls(np.asarray(traj.qpos, dtype=float), t_state).upright[..., None]
    # Here, not at the top: the motor model imports JAX, and `simulate` imports these metrics before it
    # checks its arguments (a refusal would pay for JAX's import, about 1.5 s of CPU).
    from hopper_mjx.hardware.actuators import Motor, envelope

    figures = (np.asarray(a, dtype=float)[:, None, :] for a in (stall_torque, no_load_speed, torque_limit))
    motor = Motor(*figures, delay=0)
    # The torque the motor can give in τ's own direction at that speed, within the current limit.
    low, high = envelope(motor, speed, xp=np)
    available = np.where(torque < 0, -low, high)
    with np.errstate(divide="ignore", invalid="ignore"):
        use = np.where(available > 0, np.abs(torque) / available, np.where(torque == 0, 0.0, np.inf))
    peak = lambda values: np.where(upright, values, -np.inf).max(axis=1)
    out = {}
    for name, values in (("peak_torque", np.abs(torque)), ("peak_power", np.abs(torque * speed)), ("line_use", use)):
        worst = peak(values)
        worst = np.where(np.isneginf(worst), np.nan, worst)
        out |= {f"{name}_{j}": worst[:, k] for k, j in enumerate(JOINT_NAMES)}
    return out


class _Falls(NamedTuple):
    roll: np.ndarray  # (N, T) rad
    pitch: np.ndarray  # (N, T) rad
    fell: np.ndarray  # (N,) bool
    index: np.ndarray  # (N,) state sample of the fall (the last sample without one)
    t_fall: np.ndarray  # (N,) s, inf without a fall
    upright: np.ndarray  # (N, T) bool, up to and including the fall sample


def _falls(qpos: np.ndarray, t_state: np.ndarray) -> _Falls:
    z = qpos[:, :, 2]
    roll, pitch = roll_pitch(qpos[:, :, 3:7])
    down = _down(z, roll, pitch)
    fell = down.any(axis=1)
    fall_index = np.where(fell, down.argmax(axis=1), len(t_state) - 1)
    t_fall = np.where(fell, t_state[fall_index], np.inf)
    upright = np.arange(len(t_state)) <= fall_index[:, None]
    return _Falls(roll, pitch, fell, fall_index, t_fall, upright)


class _Hops(NamedTuple):
    liftoff: np.ndarray  # (N, H) s, NaN-padded
    complete: np.ndarray  # (N, H) bool: a flight with its landing and the stance before it, before any fall
    flight_time: np.ndarray  # (N, H) s
    stance_time: np.ndarray
    period: np.ndarray


def _hops(flag: np.ndarray, t_contact: np.ndarray, t_fall: np.ndarray) -> _Hops:
    liftoff = _padded_times(_events(flag, rising=False), t_contact)  # (N, H)
    touchdowns = _padded_times(_events(flag, rising=True), t_contact)
    landing = _nearest_after(touchdowns, liftoff, first=True)  # touchdown ending each flight
    stance_start = _nearest_after(touchdowns, liftoff, first=False)  # touchdown before each lift-off
    complete = np.isfinite(landing) & np.isfinite(stance_start) & (landing < t_fall[:, None])
    return _Hops(liftoff, complete, landing - liftoff, liftoff - stance_start, landing - stance_start)


def _apexes(z, flag, t_state, t_contact, liftoff, standing_height) -> tuple[np.ndarray, np.ndarray]:
    """(apex rise over the standing height, rise over the lift-off height), (N, H) m, of each flight."""
    n, width = z.shape[0], liftoff.shape[1]
    # The highest state sample while the contact stream says airborne, labelled by how
    # many lift-offs came before it.
    at = np.clip(np.searchsorted(t_contact, t_state, side="right") - 1, 0, len(t_contact) - 1)
    flight_id = np.cumsum(_events(flag, rising=False), axis=1)[:, at] - 1
    airborne = ~flag[:, at] & (flight_id >= 0)
    slot = np.where(airborne, np.arange(n)[:, None] * width + flight_id, n * width)
    apex = np.full(n * width + 1, -np.inf)
    np.maximum.at(apex, slot.ravel(), z.ravel())
    apex = apex[:-1].reshape(n, width)
    standing = standing_height if np.ndim(standing_height) == 0 else np.reshape(standing_height, (n, 1))
    rise = np.where(np.isfinite(apex), apex - standing, np.nan)
    # Lift-off height, interpolated: the base moves fast there and the state stream may be coarse.
    z_liftoff = np.stack([np.interp(liftoff[i], t_state, z[i]) for i in range(n)])
    return rise, np.where(np.isfinite(apex), apex - z_liftoff, np.nan)


def _mean_velocity(qpos, t_state, end, speed_window) -> np.ndarray:
    """(N, 2) m/s, horizontal base velocity over the last window before the end (or the fall)."""
    start = np.searchsorted(t_state, t_state[end] - speed_window)
    span = t_state[end] - t_state[start]
    rows = np.arange(qpos.shape[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        return (qpos[rows, end, :2] - qpos[rows, start, :2]) / np.where(span > 0, span, np.nan)[:, None]


def _check_work(work, mass) -> None:
    if work is not None and (mass is None or not np.all(np.asarray(mass) > 0)):
        raise ValueError("the cost of transport needs the robot's mass (kg) along with the work")


def _mechanical_power(n: int, t_state, work, mass) -> np.ndarray:
    """(N,) W/kg: the motors' work over the whole record, per second and kilogram (NaN without work)."""
    _check_work(work, mass)
    length = t_state[-1] - t_state[0]
    if work is None or not length > 0:
        return np.full(n, np.nan)
    return np.asarray(work, float) / (mass * length)


def _cost_of_transport(qpos, end, g, work, mass) -> np.ndarray:
    n = qpos.shape[0]
    _check_work(work, mass)
    if work is None:
        return np.full(n, np.nan)
    travel = np.linalg.norm(qpos[np.arange(n), end, :2] - qpos[:, 0, :2], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(travel >= MIN_TRANSPORT, np.asarray(work, float) / (mass * g * travel), np.nan)
