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

from hopper_mjx.engine.chain import algebra as al
from hopper_mjx.engine.chain.model import ChainModel
from hopper_mjx.engine.chain.stage import stored


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


def _base_and_trig(cm: ChainModel, qpos):
    """The base rotation (quaternion normalised as MuJoCo does) and each hinge's (cos, sin)."""
    w, x, y, z = qpos[3:7]
    norm = jnp.sqrt(w * w + x * x + y * y + z * z)
    rot = al.quat_to_mat(w / norm, x / norm, y / norm, z / norm)
    angles = [qpos[link.hinge.qpos_adr] - link.hinge.qpos0 for link in cm.links if link.hinge is not None]
    return rot, tuple((jnp.cos(a), jnp.sin(a)) for a in angles)


def _place_link(link, rot, origin, cos_sin):
    """A link's rotation and origin from its parent's; with a hinge, its world axis and anchor."""
    origin = al.vadd(origin, al.matvec(rot, link.pos))
    rot = al.matmul(rot, link.rot)
    hinge = link.hinge
    if hinge is None:
        return rot, origin, None, None
    anchor = al.vadd(origin, al.matvec(rot, hinge.pos))
    axis = al.matvec(rot, hinge.axis)
    rot = al.matmul(rot, al.axis_rotation(hinge.axis, *cos_sin))
    return rot, al.vsub(anchor, al.matvec(rot, hinge.pos)), axis, anchor


def _mass_placement(cm: ChainModel, rots, origins):
    locals_ = [(cm.base_com, cm.base_inertia)] + [(link.com, link.inertia) for link in cm.links]
    coms = tuple(al.vadd(o, al.matvec(r, com)) for r, o, (com, _) in zip(rots, origins, locals_))
    inertias = tuple(al.rotate_sym(r, inertia) for r, (_, inertia) in zip(rots, locals_))
    return coms, inertias


def kinematics(cm: ChainModel, gate, qpos) -> Pose:
    """Body poses, inertias and dof motions from qpos (a tuple of nq scalars), one stage per body."""
    rot, trig = stored(gate, lambda q: _base_and_trig(cm, q), qpos)
    origin = (0.0, 0.0, 0.0)
    rots, origins, anchors = [rot], [origin], [None]
    dof_w = [(0.0, 0.0, 0.0)] * 3 + [al.column(rot, k) for k in range(3)]
    dof_v = [tuple(1.0 if i == k else 0.0 for i in range(3)) for k in range(3)] + [(0.0, 0.0, 0.0)] * 3
    trig = iter(trig)
    for link in cm.links:
        cos_sin = next(trig) if link.hinge is not None else None
        rot, origin, axis, anchor = stored(gate, lambda *a, link=link: _place_link(link, *a), rot, origin, cos_sin)
        if link.hinge is not None:
            dof_w.append(axis)
            dof_v.append(stored(gate, al.cross, anchor, axis))  # axis x (O - anchor)
        rots.append(rot)
        origins.append(origin)
        anchors.append(anchor)
    coms, inertias = stored(gate, lambda r, o: _mass_placement(cm, r, o), tuple(rots), tuple(origins))
    return Pose(tuple(qpos[:3]), tuple(rots), tuple(origins), coms, inertias,
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


def _momenta(cm: ChainModel, pose: Pose, composite):
    """Per dof j: the (angular about O, linear) momentum of body(j)'s subtree moving with dof j."""
    out = []
    for j, b in enumerate(dof_body(cm)):
        m, h, about_o = composite[b]
        w, v = pose.dof_w[j], pose.dof_v[j]
        out.append((al.vadd(al.sym_matvec(about_o, w), al.cross(h, v)), al.vsub(al.vscale(m, v), al.cross(h, w))))
    return tuple(out)


def _mass_entries(cm: ChainModel, pose: Pose, momenta) -> dict:
    mass = {}
    for i in range(cm.nv):
        for j in range(i, cm.nv):
            angular, linear = momenta[j]
            mass[i, j] = al.add(al.dot(pose.dof_w[i], angular), al.dot(pose.dof_v[i], linear))
        mass[i, i] = al.add(mass[i, i], cm.armature[i])
    return mass


def mass_matrix(cm: ChainModel, gate, pose: Pose) -> dict:
    """Joint-space inertia M as {(i, j): value} for i <= j, armature included (composite rigid bodies)."""
    composite = stored(gate, lambda p: _composites(cm, p), pose)
    momenta = stored(gate, lambda p, c: _momenta(cm, p, c), pose, composite)
    return stored(gate, lambda p, mo: _mass_entries(cm, p, mo), pose, momenta)


def _body_wrench(cm: ChainModel, pose: Pose, b: int, qvel, motion):
    """Newton-Euler forward step into body b: its (omega, alpha, origin acceleration) from the
    parent's, and the force and moment about O that its motion takes."""
    omega, alpha, acc_origin = motion
    hinge = None if b == 0 else cm.links[b - 1].hinge
    origin = pose.origin[b]
    if b > 0 and hinge is None:
        acc_origin = _point_acc(acc_origin, alpha, omega, al.vsub(origin, pose.origin[b - 1]))
    elif hinge is not None:  # via the anchor, a point of both the parent and the child
        anchor = pose.anchor[b]
        acc_origin = _point_acc(acc_origin, alpha, omega, al.vsub(anchor, pose.origin[b - 1]))
        spin = al.vscale(qvel[hinge.dof], pose.dof_w[hinge.dof])
        alpha = al.vadd(alpha, al.cross(omega, spin))
        omega = al.vadd(omega, spin)
        acc_origin = _point_acc(acc_origin, alpha, omega, al.vsub(origin, anchor))
    acc_com = _point_acc(acc_origin, alpha, omega, al.vsub(pose.com[b], origin))
    force = al.vscale(body_masses(cm)[b], acc_com)
    inertia = pose.inertia[b]
    torque = al.vadd(al.sym_matvec(inertia, alpha), al.cross(omega, al.sym_matvec(inertia, omega)))
    return (omega, alpha, acc_origin), (force, al.vadd(torque, al.cross(pose.com[b], force)))


def _project_wrenches(cm: ChainModel, pose: Pose, wrenches) -> tuple:
    """Sum the wrenches from the tip and project them on each dof."""
    out = [None] * cm.nv
    force, moment = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    for b in reversed(range(len(wrenches))):
        force, moment = al.vadd(force, wrenches[b][0]), al.vadd(moment, wrenches[b][1])
        hinge = None if b == 0 else cm.links[b - 1].hinge
        if hinge is not None:
            about_anchor = al.vsub(moment, al.cross(pose.anchor[b], force))
            out[hinge.dof] = al.dot(pose.dof_w[hinge.dof], about_anchor)
    out[0:3] = force
    out[3:6] = al.mattvec(pose.rot[0], moment)
    return tuple(out)


def bias(cm: ChainModel, gate, pose: Pose, qvel, gravity) -> tuple:
    """Coriolis, centrifugal and gravity forces (MuJoCo's qfrc_bias) by Newton-Euler, one stage per body."""
    omega = stored(gate, al.matvec, pose.rot[0], tuple(qvel[3:6]))
    motion = (omega, (0.0, 0.0, 0.0), al.vscale(-1.0, tuple(gravity)))  # the base accelerated against gravity
    wrenches = []
    for b in range(len(body_masses(cm))):
        motion, wrench = stored(gate, lambda p, q, mo, b=b: _body_wrench(cm, p, b, q, mo), pose, qvel, motion)
        wrenches.append(wrench)
    return stored(gate, lambda p, w: _project_wrenches(cm, p, w), pose, tuple(wrenches))


def _point_acc(acc, alpha, omega, r):
    """Acceleration of a point r away on the same rigid body."""
    return al.vadd(acc, al.vadd(al.cross(alpha, r), al.cross(omega, al.cross(omega, r))))


def applied_forces(cm: ChainModel, qpos, qvel, ctrl) -> tuple:
    """Actuator forces (clamped like MuJoCo: ctrl, actuator force, joint force range) minus damping."""
    qfrc = [al.mul(al.neg(d), v) for d, v in zip(cm.damping, qvel)]
    act = [0.0] * cm.nv
    for (dof, gear, gain, b0, b1, b2, ctrl_range, force_range), qadr, u in zip(cm.actuators, cm.actuator_qpos, ctrl):
        if ctrl_range is not None:
            u = jnp.clip(u, *ctrl_range)
        force = al.total((al.mul(gain, u), b0, al.mul(al.mul(b1, gear), qpos[qadr]),
                          al.mul(al.mul(b2, gear), qvel[dof])))
        if force_range is not None:
            force = jnp.clip(force, *force_range)
        act[dof] = al.add(act[dof], al.mul(gear, force))
    for dof, lo, hi in cm.joint_force_range:
        act[dof] = jnp.clip(act[dof], lo, hi)
    return tuple(al.add(a, b) for a, b in zip(qfrc, act))
