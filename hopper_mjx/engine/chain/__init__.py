"""The chain engine: MuJoCo's step specialised, at trace time, to one monoped's topology.

A free base, a serial chain of hinges, a sphere foot and a base box on a plane floor, or on
a heightfield (`chain_hfield`, `chain_hfield_box`; there the leg links' boxes too), for any URDF
the loader accepts (`chain_model.describe` says why another model is not one). The step is
MuJoCo's, stage by stage, written as per-instance scalar arithmetic with the model's numbers
as constants, so that `vmap` turns every quantity into one contiguous vector over instances:

    kinematics -> mass matrix, bias, actuation, damping -> constraint rows -> Newton solve
    -> (integrate) Euler with implicit joint damping

Each stage's outputs are stored once (`chain_stage.stored`); the engine's `model` pytree
carries the run-time true predicate that makes that work, a heightfield's heights, and, for a
batch of per-instance robots (`vary`), the instance's masses, inertias, centres of mass, link
offsets, foot radius and friction, joint damping and armature, motor gears and MuJoCo's constraint
weights derived from them in place of their constants (`chain_model.instance`).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco

from hopper_mjx import registry
from hopper_mjx.engine.chain import algebra as al
from hopper_mjx.engine.chain import constraint as chain_constraint
from hopper_mjx.engine.chain import smooth as chain_smooth
from hopper_mjx.engine.chain import solver as chain_solver
from hopper_mjx.engine.chain.hfield import TerrainParams
from hopper_mjx.engine.chain.model import ChainModel, NotChain, derive, describe, entries, instance
from hopper_mjx.engine.chain.stage import BATCH_AXIS, stored
from hopper_mjx.engine.xla import CPU_COMPILER_OPTIONS, FUSION_EMITTERS, WIDE_VECTORS, trace_once
from hopper_mjx.terrain import from_model
from hopper_mjx.variation import draw

__all__ = ["BATCH_AXIS", "ChainData", "ChainEngine", "ChainParams", "NotChain", "TerrainParams", "make",
           "make_for_tools"]


class ChainParams(NamedTuple):
    """The compiled function's model argument: a run-time true gate for `stored`; on a heightfield
    floor its heights (a run-time input: a new terrain of the same grid does not recompile, and
    vmapping this leaf gives each instance its own); and the instance's values of the model fields it
    takes at run time (`vary`; None: the model's own, folded in as constants)."""

    gate: jax.Array
    terrain: TerrainParams | None = None
    robot: dict | None = None  # this instance's numbers in place of the constants: chain_model.derive


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ChainData:
    """One instance's state and the last forward's results."""

    qpos: jax.Array  # (nq,)
    qvel: jax.Array  # (nv,)
    qacc: jax.Array  # (nv,) of the last forward
    ctrl: jax.Array  # (nu,)
    time: jax.Array  # ()
    qacc_warmstart: jax.Array  # (nv,) the solver's start: the previous step's qacc
    mass: jax.Array  # (nv (nv + 1) / 2,) M's upper triangle, row by row
    qfrc_smooth: jax.Array  # (nv,) applied + actuator - bias
    qfrc_constraint: jax.Array  # (nv,)
    foot_touching: jax.Array  # () bool
    foot_force: jax.Array  # (3,) N floor on foot, world
    foot_pos: jax.Array  # (3,) m contact point, world (zeros when not touching)
    solver_niter: jax.Array  # () int32 Newton iterations of the last forward (MuJoCo's solver_niter)

    def replace(self, **fields) -> ChainData:
        return dataclasses.replace(self, **fields)


def _smooth(cm: ChainModel, gate, pose, qpos, qvel, ctrl, gravity):
    """Mass matrix, qfrc_smooth and the unconstrained acceleration."""
    mass = chain_smooth.mass_matrix(cm, gate, pose)
    bias = chain_smooth.bias(cm, gate, pose, qvel, gravity)
    qfrc_smooth = stored(gate, lambda *a: tuple(
        al.sub(f, b) for f, b in zip(chain_smooth.applied_forces(cm, *a), bias)), qpos, qvel, ctrl)
    return mass, qfrc_smooth, chain_solver.solve_spd(gate, mass, qfrc_smooth)


def _foot_force(foot: chain_constraint.FootContact, force) -> tuple:
    if isinstance(foot.directions, jax.Array):  # a heightfield's rows, stacked: the solve's forces an array
        total = jnp.sum(force[foot.rows[0]:foot.rows[-1] + 1, None] * foot.directions, 0)  # its rows are a run
        return tuple(jnp.where(foot.touching, total[k], 0.0) for k in range(3))
    total = (0.0, 0.0, 0.0)
    for row, direction in zip(foot.rows, foot.directions):
        total = al.vadd(total, al.vscale(force[row], direction))
    return tuple(jnp.where(foot.touching, x, 0.0) for x in total)


class ChainEngine:
    """MuJoCo's step for the chain topology, behind the engine interface (hopper_mjx.engine)."""

    name = "chain"
    # A diverged instance keeps these from its last finite state (the rest is recomputed).
    freeze_fields = ("qpos", "qvel", "qacc_warmstart")
    # The model's numbers are folded into the step at trace time, but for these and the constants MuJoCo
    # derives from them (of which the step reads the constraint weights), which `vary` makes run-time values.
    varies = registry.CHAIN_VARIES | frozenset(draw.CONSTANTS)

    def __init__(self, mj_model: mujoco.MjModel, max_foot_contacts: int | None = None,
                 varies: frozenset[str] = frozenset()):
        """`max_foot_contacts` (heightfield floors): keep only the foot's deepest this many
        contacts, fewer constraint rows than the block's 2 x rows x cols prisms; C's answer
        whenever at most that many exist, the shallowest dropped otherwise. None: all.
        `varies`: the model fields a batch will vary per instance (NotChain for one it cannot)."""
        self.chain = describe(mj_model)
        if "geom_size" in varies and self.chain.terrain is not None:  # the cell block is sized for one radius
            raise NotChain("not a chain model: a drawn foot radius on a heightfield floor is not written yet")
        self.source = mj_model  # the nominal model: `chain_model.instance` reads its frames and indices
        self.settable = {f: draw.settable(mj_model, f) for f in registry.CHAIN_VARIES}
        if max_foot_contacts is not None:
            if self.chain.terrain is None or max_foot_contacts < 1:
                raise ValueError("max_foot_contacts needs a heightfield floor and must be >= 1")
            self.chain = dataclasses.replace(
                self.chain, terrain=dataclasses.replace(self.chain.terrain, max_contacts=int(max_foot_contacts)))
        self.nu = int(mj_model.nu)
        # On a heightfield the fusion emitters run the step faster; on the plane the classic ones; wide vectors on
        # both (xla.py).
        emitters = CPU_COMPILER_OPTIONS if self.chain.terrain is None else FUSION_EMITTERS
        self.compiler_options = emitters | WIDE_VECTORS
        self.model = ChainParams(gate=jnp.array(True))
        if self.chain.terrain is not None:
            t = self.chain.terrain
            self.model = self.with_heights(from_model(mj_model).heights, t.origin[2] - t.base)
        trace_once(self)

    def with_heights(self, heights, bottom=None) -> ChainParams:
        """The model argument on the terrain `heights` ((nrow, ncol) m, world, on this model's
        grid; a leading batch axis gives each instance its own), its prisms' `bottom` (world z)
        by default `base` below its lowest vertex, where the model convention puts it."""
        t = self.chain.terrain
        if t is None:
            raise ValueError("the model's floor is a plane, not a heightfield")
        heights = jnp.asarray(heights)
        if heights.shape[-2:] != (t.nrow, t.ncol):
            raise ValueError(f"heights must be ({t.nrow}, {t.ncol}) for this model, got {heights.shape}")
        bottom = jnp.min(heights, axis=(-2, -1)) - t.base if bottom is None else jnp.asarray(bottom, heights.dtype)
        return ChainParams(gate=jnp.array(True), terrain=TerrainParams(heights, bottom))

    def on_ground(self, model: ChainParams, heights) -> ChainParams:
        """One instance's model on its own ground `heights` (nrow, ncol) m, world, on this model's grid."""
        return model._replace(terrain=self.with_heights(heights).terrain)

    def vary(self, model: ChainParams, values: dict) -> ChainParams:
        """One instance's model: its values of the varied fields as run-time values (`varies`; `engine.make`
        sends any other varied field to mjx); no values, the model's constants stay folded (the same program)."""
        other = set(values) - self.varies
        if other:
            raise ValueError(f"the chain engine cannot take {', '.join(sorted(other))} at run time")
        if not values:
            return model
        # Once per rollout: what the step would recompute from the drawn numbers every step (`derive`).
        return model._replace(robot=derive(self.chain, self.source, entries(self.chain, values, self.settable)))

    def instance(self, model: ChainParams) -> ChainModel:
        """The chain model of this instance: the folded constants, or its robot's values in their place."""
        if not model.robot:
            return self.chain
        return instance(self.chain, self.source, model.robot)

    def make_data(self, qpos, qvel) -> ChainData:
        qpos = jnp.asarray(qpos)
        cm, dtype = self.chain, qpos.dtype
        zeros = lambda *shape: jnp.zeros(shape, dtype)
        return ChainData(
            qpos=qpos, qvel=jnp.asarray(qvel, dtype), qacc=zeros(cm.nv), ctrl=zeros(self.nu), time=zeros(),
            qacc_warmstart=zeros(cm.nv), mass=zeros(cm.nv * (cm.nv + 1) // 2), qfrc_smooth=zeros(cm.nv),
            qfrc_constraint=zeros(cm.nv), foot_touching=jnp.zeros((), bool), foot_force=zeros(3), foot_pos=zeros(3),
            solver_niter=jnp.zeros((), jnp.int32),
        )

    def forward(self, model: ChainParams, data: ChainData, gravity) -> ChainData:
        cm, gate, dtype = self.instance(model), model.gate, data.qpos.dtype
        qpos = tuple(data.qpos[i] for i in range(cm.nq))
        qvel = tuple(data.qvel[i] for i in range(cm.nv))
        ctrl = tuple(data.ctrl[i] for i in range(self.nu))
        gravity = tuple(jnp.asarray(gravity, dtype)[i] for i in range(3))
        pose = chain_smooth.kinematics(cm, gate, qpos)
        mass, qfrc_smooth, qacc_smooth = _smooth(cm, gate, pose, qpos, qvel, ctrl, gravity)
        rows, foot = chain_constraint.rows(cm, gate, pose, qpos, qvel, model.terrain)
        warm = tuple(data.qacc_warmstart[i] for i in range(cm.nv))
        sol = chain_solver.solve(gate, mass, qfrc_smooth, qacc_smooth, warm, rows, iterations=cm.iterations,
                                 ls_iterations=cm.ls_iterations, tolerance=cm.tolerance, ls_tolerance=cm.ls_tolerance,
                                 cost_scale=cm.cost_scale, warmstart=cm.warmstart,
                                 stacked=cm.terrain is not None)  # a heightfield's many rows: solver.Stacked
        upper = [mass[i, j] for i in range(cm.nv) for j in range(i, cm.nv)]
        return data.replace(
            qacc=al.vector(sol.qacc, dtype), mass=al.vector(upper, dtype), qfrc_smooth=al.vector(qfrc_smooth, dtype),
            qfrc_constraint=al.vector(sol.qfrc_constraint, dtype), foot_touching=foot.touching,
            foot_force=al.vector(_foot_force(foot, sol.force), dtype), foot_pos=al.vector(foot.pos, dtype),
            solver_niter=sol.iterations.astype(jnp.int32),
        )

    def integrate(self, model: ChainParams, data: ChainData, gravity) -> ChainData:
        """Semi-implicit Euler; joint damping implicit as MuJoCo's: (M + h B) a = qfrc_smooth + qfrc_constraint."""
        cm = self.instance(model)
        h, qacc, damping = cm.timestep, data.qacc, cm.damping
        if cm.eulerdamp and any(not al.is_const(d) or d for d in damping):  # run-time or nonzero damping
            upper = iter(data.mass[k] for k in range(data.mass.shape[0]))
            damped = {(i, j): next(upper) + (h * damping[i] if i == j else 0.0)
                      for i in range(cm.nv) for j in range(i, cm.nv)}
            total = data.qfrc_smooth + data.qfrc_constraint
            qacc = al.vector(chain_solver.solve_spd(model.gate, damped, tuple(total[i] for i in range(cm.nv))),
                           data.qvel.dtype)
        qvel = data.qvel + h * qacc
        return data.replace(qpos=_advance_qpos(cm, data.qpos, qvel), qvel=qvel, time=data.time + h,
                            qacc_warmstart=data.qacc)

    def program_key(self) -> tuple:
        """What a traced step folds in besides the MuJoCo model's numbers (`shell.programs`): the foot's
        contacts kept on a heightfield too."""
        terrain = self.chain.terrain
        return (self.name, sorted(self.varies), sorted(self.compiler_options.items()),
                None if terrain is None else terrain.max_contacts)

    def foot_contact(self, model: ChainParams, data: ChainData):
        return data.foot_touching, data.foot_force, data.foot_pos


def _advance_qpos(cm: ChainModel, qpos: jax.Array, qvel: jax.Array) -> jax.Array:
    """qpos after h with velocity qvel: the base quaternion turned by its body-frame rate."""
    h = cm.timestep
    w, x, y, z = (qpos[i] for i in range(3, 7))
    wx, wy, wz = (qvel[i] for i in range(3, 6))
    rate = jnp.sqrt(wx * wx + wy * wy + wz * wz)
    half = 0.5 * h * rate
    scale = jnp.where(rate > chain_constraint.MINVAL, jnp.sin(half) / jnp.where(rate > 0, rate, 1.0), 0.0)
    c, ax, ay, az = jnp.cos(half), wx * scale, wy * scale, wz * scale
    quat = jnp.stack([w * c - x * ax - y * ay - z * az, w * ax + x * c + y * az - z * ay,
                      w * ay - x * az + y * c + z * ax, w * az + x * ay - y * ax + z * c])
    quat = quat / jnp.sqrt(jnp.sum(quat * quat))
    hinges = qpos[7:] + h * qvel[6:]
    return jnp.concatenate([qpos[:3] + h * qvel[:3], quat, hinges])


# The foot's contacts on a heightfield that the tools keep as constraint rows (`engine.make`). Every slot costs
# its four pyramid rows in the solve whether or not it holds a contact. Measured (before docs/performance.md's levers
# c10 and c11, which made every figure smaller) with perf.bench's standing batch,
# N = 1024 on rough:amp=0.02 (CPU us a step; final state against native): all 18 slots 39.8 us, 7.5e-7 m;
# 10 slots 14.0 us; 8 slots 9.5 us, 6.8e-7 m; 6 slots 8.2 us, but some feet then touch more prisms than
# are kept and the batch leaves native's by 1e-3 m in 0.4 s.
FOOT_CONTACTS = 8


def make(mj_model: mujoco.MjModel, max_foot_contacts: int | None = None,
         varies: frozenset[str] = frozenset()) -> ChainEngine:
    """The chain engine of `mj_model` for a batch varying `varies` per instance; `NotChain` (one line why)
    when the model is outside it."""
    return ChainEngine(mj_model, max_foot_contacts, varies)


def make_for_tools(mj_model: mujoco.MjModel, varies: frozenset[str] = frozenset()) -> ChainEngine:
    """`make` as the tools run it: on a heightfield floor the foot keeps its deepest FOOT_CONTACTS."""
    engine = ChainEngine(mj_model, None, varies)
    if engine.chain.terrain is None:
        return engine
    return ChainEngine(mj_model, FOOT_CONTACTS, varies)
