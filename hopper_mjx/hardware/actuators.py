"""Actuator models: what turns a controller's commanded joint torques into the torques the joints get.

A controller commands each joint's torque as if its motor were a perfect torque source. The
actuator sits between it and the engine, per instance and pure, as the core vmaps it:

    ctrl (commanded) -> [delay line] -> [the motor's torque-speed envelope] -> ctrl (applied)

- `ideal`: the seed's EffortJointInterface, a torque source up to the URDF's effort limit (the
  controllers saturate there already), so nothing is added: today's numbers, today's program.
- `dc`: a DC motor behind its gearbox, as joint-side figures: stall torque `tau_s` (default the
  URDF's effort) and no-load speed `w0` (default the URDF's velocity). At a supply voltage the
  motor gives tau = tau_s (u - w / w0), u in [-1, 1], so the torque it can apply at joint speed w
  lies in [tau_s (-1 - w / w0), tau_s (1 - w / w0)]: a clip whose bounds move with the speed (the
  line of Isaac Lab's DCMotor). Driving itself, a joint therefore never passes w0. A current limit,
  given as the joint torque it allows (default the stall torque: no further limit), clips again.
  Its electrical power is the mechanical power plus the copper loss i²R, which for these figures is
  tau² w0 / tau_s (R = V² / (tau_s w0), i = tau w0 / V); the supply gives no energy back (no
  regeneration), so the energy drawn is the integral of max(P, 0).
- A position controller (a policy, `control.base.Servo`) commands joint targets instead: they go
  through the same delay line (`delayed`), its drivers' PD law makes the torque on the joints as they
  are now, and the motors' envelope applies to that (`motors`).
- An action delay of `delay` physics steps, per instance, applies each command that many steps
  after the controller gave it; the motors start from zero torque (the line starts empty).

The model's kind and the delay line's length are static (they shape the program); every figure
is a per-instance value carried in the batch's state (`Drive`), so instances can differ without
a recompile.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx import registry
from hopper_mjx.model.layout import Layout


class Motor(NamedTuple):
    """One instance's motor figures, joint order (haa, hfe, kfe)."""

    stall_torque: jax.Array  # (3,) N·m at the joint, at zero speed
    no_load_speed: jax.Array  # (3,) rad/s at the joint
    torque_limit: jax.Array  # (3,) N·m, the current limit as the joint torque it allows
    delay: jax.Array  # () int32, physics steps from command to torque


class Drive(NamedTuple):
    """One instance's actuator state."""

    motor: Motor
    line: jax.Array  # (depth, 3) N·m commanded joint torques, newest first
    energy: jax.Array  # () J: dc, drawn from the supply; ideal, the motors' work ∫Σ|τ·q̇|dt (as the controllers')


def envelope(motor: Motor, speed: jax.Array, xp=jnp) -> tuple[jax.Array, jax.Array]:
    """(lowest, highest) joint torque N·m the motor can apply at joint speed `speed` rad/s. `motor` needs only
    the three figures; xp=np works it out in NumPy (the metrics' and the jump bound's float64)."""
    tau_s, w0 = motor.stall_torque, motor.no_load_speed
    ratio = speed / w0  # w0 = inf (no velocity limit in the URDF): 0, a plain torque source
    low = xp.maximum(tau_s * (-1.0 - ratio), -motor.torque_limit)
    high = xp.minimum(tau_s * (1.0 - ratio), motor.torque_limit)
    return xp.minimum(low, 0.0), xp.maximum(high, 0.0)


def electrical_power(motor: Motor, torque: jax.Array, speed: jax.Array) -> jax.Array:
    """(3,) W each joint's motor draws: mechanical power plus copper loss tau² w0 / tau_s."""
    return torque * speed + torque * torque * motor.no_load_speed / motor.stall_torque


def nominal_no_load(layout: Layout, kind: str) -> np.ndarray:
    """(3,) rad/s: each joint's motor's no-load speed as the URDF gives it (its <limit velocity>); inf for ideal
    motors, a torque source with no speed line and the effort limit as its only bound."""
    registry.check("motor", registry.MOTORS, kind)
    return np.full(3, np.inf) if kind == "ideal" else np.asarray(layout.speed_limit, dtype=float)


class Actuation:
    """The static part of an actuator model: its kind and its delay line's length."""

    def __init__(self, layout: Layout, kind: str = "ideal", max_delay: int = 0):
        registry.check("motor", registry.MOTORS, kind)
        if max_delay < 0:
            raise ValueError(f"the action delay must be >= 0 steps, got {max_delay}")
        if kind == "dc" and not all(math.isfinite(w) for w in layout.speed_limit):
            raise ValueError("a dc motor needs each joint's <limit velocity> in the URDF (its no-load speed)")
        self.layout, self.kind, self.depth = layout, kind, max_delay + 1

    @property
    def passthrough(self) -> bool:
        """Adds nothing to the step (ideal motors, no delay): the core then skips it altogether."""
        return self.kind == "ideal" and self.depth == 1

    def motor(self, n: int, *, delay_steps=0, stall_torque=None, no_load_speed=None, torque_limit=None) -> Motor:
        """(N, ...) figures of N instances: the URDF's unless given (each broadcast to (N, 3), delay to (N,))."""
        lay = self.layout
        tau_s = np.broadcast_to(lay.effort_limit if stall_torque is None else stall_torque, (n, 3))
        limit = tau_s if torque_limit is None else np.broadcast_to(torque_limit, (n, 3))
        w0 = np.broadcast_to(nominal_no_load(lay, self.kind) if no_load_speed is None else no_load_speed, (n, 3))
        if self.kind == "ideal":  # no speed line, whatever figures were given
            w0 = np.full((n, 3), np.inf)
        delay = np.broadcast_to(np.asarray(delay_steps, dtype=np.int32), (n,))
        if delay.min() < 0 or delay.max() >= self.depth:
            raise ValueError(f"action delays must be 0..{self.depth - 1} steps, got {delay.min()}..{delay.max()}")
        f32 = lambda a: jnp.asarray(a, dtype=jnp.float32)
        return Motor(f32(tau_s), f32(w0), f32(limit), jnp.asarray(delay))

    def init(self, motor: Motor) -> Drive:
        """A batch's drive state at rest (batched figures in, batched state out)."""
        n = motor.delay.shape[0]
        return Drive(motor=motor, line=jnp.zeros((n, self.depth, 3), jnp.float32), energy=jnp.zeros(n, jnp.float32))

    def apply(self, drive: Drive, ctrl: jax.Array, qvel: jax.Array, dt: float) -> tuple[jax.Array, Drive]:
        """(applied ctrl (nu,), drive after one step of dt s) of one instance: commanded ctrl (nu,),
        joint speeds from qvel (nv,)."""
        lay = self.layout
        act, gear = jnp.asarray(lay.actuator_of_joint), jnp.asarray(lay.gear)
        torque, drive = self.delayed(drive, ctrl[act] * gear)
        torque, drive = self.motors(drive, torque, qvel, dt)
        return jnp.zeros_like(ctrl).at[act].set(torque / gear), drive

    def delayed(self, drive: Drive, command: jax.Array) -> tuple[jax.Array, Drive]:
        """(the command (3,), joint order, given `delay` steps ago; drive with `command` pushed into its line)."""
        line = jnp.concatenate([command[None], drive.line[:-1]])
        return line[drive.motor.delay], drive._replace(line=line)

    def motors(self, drive: Drive, torque: jax.Array, qvel: jax.Array, dt: float) -> tuple[jax.Array, Drive]:
        """(the joint torques (3,) the motors apply for `torque` asked now, within their envelope at the joint
        speeds from qvel (nv,); drive with the energy drawn over dt s)."""
        speed = qvel[jnp.asarray(self.layout.joint_dof)]
        low, high = envelope(drive.motor, speed)
        torque = jnp.clip(torque, low, high)
        if self.kind == "dc":
            power = jnp.maximum(electrical_power(drive.motor, torque, speed), 0.0)
        else:
            power = jnp.abs(torque * speed)
        return torque, drive._replace(energy=drive.energy + dt * power.sum())
