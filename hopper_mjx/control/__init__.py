"""Controllers of the batched core, and the registry every tool builds them through."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from hopper_mjx import registry
from hopper_mjx.control import balance, jump, pid, raibert
from hopper_mjx.control.base import Controller, PDScale, hold, zero_torque
from hopper_mjx.model.robot import Robot

NAMES = tuple(registry.CONTROLLERS)
# registry.GAIT_CONTROLLERS' builders: (robot, a registry.MOTORS name) -> Controller. The jump ends its full stroke's
# push where those motors' speed line runs out (`control.stroke.release`); Raibert's thrust is the spring's, whatever
# the motors.
GAITS = {"raibert": lambda robot, motor: raibert.raibert(robot),
         "jump": lambda robot, motor: jump.jump(robot, motor=motor)}


def gait(name: str, robot: Robot, motor: str = registry.DEFAULT_MOTOR) -> Controller:
    """The gait `name` (`GAITS`) for `robot` driven by `motor` (a registry.MOTORS name)."""
    return GAITS[name](robot, motor)


def make(name: str, robot: Robot, n: int, *, height: float = raibert.DEFAULT_HEIGHT,
         speed=(0.0, 0.0), gains=None, mj_model=None, pd: PDScale | None = None,
         legs: Sequence[Robot] | None = None, latency=None,
         motor: str = registry.DEFAULT_MOTOR) -> tuple[Controller, object]:
    """(controller, per-instance params or None) for n instances of `robot`.

    none: limp; hold: PD to the initial joint angles; pid: the seed's joint position
    controllers holding them, with `gains` (`pid.load_gains`; default the shipped
    monoped.yaml); raibert: hop at `height` m of apex rise over the standing height
    and `speed` (vx, vy) m/s; balance: stand on the foot, an LQR designed on `mj_model`
    (required) about its stance. pd: each instance's factors on the joint PD gains
    (`base.pd_scale`), for the controllers that have them (`registry.PD_CONTROLLERS`). legs: each
    instance's robot facts when its leg is drawn (`variation.draw.legs`): raibert models each instance's
    own leg; hold and pid hold each instance's own start (its own stance) anyway; balance keeps the
    URDF's design. latency: s, each instance's action delay (scalar or (n,)), which the gaits that predict
    (`registry.PREDICTING_CONTROLLERS`) act over; the others, and these with none, take their torques as prompt.
    motor: the motors the batch runs (`gait`).
    """
    registry.check("controller", registry.CONTROLLERS, name)
    if pd is not None and name not in registry.PD_CONTROLLERS:
        raise ValueError(f"{name} has no joint PD gains to scale; kp_scale and kd_scale take "
                         f"{', '.join(registry.PD_CONTROLLERS)} or a policy")
    if name == "none":
        return zero_torque(robot.layout), None
    if name == "hold":
        return hold(robot.layout), pd
    if name == "pid":
        return pid.pid(robot.layout, gains), pd
    if name == "balance":
        if mj_model is None:
            raise ValueError("balance is designed on the compiled model: pass mj_model=")
        return balance.balance(robot, mj_model), None
    if len(speed) != 2:  # raibert, jump
        raise ValueError(f"speed needs two values VX,VY in m/s, got {list(speed)}")
    leg = None if legs is None else raibert.legs(robot, legs)
    return gait(name, robot, motor), raibert.raibert_params(n, height=height, speed=speed, pd=pd, leg=leg,
                                                            latency=predicted_latency(name, latency))


def ramp_note(names, speed, height: float, gravities, duration: float) -> str | None:
    """A line saying where a gait's speed reference, which ramps from rest to the command by `speed_step` a hop
    (`raibert.speed_update`), needs longer than the run: its robots then move slower than commanded for all of it
    (1 m/s for 4 s reached 0.17 m/s). The time is a lower bound: the hops' flights alone, each the ballistic
    2 sqrt(2 h / g) of the commanded rise h; their stances add more. `names`: a controller's, or several run side
    by side, whose gaits ramp alike and share the line. None for other controllers, no speed, or a run long enough
    at every gravity."""
    gaits = [n for n in ([names] if isinstance(names, str) else names) if n in registry.GAIT_CONTROLLERS]
    if not gaits or height <= 0:
        return None
    step = raibert.RaibertConfig().speed_step
    hops = math.ceil(max(abs(float(v)) for v in speed) / step - 1e-9)
    flight = {g: hops * 2.0 * math.sqrt(2.0 * height / g) for g in sorted(gravities) if g > 0}
    short = ", ".join(f"{t:.1f} s at g = {g:g} m/s²" for g, t in flight.items() if t > duration)
    if not short:  # no speed (0 hops), or a run long enough everywhere
        return None
    one = len(gaits) == 1
    its = "its" if one else "their"
    return (f"note: {' and '.join(gaits)} ramp{'s' if one else ''} {its} speed from rest to --speed "
            f"{','.join(f'{float(v):g}' for v in speed)} m/s by {step:g} m/s a hop, {hops} hops: their flights alone "
            f"take {short}, more than --duration {duration:g} s; {its} robots move slower than commanded until then")


def predicted_latency(name: str, latency):
    """`latency` (s, scalar or (n,)) for the gait `name` to predict over, or None: it does not predict
    (`registry.PREDICTING_CONTROLLERS`), or there is no delay (no leaves: the gait's program without a prediction)."""
    if name not in registry.PREDICTING_CONTROLLERS or latency is None or not np.any(np.asarray(latency) > 0):
        return None
    return latency


__all__ = ["GAITS", "NAMES", "Controller", "gait", "make", "predicted_latency", "ramp_note"]
