"""Runs a sweep in resumable chunks, on every local device and across processes.

Each chunk of `spec.chunk` instances is one call of the batched core (which
shards it over the local devices); its metrics are written atomically to
`OUT/chunks/NNNNN.npy`, so a killed run resumes where it stopped. Under
`jax.distributed`, process p runs chunks p, p + P, p + 2P, ...; their rows
then travel to process 0 through JAX's own collectives (no shared filesystem
needed), which writes the merged outputs.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import jax
import numpy as np
from tqdm import tqdm

from hopper_mjx import registry, terrain
from hopper_mjx.control import gait, predicted_latency
from hopper_mjx.control.balance import balance
from hopper_mjx.control.base import pd_scale
from hopper_mjx.control.raibert import GAINS, raibert_params
from hopper_mjx.control.raibert import legs as raibert_legs
from hopper_mjx.hardware import signals
from hopper_mjx.metrics import hops
from hopper_mjx.shell.files import atomic_write
from hopper_mjx.sim import Sim, gravity_vectors, steps_for
from hopper_mjx.sweep import limits
from hopper_mjx.sweep.folder import chunk_path, claim, read_chunk
from hopper_mjx.sweep.grid import BAND_KINDS, SAMPLE_HZ, Instances, SweepSpec, expand
from hopper_mjx.variation import draw

COLUMNS = ("apex_height", "flight_rise", "flight_time", "ballistic_flight_time", "stance_time", "hop_period",
           "duty_factor", "mean_speed", "tracking_error",
           "max_roll", "max_pitch", "hops", "fell", "diverged", "cost_of_transport",
           "energy_per_hop", "mechanical_power", "highest_apex")
# An obstacle, gaps or terrain sweep's extra columns (`hops.terrain_metrics`).
TERRAIN_COLUMNS = ("distance_made_good", "obstacles_cleared", "highest_cleared", "fall_x", "fall_y")
# A block or gaps sweep's, besides: how its landings went (`hops.landing_metrics`).
LANDING_COLUMNS = ("landing_tilt", "impact_force", "past_tilt", "past_impact")
# And what its jumps asked of each joint's motor (`hops.actuator_metrics`).
ACTUATOR_COLUMNS = tuple(f"{m}_{j}" for m in ("peak_torque", "peak_power", "line_use") for j in hops.JOINT_NAMES)
# A gravity sweep asked past the motors' bound, besides: how its highest hop landed (`hops.hop_metrics`).
LIMIT_COLUMNS = ("highest_landing_tilt",)


def recorded(timestep: float, torque: bool = False) -> signals.SensorConfig:
    """The streams a sweep records: contact and state at the physics rate (events, lift-off heights and apexes to
    the step, short flights too), the IMU and odometry at 100 Hz; the joints' torques where its metrics read them
    (a block or gaps sweep's)."""
    rate = 1.0 / timestep
    return signals.SensorConfig(imu_rate=SAMPLE_HZ, odom_rate=SAMPLE_HZ, contact_rate=rate, state_rate=rate,
                                torque=torque)


def columns(spec: SweepSpec) -> tuple[str, ...]:
    """The metrics a sweep's rows hold."""
    bands = LANDING_COLUMNS + ACTUATOR_COLUMNS if spec.kind in BAND_KINDS else ()
    limit = LIMIT_COLUMNS if spec.kind == "gravity" and limits.apex_bounds(spec) else ()
    return COLUMNS + (TERRAIN_COLUMNS if spec.grounds else ()) + bands + limit


class ChunkRunner:
    """One compiled rollout + metrics, applied to chunks of the grid."""

    def __init__(self, spec: SweepSpec, instances: Instances, sim: Sim, robots: dict, controls: dict):
        """`robots`: {model field: (rows, ...)} each robot row's model (`draw.with_constants`), or {};
        `controls`: {control parameter: (rows, ...)} its controller's, motors' and sensors' (`Instances.robot_row`
        says which row an instance runs)."""
        self.spec, self.instances, self.sim, self.robots, self.controls = spec, instances, sim, robots, controls
        # Each robot row's leg, when drawn: what Raibert models and where the apex rise counts from.
        own = draw.legs(sim.mj_model, robots)
        self.legs = None if own is None or spec.controller not in registry.GAIT_CONTROLLERS \
            else raibert_legs(sim.robot, own)
        self.standing = None if own is None else np.array([r.standing_height for r in own])
        self.policy = registry.policy_path(spec.controller) if registry.is_policy(spec.controller) else None
        if spec.controller == "balance":  # commands nothing: it stands
            self.controller = balance(sim.robot, sim.mj_model)
        elif self.policy is None:
            self.controller = gait(spec.controller, sim.robot, sim.actuation.kind)
        else:  # brax is imported only when a policy is swept
            from hopper_mjx.envs.policy import policy_controller, read

            self.controller = policy_controller(sim.mj_model, self.policy)
            self.policy_config = read(self.policy)[3]  # once, not per chunk
        self.sensors = recorded(sim.layout.timestep, torque=spec.kind in BAND_KINDS)
        self.steps = steps_for(spec.duration, sim.layout.timestep, self.sensors)
        self.columns = columns(spec)
        self.grounds = [terrain.parse(g) for g in spec.grounds]  # one per value, all on the model's grid
        self._heights = {}

    def ground(self, full: np.ndarray):
        """((n, nrow, ncol) m each instance's ground, (n, B, 3) its obstacles) of a terrain sweep,
        or (None, None); replicate r's draw under seed=each is the same at every value and gravity."""
        if not self.grounds:
            return None, None
        inst = self.instances
        which = [(self.spec.values.index(v), r) for v, r in zip(inst.value[full], inst.replicate[full])]
        for k, r in set(which) - set(self._heights):
            grid = self.grounds[k].instance(self.spec.seed, r)
            self._heights[k, r] = grid.terrain().heights
        bands = [g.obstacles() for g in self.grounds]
        width = max(len(b) for b in bands)
        padded = [np.vstack([b, np.full((width - len(b), 3), np.nan)]) for b in bands]
        return np.stack([self._heights[w] for w in which]), np.stack([padded[k] for k, _ in which])

    def params(self, full: np.ndarray):
        """Every instance's command (and swept gain, and PD factors): the same for Raibert and a policy."""
        spec = self.spec
        row = self.instances.robot_row[full]
        pick = lambda name: self.controls[name][row] if name in self.controls else None
        pd = pd_scale(len(full), pick("kp_scale"), pick("kd_scale"))
        if spec.controller == "balance":
            return None
        if self.policy is not None:
            from hopper_mjx.envs.policy import policy_params

            return policy_params(self.sim.robot, len(full), height=spec.height, speed=spec.speed,
                                 config=self.policy_config, pd=pd)
        gains = {spec.param: self.instances.value[full]} if spec.param in GAINS else {}
        leg = None if self.legs is None else jax.tree_util.tree_map(lambda v: v[row], self.legs)
        delay = pick("action_delay")  # ms, drawn or swept; else the run's one
        latency = predicted_latency(spec.controller, spec.physics.action_delay if delay is None else delay * 1e-3)
        return raibert_params(len(full), height=spec.height, speed=spec.speed, pd=pd, leg=leg, latency=latency,
                              **gains)

    def mass(self, full: np.ndarray):
        """kg of each instance's robot (its drawn link masses), for the cost of transport and power."""
        if "body_mass" not in self.robots:
            return self.sim.layout.total_mass
        return self.robots["body_mass"][self.instances.robot_row[full]].sum(axis=1)

    def standing_height(self, row: np.ndarray):
        """m: the URDF's standing height, or (n,) each instance's own when its leg is drawn."""
        return self.sim.robot.standing_height if self.standing is None else self.standing[row]

    def __call__(self, index: np.ndarray) -> np.ndarray:
        """Metrics (len(index), len(COLUMNS)) of the given instances."""
        n = len(index)
        full = np.concatenate([index, np.full(self.spec.chunk - n, index[0])])  # one shape, one compile
        inst = self.instances
        row = inst.robot_row[full]
        heights, obstacles = self.ground(full)
        final, traj = self.sim.run(gravity_vectors(inst.gravity[full]), self.controller, self.params(full),
                                   duration=self.spec.duration, sensors=self.sensors, key=self.spec.seed,
                                   qvel=inst.qvel[full], variation={f: v[row] for f, v in self.robots.items()},
                                   ground=heights,
                                   **self.sim.per_instance({k: v[row] for k, v in self.controls.items()}))
        result = hops.hop_metrics(traj, inst.gravity[full], command_speed=self.spec.speed,
                                     standing_height=self.standing_height(row),
                                     work=np.asarray(motor_energy(final)), mass=self.mass(full))
        result["diverged"] = np.asarray(final.diverged)
        if self.grounds:
            result |= hops.terrain_metrics(traj, command_speed=self.spec.speed, obstacles=obstacles)
        if self.spec.kind in BAND_KINDS:
            result |= hops.landing_metrics(traj, obstacles)
            result |= hops.actuator_metrics(traj, self.sim.layout.joint_dof, *motor_figures(final, self.sim.layout))
        return np.stack([np.asarray(result[c], dtype=np.float64) for c in self.columns], axis=1)[:n]


def motor_energy(final):
    """(N,) J the motors used: with a motor model, what the drive measured (dc: electrical energy drawn);
    with ideal motors and no delay, the controller's ∫Σ|τ·q̇|dt of the torques it commanded (the same)."""
    return final.drive.energy if final.drive else final.cstate.work


def motor_figures(final, layout) -> tuple:
    """(stall torque, no-load speed, torque limit), (N, 3) N·m, rad/s, N·m each: the motors the run had (ideal
    prompt motors: the effort limit at every speed)."""
    if final.drive:
        motor = final.drive.motor
        return tuple(np.asarray(a) for a in (motor.stall_torque, motor.no_load_speed, motor.torque_limit))
    effort = np.broadcast_to(np.asarray(layout.effort_limit, float), final.gravity.shape)
    return effort, np.full_like(effort, np.inf), effort


def robots(spec: SweepSpec, mj_model) -> tuple[dict, dict, dict]:
    """(model fields, control parameters, results.csv columns), each {name: (rows, ...)}: one robot per
    replicate, and with a swept parameter one per value and replicate (`Instances.robot_row`); raises
    ValueError for a value outside its parameter's range."""
    parts = [(draw.draw(s, mj_model, spec.num, spec.seed), draw.draw_controls(s, mj_model, spec.num,
                                                                                         spec.seed))
             for s in spec.robot_specs()]
    stack = lambda dicts: {k: np.concatenate([d[k] for d in dicts]) for k in dicts[0]}
    drawn, controls = stack([p[0] for p in parts]), stack([p[1] for p in parts])
    both = spec.robot_specs()[0]
    columns = draw.columns(both, mj_model, drawn) | draw.control_columns(controls)
    if spec.sweeps_robot:  # the swept value has its own column already
        columns = {k: v for k, v in columns.items() if k != spec.param}
    return drawn, controls, columns


def run(spec: SweepSpec, out: Path, *, progress: bool = True) -> tuple[Instances, np.ndarray, dict]:
    """Runs (or resumes) the sweep; returns the grid, its metrics (n, len(COLUMNS)) and run facts."""
    out = Path(out)
    claim(out, spec)
    (out / "chunks").mkdir(exist_ok=True)
    physics = spec.robot_physics
    drawn, controls, robot = robots(spec, physics.mj_model)
    sim = physics.sim(controls=controls)
    instances = expand(spec, sim.layout.nv)
    instances = dataclasses.replace(instances, robot={k: v[instances.robot_row] for k, v in robot.items()})
    chunks = [np.arange(i, min(i + spec.chunk, len(instances))) for i in range(0, len(instances), spec.chunk)]
    me, procs = jax.process_index(), jax.process_count()
    mine = list(range(me, len(chunks), procs))
    saved = {k: read_chunk(out, k, len(chunks[k]), len(columns(spec))) for k in mine}
    todo = [k for k in mine if saved[k] is None]  # missing, or damaged by a kill mid-write: (re)computed
    runner = ChunkRunner(spec, instances, sim, draw.with_constants(sim.mj_model, drawn), controls) \
        if todo else None

    start, simulated = time.perf_counter(), 0
    # Counted in instances, whole numbers: instance-seconds (instances x a duration such as 0.01 s) showed float sums
    # such as 0.30000000000000004/0.3 on short runs.
    bar = tqdm(total=sum(len(chunks[k]) for k in todo), unit="instance", disable=not progress,
               desc=f"sweep {spec.kind}, {spec.duration:g} s each" + (f" [process {me}/{procs}]" if procs > 1 else ""),
               smoothing=0.3)
    for k in todo:
        rows = saved[k] = runner(chunks[k])
        atomic_write(chunk_path(out, k), lambda f, rows=rows: np.save(f, rows))
        simulated += len(chunks[k]) * runner.steps
        bar.update(len(chunks[k]))
        bar.set_postfix_str(f"{simulated / (time.perf_counter() - start):,.0f} steps/s")
    bar.close()
    wall = time.perf_counter() - start

    # With one process its chunks are all the chunks; with several, gather them in chunk order.
    rows_by_chunk = [saved[k] for k in mine]
    if procs > 1:
        rows_by_chunk = _gather_to_all(rows_by_chunk, chunks, procs, len(columns(spec)))
        if me == 0:  # keep every chunk on the coordinator, so it can merge and resume
            for k, rows in enumerate(rows_by_chunk):
                if not chunk_path(out, k).exists():
                    atomic_write(chunk_path(out, k), lambda f, rows=rows: np.save(f, rows))
    table = np.concatenate(rows_by_chunk)
    facts = {
        "wall_s": wall,
        "steps_simulated": simulated,
        "steps_per_s": simulated / wall if simulated else None,
        "devices": [str(d) for d in jax.local_devices()],
        "processes": procs,
    }
    return instances, table, facts


def _gather_to_all(mine_rows: list[np.ndarray], chunks: list[np.ndarray], procs: int,
                   width: int = len(COLUMNS)) -> list[np.ndarray]:
    """Every process's chunk rows, in chunk order, on every process (bit-exact)."""
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    per_proc = -(-len(chunks) // procs)
    block = np.full((per_proc, chunks[0].size, width), np.nan)
    for j, rows in enumerate(mine_rows):
        block[j, : len(rows)] = rows
    # A global array with one slice per process, replicated by a jitted identity: an
    # all-gather over JAX's CPU collectives. float64 travels as uint32 pairs, since
    # JAX without x64 would round it to float32.
    devices = sorted(jax.devices(), key=lambda d: (d.process_index, d.id))
    mesh = Mesh(np.array(devices).reshape(procs, -1), ("process", "local"))
    local = jax.make_array_from_process_local_data(
        NamedSharding(mesh, PartitionSpec("process")), block.view(np.uint32)[None]
    )
    everywhere = jax.jit(lambda x: x, out_shardings=NamedSharding(mesh, PartitionSpec()))(local)
    gathered = np.asarray(everywhere.addressable_data(0)).view(np.float64)
    return [gathered[k % procs, k // procs, : len(chunks[k])] for k in range(len(chunks))]
