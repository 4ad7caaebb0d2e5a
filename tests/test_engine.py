"""The engine seam: names, the choice, and one step of the generic engine against MuJoCo C."""

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hopper_mjx import engine, registry
from hopper_mjx.model.robot import stance_qpos


def test_names_and_the_fallback(mj_model, capsys):
    for name in registry.ENGINES:  # every registered name builds an engine that meets the contract
        assert isinstance(engine.make(name, mj_model), engine.Engine)
    capsys.readouterr()
    assert engine.make("auto", mj_model).name == "chain"
    assert capsys.readouterr().err == ""
    rk4 = copy.deepcopy(mj_model)
    rk4.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    assert engine.make("auto", rk4).name == "mjx"
    notice = capsys.readouterr().err
    assert notice.startswith("note: engine auto uses mjx") and "integrator" in notice and notice.count("\n") == 1
    with pytest.raises(ValueError, match="not a chain model: the integrator is not Euler"):
        engine.make("chain", rk4)
    with pytest.raises(ValueError, match="unknown engine 'bogus'; choose from: auto, chain, mjx"):
        engine.make("bogus", mj_model)


def test_sim_rejects_an_unknown_engine_before_building_anything(mj_model):
    from hopper_mjx.sim import Sim

    with pytest.raises(ValueError, match="unknown engine"):
        Sim(mj_model, engine="warp")


def test_one_mjx_step_in_contact_equals_mujoco_c(mj_model):
    """Foot pressed 2 mm into the floor under the Moon's gravity, a control on every joint."""
    eng = engine.make("mjx", mj_model)
    g = np.array([0.0, 0.0, -1.62])
    qpos = stance_qpos(mj_model, clearance=-0.002)
    ctrl = np.array([5.0, -10.0, 20.0])
    m = copy.deepcopy(mj_model)
    m.opt.gravity[:] = g
    d = mujoco.MjData(m)
    d.qpos[:], d.ctrl[:] = qpos, ctrl
    mujoco.mj_forward(m, d)
    touch = np.zeros(6)
    mujoco.mj_contactForce(m, d, 0, touch)
    mujoco.mj_step(m, d)

    @jax.jit
    def step(q, v, u, gravity):
        data = eng.forward(eng.model, eng.make_data(q, v).replace(ctrl=u), gravity)
        return eng.integrate(eng.model, data, gravity), eng.foot_contact(eng.model, data)

    data, (flag, force, pos) = step(jnp.asarray(qpos, jnp.float32), jnp.zeros(mj_model.nv), jnp.asarray(ctrl),
                                    jnp.asarray(g, jnp.float32))
    np.testing.assert_allclose(np.asarray(data.qpos), d.qpos, atol=1e-5)
    np.testing.assert_allclose(np.asarray(data.qvel), d.qvel, atol=2e-3)
    assert float(data.time) == pytest.approx(mj_model.opt.timestep)
    assert bool(flag)
    # MuJoCo's contact frame: normal first, pointing from the floor (geom1) to the foot.
    assert float(force[2]) == pytest.approx(touch[0], rel=1e-3)
    assert float(pos[2]) == pytest.approx(-0.001, abs=2e-4)  # midway through the 2 mm overlap
    assert eng.freeze_fields == ("qpos", "qvel", "act", "qacc_warmstart")


def test_each_engine_compiles_with_its_own_xla_emitters(mj_model):
    """The chain on a heightfield takes XLA:CPU's fusion emitters (faster there), the plane and mjx the classic
    ones; the chain wide vectors on either. (The core's terrain runs against MuJoCo C, in test_terrain_physics.py,
    run under the chain's options.)"""
    from hopper_mjx.engine import chain
    from tests.hfield_model import hfield_model

    rough = hfield_model(0.02 * np.random.default_rng(3).standard_normal((21, 21)), 1.0, 1.0)
    assert engine.make("chain", mj_model).compiler_options == engine.CPU_COMPILER_OPTIONS | engine.WIDE_VECTORS
    assert engine.make("mjx", mj_model).compiler_options == engine.CPU_COMPILER_OPTIONS
    assert chain.make_for_tools(rough).compiler_options == engine.FUSION_EMITTERS | engine.WIDE_VECTORS
    assert engine.FUSION_EMITTERS["xla_cpu_use_fusion_emitters"] is True


def test_the_same_engine_is_built_once_per_process(mj_model, capsys):
    """`engine.make` again with an equal model (another compile of the same URDF) returns the engine already
    built, its step's trace with it; "auto" on a chain model is the chain engine; a model that differs in
    any number, or other varied fields, gets its own; the fallback's notice is said at every call."""
    from hopper_mjx.model import loader

    chain = engine.make("chain", mj_model)
    assert engine.make("chain", loader.load()) is chain
    assert engine.make("auto", loader.load()) is chain
    other = copy.deepcopy(mj_model)
    other.opt.timestep = 0.002
    assert engine.make("chain", other) is not chain
    assert engine.make("chain", mj_model, frozenset({"body_mass"})) is not chain
    assert engine.make("mjx", mj_model) is engine.make("mjx", loader.load()) is not chain
    rk4 = copy.deepcopy(mj_model)
    rk4.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    capsys.readouterr()
    assert engine.make("auto", rk4) is engine.make("auto", rk4)
    assert capsys.readouterr().err.count("note: engine auto uses mjx") == 2


def _equations(jaxpr) -> int:
    """Equations of a jaxpr, those of the jaxprs nested in them (jits, branches, loop bodies) included."""
    from jax.extend.core import ClosedJaxpr, Jaxpr

    count = 0
    for eqn in jaxpr.eqns:
        count += 1
        for param in eqn.params.values():
            for sub in param if isinstance(param, (tuple, list)) else (param,):
                if isinstance(sub, (ClosedJaxpr, Jaxpr)):
                    count += _equations(sub.jaxpr if isinstance(sub, ClosedJaxpr) else sub)
    return count


def test_vmap_batches_the_chain_step_once(mj_model, monkeypatch):
    """Under the core's vmap each equation of the chain's forward is batched about once: a stage stored behind
    its conditional is a nested jit, whose batching JAX caches, and the Newton loop's carry is batched from the
    start. A plain branch is batched twice (JAX's cond rule: once to learn which outputs are batched, once to
    batch them) and a loop body once per carry found batched later: 13,553 primitives for 8,226 equations before
    (docs/performance.md, c16), 7,102 for 8,327 now."""
    from jax._src.interpreters import batching

    eng = engine.make("chain", mj_model)
    qpos = jnp.asarray(stance_qpos(mj_model, clearance=-0.002), jnp.float32)
    data = eng.make_data(qpos, jnp.zeros(mj_model.nv, jnp.float32))
    gravity = jnp.array([0.0, 0.0, -9.81], jnp.float32)
    plain = jax.make_jaxpr(eng.forward.__wrapped__)(eng.model, data, gravity)
    batched = []
    process = batching.BatchTrace.process_primitive
    monkeypatch.setattr(batching.BatchTrace, "process_primitive",
                        lambda self, *a, **k: batched.append(1) or process(self, *a, **k))
    many = jax.tree_util.tree_map(lambda x: jnp.stack([x] * 4), data)
    jax.make_jaxpr(lambda m, d, g: jax.vmap(lambda x: eng.forward(m, x, g), axis_name=engine.BATCH_AXIS)(d))(
        eng.model, many, gravity)
    assert 0.5 * _equations(plain.jaxpr) < len(batched) < 1.1 * _equations(plain.jaxpr)


def test_the_chain_engine_with_raibert_and_the_sensors_imports_neither_brax_nor_mjx():
    """About 0.8 s of every process on the chain engine: brax (whose package imports MJX) and MJX stay unimported
    until a policy or the mjx engine needs them. A fresh interpreter builds the engine, the controller and a
    reset, as a command does."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from hopper_mjx import control, engine, model\n"
            "from hopper_mjx.hardware import signals\n"
            "from hopper_mjx.model.robot import Robot\n"
            "m = model.load()\n"
            "engine.make('auto', m)\n"
            "control.make('raibert', Robot.of(m), 2)\n"
            "print(sorted(k for k in ('brax', 'mujoco.mjx') if k in sys.modules))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stdout
