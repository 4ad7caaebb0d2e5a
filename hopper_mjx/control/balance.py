"""`balance`: an LQR about the monoped standing on its sphere foot (why `stand` allows small hops: docs/control.md).

The robot standing still is an inverted pendulum on a 3 cm ball with an actuated hip
(haa, hfe) and knee (kfe): underactuated, like the acrobot. The controller is linear
state feedback about that stance:

1. Equilibrium (MuJoCo C, float64): the standing pose (`model.robot.standing_qpos`, the
   centre of mass above the foot) lowered into the soft contact and the joint torques
   that hold it, found by Gauss-Newton on qacc = 0 at rest.
2. Linearisation about that state, in tangent coordinates: dq (9: base position, base
   rotation vector in the body frame, joint angles) and qvel (9), as MuJoCo's
   `mjd_transitionFD` lays them out. The gain uses MuJoCo C's (`c_linearisation`);
   `jax_linearisation` (`jax.jacfwd` of the engine's step) differs from it by 1.2 % of
   max |A|, an open question (docs/control.md), and a gain on it does not hold the roll.
3. Design: three coordinates are left out, each an uncontrollable mode with λ = 1 that
   nothing else depends on at first order (the PBH test finds them, to 1e-13):
   the yaw angle and yaw rate (the joint axes lie along x and y and the sphere contact
   has no torsional friction, so nothing turns the robot about the vertical), and the
   horizontal position (a ball rolling without slip keeps x_foot + r·θ_shank fixed, so
   the robot can stand anywhere but cannot be steered back: the horizontal *speed* is
   held at zero instead, and the robot may end a kick a few cm from where it began).
   The rest is checked stabilisable (PBH test on every mode with |λ| >= 1) and a
   discrete-time LQR gain comes from the Riccati equation, solved by doubling (NumPy).

Gravity is per instance, so steps 1-3 run on a log-spaced grid of g (`GRID`) and the
controller interpolates the gain in log g, the holding torque per unit g and the
equilibrium pose in g at run time.
"""

from __future__ import annotations

import copy
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from hopper_mjx.control.base import Controller, saturate, to_ctrl
from hopper_mjx.hardware.signals import Observation
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import Robot, standing_qpos
from hopper_mjx.shell.programs import model_digest

GRID = tuple(float(g) for g in np.geomspace(0.5, 12.0, 7))  # m/s², the gravities the gain is designed at
# Bryson's rule: the deviation of each state (m, rad, m/s, rad/s) and torque (share of the
# effort limit) that costs one unit. Tilt is what falls, so it is held tightest.
MAX_DEVIATION = {"z": 0.05, "tilt": 0.05, "joint": 0.3, "xy_rate": 0.5, "z_rate": 0.5,
                 "tilt_rate": 1.0, "joint_rate": 2.0}
MAX_TORQUE_SHARE = 0.5
YAW = 5  # the tangent index of the yaw angle and of the yaw rate (within qvel)
# The designed coordinates: neither yaw nor the horizontal position (see the module doc).
KEPT_POSITION = (2, 3, 4, 6, 7, 8)  # z, roll, pitch, haa, hfe, kfe
KEPT_RATE = (0, 1, 2, 3, 4, 6, 7, 8)  # all but the yaw rate


class Linear(NamedTuple):
    """x' = A x + B u about one equilibrium; x = (dq, qvel) in tangent coordinates, u joint torques."""

    qpos: np.ndarray  # (nq,) the equilibrium pose
    torque: np.ndarray  # (3,) N·m, haa, hfe, kfe holding it
    a: np.ndarray  # (2 nv, 2 nv)
    b: np.ndarray  # (2 nv, 3)


class Design(NamedTuple):
    """The gain at one gravity and what decided it."""

    linear: Linear
    gain: np.ndarray  # (3, 2 nv) u = torque - gain @ x (zero columns for yaw)
    open_loop: float  # spectral radius of A (reduced), > 1: the stance falls unaided
    closed_loop: float  # spectral radius of A - B K (reduced)
    pbh: float  # smallest singular value of [λI - A, B] over the modes with |λ| >= 1 (0: not stabilisable)


def equilibrium(mj_model: mujoco.MjModel, g: float, *, iterations: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """(qpos, joint torques) standing still at gravity g: the standing pose sunk into the soft
    contact, from MuJoCo C in float64 (Gauss-Newton on qacc = 0 over base height and torques)."""
    lay = Layout.of(mj_model)
    m = copy.deepcopy(mj_model)
    m.opt.gravity[:] = (0.0, 0.0, -g)
    d = mujoco.MjData(m)
    qpos = standing_qpos(m)

    def qacc(p: np.ndarray) -> np.ndarray:
        d.qpos[:] = qpos
        d.qpos[2] += p[0]
        d.qvel[:] = 0.0
        d.qacc_warmstart[:] = 0.0
        d.ctrl[:] = 0.0
        d.ctrl[list(lay.actuator_of_joint)] = p[1:] / np.asarray(lay.gear)
        mujoco.mj_forward(m, d)
        return d.qacc.copy()

    p = np.zeros(4)
    for _ in range(iterations):
        r = qacc(p)
        jac = np.stack([(qacc(p + e) - qacc(p - e)) / (2 * e.max()) for e in np.eye(4) * 1e-7], axis=1)
        p = p - np.linalg.lstsq(jac, r, rcond=None)[0]
        if np.abs(r).max() < 1e-10:
            break
    qpos = qpos.copy()
    qpos[2] += p[0]
    return qpos, p[1:]


def tangent_qpos(qpos, dq):
    """qpos displaced by the tangent dq (9,): base position, base rotation by the body-frame vector
    dq[3:6] (to first order, as the linearisation needs), joint angles."""
    half = jnp.concatenate([jnp.ones(1, dq.dtype), 0.5 * dq[3:6]])
    half = half / jnp.linalg.norm(half)
    return jnp.concatenate([qpos[:3] + dq[:3], _quat_mul(qpos[3:7], half), qpos[7:] + dq[6:]])


def tangent_error(qpos, reference):
    """(9,) the tangent from `reference` to `qpos`: position, body-frame rotation vector (to first order), joints."""
    w, x, y, z = (reference[i] for i in range(3, 7))
    a, b, c, d = (qpos[i] for i in range(3, 7))
    # conj(reference) ⊗ qpos, the rotation from the reference to the present pose in the body frame
    rw = w * a + x * b + y * c + z * d
    rv = jnp.stack([w * b - x * a - y * d + z * c, w * c + x * d - y * a - z * b, w * d - x * c + y * b - z * a])
    return jnp.concatenate([qpos[:3] - reference[:3], 2.0 * jnp.sign(rw) * rv, qpos[7:] - reference[7:]])


def heading_state(qpos, qvel, reference):
    """x = (dq, qvel) from the stance `reference` turned to the robot's present heading: the design has no
    yaw, so a robot that has turned about the vertical is held in its own heading frame (its linear
    velocity too; the base rate is already in the body frame)."""
    w, qx, qy, qz = (qpos[i] for i in range(3, 7))
    yaw = jnp.arctan2(2 * (w * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    turn = jnp.stack([jnp.cos(yaw / 2), 0.0 * yaw, 0.0 * yaw, jnp.sin(yaw / 2)])
    reference = reference.at[3:7].set(_quat_mul(turn, reference[3:7]))
    dq = tangent_error(qpos, reference)
    unturn = lambda v: jnp.stack([c * v[0] + s * v[1], -s * v[0] + c * v[1]])
    dq = dq.at[:2].set(0.0).at[YAW].set(0.0)  # not designed: the gain's columns there are zero
    qvel = qvel.at[:2].set(unturn(qvel[:2]))
    return jnp.concatenate([dq, qvel])


def _quat_mul(p, q):
    w, x, y, z = (p[i] for i in range(4))
    a, b, c, d = (q[i] for i in range(4))
    return jnp.stack([w * a - x * b - y * c - z * d, w * b + x * a + y * d - z * c,
                      w * c - x * d + y * a + z * b, w * d + x * c - y * b + z * a])


def velocity_jacobians(engine, layout: Layout):
    """A compiled `(qpos, torque, g) -> (d qvel'/d dq, d qvel'/d qvel, d qvel'/d torque)` of one engine step at
    rest; the arguments are traced, so one compile serves every gravity (called once per gravity: a vmap over
    them made XLA's compile take minutes and gigabytes)."""
    act = jnp.asarray(layout.actuator_of_joint)
    gear = jnp.asarray(layout.gear)

    def next_qvel(dq, qvel, torque, qpos, g):
        ctrl = jnp.zeros(layout.nu, qpos.dtype).at[act].set(torque / gear)
        gravity = jnp.stack([jnp.zeros_like(g), jnp.zeros_like(g), -g])
        # The solver starts from free fall, not from the answer: started at the equilibrium's qacc (0) it would
        # stop at once, and forward-mode derivatives through a loop that never ran are those of its start.
        fall = jnp.zeros(layout.nv, qpos.dtype).at[2].set(-g)
        d = engine.make_data(tangent_qpos(qpos, dq), qvel).replace(ctrl=ctrl, qacc_warmstart=fall)
        d = engine.forward(engine.model, d, gravity)
        return engine.integrate(engine.model, d, gravity).qvel

    def jacobians(qpos, torque, g):
        zero = jnp.zeros(layout.nv, qpos.dtype)
        return jax.jacfwd(next_qvel, (0, 1, 2))(zero, zero, jnp.zeros_like(torque), qpos, g)

    return jax.jit(jacobians, compiler_options=engine.compiler_options)


def discrete(layout: Layout, qpos, torque, dv_dq, dv_dv, dv_du) -> Linear:
    """The step's (A, B) from its velocity Jacobians: semi-implicit Euler moves the pose by h·qvel'
    (exact to first order, for the base rotation too: at rest the body-frame rotations add)."""
    h, nv = layout.timestep, layout.nv
    dv = np.hstack([dv_dq, dv_dv])
    a = np.vstack([np.hstack([np.eye(nv), np.zeros((nv, nv))]) + h * dv, dv])
    b = np.vstack([h * dv_du, dv_du])
    return Linear(qpos=np.asarray(qpos, float), torque=np.asarray(torque, float), a=a, b=b)


def reduced(n: int) -> np.ndarray:
    """Indices of x = (dq, qvel) kept in the design (`KEPT_POSITION`, `KEPT_RATE`)."""
    return np.array([*KEPT_POSITION, *(n + i for i in KEPT_RATE)])


def riccati(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, *, iterations: int = 60) -> np.ndarray:
    """P of the discrete algebraic Riccati equation P = Q + A'PA - A'PB (R + B'PB)^-1 B'PA, by the
    structure-preserving doubling algorithm (quadratic convergence, so a 1 kHz step's slow modes
    need tens of iterations rather than the plain recursion's ~10^5)."""
    n = a.shape[0]
    ak, gk, hk = a.copy(), b @ np.linalg.solve(r, b.T), q.copy()
    for _ in range(iterations):
        w = np.linalg.inv(np.eye(n) + gk @ hk)
        ak, gk, h_next = ak @ w @ ak, gk + ak @ w @ gk @ ak.T, hk + ak.T @ hk @ w @ ak
        done = np.abs(h_next - hk).max() <= 1e-12 * max(1.0, np.abs(h_next).max())
        hk = 0.5 * (h_next + h_next.T)
        if done:
            break
    return hk


def lqr_gain(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """K with u = -K x minimising Σ x'Qx + u'Ru."""
    p = riccati(a, b, q, r)
    return np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)


def pbh(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest singular value of [λI - A, B] over A's modes with |λ| >= 1: > 0 iff (A, B) is stabilisable."""
    n = a.shape[0]
    lams = [lam for lam in np.linalg.eigvals(a) if abs(lam) >= 1.0 - 1e-9]
    return min((np.linalg.svd(np.hstack([lam * np.eye(n) - a, b]), compute_uv=False)[-1] for lam in lams),
               default=np.inf)


def weights(layout: Layout) -> tuple[np.ndarray, np.ndarray]:
    """(Q, R) of the reduced state (Bryson's rule on `MAX_DEVIATION`, `MAX_TORQUE_SHARE`)."""
    dev = MAX_DEVIATION
    position = [dev["z"], dev["tilt"], dev["tilt"], dev["joint"], dev["joint"], dev["joint"]]
    rate = [dev["xy_rate"], dev["xy_rate"], dev["z_rate"], dev["tilt_rate"], dev["tilt_rate"],
            dev["joint_rate"], dev["joint_rate"], dev["joint_rate"]]
    q = np.diag(1.0 / np.square(position + rate))
    r = np.diag(1.0 / np.square(MAX_TORQUE_SHARE * np.asarray(layout.effort_limit)))
    return q, r


def design(linear: Linear, layout: Layout) -> Design:
    """The LQR gain of one linearisation, on the state without yaw."""
    keep = reduced(layout.nv)
    a, b = linear.a[np.ix_(keep, keep)], linear.b[keep]
    q, r = weights(layout)
    k = lqr_gain(a, b, q, r)
    gain = np.zeros((b.shape[1], 2 * layout.nv))
    gain[:, keep] = k
    radius = lambda m: float(np.abs(np.linalg.eigvals(m)).max())
    return Design(linear=linear, gain=gain, open_loop=radius(a), closed_loop=radius(a - b @ k), pbh=pbh(a, b))


def c_linearisation(mj_model: mujoco.MjModel, g: float) -> Linear:
    """(A, B) of MuJoCo C's step about the equilibrium at gravity g, by its centred finite differences
    (`mjd_transitionFD`, float64, the constraint solver run to convergence), B in joint torques."""
    lay = Layout.of(mj_model)
    qpos, torque = equilibrium(mj_model, g)
    m = copy.deepcopy(mj_model)
    m.opt.gravity[:] = (0.0, 0.0, -g)
    m.opt.iterations, m.opt.ls_iterations, m.opt.tolerance = 100, 50, 1e-15
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    d.ctrl[list(lay.actuator_of_joint)] = torque / np.asarray(lay.gear)
    a, b = np.zeros((2 * m.nv, 2 * m.nv)), np.zeros((2 * m.nv, m.nu))
    mujoco.mjd_transitionFD(m, d, 1e-7, 1, a, b, None, None)
    b = b[:, list(lay.actuator_of_joint)] / np.asarray(lay.gear)
    return Linear(qpos=qpos, torque=torque, a=a, b=b)


def jax_linearisation(engine, mj_model: mujoco.MjModel, grid=GRID) -> list[Linear]:
    """(A, B) about each equilibrium of `grid` from `jax.jacfwd` of the engine's step (one compile)."""
    layout = Layout.of(mj_model)
    dtype = jnp.zeros(0).dtype  # float64 under jax x64, else float32
    jacobians = velocity_jacobians(engine, layout)
    out = []
    for g in grid:
        q, tau = equilibrium(mj_model, g)
        jac = jacobians(jnp.asarray(q, dtype), jnp.asarray(tau, dtype), jnp.asarray(g, dtype))
        out.append(discrete(layout, q, tau, *(np.asarray(j, float) for j in jac)))
    return out


def designs(mj_model: mujoco.MjModel, grid=GRID) -> list[Design]:
    """One `Design` per gravity of `grid`, from MuJoCo C's linearisation: the engine's own (`jax_linearisation`)
    differs from it by 1.2 % of max |A| (docs/control.md), enough to leave the roll loop unstable."""
    layout = Layout.of(mj_model)
    return [design(c_linearisation(mj_model, g), layout) for g in grid]


class BalanceState(NamedTuple):
    work: jax.Array  # () J, |τ·q̇| integrated, as Raibert's (the sweep's cost of transport reads it)


def balance(robot: Robot, mj_model: mujoco.MjModel, grid=GRID) -> Controller:
    """`balance`: u = τ₀(g) - K(g)·(x - x₀(g)), K and the equilibrium interpolated in log g over `grid`,
    clipped at the effort limits. Raises ValueError if a grid point is not stabilisable."""
    found = designs(mj_model, grid)
    bad = [g for g, d in zip(grid, found) if not (d.pbh > 1e-9 and d.closed_loop < 1.0)]
    if bad:
        raise ValueError(f"balance: the stance is not stabilisable at g = {bad} m/s²")
    layout = robot.layout
    log_g = jnp.asarray(np.log(grid))
    qpos0 = jnp.asarray(np.stack([d.linear.qpos for d in found]))
    # Holding torque is gravity's moment, proportional to g: interpolated per unit g, it is exact between
    # the grid's points (interpolating the torque itself in log g would leave a bias the weak pendulum mode
    # cannot afford).
    torque_per_g = jnp.asarray(np.stack([d.linear.torque / g for g, d in zip(grid, found)]))
    gain = jnp.asarray(np.stack([d.gain for d in found]))
    joint_dof = jnp.asarray(layout.joint_dof)

    def at(table, g, linear=False):
        """Table rows interpolated (linearly in log g, or in g: `linear`; held at the ends) at gravity g."""
        flat = table.reshape(table.shape[0], -1)
        x, xs = (g, jnp.exp(log_g)) if linear else (jnp.log(g), log_g)
        row = jax.vmap(lambda col: jnp.interp(x, xs, col), in_axes=1)(flat)
        return row.reshape(table.shape[1:])

    def act(s: BalanceState, obs: Observation, gravity):
        g = jnp.maximum(-gravity[2], grid[0])
        x = heading_state(obs.qpos, obs.qvel, at(qpos0, g, linear=True))  # the contact sinks in proportion to g
        torque = saturate(layout, g * at(torque_per_g, g) - at(gain, g) @ x)
        work = s.work + jnp.abs(torque * obs.qvel[joint_dof]).sum() * layout.timestep
        return to_ctrl(layout, torque), BalanceState(work=work)

    return Controller(name="balance", init=lambda obs, params: BalanceState(work=jnp.zeros(())), act=act,
                      key=f"balance|{grid!r}|{robot!r}|{model_digest(mj_model)}")
