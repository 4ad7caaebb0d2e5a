"""The most one stance can put into a jump: the knee motor's torque-speed line over the leg's stroke.

A hop's energy comes from the motors during stance; the robot has no spring, so what a landing brings in is
absorbed by the leg on the way down and the next takeoff starts, at best, from rest at the bottom of the stroke.
The bound integrates the best push there is from that bottom to lift-off:

- The body stays upright and the whole-robot centre of mass (COM) straight above the foot; the knee alone sets
  its height h(q) over the floor (the virtual leg, `control.kinematics`). The hip joints then turn at zero torque:
  a hip torque would turn the body, not raise it. h(q) is measured with MuJoCo C on the compiled model, the knee
  from its lower stop to its upper one, the hip flexion chosen at each angle to keep the COM over the foot.
- The knee gives all its motor allows at each speed: the ideal motor its effort limit; the DC motor its line
  tau_s (1 - w/w0), clipped at the current limit (`actuators.envelope`). Full torque at every angle is the best
  push: it reaches every height of the stroke with the most speed.
- Energy: the whole robot's kinetic energy along the stroke is ½·I(q)·q̇², I(q) = tᵀ M t with M MuJoCo's mass
  matrix and t the path's tangent per radian of knee, so the links' own motion is paid for:
  d(½ I q̇²)/dq = tau(q̇) - m g h'(q). The COM's speed is h'(q)·q̇.
- Lift-off: the push may be released at any angle; the bound takes the one whose flight goes highest, up to where
  the knee can no longer keep up with the body (the DC line reaches zero torque, q̇ = w0: the floor's push would
  turn negative) or the knee's upper stop.
- The COM then rises v²/2g more. The apex reported is the base's, as the hop metrics measure it: the COM's
  apex plus the base's height over the COM in the lift-off pose, less the standing height.

So the ideal motor's work is its effort limit times the knee's travel to that lift-off, about the same whatever g;
a DC motor gives less, and less the faster the push (the lower g, the faster the knee turns over the same stroke).
The apex then scales about as 1/g. Per-instance robots (drawn masses, legs, motors) are not bounded apart: the
bound is the model's. Plain NumPy and MuJoCo C, computed once per sweep.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import mujoco
import numpy as np

from hopper_mjx.hardware.actuators import envelope
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import balancing, com_ahead_of_foot, standing_height

KNEE = 2  # joint index of kfe in (haa, hfe, kfe)
SAMPLES = 401  # knee angles at which h(q) is measured with MuJoCo C
SUBSTEPS = 20  # integration steps per sampled interval


class Stroke(NamedTuple):
    """The leg's stroke as the bound sees it, sampled at the knee's angles (from its lower stop up)."""

    knee: np.ndarray  # (S,) rad
    hip: np.ndarray  # (S,) rad, the hip flexion that keeps the COM above the foot
    com_height: np.ndarray  # (S,) m, COM over the floor, foot on the floor, COM above it
    base_over_com: np.ndarray  # (S,) m, the base origin's height over the COM in that pose
    inertia: np.ndarray  # (S,) kg·m²/rad²: the whole robot's kinetic energy is ½·inertia·q̇² along the stroke
    mass: float  # kg, the whole robot


class JumpBound(NamedTuple):
    """One gravity's bound (SI units)."""

    gravity: float  # m/s²
    energy: float  # J the knee's work from the push's start to the lift-off
    takeoff_speed: float  # m/s of the COM at lift-off
    takeoff_knee: float  # rad, the knee at lift-off
    apex_rise: float  # m, the base's apex over its standing height


class KneeMotor(NamedTuple):
    """The knee's motor, joint-side figures."""

    stall_torque: float  # N·m (the ideal motor: its effort limit)
    no_load_speed: float  # rad/s (inf: the ideal motor, no speed line)
    torque_limit: float  # N·m, the current limit


def knee_motor(mj_model: mujoco.MjModel, motor: str) -> KneeMotor:
    """The URDF's knee motor for a `registry.MOTORS` kind; refuses one that bounds nothing."""
    lay = Layout.of(mj_model)
    effort, speed = lay.effort_limit[KNEE], lay.speed_limit[KNEE]
    if not (math.isfinite(effort) and effort > 0):
        raise ValueError(f"the knee's motor has no effort limit ({effort:g} N·m): there is no bound on a jump; "
                         "give the URDF's kfe joint <limit effort=...>")
    if motor == "dc":
        if not math.isfinite(speed):
            raise ValueError("a dc motor's bound needs the knee's <limit velocity> in the URDF (its no-load speed)")
        return KneeMotor(effort, speed, effort)
    return KneeMotor(effort, math.inf, effort)


def _hip_over_foot(m: mujoco.MjModel, d: mujoco.MjData, lay: Layout, knee: float) -> float:
    """The hip flexion (rad) that puts the COM straight above the foot at `knee`; leaves d in that pose."""
    return balancing(lambda hip: com_ahead_of_foot(m, d, lay, hip, knee), *lay.joint_range[1],
                     f"hip flexion at knee {knee:.3f} rad")


def stroke(mj_model: mujoco.MjModel) -> Stroke:
    """h(q), the base's offset over the COM and the kinetic energy's inertia along the knee's range, measured
    with MuJoCo C: the foot's bottom held at the origin, the body upright, the COM above the foot."""
    m, lay = mj_model, Layout.of(mj_model)
    d = mujoco.MjData(m)
    foot = lay.foot_geom
    knees = np.linspace(*lay.joint_range[KNEE], SAMPLES)
    hips, height, offset = np.empty(SAMPLES), np.empty(SAMPLES), np.empty(SAMPLES)
    qpos = np.empty((SAMPLES, m.nq))
    for i, q in enumerate(knees):
        hips[i] = _hip_over_foot(m, d, lay, q)
        bottom = d.geom_xpos[foot] - [0.0, 0.0, m.geom_size[foot, 0]]
        qpos[i] = d.qpos
        qpos[i, :3] -= bottom  # the foot's bottom at the origin
        height[i] = d.subtree_com[0, 2] - bottom[2]
        offset[i] = d.qpos[2] - d.subtree_com[0, 2]
    # The path's tangent per radian of knee, in velocity coordinates (the base's orientation is fixed, so the
    # free joint's linear part is d(position)/dq and its angular part zero), and ½ t^T M t.
    tangent = np.zeros((SAMPLES, m.nv))
    slope = np.gradient(qpos, knees, axis=0)
    tangent[:, :3] = slope[:, :3]
    for j in lay.joint_qpos:
        tangent[:, lay.joint_dof[lay.joint_qpos.index(j)]] = slope[:, j]
    inertia = np.empty(SAMPLES)
    full = np.zeros((m.nv, m.nv))
    for i in range(SAMPLES):
        d.qpos[:] = qpos[i]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_crb(m, d)
        mujoco.mj_fullM(m, d, full)
        inertia[i] = tangent[i] @ full @ tangent[i]
    return Stroke(knees, hips, height, offset, inertia, float(m.body_mass.sum()))


def _knee_torque(motor: KneeMotor, speed: float) -> float:
    """N·m the knee's motor gives while extending at `speed` rad/s (`actuators.envelope`'s upper bound)."""
    return float(envelope(motor, speed, xp=np)[1])


def _push_across(leg: Stroke, slope: np.ndarray, motor: KneeMotor, g: float, i: int, kinetic: float,
                 work: float) -> tuple[float, float, bool]:
    """(kinetic energy J, the knee's work J, whether the foot left the floor) after pushing from sample i of the
    stroke to sample i + 1, in SUBSTEPS steps (slope and inertia interpolated linearly)."""
    dq = (leg.knee[i + 1] - leg.knee[i]) / SUBSTEPS
    for j in range(SUBSTEPS):
        f = (j + 0.5) / SUBSTEPS
        s = slope[i] + (slope[i + 1] - slope[i]) * f
        inertia = leg.inertia[i] + (leg.inertia[i + 1] - leg.inertia[i]) * f
        tau = _knee_torque(motor, math.sqrt(2.0 * kinetic / inertia))
        if tau <= 0.0:  # the knee cannot keep up with the body: the foot has left the floor
            return kinetic, work, True
        kinetic += (tau - leg.mass * g * s) * dq
        work += tau * dq
        if kinetic <= 0.0:  # the knee cannot lift the robot from here: the push starts higher up
            kinetic, work = 0.0, 0.0
    return kinetic, work, False


def jump_bound(leg: Stroke, motor: KneeMotor, gravity: float, standing: float) -> JumpBound:
    """The bound at `gravity` m/s² (> 0), for a robot standing with its base `standing` m up."""
    if not gravity > 0:
        raise ValueError(f"a jump's bound needs a downward gravity, got {gravity:g} m/s²")
    g = gravity
    slope = np.gradient(leg.com_height, leg.knee)  # h'(q), m/rad, > 0 as the knee extends
    kinetic, work = 0.0, 0.0  # J: the whole robot's kinetic energy ½·I·q̇², the knee's work so far
    best = (leg.com_height[0], 0.0, leg.knee[0], 0.0)  # (COM apex, COM speed, knee, work) of the best lift-off
    for i in range(len(leg.knee) - 1):
        kinetic, work, left = _push_across(leg, slope, motor, g, i, kinetic, work)
        if left:
            break
        v = slope[i + 1] * math.sqrt(2.0 * kinetic / leg.inertia[i + 1])  # the COM's speed
        apex = leg.com_height[i + 1] + v * v / (2.0 * g)
        if apex > best[0]:  # leaving the floor here (the push released) would fly this high
            best = (apex, v, leg.knee[i + 1], work)
    apex_com, speed, knee, work = best
    apex_base = apex_com + float(np.interp(knee, leg.knee, leg.base_over_com))
    return JumpBound(g, work, speed, float(knee), apex_base - standing)


def bounds(mj_model: mujoco.MjModel, motor: str, gravity) -> dict[float, JumpBound]:
    """{g: its JumpBound} for each gravity, the model's robot with `motor` (a registry.MOTORS kind)."""
    knee, leg, standing = _robot(mj_model, motor)
    return {float(g): jump_bound(leg, knee, float(g), standing) for g in gravity}


def _robot(mj_model: mujoco.MjModel, motor: str) -> tuple[KneeMotor, Stroke, float]:
    """What every gravity's bound is integrated over: the knee's motor, the leg's stroke (sampled in MuJoCo C, the
    costly part) and the standing height."""
    return knee_motor(mj_model, motor), stroke(mj_model), standing_height(mj_model)


def apex_bounds(mj_model: mujoco.MjModel, motor: str, gravity, height: float) -> dict[float, float]:
    """{g: the bound's apex rise, m} at each of `gravity` (> 0) when a commanded rise of `height` m asks for more
    than `motor` gives at one of them at least; {} when it asks for no more, or where the knee's motor bounds
    nothing (its URDF gives no limit). The highest gravity's bound is the lowest: one integration tells. The robot
    is sampled once for all of them."""
    try:
        knee, leg, standing = _robot(mj_model, motor)
        if height <= jump_bound(leg, knee, float(max(gravity)), standing).apex_rise:
            return {}
    except ValueError:
        return {}
    return {float(g): jump_bound(leg, knee, float(g), standing).apex_rise for g in gravity}


def tucked_drop(mj_model: mujoco.MjModel) -> float:
    """m from the base origin down to the foot's bottom with the leg drawn up as far as it goes (hips straight,
    the knee at its lower stop): the least the base must be above a block for the foot to pass over it."""
    m, lay = mj_model, Layout.of(mj_model)
    d = mujoco.MjData(m)
    d.qpos[:] = m.qpos0
    d.qpos[list(lay.joint_qpos)] = (0.0, 0.0, lay.joint_range[KNEE][0])
    mujoco.mj_kinematics(m, d)
    return float(d.qpos[2] - (d.geom_xpos[lay.foot_geom, 2] - m.geom_size[lay.foot_geom, 0]))


def highest_block(b: JumpBound, standing: float, drop: float) -> float:
    """m: the tallest block the bound's apex lets the foot pass over (foot drawn up, no clearance): the base's
    highest point, standing + apex rise, less `tucked_drop`."""
    return standing + b.apex_rise - drop


def widest_gap(b: JumpBound, reach: float) -> float:
    """m: the widest gap a jump of the bound's takeoff speed spans, level to level: the COM's range v²/g launched at
    45°, and the foot leaving from `reach` behind the COM and landing `reach` ahead of it (`leg_reach`). A push along
    a tilted leg works against less of the weight and gives a little more speed; left out."""
    return b.takeoff_speed**2 / b.gravity + 2.0 * reach


def leg_reach(mj_model: mujoco.MjModel) -> float:
    """m: the farthest the foot's edge gets from the hip's flexion axis, the leg straight: thigh, shank and the foot's
    radius, as far as the foot can be ahead of or behind the COM at takeoff and landing (a loose figure: the COM
    sits above the hip, and a leg swung far out does not hold the body)."""
    from hopper_mjx.model.robot import LegGeometry

    leg = LegGeometry.of(mj_model)
    return leg.thigh + leg.shank + leg.foot_radius
