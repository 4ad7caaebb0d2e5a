"""What a sweep simulates: its arguments, and the instances they expand to.

A `SweepSpec` holds every argument that changes results; it is saved as the
run's manifest, so a rerun into the same folder can tell a resume from a
different experiment. A gains or param sweep's values are a Raibert gain's or a --randomize parameter's; an
obstacle, gaps or terrain sweep's are a terrain's (a block's height, a gap's width, rough ground's amplitude), each
with its own ground (`grounds`, one --terrain spec per value, all on one grid). Instances are ordered value-major,
then gravity, then replicate, and chunked in that order. Replicate r has the same kick, and the same robot under
--randomize, at every grid point (common random numbers): a swept parameter replaces its own draw only, the others'
stay as they were.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from hopper_mjx import registry
from hopper_mjx.scenario import Physics
from hopper_mjx.shell import budget, checks
from hopper_mjx.variation.spec import NAMES, Dist, Spec

PLANETS = {1.62: "Moon", 3.71: "Mars", 9.81: "Earth"}
DEFAULT_GRAVITY = (0.5, 1.0, 1.62, 2.5, 3.71, 5.0, 7.5, 9.81, 12.0)  # m/s²
# m/s and rad/s: std of the random initial base velocity (x, y, roll and pitch rates). The default
# sweep's kick is small, so that its table describes steady hopping: every replicate survives it at
# every gravity (README). Robustness is measured with --kick 0.3: 96.0 % survive over 1-12 m/s²
# (docs/control.md).
KICK = 0.03
SAMPLE_HZ = 100  # a sweep's IMU and odometry rate (contact and state: the physics rate); a run is whole samples
TERRAIN_KINDS = ("obstacle", "gaps", "terrain")  # sweeps over a terrain's parameter: one ground per value
# The terrain sweeps whose ground holds one band across the way to get past, and what the band is called.
BAND_KINDS = {"obstacle": "block", "gaps": "gap"}
PASSED = {"obstacle": "cleared", "gaps": "crossed"}  # what getting past a band sweep's band is called
KINDS = ("gravity", "gains", "param", *TERRAIN_KINDS)


def sample_steps(timestep: float) -> int:
    """Physics steps that hold one sample of every stream a sweep records."""
    return round(1 / (SAMPLE_HZ * timestep))


@dataclass(frozen=True)
class SweepSpec:
    kind: str  # one of KINDS: "gains" (a Raibert gain), "param" (a gain or a --randomize parameter), a terrain's
    gravity: tuple[float, ...]  # m/s², pointing down
    num: int  # replicates per grid point
    duration: float  # s of simulated time
    height: float  # m, commanded apex rise over standing height
    speed: tuple[float, float]  # m/s commanded (vx, vy)
    seed: int
    kick: float = KICK
    chunk: int = 256  # instances per compiled call; fixed so every chunk reuses one compile
    param: str | None = None  # the Raibert gain or --randomize parameter swept by `gains` / `param`
    values: tuple[float, ...] = ()
    controller: str = "raibert"  # or policy:PATH, a policy trained by experiments/train.py
    physics: Physics = Physics()  # the robot, its engine (and what else compiles), the same for every grid point
    grounds: tuple[str, ...] = ()  # obstacle / terrain sweeps: the --terrain spec of each of `values`

    @staticmethod
    def whole_duration(duration: float, timestep: float) -> float:
        """The s a sweep of `duration` s runs: whole samples of its streams (`budget.whole_steps`), as its runner
        steps it, so that its rows and report say the time run; `duration` itself where it cannot run at all."""
        if not (math.isfinite(duration) and duration > 0):
            return duration  # refused with the rest, below
        return budget.run_time(duration, timestep, sample_steps(timestep))

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"unknown sweep kind {self.kind!r}; use {', '.join(KINDS)}")
        if not self.gravity:
            raise ValueError("no gravity values given")
        bad = [g for g in self.gravity if not (math.isfinite(g) and g > 0)]
        if bad:
            raise ValueError(f"--gravity values must be finite and > 0 m/s², got {bad}")
        if len(set(self.gravity)) != len(self.gravity):  # a grid point twice would be counted twice
            raise ValueError(f"--gravity values must differ, got {list(self.gravity)}")
        checks.check_seed(self.seed)
        if self.num < 1:
            raise ValueError(f"--num must be >= 1, got {self.num}")
        if not (math.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"--duration must be > 0 s, got {self.duration}")
        if not (math.isfinite(self.height) and self.height >= 0):
            raise ValueError(f"--height must be >= 0 m, got {self.height}")
        if len(self.speed) != 2 or not all(math.isfinite(v) for v in self.speed):
            raise ValueError(f"--speed must be two finite numbers VX,VY, got {self.speed}")
        if not (math.isfinite(self.kick) and self.kick >= 0):
            raise ValueError(f"--kick must be >= 0, got {self.kick}")
        if self.chunk < 1:
            raise ValueError(f"--chunk must be >= 1, got {self.chunk}")
        checks.check_engine(self.physics.engine)
        if self.controller not in registry.SWEEP_CONTROLLERS and not registry.is_policy(self.controller):
            raise ValueError(f"--controller {self.controller!r}: a sweep runs "
                             f"{', '.join(registry.SWEEP_CONTROLLERS)} or policy:PATH")
        if self.kind in ("gains", "param"):
            from hopper_mjx.control.raibert import GAINS

            if self.kind == "gains" and self.param not in GAINS:
                raise ValueError(f"unknown gain {self.param!r}; choose from {', '.join(GAINS)}")
            if self.param not in (*GAINS, *NAMES):
                raise ValueError(f"unknown --param {self.param!r}; choose a Raibert gain ({', '.join(GAINS)}) or a "
                                 f"--randomize parameter ({', '.join(NAMES)})")
            if self.param in GAINS and self.controller not in registry.GAIT_CONTROLLERS:
                raise ValueError(f"{self.param} is a Raibert gain: use --controller "
                                 f"{' or '.join(registry.GAIT_CONTROLLERS)}")
            if self.param in self.variation.names:
                raise ValueError(f"--param {self.param} is drawn by --randomize too; leave it out of one")
            if not self.values or not all(math.isfinite(v) for v in self.values):
                raise ValueError("--values must be one or more finite numbers")
            if len(set(self.values)) != len(self.values):  # as gravity: a grid point twice is counted twice
                raise ValueError(f"--values must differ, got {list(self.values)}")
            if self.param in GAINS:  # refused here, not by the chunk that would run it
                from hopper_mjx.control.raibert import check_gain

                for value in self.values:
                    try:
                        check_gain(self.param, value)
                    except ValueError as err:
                        raise ValueError(f"--values {value:g}: {err}") from None
        if self.kind in TERRAIN_KINDS:
            self._check_grounds()
        elif self.grounds:
            raise ValueError(f"a {self.kind} sweep runs on the physics' ground; grounds are for "
                             f"{' and '.join(TERRAIN_KINDS)} sweeps")

    def _check_grounds(self) -> None:
        from hopper_mjx.terrain import TerrainError, parse

        if self.controller not in registry.TERRAIN_SWEEP_CONTROLLERS and not registry.is_policy(self.controller):
            raise ValueError(f"--controller {self.controller}: {self.kind} sweeps measure a hopping gait on terrain: "
                             f"use {', '.join(registry.TERRAIN_SWEEP_CONTROLLERS)} or policy:PATH")
        if not self.values or len(self.grounds) != len(self.values) or len(set(self.values)) != len(self.values):
            raise ValueError(f"a {self.kind} sweep needs one ground per value, the values all different")
        try:
            shapes = {parse(g).shape for g in self.grounds}
        except TerrainError as err:
            raise ValueError(f"--terrain: {err}") from None
        if len(shapes) != 1 or (0, 0) in shapes:
            raise ValueError(f"a {self.kind} sweep's grounds must be height fields on one grid (the same size and "
                             "cell)")
        if str(self.physics.ground) != self.grounds[0]:
            raise ValueError(f"a {self.kind} sweep compiles its first ground {self.grounds[0]}; the physics has "
                             f"{self.physics.ground}")

    def to_json(self) -> dict:
        """The manifest: the grid's arguments and the physics' fields, side by side."""
        grid = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "physics"}
        if not self.grounds:  # a sweep on the physics' ground keeps the manifest it always had
            del grid["grounds"]
        return grid | self.physics.to_json()

    @property
    def variation(self) -> Spec:
        """Which robot parameters each replicate draws (empty: the URDF's robot)."""
        return self.physics.variation or Spec()

    @property
    def swept(self) -> bool:
        """The grid has a value axis beside gravity (a gain, a parameter, or a terrain's)."""
        return self.kind != "gravity"

    @property
    def sweeps_robot(self) -> bool:
        """The swept value is a --randomize parameter: each value is a robot of its own."""
        return self.swept and self.param in NAMES

    def robot_specs(self) -> list[Spec]:
        """The variation of each value's robots (one spec; a swept parameter's: one per value, the
        parameter fixed at it after the others, whose draws stay as they were)."""
        if not self.sweeps_robot:
            return [self.variation]
        return [Spec((*self.variation.items, (self.param, Dist("fixed", v)))) for v in self.values]

    @property
    def robot_physics(self) -> Physics:
        """The physics the sweep compiles: with the swept parameter among its variation, so that the engine
        and the delay lines take it."""
        if not self.sweeps_robot:
            return self.physics
        items = (*self.variation.items, (self.param, Dist("uniform", min(self.values), max(self.values))))
        return dataclasses.replace(self.physics, variation=Spec(items))


@dataclass(frozen=True)
class Instances:
    """The expanded grid, one row per simulated monoped."""

    gravity: np.ndarray  # (n,) m/s²
    replicate: np.ndarray  # (n,) int
    value: np.ndarray  # (n,) swept gain value (NaN for a gravity sweep)
    qvel: np.ndarray  # (n, nv) initial velocity: the random kick
    robot: dict = dataclasses.field(default_factory=dict)  # column name -> (n,) drawn robot parameter
    # (n,) row of the drawn robots each instance runs (`runner.robots`): its replicate, or with a swept
    # parameter value index x num + replicate.
    robot_row: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.gravity)


def expand(spec: SweepSpec, nv: int) -> Instances:
    values = spec.values if spec.swept else (math.nan,)
    index, gravity, replicate = (
        a.ravel() for a in np.meshgrid(np.arange(len(values)), spec.gravity, np.arange(spec.num), indexing="ij")
    )
    value = np.asarray(values, dtype=float)[index]
    # Common random numbers: replicate r gets the same kick at every gravity and gain value,
    # so differences along the grid are not sampling noise; nor do they depend on chunking.
    kicks = np.array([np.random.default_rng([spec.seed, r]).normal(0.0, spec.kick, 4) for r in range(spec.num)])
    qvel = np.zeros((len(gravity), nv))
    qvel[:, [0, 1, 3, 4]] = kicks[replicate.astype(int)]  # vx, vy, roll rate, pitch rate
    row = index * spec.num + replicate if spec.sweeps_robot else replicate
    return Instances(gravity=gravity, replicate=replicate.astype(int), value=value, qvel=qvel,
                     robot_row=row.astype(int))
