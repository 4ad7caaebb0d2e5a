"""Engines: what steps one instance's physics, behind one interface, so that they are interchangeable.

    engine = hopper_mjx.engine.make("mjx", mj_model)

Every engine has, per instance and pure (the core vmaps them):

- `name`, `model` (the pytree passed into the compiled function), `freeze_fields`
  (data fields a diverged instance keeps from its last finite state) and `varies` (the model
  fields it takes per instance at run time);
- `vary(model, values) -> model`: one instance's model, `values` {field: array} replacing
  the nominal fields (`variation.draw` draws them); `{}` returns `model` unchanged;
- `on_ground(model, heights) -> model`: one instance's model on its own ground, `heights` (nrow, ncol) m
  on the grid of the model's height field (`terrain.from_model` decodes a model's, `terrain.to_model_data`
  encodes them for MuJoCo's);
- `make_data(qpos, qvel) -> data` at time 0;
- `forward(model, data, gravity) -> data`: uses `data.ctrl` (actuator order), sets `qacc`
  and the contacts;
- `integrate(model, data, gravity) -> data`: the step to t + dt;
- `foot_contact(model, data) -> (flag, force, pos)` of the last forward: () bool foot
  touching, (3,) N floor-on-foot force and (3,) m contact point, world frame.

The core vmaps over instances with `axis_name=BATCH_AXIS`, so that an engine (or a controller) may skip a
stage no instance of the chunk needs (`batch_any`: a policy's network between its decisions, the chain's line
search once every instance's has ended), or run it for the few that do (`chain.stage.only_where`: the chain
engine's boxes against a heightfield).
`data` is a pytree with `qpos`, `qvel`, `qacc`, `ctrl`, `time` and `.replace(**fields)`.
"mjx" (MuJoCo MJX, any model) is the reference and the fallback; "chain" is MuJoCo's step
specialised to the monoped's topology (free base, serial chain of hinges, sphere foot and base
box on a plane or a heightfield; several times faster on CPU);
"auto" picks "chain" when the model qualifies and otherwise "mjx", with a one-line notice
on stderr saying why.
"""

from __future__ import annotations

import sys
from typing import Any, Protocol, runtime_checkable

import mujoco

from hopper_mjx import registry
from hopper_mjx.engine.chain.stage import BATCH_AXIS, batch_any
from hopper_mjx.engine.xla import CPU_COMPILER_OPTIONS, FUSION_EMITTERS, WIDE_VECTORS
from hopper_mjx.shell.programs import model_digest
from hopper_mjx.variation.spec import check_engine_varies


@runtime_checkable
class Engine(Protocol):
    """The contract above, checked against every engine by the tests (`isinstance(e, Engine)`)."""

    name: str
    model: Any
    freeze_fields: tuple[str, ...]
    varies: frozenset[str]
    compiler_options: dict  # XLA:CPU options for a jit of this engine's step (engine/xla.py)

    def vary(self, model, values: dict) -> Any: ...

    def on_ground(self, model, heights) -> Any: ...

    def make_data(self, qpos, qvel) -> Any: ...

    def forward(self, model, data, gravity) -> Any: ...

    def integrate(self, model, data, gravity) -> Any: ...

    def foot_contact(self, model, data) -> tuple: ...

    def program_key(self) -> tuple: ...  # what its traced step folds in besides the MuJoCo model's numbers


def check_name(name: str) -> None:
    """Raises ValueError for an unknown engine name (before any model is built)."""
    registry.check("engine", registry.ENGINES, name)


# The engines this process has built, by name, model and varied fields (`make`). An engine is immutable once
# built, and its step's trace (xla.trace_once) and the batched forms of that trace live on it: the same engine
# again (a training's evaluation, the next seed of --seeds, a scan's rollouts) skips re-tracing the step.
_BUILT: dict = {}
_KEEP = 8  # engines kept; the oldest goes first


def make(name: str, mj_model: mujoco.MjModel, varies: frozenset[str] = frozenset()):
    """The engine called `name` for a compiled monoped whose model `varies` these fields per instance;
    "chain" raises `NotChain` (a ValueError) for a model outside its topology and ValueError for a
    field it cannot vary, "auto" falls back to "mjx" for either. The same arguments again return the
    engine already built."""
    check_name(name)
    check_engine_varies(name, varies)
    varies, digest = frozenset(varies), model_digest(mj_model)
    # "auto" that resolves to the chain is the chain engine: one build for both names.
    keys = [(name, digest, varies)] + ([("chain", digest, varies)] if name == "auto" else [])
    found = next((k for k in keys if k in _BUILT), None)
    if found is None:
        if len(_BUILT) >= _KEEP:
            _BUILT.pop(next(iter(_BUILT)))
        engine, note = _build(name, mj_model, varies)
        found = (engine.name if not note else name, digest, varies)
        _BUILT[found] = engine, note
    built, note = _BUILT[found]
    if note:  # every time: each tool that asked for "auto" says what it got
        print(note, file=sys.stderr)
    return built


def _build(name: str, mj_model: mujoco.MjModel, varies: frozenset[str]):
    """(the engine, the "auto" fallback's notice or "")."""
    note = ""
    if name in ("auto", "chain"):
        from hopper_mjx.engine import chain

        try:
            check_engine_varies("chain", varies)
            return chain.make_for_tools(mj_model, varies=varies), ""
        except ValueError as err:  # NotChain, or a varied field
            if name == "chain":
                raise
            note = f"note: engine auto uses mjx ({err})"
    # Imported only here: MJX's import costs about 0.8 s, which a process on the chain engine never needs.
    from hopper_mjx.engine.mjx import MjxEngine

    return MjxEngine(mj_model, varies), note


__all__ = ["BATCH_AXIS", "batch_any", "CPU_COMPILER_OPTIONS", "FUSION_EMITTERS", "WIDE_VECTORS", "Engine",
           "check_name", "make"]
