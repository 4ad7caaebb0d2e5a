"""A monoped task's configuration (`MonopedConfig`): everything that shapes a task, saved beside a trained policy
(`hopper_env.json`), and the training physics it asks for (`training_model`: the timestep and the solver's cap
the env's engine is made from; the physics step itself is the core's, `hopper_mjx.step`)."""

from __future__ import annotations

import copy
import dataclasses
import math

import mujoco
import numpy as np

from hopper_mjx import engine as engines
from hopper_mjx import registry
from hopper_mjx.hardware.pushes import Pushes
from hopper_mjx.metrics import hops
from hopper_mjx.model.layout import Layout
from hopper_mjx.terrain import scan as terrain_scan
from hopper_mjx.variation.spec import Spec

MAX_TILT_FROM_VERTICAL = 0.8  # rad between the base's z axis and the vertical that ends an episode

APEX_REWARDS = ("predicted", "flight")
RANGES = ("gravity_range", "apex_range", "speed_range", "lateral_speed_range", "initial_clearance", "height_band")
# Fields of configs saved before stand was redefined (its foot-support term); a policy's hopper_env.json with
# them still loads (they only shaped the reward it was trained on).
RETIRED = ("w_support", "support_scale")
# A kernel exp(-error / scale) with a scale of 0 or below pays more the larger the error.
SCALES = ("height_scale", "apex_scale", "speed_scale", "upright_scale", "clearance_target")
WEIGHTS = ("w_alive", "w_height", "w_apex", "w_speed", "w_upright", "w_effort", "w_action_rate", "w_spin",
           "w_clearance", "fall_penalty")


@dataclasses.dataclass(frozen=True)
class MonopedConfig:
    """Everything that shapes a task; saved beside a trained policy (`to_dict`). Each task's
    `default_config()` sets its own defaults (hopper_mjx.envs.tasks)."""

    task: str = "hop"  # a policy folder saved before tasks existed is a `hop` policy
    policy_rate: float = 50.0  # Hz; the physics runs at 1 / timestep
    # m/s², per episode, log-uniform: as much experience per factor of g at the Moon end
    # (slow hops, few per episode) as at the Earth end.
    gravity_range: tuple[float, float] = (1.0, 12.0)
    observe_gravity: bool = False
    apex_range: tuple[float, float] = (1.0, 1.2)  # m, commanded base height at the top of a hop
    speed_range: tuple[float, float] = (-0.2, 0.2)  # m/s, commanded vx (and vy unless lateral_speed_range)
    lateral_speed_range: tuple[float, float] | None = None  # m/s, commanded vy; None: as speed_range
    action_scale: tuple[float, float, float] = (0.3, 0.6, 0.8)  # rad per unit action: haa, hfe, kfe
    kp: tuple[float, float, float] = (300.0, 300.0, 300.0)  # N·m/rad
    kd: tuple[float, float, float] = (6.0, 6.0, 6.0)  # N·m·s/rad
    # Reward weights (per policy step) and kernel widths.
    w_alive: float = 0.0  # per step upright (stand)
    w_height: float = 0.0  # stand: exp(-(distance of z outside height_band) / height_scale)
    # m about the standing height, stand: the base anywhere from a crouch to a small hop's apex is "up".
    height_band: tuple[float, float] = (0.0, 0.0)
    height_scale: float = 0.05  # m
    w_apex: float = 1.0
    apex_scale: float = 0.1  # m; exp(-|error| / scale)
    # What the apex kernel judges (`APEX_REWARDS`): "predicted", the ballistic apex from the state (its height
    # when falling: a hop is judged below its top all through its fall and stance); "flight", the apex of the
    # flight under way, held through the stance after it (each hop's apex, as the evaluation measures it).
    apex_reward: str = "predicted"
    w_speed: float = 0.5
    speed_scale: float = 0.3  # m/s
    w_upright: float = 0.5
    upright_scale: float = 0.25  # rad; exp(-(tilt / scale)²)
    w_effort: float = 0.05  # times the mean of (torque / limit)²
    w_action_rate: float = 0.02
    w_spin: float = 0.01  # times |angular rate|², rad²/s²
    # In flight, the foot's bottom over the ground under it, as a share of clearance_target (capped at 1): a leg
    # drawn up in flight, which a block's face or a step's riser ahead asks for (0: no such term).
    w_clearance: float = 0.0
    clearance_target: float = 0.12  # m
    # s: the ground the term measures from is the highest the foot will pass over in this time at the base's
    # horizontal velocity (0: the ground under it), so a foot rising towards a face ahead earns only once above it.
    clearance_lookahead: float = 0.0
    fall_penalty: float = 10.0
    # A fall: the base's z axis this far from vertical (rad; not the metrics' per-axis roll/pitch
    # bound, see docs/learning.md), or its origin this low (m).
    max_tilt: float = MAX_TILT_FROM_VERTICAL
    min_base_height: float = hops.FALL_HEIGHT  # m
    initial_clearance: tuple[float, float] = (0.0, 0.1)  # m, foot above the floor at reset
    initial_joint_noise: float = 0.05  # rad
    # Training physics: the core's 1 ms step (a policy trained at 2 ms hopped 9-11 % of its commanded apex
    # higher there than in the core: docs/learning.md) and MuJoCo's Newton solver, warm-started, capped at these
    # iterations (the core's runs to convergence; the cap moved the apex by <= 1 %, and is cheaper on CPU MJX).
    timestep: float = 0.001  # s
    solver_iterations: int = 2
    ls_iterations: int = 4
    engine: str = "auto"  # hopper_mjx.engine name: auto (chain for the monoped), chain or mjx
    robot: str = ""  # `model.robot.fingerprint` of the robot (set by the env); "" in policies saved before it
    # The robots episodes run: a --randomize spec ("" the URDF's robot), drawn once with randomize_seed.
    randomize: str = ""
    randomize_seed: int = 0
    motor: str = registry.DEFAULT_MOTOR  # a registry.MOTORS name: the joints' motors (hopper_mjx.hardware.actuators)
    action_delay: float = 0.0  # s from the PD torque to the motors', whole steps of `timestep`; a drawn one wins
    push: tuple[float, float] | None = None  # (interval s, speed m/s) of random horizontal pushes in an episode
    terrain: str = ""  # a --terrain spec with a fixed seed: the ground of every episode ("" the flat plane)
    # On a terrain: the policy reads the height scan; False zeros it (the same network, blind: what the scan adds).
    observe_scan: bool = True
    # The scan's points (`scan`): a grid of counts (ahead, left) at spacing m, centred under the base. The default
    # reaches 0.2 m ahead, less than a hop at the Moon carries the base (0.35 m at 0.5 m/s and a 0.1 m rise).
    scan_counts: tuple[int, int] = (5, 5)
    scan_spacing: tuple[float, float] = (0.1, 0.1)

    def __post_init__(self):
        self._check_numbers()
        for name in RANGES:
            pair = getattr(self, name)
            if pair is None:
                continue
            lo, hi = pair
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ValueError(f"{name} must be a finite (low, high) pair with low <= high, got {(lo, hi)}")
        if not self.gravity_range[0] > 0:
            raise ValueError(f"gravity_range must be > 0 m/s² (magnitudes, drawn log-uniformly), "
                             f"got {self.gravity_range}")
        if self.apex_reward not in APEX_REWARDS:
            raise ValueError(f"apex_reward must be one of {', '.join(APEX_REWARDS)}, got {self.apex_reward!r}")
        if not (self.policy_rate > 0 and self.timestep > 0):
            raise ValueError(f"policy_rate and timestep must be positive, got {self.policy_rate}, {self.timestep}")
        engines.check_name(self.engine)
        registry.check("motor", registry.MOTORS, self.motor)
        if not (math.isfinite(self.action_delay) and self.action_delay >= 0
                and abs(self.delay_steps * self.timestep - self.action_delay) <= 1e-9):
            raise ValueError(f"action_delay must be a whole number (>= 0) of physics steps ({self.timestep * 1e3:g} "
                             f"ms), got {self.action_delay * 1e3:g} ms")
        if self.push is not None:
            Pushes.of(*self.push, self.timestep)  # raises for an interval of no whole step, a negative speed
        ground = self.ground  # raises TerrainError (a ValueError) for a bad spec
        if ground.is_flat and self.terrain:  # "flat" is the plane, which the env and its users know as ""
            object.__setattr__(self, "terrain", "")
        if ground.each:
            raise ValueError(f"terrain {self.terrain!r}: training puts every episode on one ground; give a fixed seed")
        if not self.observe_scan and not self.terrain:
            raise ValueError("observe_scan=false zeros the height scan, which a policy reads only on a terrain; "
                             "this one trains on the flat plane")
        shaped = [f for f in ("scan_counts", "scan_spacing") if getattr(self, f) != getattr(MonopedConfig, f)]
        if shaped and not self.terrain:
            raise ValueError(f"{' and '.join(shaped)} shape{'s' * (len(shaped) == 1)} the height scan, which a policy "
                             "reads only on a terrain; this one trains on the flat plane")
        dc_only = [name for name in self.variation.controls if registry.CONTROL_PARAMETERS[name].needs == "dc"]
        if dc_only and self.motor != "dc":
            raise ValueError(f"randomize: {', '.join(dc_only)} are a dc motor's figures; set motor='dc'")

    def _check_numbers(self) -> None:
        """The reward's, the PD law's and the physics' numbers: finite, and positive where a sign would turn their
        meaning around (a kernel's width, a gain, the step); raises ValueError naming the first that is not."""
        def bad(name: str, why: str):
            return ValueError(f"{name} must be {why}, got {getattr(self, name)}")

        def holds(name: str, positive: bool) -> bool:  # every value of the field finite and > 0 (or >= 0)
            v = np.atleast_1d(np.asarray(getattr(self, name), dtype=float))
            return bool(np.all(np.isfinite(v)) and np.all(v > 0 if positive else v >= 0))

        for name, why in ([(n, "finite and > 0 (a kernel's width)") for n in SCALES]
                          + [("timestep", "finite and > 0 s"), ("policy_rate", "finite and > 0 Hz"),
                             ("action_scale", "three finite values > 0 rad per unit action")]):
            if not holds(name, positive=True):
                raise bad(name, why)
        for name in ("kp", "kd", "initial_joint_noise", "clearance_lookahead"):
            if not holds(name, positive=False):
                raise bad(name, "finite and >= 0")
        for name in (*WEIGHTS, "min_base_height"):
            if not math.isfinite(getattr(self, name)):
                raise bad(name, "finite")
        terrain_scan.check_grid(self.scan_counts, self.scan_spacing)
        if not 0 < self.max_tilt <= math.pi:
            raise bad("max_tilt", "in (0, pi] rad from the vertical")
        if self.solver_iterations < 1 or self.ls_iterations < 1:
            raise ValueError(f"solver_iterations and ls_iterations must be >= 1, got {self.solver_iterations}, "
                             f"{self.ls_iterations}")

    @property
    def delay_steps(self) -> int:
        """The fixed action delay in physics steps."""
        return round(self.action_delay / self.timestep)

    @property
    def scan(self) -> np.ndarray:
        """(K, 2) m: the height scan's points in the base's yaw frame (`terrain.scan.scan_points`)."""
        return terrain_scan.scan_points(self.scan_counts, self.scan_spacing)

    @property
    def scan_size(self) -> int:
        """The height scan's points a policy of this config reads: none on the flat plane."""
        return len(self.scan) if self.terrain else 0

    @property
    def variation(self) -> Spec:
        """The robots' spec (empty: the URDF's robot); raises ValueError for a bad one."""
        return Spec.parse(self.randomize) if self.randomize else Spec()

    @property
    def ground(self):
        """The parsed `terrain` (`terrain.Ground`; FLAT for "")."""
        from hopper_mjx import terrain

        return terrain.parse(self.terrain) if self.terrain else terrain.FLAT

    @property
    def vy_range(self) -> tuple[float, float]:
        return self.speed_range if self.lateral_speed_range is None else self.lateral_speed_range

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def overridden(self, pairs: list[str], owned: dict[str, str]) -> "MonopedConfig":
        """This config with `KEY=VALUE` texts applied (a pair as `low,high`), checked whole; raises ValueError
        naming the first bad one. `owned`: fields another option sets {field: that option}, refused here."""
        fields = {f.name for f in dataclasses.fields(self)}
        changes = {}
        for pair in pairs:
            key, sep, text = pair.partition("=")
            key = key.strip()
            if not sep or key not in fields or key in ("task", "robot"):
                known = ", ".join(sorted(set(fields) - set(owned) - {"task", "robot"}))
                raise ValueError(f"{pair!r} is not KEY=VALUE with a task config field; fields: {known}")
            if key in owned:
                raise ValueError(f"{key} is set by {owned[key]}, not here")
            default = getattr(self, key)
            try:
                if isinstance(default, bool):
                    if text.lower() not in ("true", "false"):
                        raise ValueError
                    value = text.lower() == "true"
                elif isinstance(default, (int, float)):
                    value = type(default)(text)
                elif isinstance(default, str):
                    value = text
                else:  # a tuple, or a pair whose default is None: comma-separated numbers (whole for a count)
                    value = tuple((int if _whole(default) else float)(v) for v in text.split(","))
                    if len(value) != (2 if default is None else len(default)):
                        raise ValueError
            except ValueError:
                raise ValueError(f"{key}={text!r}: expected {_kind(default)}") from None
            changes[key] = value
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_dict(cls, values: dict) -> "MonopedConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        values = {k: v for k, v in values.items() if k not in RETIRED}
        unknown = set(values) - known
        if unknown:
            raise ValueError(f"unknown MonopedConfig field(s): {sorted(unknown)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def _kind(default) -> str:
    if isinstance(default, bool):
        return "true or false"
    if isinstance(default, (int, float, str)):
        return f"a {type(default).__name__}"
    return f"{2 if default is None else len(default)} comma-separated {'whole ' if _whole(default) else ''}numbers"


def _whole(default) -> bool:
    """A tuple field of whole numbers (a count), by its default."""
    return default is not None and isinstance(default[0], int)


def steps_per_action(rate: float, timestep: float) -> int | None:
    """Whole physics steps of `timestep` s per policy step at `rate` Hz; None where the rate does not divide the
    physics rate (or is not a positive number)."""
    steps = 1.0 / (rate * timestep) if math.isfinite(rate) and rate > 0 else 0.0
    return int(round(steps)) if steps >= 1 and abs(steps - round(steps)) <= 1e-6 else None


def decimation(layout: Layout, cfg: MonopedConfig) -> int:
    """Physics steps per policy step; the policy rate must divide the physics rate."""
    steps = steps_per_action(cfg.policy_rate, layout.timestep)
    if steps is None:
        raise ValueError(f"policy_rate={cfg.policy_rate} Hz must divide the physics rate {1 / layout.timestep:g} Hz")
    return steps


def training_model(mj_model: mujoco.MjModel, cfg: MonopedConfig) -> mujoco.MjModel:
    """The model the environment steps: the configured timestep, MuJoCo's sensor stage off
    (signals come from the state), the constraint solver capped at the configured iterations."""
    m = copy.deepcopy(mj_model)
    m.opt.timestep = cfg.timestep
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
    m.opt.iterations = cfg.solver_iterations
    m.opt.ls_iterations = cfg.ls_iterations
    return m
