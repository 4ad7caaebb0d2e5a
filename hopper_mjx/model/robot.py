"""Robot facts computed once from a compiled monoped and passed down to every layer.

The stance pose, the standing height and the leg geometry belong to the robot,
not to the simulator or a controller: they are measured here from the `MjModel`
with MuJoCo C, once, and everything above takes them as arguments.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import mujoco
import numpy as np

from hopper_mjx.model.layout import Layout
from hopper_mjx.model.loader import JOINTS, LEG_CONTACT_GROUP

STANCE_HFE = 0.5  # rad: hip flexion of the default crouched stance
CLEARANCE = 0.05  # m between the foot and the floor in the default initial state


def com_ahead_of_foot(m: mujoco.MjModel, d: mujoco.MjData, lay: Layout, hip: float, knee: float) -> float:
    """m the whole-robot centre of mass is ahead (+x) of the foot's centre with the joints at (0, hip, knee) and the
    base at qpos0; leaves `d` in that pose."""
    d.qpos[:] = m.qpos0
    d.qpos[list(lay.joint_qpos)] = (0.0, hip, knee)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    return d.subtree_com[0, 0] - d.geom_xpos[lay.foot_geom, 0]


def balancing(ahead, lo: float, hi: float, what: str) -> float:
    """The angle in [lo, hi] where `ahead(angle)` (the COM ahead of the foot) is zero, by 60 bisections, `ahead`
    called last at it; ValueError naming `what` when it keeps one sign there."""
    f_lo = ahead(lo)
    if f_lo * ahead(hi) > 0:
        raise ValueError(f"no {what} puts the centre of mass above the foot")
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f_mid = ahead(mid)
        if f_lo * f_mid <= 0:
            hi = mid
        else:
            lo, f_lo = mid, f_mid
    ahead(0.5 * (lo + hi))
    return 0.5 * (lo + hi)


def stance_qpos(mj_model: mujoco.MjModel, clearance: float = CLEARANCE, hfe: float = STANCE_HFE) -> np.ndarray:
    """qpos upright at rest: hip flexed by `hfe`, the knee bent so that the whole-robot
    centre of mass sits straight above the foot, the foot `clearance` m above the floor."""
    m, lay = mj_model, Layout.of(mj_model)
    d = mujoco.MjData(m)
    balancing(lambda kfe: com_ahead_of_foot(m, d, lay, hfe, kfe), *lay.joint_range[2], f"knee angle at hfe={hfe}")
    d.qpos[2] += clearance - (d.geom_xpos[lay.foot_geom, 2] - m.geom_size[lay.foot_geom, 0])
    return d.qpos.copy()


def standing_qpos(mj_model: mujoco.MjModel) -> np.ndarray:
    """qpos standing still in the default stance with the foot on the floor (`stance_qpos` is the
    same pose lifted `CLEARANCE` m, the default initial state)."""
    return stance_qpos(mj_model, clearance=0.0)


def standing_height(mj_model: mujoco.MjModel) -> float:
    """Base height (m) of the model standing still in the default stance, foot on the floor."""
    return float(standing_qpos(mj_model)[2])


def holding_torque(mj_model: mujoco.MjModel) -> np.ndarray:
    """(3,) N·m per m/s² of gravity: the joint torques (haa, hfe, kfe) that hold the robot still in its standing
    pose, its whole weight on the foot (static balance: each link's weight against the foot's contact force)."""
    m, lay = mj_model, Layout.of(mj_model)
    d = mujoco.MjData(m)
    d.qpos[:] = standing_qpos(m)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    weight = np.zeros(m.nv)  # generalised force of each link's weight under 1 m/s² of gravity
    jac = np.zeros((3, m.nv))
    for body in range(1, m.nbody):
        mujoco.mj_jacBodyCom(m, d, jac, None, body)
        weight -= jac.T @ np.array([0.0, 0.0, m.body_mass[body]])
    contact = d.geom_xpos[lay.foot_geom] - [0.0, 0.0, m.geom_size[lay.foot_geom, 0]]  # the sphere's lowest point
    mujoco.mj_jac(m, d, jac, None, contact, m.geom_bodyid[lay.foot_geom])
    joints = list(lay.joint_dof)
    base = [i for i in range(m.nv) if i not in joints]
    force = np.linalg.lstsq(jac[:, base].T, -weight[base], rcond=None)[0]  # the floor's push that balances the base
    return -(weight[joints] + jac[:, joints].T @ force)


def max_standing_gravity(mj_model: mujoco.MjModel) -> tuple[float, int]:
    """(m/s², joint index): the strongest gravity under which the motors can still hold the standing pose, and the
    joint whose effort limit sets it."""
    per_g = np.abs(holding_torque(mj_model))
    limits = np.asarray(Layout.of(mj_model).effort_limit)
    ratios = np.where(per_g > 0, limits / np.maximum(per_g, 1e-300), np.inf)
    k = int(np.argmin(ratios))
    return float(ratios[k]), k


# What makes the robot this robot: its bodies, inertias, joints, limits, motors and geoms,
# not the world it stands in (timestep, gravity, floor, friction).
_FINGERPRINT_FIELDS = ("body_pos", "body_quat", "body_mass", "body_inertia", "body_ipos", "body_iquat", "jnt_type",
                       "jnt_axis", "jnt_pos", "jnt_range", "actuator_gear", "actuator_ctrlrange")


def fingerprint(mj_model: mujoco.MjModel) -> str:
    """A short hash of the robot a compiled model holds (a trained policy records the one it learnt on)."""
    m = mj_model
    h = hashlib.sha256()
    for name in _FINGERPRINT_FIELDS:
        h.update(np.round(np.asarray(getattr(m, name), dtype=float), 9).tobytes())
    # The floor (or terrain) belongs to the world; the leg links' contact boxes (terrain only) follow from their
    # cylinders: a policy learnt on the plane runs on a terrain.
    on_robot = (m.geom_bodyid > 0) & (m.geom_group != LEG_CONTACT_GROUP)
    for name in ("geom_type", "geom_size", "geom_pos", "geom_quat"):
        h.update(np.round(np.asarray(getattr(m, name)[on_robot], dtype=float), 9).tobytes())
    return h.hexdigest()[:16]


def _link_groups(m: mujoco.MjModel, joints) -> list[list[int]]:
    """Bodies of base, hip, thigh and shank (+ everything rooted below the shank, e.g. the foot)."""
    base = int(m.jnt_bodyid[0])
    groups = [[base]] + [[int(j.bodyid[0])] for j in joints]
    groups[-1] += [b for b in range(m.nbody) if b not in sum(groups, []) and m.body_rootid[b] == base]
    return groups


def _group_inertia(m: mujoco.MjModel, d: mujoco.MjData, group, com) -> tuple[float, float, float]:
    """Principal inertia of a body group about its own COM (parallel-axis), frames aligned at zero angles."""
    total = np.zeros((3, 3))
    for b in group:
        rot = d.ximat[b].reshape(3, 3)
        r = d.xipos[b] - com
        total += rot @ np.diag(m.body_inertia[b]) @ rot.T + m.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
    return tuple(float(v) for v in np.diag(total))


@dataclass(frozen=True)
class LegGeometry:
    """Static lengths of a monoped leg (m), hashable like `Layout`."""

    haa_below_base: float  # base origin -> haa axis
    hfe_below_haa: float  # haa axis -> hfe axis, along the leg at zero haa
    thigh: float  # hfe -> kfe
    shank: float  # kfe -> foot centre
    foot_radius: float
    # Mass (kg) and centre of mass (m, in the link's frame at zero angles, from its
    # joint axis; for the base from the haa axis point) of base, hip, thigh, shank+foot.
    link_mass: tuple[float, ...]
    link_com: tuple[tuple[float, float, float], ...]
    link_inertia: tuple[tuple[float, float, float], ...]  # kg·m², principal, about each link's COM

    @classmethod
    def of(cls, m: mujoco.MjModel) -> "LegGeometry":
        """Measures a compiled monoped at its reference pose (every joint at zero), lengths between
        consecutive joint anchors."""
        foot = Layout.of(m).foot_geom
        d = mujoco.MjData(m)
        mujoco.mj_kinematics(m, d)  # reference pose: frames aligned
        joints = [m.joint(name) for name in JOINTS]
        anchor = [d.xanchor[j.id].copy() for j in joints]
        groups = _link_groups(m, joints)
        mass = [float(m.body_mass[g].sum()) for g in groups]
        com = [(m.body_mass[g][:, None] * d.xipos[g]).sum(axis=0) / mm for g, mm in zip(groups, mass)]
        origin = [anchor[0]] + anchor  # the base's COM is taken from the haa axis point too
        return cls(
            haa_below_base=float(np.linalg.norm(anchor[0] - d.xpos[m.jnt_bodyid[0]])),
            hfe_below_haa=float(np.linalg.norm(anchor[1] - anchor[0])),
            thigh=float(np.linalg.norm(anchor[2] - anchor[1])),
            shank=float(np.linalg.norm(d.geom_xpos[foot] - anchor[2])),
            foot_radius=float(m.geom_size[foot, 0]),
            link_mass=tuple(mass),
            link_com=tuple(tuple(float(v) for v in c - o) for c, o in zip(com, origin)),
            link_inertia=tuple(_group_inertia(m, d, g, c) for g, c in zip(groups, com)),
        )


@dataclass(frozen=True)
class Robot:
    """Everything the layers above read about one compiled monoped; hashable, so a static argument."""

    layout: Layout
    leg: LegGeometry
    stance_qpos: tuple[float, ...]  # the default initial pose (foot `CLEARANCE` above the floor)
    standing_height: float  # m, base height in that stance with the foot on the floor

    @classmethod
    def of(cls, mj_model: mujoco.MjModel) -> "Robot":
        leg = LegGeometry.of(mj_model)
        return cls(
            layout=Layout.of(mj_model),
            leg=leg,
            stance_qpos=tuple(float(v) for v in stance_qpos(mj_model)),
            standing_height=standing_height(mj_model),
        )

    @property
    def stance_joints(self) -> np.ndarray:
        """(3,) rad, haa, hfe, kfe of the stance."""
        return np.asarray(self.stance_qpos)[list(self.layout.joint_qpos)]


def same_robot(recorded: str, mj_model, what: str) -> str:
    """The fingerprint of `mj_model`'s robot, refusing one other than `recorded` (when recorded)."""
    found = fingerprint(mj_model)
    if recorded and recorded != found:
        raise ValueError(f"{what} is for another robot (fingerprint {recorded}) than the one given ({found}): "
                         "give the --urdf it was trained with")
    return found
