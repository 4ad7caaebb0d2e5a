"""The jump's leap over a block on the chain engine against MuJoCo C: the torques the jump's DC motors applied in the
core (float32) are replayed, from the flight before the leap, on the chain's float64 step and on C. Both go through the
launching stance, the high flight over the block and the landing stance beyond it on one base path (within 1e-3 m),
until a leg's box first touches the block: from there the chain's box contacts are not C's (test_chain_terrain_box)."""

from __future__ import annotations

import inspect

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from test_chain_terrain import _step_fn
from test_jump import BLOCK, LEAP_CELLS, REPLAYED_CELLS

from hopper_mjx import model, terrain
from hopper_mjx.control import jump
from hopper_mjx.engine import chain
from hopper_mjx.shell import programs

CELLS = tuple((h, g) for _, h, g in REPLAYED_CELLS)  # (block height m, gravity m/s²)
REPLAY = 2600  # steps (2.6 s) from the apex before the launch: past the landing stance and a leg's first touch
FAR_EDGE = 0.7  # m, the block's far face (x = 0.6 m, 0.1 m long)


@pytest.fixture(scope="module")
def leap(jump_leaps):
    """The jump over these blocks in the core (conftest's `jump_leaps`, as test_jump's cells: one model, each
    instance's block its ground), every state, foot contact and applied torque at the physics rate. The leaps launch
    at about 5.1 s and land at 6.9-7.0 s."""
    sim, mj_model, grids, traj = jump_leaps
    cells = [LEAP_CELLS.index(cell) for cell in REPLAYED_CELLS]
    return mj_model, sim.robot, grids[cells], jax.tree_util.tree_map(lambda x: x[cells], traj)


def leap_start(z: np.ndarray, flag: np.ndarray) -> int:
    """The step of the apex of the flight before the leap's launching stance: the leap is the flight of the highest
    apex, its launching stance the one before it."""
    touchdowns = np.flatnonzero(flag[1:] & ~flag[:-1]) + 1
    liftoffs = np.flatnonzero(~flag[1:] & flag[:-1]) + 1
    launch = touchdowns[touchdowns < z.argmax()][-1]
    before = liftoffs[liftoffs < launch][-1]
    return int(before + z[before:launch].argmax())


def _replay_program(engine: chain.ChainEngine, mj_model: mujoco.MjModel) -> programs.Stored:
    """The chain's float64 step (`_step_fn`, vmapped as the core does) scanned over a torque record: qpos after each
    step. Kept on disk as the core's programs are (`shell.programs`): its trace alone takes ~25 s."""
    step = _step_fn(engine, chain.BATCH_AXIS)

    def replay(params, qpos, qvel, ctrl, gravity):
        def one(carry, u):
            qpos, qvel, warm = carry
            qpos, qvel, warm, _, _ = step(params, qpos, qvel, u, gravity, warm)
            return (qpos, qvel, warm), qpos

        return jax.lax.scan(one, (qpos, qvel, jnp.zeros_like(qvel)), ctrl)[1]

    code = inspect.getsource(_step_fn) + inspect.getsource(_replay_program)  # the tests' code is not the package's
    key = repr(("test_leap_against_c replay", code, programs.model_digest(mj_model), engine.program_key()))
    return programs.Stored(replay, key, engine.compiler_options)


def c_replay(h: float, g: float, qpos, qvel, ctrl) -> tuple[np.ndarray, list]:
    """MuJoCo C (the model's own options) from (qpos, qvel) on the block of height `h` at gravity `g`, driven by `ctrl`
    (steps, nu): its qpos after each step, and each step's contacts as (geom name, position)."""
    m = model.load(terrain=terrain.parse(BLOCK.format(h=h)).terrain())
    m.opt.gravity[:] = (0.0, 0.0, -g)
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = qpos, qvel
    path, contacts = [], []
    for u in ctrl:
        d.ctrl[:] = u
        mujoco.mj_step(m, d)
        path.append(d.qpos.copy())
        contacts.append([(m.geom(c.geom2).name, c.pos.copy()) for c in d.contact[:d.ncon]])
    return np.array(path), contacts


@pytest.fixture(scope="module")
def replays(leap):
    """Per cell, from the apex before the leap's launching stance, `REPLAY` steps of the recorded controls on C and on
    the chain (float64, one program for both cells): (start steps, C's qpos, the chain's, C's contacts, the robot)."""
    mj_model, robot, grids, traj = leap
    layout = robot.layout
    ctrl = np.zeros(traj.torque.shape[:2] + (mj_model.nu,))
    ctrl[..., list(layout.actuator_of_joint)] = traj.torque / np.asarray(layout.gear)  # the ctrl the core applied
    starts = [leap_start(q[:, 2], f.astype(bool)) for q, f in zip(traj.qpos, traj.contact.flag)]
    assert max(starts) + REPLAY <= traj.qpos.shape[1], "the run holds the whole replay"
    qpos = np.stack([traj.qpos[i, s] for i, s in enumerate(starts)]).astype(np.float64)
    qvel = np.stack([traj.qvel[i, s] for i, s in enumerate(starts)]).astype(np.float64)
    us = np.stack([ctrl[i, s:s + REPLAY] for i, s in enumerate(starts)])  # (cells, steps, nu)
    theirs = [c_replay(h, g, qpos[i], qvel[i], us[i]) for i, (h, g) in enumerate(CELLS)]
    with jax.enable_x64(True):
        engine = chain.make_for_tools(mj_model)
        params = engine.with_heights(np.asarray(grids, np.float64))
        gravity = np.array([[0.0, 0.0, -g] for _, g in CELLS])
        ours = _replay_program(engine, mj_model)(params, *(jnp.asarray(x) for x in (
            qpos, qvel, us.transpose(1, 0, 2), gravity)))
    ours = np.asarray(ours).transpose(1, 0, 2)  # (cells, steps, nq)
    return starts, np.array([path for path, _ in theirs]), ours, [contacts for _, contacts in theirs], robot


def foot_only(contacts: list) -> int:
    """Steps before the first contact of anything but the foot (a leg's or the base's box) with the ground."""
    return next((k for k, step in enumerate(contacts) if any(name != model.FOOT_GEOM for name, _ in step)),
                len(contacts))


def landing(path: np.ndarray, contacts: list) -> tuple[int, int, float]:
    """(touchdown, lift-off) steps of the stance after the leap's apex on C's path, and the foot's first contact x."""
    feet = np.array([any(name == model.FOOT_GEOM for name, _ in step) for step in contacts])
    down = path[:, 2].argmax() + feet[path[:, 2].argmax():].argmax()
    up = down + (~feet[down:]).argmax()
    return int(down), int(up), float(next(p[0] for name, p in contacts[down] if name == model.FOOT_GEOM))


def test_the_replay_leaps_the_block_and_lands_beyond_it(replays):
    """On C's path: an apex high enough for the drawn-up foot to pass over the top, 0.4 m over the hop's before, the
    foot down beyond the far edge before a leg's box touches, a metre of base path. (Since the leap lands its knee
    past a tall block's edge, `jump.knee_room`, the 0.6 m block's thigh grazes the far face 38 ms into the landing
    stance, as the knee folds back: the comparison with C runs to there.)"""
    starts, c, _, contacts, robot = replays
    drop = float(jump.tuck_drop(robot, robot.leg))
    for (h, g), start, path, touching in zip(CELLS, starts, c, contacts):
        apex = path[:, 2].argmax()
        down, up, x = landing(path, touching)
        clean = foot_only(touching)
        travel = np.linalg.norm(np.diff(path[:clean, :3], axis=0), axis=1).sum()
        print(f"\nblock {h} m at {g} m/s²: from the apex at {start * 1e-3:.3f} s (z {path[0, 2]:.3f} m), leap apex"
              f" {path[apex, 2]:.3f} m at {(start + apex) * 1e-3:.3f} s, foot down at x {x:.3f} m from"
              f" {(start + down) * 1e-3:.3f} s to {(start + up) * 1e-3:.3f} s, a leg's box touches at"
              f" {(start + clean) * 1e-3:.3f} s, base path {travel:.2f} m till then")
        assert path[apex, 2] >= h + drop, "the drawn-up foot passes over the top"
        assert path[apex, 2] - path[0, 2] >= 0.4, "a leap, not a hop"
        assert x > FAR_EDGE, "the foot comes down beyond the block"
        assert down < clean, "the foot lands before any other contact"
        assert travel > 1.0


def test_the_leap_on_the_chain_follows_mujoco_c(replays):
    """The base paths of the chain (float64) and C through the launch, the flight, the landing stance and after, until
    a leg's box touches the block (printed after: there the chain's box-prism contacts are not C's)."""
    starts, c, ours, contacts, _ = replays
    err = np.linalg.norm(ours[:, :, :3] - c[:, :, :3], axis=2)  # (cells, steps) m
    worst = 0.0
    for (h, g), start, e, path, touching in zip(CELLS, starts, err, c, contacts):
        clean = foot_only(touching)
        down, up, _ = landing(path, touching)
        worst = max(worst, e[:clean].max())
        after = (f"till a leg's box touches ({(start + clean) * 1e-3:.3f} s), {e[clean:clean + 50].max():.1e} m 50 ms"
                 " after" if clean < len(e) else "to the replay's end, where no leg's box has touched")
        print(f"\nblock {h} m at {g} m/s²: base path max |chain - C| {e[:down].max():.1e} m to the landing,"
              f" {e[:up].max():.1e} m through its stance, {e[:clean].max():.1e} m {after},"
              f" {e.max():.1e} m at {(start + REPLAY) * 1e-3:.3f} s")
    assert worst <= 1e-3, f"the chain's base path leaves C's by {worst:.2e} m"
