"""Controllers of the batched core, and the registry every tool builds them through."""

from __future__ import annotations

from hopper_mjx import registry
from hopper_mjx.control import balance, pid, raibert
from hopper_mjx.control.base import Controller, hold, zero_torque
from hopper_mjx.model.robot import Robot

NAMES = tuple(registry.CONTROLLERS)


def make(name: str, robot: Robot, n: int, *, height: float = raibert.DEFAULT_HEIGHT,
         speed=(0.0, 0.0), gains=None, mj_model=None) -> tuple[Controller, object]:
    """(controller, per-instance params or None) for n instances of `robot`.

    none: limp; hold: PD to the initial joint angles; pid: the seed's joint position
    controllers holding them, with `gains` (`pid.load_gains`; default the shipped
    monoped.yaml); raibert: hop at `height` m of apex rise over the standing height
    and `speed` (vx, vy) m/s; balance: stand on the foot, an LQR designed on `mj_model`
    (required) about its stance.
    """
    registry.check("controller", registry.CONTROLLERS, name)
    if name == "none":
        return zero_torque(robot.layout), None
    if name == "hold":
        return hold(robot.layout), None
    if name == "pid":
        return pid.pid(robot.layout, gains), None
    if name == "balance":
        if mj_model is None:
            raise ValueError("balance is designed on the compiled model: pass mj_model=")
        return balance.balance(robot, mj_model), None
    if len(speed) != 2:  # raibert
        raise ValueError(f"speed needs two values VX,VY in m/s, got {list(speed)}")
    return raibert.raibert(robot), raibert.raibert_params(n, height=height, speed=speed)


__all__ = ["NAMES", "Controller", "make"]
