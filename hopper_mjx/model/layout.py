"""Where things live in a compiled monoped: addresses, limits and lengths by name.

A `Layout` holds only Python scalars and tuples, so it is hashable and can be a
static argument of compiled functions, like MJX's own NumPy model structure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from hopper_mjx.model.loader import FLOOR_GEOM, FOOT_GEOM, JOINTS, ROOT_JOINT


@dataclass(frozen=True)
class Layout:
    nq: int
    nv: int
    nu: int
    timestep: float  # s
    joint_qpos: tuple[int, ...]  # qpos address of haa, hfe, kfe
    joint_dof: tuple[int, ...]  # qvel address of haa, hfe, kfe
    joint_range: tuple[tuple[float, float], ...]  # rad
    effort_limit: tuple[float, ...]  # N·m of joint torque, haa, hfe, kfe (the URDF's <limit effort>)
    speed_limit: tuple[float, ...]  # rad/s, haa, hfe, kfe (the URDF's <limit velocity>; inf: none given)
    gear: tuple[float, ...]  # joint torque per unit of control, haa, hfe, kfe (mechanicalReduction)
    actuator_of_joint: tuple[int, ...]  # actuator index driving haa, hfe, kfe
    foot_geom: int
    floor_geom: int
    total_mass: float  # kg
    # The leg's lengths are the leg's: `model.robot.LegGeometry`.

    @classmethod
    def of(cls, m: mujoco.MjModel) -> "Layout":
        if m.jnt_type[0] != mujoco.mjtJoint.mjJNT_FREE or m.joint(0).name != ROOT_JOINT:
            raise ValueError("the first joint must be the free base joint added by hopper_mjx.model.load")
        joints = [m.joint(name) for name in JOINTS]
        act = []
        for j in joints:
            driving = np.flatnonzero((m.actuator_trnid[:, 0] == j.id) & (m.actuator_trntype == 0))
            if len(driving) != 1:
                raise ValueError(f"joint '{j.name}' must be driven by exactly one motor")
            act.append(int(driving[0]))
        foot = m.geom(FOOT_GEOM)
        if len({int(j.bodyid[0]) for j in joints} | {int(foot.bodyid[0])}) != 4:
            raise ValueError("haa, hfe, kfe and the foot must sit on four distinct bodies")
        gear = m.actuator_gear[act, 0]
        torque_range = m.actuator_ctrlrange[act] * gear[:, None]  # rows in joint order
        return cls(
            nq=m.nq,
            nv=m.nv,
            nu=m.nu,
            timestep=float(m.opt.timestep),
            joint_qpos=tuple(int(j.qposadr[0]) for j in joints),
            joint_dof=tuple(int(j.dofadr[0]) for j in joints),
            joint_range=tuple((float(j.range[0]), float(j.range[1])) for j in joints),
            effort_limit=tuple(float(v) for v in torque_range[:, 1]),
            # The loader keeps each motor's URDF velocity limit as its user data (no MuJoCo field holds one).
            speed_limit=tuple(float(m.actuator_user[a, 0]) if m.nuser_actuator else math.inf for a in act),
            gear=tuple(float(v) for v in gear),
            actuator_of_joint=tuple(act),
            foot_geom=int(foot.id),
            floor_geom=int(m.geom(FLOOR_GEOM).id),
            total_mass=float(m.body_mass.sum()),
        )
