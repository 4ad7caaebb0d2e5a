"""The names a user types, each defined once: controllers, engines, tasks and the policy prefix.

The factories (`control.make`, `engine.make`, `envs.make`) dispatch on these names, and every
`--controller`, `--engine` and `--task` choice, help text and error message is derived from
them. This module imports nothing, so that a command can refuse a bad name before JAX or
MuJoCo is loaded.
"""

from __future__ import annotations

POLICY_PREFIX = "policy:"  # `policy:PATH`: a policy trained by experiments/train.py, run as a controller

CONTROLLERS = {
    "none": "limp",
    "hold": "keep the initial joint angles",
    "pid": "the seed's joint position controllers, holding them",
    "raibert": "hop to --height and --speed",
    "balance": "stand still on the foot: an LQR about the stance (holds it at rest; kicks topple it, docs/control.md)",
}
# The controllers a gravity sweep runs beside `policy:PATH`: the tasks' references.
SWEEP_CONTROLLERS = ("raibert", "balance")
ENGINES = {
    "auto": "chain when the model qualifies, else mjx",
    "chain": "MuJoCo's step specialised to the monoped",
    "mjx": "MuJoCo MJX, the reference",
}
DEFAULT_ENGINE = "auto"
TASKS = {
    "stand": "stay upright at the standing height",
    "hop": "hop in place to a commanded apex",
    "hop_velocity": "hop to a commanded apex at a commanded (vx, vy)",
}


def listed(registry: dict[str, str]) -> str:
    """'a (what a is), b (what b is)': for help texts."""
    return ", ".join(f"{name} ({what})" for name, what in registry.items())


def check(kind: str, registry: dict[str, str], name: str, *, extra: str = "") -> None:
    """Raises ValueError for a name the registry does not hold; `extra` names further accepted forms."""
    if name not in registry:
        raise ValueError(f"unknown {kind} {name!r}; choose from: {', '.join([*registry, *filter(None, [extra])])}")


def is_policy(controller: str) -> bool:
    return controller.startswith(POLICY_PREFIX)


def policy_path(controller: str) -> str:
    """The folder of a `policy:PATH` controller."""
    return controller.removeprefix(POLICY_PREFIX)
