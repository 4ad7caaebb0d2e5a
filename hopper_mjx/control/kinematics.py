"""Kinematics of the haa/hfe/kfe leg, for one instance, in pure JAX.

Frames and angles (as in the URDF): the base frame has z up the box; haa turns
the whole leg about the base x axis at `haa_below_base` under the base origin;
hfe and kfe turn about y, `hfe_below_haa` and then `thigh` further down. At zero
angles the leg hangs straight down. Positive hfe swings the foot towards -x;
the knee bends with negative kfe.

The *virtual leg* runs from the hfe axis to the foot centre. Its length depends
on the knee alone, which is what lets the Raibert controller treat the
articulated leg as a telescopic one:  L² = thigh² + shank² + 2·thigh·shank·cos(kfe).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from hopper_mjx.model.layout import Layout


@dataclass(frozen=True)
class LegGeometry:
    """Static lengths of a monoped leg (m), hashable like `Layout`."""

    haa_below_base: float  # base origin -> haa axis
    hfe_below_haa: float  # haa axis -> hfe axis, along the leg at zero haa
    thigh: float  # hfe -> kfe
    shank: float  # kfe -> foot centre
    foot_radius: float
    standing_height: float  # base height at rest: default stance, foot on the floor
    com_ahead_of_haa: float  # x of the whole-robot COM from the haa axis, standing (base frame)

    @classmethod
    def of(cls, m: mujoco.MjModel) -> "LegGeometry":
        """Measures a compiled monoped at its default stance (`Sim.stance_qpos(clearance=0)`)."""
        from hopper_mjx.sim import Sim  # the stance pose is the core's definition

        layout = Layout.of(m)
        stance = Sim(m).stance_qpos(clearance=0.0)
        d = mujoco.MjData(m)
        d.qpos[:] = stance
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        haa, hfe = (m.joint(name) for name in ("haa_joint", "hfe_joint"))
        base = d.xpos[m.jnt_bodyid[0]]
        return cls(
            haa_below_base=float(np.linalg.norm(d.xanchor[haa.id] - base)),
            hfe_below_haa=float(np.linalg.norm(d.xanchor[hfe.id] - d.xanchor[haa.id])),
            thigh=layout.thigh,
            shank=layout.shank,
            foot_radius=layout.foot_radius,
            standing_height=float(stance[2]),
            com_ahead_of_haa=float(d.subtree_com[0, 0] - d.xanchor[haa.id][0]),
        )

    def matches(self, layout: Layout) -> bool:
        close = lambda a, b: abs(a - b) < 1e-6
        return (
            close(self.haa_below_base + self.hfe_below_haa, layout.hip_below_base)
            and close(self.thigh, layout.thigh)
            and close(self.shank, layout.shank)
            and close(self.foot_radius, layout.foot_radius)
        )


@functools.lru_cache(maxsize=1)
def _shipped() -> LegGeometry:
    from hopper_mjx import model

    return LegGeometry.of(model.load())


def geometry_for(layout: Layout, leg: LegGeometry | None = None) -> LegGeometry:
    """`leg`, or the shipped monoped's geometry; either must agree with `layout`."""
    leg = leg or _shipped()
    if not leg.matches(layout):
        raise ValueError(
            "the leg geometry does not match this model's layout; "
            "pass leg=LegGeometry.of(mj_model) for a model built from another URDF"
        )
    return leg


def leg_length(leg: LegGeometry, kfe: jax.Array) -> jax.Array:
    """Virtual leg length (m), hfe axis -> foot centre."""
    l1, l2 = leg.thigh, leg.shank
    return jnp.sqrt(l1 * l1 + l2 * l2 + 2 * l1 * l2 * jnp.cos(kfe))


def leg_length_gradient(leg: LegGeometry, kfe: jax.Array) -> jax.Array:
    """dL/dkfe (m/rad): the knee's lever on the virtual leg (0 with the knee straight)."""
    return -leg.thigh * leg.shank * jnp.sin(kfe) / leg_length(leg, kfe)


def leg_length_rate(leg: LegGeometry, kfe: jax.Array, kfe_rate: jax.Array) -> jax.Array:
    """dL/dt (m/s), positive while the leg extends."""
    return leg_length_gradient(leg, kfe) * kfe_rate


def foot_position(leg: LegGeometry, q: jax.Array) -> jax.Array:
    """Foot centre (3,) relative to the haa axis point, base frame; q = (haa, hfe, kfe)."""
    haa, hfe, kfe = q[0], q[1], q[2]
    x = -leg.thigh * jnp.sin(hfe) - leg.shank * jnp.sin(hfe + kfe)
    z = -leg.hfe_below_haa - leg.thigh * jnp.cos(hfe) - leg.shank * jnp.cos(hfe + kfe)
    return jnp.stack([x, -z * jnp.sin(haa), z * jnp.cos(haa)])


def jacobian(leg: LegGeometry, q: jax.Array) -> jax.Array:
    """d foot_position / dq (3, 3), base frame: torques = J^T · (force at the foot)."""
    return jax.jacfwd(lambda angles: foot_position(leg, angles))(q)


def inverse(leg: LegGeometry, foot: jax.Array) -> jax.Array:
    """Joint angles (haa, hfe, kfe), knee bent backwards (kfe <= 0), that put the foot
    centre at `foot` (base frame, relative to the haa axis point). Out-of-reach
    targets are pulled onto the reachable virtual-leg lengths."""
    x, y, z = foot[0], foot[1], foot[2]
    haa = jnp.arctan2(y, -z)
    # Distance below the haa axis within the leg's own (haa-turned) plane, minus the hip offset.
    down = jnp.sqrt(y * y + z * z) - leg.hfe_below_haa
    l1, l2 = leg.thigh, leg.shank
    length = jnp.clip(jnp.sqrt(x * x + down * down), abs(l1 - l2) + 1e-3, l1 + l2 - 1e-6)
    cos_knee = (length * length - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    kfe = -jnp.arccos(jnp.clip(cos_knee, -1.0, 1.0))
    # The virtual leg's angle from straight down, minus its angle at hfe = 0.
    leg_angle = jnp.arctan2(-x, down)
    offset = jnp.arctan2(l2 * jnp.sin(kfe), l1 + l2 * jnp.cos(kfe))
    return jnp.stack([haa, leg_angle - offset, kfe])
