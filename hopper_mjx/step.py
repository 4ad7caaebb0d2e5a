"""The one physics step after a controller's output, shared by the core (`sim`) and the training
environments (`envs`), so that a policy is trained on the physics it is judged on.

    ctrl, torque, cstate, drive = actuate(plant, servo, command, cstate, drive, now, qvel)
    data, step, signals, diverged = advance(plant, model, data, gravity, ctrl, key, step)

`actuate` takes the command through the delay line and the motors (a position controller's targets
tracked by its joint drivers on the joints as they are `now`); `advance` steps the engine (forward,
then integrate), freezes a diverged instance, counts the step and applies the push due after it.
What differs between training and the core (the timestep, the solver's iteration cap, the policy's
rate) is the configuration: the compiled model the engine was made from and the `Plant`, recorded with
a policy; the functions are the same.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp

from hopper_mjx.control.base import Servo, to_ctrl
from hopper_mjx.hardware.actuators import Actuation
from hopper_mjx.hardware.pushes import Pushes, push

DIVERGED_SPEED = 1e6  # rad/s or m/s: beyond this a state is taken as diverged (frozen, reported)


class Plant(NamedTuple):
    """What stands between a controller's output and the next state, static for a batch."""

    engine: Any  # an `engine.Engine`, made from the model whose timestep and solver settings the step runs
    actuation: Actuation  # the motors and the action delay
    pushes: Pushes | None = None  # random shoves, or none
    counts: bool = False  # physics steps are counted: the pushes' schedule and the sensor noise read them


def actuate(plant: Plant, servo: Servo | None, command, cstate, drive, now, qvel):
    """(ctrl (nu,), joint torques (3,) N·m or None, controller state, drive): a controller's command through
    the delay line and the motors. A torque controller's command (`servo` None) is its ctrl; a position
    controller's is joint targets, delayed on their way to its drivers (`servo.track`), whose PD law reads
    the joints as they are `now` (an `Observation`, or data with `qpos` and `qvel`)."""
    actuation, dt = plant.actuation, plant.actuation.layout.timestep
    if servo is None:
        if actuation.passthrough:  # static: ideal, prompt motors add nothing
            return command, None, cstate, drive
        ctrl, drive = actuation.apply(drive, command, qvel, dt)
        return ctrl, None, cstate, drive
    if actuation.depth > 1:
        command, drive = actuation.delayed(drive, command)
    torque, cstate = servo.track(cstate, command, now)
    if not actuation.passthrough:
        torque, drive = actuation.motors(drive, torque, qvel, dt)
    return to_ctrl(actuation.layout, torque), torque, cstate, drive


def advance(plant: Plant, model, data, gravity, ctrl, key, step, measure: Callable | None = None,
            diverged: jax.Array | None = None):
    """(data, step, what `measure` returned, diverged): one physics step of one instance from `data` with
    `ctrl` applied. `measure(data)` reads the state between forward and integrate (where MuJoCo's sensors
    read it); with `diverged` given, an instance that is or becomes non-finite or faster than
    `DIVERGED_SPEED` keeps its last finite state (`engine.freeze_fields`). Then the step is counted and the
    push due after it applied, so that whatever reads the state next (sensors, a controller) sees it."""
    engine = plant.engine
    new = engine.forward(model, data.replace(ctrl=ctrl), gravity)
    measured = None if measure is None else measure(new)
    new = engine.integrate(model, new, gravity)
    if diverged is not None:
        finite = (jnp.isfinite(new.qpos).all() & jnp.isfinite(new.qvel).all()
                  & (jnp.abs(new.qvel) < DIVERGED_SPEED).all())
        diverged = diverged | ~finite
        new = new.replace(**{f: jnp.where(diverged, getattr(data, f), getattr(new, f)) for f in engine.freeze_fields})
    if plant.counts:
        step = step + 1
    if plant.pushes is not None:  # `step` steps done: the push due now
        new = new.replace(qvel=push(plant.pushes, key, step, new.qvel))
    return new, step, measured, diverged
