"""bench at a tiny size: a well-formed, physically sensible record (never any timing assertion)."""

import json
import math

import numpy as np
import pytest

from hopper_mjx.perf import bench

# A robot per instance on both sides (the core's run-time values, native's model per instance), with a
# drawn gear, masses and leg: the two agree only if each native model is its instance's robot.
ROBOTS = "body_mass=scale(0.8,1.2),actuator_gear=scale(0.8,1.2),shank_length=scale(0.8,1.2),foot_friction=0.4..1"


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    path = tmp_path_factory.mktemp("bench") / "bench.json"
    argv = ["--num", "4", "--steps", "200", "--repeat", "1", "--randomize", ROBOTS, "--env", "hop",
            "--env-actions", "random", "--json", str(path)]
    assert bench.main(argv) == 0
    return json.loads(path.read_text())


def test_json_has_finite_positive_rates(record):
    for key in ("core_steps_per_s", "native_steps_per_s", "ratio", "compile_s", "peak_rss_mb",
                "core_cpu_us_per_step", "native_cpu_us_per_step", "cpu_ratio"):
        assert math.isfinite(record[key]) and record[key] > 0, key
    assert record["num"] == 4 and record["steps"] == 200 and record["randomize"]
    assert record["ratio"] == pytest.approx(record["core_steps_per_s"] / record["native_steps_per_s"])
    assert record["devices"] >= 1 and record["native_threads"] >= 1
    assert record["diverged"] == 0
    assert record["engine"] == "chain"  # auto picks it for the monoped


def test_the_env_is_timed_over_the_physics_steps_it_stepped(record):
    """--env hop under random actions: the task's training env on the same robots, 200 physics steps of 1 ms at
    50 Hz: every instance's simulated time is 0.2 s (none fell in it, so no auto-reset started one again), its
    rates agree with each other, and the comparison with the core's is the ratio of the two rates."""
    assert record["env_task"] == "hop" and record["env_policy_rate_hz"] == pytest.approx(50.0)
    assert record["env_actions"] == "random" and "random actions" in bench.format_table(record)
    np.testing.assert_allclose(record["env_final_time_s"], [0.2] * 4, atol=1e-5)
    assert math.isfinite(record["env_physics_steps_per_s"]) and record["env_physics_steps_per_s"] > 0
    assert record["env_physics_steps_per_s"] == pytest.approx(20 * record["env_steps_per_s"])
    assert record["env_to_core"] == pytest.approx(record["env_physics_steps_per_s"] / record["core_steps_per_s"])
    assert "env hop physics steps/s" in bench.format_table(record)
    # A physics step with the env's work around it. Brax compiles the env with XLA's default (fusion) emitters, which
    # write a stored stage's outputs a kernel each where the core's classic ones write a dozen a kernel
    # (docs/performance.md, c31): more kernels than the core's step with its controller, not several steps' worth.
    assert record["kernels_per_step"] < record["env_kernels_per_pass"] < 3 * record["kernels_per_step"]


def test_mjx_and_native_step_the_same_physics(record):
    # 0.2 s from 5 cm, through touchdown under the stronger gravities, each instance its own robot: both sides
    # must agree to float32 precision (the core runs float32).
    assert record["max_final_qpos_gap"] < 1e-4
    assert record["native_final_base_height_m"] == pytest.approx(record["core_final_base_height_m"], abs=1e-5)


def test_native_hold_model_is_the_hold_law(mj_model):
    import mujoco

    from hopper_mjx.control.base import HOLD_GAINS
    from hopper_mjx.model.layout import Layout

    layout = Layout.of(mj_model)
    m = bench.native_hold_model(mj_model, layout, **HOLD_GAINS)
    d = mujoco.MjData(m)
    qadr, dadr = list(layout.joint_qpos), list(layout.joint_dof)
    d.qpos[qadr] = (0.01, 0.3, -0.5)
    d.qvel[dadr] = (0.2, -1.0, 0.5)
    target = np.array([0.0, 0.32, -0.2])  # the knee error saturates its motor
    d.ctrl[list(layout.actuator_of_joint)] = target
    mujoco.mj_forward(m, d)
    expected = np.clip(HOLD_GAINS["p"] * (target - d.qpos[qadr]) - HOLD_GAINS["d"] * d.qvel[dadr],
                       -np.array(layout.effort_limit), layout.effort_limit)
    np.testing.assert_allclose(d.actuator_force[list(layout.actuator_of_joint)], expected, rtol=1e-12)
    assert np.any(np.abs(expected) == np.array(layout.effort_limit))  # the saturation is exercised


def test_gravities_span_moon_to_earth():
    g = bench.bench_gravities(200)
    assert g.shape == (200,) and g.min() == pytest.approx(1.62) and g.max() == pytest.approx(9.81)
    assert len(np.unique(g)) == bench.DISTINCT_GRAVITIES
    with pytest.raises(ValueError, match="--num"):
        bench.bench_gravities(0)


def test_table_and_plot_from_records(record, tmp_path):
    table = bench.markdown_table([record, record])
    assert table.count("\n") == 3 and f"| {record['num']} |" in table
    png = tmp_path / "scaling.png"
    both = [record, dict(record, num=8), dict(record, engine="mjx"), dict(record, num=8, engine="mjx")]
    bench.plot_scaling(both, str(png))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_arguments_exit_with_a_message(capsys):
    assert bench.main(["--num", "0", "--steps", "20"]) == 2
    assert "--num" in capsys.readouterr().err
    assert bench.main(["--num", "4", "--steps", "20", "--engine", "warp"]) == 2
    assert "--engine: unknown engine 'warp'" in capsys.readouterr().err
    assert bench.main(["--num", "4", "--steps", "20", "--engine", "chain,mjx"]) == 2
    assert "--engine: several engines are compared with --scaling only" in capsys.readouterr().err
    assert bench.main(["--num", "4", "--steps", "20", "--env", "jump"]) == 2
    assert "--env: unknown task 'jump'" in capsys.readouterr().err
    assert bench.main(["--num", "4", "--steps", "20", "--env", "hop", "--scaling", "4,8"]) == 2
    assert "--env times one N: give it without --scaling" in capsys.readouterr().err
    assert bench.main(["--num", "4", "--steps", "20", "--env-actions", "random"]) == 2
    assert "--env-actions is --env's: give --env TASK too" in capsys.readouterr().err
    assert bench.main(["--num", "4", "--steps", "20", "--randomize", "shank_length=0.05"]) == 2
    assert "--randomize: the leg of instance 0 (thigh 0.35 m, shank 0.05 m, foot radius 0.03 m) cannot reach the " \
           "floor" in capsys.readouterr().err


@pytest.fixture(scope="module")
def settling_chain():
    """A standing chain batch of 8, touched down and still settling, and its Newton iterations and the states
    each forward started from over 40 steps (perf.profile's)."""
    from hopper_mjx.perf import profile
    from hopper_mjx.scenario import Physics

    physics = Physics()
    sim, standing = profile.standing_batch(8, 100, physics)
    niter, states = profile.newton_iterations(sim.engine, standing.data.qpos, standing.data.qvel, standing.data.ctrl,
                                              standing.gravity, 40)
    return physics, sim, standing, niter, states


def test_profile_counts_the_newton_iterations_mujoco_c_runs(settling_chain):
    """perf.profile's replay: from each state of a standing chain batch, MuJoCo C (float64) runs the Newton
    iterations the chain (float32) ran, so the profile can say the batch's extra iterations are the physics' own."""
    from hopper_mjx.perf import profile

    physics, sim, standing, niter, states = settling_chain
    assert sim.engine.name == "chain"
    ctrl, gravity = np.asarray(standing.data.ctrl), np.asarray(standing.gravity)
    c = profile.c_iterations(physics.mj_model, states, ctrl, gravity)
    assert niter.shape == c.shape == (8, 40)
    print("\nC's Newton iterations (0, 1, ...):", np.bincount(c.ravel()), "the chain's:", np.bincount(niter.ravel()))
    assert np.mean(niter == c) >= 0.95
    assert len(np.unique(c)) >= 2, "the states take more than one count"
    moved = tuple(np.roll(x, 1, axis=1) for x in states)  # the states one step out of line: other counts
    assert np.mean(profile.c_iterations(physics.mj_model, moved, ctrl, gravity) == niter) < np.mean(niter == c)


def test_profile_cuts_feed_every_stage_to_the_next_steps_position_and_velocity(settling_chain):
    """perf.profile times each cut of the step as a loop of it: a stage whose outputs fed only the next velocity while
    the positions stood still was loop-invariant where it reads the positions alone (the kinematics, the ground's
    contacts), XLA hoisted it out of the timed loop, and its cost was counted in the solve's setup (on rough ground
    1.9 of the setup's 2.5 µs). Each cut's next qpos and qvel are now computed from its stages, not passed through."""
    import jax

    from hopper_mjx.perf import profile

    _, sim, standing, _, _ = settling_chain
    data = profile._chain_data(sim.engine, standing.data.qpos, standing.data.qvel, standing.data.ctrl)
    one = jax.tree_util.tree_map(lambda x: x[0], data)
    for depth in range(1, len(profile.CHAIN_STAGES) - 1):
        closed = jax.make_jaxpr(profile.chain_cut(sim.engine, depth))(sim.engine.model, one, standing.gravity[0])
        ins, outs = closed.jaxpr.invars, closed.jaxpr.outvars
        names = [jax.tree_util.keystr(path) for path, _ in jax.tree_util.tree_flatten_with_path(one)[0]]
        for name in (".qpos", ".qvel"):
            assert outs[names.index(name)] not in ins, (depth, name)  # computed, not the input passed through


def test_a_part_of_the_step_below_0_says_why():
    """On the plane the cuts before the setup cost more than the step they stand for (they keep outputs the whole
    step never computes), and the setup reads -0.12 µs: the table says so under it, and only then."""
    from hopper_mjx.perf import profile

    assert "below 0: the cuts before it keep" in profile._lines("head", [("a", 0.6), ("setup", -0.12)], 1.0)
    assert "below 0" not in profile._lines("head", [("a", 0.6), ("setup", 0.12)], 1.0)


def test_profile_solve_setup_cut_is_mujoco_c_with_no_newton_iteration(settling_chain):
    """perf.profile times the solve's setup as the step with the iteration cap at 0: from the same states its
    accelerations are MuJoCo C's with `opt.iterations = 0` (the better of the warm start and the smooth
    accelerations), and the Newton iterations the full step adds change them where the chain ran any."""
    import copy

    import jax

    from hopper_mjx.perf import profile

    physics, sim, standing, niter, states = settling_chain
    ctrl, gravity = np.asarray(standing.data.ctrl), np.asarray(standing.gravity)
    niter, (qpos, qvel, warm) = niter[:, :10], tuple(x[:, :10] for x in states)
    setup = profile.without_iterations(sim.engine)
    data = jax.vmap(lambda q, v, w, u: setup.make_data(q, v).replace(qacc_warmstart=w, ctrl=u))(
        qpos.reshape(80, -1), qvel.reshape(80, -1), warm.reshape(80, -1), np.repeat(ctrl, 10, axis=0))
    out = jax.vmap(setup.forward, in_axes=(None, 0, 0))(sim.engine.model, data, np.repeat(gravity, 10, axis=0))
    assert not np.any(np.asarray(out.solver_niter))
    m = copy.deepcopy(physics.mj_model)
    m.opt.iterations = 0
    c_qacc = profile.c_replay(m, (qpos, qvel, warm), ctrl, gravity, lambda d: d.qacc).reshape(80, -1)
    chain_qacc = np.asarray(out.qacc)
    scale = np.abs(c_qacc).max()
    assert np.abs(chain_qacc - c_qacc).max() <= 1e-4 * scale, np.abs(chain_qacc - c_qacc).max()
    full = np.asarray(jax.vmap(sim.engine.forward, in_axes=(None, 0, 0))(
        sim.engine.model, data, np.repeat(gravity, 10, axis=0)).qacc)
    ran = niter.reshape(80) > 0
    assert ran.sum() >= 8, "the states take Newton iterations"
    assert np.abs(full - chain_qacc)[ran].max(axis=1).min() > 1e-3 * scale  # the cut leaves those iterations out


def _sorts_program(loop: int, branches: tuple[int, int]) -> str:
    """A compiled program whose kernels are known: `loop` sorts in a while loop's body, then a conditional
    with branches of the given numbers of sorts (each sort one kernel, the scaling before it another)."""
    import jax
    import jax.numpy as jnp

    def sorts(k):
        def run(x):
            for _ in range(k):
                x = jnp.sort(x * 1.5)
            return x
        return run

    def f(p, x):
        x = jax.lax.while_loop(lambda c: c[0] < 3, lambda c: (c[0] + 1, sorts(loop)(c[1])), (0, x))[1]
        return jax.lax.cond(p, sorts(branches[0]), sorts(branches[1]), x)

    return jax.jit(f).lower(True, jnp.ones(5)).compile().as_text()


def test_kernels_count_a_loop_body_once_and_a_conditionals_larger_branch():
    from hopper_mjx.perf import kernels

    base = kernels.count(_sorts_program(1, (1, 1)))
    assert kernels.count(_sorts_program(2, (1, 1))) == base + 2  # once, though the loop runs 3 times
    assert kernels.count(_sorts_program(1, (1, 3))) == kernels.count(_sorts_program(1, (3, 1))) == base + 4
    assert kernels.count(_sorts_program(1, (3, 3))) == base + 4
    with pytest.raises(ValueError, match="HLO"):
        kernels.count("not a program")


@pytest.fixture(scope="module")
def flat_step_kernels(settling_chain) -> int:
    from hopper_mjx.perf import kernels

    _, sim, standing, _, _ = settling_chain
    return kernels.per_step(sim.engine, standing.data, standing.gravity)


def test_the_flat_chain_step_launches_at_most_500_kernels(flat_step_kernels):
    """perf.profile's kernel count of the core's flat step, watched: 1,102 at 8 instances (2 Dec), 479 since each
    stored stage writes its outputs a dozen to a kernel (6 Dec, docs/performance.md's c31). A change that adds
    kernels to every step (each costs a launch) fails here first."""
    print(f"\nkernels a flat chain step launches: {flat_step_kernels}")
    assert 250 <= flat_step_kernels <= 500


def test_the_bench_counts_the_kernels_of_the_rollout_it_ran(record, flat_step_kernels):
    """The bench's count is its own compiled rollout's: the engine's step (here with run-time robots, more than the
    flat step's folded constants) plus the controller and the record, so more than the bare step launches."""
    print(f"\nkernels a core step launches (bench): {record['kernels_per_step']}")
    assert flat_step_kernels < record["kernels_per_step"] < 5 * flat_step_kernels
    assert f"{record['kernels_per_step']:,}" in bench.format_table(record)


def test_the_flat_chain_steps_equations_are_counted_inside_its_loops_and_by_writer(settling_chain):
    """perf.profile's size of the step before XLA: 10,436 jaxpr equations flat (4 Dec; 43,757 on
    `rough:amp=0.02,seed=1`). The count walks into the conditionals' branches and the loops' bodies (the Newton
    solve is a while loop, every stored stage a conditional), so it is several times the top level's, and it names
    the engine functions that wrote them: the solver's the most."""
    import jax

    from hopper_mjx.perf import kernels, profile

    _, sim, standing, _, _ = settling_chain
    counts = kernels.equations(sim.engine, standing.data, standing.gravity)
    total = sum(counts.values())
    top = len(jax.make_jaxpr(kernels._batched_step(sim.engine))(sim.engine.model, standing.data,
                                                                 standing.gravity).jaxpr.eqns)
    print(f"\njaxpr equations of a flat chain step: {total:,} ({top:,} at its top level)")
    assert 5_000 <= total <= 20_000 and total > 3 * top
    solver = sum(n for name, n in counts.items() if name.startswith("solver."))
    assert solver > total / 3 and max(counts, key=counts.get).startswith(("solver.", "other"))
    assert all(name.startswith(("solver.", "smooth.", "constraint.", "chain.", "other")) for name in counts), counts
    assert f"{total:,}" in profile._equations(counts)
