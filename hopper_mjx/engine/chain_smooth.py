"""Smooth dynamics of the chain, per instance in scalar arithmetic: kinematics, the mass
matrix (composite rigid bodies), bias forces (recursive Newton-Euler), actuation and damping.

Positions are taken relative to the base origin O (better conditioned in float32 than the
world origin), and each dof's motion is a spatial vector (w, v): the angular velocity it
gives and the velocity of the body point at O. MuJoCo's free joint: qvel[:3] is the world
velocity of the base origin, qvel[3:6] the angular velocity in the base frame.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from hopper_mjx.engine import chain_algebra as al
from hopper_mjx.engine.chain_model import ChainModel


class Pose(NamedTuple):
    base_pos: tuple  # (3,) world position of the base origin O
    rot: tuple  # per body (base first): 3x3 world rotation
    origin: tuple  # per body: body origin relative to O
    com: tuple  # per body: centre of mass relative to O
    inertia: tuple  # per body: inertia about the COM, world axes (sym6)
    dof_w: tuple  # per dof: angular part of its motion
    dof_v: tuple  # per dof: linear part at O
    anchor: tuple  # per body: hinge anchor relative to O (None without a hinge)


def dof_body(cm: ChainModel) -> tuple[int, ...]:
    """The body (0 = base) that each dof moves."""
    bodies = [0] * 6
    for k, link in enumerate(cm.links):
        if link.hinge is not None:
            bodies.append(k + 1)
    return tuple(bodies)


def body_masses(cm: ChainModel) -> tuple:
    return (cm.base_mass,) + tuple(link.mass for link in cm.links)


def kinematics(cm: ChainModel, qpos) -> Pose:
    """Body poses, inertias and dof motions from qpos (a tuple of nq scalars)."""
    w, x, y, z = qpos[3:7]
    norm = jnp.sqrt(w * w + x * x + y * y + z * z)
    rot = al.quat_to_mat(w / norm, x / norm, y / norm, z / norm)
    origin = (0.0, 0.0, 0.0)
    rots, origins, anchors = [rot], [origin], [None]
    dof_w = [(0.0, 0.0, 0.0)] * 3 + [al.column(rot, k) for k in range(3)]
    dof_v = [tuple(1.0 if i == k else 0.0 for i in range(3)) for k in range(3)] + [(0.0, 0.0, 0.0)] * 3
    for link in cm.links:
        origin = al.vadd(origin, al.matvec(rot, link.pos))
        rot = al.matmul(rot, link.rot)
        anchor = None
        hinge = link.hinge
        if hinge is not None:
            anchor = al.vadd(origin, al.matvec(rot, hinge.pos))
            axis = al.matvec(rot, hinge.axis)
            angle = qpos[hinge.qpos_adr] - hinge.qpos0
            rot = al.matmul(rot, al.axis_rotation(hinge.axis, jnp.cos(angle), jnp.sin(angle)))
            origin = al.vsub(anchor, al.matvec(rot, hinge.pos))
            dof_w.append(axis)
            dof_v.append(al.cross(anchor, axis))  # axis x (O - anchor)
        rots.append(rot)
        origins.append(origin)
        anchors.append(anchor)
    coms, inertias = [], []
    locals_ = [(cm.base_com, cm.base_inertia)] + [(link.com, link.inertia) for link in cm.links]
    for r, o, (com, inertia) in zip(rots, origins, locals_):
        coms.append(al.vadd(o, al.matvec(r, com)))
        inertias.append(al.rotate_sym(r, inertia))
    return Pose(tuple(qpos[:3]), tuple(rots), tuple(origins), tuple(coms), tuple(inertias),
                tuple(dof_w), tuple(dof_v), tuple(anchors))


def _composites(cm: ChainModel, pose: Pose):
    """Per body: (mass, first moment h = m c, inertia about O) of the subtree rooted there."""
    out = []
    acc = None
    for m, c, inertia in reversed(list(zip(body_masses(cm), pose.com, pose.inertia))):
        cc = al.dot(c, c)
        about_o = (
            al.add(inertia[0], al.mul(m, al.sub(cc, al.mul(c[0], c[0])))),
            al.add(inertia[1], al.mul(m, al.sub(cc, al.mul(c[1], c[1])))),
            al.add(inertia[2], al.mul(m, al.sub(cc, al.mul(c[2], c[2])))),
            al.sub(inertia[3], al.mul(m, al.mul(c[0], c[1]))),
            al.sub(inertia[4], al.mul(m, al.mul(c[0], c[2]))),
            al.sub(inertia[5], al.mul(m, al.mul(c[1], c[2]))),
        )
        body = (m, al.vscale(m, c), about_o)
        acc = body if acc is None else (
            acc[0] + m, al.vadd(acc[1], body[1]), tuple(al.add(a, b) for a, b in zip(acc[2], about_o)))
        out.append(acc)
    return out[::-1]


def mass_matrix(cm: ChainModel, pose: Pose) -> dict:
    """Joint-space inertia M as {(i, j): value} for i <= j, armature included."""
    composite = _composites(cm, pose)
    bodies = dof_body(cm)
    momenta = []
    for j, b in enumerate(bodies):
        m, h, about_o = composite[b]
        w, v = pose.dof_w[j], pose.dof_v[j]
        momenta.append((al.vadd(al.sym_matvec(about_o, w), al.cross(h, v)), al.vsub(al.vscale(m, v), al.cross(h, w))))
    mass = {}
    for i in range(cm.nv):
        for j in range(i, cm.nv):
            angular, linear = momenta[j]
            mass[i, j] = al.add(al.dot(pose.dof_w[i], angular), al.dot(pose.dof_v[i], linear))
        mass[i, i] = al.add(mass[i, i], cm.armature[i])
    return mass


def bias(cm: ChainModel, pose: Pose, qvel, gravity) -> tuple:
    """Coriolis, centrifugal and gravity forces (MuJoCo's qfrc_bias) by Newton-Euler."""
    omega = al.matvec(pose.rot[0], tuple(qvel[3:6]))
    alpha = (0.0, 0.0, 0.0)
    acc_origin = al.vscale(-1.0, tuple(gravity))  # accelerate the base against gravity
    masses = body_masses(cm)
    forces, moments = [], []
    origin_prev = pose.origin[0]
    for b in range(len(masses)):
        hinge = None if b == 0 else cm.links[b - 1].hinge
        origin = pose.origin[b]
        if hinge is None and b > 0:
            acc_origin = _point_acc(acc_origin, alpha, omega, al.vsub(origin, origin_prev))
        elif hinge is not None:  # via the anchor, a point of both the parent and the child
            anchor = pose.anchor[b]
            acc_origin = _point_acc(acc_origin, alpha, omega, al.vsub(anchor, origin_prev))
            spin = al.vscale(qvel[hinge.dof], pose.dof_w[hinge.dof])
            alpha = al.vadd(alpha, al.cross(omega, spin))
            omega = al.vadd(omega, spin)
            acc_origin = _point_acc(acc_origin, alpha, omega, al.vsub(origin, anchor))
        acc_com = _point_acc(acc_origin, alpha, omega, al.vsub(pose.com[b], origin))
        f = al.vscale(masses[b], acc_com)
        inertia = pose.inertia[b]
        n = al.vadd(al.sym_matvec(inertia, alpha), al.cross(omega, al.sym_matvec(inertia, omega)))
        forces.append(f)
        moments.append(al.vadd(n, al.cross(pose.com[b], f)))  # about O
        origin_prev = origin
    out = [None] * cm.nv
    force, moment = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    for b in reversed(range(len(masses))):
        force, moment = al.vadd(force, forces[b]), al.vadd(moment, moments[b])
        hinge = None if b == 0 else cm.links[b - 1].hinge
        if hinge is not None:
            about_anchor = al.vsub(moment, al.cross(pose.anchor[b], force))
            out[hinge.dof] = al.dot(pose.dof_w[hinge.dof], about_anchor)
    out[0:3] = force
    out[3:6] = al.mattvec(pose.rot[0], moment)
    return tuple(out)


def _point_acc(acc, alpha, omega, r):
    """Acceleration of a point r away on the same rigid body."""
    return al.vadd(acc, al.vadd(al.cross(alpha, r), al.cross(omega, al.cross(omega, r))))


def applied_forces(cm: ChainModel, qpos, qvel, ctrl) -> tuple:
    """Actuator forces (clamped like MuJoCo: ctrl, actuator force, joint force range) minus damping."""
    qfrc = [al.mul(-d, v) for d, v in zip(cm.damping, qvel)]
    act = [0.0] * cm.nv
    for (dof, gear, gain, b0, b1, b2, ctrl_range, force_range), qadr, u in zip(cm.actuators, cm.actuator_qpos, ctrl):
        if ctrl_range is not None:
            u = jnp.clip(u, *ctrl_range)
        force = al.total((al.mul(gain, u), b0, al.mul(b1 * gear, qpos[qadr]), al.mul(b2 * gear, qvel[dof])))
        if force_range is not None:
            force = jnp.clip(force, *force_range)
        act[dof] = al.add(act[dof], al.mul(gear, force))
    for dof, lo, hi in cm.joint_force_range:
        act[dof] = jnp.clip(act[dof], lo, hi)
    return tuple(al.add(a, b) for a, b in zip(qfrc, act))
