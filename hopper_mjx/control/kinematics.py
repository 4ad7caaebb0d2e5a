"""Kinematics of the haa/hfe/kfe leg, for one instance, in pure JAX.

Frames and angles (as in the URDF): the base frame has z up the box; haa turns
the whole leg about the base x axis at `haa_below_base` under the base origin;
hfe and kfe turn about y, `hfe_below_haa` and then `thigh` further down. At zero
angles the leg hangs straight down. Positive hfe swings the foot towards -x;
the knee bends with negative kfe.

The *virtual leg* runs from the hfe axis to the foot centre. Its length depends
on the knee alone, which is what lets the Raibert controller treat the
articulated leg as a telescopic one:  L² = thigh² + shank² + 2·thigh·shank·cos(kfe).

Every function takes a `LegGeometry` of floats (the URDF's leg, folded into the program as
constants) or one whose fields are arrays (an instance's own leg, a run-time value: the
geometry is a pytree, so a batch of legs is vmapped like any other state).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from hopper_mjx.model.robot import LegGeometry

# The model layer stays free of JAX; here, where legs become traced values, the geometry is a pytree.
jax.tree_util.register_dataclass(LegGeometry, data_fields=[f.name for f in dataclasses.fields(LegGeometry)],
                                 meta_fields=[])


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


def rot_x(angle: jax.Array, v: jax.Array) -> jax.Array:
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.stack([v[0], c * v[1] - s * v[2], s * v[1] + c * v[2]])


def rot_y(angle: jax.Array, v: jax.Array) -> jax.Array:
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.stack([c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2]])


def _chain(leg: LegGeometry, q: jax.Array, thigh_point: jax.Array, shank_point: jax.Array):
    """Points fixed in the thigh and shank (frames at their joint axes) -> base frame, from haa."""
    hip = jnp.array([0.0, 0.0, -leg.hfe_below_haa])
    knee = jnp.array([0.0, 0.0, -leg.thigh])
    thigh = rot_x(q[0], hip + rot_y(q[1], thigh_point))
    shank = rot_x(q[0], hip + rot_y(q[1], knee + rot_y(q[2], shank_point)))
    return thigh, shank


def from_base(leg: LegGeometry, point: jax.Array) -> jax.Array:
    """A point (3,) given from the haa axis point, from the base origin instead (base frame)."""
    return point - jnp.array([0.0, 0.0, leg.haa_below_base])


def foot_position(leg: LegGeometry, q: jax.Array) -> jax.Array:
    """Foot centre (3,) relative to the haa axis point, base frame; q = (haa, hfe, kfe)."""
    return _chain(leg, q, jnp.zeros(3), jnp.array([0.0, 0.0, -leg.shank]))[1]


def _link_points(leg: LegGeometry, q: jax.Array) -> jax.Array:
    """COMs (4, 3) of base, hip, thigh, shank+foot relative to the haa axis point, base frame."""
    base, hip, thigh, shank = (jnp.asarray(c) for c in leg.link_com)
    thigh, shank = _chain(leg, q, thigh, shank)
    return jnp.stack([base, rot_x(q[0], hip), thigh, shank])


def com_position(leg: LegGeometry, q: jax.Array) -> jax.Array:
    """Whole-robot centre of mass (3,) relative to the haa axis point, base frame."""
    mass = jnp.asarray(leg.link_mass)
    return mass @ _link_points(leg, q) / mass.sum()


def angular_momentum(leg: LegGeometry, q: jax.Array, qd: jax.Array, gyro: jax.Array) -> jax.Array:
    """Whole-robot angular momentum (3,) about its COM, base frame (kg·m²/s).

    q, qd: joint angles and rates (haa, hfe, kfe); gyro: base angular velocity, base frame.
    This is what the robot keeps through a flight: with the joints held, it spins at
    about H / (whole-robot inertia).
    """
    mass = jnp.asarray(leg.link_mass)
    points, rates = jax.jvp(lambda a: _link_points(leg, a), (q,), (qd,))
    com = mass @ points / mass.sum()
    com_rate = mass @ rates / mass.sum()
    # Velocities relative to the COM in the (rotating) base frame.
    rel = points - com
    vel = rates - com_rate + jnp.cross(gyro, rel)
    orbital = (mass[:, None] * jnp.cross(rel, vel)).sum(axis=0)
    ex, ey = jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0])
    hip_w = gyro + qd[0] * ex
    side = rot_x(q[0], ey)
    thigh_w = hip_w + qd[1] * side
    shank_w = thigh_w + qd[2] * side
    def spin(inertia, rotate, w):  # I·w for a link whose principal axes are turned by `rotate`
        return rotate(inertia * rotate(w, inverse=True))

    hip_axes = lambda v, inverse=False: rot_x(-q[0] if inverse else q[0], v)

    def limb_axes(angle):
        def rotate(v, inverse=False):
            if inverse:
                return rot_y(-angle, rot_x(-q[0], v))
            return rot_x(q[0], rot_y(angle, v))
        return rotate

    inertia = [jnp.asarray(i) for i in leg.link_inertia]
    spin_total = (
        inertia[0] * gyro
        + spin(inertia[1], hip_axes, hip_w)
        + spin(inertia[2], limb_axes(q[1]), thigh_w)
        + spin(inertia[3], limb_axes(q[1] + q[2]), shank_w)
    )
    return orbital + spin_total


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
