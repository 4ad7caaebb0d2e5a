"""python -m hopper_mjx.perf.bench: the batched core (engine chain or mjx) against native multithreaded MuJoCo.

    python -m hopper_mjx.perf.bench --num 4096 --steps 1000 --json bench.json
    python -m hopper_mjx.perf.bench --scaling 64,256,1024,4096,16384 --steps 200 --engine chain,mjx --plot scaling.png

Both sides step the same compiled model, the same N instances for the same T
steps from the same initial state, instance i under the same gravity:

- core: `Sim.rollout` on `--engine` (auto: chain for the monoped) with the `hold`
  controller and the default 50 Hz signals, i.e. the full core (physics,
  controller, signals, divergence guard), sharded over every local device. Its
  JSON keys start with `core_`; `engine` names the engine that ran.
- native: `mujoco.rollout` with one thread per device, per-instance gravity
  given as a list of `MjModel`s (with `--randomize`, one model per instance: its
  drawn fields set and `mj_setConst` called, as the core's robot). The `hold` law (PD to the initial joint angles,
  saturated at the effort limits) runs inside MuJoCo's C step as affine-bias
  servo actuators with a constant target, so native pays for the same
  closed-loop control law without a Python callback. Native also computes its
  native sensors and writes its full state every step. `--controller raibert`
  has no C twin: the core runs Raibert's hopping controller while native keeps the
  hold law, which flatters native (cheaper control, fewer contact changes).

With `--env TASK`, the task's training env (train.py's wrapping, the stance held, or with `--env-actions random`
flailing as an untrained policy makes it) is then timed for the same N and T, sharded as Brax's training pmaps it
(`perf.env_pace`): its physics steps/s beside the core's. Its JSON keys start with `env_`.

    python -m hopper_mjx.perf.bench --num 256 --steps 1000 --env hop   # training's physics against the core's

Timings interleave the two sides and keep each side's best of `--repeat`
runs, because the cores are shared and noise only ever adds time. The ratio
is core steps/s over native steps/s.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from hopper_mjx import cli, registry
from hopper_mjx.perf import kernels
from hopper_mjx.perf.env_pace import ACTIONS as ENV_ACTIONS
from hopper_mjx.scenario import Physics
from hopper_mjx.shell import budget, jaxsetup, process
from hopper_mjx.shell.files import atomic_write, atomic_write_text

DISTINCT_GRAVITIES = 64  # distinct values, tiled over the batch: one native MjModel each
GRAVITY_SPAN = (1.62, 9.81)  # m/s², Moon to Earth
NATIVE_BUFFER_STEPS = 1 << 18  # instance-steps of native output (state + sensors) held at once
COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",  # includes a persistent-cache read
)


# Controllers with a native counterpart to time against (pid's integral state has none here).
CONTROLLERS = tuple(name for name in registry.CONTROLLERS if name != "pid")


def bench_gravities(num: int) -> np.ndarray:
    """(num,) gravity magnitudes: `DISTINCT_GRAVITIES` values from Moon to Earth, tiled."""
    if num < 1:
        raise ValueError(f"--num must be >= 1, got {num}")
    values = np.linspace(*GRAVITY_SPAN, min(num, DISTINCT_GRAVITIES))
    return values[np.arange(num) % values.size]


# -- native ---------------------------------------------------------------------


def native_hold_model(mj_model, layout, p: float, d: float):
    """A copy of `mj_model` whose motors are servos computing the `hold` law in C:
    torque = clip(p (ctrl - q) - d qdot, effort limit), with ctrl the target angle."""
    import mujoco

    m = copy.deepcopy(mj_model)
    for act in layout.actuator_of_joint:
        gear = m.actuator_gear[act, 0]
        m.actuator_gaintype[act] = mujoco.mjtGain.mjGAIN_FIXED
        m.actuator_biastype[act] = mujoco.mjtBias.mjBIAS_AFFINE
        m.actuator_gainprm[act, :3] = (p / gear, 0.0, 0.0)
        m.actuator_biasprm[act, :3] = (0.0, -p / gear, -d / gear)
        m.actuator_forcelimited[act] = True
        m.actuator_forcerange[act] = m.actuator_ctrlrange[act]  # the motor's torque limits
        m.actuator_ctrllimited[act] = False
    return m


class NativeRollout:
    """`mujoco.rollout` of the batch with one thread per core and a model per gravity, or per instance
    for per-instance robots (`robots`: {field: (N, ...)}, `variation.draw.with_constants`)."""

    def __init__(self, mj_model, gravity: np.ndarray, qpos0: np.ndarray, ctrl: np.ndarray, threads: int,
                 robots: dict | None = None):
        import mujoco
        from mujoco import rollout

        from hopper_mjx.variation.draw import instance_model

        if robots:  # MuJoCo's rollout takes a sequence of models, one per initial state
            self.models = [instance_model(mj_model, robots, i) for i in range(len(gravity))]
            for m, g in zip(self.models, gravity):
                m.opt.gravity[:] = g
                # A servo's bias reads the joint through the gear (actuator_length = gear q): rescaled, the hold
                # law stays the one a controller computes with the URDF's gear, as on the core's side.
                m.actuator_biasprm[:, 1:3] *= mj_model.actuator_gear[:, :1] / m.actuator_gear[:, :1]
        else:
            models = {}
            for g in map(tuple, gravity):
                if g not in models:
                    models[g] = copy.deepcopy(mj_model)
                    models[g].opt.gravity[:] = g
            self.models = [models[g] for g in map(tuple, gravity)]
        self.datas = [mujoco.MjData(mj_model) for _ in range(threads)]
        d = mujoco.MjData(mj_model)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        states = []
        for q in np.atleast_2d(qpos0):  # one initial state, or one per instance
            d.qpos[:] = q
            states.append(np.empty(mujoco.mj_stateSize(mj_model, spec)))
            mujoco.mj_getState(mj_model, d, states[-1], spec)
        self.initial_state = np.broadcast_to(np.array(states), (len(gravity), states[0].size))
        self.ctrl = np.broadcast_to(np.asarray(ctrl, dtype=float), (len(gravity), mj_model.nu))
        self.threads = threads
        self.pool = rollout.Rollout(nthread=threads if threads > 1 else 0)

    def run(self, steps: int) -> np.ndarray:
        """Steps every instance `steps` times; returns the final qpos (N, nq)."""
        n = len(self.models)
        group = max(1, min(n, NATIVE_BUFFER_STEPS // steps))
        final = []
        for lo in range(0, n, group):
            hi = min(n, lo + group)
            state, _ = self.pool.rollout(
                self.models[lo:hi],
                self.datas,
                initial_state=self.initial_state[lo:hi],
                control=self.ctrl[lo:hi, None],
                nstep=steps,
            )
            final.append(state[:, -1].copy())
        nq = self.models[0].nq
        return np.concatenate(final)[:, 1 : 1 + nq]  # FULLPHYSICS: time, qpos, qvel, ...

    def close(self) -> None:
        self.pool.close()


# -- MJX ------------------------------------------------------------------------


class CompileClock:
    """Seconds JAX spends tracing, lowering and compiling (or loading from the cache)."""

    def __init__(self):
        import jax

        self.seconds = 0.0
        self.cache_hits = 0
        jax.monitoring.register_event_duration_secs_listener(self._on_duration)
        jax.monitoring.register_event_listener(self._on_event)

    def _on_duration(self, event: str, duration: float, **_):
        if event in COMPILE_EVENTS:
            self.seconds += duration

    def _on_event(self, event: str, **_):
        if event == "/jax/compilation_cache/cache_hits":
            self.cache_hits += 1


def controller_pair(name: str, sim, gravity, stance: np.ndarray | None = None):
    """(MJX controller, params, native MjModel, native ctrl (nu,) or (N, nu)) for a --controller value;
    `stance`: (N, nq) each instance's own start (the hold law's targets), None the robot's."""
    from hopper_mjx import control
    from hopper_mjx.control.base import HOLD_GAINS

    layout = sim.layout
    registry.check("controller", dict.fromkeys(CONTROLLERS), name)
    controller, params = control.make(name, sim.robot, len(gravity), motor=sim.actuation.kind)
    if name == "none":
        return controller, params, sim.mj_model, np.zeros(layout.nu)
    # raibert has no C twin: native keeps the (cheaper) hold law, see the module doc.
    joints = sim.robot.stance_joints if stance is None else stance[:, list(layout.joint_qpos)]
    ctrl = np.zeros(np.shape(joints)[:-1] + (layout.nu,))
    ctrl[..., list(layout.actuator_of_joint)] = joints
    return controller, params, native_hold_model(sim.mj_model, layout, **HOLD_GAINS), ctrl


def timed(fn):
    """(wall s, process CPU s, result): CPU time is the work done, whatever the background load."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = fn()
    return time.perf_counter() - wall, time.process_time() - cpu, result


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux reports KiB


def machine(devices) -> dict:
    """What a record was measured on: the devices, the cores and the versions."""
    import jax
    import mujoco

    return {"devices": len(devices), "device_kind": devices[0].platform, "cpu_count": os.cpu_count(),
            "jax": jax.__version__, "mujoco": mujoco.__version__, "python": platform.python_version()}


def run(num: int, steps: int, *, controller: str = "hold", chunk: int = 256, repeat: int = 2,
        threads: int | None = None, physics: Physics = Physics()) -> dict:
    """One side-by-side measurement of `physics` (its robot, engine and timestep); returns the JSON record."""
    import jax

    from hopper_mjx.sim import gravity_vectors
    from hopper_mjx.variation import draw

    if steps < 1 or repeat < 1:
        raise ValueError(f"--steps and --repeat must be >= 1, got {steps} and {repeat}")
    cli.check_engine(physics.engine)
    clock = CompileClock()
    sim = physics.sim(chunk=chunk)
    threads = threads or len(sim.devices)
    gravity = gravity_vectors(bench_gravities(num))
    robots = {} if not physics.variation else draw.with_constants(  # each instance's robot, on both sides
        sim.mj_model, draw.draw(physics.variation, sim.mj_model, num, seed=0))
    stance = draw.stances(sim.mj_model, robots)
    core_controller, params, native_model, native_ctrl = controller_pair(controller, sim, gravity, stance)
    qpos0 = np.asarray(sim.robot.stance_qpos) if stance is None else stance
    state0 = sim.reset(gravity, key=0, controller=core_controller, params=params, qpos=qpos0, variation=robots)
    jax.block_until_ready(state0)

    def run_mjx():
        final, traj = sim.rollout(state0, core_controller, steps=steps)
        jax.block_until_ready((final, traj))
        return final

    first_s = timed(run_mjx)[0]
    compile_s, cache_hits = clock.seconds, clock.cache_hits  # the rollout's, before the kernels are counted
    pool = NativeRollout(native_model, gravity, qpos0, native_ctrl, threads, robots)
    core_runs, native_runs = [], []
    for _ in range(repeat):  # interleaved, so that both sides see the same background load
        wall, cpu, final = timed(run_mjx)
        core_runs.append((wall, cpu))
        wall, cpu, native_qpos = timed(lambda: pool.run(steps))
        native_runs.append((wall, cpu))
    pool.close()
    # The rollout just run, read back from the compile cache: one pass through its loops is a physics step, the
    # controller, the record's branch and the loops' own bookkeeping.
    kernels_per_step = kernels.count(sim.rollout_program(state0, core_controller, steps=steps).compile().as_text())
    total, core_s, native_s = num * steps, [w for w, _ in core_runs], [w for w, _ in native_runs]
    core_rate, native_rate = total / min(core_s), total / min(native_s)
    core_cpu = min(c for _, c in core_runs) / total * 1e6
    native_cpu = min(c for _, c in native_runs) / total * 1e6
    qpos = np.asarray(final.data.qpos)
    record = {
        "num": num,
        "steps": steps,
        "controller": controller,
        "engine": sim.engine.name,
        "urdf": physics.urdf,
        "terrain": str(physics.ground),
        "randomize": str(physics.variation) if physics.variation else None,
        "native_controller": "none" if controller == "none" else "hold",
        "timestep": physics.timestep,
        "core_steps_per_s": core_rate,
        "native_steps_per_s": native_rate,
        "ratio": core_rate / native_rate,
        "compile_s": compile_s,
        "kernels_per_step": kernels_per_step,
        "compile_cache_hits": cache_hits,
        "first_call_s": first_s,
        "core_runs_s": core_s,
        "native_runs_s": native_s,
        "core_cpu_us_per_step": core_cpu,
        "native_cpu_us_per_step": native_cpu,
        "cpu_ratio": native_cpu / core_cpu,
        "peak_rss_mb": peak_rss_mb(),
        "native_threads": threads,
        "chunk": min(chunk, -(-num // len(sim.devices))),
        "diverged": int(np.asarray(final.diverged).sum()),
        "core_final_base_height_m": float(np.median(qpos[:, 2])),
        **machine(sim.devices),
    }
    if controller != "raibert":  # same law on both sides: same trajectories
        record["native_final_base_height_m"] = float(np.median(native_qpos[:, 2]))
        record["max_final_qpos_gap"] = float(np.abs(native_qpos - qpos).max())
    return record


def with_env(record: dict, task: str, physics: Physics, repeat: int, actions: str = "hold") -> dict:
    """`record` and `task`'s training env timed on the same physics, N and T (`perf.env_pace`), beside the core."""
    from hopper_mjx.perf import env_pace

    env = env_pace.run(task, record["num"], record["steps"], physics, repeat, actions)
    return record | env | {"env_to_core": env["env_physics_steps_per_s"] / record["core_steps_per_s"]}


def format_table(record: dict) -> str:
    rows = [
        ("instances x steps", f"{record['num']} x {record['steps']}  (controller {record['controller']})"),
        *([("randomize", record["randomize"])] if record.get("randomize") else []),
        ("core steps/s", f"{record['core_steps_per_s']:,.0f}  engine {record['engine']}, on {record['devices']} "
                         f"{record['device_kind']} device(s)"),
        ("native steps/s",
         f"{record['native_steps_per_s']:,.0f}  mujoco.rollout, {record['native_threads']} thread(s)"),
        ("ratio core / native", f"{record['ratio']:.2f}"),
        ("CPU us per step", f"core {record['core_cpu_us_per_step']:.2f}, "
                            f"native {record['native_cpu_us_per_step']:.2f}  (ratio {record['cpu_ratio']:.2f})"),
        ("compile", f"{record['compile_s']:.1f} s  ({record['compile_cache_hits']} persistent-cache hit(s))"),
        ("kernels per core step", f"{record['kernels_per_step']:,}  (compiled rollout, one pass through its loops)"),
        ("peak RSS", f"{record['peak_rss_mb']:,.0f} MB"),
        ("diverged instances", f"{record['diverged']}"),
    ]
    if "max_final_qpos_gap" in record:
        rows.append(("final qpos, max |core - native|", f"{record['max_final_qpos_gap']:.2e}"))
    if "env_task" in record:
        rows += [(f"env {record['env_task']} physics steps/s",
                  f"{record['env_physics_steps_per_s']:,.0f}  ({record['env_to_core']:.2f} of the core's; train.py's "
                  f"env wrapping, {ENV_ACTIONS[record['env_actions']]})"),
                 (f"env {record['env_task']} env steps/s",
                  f"{record['env_steps_per_s']:,.0f}  (policy steps at {record['env_policy_rate_hz']:g} Hz; "
                  f"first call {record['env_first_call_s']:.1f} s)"),
                 (f"env {record['env_task']} kernels per pass", f"{record['env_kernels_per_pass']:,}  (a physics step, "
                  "and the env's work around a policy step once)")]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


# -- scaling --------------------------------------------------------------------


def scaling(nums: list[int], engines: list[str], steps: int, extra_args: list[str]) -> list[dict]:
    """One fresh process per N and engine, so that each peak RSS and compile time is that run's own;
    the engines alternate at each N, so that both meet the same background load."""
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        for num in nums:
            for engine in engines:
                out = Path(tmp) / f"{num}-{engine}.json"
                cmd = [sys.executable, "-m", "hopper_mjx.perf.bench", "--num", str(num), "--steps", str(steps),
                       "--engine", engine, "--json", str(out), *extra_args]
                subprocess.run(cmd, check=True)
                records.append(json.loads(out.read_text()))
    return records


def markdown_table(records: list[dict]) -> str:
    lines = [
        "| engine | N | core steps/s | native steps/s | ratio | CPU µs/step core / native | CPU ratio | compile s "
        "| peak RSS MB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in records:
        lines.append(
            f"| {r.get('engine', 'mjx')} | {r['num']} "
            f"| {r['core_steps_per_s']:,.0f} | {r['native_steps_per_s']:,.0f} | {r['ratio']:.2f} | "
            f"{r['core_cpu_us_per_step']:.1f} / {r['native_cpu_us_per_step']:.1f} | {r['cpu_ratio']:.2f} | "
            f"{r['compile_s']:.1f} | {r['peak_rss_mb']:,.0f} |"
        )
    return "\n".join(lines)


def scaling_figure(records: list[dict]):
    """The --scaling records' figure (a matplotlib Figure): each side's steps/s and their ratio against N, one
    colour per engine; its subtitle the physics the records ran (no error bars: each point is a best run)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hopper_mjx import terrain
    from hopper_mjx.variation.spec import Spec

    fig, (rate, ratio) = plt.subplots(1, 2, figsize=(10, 4.4))
    for k, engine in enumerate(dict.fromkeys(r.get("engine", "mjx") for r in records)):
        runs = [r for r in records if r.get("engine", "mjx") == engine]
        nums, color = [r["num"] for r in runs], f"C{k}"
        rate.loglog(nums, [r["core_steps_per_s"] for r in runs], "o-", color=color,
                    label=f"core ({engine}), {runs[0]['devices']} devices")
        rate.loglog(nums, [r["native_steps_per_s"] for r in runs], "s--", color=color, alpha=0.6,
                    label=f"native mujoco.rollout, {runs[0]['native_threads']} threads, beside {engine}")
        ratio.semilogx(nums, [r["ratio"] for r in runs], "o-", color=color, label=engine)
    rate.set_xlabel("batch size N (instances)")
    rate.set_ylabel("N × steps / wall time (steps/s)")
    rate.legend(fontsize=8)
    rate.grid(True, which="both", alpha=0.3)
    ratio.axhline(1.0, color="gray", linestyle="--", label="as fast as native")
    ratio.legend()
    ratio.set_xlabel("batch size N (instances)")
    ratio.set_ylabel("core / native steps/s (1)")
    ratio.grid(True, which="both", alpha=0.3)
    first = records[0]
    physics = Physics(urdf=first.get("urdf"), ground=terrain.parse(first.get("terrain", "flat")),
                      variation=Spec.parse(first["randomize"]) if first.get("randomize") else None,
                      model_options={"timestep": first.get("timestep", 1e-3)}).described()  # engines: the legend
    fig.suptitle(f"monoped, {first['steps']} steps per instance, controller {first['controller']}; each point the "
                 f"best of {len(first['core_runs_s'])} timed runs\n{'; '.join(physics.values())}", fontsize=10)
    fig.tight_layout()
    return fig


def plot_scaling(records: list[dict], path: str) -> None:
    import matplotlib.pyplot as plt

    fig = scaling_figure(records)
    atomic_write(path, lambda f: fig.savefig(f, dpi=100, format=Path(path).suffix[1:] or None))
    plt.close(fig)


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python -m hopper_mjx.perf.bench", __doc__)
    p.add_argument("--num", type=int, default=4096, help="instances N")
    p.add_argument("--steps", type=int, default=1000, help="physics steps T per instance (multiple of 20)")
    p.add_argument("--controller", default="hold",
                   help=f"{registry.listed({k: registry.CONTROLLERS[k] for k in CONTROLLERS})}; native runs "
                        "the same hold law as C servos for every one but none")
    p.add_argument("--chunk", type=int, default=256, help=cli.CHUNK_HELP)
    # with --scaling, --engine takes a comma-separated list (e.g. chain,mjx), run side by side
    cli.add_physics_options(p, engine_help="; with --scaling, several (chain,mjx) side by side")
    for flag in ("--motor", "--action-delay", "--push"):  # timed against MuJoCo C, which has no twin of them
        p.refuse(flag, "perf.bench times ideal motors without delay or pushes (native MuJoCo has no twin of them); "
                 f"drop {flag}")
    p.add_argument("--repeat", type=int, default=2, help="timed runs per side; the best counts")
    p.add_argument("--threads", type=int, default=None, help="native threads (default: one per device)")
    p.add_argument("--timestep", type=float, default=1e-3, help="physics step, s")
    p.add_argument("--json", default=None, help="write the record (or the scaling records) here")
    p.add_argument("--scaling", default=None, help="comma-separated N values: one bench process each")
    p.add_argument("--plot", default=None, help="with --scaling: save the scaling plot (PNG) here")
    p.add_argument("--env", default=None, metavar="TASK",
                   help=f"then time this task's training env on the same physics: {registry.listed(registry.TASKS)}")
    p.add_argument("--env-actions", default="hold", choices=tuple(ENV_ACTIONS),
                   help="--env's actions: hold (zero, the stance held) or random (uniform in [-1, 1] each policy "
                        "step, a fixed draw: robots that flail and fall as an untrained policy's do, with the "
                        "auto-resets training makes)")
    return p


def check(args) -> tuple[list[int] | None, Physics]:
    """Every option, before anything is built; returns the --scaling sizes (None without it) and the
    physics (its engine the first of --engine's)."""
    for name in ("num", "steps", "repeat", "chunk") + (("threads",) if args.threads is not None else ()):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name} must be >= 1, got {getattr(args, name)}")
    cli.check_range("--timestep", args.timestep, low=0, high=cli.MAX_TIMESTEP, open_low=True)
    for num in [args.num] + (cli.parse_indices(args.scaling, "--scaling") if args.scaling else []):
        # Both sides hold the batch, and native writes its full state every step (in NATIVE_BUFFER_STEPS slices).
        budget.check_memory("--num" if num == args.num else "--scaling", num, states=2)
    engines = args.engine.split(",")
    if len(engines) > 1 and not args.scaling:
        raise ValueError("--engine: several engines are compared with --scaling only")
    try:
        registry.check("controller", dict.fromkeys(CONTROLLERS), args.controller)
    except ValueError as err:
        raise ValueError(f"--controller: {err}") from None
    if args.json:
        cli.check_writable("--json", args.json, suffixes=(".json",))
    sizes = [args.num] + (cli.parse_indices(args.scaling, "--scaling") if args.scaling else [])
    physics = cli.check_physics(argparse.Namespace(**vars(args) | {"engine": engines[0]}),
                                {"timestep": args.timestep}, engines=engines, n=2 * max(sizes))  # both sides' heights
    cli.refuse_each(physics.ground, "perf.bench")
    if args.env is None and args.env_actions != "hold":
        raise ValueError("--env-actions is --env's: give --env TASK too")
    if args.env is not None:
        try:
            registry.check("task", registry.TASKS, args.env)
        except ValueError as err:
            raise ValueError(f"--env: {err}") from None
        if args.scaling:
            raise ValueError("--env times one N: give it without --scaling")
        if args.num % (os.cpu_count() or 1):  # one device per core (jaxsetup), each a share of the envs, as Brax's
            raise ValueError(f"--num={args.num} must be a multiple of the {os.cpu_count()} devices for --env")
    if args.plot and not args.scaling:
        raise ValueError("--plot draws the --scaling records: give --scaling N1,N2,... too")
    if args.plot:
        cli.check_writable("--plot", args.plot, suffixes=cli.PLOT_SUFFIXES)
    nums = cli.parse_indices(args.scaling, "--scaling") if args.scaling else None
    if nums is not None and (not nums or min(nums) < 1):
        raise ValueError(f"--scaling needs instance counts >= 1, got {args.scaling!r}")
    cli.check_whole_periods("--steps", args.steps, args.timestep)  # last: it imports JAX
    return nums, physics


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        nums, physics = check(args)
        jaxsetup.configure()
        if nums:
            passed = ["--controller", args.controller, "--chunk", str(args.chunk), "--repeat", str(args.repeat),
                      *physics.flags()] + (["--threads", str(args.threads)] if args.threads else [])
            records = scaling(nums, args.engine.split(","), args.steps, passed)
            print(markdown_table(records))
            if args.plot:
                plot_scaling(records, args.plot)
            result = records
        else:
            result = run(args.num, args.steps, controller=args.controller, chunk=args.chunk,
                         repeat=args.repeat, threads=args.threads, physics=physics)
            if args.env is not None:
                result = with_env(result, args.env, physics, args.repeat, args.env_actions)
            print(format_table(result))
    except (ValueError, argparse.ArgumentTypeError) as err:
        return cli.fail(err)
    if args.json:
        atomic_write_text(args.json, json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
