"""URDF -> MjSpec -> MjModel: the seed monoped (or any URDF with its joint names).

The URDF is first checked here, so that a bad file fails with a message that
names the problem; MuJoCo's own URDF parser then builds an `MjSpec`, to which
the simulation-only parts are added: a free-floating base, the ground (a plane, or a
terrain's height field), explicit foot/base-ground contact pairs (on a terrain the thigh's and
shank's too), an IMU site, native
MuJoCo sensors (for users of the exported MJCF) and one torque motor per transmission.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco

from hopper_mjx import terrain as terrains
from hopper_mjx.shell.checks import MAX_TIMESTEP

DEFAULT_URDF = Path(__file__).with_name("monoped.urdf")
JOINTS = ("haa_joint", "hfe_joint", "kfe_joint")
DEFAULT_TIMESTEP = 1e-3  # s; the Gazebo original ran its physics at 1 kHz
SOLVER_ITERATIONS = 4  # the constraint solver's Newton and line-search caps (see build_spec)

# Names of the elements the loader adds; downstream code finds them by name.
ROOT_JOINT = "root"
FLOOR_GEOM = "floor"
FOOT_GEOM = "foot"
IMU_SITE = "imu"
FOOT_SITE = "foot_site"
# Contact-only boxes around the thigh's and shank's cylinders (terrain only): massless, hidden in MuJoCo's
# default view and left out of the robot's fingerprint (they follow from the cylinders).
LEG_CONTACT_GROUP = 3
LEG_CONTACT_SUFFIX = "_contact"

FOOT_FRICTION = 1.0  # rubber on concrete is 0.6-1.0


class URDFError(ValueError):
    """The URDF cannot describe a monoped that this toolkit can simulate."""


MAX_TEXT_BYTES = 16 << 20  # a description file is far smaller; /dev/zero or a disk image is not one


def read_text(path: str | os.PathLike, what: str, error: type[ValueError] = ValueError,
              max_bytes: int = MAX_TEXT_BYTES) -> str:
    """A text file's contents; `error` with one line naming the file if it is missing, unreadable,
    larger than `max_bytes` or not UTF-8 text (`what`, e.g. "URDF file", says what it should have been)."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            data = f.read(max_bytes + 1)  # bounded: a device or a huge file is refused, not read whole
        if len(data) > max_bytes:
            raise error(f"{path} is over {max_bytes >> 20} MiB: not a {what}")
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise error(f"{path} is not a text (UTF-8) {what}") from None
    except OSError as err:
        raise error(f"cannot read {what} {path}: {err.strerror}") from None


@dataclass(frozen=True)
class Transmission:
    joint: str
    actuator: str
    reduction: float
    effort: float  # N·m at the joint, from <limit effort>
    velocity: float  # rad/s at the joint, from <limit velocity> (inf when the URDF gives none)


@dataclass(frozen=True)
class LegDescription:
    """What the loader needs to know from the URDF, checked before MuJoCo sees it."""

    base_link: str
    leg_links: tuple[str, str]  # the thigh and the shank (children of hfe_joint and kfe_joint)
    contact_links: tuple[str, ...]  # the shank and everything fixed to it
    foot_link: str
    foot_radius: float
    transmissions: tuple[Transmission, ...]


def _number(element: ET.Element | None, attr: str, where: str) -> float:
    if element is None or element.get(attr) is None:
        raise URDFError(f"{where}: missing '{attr}'")
    try:
        value = float(element.get(attr))
    except ValueError:
        raise URDFError(f"{where}: '{attr}' is not a number: {element.get(attr)!r}") from None
    if not math.isfinite(value):
        raise URDFError(f"{where}: '{attr}' is not finite")
    return value


def _positive(text: str | None, where: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise URDFError(f"{where} is not a number: {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise URDFError(f"{where} must be a finite number > 0, got {text.strip()}")
    return value


def _check_origins(robot: ET.Element) -> None:
    """Every <origin>'s xyz and rpy: three finite numbers (MuJoCo would log a NaN pose to a file and fail)."""
    for parent in robot.iter():
        for origin in parent.findall("origin"):
            for attr in ("xyz", "rpy"):
                text = origin.get(attr)
                if text is None:
                    continue
                where = f"<{parent.tag} name={parent.get('name')!r}> <origin {attr}>" if parent.get("name") else \
                    f"an <origin {attr}> in <{parent.tag}>"
                try:
                    values = [float(v) for v in text.split()]
                except ValueError:
                    raise URDFError(f"{where} is not three numbers: {text!r}") from None
                if len(values) != 3 or not all(math.isfinite(v) for v in values):
                    raise URDFError(f"{where} must be three finite numbers, got {text!r}")


def _check_limits(joints: dict[str, ET.Element]) -> None:
    """Each leg joint's <limit lower upper>: finite, lower below upper (MuJoCo would drop a reversed range
    and leave the joint unlimited)."""
    for name in JOINTS:
        limit = joints[name].find("limit")
        lower, upper = (_number(limit, k, f"joint '{name}' <limit>") for k in ("lower", "upper"))
        if not lower < upper:
            raise URDFError(f"joint '{name}' <limit>: lower {lower:g} must be below upper {upper:g}")


def _check_inertial(link: ET.Element) -> None:
    name = link.get("name")
    inertial = link.find("inertial")
    if inertial is None:
        raise URDFError(
            f"link '{name}' has no <inertial>: every link of a simulated monoped "
            "needs a mass and an inertia"
        )
    mass = _number(inertial.find("mass"), "value", f"link '{name}' <mass>")
    if mass <= 0:
        raise URDFError(f"link '{name}' has mass {mass}: masses must be positive")
    inertia = inertial.find("inertia")
    if inertia is None:
        raise URDFError(f"link '{name}' has no <inertia> in its <inertial>")
    diag = [_number(inertia, k, f"link '{name}' <inertia>") for k in ("ixx", "iyy", "izz")]
    if min(diag) <= 0:
        raise URDFError(f"link '{name}' has a non-positive principal inertia {diag}")


def _transmissions(robot: ET.Element, joints: dict[str, ET.Element]) -> list[Transmission]:
    """The URDF's EffortJointInterface transmissions, each with its joint's effort limit."""
    transmissions = []
    for trans in robot.findall("transmission"):
        joint = trans.find("joint")
        jname = None if joint is None else joint.get("name")
        if jname not in joints:
            raise URDFError(f"transmission '{trans.get('name')}' drives the unknown joint {jname!r}")
        interfaces = " ".join(h.text or "" for h in trans.iter("hardwareInterface"))
        if "EffortJointInterface" not in interfaces:
            raise URDFError(
                f"transmission '{trans.get('name')}' is not an EffortJointInterface; "
                "only torque-driven joints are supported"
            )
        actuator = trans.find("actuator")
        reduction = actuator.find("mechanicalReduction") if actuator is not None else None
        if reduction is not None:  # a number > 0: the motor's torque is divided by it (0 would divide by zero)
            reduction = _positive(reduction.text, f"transmission '{trans.get('name')}' <mechanicalReduction>")
        effort = _number(joints[jname].find("limit"), "effort", f"joint '{jname}' <limit>")
        if effort <= 0:
            raise URDFError(f"joint '{jname}' has effort limit {effort}: it must be positive")
        limit = joints[jname].find("limit")
        velocity = math.inf
        if limit is not None and limit.get("velocity") is not None:
            velocity = _positive(limit.get("velocity"), f"joint '{jname}' <limit velocity>")
        transmissions.append(
            Transmission(
                joint=jname,
                actuator=(actuator.get("name") if actuator is not None else None) or f"{jname}_motor",
                reduction=reduction or 1.0,
                effort=effort,
                velocity=velocity,
            )
        )
    return transmissions


def describe(urdf_text: str, source: str = "<string>") -> LegDescription:
    """Checks a monoped URDF and extracts the facts the loader relies on."""
    try:
        robot = ET.fromstring(urdf_text)
    except ET.ParseError as err:
        raise URDFError(f"{source} is not well-formed XML: {err}") from None
    if robot.tag != "robot":
        raise URDFError(f"{source}: the root element is <{robot.tag}>, not <robot>")

    links = {link.get("name"): link for link in robot.findall("link")}
    joints = {joint.get("name"): joint for joint in robot.findall("joint")}
    missing = [name for name in JOINTS if name not in joints]
    if missing:
        raise URDFError(
            f"{source} lacks the joint(s) {missing}; a monoped needs {list(JOINTS)} "
            f"(found {sorted(j for j in joints if j)})"
        )
    for link in links.values():
        _check_inertial(link)
    _check_origins(robot)

    def parent_child(name: str) -> tuple[str, str]:
        joint = joints[name]
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None:
            raise URDFError(f"joint '{name}' needs a <parent> and a <child>")
        for end in (parent.get("link"), child.get("link")):
            if end not in links:
                raise URDFError(f"joint '{name}' names the unknown link '{end}'")
        return parent.get("link"), child.get("link")

    chain = [parent_child(name) for name in JOINTS]
    for (_, child), (parent, _), name in zip(chain, chain[1:], JOINTS[1:]):
        if parent != child:
            raise URDFError(f"'{name}' must hang from the child of the joint before it ('{child}')")
    for name in JOINTS:
        if joints[name].get("type") != "revolute":
            raise URDFError(f"'{name}' must be revolute, not {joints[name].get('type')!r}")
    _check_limits(joints)

    base_link = chain[0][0]
    children = {link: [] for link in links}
    for joint in joints.values():
        p, c = parent_child(joint.get("name"))
        children[p].append((c, joint.get("type")))
    if any(c == base_link for kids in children.values() for c, _ in kids):
        raise URDFError(f"the link above haa_joint ('{base_link}') must be the root of the tree")

    contact_links = [chain[2][1]]
    for link in contact_links:  # grows while walking the fixed joints below the shank
        contact_links += [c for c, kind in children[link] if kind == "fixed"]
    feet = [
        (link, _number(c.find("geometry/sphere"), "radius", f"link '{link}' sphere"))
        for link in contact_links
        for c in links[link].findall("collision")
        if c.find("geometry/sphere") is not None
    ]
    if len(feet) != 1:
        raise URDFError(
            f"expected exactly one <sphere> collision (the foot) on {contact_links}, found {len(feet)}"
        )
    if not feet[0][1] > 0:
        raise URDFError(f"link '{feet[0][0]}' sphere: the foot's radius must be > 0, got {feet[0][1]:g}")

    transmissions = _transmissions(robot, joints)
    undriven = [name for name in JOINTS if name not in {t.joint for t in transmissions}]
    if undriven:
        raise URDFError(f"no EffortJointInterface <transmission> drives {undriven}")

    return LegDescription(
        base_link=base_link,
        leg_links=(chain[1][1], chain[2][1]),
        contact_links=tuple(contact_links),
        foot_link=feet[0][0],
        foot_radius=feet[0][1],
        transmissions=tuple(transmissions),
    )


def _add_floor(spec: mujoco.MjSpec, terrain: terrains.Terrain | None) -> None:
    """The ground: MuJoCo's plane, or `terrain`'s height field in its place (the same name, so the same pairs)."""
    floor = spec.worldbody.add_geom(
        name=FLOOR_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05], contype=0, conaffinity=0
    )
    if terrain is not None:
        terrains.to_spec(spec, floor, terrain)


def _add_leg_pairs(spec: mujoco.MjSpec, leg: LegDescription) -> None:
    """On a terrain a block's edge can meet the thigh or the shank: each link's collision cylinders get a
    bounding box paired with the floor. A box, not the cylinder or a capsule: the chain engine's exact
    box-prism routine (`engine/chain/hfield_box.py`) serves it, and MJX collides boxes with a height field.
    Frictionless (condim 1, as the base box): it only has to stop a link going through the ground, which
    happens after a stumble, and one row a contact, not four, keeps every step's solve cheap."""
    for name in leg.leg_links:
        body = spec.body(name)
        for k, cyl in enumerate([g for g in body.geoms if g.type == mujoco.mjtGeom.mjGEOM_CYLINDER]):
            radius, half = cyl.size[0], cyl.size[1]
            box = body.add_geom(name=f"{name}{LEG_CONTACT_SUFFIX}{k or ''}", type=mujoco.mjtGeom.mjGEOM_BOX,
                                size=[radius, radius, half], pos=cyl.pos, quat=cyl.quat, contype=0,
                                conaffinity=0, group=LEG_CONTACT_GROUP, mass=0, rgba=[0, 0, 0, 0])
            spec.add_pair(geomname1=FLOOR_GEOM, geomname2=box.name, condim=1)


def _add_sensors(spec: mujoco.MjSpec) -> None:
    """MuJoCo's native IMU, odometry and foot-touch sensors, for users of the exported MJCF."""
    obj = {"objtype": mujoco.mjtObj.mjOBJ_SITE, "objname": IMU_SITE}
    for name, kind in (
        ("imu_quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT),
        ("imu_gyro", mujoco.mjtSensor.mjSENS_GYRO),
        ("imu_accel", mujoco.mjtSensor.mjSENS_ACCELEROMETER),
        ("odom_pos", mujoco.mjtSensor.mjSENS_FRAMEPOS),
        ("odom_linvel", mujoco.mjtSensor.mjSENS_FRAMELINVEL),
        ("odom_angvel", mujoco.mjtSensor.mjSENS_FRAMEANGVEL),
    ):
        spec.add_sensor(name=name, type=kind, **obj)
    spec.add_sensor(name="foot_touch", type=mujoco.mjtSensor.mjSENS_TOUCH,
                    objtype=mujoco.mjtObj.mjOBJ_SITE, objname=FOOT_SITE)


def _check_options(timestep, friction, iterations, ls_iterations) -> None:
    if not (isinstance(timestep, (int, float)) and math.isfinite(timestep) and 0 < timestep <= MAX_TIMESTEP):
        raise ValueError(f"timestep must be in (0, {MAX_TIMESTEP:g}] s, got {timestep!r}")
    if len(friction) != 2 or not all(math.isfinite(mu) and mu >= 0 for mu in friction):
        raise ValueError(f"friction must be two finite coefficients >= 0, got {friction!r}")
    for name, cap in (("iterations", iterations), ("ls_iterations", ls_iterations)):
        if not (isinstance(cap, int) and not isinstance(cap, bool) and 1 <= cap <= 1000):
            raise ValueError(f"{name} must be a whole number in 1..1000, got {cap!r}")


def build_spec(urdf: str | os.PathLike | None = None, *, timestep: float = DEFAULT_TIMESTEP,
               friction: tuple[float, float] = (FOOT_FRICTION, FOOT_FRICTION),
               terrain: terrains.Terrain | None = None, iterations: int = SOLVER_ITERATIONS,
               ls_iterations: int = SOLVER_ITERATIONS) -> mujoco.MjSpec:
    """The monoped as an editable `MjSpec`, with everything the simulation adds. `friction`: the foot-floor
    contact's two sliding coefficients (Gazebo's mu, mu2), which a world file sets (`hopper_mjx.model.world`).
    `terrain`: a height grid the floor becomes (`terrain.to_spec`), keeping its name and contact pairs;
    None keeps the plane. `iterations`, `ls_iterations`: the constraint solver's caps (a policy's training
    physics asks for fewer, `envs.task_config.training_model`)."""
    path = Path(urdf) if urdf is not None else DEFAULT_URDF
    _check_options(timestep, friction, iterations, ls_iterations)
    leg = describe(read_text(path, "URDF file", URDFError), str(path))
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except ValueError as err:
        raise URDFError(f"MuJoCo could not parse {path}: {err}") from None

    spec.compiler.fusestatic = False  # keep the foot link; the contact sensor names it
    spec.compiler.discardvisual = False  # keep the non-colliding link geoms for pictures
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER  # semi-implicit, as Gazebo/ODE
    # (SOLVER_ITERATIONS) Batched MJX pays for every line-search iteration of every instance (a fixed-length
    # scan), so MuJoCo's 50 made the solver ~2/3 of a step in contact. Newton on <= 2
    # contacts converges in 1-2 iterations with 4 line-search steps: MJX's error against
    # MuJoCo C with the defaults stays at 1.3e-4 m over a landing (docs/performance.md).
    spec.option.iterations = iterations
    spec.option.ls_iterations = ls_iterations

    base = spec.body(leg.base_link)
    base.add_freejoint(name=ROOT_JOINT)
    base.add_site(name=IMU_SITE, pos=[0, 0, 0])

    world = spec.worldbody
    world.add_light(name="sun", pos=[0, 0, 4], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    _add_floor(spec, terrain)

    # Robot geoms collide only through explicit pairs: foot-floor while hopping,
    # base-floor after a fall. On the plane the leg links never reach the floor before the
    # base does; on a terrain a block's edge can meet them (`_add_leg_pairs`).
    # The base pair is frictionless (condim 1: 4 constraint rows, not 16): it only
    # acts after a fall, which the metrics have already called at a base height of
    # 0.4 m, and its rows were half the solver's work on every step (docs/performance.md).
    for geom in spec.geoms:
        if geom.name != FLOOR_GEOM:
            geom.contype = geom.conaffinity = 0
    foot_body = spec.body(leg.foot_link)
    foot = next(g for g in foot_body.geoms if g.type == mujoco.mjtGeom.mjGEOM_SPHERE)
    foot.name = FOOT_GEOM
    spec.add_pair(geomname1=FLOOR_GEOM, geomname2=FOOT_GEOM, condim=3,
                  friction=[friction[0], friction[1], 0.005, 1e-4, 1e-4])
    for i, geom in enumerate(base.geoms):
        geom.name = geom.name or f"{leg.base_link}_collision{i}"
        spec.add_pair(geomname1=FLOOR_GEOM, geomname2=geom.name, condim=1)
    if terrain is not None:
        _add_leg_pairs(spec, leg)
    foot_body.add_site(name=FOOT_SITE, pos=foot.pos, size=[leg.foot_radius * 1.1, 0, 0],
                       type=mujoco.mjtGeom.mjGEOM_SPHERE)

    _add_sensors(spec)
    for t in leg.transmissions:
        spec.add_actuator(
            name=t.actuator,
            target=t.joint,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            gear=[t.reduction, 0, 0, 0, 0, 0],
            ctrllimited=True,
            ctrlrange=[-t.effort / t.reduction, t.effort / t.reduction],
            userdata=[t.velocity],  # MuJoCo has no joint speed limit: the motor models read it here
        )
    return spec


def load(urdf: str | os.PathLike | None = None, *, timestep: float = DEFAULT_TIMESTEP,
         friction: tuple[float, float] = (FOOT_FRICTION, FOOT_FRICTION),
         terrain: terrains.Terrain | None = None, iterations: int = SOLVER_ITERATIONS,
         ls_iterations: int = SOLVER_ITERATIONS) -> mujoco.MjModel:
    """Compiles a monoped URDF (default: the shipped seed monoped) to an `MjModel`, on `terrain` (a
    `hopper_mjx.terrain.Terrain`; None: the flat plane), its solver capped at `iterations` and `ls_iterations`."""
    spec = build_spec(urdf, timestep=timestep, friction=friction, terrain=terrain, iterations=iterations,
                      ls_iterations=ls_iterations)
    try:
        return spec.compile()
    except ValueError as err:
        raise URDFError(f"MuJoCo could not compile {urdf or DEFAULT_URDF}: {err}") from None
