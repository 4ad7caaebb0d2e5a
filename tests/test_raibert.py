"""Raibert's controller part by part: each pure function against an oracle derived independently
(phase logic by its truth table, energy and spring-mass formulas, virtual work, the leg's geometry)."""

import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hopper_mjx.control import foothold, kinematics, raibert
from hopper_mjx.control.raibert import COMPRESSION, FLIGHT, THRUST, UNLOADING
from hopper_mjx.hardware.signals import Contact, Observation
from hopper_mjx.model.robot import CLEARANCE, Robot

L0 = 0.64  # m, the default touchdown leg length


@pytest.fixture(scope="module")
def robot(mj_model):
    return Robot.of(mj_model)


def _state(params=None, **fields):
    params = params or raibert.raibert_params(1, height=0.1, speed=(0.4, 0.0))
    obs = Observation(time=jnp.float32(0.0), qpos=jnp.zeros(10), qvel=jnp.zeros(9),
                      contact=Contact(jnp.bool_(False), jnp.zeros(3), jnp.zeros(3)))
    s = raibert.initial_state(jax.tree_util.tree_map(lambda v: v[0], params), obs)
    return s._replace(**{k: jnp.asarray(v, dtype=jnp.float32) for k, v in fields.items()})


def _obs(robot, *, z=1.0, joints=None, qvel=None):
    qpos = np.array(robot.stance_qpos, dtype=np.float32)
    qpos[2] = z
    if joints is not None:
        qpos[list(robot.layout.joint_qpos)] = joints
    qvel = np.zeros(robot.layout.nv, np.float32) if qvel is None else np.asarray(qvel, np.float32)
    return Observation(time=jnp.float32(1.0), qpos=jnp.asarray(qpos), qvel=jnp.asarray(qvel),
                       contact=Contact(jnp.bool_(False), jnp.zeros(3), jnp.zeros(3)))


# -- phases -----------------------------------------------------------------------
@pytest.mark.parametrize("phase, touching, elapsed, length, rate, expected", [
    (FLIGHT, True, 0.02, 0.6, -0.1, COMPRESSION),  # touchdown
    (FLIGHT, True, 0.005, 0.6, -0.1, FLIGHT),  # too soon after the last change: debounced
    (FLIGHT, False, 0.5, 0.6, 0.0, FLIGHT),
    (COMPRESSION, True, 0.05, 0.58, -0.2, COMPRESSION),  # still shortening
    (COMPRESSION, True, 0.05, 0.58, 0.0, THRUST),  # the bottom
    (THRUST, True, 0.05, 0.63, 0.3, THRUST),
    (THRUST, True, 0.05, 0.641, 0.3, UNLOADING),  # back to the touchdown length
    (UNLOADING, False, 0.02, 0.64, 0.0, FLIGHT),  # lift-off
    (COMPRESSION, False, 0.02, 0.6, 0.0, FLIGHT),  # lift-off wins over the bottom
])
def test_next_phase_follows_its_truth_table(phase, touching, elapsed, length, rate, expected):
    new, ev = raibert.next_phase(jnp.int32(phase), jnp.bool_(touching), jnp.float32(elapsed),
                                 jnp.float32(length), jnp.float32(rate), jnp.float32(L0))
    assert int(new) == expected
    assert bool(ev.touchdown) == (phase == FLIGHT and expected == COMPRESSION)
    assert bool(ev.liftoff) == (phase != FLIGHT and expected == FLIGHT)


# -- part 1: height -------------------------------------------------------------------
def _events(**fired):
    return raibert.Events(**{k: jnp.bool_(fired.get(k, False)) for k in raibert.Events._fields})


def test_thrust_supplies_the_energy_missing_for_the_apex(robot):
    mass, g, stiffness = robot.layout.total_mass, 3.71, 200.0  # a soft spring: it stores less than is missing
    s = _state(height_bias=0.02)
    body = raibert.sense(robot, _obs(robot, z=0.8, joints=(0.0, 0.6, -1.4), qvel=np.r_[0, 0, -0.3, np.zeros(6)]))
    bias, force = raibert.height_update(s, _events(bottom=True), body, g, stiffness, mass, robot.standing_height)
    squeeze = L0 - float(body.length)
    assert squeeze > raibert.MIN_SQUEEZE
    apex = robot.standing_height + 0.1 + 0.02
    # Energy at the bottom plus the thrust's work over the stroke = potential energy at the apex.
    energy = mass * g * float(body.z) + 0.5 * mass * 0.3**2 + 0.5 * stiffness * squeeze**2 + float(force) * squeeze
    assert energy == pytest.approx(mass * g * apex, rel=1e-5)
    assert float(force) > 0
    assert float(bias) == pytest.approx(0.02)  # adapted at touchdown only


def test_apex_bias_adapts_at_touchdown_and_is_bounded(robot):
    body = raibert.sense(robot, _obs(robot))
    adapt = raibert.RaibertConfig().height_adapt
    s = _state(apex=robot.standing_height + 0.08, height_bias=0.01)  # 2 cm short of the commanded 0.10
    bias, _ = raibert.height_update(s, _events(touchdown=True), body, 9.81, 2000.0, 6.8, robot.standing_height)
    assert float(bias) == pytest.approx(0.01 + adapt * 0.02, abs=1e-6)
    s = _state(apex=robot.standing_height - 5.0, height_bias=0.25)
    bias, _ = raibert.height_update(s, _events(touchdown=True), body, 9.81, 2000.0, 6.8, robot.standing_height)
    assert float(bias) == pytest.approx(raibert.MAX_HEIGHT_BIAS)


# -- part 2: speed bookkeeping ------------------------------------------------------------
def test_stance_time_starts_at_half_a_spring_mass_period_then_is_measured():
    cfg = raibert.RaibertConfig()
    s = _state()
    first = raibert.speed_update(s, _events(), jnp.zeros(2), jnp.float32(0.3), 9.81)
    # k = m·9.81/sag: half a period π·√(m/k) = π·√(sag/9.81)
    assert float(first.stance_time) == pytest.approx(math.pi * math.sqrt(cfg.sag / 9.81), rel=1e-6)
    s = _state(touchdown_time=1.0, stance_time=0.2)
    out = raibert.speed_update(s, _events(liftoff=True), jnp.zeros(2), jnp.float32(1.17), 9.81)
    assert float(out.stance_time) == pytest.approx(0.17, abs=1e-6)
    assert float(out.gain) == pytest.approx(cfg.speed_gain * cfg.leg_length / (9.81 * 0.17), rel=1e-5)


def test_speed_reference_ramps_and_the_placement_integral_is_bounded():
    cfg = raibert.RaibertConfig()
    s = _state(speed_reference=[0.1, 0.0], speed_offset=[0.095, 0.0], stance_time=0.2)
    v = jnp.array([0.9, 0.0])
    out = raibert.speed_update(s, _events(touchdown=True), v, jnp.float32(2.0), 9.81)
    np.testing.assert_allclose(out.reference, [0.1 + cfg.speed_step, 0.0], atol=1e-6)  # one step towards 0.4
    np.testing.assert_allclose(out.error, v - out.reference, atol=1e-6)
    gain = cfg.speed_gain * cfg.leg_length / (9.81 * 0.2)
    np.testing.assert_allclose(out.offset, [0.095 + cfg.speed_integral * gain * 0.75, 0.0], rtol=1e-5)
    far_too_fast = raibert.speed_update(s, _events(touchdown=True), jnp.array([5.0, 0.0]), jnp.float32(2.0), 9.81)
    np.testing.assert_allclose(far_too_fast.offset, [raibert.MAX_SPEED_OFFSET, 0.0], atol=1e-6)
    still = raibert.speed_update(s, _events(), v, jnp.float32(2.0), 9.81)  # not at touchdown: nothing moves
    np.testing.assert_allclose(still.reference, [0.1, 0.0])
    np.testing.assert_allclose(still.offset, [0.095, 0.0])


# -- stance and flight torques ---------------------------------------------------------------
def _speed(stance_time=0.2):
    z2 = jnp.zeros(2)
    return raibert.Speed(jnp.float32(stance_time), jnp.float32(0.0), jnp.float32(0.0), z2, z2, z2)


def test_stance_torque_is_the_leg_force_through_the_jacobian(robot):
    """Level body, no spin, no speed: the attitude servo is idle and τ = -Jᵀ·F, F along foot -> COM;
    by virtual work, τ·δq = -F·δfoot for any small joint motion."""
    cfg, leg = raibert.RaibertConfig(), robot.leg
    body = raibert.sense(robot, _obs(robot, joints=(0.05, 0.6, -1.3)))
    stiffness, thrust = 2000.0, 30.0
    torque = raibert.stance_torque(leg, cfg, jnp.int32(THRUST), body, jnp.zeros(3), _speed(), thrust, 9.81,
                                   stiffness, 6.8, jnp.ones(2))
    force = (stiffness * (L0 - float(body.length)) + thrust)
    direction = np.asarray(body.com - body.foot) / np.linalg.norm(np.asarray(body.com - body.foot))
    dq = jnp.array([1e-3, -2e-3, 1.5e-3])
    _, dfoot = jax.jvp(lambda q: kinematics.foot_position(leg, q), (body.q,), (dq,))
    assert float(torque @ dq) == pytest.approx(-force * float(direction @ np.asarray(dfoot)), rel=1e-4)
    unloading = raibert.stance_torque(leg, cfg, jnp.int32(UNLOADING), body._replace(qd=jnp.array([1.0, -2.0, 3.0])),
                                      jnp.zeros(3), _speed(), thrust, 9.81, stiffness, 6.8, jnp.ones(2))
    np.testing.assert_allclose(unloading, -np.array(raibert.FLIGHT_KD) * [1.0, -2.0, 3.0], rtol=1e-6)


def test_flight_torque_drives_the_foot_to_the_neutral_placement(robot):
    """Moving at v with the last stance T_s, the PD's target puts the foot v·T_s/2 ahead of the COM
    on a virtual leg of the touchdown length (read back from the torque: target = q + τ/kp at rest)."""
    cfg, leg = raibert.RaibertConfig(), robot.leg
    body = raibert.sense(robot, _obs(robot, qvel=np.r_[0.5, 0, 0, np.zeros(6)]))
    inertia = raibert.inertia_facts(leg)
    torque = raibert.flight_torque(leg, cfg, body, jnp.zeros(3), _speed(0.2), 9.81, inertia)
    target = body.q + torque / jnp.asarray(raibert.FLIGHT_KP)
    foot = kinematics.foot_position(leg, target)
    np.testing.assert_allclose(np.asarray(foot - body.com)[:2], [0.5 * 0.2 / 2, 0.0], atol=1e-4)
    assert float(kinematics.leg_length(leg, target[2])) == pytest.approx(cfg.leg_length, abs=1e-4)


def test_flight_gains_are_the_shipped_position_controllers(robot):
    from hopper_mjx.control import pid

    gains = pid.load_gains()
    assert raibert.FLIGHT_KP == tuple(gains[j]["p"] for j in ("haa_joint", "hfe_joint", "kfe_joint"))
    assert raibert.FLIGHT_KD == tuple(gains[j]["d"] for j in ("haa_joint", "hfe_joint", "kfe_joint"))


# -- on a terrain ---------------------------------------------------------------------
def _ground(heights, size=(1.0, 1.0)):
    from hopper_mjx.hardware.signals import SensedGround

    heights = jnp.asarray(heights, jnp.float32)
    return SensedGround(heights, jnp.zeros(25), jnp.zeros(3), size)


def _step(x0=0.2, rise=0.05):
    """A 2 m x 2 m grid (cell 0.05 m) whose ground rises by `rise` beyond x = x0."""
    xs = np.linspace(-1.0, 1.0, 41)
    return np.broadcast_to(np.where(xs >= x0, rise, 0.0), (41, 41))


def test_thrust_aims_above_the_ground_it_lands_on(robot):
    """The same bottom of a stance, on the plane and aimed above a floor 5 cm up: the thrust adds m·g·0.05."""
    mass, g, stiffness = robot.layout.total_mass, 9.81, 200.0
    s = _state(height_bias=0.02)
    body = raibert.sense(robot, _obs(robot, z=0.8, joints=(0.0, 0.6, -1.4), qvel=np.r_[0, 0, -0.3, np.zeros(6)]))
    _, plane = raibert.height_update(s, _events(bottom=True), body, g, stiffness, mass, robot.standing_height)
    _, up = raibert.height_update(s, _events(bottom=True), body, g, stiffness, mass, robot.standing_height,
                                  jnp.float32(0.05))
    squeeze = L0 - float(body.length)
    assert (float(up) - float(plane)) * squeeze == pytest.approx(mass * g * 0.05, rel=1e-4)


def test_the_apex_is_measured_above_the_floor_it_was_aimed_over(robot):
    """At touchdown the apex counts from the floor of the hop: 8 cm over a floor 5 cm up is 2 cm short."""
    body = raibert.sense(robot, _obs(robot))
    adapt = raibert.RaibertConfig().height_adapt
    s = _state(apex=robot.standing_height + 0.13, height_bias=0.01, floor=0.05)
    bias, _ = raibert.height_update(s, _events(touchdown=True), body, 9.81, 2000.0, 6.8, robot.standing_height,
                                    jnp.float32(0.05))
    assert float(bias) == pytest.approx(0.01 + adapt * 0.02, abs=1e-6)


def test_the_landing_floor_is_the_step_ahead(robot):
    """Standing before a step and moving towards it, the next hop is aimed above the step; moving away,
    or hopping in place, above the ground under the foot."""
    ground = _ground(_step(x0=0.2))
    obs = lambda vx: _obs(robot, qvel=np.r_[vx, np.zeros(8)])
    speed = raibert.speed_update(_state(), _events(), jnp.zeros(2), jnp.float32(0.3), 9.81)
    floor = lambda vx: float(foothold.landing_floor(robot.leg, raibert.sense(robot, obs(vx)), ground,
                                                   jnp.zeros(2), speed, jnp.float32(0.1), 9.81))
    assert floor(0.6) == pytest.approx(0.05)  # ahead by v·(T_s + T_f) ≈ 0.6·0.43 m: on the step
    assert floor(0.0) == pytest.approx(0.0)
    assert floor(-0.6) == pytest.approx(0.0)


def test_a_level_ground_at_zero_acts_as_the_plane(robot):
    """A whole hop cycle of `act` on a level grid at z = 0 commands what it commands on the plane."""
    ctrl = raibert.raibert(robot)
    params = jax.tree_util.tree_map(lambda v: v[0], raibert.raibert_params(1, height=0.1, speed=(0.3, 0.0)))
    level = _ground(np.zeros((41, 41)))
    for phase, touching, z, vz in ((FLIGHT, False, 1.0, -0.5), (THRUST, True, 0.85, 0.1)):
        obs = _obs(robot, z=z, joints=(0.05, 0.55, -1.2), qvel=np.r_[0.3, 0, vz, np.zeros(6)])
        touch = Contact(jnp.bool_(touching), jnp.zeros(3), jnp.zeros(3))
        s = raibert.initial_state(params, obs)._replace(phase=jnp.int32(phase))
        plane, _ = ctrl.act(s, obs._replace(contact=touch), jnp.array([0.0, 0.0, -9.81]))
        ground, _ = ctrl.act(s, obs._replace(contact=touch, ground=level), jnp.array([0.0, 0.0, -9.81]))
        np.testing.assert_allclose(ground, plane, atol=1e-5)
        assert np.abs(np.asarray(plane)).max() > 1.0  # a real command, not zeros on both sides


def test_rising_towards_a_step_the_leg_is_drawn_up_by_its_rise(robot):
    """In a rising flight whose foothold is on a step 5 cm above the ground under the foot, the PD's target
    leg is 5 cm shorter (read back from the torque as above)."""
    cfg, leg = raibert.RaibertConfig(), robot.leg
    inertia = raibert.inertia_facts(leg)
    step = _ground(_step(x0=0.1))  # the foot is near x = 0, the foothold v·T_s/2 = 0.15 ahead of the COM
    for vz, shorter in ((0.5, 0.05),):
        body = raibert.sense(robot, _obs(robot, qvel=np.r_[0.5, 0, vz, np.zeros(6)]))
        torque = raibert.flight_torque(leg, cfg, body, jnp.zeros(3), _speed(0.6), 9.81, inertia, ground=step,
                                       base_xy=jnp.zeros(2))
        target = body.q + torque / jnp.asarray(raibert.FLIGHT_KP)
        assert float(kinematics.leg_length(leg, target[2])) == pytest.approx(cfg.leg_length - shorter, abs=1e-4)


def _fine_step(x0=0.2, rise=0.05):
    """A 2 m x 2 m grid of the tools' 4 cm cells whose ground rises by `rise` beyond x = x0: the riser is the
    ramp across the cell before x0."""
    xs = np.linspace(-1.0, 1.0, 51)
    return np.broadcast_to(np.where(xs >= x0 - 1e-9, rise, 0.0), (51, 51))


def test_a_foothold_on_a_riser_is_moved_clear_of_it(robot):
    """Wherever on or near a 5 cm step's riser (the ramp from x = 0.16 to 0.20) the foot would land, the foothold
    is moved so that the foot's centre lands 2 cm or more off the ramp, on the ground below or on the step (a 3 cm
    sphere 2 cm before the ramp's foot stands on the ground: it would touch the 51° ramp from 1.4 cm); on level
    and on gentle rough ground the placement is left exactly as it was."""
    leg = robot.leg
    body = raibert.sense(robot, _obs(robot))  # at rest in the air: it lands where the placement puts it
    com_x = float(foothold.foothold(leg, body, jnp.zeros(2), jnp.zeros(2))[0])
    placement = jnp.zeros(2)
    step = _ground(_fine_step())
    for want in np.arange(0.10, 0.27, 0.005):  # the landing point, world x
        base_xy = jnp.array([want - com_x, 0.0])
        moved = foothold.clear_of_edges(leg, body, step, base_xy, placement, jnp.float32(0.1), 9.81)
        lands = want + float(moved[0])
        assert lands <= 0.14 + 1e-6 or lands >= 0.22 - 1e-6, f"aimed at {want:.3f}, lands at {lands:.3f}"
        assert abs(lands - want) <= 0.05 + 1e-6  # at most EDGE_SHIFTS steps
        assert abs(float(moved[1])) < 1e-7
    xs = np.linspace(-1.0, 1.0, 51)
    rough = 0.02 * np.sin(2 * np.pi * xs / 0.4)[None, :] * np.cos(2 * np.pi * xs / 0.4)[:, None]
    for heights in (np.zeros((51, 51)), rough):
        for want in (0.0, 0.13, 0.31):
            moved = foothold.clear_of_edges(leg, body, _ground(heights), jnp.array([want - com_x, 0.0]), placement,
                                           jnp.float32(0.1), 9.81)
            assert np.asarray(moved).tolist() == [0.0, 0.0]


def test_below_a_risers_top_the_swing_waits(robot):
    """Rising towards a step 5 cm up, the foot still below its top: the PD's target keeps the foot where it is
    under the COM (the leg only shortens); once the foot is above the top and clear, it reaches ahead to place."""
    cfg, leg = raibert.RaibertConfig(), robot.leg
    inertia = raibert.inertia_facts(leg)
    step = _ground(_step(x0=0.1))  # the foot is near x = 0, the foothold v·T_s/2 = 0.15 ahead of the COM
    ahead = {}
    for clearance in (0.03, 0.12):  # the foot's bottom above z = 0: below the step's top, then above it
        body = raibert.sense(robot, _obs(robot, z=robot.standing_height + clearance,
                                         qvel=np.r_[0.5, 0, 0.5, np.zeros(6)]))
        torque = raibert.flight_torque(leg, cfg, body, jnp.zeros(3), _speed(0.6), 9.81, inertia, ground=step,
                                       base_xy=jnp.zeros(2))
        target = body.q + torque / jnp.asarray(raibert.FLIGHT_KP)
        now = np.asarray(body.foot - body.com)[:2]
        ahead[clearance] = np.asarray(kinematics.foot_position(leg, target) - body.com)[:2] - now
    np.testing.assert_allclose(ahead[0.03], 0.0, atol=1e-4)
    assert ahead[0.12][0] > 0.1


# -- each instance's own leg -----------------------------------------------------------------
SHANKS = (0.30, 0.38, 0.45)  # m: one batch, three legs (the URDF's is 0.35)


def test_each_instance_places_its_own_foot_with_its_own_leg(mj_model, robot):
    """One batch of three shanks, each at its own stance moving at 0.5 m/s: the flight PD's target joint angles,
    put through MuJoCo C's forward kinematics of that instance's model, put its foot v·T_s/2 ahead of its centre
    of mass on a virtual leg of its own touchdown length (the URDF's margin over its standing leg), to 1e-6 m in
    float64; the URDF's leg model would miss by centimetres. Its standing height is MuJoCo's."""
    from hopper_mjx.variation import draw
    from hopper_mjx.variation.spec import Spec

    drawn = [draw.draw(Spec.parse(f"shank_length={s}"), mj_model, 1, 0) for s in SHANKS]
    values = {"body_pos": np.concatenate([d["body_pos"] for d in drawn])}
    own, stances = draw.legs(mj_model, values), draw.stances(mj_model, values)
    params = raibert.raibert_params(len(SHANKS), height=0.1, speed=(0.5, 0.0), leg=raibert.legs(robot, own))
    lay = robot.layout
    qvel = np.r_[0.5, np.zeros(lay.nv - 1)]

    def target(params, qpos, urdf: bool):
        obs = Observation(time=jnp.float64(1.0), qpos=qpos, qvel=jnp.asarray(qvel),
                          contact=Contact(jnp.bool_(False), jnp.zeros(3), jnp.zeros(3)))
        leg, inertia = (robot.leg, raibert.inertia_facts(robot.leg)) if urdf else (params.leg.geometry,
                                                                                     params.leg.inertia)
        body = raibert.sense(robot, obs, leg)
        torque = raibert.flight_torque(leg, params.gains, body, jnp.zeros(3), _speed(0.2), 9.81, inertia)
        return body.q + torque / jnp.asarray(raibert.FLIGHT_KP)

    with jax.enable_x64(True):
        params64 = jax.tree_util.tree_map(lambda v: jnp.asarray(v, jnp.float64), params)
        both = jax.jit(jax.vmap(lambda p, q: (target(p, q, False), target(p, q, True))))(params64, jnp.asarray(stances))
        targets = dict(zip((False, True), map(np.asarray, both)))
    hfe_anchor = lambda d: d.xanchor[mj_model.joint("hfe_joint").id]
    for i, shank in enumerate(SHANKS):
        m = draw.instance_model(mj_model, values, i)
        d = mujoco.MjData(m)
        d.qpos[:] = stances[i]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        com = d.subtree_com[int(m.jnt_bodyid[0])].copy()  # where the foot is placed from: now, before the swing
        assert float(params.leg.standing_height[i]) == pytest.approx(stances[i][2] - CLEARANCE, abs=1e-6)
        miss = {}
        for urdf, q in targets.items():
            d.qpos[list(lay.joint_qpos)] = q[i]
            mujoco.mj_kinematics(m, d)
            foot = d.geom_xpos[lay.foot_geom]
            miss[urdf] = max(np.abs(foot[:2] - com[:2] - [0.5 * 0.2 / 2, 0.0]).max(),
                             abs(np.linalg.norm(foot - hfe_anchor(d)) - float(params.gains.leg_length[i])))
        assert miss[False] < 1e-6, f"shank {shank} m: its foot lands {miss[False]:.1e} m off"
        assert miss[True] > 1e-2, f"shank {shank} m: the URDF's leg model misses by only {miss[True]:.1e} m"
    # The touchdown length keeps the URDF's margin over each standing leg (a longer shank stands taller).
    np.testing.assert_allclose(params.gains.leg_length - params.leg.length_shift, raibert.RaibertConfig().leg_length,
                               atol=1e-6)
    assert np.all(np.diff(params.gains.leg_length) > 0.02) and np.all(np.diff(params.leg.standing_height) > 0.02)


def test_a_long_and_a_short_shank_hop_on_the_commanded_apex_of_their_own_legs(tmp_path):
    """`sweep param --param shank_length` at Earth, 4 s: the 0.45 m shank (every robot fell while Raibert modelled
    the URDF's 0.35 m leg) and the 0.30 m one hop without a fall, each apex 0.10 m ± 15 % over its own standing
    height (the sweep measures it there; over the URDF's it would be 11 cm off for the 0.45 m leg)."""
    import csv

    from hopper_mjx.sweep.__main__ import main

    out = tmp_path / "legs"
    assert main(["param", "--param", "shank_length", "--values", "0.30,0.45", "--gravity", "9.81", "--num", "1",
                 "--duration", "4", "--chunk", "2", "--no-progress", "--out", str(out)]) == 0
    with open(out / "results.csv") as f:
        rows = {float(r["shank_length"]): r for r in csv.DictReader(f)}
    assert set(rows) == {0.30, 0.45}
    for shank, r in rows.items():
        assert r["fell"] == "0" and r["diverged"] == "0", shank
        assert int(r["hops"]) >= 6, shank
        assert abs(float(r["apex_height"]) - 0.10) < 0.015, (shank, r["apex_height"])


def test_a_speed_the_gait_ramps_to_for_longer_than_the_run_is_noted():
    """The gaits ramp their speed reference from rest by `speed_step` a hop: --speed 1,0 for 4 s moved at 0.17 m/s,
    and nothing said why. The note names the hops and, at each gravity where they outlast the run, their flights'
    ballistic time (a lower bound on the ramp); otherwise, and for controllers without the ramp, there is none."""
    from hopper_mjx import control

    step = raibert.RaibertConfig().speed_step
    hops = math.ceil(1.0 / step)
    flight = {g: hops * 2 * math.sqrt(2 * 0.1 / g) for g in (1.62, 9.81)}  # s: each hop's rise and fall of 0.1 m
    assert 4.0 < flight[9.81] < 6.0 < flight[1.62]
    note = control.ramp_note("raibert", (1.0, 0.0), 0.1, [9.81, 1.62], 4.0)
    assert note.startswith(f"note: raibert ramps its speed from rest to --speed 1,0 m/s by {step:g} m/s a hop, "
                           f"{hops} hops: their flights alone take {flight[1.62]:.1f} s at g = 1.62 m/s², "
                           f"{flight[9.81]:.1f} s at g = 9.81 m/s², more than --duration 4 s")
    only_moon = control.ramp_note("jump", (0.0, -1.0), 0.1, [9.81, 1.62], 6.0)  # either axis; Earth's flights fit
    assert f"{flight[1.62]:.1f} s at g = 1.62 m/s², more than" in only_moon and "9.81" not in only_moon
    assert control.ramp_note("raibert", (1.0, 0.0), 0.1, [9.81, 1.62], 20.0) is None  # long enough everywhere
    assert control.ramp_note("raibert", (0.0, 0.0), 0.1, [9.81], 1.0) is None
    assert control.ramp_note("hold", (1.0, 0.0), 0.1, [9.81], 1.0) is None
    assert control.ramp_note("policy:runs/hop-ppo", (1.0, 0.0), 0.1, [9.81], 1.0) is None
    # Gaits run side by side on one command (a sweep of several controllers) share one line; a policy is left out.
    both = control.ramp_note(["jump", "policy:runs/hop-ppo", "raibert"], (1.0, 0.0), 0.1, [9.81, 1.62], 4.0)
    assert both == note.replace("raibert ramps its speed", "jump and raibert ramp their speed").replace(
        "; its robots", "; their robots")
    # The commands' batch (simulate, ros.record, render --video) gives its gait, command and gravities.
    from hopper_mjx import cli, simulate

    batch = cli.check_batch(simulate.parser().parse_args(["--controller", "raibert", "--speed", "1,0", "--gravity",
                                                          "9.81,1.62,9.81"]))
    assert cli.speed_note(batch, 4.0) == note
