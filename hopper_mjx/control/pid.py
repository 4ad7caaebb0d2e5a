"""The seed's ros_control joint position controllers, batched.

Each joint runs `effort_controllers/JointPositionController` semantics:

    target   <- clipped to the joint's URDF range (ros_control's enforceJointLimits)
    e        =  target - q,            ė = 0 - q̇   (the target is a set point)
    i_term   <- clip(i_term + i·e·dt, -i_clamp, +i_clamp)     (control_toolbox::Pid)
    effort   =  p·e + i_term + d·ė,    saturated at the URDF effort limit

Gains come from a YAML file laid out like the seed's ``monoped.yaml`` (the
shipped default is ``hopper_mjx/control/monoped.yaml``) and may differ per
instance: they live in the controller state next to the targets.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from hopper_mjx.control.base import Controller, PDScale, clip_to_limits, joint_state, pd
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.loader import JOINTS, read_text
from hopper_mjx.shell.checks import load_yaml

DEFAULT_GAINS = Path(__file__).with_name("monoped.yaml")
SEED_GAINS_NAMES = ("monoped.yaml", "monoped.yml")
CONTROLLER_TYPE = "effort_controllers/JointPositionController"
GAINS_BYTES = 1 << 20  # a gains file is a page of YAML
GAIN_KEYS = ("p", "i", "d", "i_clamp")  # N·m/rad, N·m/(rad·s), N·m·s/rad, N·m


class PidGains(NamedTuple):
    """Gains of the three joints (haa, hfe, kfe), each a (3,) array (or (N, 3) batched)."""

    p: jax.Array
    i: jax.Array
    d: jax.Array
    i_clamp: jax.Array


def gains_file(path: str | Path) -> Path:
    """The gains file a path names: the file itself, or in a folder (the seed's package or its
    ``config/``) ``monoped.yaml`` or ``monoped.yml``; the seed's launch file spells it .yml."""
    path = Path(path)
    if not path.is_dir():
        return path
    candidates = [folder / name for folder in (path, path / "config") for name in SEED_GAINS_NAMES]
    found = [c for c in candidates if c.is_file()]
    if not found:
        raise ValueError(f"no {' or '.join(SEED_GAINS_NAMES)} in the folder {path} (nor in its config/)")
    return found[0]


def load_gains(path: str | Path | None = None) -> dict[str, dict[str, float]]:
    """joint name -> {p, i, d, i_clamp} from a seed-style monoped.yaml (default: the shipped one).

    `path` is a YAML file (any extension) or a folder holding the seed's file (`gains_file`).
    The controllers may sit under one namespace key (``monoped:`` in the seed)
    or at the top level. ``i_clamp`` defaults to 0 (no integral action), as in
    control_toolbox when it is not given.
    """
    path = gains_file(path) if path is not None else DEFAULT_GAINS
    try:
        doc = load_yaml(read_text(path, "PID gains file", max_bytes=GAINS_BYTES))
    except yaml.YAMLError as err:
        first_line = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise ValueError(f"{path} is not valid YAML: {first_line}") from None
    if isinstance(doc, dict) and len(doc) == 1 and not any(str(k).endswith("_controller") for k in doc):
        doc = next(iter(doc.values()))  # the seed's `monoped:` namespace
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: expected a mapping of <joint>_position_controller entries")
    gains, drivers = {}, {}
    for name, entry in doc.items():
        if not (isinstance(entry, dict) and entry.get("type") == CONTROLLER_TYPE):
            continue  # e.g. the joint_state_controller
        joint = entry.get("joint")
        if joint not in JOINTS:
            raise ValueError(f"{path}: '{name}' drives unknown joint {joint!r}; expected one of {list(JOINTS)}")
        if joint in gains:
            raise ValueError(f"{path}: '{name}' drives {joint}, which '{drivers[joint]}' drives already")
        drivers[joint] = name
        pid_entry = entry.get("pid")
        if not isinstance(pid_entry, dict):
            raise ValueError(f"{path}: '{name}' has no pid: {{p, i, d}} mapping")
        values = {}
        for key in GAIN_KEYS:
            raw = pid_entry.get(key, 0.0 if key in ("i", "d", "i_clamp") else None)
            try:
                value = float(raw)
            except (TypeError, ValueError):
                raise ValueError(f"{path}: '{name}' pid.{key} must be a number, got {raw!r}") from None
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{path}: '{name}' pid.{key} must be finite and >= 0, got {value}")
            values[key] = value
        gains[joint] = values
    missing = [j for j in JOINTS if j not in gains]
    if missing:
        raise ValueError(f"{path}: no {CONTROLLER_TYPE} for joint(s) {missing}")
    return gains


def gains_of(gains: dict[str, dict[str, float]] | None = None) -> PidGains:
    """`load_gains`-style dict (default: the shipped file) -> per-joint arrays."""
    gains = load_gains() if gains is None else gains
    return PidGains(*(jnp.asarray([gains[j][k] for j in JOINTS], dtype=jnp.float32) for k in GAIN_KEYS))


def effort(gains: PidGains, error: jax.Array, rate: jax.Array, i_term: jax.Array,
           dt: float) -> tuple[jax.Array, jax.Array]:
    """One control_toolbox::Pid update for a set point (ė = -q̇) -> (unsaturated effort, new integral term)."""
    i_term = jnp.clip(i_term + gains.i * error * dt, -gains.i_clamp, gains.i_clamp)
    return pd(gains.p, gains.d, error, rate, bias=i_term), i_term


class PidState(NamedTuple):
    target: jax.Array  # (3,) rad, joint set points (haa, hfe, kfe)
    gains: PidGains
    i_term: jax.Array  # (3,) N·m


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class PidParams:
    """Per-instance parameters of `pid`, each (3,) per instance (haa, hfe, kfe), (n, 3) batched."""

    target: jax.Array  # rad, joint set points
    p: jax.Array  # N·m/rad
    i: jax.Array  # N·m/(rad·s)
    d: jax.Array  # N·m·s/rad
    i_clamp: jax.Array  # N·m, bound on the integral term

    @property
    def gains(self) -> PidGains:
        return PidGains(self.p, self.i, self.d, self.i_clamp)


def pid_params(n: int, target, gains: dict[str, dict[str, float]] | None = None, **per_instance) -> PidParams:
    """Per-instance parameters for `pid`: targets (3,) or (n, 3) rad, and gains.

    `per_instance` may override any of p, i, d, i_clamp with a (3,) or (n, 3) array.
    """
    unknown = set(per_instance) - set(GAIN_KEYS)
    if unknown:
        raise ValueError(f"unknown PID gain(s) {sorted(unknown)}; expected {list(GAIN_KEYS)}")
    base = gains_of(gains)._asdict()
    out = {"target": target, **{k: per_instance.get(k, base[k]) for k in GAIN_KEYS}}
    batched = {}
    for key, value in out.items():
        value = np.asarray(value, dtype=np.float32)
        try:
            batched[key] = np.broadcast_to(value, (n, len(JOINTS))).copy()
        except ValueError:
            raise ValueError(f"PID {key} must have shape (3,) or ({n}, 3), got {value.shape}") from None
        if not np.all(np.isfinite(batched[key])):
            raise ValueError(f"PID {key} must be finite")
        if key != "target" and np.any(batched[key] < 0):
            raise ValueError(f"PID gain {key} must be >= 0")
    return PidParams(**batched)


def pid(layout: Layout, gains: dict[str, dict[str, float]] | None = None) -> Controller:
    """`pid`: the three joint position controllers.

    params: None (hold the joint angles each instance starts with, `gains` for
    all), a `PDScale` (the same, p and d times the instance's factors) or `pid_params(...)`
    (per-instance targets and gains).
    """
    lower, upper = (jnp.asarray(r) for r in zip(*layout.joint_range))
    shared = gains_of(gains)

    def init(obs, params: PidParams | PDScale | None):
        if params is None or isinstance(params, PDScale):
            gains = shared if params is None else shared._replace(p=shared.p * params.kp, d=shared.d * params.kd)
            return PidState(target=joint_state(layout, obs)[0], gains=gains, i_term=jnp.zeros(len(JOINTS)))
        return PidState(target=params.target, gains=params.gains, i_term=jnp.zeros(len(JOINTS)))

    def act(state, obs, gravity):
        q, qd = joint_state(layout, obs)
        target = jnp.clip(state.target, lower, upper)
        torque, i_term = effort(state.gains, target - q, qd, state.i_term, layout.timestep)
        return clip_to_limits(layout, torque), state._replace(i_term=i_term)

    return Controller(name="pid", init=init, act=act, key=f"pid|{shared!r}|{layout!r}")
