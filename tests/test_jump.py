"""The jump: Raibert's gait that leaps what lies ahead. Its look at the ground against the terrain's own geometry, its
drawn-up leg against MuJoCo C, and its leaps over the obstacle sweep's blocks on the chain engine."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hopper_mjx import control, terrain
from hopper_mjx.control import jump, kinematics, raibert
from hopper_mjx.hardware.signals import SensedGround
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import Robot
from hopper_mjx.sim import gravity_vectors

BLOCK = "obstacle:height={h},x=0.6,length=0.1,size=8x4"  # the obstacle sweep's block, on its 4 cm grid
GAP = "gaps:width={w},spacing=8,depth=1,x=0.6,size=8x4"  # the gaps sweep's trench, on the same grid


def _sensed(spec: str) -> SensedGround:
    t = terrain.parse(spec).terrain()
    return SensedGround(jnp.asarray(t.heights, jnp.float32), jnp.zeros(1), jnp.zeros(3), tuple(t.size))


def test_the_obstacle_ahead_is_the_block_as_the_engine_collides_with_it():
    """A 0.3 m block from x = 0.6 to 0.7: the grid (cell 4 cm) makes each vertical face a ramp one cell wide, so ground
    5 cm up (`STEP_UP`) starts 7 mm up the near ramp (x = 0.567) and ends 7 mm before the far one's foot (0.713). The
    samples, 2 cm apart, find both within one sample; the top is the block's height. Flat ground, ground behind the
    foot, and no direction of travel hold no obstacle."""
    ground = _sensed(BLOCK.format(h=0.3))
    ahead = jnp.array([1.0, 0.0])
    spacing = (jump.LOOK_SPAN + 0.03) / (jump.SAMPLES - 1)
    for foot_x in (0.1, 0.3, 0.45):
        seen, face, far, top = (float(v) for v in jump.obstacle(ground, jnp.array([foot_x, 0.0]), ahead, 0.03))
        assert seen == 1.0 and top == pytest.approx(0.3)
        assert foot_x + face == pytest.approx(0.567, abs=spacing)
        assert foot_x + far == pytest.approx(0.713, abs=spacing)
    assert not jump.obstacle(_sensed(BLOCK.format(h=0.0)), jnp.array([0.3, 0.0]), ahead, 0.03)[0]
    assert not jump.obstacle(ground, jnp.array([0.9, 0.0]), ahead, 0.03)[0]  # past it
    assert not jump.obstacle(ground, jnp.array([0.3, 0.0]), -ahead, 0.03)[0]  # going the other way
    assert not jump.obstacle(ground, jnp.array([0.3, 0.0]), jnp.zeros(2), 0.03)[0]  # hopping in place


def test_a_gap_ahead_is_found_from_its_lip_to_its_far_side_and_a_drop_with_none_in_view_is_not():
    """A 0.45 m gap from x = 0.6, 1 m deep: ground 5 cm down starts 2 mm into the near ramp (x = 0.562) and the far
    side is back within 5 cm of the lip at 1.078; its top is the lip's level, the ground under the foot. A gap whose
    far side is beyond `LOOK_SPAN` is a step down, hopped down, not leapt."""
    ahead = jnp.array([1.0, 0.0])
    spacing = (jump.LOOK_SPAN + 0.03) / (jump.SAMPLES - 1)
    ground = _sensed(GAP.format(w=0.45))
    for foot_x in (0.1, 0.3, 0.45):
        seen, face, far, top = (float(v) for v in jump.obstacle(ground, jnp.array([foot_x, 0.0]), ahead, 0.03))
        assert seen == 1.0 and top == pytest.approx(0.0, abs=1e-6)
        assert foot_x + face == pytest.approx(0.562, abs=spacing)
        assert foot_x + far == pytest.approx(1.078, abs=spacing)
    assert not jump.obstacle(_sensed(GAP.format(w=1.5)), jnp.array([0.3, 0.0]), ahead, 0.03)[0]


def test_a_gaps_leap_rises_as_high_as_carrying_it_over_needs_with_the_most_boost():
    """`carry_speed`: the flight 2·up/g at the lift-off speed v plus the boost's share of the stance's vertical speed
    change carries the COM exactly `travel` with the boost at `MAX_BOOST`; nothing to carry needs no rise."""
    travel, v, push, length, g = 0.6, 0.3, 1.5, 0.64, 9.81
    up = float(jump.carry_speed(travel, v, push, length, g))
    assert (v + jump.MAX_BOOST / length * (up + push)) * 2.0 * up / g == pytest.approx(travel, rel=1e-5)
    assert float(jump.carry_speed(0.0, v, push, length, g)) == pytest.approx(0.0, abs=1e-6)
    assert float(jump.carry_speed(2 * travel, v, push, length, g)) > up


def test_below_the_moon_a_gaps_leap_carries_across_by_height_not_boost():
    """`gap_lift` for a slow hop (0.5 m/s²): where the lift-off that carries the COM `travel` at the speed it has,
    boost-free, is within `LEVEL_LIFT`, the leap takes it, and the boost `_launch` sizes for it is nil; where it is
    past `LEVEL_LIFT`, the boost gives the rest. Hops that are not slow (the Moon, Earth) keep `carry_speed`'s, with
    the most boost."""
    travel, v, push, length = 1.0, 0.3, 0.4, 0.64

    def boost(up, v, g):  # m: as `_launch` sizes it
        return (travel / (2.0 * up / g) - v) * length / (up + push)

    up = float(jump.gap_lift(travel, v, push, length, 0.5, True))
    assert v * 2.0 * up / 0.5 == pytest.approx(travel, rel=1e-5) and up <= jump.LEVEL_LIFT
    assert boost(up, v, 0.5) == pytest.approx(0.0, abs=1e-6)
    assert up > float(jump.carry_speed(travel, v, push, length, 0.5))
    slow = float(jump.gap_lift(travel, 0.15, push, length, 0.5, True))  # boost-free would need 1.67 m/s
    assert slow == pytest.approx(jump.LEVEL_LIFT)
    assert 0.0 < boost(slow, 0.15, 0.5) < jump.MAX_BOOST / 2
    for g, push in ((1.62, 0.8), (9.81, 1.5)):
        assert float(jump.gap_lift(0.3, v, push, length, g, False)) == float(jump.carry_speed(0.3, v, push, length, g))


def test_the_drawn_up_leg_drops_the_foot_as_much_as_tuck_drop_says_in_mujoco_c(mj_model):
    """The foot `TUCK_AHEAD` ahead of the hip on the shortest leg the knee allows less `TUCK_KNEE`: its joint angles
    are within their ranges, and MuJoCo C puts the foot's bottom `tuck_drop` below the level base origin."""
    robot = Robot.of(mj_model)
    leg, lay = robot.leg, Layout.of(mj_model)
    length = float(jump.tuck_length(robot, leg))
    assert length == pytest.approx(float(kinematics.leg_length(leg, lay.joint_range[2][0] + jump.TUCK_KNEE)))
    down = leg.hfe_below_haa + np.sqrt(length**2 - jump.TUCK_AHEAD**2)
    angles = np.asarray(kinematics.inverse(leg, jnp.array([jump.TUCK_AHEAD, 0.0, -down])))
    for (low, high), q in zip(lay.joint_range, angles):
        assert low <= q <= high
    d = mujoco.MjData(mj_model)
    d.qpos[:] = mj_model.qpos0
    d.qpos[2] = 2.0
    d.qpos[list(lay.joint_qpos)] = angles
    mujoco.mj_kinematics(mj_model, d)
    foot_bottom = d.geom_xpos[lay.foot_geom, 2] - mj_model.geom_size[lay.foot_geom, 0]
    assert d.qpos[2] - foot_bottom == pytest.approx(float(jump.tuck_drop(robot, leg)), abs=1e-5)
    # Drawn up, the foot is higher than standing by the most that the knee's stop allows less its margin.
    assert float(jump.tuck_drop(robot, leg)) < robot.standing_height - 0.1


def test_a_tall_blocks_leap_lands_its_knee_past_the_far_edge_in_mujoco_c(mj_model):
    """`jump.knee_room`: in the landing pose (the virtual leg at Raibert's length, the hip over the foot, the foot on
    the ground past a block's far edge), MuJoCo C puts the knee `KNEE_CLEAR` past the edge and its height where
    knee_room says; a block below the knee gets no room, one above it the room that carries the knee past."""
    robot = Robot.of(mj_model)
    leg, lay = robot.leg, Layout.of(mj_model)
    length = raibert.RaibertConfig().leg_length
    angles = np.asarray(kinematics.inverse(leg, jnp.array([0.0, 0.0, -(leg.hfe_below_haa + length)])))
    d = mujoco.MjData(mj_model)
    d.qpos[:] = mj_model.qpos0
    d.qpos[list(lay.joint_qpos)] = angles
    mujoco.mj_kinematics(mj_model, d)
    foot = d.geom_xpos[lay.foot_geom]
    knee = d.xanchor[mj_model.joint("kfe_joint").id]
    behind, up = foot[0] - knee[0], knee[2] - (foot[2] - leg.foot_radius)  # the knee from the foot on the ground
    assert 0.1 < behind < 0.2 and up == pytest.approx(0.35, abs=0.01)
    far = 0.7
    for top in (up + 0.05, up + 0.3):  # above the knee: the foot set far + radius + LAND_BEYOND + room past it
        room = float(jump.knee_room(leg, top, 0.0, length))
        centre = far + leg.foot_radius + jump.LAND_BEYOND + room
        assert centre - behind == pytest.approx(far + jump.KNEE_CLEAR, abs=1e-5)
    assert float(jump.knee_room(leg, up - 0.05, 0.0, length)) == 0.0  # below it: the landing as before


FLAT_GRAVITY = (1.62, 3.71, 9.81)
FLAT_DURATION = 4.5  # s: the Moon's full-stroke hop is at its top (both tests run one compiled rollout of the jump)


def test_on_the_flat_plane_the_jump_is_raibert(sim):
    """Nothing to look at, and a hop its ordinary stroke gives: Raibert's trajectory. Not bit for bit: the jump's
    program holds the full stroke beside Raibert's stance and XLA fuses the two otherwise, so the float32 rounding
    differs: within 1e-4 m over 4.5 s (2e-5 m measured) and, in the angles, within 1e-3 rad (1.1e-4 rad measured at
    a knee's landing on an AVX-512 EPYC, 3 Dec), where a leap or the full stroke moves the knee by tenths of a rad."""
    runs = []
    for build in (raibert.raibert, jump.jump):
        params = raibert.raibert_params(len(FLAT_GRAVITY), height=0.1, speed=(0.3, 0.0))
        final, traj = sim.run(gravity_vectors(FLAT_GRAVITY), build(sim.robot), params, duration=FLAT_DURATION)
        runs.append(np.asarray(traj.qpos))
    np.testing.assert_allclose(runs[0][:, :, :3], runs[1][:, :, :3], rtol=0, atol=1e-4)  # the base, m
    np.testing.assert_allclose(runs[0][:, :, 3:], runs[1][:, :, 3:], rtol=0, atol=1e-3)  # its quaternion, the joints


def test_asked_for_more_the_jump_takes_the_full_stroke_to_most_of_the_bound(sim, mj_model):
    """Asked for a 6 m rise in place with ideal motors, the first hop rises at least 70 % of the energy bound's apex
    (`hardware.bound`) at the Moon, Mars and Earth; its stance reached down to the full stroke's bottom
    (`control.stroke`), and the base stays within the hop metrics' 0.8 rad of level up to that hop's top."""
    from hopper_mjx.control import stroke
    from hopper_mjx.hardware import bound
    from hopper_mjx.metrics.hops import roll_pitch

    params = raibert.raibert_params(len(FLAT_GRAVITY), height=6.0)
    _, traj = sim.run(gravity_vectors(FLAT_GRAVITY), jump.jump(sim.robot), params, duration=FLAT_DURATION)
    qpos = np.asarray(traj.qpos)
    bounds = bound.bounds(mj_model, "ideal", FLAT_GRAVITY)
    lowest = Layout.of(mj_model).joint_range[2][0]
    for i, g in enumerate(FLAT_GRAVITY):
        top = int(np.argmax(qpos[i, :, 2]))
        rise = qpos[i, top, 2] - sim.robot.standing_height
        assert rise >= 0.7 * bounds[g].apex_rise, (g, rise, bounds[g].apex_rise)
        assert qpos[i, :top, -1].min() < lowest + stroke.LOW_MARGIN + 0.05
        roll, pitch = roll_pitch(qpos[i, :top, 3:7])
        assert np.abs(roll).max() < 0.8 and np.abs(pitch).max() < 0.8


# The sweeps' cells the jump must get past (block or gap spec, its size m, gravity m/s²): the blocks beyond what half
# of Raibert's robots clear there (docs/sweeps.md), the gaps none of Raibert's crossed at Mars and Earth, a block
# at Ceres, where a slow lift-off's leap is launched and pushed as `jump`'s "slow hops" say, and a gap at 0.5 m/s²,
# leapt by height (`gap_lift`); a 0.15 m block at Earth, Mars and the Moon, low enough that its leap takes the most
# boost (`FIFTEEN`); then the two Moon blocks whose leaps tests/test_leap_against_c.py replays on C (their leaps land
# on the foot alone).
FIFTEEN = ((BLOCK, 0.15, 9.81), (BLOCK, 0.15, 3.71), (BLOCK, 0.15, 1.62))
SWEEP_CELLS = ((BLOCK, 0.8, 1.62), (BLOCK, 0.3, 3.71), (BLOCK, 0.2, 9.81),
               (GAP, 0.45, 1.62), (GAP, 0.45, 3.71), (GAP, 0.45, 9.81), (BLOCK, 0.3, 0.28), (GAP, 0.6, 0.5)) + FIFTEEN
REPLAYED_CELLS = ((BLOCK, 0.6, 1.62), (BLOCK, 0.7, 1.62))
LEAP_CELLS = SWEEP_CELLS + REPLAYED_CELLS
LEAP_SPEED = (0.3, 0.0)  # m/s, the sweeps'
LEAP_DURATION = 12.0  # s: Ceres's robot reaches the block at about 7 s and its leap flies 2.5 s


def leap_run():
    """The jump over `LEAP_CELLS` with DC motors on the chain engine, one model and each instance's ground its own,
    `LEAP_DURATION` at the sweeps' speed, every state, foot contact and applied torque recorded at the physics rate:
    one compiled program for both files (conftest's `jump_leaps`). Returns (sim, mj_model, grids, trajectory)."""
    from hopper_mjx.scenario import Physics
    from hopper_mjx.sweep.runner import recorded

    physics = Physics(ground=terrain.parse(BLOCK.format(h=0.3)), motor="dc", engine="chain")
    sim = physics.sim(chunk=len(LEAP_CELLS))
    grids = np.stack([terrain.parse(spec.format(h=size, w=size)).terrain().heights for spec, size, _ in LEAP_CELLS])
    controller, params = control.make("jump", sim.robot, len(LEAP_CELLS), height=0.1, speed=LEAP_SPEED)
    _, traj = sim.run(gravity_vectors([g for *_, g in LEAP_CELLS]), controller, params, duration=LEAP_DURATION,
                      sensors=recorded(physics.timestep, torque=True), key=0, ground=grids)
    return sim, physics.mj_model, grids, jax.tree_util.tree_map(np.asarray, traj)


def leap_bands() -> np.ndarray:
    """(cells, 1, 3) each `LEAP_CELLS` cell's obstacle as the sweeps' metrics take it: (near, far, height), a gap's
    height -1."""
    return np.array([[[0.6, 0.7, size] if spec == BLOCK else [0.6, 0.6 + size, -1.0]] for spec, size, _ in LEAP_CELLS])


def test_the_jump_leaps_the_sweeps_blocks_and_gaps(jump_leaps):
    """Each robot's foot comes down beyond the block's far edge (the sweep's `cleared`), and the base rose at
    least as high as the drawn-up foot needs to pass over the top; each gap's robot lands beyond a 0.45 m gap, which
    none of Raibert's robots crossed at Mars and Earth in the gaps sweep of 3 Dec (docs/sweeps.md); Ceres's robot clears
    a 0.3 m block, which none of the jump's 16 did before its slow-hop rules (the five-gravity sweep of 3 Dec); and at
    0.5 m/s² the robot lands beyond a 0.6 m gap, which none of 16 did before a gap's leap took height for boost."""
    from hopper_mjx.metrics import hops

    sim, _, _, traj = jump_leaps
    cleared = hops.terrain_metrics(traj, command_speed=LEAP_SPEED, obstacles=leap_bands())["obstacles_cleared"]
    assert list(cleared) == [1] * len(LEAP_CELLS)
    drop = float(jump.tuck_drop(sim.robot, sim.robot.leg))
    for (spec, h, _), z in zip(LEAP_CELLS, traj.qpos[:, :, 2]):
        if spec == BLOCK:
            assert z.max() >= h + drop


def test_a_boosted_leap_over_a_block_lands_near_level(jump_leaps):
    """Mars's 0.3 m and Earth's 0.2 m blocks are leapt with a boost (the launching foot set behind the neutral point):
    the launching stance steers the spin that lands the body level (`jump.landing_spin`), so the first landing beyond
    each is tilted under 17°. With Raibert's servo in that stance (damping the spin to zero, levelling the body)
    Earth's landed 23° off upright, at the 0.4 rad tilt budget."""
    from hopper_mjx.metrics import hops

    _, _, _, traj = jump_leaps
    tilt = hops.landing_metrics(traj, leap_bands())["past_tilt"]  # deg from upright, at the first touchdown beyond
    boosted = [LEAP_CELLS.index(cell) for cell in ((BLOCK, 0.3, 3.71), (BLOCK, 0.2, 9.81))]
    assert np.all(tilt[boosted] < 17.0), tilt[boosted]


def test_a_boosted_block_leaps_push_speeds_the_com_on_by_its_lean_and_its_robot_hops_on(jump_leaps):
    """`jump.forward_work` sizes a boosted block leap's extra thrust on this: from the launching stance's bottom, the
    COM tanφ ahead of the foot, the push that lifts the COM at `up` speeds it on by about up·tanφ. On the chain engine
    each boosted leap's COM gains 1-2× that from the bottom to lift-off (the lean grows as the COM moves over the
    foot, so the sizing is the least of it); a leap with no lean gains nothing. And the 0.15 m blocks' robots are up at
    the end: with the thrust sized for the rise alone (4412baa), Earth's fell after its landing."""
    sim, mj_model, _, traj = jump_leaps
    data = mujoco.MjData(mj_model)

    def com(q, v):  # the whole robot's COM and its velocity, MuJoCo C
        data.qpos[:], data.qvel[:] = q, v
        mujoco.mj_forward(mj_model, data)
        mujoco.mj_subtreeVel(mj_model, data)
        return data.subtree_com[1].copy(), data.subtree_linvel[1].copy()

    gains = {}
    for i, (spec, h, g) in enumerate(LEAP_CELLS):
        if spec != BLOCK:
            continue
        q, v, touching = traj.qpos[i], traj.qvel[i], traj.contact.flag[i]
        liftoffs = np.flatnonzero(~touching[1:] & touching[:-1]) + 1
        touchdowns = np.flatnonzero(touching[1:] & ~touching[:-1]) + 1
        # The leap: the flight in which the base passes the face (the Moon's 0.8 m leap comes down on the top's edge).
        leap = next((t for t in liftoffs if q[t, 0] < 0.6 < q[touchdowns[touchdowns > t][0], 0]), None)
        if leap is None:
            continue
        start = touchdowns[touchdowns < leap][-1]
        bottom = start + int(np.argmin(q[start:leap, 2]))
        (c, v_bottom), (_, v_off) = com(q[bottom], v[bottom]), com(q[leap], v[leap])
        foot = traj.contact.pos[i, bottom]
        lean = (c[0] - foot[0]) / (c[2] - foot[2])
        gains[(h, g)] = (lean, (v_off[0] - v_bottom[0]) / (v_off[2] * lean))
    boosted = [cell for cell, (lean, _) in gains.items() if lean > 0.05]
    assert {(h, g) for _, h, g in FIFTEEN + ((BLOCK, 0.3, 3.71), (BLOCK, 0.2, 9.81))} <= set(boosted), gains
    assert all(1.0 < gains[cell][1] < 2.0 for cell in boosted), gains
    up = traj.qpos[[LEAP_CELLS.index(cell) for cell in FIFTEEN], -1, 2]
    assert np.all(up > 0.5 * sim.robot.standing_height), up


def test_a_block_or_gaps_sweep_runs_the_jump_unless_told_raibert():
    from hopper_mjx.sweep import __main__ as sweep

    for kind in ("obstacle", "gaps"):
        assert sweep.parser().parse_args([kind]).controller == "jump"
        assert sweep.parser().parse_args([kind, "--controller", "raibert"]).controller == "raibert"
        # A trained policy runs there too (tests/test_policy.py); balance, which stands, is refused in one line
        # (tests/test_bad_inputs.py).
        assert sweep.parser().parse_args([kind, "--controller", "policy:run"]).controller == "policy:run"
