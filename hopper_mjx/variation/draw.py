"""A variation spec drawn per instance into MuJoCo model fields, and the constants those fields imply.

    values = draw(spec, mj_model, n=64, seed=0)     # {"body_mass": (64, nbody), "pair_friction": (64, npair, 5)}
    controls = draw_controls(spec, mj_model, 64, 0) # {"kp_scale": (64, 3), "action_delay": (64,), ...}
    values = with_constants(mj_model, values)       # + body_invweight0, dof_invweight0, ... per instance
    m_i = instance_model(mj_model, values, i)       # instance i as a MuJoCo C model (mj_setConst called)
    qpos0 = stances(mj_model, values)               # (64, nq) each drawn leg's own stance (None: leg not drawn)
    own = legs(mj_model, values)                    # each drawn leg's robot facts, as its controller knows them

Each varied field is drawn whole, (N, *field shape): the nominal model's values where the spec
leaves them, so instance i is re-created by setting the fields into a copy of the model. MuJoCo
derives constants from masses and inertias once, at compile time (`mj_setConst`: the constraint
regularisation's body/dof invweight0, subtree masses, ...); they are recomputed here per instance
with MuJoCo C, so an engine given `with_constants` steps each instance as MuJoCo C would.
"""

from __future__ import annotations

import copy
import math

import mujoco
import numpy as np

from hopper_mjx import registry
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.loader import JOINTS
from hopper_mjx.model.robot import Robot, stance_qpos
from hopper_mjx.variation.spec import Spec

# Fields `mj_setConst` derives from masses, inertias, armature and gear that MJX's step reads (MJX reads
# body_sameframe, which changes with a moved centre of mass, nowhere).
CONSTANTS = ("body_subtreemass", "body_invweight0", "dof_invweight0", "dof_M0", "actuator_acc0")
# (A body's offset moves the others' lever arms; a foot's radius feeds none of them.)
FEEDS_CONSTANTS = {"body_mass", "body_inertia", "body_ipos", "dof_armature", "actuator_gear", "body_pos"}
# Columns of a row a parameter sets: None, the whole row; a list, those columns (one draw shared by them
# unless the parameter draws per axis).
_COLUMNS = {"body_inertia": None, "body_ipos": [0, 1, 2], "pair_friction": [0, 1], "actuator_gear": [0],
            "body_pos": [0, 1, 2], "geom_size": [0]}
_PER_AXIS = {"body_ipos"}  # one draw per column (x, y, z), not one per row
# Fields that move the leg's geometry: an instance then starts from its own stance (`stances`).
GEOMETRY = frozenset({"body_pos", "geom_size"})


def rows(mj_model: mujoco.MjModel, elements: str) -> list[int]:
    """Indices into a field's first axis for a `registry.Parameter.elements` name."""
    m = mj_model
    lay = Layout.of(m)
    joints = [m.joint(name) for name in JOINTS]
    links = {"base": int(m.jnt_bodyid[0]), "hip": int(joints[0].bodyid[0]), "thigh": int(joints[1].bodyid[0]),
             "shank": int(joints[2].bodyid[0]), "foot": int(m.geom_bodyid[lay.foot_geom])}
    if elements in links:
        return [links[elements]]
    if elements == "bodies":
        return [b for b in range(1, m.nbody) if m.body_mass[b] > 0 or b in links.values()]
    if elements == "joints":
        return list(lay.joint_dof)
    if elements == "actuators":
        return list(lay.actuator_of_joint)
    if elements == "foot_geom":
        return [lay.foot_geom]
    if elements == "foot_pair":
        return [int(p) for p in np.flatnonzero((m.pair_geom1 == lay.foot_geom) | (m.pair_geom2 == lay.foot_geom))]
    raise ValueError(f"unknown elements {elements!r}")


def draw(spec: Spec, mj_model: mujoco.MjModel, n: int, seed: int) -> dict[str, np.ndarray]:
    """{field: (n, *field shape)} float64 of every field the spec varies; raises ValueError naming a
    parameter whose drawn value lies outside its valid range (`registry.PARAMETERS`)."""
    values = {}
    for name, dist in spec.model.items:  # the controller's, motors' and sensors' parameters: `draw_controls`
        par = registry.PARAMETERS[name]
        nominal = np.asarray(getattr(mj_model, par.field), dtype=float)
        field = values.setdefault(par.field, np.broadcast_to(nominal, (n, *nominal.shape)).copy())
        index = np.ix_(rows(mj_model, par.elements), _COLUMNS.get(par.field) or range(nominal.shape[-1])) \
            if nominal.ndim == 2 else (rows(mj_model, par.elements),)
        at = nominal[index]
        # One draw per element (per row; per row and axis for the centre of mass), spread over its columns.
        shape = at.shape[:1] + (1,) if nominal.ndim == 2 and par.field not in _PER_AXIS else at.shape
        if par.length:
            _check_link(mj_model, name, par)
        ends = dist.ends(shape)
        if ends is not None:  # refused whatever the draws: the same spec must not pass at one --num and fail at another
            _check_range(name, par, _field_values(par, dist, at, ends), dist)
        drawn = _field_values(par, dist, at, dist.draw(spec.rng(seed, name), np.ones(shape), n))
        _check_range(name, par, drawn)
        if par.length:  # the row's length: drawn (or scaled from the nominal length), the direction kept
            field[(slice(None), *index)] = at / np.linalg.norm(at, axis=-1, keepdims=True) * drawn
        else:
            field[(slice(None), *index)] = at + drawn if par.offset else drawn
    return values


def _field_values(par: registry.Parameter, dist, at: np.ndarray, raw: np.ndarray) -> np.ndarray:
    """The values `raw` draws of `dist` give the elements `at` (nominal values): a factor times the nominal value
    (or a length row's length), else the draw itself, one per element."""
    if par.length:
        return np.linalg.norm(at, axis=-1, keepdims=True) * raw if dist.kind == "scale" else raw
    return at * raw if dist.kind == "scale" else np.broadcast_to(raw, (raw.shape[0], *at.shape))


def _control_values(dist, nominal: np.ndarray, raw: np.ndarray) -> np.ndarray:
    """The values `raw` draws of `dist` give a control parameter: a factor times its undrawn value, else the draw."""
    return nominal * raw if dist.kind == "scale" else raw


def _check_link(m: mujoco.MjModel, name: str, par: registry.Parameter) -> None:
    """A length parameter's body must be its own link, below the joint before it, at a distance from it."""
    kfe_body = int(m.joint(JOINTS[2]).bodyid[0])
    body = rows(m, par.elements)[0]
    if par.elements == "foot" and body == kfe_body:
        raise ValueError(f"{name}: the foot sphere sits on the shank link itself; {name} needs a foot link")
    if not np.any(m.body_pos[body]):
        raise ValueError(f"{name}: the {par.elements} link sits at its parent's origin; no length to draw")


def settable(mj_model: mujoco.MjModel, field: str) -> np.ndarray:
    """Bool mask, the shape of `field`: the entries some `registry.PARAMETERS` entry can set (a length keeps
    a zero component zero). The chain engine takes these as run-time values and folds the rest."""
    nominal = np.asarray(getattr(mj_model, field))
    mask = np.zeros(nominal.shape, bool)
    for par in registry.PARAMETERS.values():
        if par.field != field:
            continue
        at = rows(mj_model, par.elements)
        if nominal.ndim == 1:
            mask[at] = True
            continue
        cols = _COLUMNS.get(field) or range(nominal.shape[-1])
        mask[np.ix_(at, cols)] = nominal[np.ix_(at, cols)] != 0 if par.length else True
    return mask


def columns(spec: Spec, mj_model: mujoco.MjModel, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """{column name: (N,)} of each drawn parameter, one column per element it draws: `base_mass`,
    `body_mass_upperleg`, `dof_damping_kfe`, `base_com_z` (for a table such as a sweep's results.csv)."""
    out = {}
    for name, _ in spec.model.items:
        par = registry.PARAMETERS[name]
        field = values[par.field]
        at = rows(mj_model, par.elements)
        if par.field in _PER_AXIS:
            for r in at:
                out.update({f"{name}_{axis}": field[:, r, k] for k, axis in enumerate("xyz")})
            continue
        labels = _labels(mj_model, par.elements, at)
        for r, label in zip(at, labels):
            value = field[:, r] if field.ndim == 2 else field[:, r, 0]
            value = np.linalg.norm(field[:, r], axis=-1) if par.length else value
            out[name if len(at) == 1 else f"{name}_{label}"] = value
    return out


def nominal_control(name: str, layout: Layout) -> np.ndarray:
    """A control parameter's value when it is not drawn: (3,) per joint, (3,) per axis, or ()."""
    par = registry.CONTROL_PARAMETERS[name]
    value = {"one": 1.0, "zero": 0.0, "effort": np.asarray(layout.effort_limit),
             "speed": np.asarray(layout.speed_limit)}[par.nominal]
    return np.broadcast_to(np.asarray(value, dtype=float), (3,) if par.joints or par.axes else ())


def draw_controls(spec: Spec, mj_model: mujoco.MjModel, n: int, seed: int) -> dict[str, np.ndarray]:
    """{name: (n,) or (n, 3)} float64 of each controller, motor and sensor parameter the spec draws
    (`registry.CONTROL_PARAMETERS`), from the same seed and per-parameter streams as the model fields;
    delays (ms) rounded to whole physics steps. Raises ValueError for a value outside its range."""
    lay = Layout.of(mj_model)
    out = {}
    for name, dist in spec.controls.items():
        par = registry.CONTROL_PARAMETERS[name]
        nominal = nominal_control(name, lay)
        ends = dist.ends(nominal.shape)
        if ends is not None:
            _check_range(name, par, _control_values(dist, nominal, ends), dist)
        drawn = _control_values(dist, nominal, dist.draw(spec.rng(seed, name), np.ones(nominal.shape), n))
        _check_range(name, par, drawn)
        if par.unit == "ms":  # at the physics' resolution
            step = lay.timestep * 1e3
            drawn = np.round(drawn / step) * step
        out[name] = drawn
    return out


def control_columns(controls: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """{column: (N,)} of `draw_controls`' values: `action_delay`, `kp_scale_hfe`, `gyro_bias_x`, ..."""
    out = {}
    for name, values in controls.items():
        if values.ndim == 1:
            out[name] = values
            continue
        labels = "xyz" if registry.CONTROL_PARAMETERS[name].axes else [j.removesuffix("_joint") for j in JOINTS]
        out.update({f"{name}_{label}": values[:, k] for k, label in enumerate(labels)})
    return out


def _labels(m: mujoco.MjModel, elements: str, at: list[int]) -> list[str]:
    if elements in ("joints", "actuators"):
        return [j.removesuffix("_joint") for j in JOINTS]
    if elements == "bodies":
        return [m.body(b).name for b in at]
    return [elements] * len(at)


FLOAT32_MAX = float(np.finfo(np.float32).max)


def _check_range(name: str, par: registry.Parameter | registry.ControlParameter, drawn: np.ndarray,
                 dist=None) -> None:
    """Every value of `drawn` within the parameter's range; with `dist`, `drawn` are its least and greatest draws,
    and the refusal names the distribution."""
    high = min(par.high, FLOAT32_MAX)  # the core computes in float32: a larger value would be inf there
    low_bad = drawn <= par.low if par.open_low else drawn < par.low
    bad = low_bad | (drawn > high) | ~np.isfinite(drawn) | (drawn < -FLOAT32_MAX)
    if bad.any():
        i = int(np.argwhere(bad)[0][0])
        value = float(drawn[bad][0])
        lower = f"{'>' if par.open_low else '>='} {par.low:g}"
        upper = "" if par.high == float("inf") else f" and <= {par.high:g}"
        if math.isfinite(value) and abs(value) > FLOAT32_MAX:
            upper += f" (and within ±{FLOAT32_MAX:.3g}: the core computes in float32)"
        kind = "an offset" if par.offset else "a value"
        unit = "" if par.unit == "1" else f" {par.unit}"  # a factor or a friction coefficient has none
        if dist is None:
            said = f"{name} drew {kind} of {value:g}{unit} for instance {i}"
        else:
            said = f"{name}={dist} {'sets' if dist.kind == 'fixed' else 'can draw'} {kind} of {value:g}{unit}"
        raise ValueError(f"{said}; it must be {lower}{upper}")


def instance_model(mj_model: mujoco.MjModel, values: dict[str, np.ndarray], i: int) -> mujoco.MjModel:
    """Instance i as a MuJoCo C model: a copy with its drawn fields set and the derived constants recomputed."""
    m = copy.deepcopy(mj_model)
    for field, v in values.items():
        if field not in CONSTANTS:
            getattr(m, field)[:] = v[i]
    mujoco.mj_setConst(m, mujoco.MjData(m))
    return m


def with_constants(mj_model: mujoco.MjModel, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """`values` and, when a varied field feeds them, the derived `CONSTANTS` of each instance (N, ...),
    computed by MuJoCo C (friction and damping leave them as they are)."""
    if not FEEDS_CONSTANTS & set(values):
        return dict(values)
    m, n = copy.deepcopy(mj_model), len(next(iter(values.values())))
    d = mujoco.MjData(m)
    out = {c: np.empty((n, *np.shape(getattr(m, c)))) for c in CONSTANTS}
    for i in range(n):  # one copy reused: every varied field is set whole each time
        for field, v in values.items():
            getattr(m, field)[:] = v[i]
        mujoco.mj_setConst(m, d)
        for c in CONSTANTS:
            out[c][i] = getattr(m, c)
    return {**values, **out}


def stances(mj_model: mujoco.MjModel, values: dict[str, np.ndarray]) -> np.ndarray | None:
    """(N, nq) each instance's own stance (`robot.stance_qpos` on its model: the knee that puts its centre
    of mass above its foot, the foot `CLEARANCE` above the floor) when `values` move the leg's geometry,
    else None (every instance starts from the URDF's stance). Raises ValueError naming the first instance
    whose leg cannot reach the floor: no such knee angle, or a robot geom lower than the foot in its stance."""
    if not GEOMETRY & set(values):
        return None
    m, n = copy.deepcopy(mj_model), len(next(iter(values.values())))
    lay, d = Layout.of(m), mujoco.MjData(m)
    others = [int(g) for g in m.pair_geom2 if g != lay.foot_geom]  # the robot's other geoms that touch the floor
    out = np.empty((n, m.nq))
    for i in range(n):
        for field, v in values.items():
            if field not in CONSTANTS:
                getattr(m, field)[:] = v[i]
        try:
            out[i] = stance_qpos(m)
            d.qpos[:] = out[i]
            mujoco.mj_kinematics(m, d)
            foot = d.geom_xpos[lay.foot_geom, 2] - m.geom_size[lay.foot_geom, 0]
            low, g = min(((_lowest(m, d, g), g) for g in others), default=(np.inf, -1))
            if low <= foot:
                raise ValueError(f"in its stance, geom {m.geom(g).name!r} reaches {foot - low:.3f} m below the foot")
        except ValueError as err:
            thigh, shank = (np.linalg.norm(m.body_pos[rows(m, part)[0]]) for part in ("shank", "foot"))
            raise ValueError(f"the leg of instance {i} (thigh {thigh:.3g} m, shank {shank:.3g} m, foot radius "
                             f"{m.geom_size[lay.foot_geom, 0]:.3g} m) cannot reach the floor: {err}") from None
    return out


def legs(mj_model: mujoco.MjModel, values: dict[str, np.ndarray]) -> list[Robot] | None:
    """Each instance's robot facts as its controller knows them when `values` move the leg's geometry, else
    None: `Robot.of` the URDF's model given the instance's lengths and foot radius (its leg geometry, stance and
    standing height), not its drawn masses, which no controller sees. Instances with the same leg share one."""
    drawn = sorted(GEOMETRY & set(values))
    if not drawn:
        return None
    m, n = copy.deepcopy(mj_model), len(values[drawn[0]])
    known: dict[bytes, Robot] = {}
    out = []
    for i in range(n):
        key = b"".join(np.ascontiguousarray(values[f][i]).tobytes() for f in drawn)
        if key not in known:  # a swept value repeats one leg over every replicate and gravity
            for f in drawn:
                getattr(m, f)[:] = values[f][i]
            known[key] = Robot.of(m)
        out.append(known[key])
    return out


def _lowest(m: mujoco.MjModel, d: mujoco.MjData, g: int) -> float:
    """Lowest z (m) of geom g after kinematics: a sphere's or a box's (the robot's floor geoms)."""
    if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE:
        return float(d.geom_xpos[g, 2] - m.geom_size[g, 0])
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * m.geom_size[g]
    return float((d.geom_xpos[g] + corners @ d.geom_xmat[g].reshape(3, 3).T)[:, 2].min())
