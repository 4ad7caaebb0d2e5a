"""The names a user types, each defined once: commands, controllers, engines, tasks, terrains, motors, varied
parameters, the policy prefix.

The factories (`control.make`, `engine.make`, `envs.make`, `variation.draw.draw`) dispatch on
these names, and every `--controller`, `--engine`, `--task` and `--randomize` choice, help text
and error message is derived from them. This module imports only the standard library's `typing`,
so that a command can refuse a bad name before JAX or MuJoCo is loaded.
"""

from __future__ import annotations

from typing import NamedTuple

# The commands, as a user runs them (`python -m NAME`, or `python NAME` for a script), in the order a newcomer meets
# them, each with what it is for; `python -m hopper_mjx` lists them, and tests/test_help.py holds this list to the
# modules and scripts that run as commands.
COMMANDS = {
    "hopper_mjx.sweep": "sweeps over gravity (the main job), a gain, a parameter, a terrain, or controllers",
    "hopper_mjx.simulate": "a batch of monopeds; their IMU, odometry and contact signals to .npz, or live",
    "hopper_mjx.view": "MuJoCo's interactive viewer on a live batch",
    "hopper_mjx.render": "pictures and videos, headless",
    "hopper_mjx.model": "the simulated model as MJCF or URDF; a terrain's map",
    "hopper_mjx.ros.record": "a batch's sensor streams as a ROS 1 bag or a ROS 2 MCAP",
    "hopper_mjx.ros.plots": "plots of a recording's IMU, odometry and contact signals",
    "hopper_mjx.ros.echo": "a recorded topic's messages, as rostopic echo prints them",
    "hopper_mjx.perf.bench": "the batched core against native MuJoCo, side by side",
    "hopper_mjx.perf.profile": "where the batched step spends its time",
    "experiments/train.py": "Brax PPO or SAC on a monoped task",
    "experiments/results.py": "the learning results table, from training runs",
    "experiments/export_onnx.py": "a trained policy as ONNX, checked against the JAX policy",
    "experiments/robustness.py": "the robustness table: Raibert and policies under pushes",
    "experiments/leg_energy.py": "energy per hop against the leg's lengths",
    "experiments/apex_reward.py": "what the hop task's apex term pays a hopper",
}

POLICY_PREFIX = "policy:"  # `policy:PATH`: a policy trained by experiments/train.py, run as a controller

CONTROLLERS = {
    "none": "limp",
    "hold": "keep the initial joint angles",
    "pid": "the seed's joint position controllers, holding them",
    "raibert": "hop to --height and --speed",
    "jump": "Raibert's gait, each hop sized to the ground ahead: leaps over blocks and across gaps",
    "balance": "stand still on the foot: an LQR about the stance (holds it at rest; kicks topple it, docs/control.md)",
}
# The controllers with joint PD gains that `--randomize kp_scale=...,kd_scale=...` scales (and `policy:PATH`).
PD_CONTROLLERS = ("hold", "pid", "raibert", "jump")
# The model-based controllers a gravity sweep runs beside `policy:PATH` (every task's reference among them).
SWEEP_CONTROLLERS = ("raibert", "jump", "balance")
# The controllers of Raibert's gait: they take its commands, gains and per-instance legs (`raibert_params`).
GAIT_CONTROLLERS = ("raibert", "jump")
# The gaits that know their action delay: they act on the state predicted over it (`control.latency`).
PREDICTING_CONTROLLERS = ("jump",)
# A terrain sweep's (obstacle, gaps) gaits, its default first: what jumps as the ground ahead needs. A trained
# policy (policy:PATH) runs there too.
TERRAIN_SWEEP_CONTROLLERS = ("jump", "raibert")
ENGINES = {
    "auto": "chain when the model qualifies, else mjx",
    "chain": "MuJoCo's step specialised to the monoped",
    "mjx": "MuJoCo MJX, the reference",
}
DEFAULT_ENGINE = "auto"
MOTORS = {
    "ideal": "a torque source up to the URDF's effort limit (the seed's EffortJointInterface)",
    "dc": "a DC motor: its torque-speed line from the URDF's effort (stall) and velocity (no-load speed)",
}
DEFAULT_MOTOR = "ideal"
TERRAINS = {  # --terrain NAME:KEY=VALUE,...; the keys are in hopper_mjx/terrain/spec.py and docs/terrain.md
    "flat": "MuJoCo's infinite plane at z = 0",
    "rough": "smooth random ground of a peak amplitude and a wavelength",
    "steps": "up a step onto a platform and down again",
    "stairs": "n steps up, a landing, n steps down",
    "gaps": "trenches across the ground at a spacing",
    "obstacle": "a block of a height across the ground at a distance ahead",
    "crater": "a bowl with a raised rim",
    "course": "the training course: tiles of rough ground, steps, gaps and blocks, one row per level of difficulty",
    "heightmap": "a greyscale PNG, black low, white high",
}
TASKS = {
    "stand": "stay up, upright and in place; small hops allowed",
    "hop": "hop in place to a commanded apex",
    "hop_velocity": "hop to a commanded apex at a commanded (vx, vy)",
    "hop_terrain": "hop_velocity over the training course's levels, reading a height scan around the base",
}


class Reference(NamedTuple):
    """A task's reference controller: what a trained policy is judged beside, on the same sweep."""

    controller: str  # a CONTROLLERS name
    height: float | None = None  # m of commanded apex rise; None: the task's own (evaluation) command


# Standing still on the ball foot is ill-posed under kicks (the LQR `balance` keeps none of 64 up);
# hopping in place at 5 cm keeps all (docs/control.md, "Standing balance"), so that is stand's reference.
TASK_REFERENCES = {
    "stand": Reference("raibert", 0.05),
    "hop": Reference("raibert"),
    "hop_velocity": Reference("raibert"),
    "hop_terrain": Reference("raibert"),
}


class Parameter(NamedTuple):
    """A robot parameter drawn per instance (`--randomize NAME=...`): the MuJoCo model field it sets,
    on which elements (variation.draw resolves them), its unit and the range a drawn value must lie in."""

    field: str
    elements: str  # bodies (every robot link), base, hip, thigh, shank, foot, joints, actuators, foot_pair, foot_geom
    unit: str
    what: str
    low: float = 0.0
    high: float = float("inf")
    open_low: bool = False  # low itself excluded (a mass of 0 is no body)
    offset: bool = False  # a drawn value is added to the nominal one, not put in its place
    length: bool = False  # a drawn value is the length of the field's row (an offset vector), its direction kept


_MASS = "mass of the {} link"
PARAMETERS = {
    "body_mass": Parameter("body_mass", "bodies", "kg", "every link's mass, drawn per link", open_low=True),
    "base_mass": Parameter("body_mass", "base", "kg", _MASS.format("base"), open_low=True),
    "hip_mass": Parameter("body_mass", "hip", "kg", _MASS.format("hip"), open_low=True),
    "thigh_mass": Parameter("body_mass", "thigh", "kg", _MASS.format("thigh (upper leg)"), open_low=True),
    "shank_mass": Parameter("body_mass", "shank", "kg", _MASS.format("shank (lower leg)"), open_low=True),
    "foot_mass": Parameter("body_mass", "foot", "kg", _MASS.format("foot"), open_low=True),
    "body_inertia": Parameter("body_inertia", "bodies", "kg·m²",
                              "every link's principal inertia, one draw per link for its three axes", open_low=True),
    "base_com": Parameter("body_ipos", "base", "m", "offset of the base's centre of mass, per axis (x, y, z), "
                          "added to the URDF's", low=-0.1, high=0.1, offset=True),
    "foot_friction": Parameter("pair_friction", "foot_pair", "1",
                               "sliding friction of the foot-floor contact (both directions)", high=10.0),
    "dof_damping": Parameter("dof_damping", "joints", "N·m·s/rad", "viscous damping of haa, hfe, kfe"),
    "dof_armature": Parameter("dof_armature", "joints", "kg·m²", "rotor inertia reflected at haa, hfe, kfe"),
    "dof_frictionloss": Parameter("dof_frictionloss", "joints", "N·m", "dry friction of haa, hfe, kfe"),
    "actuator_gear": Parameter("actuator_gear", "actuators", "N·m per unit of control",
                               "motor strength: the controllers command the URDF's gear, so this scales the "
                               "applied torque and its limit", open_low=True),
}
# Morphology: the leg's lengths and the foot's size, each the model field it sets (docs/variation.md).
PARAMETERS |= {
    "thigh_length": Parameter("body_pos", "shank", "m", "thigh length, hfe to kfe: the shank link's offset on the "
                              "thigh, its direction kept", open_low=True, high=1.0, length=True),
    "shank_length": Parameter("body_pos", "foot", "m", "shank length, kfe to the foot: the foot link's offset on "
                              "the shank, its direction kept", open_low=True, high=1.0, length=True),
    "foot_radius": Parameter("geom_size", "foot_geom", "m", "radius of the foot sphere", open_low=True, high=0.1),
}
# `--randomize NAME`: a named set of parameters. `playground`: MuJoCo Playground's locomotion randomisation as
# docs/variation.md's robustness table runs it (foot friction, link masses, the base's centre of mass, motor
# strength, action delay).
RANDOMIZE_PRESETS = {
    "playground": "foot_friction=0.4..1.0,body_mass=scale(0.9,1.1),base_com=-0.02..0.02,"
                  "actuator_gear=scale(0.8,1.2),action_delay=0..10",
}
# The model fields the chain engine takes as run-time values (every other varied field needs mjx): today every
# parameter's.
CHAIN_VARIES: frozenset[str] = frozenset({"dof_damping", "dof_frictionloss", "pair_friction", "body_mass",
                                          "body_inertia", "body_ipos", "dof_armature", "actuator_gear", "body_pos",
                                          "geom_size"})


class ControlParameter(NamedTuple):
    """A parameter of the robot's controller, motors or sensors drawn per instance (`--randomize NAME=...`),
    not a model field: recorded under its own name (npz key, results.csv column). `nominal` is what
    `scale(a,b)` multiplies and what an instance gets when the parameter is not drawn: "one" (a factor),
    "zero", "effort" / "speed" (the URDF's per-joint effort and velocity limits); `joints`: one draw per
    joint (haa, hfe, kfe), else one per instance; `axes`: one draw per axis (x, y, z)."""

    unit: str
    what: str
    nominal: str = "zero"
    low: float = 0.0
    high: float = float("inf")
    open_low: bool = False
    offset: bool = False  # a drawn value is a bias from zero: scale(a,b) does not apply
    joints: bool = False
    axes: bool = False
    needs: str = ""  # "dc": only with --motor dc; "pd": only with a controller that has joint PD gains


CONTROL_PARAMETERS = {
    "kp_scale": ControlParameter("1", "factor on the controller's joint PD stiffness (raibert's flight PD and "
                                 "attitude servo, hold, pid, a policy's PD), per joint", "one", joints=True,
                                 needs="pd"),
    "kd_scale": ControlParameter("1", "factor on the controller's joint PD damping, per joint", "one", joints=True,
                                 needs="pd"),
    "motor_stall_torque": ControlParameter("N·m", "a dc motor's stall torque at the joint, per joint", "effort",
                                           open_low=True, joints=True, needs="dc"),
    "motor_no_load_speed": ControlParameter("rad/s", "a dc motor's no-load speed at the joint, per joint", "speed",
                                            open_low=True, joints=True, needs="dc"),
    "motor_torque_limit": ControlParameter("N·m", "a dc motor's current limit as the joint torque it allows, per "
                                           "joint", "effort", open_low=True, joints=True, needs="dc"),
    "action_delay": ControlParameter("ms", "from a command (a torque, or a policy's joint targets) to the motors, "
                                     "whole physics steps "
                                     "(rounded)", high=1000.0),
    "sensor_delay": ControlParameter("ms", "the controller reads its observation this late, whole physics "
                                     "steps (rounded)", high=1000.0),
    "gyro_noise": ControlParameter("rad/s", "std of the IMU's angular-rate noise, per axis, each step the "
                                   "controller reads it and in the recorded IMU"),
    "gyro_bias": ControlParameter("rad/s", "constant offset of the IMU's angular rate, per axis (x, y, z)",
                                  low=-1.0, high=1.0, offset=True, axes=True),
    "accel_noise": ControlParameter("m/s²", "std of the recorded IMU's specific-force noise (no controller "
                                    "reads it)"),
    "odom_pos_noise": ControlParameter("m", "std of the odometry's position noise, each step the controller "
                                       "reads it and in the recorded odometry"),
    "odom_vel_noise": ControlParameter("m/s", "std of the odometry's linear-velocity noise, as the position's"),
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
