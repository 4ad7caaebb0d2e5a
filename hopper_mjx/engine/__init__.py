"""Engines: what steps one instance's physics, behind one interface, so that they are interchangeable.

    engine = hopper_mjx.engine.make("mjx", mj_model)

Every engine has, per instance and pure (the core vmaps them):

- `name`, `model` (the pytree passed into the compiled function) and `freeze_fields`
  (data fields a diverged instance keeps from its last finite state);
- `make_data(qpos, qvel) -> data` at time 0;
- `forward(model, data, gravity) -> data`: uses `data.ctrl` (actuator order), sets `qacc`
  and the contacts;
- `integrate(model, data, gravity) -> data`: the step to t + dt;
- `foot_contact(model, data) -> (flag, force, pos)` of the last forward: () bool foot
  touching, (3,) N floor-on-foot force and (3,) m contact point, world frame.

`data` is a pytree with `qpos`, `qvel`, `qacc`, `ctrl`, `time` and `.replace(**fields)`.
"mjx" (MuJoCo MJX, any model) is the reference; "auto" picks the best engine for the
model and today that is "mjx".
"""

from __future__ import annotations

import importlib.util

import mujoco

from hopper_mjx.engine.mjx import MjxEngine


def names() -> tuple[str, ...]:
    """The engine names `make` accepts."""
    chain = importlib.util.find_spec("hopper_mjx.engine.chain") is not None
    return ("auto", "mjx") + (("chain",) if chain else ())


def make(name: str, mj_model: mujoco.MjModel):
    """The engine called `name` for a compiled monoped."""
    if name not in names():
        raise ValueError(f"unknown engine {name!r}; choose from: {', '.join(names())}")
    if name == "chain":
        from hopper_mjx.engine import chain

        return chain.make(mj_model)
    return MjxEngine(mj_model)


__all__ = ["MjxEngine", "make", "names"]
