"""Hop metrics on synthetic trajectories whose hops are known exactly."""

from types import SimpleNamespace

import numpy as np
import pytest

from hopper_mjx.metrics import hops

G = 9.81
DT = 0.01  # s between samples
STANCE, FLIGHT = 20, 40  # samples per phase: 0.2 s and 0.4 s
STAND = 0.88  # m
SPEED = 0.3  # m/s, forward


def _trajectory(n_samples=1000):
    """Instance 0 hops forever, 1 never leaves the floor, 2 falls (height) at 5 s, 3 tips over at 5 s."""
    t = np.arange(n_samples) * DT
    k = np.arange(n_samples) % (STANCE + FLIGHT)
    stance = k < STANCE
    s = (k - STANCE) * DT  # time into the flight
    takeoff = G * FLIGHT * DT / 2
    z = np.where(stance, STAND, STAND + takeoff * s - G * s * s / 2)
    qpos = np.zeros((4, n_samples, 10))
    qpos[:, :, 3] = 1.0  # upright
    qpos[:, :, 2] = z
    qpos[:, :, 0] = SPEED * t
    qpos[1, :, 2] = STAND
    qpos[1, :, 0] = 0.0
    late = t >= 5.0
    qpos[2, late, 2] = 0.2
    angle = 1.0  # rad of pitch
    qpos[3, late, 3:7] = [np.cos(angle / 2), 0, np.sin(angle / 2), 0]
    flag = np.stack([stance, np.ones(n_samples, bool), stance, stance])
    foothold = np.stack([qpos[:, :, 0], qpos[:, :, 1], np.zeros_like(t)[None].repeat(4, 0)], axis=-1)
    pos = np.where(flag[:, :, None], foothold, 0.0)  # the foot under the base while in contact
    traj = SimpleNamespace(qpos=qpos, contact=SimpleNamespace(flag=flag, pos=pos), time={"state": t, "contact": t})
    return traj, t


def test_periodic_hops_are_measured_exactly():
    traj, t = _trajectory()
    work = np.full(4, 100.0)
    m = hops.hop_metrics(traj, np.full(4, G), command_speed=(SPEED, 0.0), standing_height=STAND,
                            work=work, mass=6.8)
    rise = G * (FLIGHT * DT / 2) ** 2 / 2  # v²/2g with v = g·T_f/2
    assert m["apex_height"][0] == pytest.approx(rise, rel=1e-9)
    assert m["flight_time"][0] == pytest.approx(FLIGHT * DT)
    assert m["stance_time"][0] == pytest.approx(STANCE * DT)
    assert m["hop_period"][0] == pytest.approx((STANCE + FLIGHT) * DT)
    assert m["duty_factor"][0] == pytest.approx(STANCE / (STANCE + FLIGHT))
    # 17 flights start in the 10 s; the first has no recorded touchdown before it, the last no landing.
    assert m["hops"][0] == 15
    assert m["mean_speed"][0] == pytest.approx(SPEED) and m["tracking_error"][0] == pytest.approx(0, abs=1e-9)
    assert not m["fell"][0] and np.isnan(m["fall_time"][0])
    assert m["max_pitch"][0] == 0 and m["max_roll"][0] == 0
    travel = SPEED * t[-1]
    assert m["cost_of_transport"][0] == pytest.approx(100.0 / (6.8 * G * travel))


def test_the_highest_apex_is_the_highest_hop_before_the_fall_not_the_last_hops_mean():
    """One hop of instance 2 raised 0.5 m higher, one of 3 after its fall: the highest is that hop's apex on 2, the
    periodic rise on 3 (the fall ends the count), and NaN without a hop."""
    traj, t = _trajectory()
    rise = G * (FLIGHT * DT / 2) ** 2 / 2
    k = np.arange(len(t)) % (STANCE + FLIGHT)
    second = (t >= 1.2) & (t < 1.8) & (k >= STANCE)  # the second complete hop's flight (before the 5 s fall)
    after = (t >= 6.0) & (t < 6.6) & (k >= STANCE)
    traj.qpos[2, second, 2] += 0.5
    traj.qpos[3, after, 2] += 0.5
    m = hops.hop_metrics(traj, np.full(4, G), standing_height=STAND)
    assert m["highest_apex"][0] == pytest.approx(rise, rel=1e-9)
    assert m["highest_apex"][2] == pytest.approx(rise + 0.5, rel=1e-9)
    assert m["apex_height"][2] < m["highest_apex"][2] - 0.3  # the mean of the last hops does not see it
    assert m["highest_apex"][3] == pytest.approx(rise, rel=1e-9)
    assert np.isnan(m["highest_apex"][1])


def test_no_hops_gives_nan_not_garbage():
    traj, _ = _trajectory()
    m = hops.hop_metrics(traj, np.full(4, G), standing_height=STAND)
    assert m["hops"][1] == 0 and not m["fell"][1]
    for key in ("apex_height", "flight_time", "stance_time", "hop_period", "duty_factor", "cost_of_transport"):
        assert np.isnan(m[key][1]), key
    assert m["mean_speed"][1] == 0


def test_falls_stop_the_count():
    traj, _ = _trajectory()
    m = hops.hop_metrics(traj, np.stack([np.zeros(4), np.zeros(4), -np.full(4, G)], axis=1),
                            standing_height=STAND)
    assert m["fell"].tolist() == [False, False, True, True]
    np.testing.assert_allclose(m["fall_time"][2:], 5.0)
    assert np.all(m["hops"][2:] == 7)  # touchdowns at 1.2, 1.8, ..., 4.8 s; instance 0, the same hops unfallen, has 15
    assert m["hops"][0] == 15
    assert m["apex_height"][2] == pytest.approx(m["apex_height"][0])
    assert m["max_pitch"][3] == pytest.approx(1.0)  # up to and including the fall sample
    assert m["mean_speed"][2] == pytest.approx(SPEED)  # over the 5 s before the fall


def test_energy_per_hop_is_the_mean_power_over_one_period():
    traj, t = _trajectory()
    work = np.array([100.0, 50.0, 100.0, 100.0])
    m = hops.hop_metrics(traj, np.full(4, G), standing_height=STAND, work=work, mass=6.8)
    power = work / (6.8 * t[-1])  # W/kg over the whole record
    np.testing.assert_allclose(m["mechanical_power"], power)
    assert m["energy_per_hop"][0] == pytest.approx(power[0] * (STANCE + FLIGHT) * DT)
    assert np.isnan(m["energy_per_hop"][1])  # no hop, no energy per hop; the power is still known


def test_zero_gravity_floats_and_divides_by_nothing():
    """The seed's zero-gravity world: the robot floats; values defined through g are NaN, not inf,
    and no numpy warning is raised. A sideways part of gravity does not count as downward pull."""
    traj, _ = _trajectory()
    gravity = np.array([[0, 0, 0], [0, 0, 0], [3.0, 0, -G], [0, 0, -G]], dtype=float)
    with np.errstate(all="raise"):
        m = hops.hop_metrics(traj, gravity, standing_height=STAND, work=np.full(4, 100.0), mass=6.8)
    assert m["floating"].tolist() == [True, True, False, False]
    assert np.isnan(m["ballistic_flight_time"][0]) and np.isnan(m["cost_of_transport"][0])
    assert m["apex_height"][0] == pytest.approx(G * (FLIGHT * DT / 2) ** 2 / 2)  # geometry needs no g
    # The tilted gravity (3 m/s² sideways) times the flight by its downward part, as the level floor sees it.
    straight = hops.hop_metrics(traj, gravity[[3, 3, 3, 3]], standing_height=STAND)
    assert m["ballistic_flight_time"][2] == straight["ballistic_flight_time"][2]
    assert m["ballistic_flight_time"][3] == pytest.approx(FLIGHT * DT, rel=1e-9)


def test_every_metric_is_its_own_array():
    """No metric is another under a second name (an alias can never disagree, so a test comparing
    the two could never fail)."""
    traj, _ = _trajectory()
    m = hops.hop_metrics(traj, np.full(4, G), standing_height=STAND, work=np.full(4, 100.0), mass=6.8)
    names = sorted(m)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            assert not np.shares_memory(m[a], m[b]), (a, b)


def test_bad_arguments():
    traj, _ = _trajectory()
    with pytest.raises(ValueError, match="gravity"):
        hops.hop_metrics(traj, np.full(3, G), standing_height=STAND)
    with pytest.raises(ValueError, match="mass"):
        hops.hop_metrics(traj, np.full(4, G), standing_height=STAND, work=np.ones(4))


def test_standing_height_is_the_stance_with_the_foot_down(mj_model):
    from hopper_mjx.model.robot import standing_height

    assert standing_height(mj_model) == pytest.approx(0.8823, abs=1e-3)


def test_terrain_metrics_distance_obstacles_and_where_the_falls_happened():
    """Instance 0 travels 3 m along +x; 2 falls at 5 s, having reached x = 1.5 m; 1 stands still."""
    traj, t = _trajectory()
    blocks = np.array([[0.6, 0.7, 0.15], [1.2, 1.3, 0.05], [2.5, 2.6, 0.3], [np.nan] * 3])
    out = hops.terrain_metrics(traj, command_speed=(SPEED, 0.0), obstacles=blocks)
    end = SPEED * t[-1]
    assert out["distance_made_good"][0] == pytest.approx(end)
    assert out["distance_made_good"][1] == 0.0
    assert out["distance_made_good"][2] == pytest.approx(SPEED * 5.0)  # up to its fall
    assert out["obstacles_cleared"].tolist() == [3, 0, 2, 2]  # footholds to 2.9 m pass 2.6; the fallen stop at 1.5
    # A base that passes a block while its foot stays before it (tripping forward) has not cleared it.
    tripped = SimpleNamespace(qpos=traj.qpos, time=traj.time, contact=SimpleNamespace(
        flag=traj.contact.flag, pos=np.where(traj.contact.pos[..., :1] > 0.65, 0.0, traj.contact.pos)))
    assert hops.terrain_metrics(tripped, obstacles=blocks)["obstacles_cleared"].tolist() == [0, 0, 0, 0]
    assert out["highest_cleared"][0] == pytest.approx(0.3)
    assert out["highest_cleared"][2] == pytest.approx(0.15)
    assert np.isnan(out["highest_cleared"][1])
    np.testing.assert_allclose(out["fall_x"], [np.nan, np.nan, SPEED * 5.0, SPEED * 5.0])
    np.testing.assert_allclose(out["fall_y"], [np.nan, np.nan, 0.0, 0.0])
    sideways = hops.terrain_metrics(traj, command_speed=(0.0, SPEED))  # commanded +y, it went +x
    assert sideways["distance_made_good"][0] == pytest.approx(0.0)
    still = hops.terrain_metrics(traj)  # no command: the straight-line distance
    assert still["distance_made_good"][0] == pytest.approx(end)
    per_instance = hops.terrain_metrics(traj, obstacles=np.broadcast_to(blocks[:1], (4, 1, 3)))
    assert per_instance["obstacles_cleared"].tolist() == [1, 0, 1, 1]


def test_landing_metrics_read_the_tilt_and_the_impact_at_each_touchdown():
    """Instance 0 lands every 0.6 s, its body tilted 5° at the 4th landing only, each landing's force rising to
    300 N in its first 0.03 s (the 2nd's to 900 N at 0.04 s, and 2000 N at 0.1 s: outside the window); 2 falls at
    5 s, and a 20° tilt at a landing after it does not count; 1 never lands. Past a band, the same at the first
    landing beyond it alone."""
    traj, t = _trajectory()
    n = len(t)
    qpos = traj.qpos.copy()
    flag = traj.contact.flag
    touchdowns = np.flatnonzero(flag[0, 1:] & ~flag[0, :-1]) + 1
    tilted = lambda deg: [np.cos(np.radians(deg) / 2), np.sin(np.radians(deg) / 2), 0.0, 0.0]
    qpos[0, touchdowns[3], 3:7] = tilted(5.0)
    late = touchdowns[t[touchdowns] > 5.0][0]
    qpos[2, late, 3:7] = tilted(20.0)
    force = np.zeros((4, n, 3))
    for k in touchdowns:
        force[:, k:k + 4, 2] = 300.0
    force[:, touchdowns[1] + 4, 2] = 900.0
    force[:, touchdowns[1] + 10, 2] = 2000.0
    landing = SimpleNamespace(qpos=qpos, time=traj.time,
                              contact=SimpleNamespace(flag=flag, pos=traj.contact.pos, force=force))
    out = hops.landing_metrics(landing)
    assert out["landing_tilt"][0] == pytest.approx(5.0)
    assert out["impact_force"][0] == pytest.approx(900.0)
    assert np.isnan(out["landing_tilt"][1]) and np.isnan(out["impact_force"][1])  # standing: no touchdown
    assert out["landing_tilt"][2] == pytest.approx(0.0, abs=1e-6)  # the 20° landing came after its fall
    assert out["impact_force"][2] == pytest.approx(900.0)
    # The landing past an obstacle: the first touchdown whose foot is beyond its far end (the 4th here), alone.
    far = SPEED * (t[touchdowns[2]] + t[touchdowns[3]]) / 2
    past = hops.landing_metrics(landing, np.array([[far - 0.1, far, 0.3]]))
    np.testing.assert_allclose(past["past_tilt"], [5.0, np.nan, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(past["past_impact"], [300.0, np.nan, 300.0, 300.0])
    never = hops.landing_metrics(landing, np.array([[0.0, 1e3, 0.3]]))
    assert np.isnan(never["past_tilt"]).all() and np.isnan(never["past_impact"]).all()
    assert np.isnan(out["past_tilt"]).all()  # no obstacle given


def test_actuator_metrics_read_each_joints_peak_torque_power_and_share_of_its_motor_line():
    """A knee torque of 60 N·m at 10 rad/s on a DC line τ_s = 80 N·m, ω0 = 20 rad/s gives 600 W and uses the
    line 1.5 times over (80·(1 − 10/20) = 40 N·m available: a figure over 1 is a torque no such motor gives);
    pushing against the motion (τ < 0 at ω > 0) the line gives 80·1.5 = 120, clipped at the 100 N·m current limit.
    Instance 2's 500 N·m after its fall at 5 s does not count; ideal motors (no-load speed inf) are measured
    against the effort alone."""
    traj, t = _trajectory()
    n = len(t)
    torque, qvel = np.zeros((4, n, 3)), np.zeros((4, n, 9))
    dof = (6, 7, 8)
    torque[:, 100, 2], qvel[:, 100, 8] = 60.0, 10.0
    torque[:, 200, 1], qvel[:, 200, 7] = -50.0, 10.0
    torque[:, 300, 0], qvel[:, 300, 6] = 20.0, -2.0
    torque[2, 700, 2] = 500.0  # t = 7 s, after instance 2's fall
    traj = SimpleNamespace(qpos=traj.qpos, qvel=qvel, torque=torque, time=traj.time)
    full = lambda *v: np.broadcast_to(np.array(v, float), (4, 3))
    out = hops.actuator_metrics(traj, dof, full(40, 80, 80), full(20, 20, 20), full(40, 100, 100))
    np.testing.assert_allclose(out["peak_torque_kfe"], 60.0)
    np.testing.assert_allclose(out["peak_power_kfe"], 600.0)
    np.testing.assert_allclose(out["line_use_kfe"], 60.0 / 40.0)
    np.testing.assert_allclose(out["peak_torque_hfe"], 50.0)
    np.testing.assert_allclose(out["line_use_hfe"], 50.0 / 100.0)  # braking: the current limit binds
    np.testing.assert_allclose(out["peak_power_haa"], 40.0)
    np.testing.assert_allclose(out["line_use_haa"], 20.0 / 40.0)  # τ > 0 at ω < 0: the line's 44 is cut to the 40 limit
    ideal = hops.actuator_metrics(traj, dof, full(40, 80, 80), full(np.inf, np.inf, np.inf), full(40, 80, 80))
    np.testing.assert_allclose(ideal["line_use_kfe"], 60.0 / 80.0)
    np.testing.assert_allclose(ideal["line_use_haa"], 20.0 / 40.0)  # no speed limit: no more than the effort


def test_the_highest_hop_s_landing_tilt_is_read_at_its_own_touchdown():
    """Instance 0's fifth hop flies 0.5 m higher than the rest and each touchdown is tilted by its own angle: the
    highest hop's landing is the fifth touchdown's. A robot that never lifts off has none; one whose hops are all
    alike takes its first (instance 2, level)."""
    traj, t = _trajectory()
    qpos, flag = traj.qpos.copy(), traj.contact.flag
    touchdowns = np.flatnonzero(flag[0, 1:] & ~flag[0, :-1]) + 1
    liftoffs = np.flatnonzero(~flag[0, 1:] & flag[0, :-1]) + 1
    tilted = lambda deg: [np.cos(np.radians(deg) / 2), 0.0, np.sin(np.radians(deg) / 2), 0.0]
    for j, k in enumerate(touchdowns):
        qpos[0, k, 3:7] = tilted(j + 1.0)
    flight = (t > t[liftoffs[liftoffs < touchdowns[4]][-1]]) & (t < t[touchdowns[4]])
    qpos[0, flight, 2] += 0.5
    m = hops.hop_metrics(SimpleNamespace(qpos=qpos, contact=traj.contact, time=traj.time), np.full(4, G),
                         standing_height=STAND)
    tilt, highest = m["highest_landing_tilt"], m["highest_apex"]
    assert tilt[0] == pytest.approx(5.0)
    assert np.isnan(tilt[1]) and tilt[2] == pytest.approx(0.0, abs=1e-6)
    assert highest[0] == pytest.approx(G * (FLIGHT * DT / 2) ** 2 / 2 + 0.5)
