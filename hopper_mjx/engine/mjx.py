"""The generic engine: MuJoCo MJX's own pipeline, for any model (the reference and the fallback).

Per instance and pure, as the core vmaps it: `forward` runs `mjx.forward` under
the instance's gravity, `integrate` the model's integrator, and `foot_contact`
reads the foot's rows of MJX's contact and constraint arrays.
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx
from mujoco.mjx._src import support  # contact_force: decodes MJX's pyramidal/elliptic efc rows

from hopper_mjx import registry
from hopper_mjx.engine.xla import CPU_COMPILER_OPTIONS, trace_once
from hopper_mjx.model.layout import Layout
from hopper_mjx.terrain import to_model_data
from hopper_mjx.variation.draw import CONSTANTS

_INTEGRATORS = {
    mujoco.mjtIntegrator.mjINT_EULER: mjx.euler,
    mujoco.mjtIntegrator.mjINT_IMPLICITFAST: mjx.implicit,
    mujoco.mjtIntegrator.mjINT_RK4: mjx.rungekutta4,
}


def without_sensors(mj_model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy with MuJoCo's sensor stage off: the core measures its signals from the state
    (hopper_mjx.hardware.signals), so the stage would be dead weight in every step."""
    m = copy.deepcopy(mj_model)
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
    return m


def with_gravity(model: mjx.Model, gravity: jax.Array) -> mjx.Model:
    return model.replace(opt=model.opt.replace(gravity=gravity))


def foot_contact(foot_geom: int, model: mjx.Model, data: mjx.Data):
    """(flag, force, pos) of the foot from MJX data after a forward: the foot touches when one
    of its contact rows has distance < 0; force (3,) N floor-on-foot and the mean contact
    point (3,) m, world frame (zeros when not touching)."""
    con = data._impl.contact
    touching = (con.geom == foot_geom).any(axis=-1) & (con.dist < 0)
    # The contact normal points from the floor (geom1) to the foot (geom2).
    forces = jnp.stack(
        [support.contact_force(model, data, i, to_world_frame=True)[:3] for i in range(con.dist.shape[0])]
    )
    force = jnp.where(touching[:, None], forces, 0.0).sum(axis=0)
    weight = touching / jnp.maximum(touching.sum(), 1)
    return touching.any(), force, weight @ con.pos


class MjxEngine:
    """MJX's generic step behind the engine interface (see hopper_mjx.engine)."""

    name = "mjx"
    # A diverged instance keeps these from its last finite state (the rest is recomputed).
    freeze_fields = ("qpos", "qvel", "act", "qacc_warmstart")
    compiler_options = CPU_COMPILER_OPTIONS
    # Every field a parameter sets, and the constants derived from them: MJX reads them all as arrays.
    varies = frozenset(p.field for p in registry.PARAMETERS.values()) | frozenset(CONSTANTS)

    def __init__(self, mj_model: mujoco.MjModel, varies: frozenset[str] = frozenset()):
        nominal = without_sensors(mj_model)
        self.source = nominal
        if "dof_frictionloss" in varies:
            # MJX lays out a joint's dry-friction row only where the model has friction (fixed at trace time):
            # a varied joint needs its row, so the layout comes from a copy with friction on every hinge, and
            # the nominal values go back in (a row whose friction is 0 adds no force).
            self.source = copy.deepcopy(nominal)
            hinges = nominal.dof_frictionloss[6:]
            self.source.dof_frictionloss[6:] = np.where(hinges > 0, hinges, 1.0)
        self.foot_geom = Layout.of(mj_model).foot_geom
        self._integrate = _INTEGRATORS[mujoco.mjtIntegrator(mj_model.opt.integrator)]
        # On this process's first device: under jax.distributed the default device may be another process's.
        self.device = jax.local_devices()[0]
        self.model = mjx.put_model(self.source, device=self.device)
        if self.source is not nominal:
            lossless = jnp.asarray(nominal.dof_frictionloss, self.model.dof_frictionloss.dtype)
            self.model = self.model.replace(dof_frictionloss=lossless)
        trace_once(self)

    def vary(self, model: mjx.Model, values: dict) -> mjx.Model:
        """One instance's model: its values of the varied fields (and their derived constants) in place
        of the nominal ones; no values, the nominal model itself (the same compiled program)."""
        return model.replace(**{f: jnp.asarray(v, getattr(model, f).dtype) for f, v in values.items()})

    def on_ground(self, model: mjx.Model, heights: jax.Array) -> mjx.Model:
        """One instance's model on its own ground `heights` (nrow, ncol) m, encoded into MJX's hfield data."""
        return model.replace(hfield_data=to_model_data(self.source, heights).astype(model.hfield_data.dtype))

    def make_data(self, qpos: jax.Array, qvel: jax.Array) -> mjx.Data:
        return mjx.make_data(self.source, device=self.device).replace(qpos=qpos, qvel=qvel)

    def forward(self, model: mjx.Model, data: mjx.Data, gravity: jax.Array) -> mjx.Data:
        return mjx.forward(with_gravity(model, gravity), data)

    def integrate(self, model: mjx.Model, data: mjx.Data, gravity: jax.Array) -> mjx.Data:
        return self._integrate(with_gravity(model, gravity), data)

    def program_key(self) -> tuple:
        """What a traced step folds in besides the MuJoCo model's numbers (`shell.programs`)."""
        return (self.name, sorted(self.varies), sorted(self.compiler_options.items()))

    def foot_contact(self, model: mjx.Model, data: mjx.Data):
        return foot_contact(self.foot_geom, model, data)
