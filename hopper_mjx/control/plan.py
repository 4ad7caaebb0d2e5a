"""What a controller built on Raibert's gait (`raibert.gait`; `jump`) may change in it: the hooks of a `Plan`, and the
stance it may put in place of the virtual spring's (`OwnPush`)."""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol

import jax

from hopper_mjx.hardware.signals import Observation


class OwnPush(NamedTuple):
    """A plan's stance in place of the spring's (`control.stroke`), per instance."""

    where: jax.Array  # bool: the leg force and the unloading brake are the plan's
    force: jax.Array  # N, the leg force along the foot -> COM line
    stiffness: jax.Array  # factor on the attitude servo's stiffness on the body's tilt (1: Raibert's)
    damping: jax.Array  # factor on its damping of the whole robot's spin (1: Raibert's)
    braked: jax.Array  # (3,) 1 where unloading brakes the joint, 0 where it lets it turn
    turn: jax.Array  # (3,) N·m added to the joint torques from the thrust to lift-off: they steer the robot's spin
    spin: Any = 0.0  # (3,) rad/s, roll, pitch, yaw: the robot's spin the attitude servo damps towards (0: Raibert's)


class Plan(Protocol):
    """Static, one per controller, each hook pure and per instance:

    - `initial`: its own state (`RaibertState.plan`);
    - `aim`, on a terrain: (the floor the next hop is aimed above, its state) from Raibert's floor;
    - `bias`, on a terrain: the apex-target bias kept of the one Raibert's height loop adapted;
    - `shift`: (2,) m, world, added to Raibert's foot placement in the flight (its speed loop's offset);
    - `flight`: the flight's joint torques from Raibert's `torque`;
    - `release`: (the leg length that ends a thrust, whether the leg holds at the bottom of its compression);
    - `push`: (an `OwnPush` in place of the spring's, the thrust force, its state).
    """

    def initial(self, obs: Observation) -> Any: ...
    def aim(self, leg, body, ground, base_xy, speed, s, ev, phase, floor, standing, g) -> tuple[jax.Array, Any]: ...
    def bias(self, s, ev, height_bias) -> jax.Array: ...
    def shift(self, s, plan, g) -> jax.Array: ...
    def flight(self, leg, body, ground, base_xy, speed, s, plan, torque, g, scale, spin, inertia) -> jax.Array: ...
    def release(self, s, leg, body) -> tuple[jax.Array, jax.Array]: ...
    def push(self, leg, body, s, ev, phase, plan, height_bias, thrust_force, standing, g, inertia) -> tuple: ...
