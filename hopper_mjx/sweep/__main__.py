"""python -m hopper_mjx.sweep gravity | gains | param | compare | obstacle | gaps | terrain — hopping across gravity
(and a gain, a parameter, or a terrain).

    python -m hopper_mjx.sweep gravity                          # the main job, ~1000 monopeds
    python -m hopper_mjx.sweep gravity --controller policy:runs/hop-ppo     # a trained policy, same kicks
    python -m hopper_mjx.sweep compare --controllers raibert,policy:runs/hop-ppo   # side by side
    python -m hopper_mjx.sweep gains --param speed_gain --values 0.1,0.3,0.6 --gravity 1.62,3.71,9.81
    python -m hopper_mjx.sweep param --param action_delay --values 0,5,10,20 --gravity 1.62,3.71,9.81
    python -m hopper_mjx.sweep obstacle --heights 0.05,0.1,0.15 --x 0.6 --speed 0.3,0    # the highest block cleared
    python -m hopper_mjx.sweep obstacle --controller jump,raibert --motor dc     # two gaits' highest blocks, one plot
    python -m hopper_mjx.sweep gaps --widths 0.1,0.2,0.4 --motor dc              # the widest gap, beside the bound
    python -m hopper_mjx.sweep terrain --amps 0,0.01,0.02,0.03                   # survival and speed vs roughness

Rerunning with the same --out resumes an interrupted sweep; finished chunks are not recomputed.
Several processes (hosts) share one sweep with --coordinator HOST:PORT --num-processes P --process-id I.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

from hopper_mjx import cli, registry
from hopper_mjx.shell import budget, jaxsetup, process
from hopper_mjx.shell.checks import DEFAULT_TIMESTEP, OutputError
from hopper_mjx.sweep import folder
from hopper_mjx.sweep.grid import BAND_KINDS, DEFAULT_GRAVITY, KICK, TERRAIN_KINDS, sample_steps

PARAM = {"obstacle": "obstacle_height", "gaps": "gap_width", "terrain": "roughness"}  # a terrain sweep's value column
VALUES = {"gains": "--values", "param": "--values", "obstacle": "--heights", "gaps": "--widths",
          "terrain": "--amps"}  # the swept values
TRAINED_PARTS = ("all", "timestep", "solver")  # what --as-trained takes of a policy's training physics
LANDING = 0.5  # m of ground a gaps sweep keeps beyond its gap to land on, before the ground's end


def swept_values(args) -> list[float]:
    """The values a sweep's second axis takes (its option in VALUES), or [] for a gravity sweep."""
    flag = VALUES.get(args.kind)
    return list(getattr(args, flag[2:])) if flag else []


def _swept_options(s: argparse.ArgumentParser, kind: str) -> None:
    """The options of a sweep's second axis: a gain's or parameter's values, a terrain's."""
    if kind == "gains":
        s.add_argument("--param", required=True, help="Raibert gain to sweep (a RaibertConfig field)")
        s.add_argument("--values", type=cli.floats("--values"), required=True, help="its values")
    if kind == "param":
        s.add_argument("--param", required=True,
                       help="a Raibert gain (RaibertConfig field) or a --randomize parameter: "
                            f"{', '.join(registry.PARAMETERS)}, {', '.join(registry.CONTROL_PARAMETERS)}")
        s.add_argument("--values", type=cli.floats("--values"), required=True,
                       help="its values, in the parameter's unit (docs/variation.md); every instance of a "
                            "value gets it")
    if kind == "obstacle":
        s.add_argument("--heights", type=cli.floats("--heights"), default=[0.05, 0.1, 0.15, 0.2],
                       help="block heights, m (default 0.05,0.1,0.15,0.2)")
        s.add_argument("--x", type=float, default=0.6, help="the block's near edge, m ahead of the start")
        s.add_argument("--length", type=float, default=0.1, help="the block's length along +x, m")
    if kind == "gaps":
        s.add_argument("--widths", type=cli.floats("--widths"), default=[0.1, 0.2, 0.3, 0.4],
                       help="gap widths along +x, m (default 0.1,0.2,0.3,0.4)")
        s.add_argument("--x", type=float, default=0.6, help="the gap's near edge, m ahead of the start")
        s.add_argument("--depth", type=float, default=1.0,
                       help="the gap's depth, m (default 1: deeper than the leg reaches, so a foot in it falls)")
    if kind == "terrain":
        s.add_argument("--amps", type=cli.floats("--amps"), default=[0.0, 0.01, 0.02, 0.03],
                       help="rough ground's peak |height|, m (default 0,0.01,0.02,0.03)")
        s.add_argument("--wavelength", type=float, default=0.4, help="rough ground's wavelength, m")


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python -m hopper_mjx.sweep", __doc__)
    sub = p.add_subparsers(dest="kind", required=True)
    kinds = (("gravity", DEFAULT_GRAVITY, 112, 10.0), ("gains", (1.62, 3.71, 9.81), 32, 10.0),
             ("param", (1.62, 3.71, 9.81), 32, 10.0), ("compare", DEFAULT_GRAVITY, 112, 10.0),
             ("obstacle", (1.62, 3.71, 9.81), 32, 10.0), ("gaps", (1.62, 3.71, 9.81), 32, 10.0),
             ("terrain", (1.62, 3.71, 9.81), 32, 10.0))
    helps = {"compare": "gravity sweeps of several controllers, one table and plot",
             "param": "any Raibert gain or --randomize parameter (model field or not) against gravity",
             "obstacle": "the highest block cleared: obstacle height x gravity at an approach --speed",
             "gaps": "the widest gap crossed: gap width x gravity at an approach --speed",
             "terrain": "survival and speed tracking: rough ground's amplitude x gravity, each replicate its own draw"}
    for kind, gravity, num, duration in kinds:
        s = sub.add_parser(kind, help=helps.get(kind, f"sweep {kind}"))
        # --gravity, as in every command; a gravity or compare sweep took its gravities as --values before, and
        # still does (gains and param sweeps' --values are the swept parameter's).
        names = ("--gravity", "--values") if kind in ("gravity", "compare") else ("--gravity",)
        s.add_argument(*names, dest="gravity", type=cli.floats("--gravity"), default=None, metavar="G,...",
                       help=f"gravity values in m/s² (default: {','.join(map(str, gravity))})"
                            + ("; --values is the same option, its older name" if len(names) > 1 else ""))
        s.add_argument("--world", type=Path, nargs="+", default=None, metavar="FILE.world",
                       help="Gazebo world files instead of --gravity: their (vertical, non-zero) gravity")
        s.set_defaults(default_gravity=list(gravity))
        _swept_options(s, kind)
        if kind in TERRAIN_KINDS:
            s.add_argument("--size", default=None, help="the ground's extents LxW, m (default: 4 m wide, and long "
                           "enough for --speed over --duration and back: the ground ends at its edge)")
        if kind in ("gravity", "param"):
            s.add_argument("--controller", default="raibert",
                           help="raibert (the tasks' reference), jump (Raibert's gait leaping what is ahead), "
                                "balance (an LQR stance) or policy:PATH")
        if kind in BAND_KINDS:
            s.add_argument("--controller", default=registry.TERRAIN_SWEEP_CONTROLLERS[0],
                           help="jump (each hop sized to the ground ahead, the leg drawn up over it; default), "
                                "raibert (hops to --height above the ground it lands on) or policy:PATH (a policy "
                                "trained by experiments/train.py, hop_terrain's reading its height scan); "
                                "comma-separated, several side by side on the same grounds and kicks (a folder "
                                "each in --out, and one table and plot)")
        if kind == "compare":
            s.add_argument("--controllers", required=True,
                           help="comma-separated: raibert, jump, balance and/or policy:PATH, each swept with the "
                           "same kicks")
        if kind in ("gravity", "compare"):
            s.add_argument("--as-trained", nargs="?", const="all", choices=TRAINED_PARTS,
                           help="policies only: run on the physics they were trained on (their config's timestep "
                                "and solver caps) instead of the core's, to measure what changes between the two; "
                                "=timestep or =solver takes that part alone (the other stays the core's)")
        s.add_argument("--num", type=int, default=num, help=f"replicates per grid point (default {num})")
        s.add_argument("--duration", type=float, default=duration,
                       help="simulated seconds per instance, whole 10 ms samples (a note says when it rounds)")
        s.add_argument("--height", type=float, default=0.10,
                       help="commanded apex rise over standing height, m; above the motors' bound (gravity sweeps), "
                       "the table and plot give each gravity's highest hop beside it")
        s.add_argument("--speed", type=cli.floats("--speed"), default=[0.3 if kind in BAND_KINDS else 0.0, 0.0],
                       help="VX,VY m/s" + (" (default 0.3,0: the approach)" if kind in BAND_KINDS else ""))
        s.add_argument("--kick", type=float, default=KICK, help="std of the random initial velocity, m/s and rad/s")
        s.add_argument("--seed", type=int, default=0)
        s.add_argument("--chunk", type=int, default=256, help=cli.CHUNK_HELP)
        cli.add_physics_options(s)
        if kind in TERRAIN_KINDS:
            s.refuse("--terrain", f"{'an' if kind == 'obstacle' else 'a'} {kind} sweep makes its own ground per value "
                     f"({VALUES[kind]}); drop --terrain")
        elif kind in ("gains", "param"):
            s.refuse("--terrain", f"a {kind} sweep runs on the flat ground only, for now; a gravity, obstacle or "
                     "terrain sweep takes terrain")
        s.add_argument("--out", type=Path, default=None, help="output folder (default runs/<kind>-<UTC time>)")
        s.add_argument("--no-progress", action="store_true")
        s.add_argument("--coordinator", default=None, help="HOST:PORT of process 0, for a multi-process sweep")
        s.add_argument("--num-processes", type=int, default=1)
        s.add_argument("--process-id", type=int, default=0)
    return p


def gravity_from_worlds(args) -> tuple[float, ...]:
    """The grid's gravity magnitudes from --world: each world's gravity must point straight down and be
    non-zero, and the worlds must leave the physics at the sweep's (the default timestep and friction)."""
    from hopper_mjx.model import loader

    worlds = cli.read_worlds(args.world, "--gravity" if args.gravity is not None else None)
    default = {"timestep": loader.DEFAULT_TIMESTEP, "friction": (loader.FOOT_FRICTION, loader.FOOT_FRICTION)}
    changed = [key for key, value in worlds.model_options(loader.FOOT_FRICTION).items() if value != default[key]]
    if changed:
        raise ValueError(f"--world sets another {' and '.join(changed)} than a sweep runs with "
                         "(0.001 s, friction 1): simulate and record take it")
    if worlds.terrain is not None:
        raise ValueError(f"--world: its <heightmap> ground is read by simulate, render and record; a sweep takes "
                         f"its ground from --terrain ({worlds.terrain})")
    for w, (gx, gy, gz) in zip(worlds.worlds, worlds.gravity):
        if gx or gy or not gz < 0:
            raise ValueError(f"--world {w.source}: gravity {w.gravity} is not a downward pull; a sweep needs one "
                             "to hop and groups instances by its size (simulate, record and render take any)")
    if worlds.warning():
        print(worlds.warning(), file=sys.stderr)
    return tuple(float(-gz) for gz in worlds.gravity[:, 2])


def check(args):
    """One SweepSpec per controller (a compare sweeps several), and the output folder; raises
    ValueError before anything is built."""
    from hopper_mjx.sweep.grid import SweepSpec

    gravity = gravity_from_worlds(args) if args.world is not None else tuple(args.gravity or args.default_gravity)
    grounds = terrain_grounds(args)
    if grounds:  # the model compiles the first; every grid point's ground is checked as --terrain is
        n = min(args.chunk, args.num * len(gravity) * len(grounds))
        grounds = [str(cli.check_ground(g, n=n)) for g in grounds]  # as the manifest keeps them
        args.terrain = grounds[0]
    physics = cli.check_physics(args, n=args.num, seed=args.seed)  # one robot per replicate, drawn now
    names = controller_names(args)
    if getattr(args, "as_trained", None):
        physics = as_trained(physics, names, args.as_trained)
    if not grounds:  # every instance on the one ground --terrain gives (the parser refuses it where it cannot)
        cli.refuse_each(physics.ground, f"a {args.kind} sweep")
    cli.check_delay(physics, args.duration, args.num, args.seed)
    check_standing("--gravity", gravity, physics.mj_model)
    if args.kind in BAND_KINDS:  # its report holds each result against the motors' bound: one they must have
        from hopper_mjx.hardware.bound import knee_motor

        knee_motor(physics.mj_model, physics.motor)
        if args.kind == "obstacle":
            check_blocks(physics, gravity, swept_values(args))
    if len(set(names)) != len(names):
        raise ValueError(f"{controller_flag(args)} lists one twice: {','.join(names)}")
    chunk = check_size(args, len(gravity))
    duration = SweepSpec.whole_duration(args.duration, physics.timestep)
    specs = []
    for name in names:
        kind = args.kind if args.kind != "compare" else "gravity"
        spec = SweepSpec(kind=kind, gravity=gravity, num=args.num, duration=duration, height=args.height,
                         speed=tuple(args.speed), seed=args.seed, kick=args.kick, chunk=chunk, physics=physics,
                         param=PARAM.get(kind, getattr(args, "param", None)), controller=name,
                         values=tuple(swept_values(args)),
                         grounds=tuple(grounds))
        check_robots(spec, args.duration)
        specs.append(spec)
        # a policy: its folder, its range
        cli.check_controller(name, args.height, args.speed, physics, controller_flag(args))
    out = args.out or Path("runs") / f"{args.kind}-{datetime.now(timezone.utc):%Y%m%d-%H%M%S}"
    cli.check_writable("--out", out, folder=True, make_parents=True)
    if several(args) and out.exists() and not any(out.glob(f"*/{folder.MANIFEST}")):
        raise ValueError(f"--out {out} exists and is not a comparison's folder; a sweep writes only into a "
                         "folder it made: use another --out")
    for spec in specs:  # a folder of another sweep, or of no sweep, is refused before anything is built
        folder.check(folder_of(args, out, spec), spec)
    if args.num_processes < 1 or not 0 <= args.process_id < args.num_processes:
        raise ValueError(f"--process-id must be in 0..--num-processes-1 (>= 1 process), "
                         f"got {args.process_id} of {args.num_processes}")
    if args.coordinator is not None and not _host_port(args.coordinator):
        raise ValueError(f"--coordinator must be HOST:PORT, got {args.coordinator!r}")
    return specs, out


def as_trained(physics, controllers: list[str], part: str = "all"):
    """`physics` on the timestep and solver caps the policies among `controllers` were trained on (their
    configs'; `envs.task_config.training_model`), which every one of them must share; `part` (TRAINED_PARTS):
    both, or the timestep or the solver caps alone."""
    from hopper_mjx.envs import policy

    others = [c for c in controllers if not c.startswith(registry.POLICY_PREFIX)]
    if others:
        raise ValueError(f"--as-trained runs policies on their training physics; {', '.join(others)} is not a "
                         f"{registry.POLICY_PREFIX}PATH")
    found = set()
    for name in controllers:
        config = policy.read(registry.policy_path(name))[3]  # JSON only
        found.add((config.timestep, config.solver_iterations, config.ls_iterations))
    if len(found) > 1:
        raise ValueError(f"--as-trained: the policies were trained on different physics {sorted(found)}; "
                         "sweep them apart")
    timestep, iterations, ls_iterations = found.pop()
    step = {"timestep": timestep} if part in ("all", "timestep") else {}
    solver = {"iterations": iterations, "ls_iterations": ls_iterations} if part in ("all", "solver") else {}
    options = {**physics.model_options, **step, **solver}
    return dataclasses.replace(physics, model_options=options)


def check_blocks(physics, gravity, heights) -> None:
    """No block above the tallest the motors' energy bound lets the robot pass over at the grid's lowest gravity
    (`hardware.bound`): no robot could clear it, so its cells would cost their compute and measure nothing."""
    from hopper_mjx.hardware import bound
    from hopper_mjx.model.robot import standing_height

    m, g = physics.mj_model, min(gravity)
    top = bound.highest_block(bound.bounds(m, physics.motor, [g])[g], standing_height(m), bound.tucked_drop(m))
    if max(heights) > top:
        raise ValueError(f"--heights {max(heights):g}: taller than any block the {physics.motor} motors can lift the "
                         f"robot over at g={g:g} m/s² ({top:.2f} m, their energy bound: docs/sweeps.md)")


def check_robots(spec, duration: float) -> None:
    """A swept parameter's robots: an engine that takes it, each value within the parameter's range (drawn
    now, no JAX), delays shorter than the run, a controller and motors it applies to."""
    if not spec.sweeps_robot:
        cli.check_controls(spec.physics, spec.controller)
        return
    from hopper_mjx.variation import draw
    from hopper_mjx.variation.spec import check_engine_varies

    physics = spec.robot_physics
    try:
        check_engine_varies(physics.engine, physics.variation.fields)
    except ValueError as err:
        raise ValueError(f"--param {spec.param}: {err}; use --engine mjx or auto") from None
    cli.check_controls(physics, spec.controller)
    for value, robots in zip(spec.values, spec.robot_specs()):
        try:
            fields = draw.draw(robots, physics.mj_model, spec.num, spec.seed)
            drawn = draw.draw_controls(robots, physics.mj_model, spec.num, spec.seed)
        except ValueError as err:
            raise ValueError(f"--values: {err}") from None
        if fields:  # a robot of other masses or legs: replicate 0's must stand at every gravity of the sweep
            check_standing(f"--values {spec.param}={value:g}:", spec.gravity,
                           draw.instance_model(physics.mj_model, fields, 0))
        for name in ("action_delay", "sensor_delay"):
            if name in drawn and drawn[name].max() * 1e-3 >= duration:
                raise ValueError(f"--values: {name} {drawn[name].max():g} ms is not shorter than the run's "
                                 f"--duration {duration:g} s")


def check_standing(flag: str, gravity, mj_model) -> None:
    """Every gravity of the grid one under which the robot's motors can hold it standing (`max_standing_gravity`):
    beyond it every instance only falls, and the sweep would measure nothing."""
    from hopper_mjx.model.layout import Layout
    from hopper_mjx.model.loader import JOINTS
    from hopper_mjx.model.robot import max_standing_gravity

    top, k = max_standing_gravity(mj_model)
    over = [g for g in gravity if g > top]
    if over:
        effort = Layout.of(mj_model).effort_limit[k]
        raise ValueError(f"{flag} {max(over):g} m/s²: the robot cannot stand there; its {JOINTS[k]} motor "
                         f"({effort:g} N·m) holds the standing pose up to {top:.3g} m/s²")


# Values a swept instance records per simulated second at the sweep's rates (contact and state at 1 kHz,
# IMU and odometry at 100 Hz: runner.recorded), and keeps per instance (its row of metrics, its kick).
RECORDED_PER_S = 1000 * (19 + 7) + 100 * (10 + 13)
KEPT = 64


def check_size(args, gravities: int) -> int:
    """The chunk the sweep runs (no larger than the grid); refuses a grid, a chunk or a duration that
    cannot run here, before the grid is even expanded."""
    if args.num < 1 or args.chunk < 1:
        return args.chunk  # SweepSpec names the bad one
    n = gravities * args.num * max(1, len(swept_values(args)))
    budget.check_steps("--duration", args.duration, DEFAULT_TIMESTEP)
    budget.check_memory("--num", n, KEPT)
    chunk = min(args.chunk, n)  # a chunk is padded to its size: never beyond the grid
    budget.check_memory("--chunk, --duration", chunk, RECORDED_PER_S * args.duration)
    return chunk


def terrain_grounds(args) -> list[str]:
    """A terrain sweep's (obstacle, gaps, terrain) --terrain spec per value (checked with the rest), else []."""
    if args.kind not in TERRAIN_KINDS:
        return []
    values = swept_values(args)
    if not values or len(set(values)) != len(values):
        raise ValueError(f"{VALUES[args.kind]} must be one or more different values")
    cli.check_range("--duration", args.duration, low=0, open_low=True)
    reach = math.hypot(*args.speed) * args.duration + 1.0  # m the robot may travel, and a margin
    size = args.size or f"{max(4.0, 2 * math.ceil(reach * 2) / 2):g}x4"
    if args.kind == "obstacle":
        cli.check_range("--length", args.length, low=0, open_low=True)
        cli.check_range("--x", args.x)
        return [f"obstacle:height={h!r},x={args.x!r},length={args.length!r},size={size}" for h in values]
    if args.kind == "gaps":
        cli.check_range("--depth", args.depth, low=0, open_low=True)
        cli.check_range("--x", args.x)
        try:
            length = float(size.split("x")[0])
        except ValueError:
            raise ValueError(f"--size must be LxW in m, e.g. 8x4, got {size!r}") from None
        room = length / 2 - LANDING - args.x  # the widest gap that leaves ground to land on beyond it
        wide = [w for w in values if w > room]
        if wide or min(values) <= 0:
            bad = max(wide) if wide else min(values)
            raise ValueError(f"--widths {bad:g}: a gap must be > 0 m and end {LANDING:g} m before the ground's end "
                             f"({length / 2:g} m ahead with --x {args.x:g}): at most {max(room, 0):.3g} m here; "
                             "give a longer --size or narrower gaps")
        # One gap: the next would start a whole ground length further on, beyond the ground's end.
        return [f"gaps:width={w!r},spacing={length:g},depth={args.depth!r},x={args.x!r},size={size}" for w in values]
    cli.check_range("--wavelength", args.wavelength, low=0, open_low=True)
    return [f"rough:amp={a!r},wavelength={args.wavelength!r},seed=each,size={size}" for a in values]


def controller_names(args) -> list[str]:
    """The controllers a sweep runs: a compare's --controllers, or a sweep's --controller (a block or gaps sweep's may
    list several)."""
    if args.kind == "compare":
        return args.controllers.split(",")
    text = getattr(args, "controller", "raibert")
    return text.split(",") if args.kind in BAND_KINDS else [text]


def controller_flag(args) -> str:
    return "--controllers" if args.kind == "compare" else "--controller"


def several(args) -> bool:
    """Does this sweep run several controllers side by side: a folder each in --out, and a comparison."""
    return len(controller_names(args)) > 1 or args.kind == "compare"


def folder_of(args, out: Path, spec) -> Path:
    return out / label(spec.controller) if several(args) else out


def _host_port(text: str) -> bool:
    host, _, port = text.rpartition(":")
    return bool(host) and port.isdigit() and 0 < int(port) < 65536


def label(controller: str) -> str:
    if controller in registry.SWEEP_CONTROLLERS:
        return controller
    return "policy-" + Path(registry.policy_path(controller)).name


def run_one(args, spec, out: Path):
    """Runs one controller's sweep into `out` and prints its report: (label, group summary), or None
    on a process other than 0."""
    from hopper_mjx.sweep import report, runner

    start = time.perf_counter()
    folder.claim(out, spec)
    process.on_stop(f"finished chunks are saved in {out}; rerun the same command to resume")
    with folder.hold(out, args.process_id):  # a second live run of this folder refuses: never mixed rows
        instances, table, facts = runner.run(spec, out, progress=not args.no_progress)
        facts["total_wall_s"] = time.perf_counter() - start
        if facts["processes"] > 1 and args.process_id != 0:
            return None
        text, notes = report.write(out, spec, instances, table, runner.columns(spec), facts)
    print(f"{label(spec.controller)}: outputs in {out}/" if several(args) else text)
    for line in notes:  # why robots fell, or a figure that means less than it seems
        print(line)
    rate = f", {facts['steps_per_s']:,.0f} steps/s" if facts["steps_per_s"] else " (all chunks were already done)"
    print(f"\n{cli.counted(len(instances), 'instance')} x {spec.duration:g} s in {facts['total_wall_s']:.0f} s{rate}; "
          f"outputs in {out}/")
    return label(spec.controller), report.group_summary(spec, instances, table, runner.columns(spec))


def ramp_notes(specs) -> list[str | None]:
    """`control.ramp_note` for the gaits the sweep runs that need longer than a run to reach --speed: one line for
    those run on the same command, which ramp alike."""
    from hopper_mjx import control

    alike: dict = {}
    for s in specs:
        names = alike.setdefault((tuple(s.speed), s.height, tuple(s.gravity), s.duration), [])
        if s.controller not in names:
            names.append(s.controller)
    return [control.ramp_note(names, *command) for command, names in alike.items()]


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        specs, out = check(args)
    except ValueError as err:
        return cli.fail(err)
    timestep = specs[0].physics.timestep
    cli.say(budget.duration_note(args.duration, timestep, sample_steps(timestep)),  # whole samples of its streams
            *ramp_notes(specs))
    jaxsetup.configure()
    from hopper_mjx.sweep import report
    if args.coordinator:
        import jax

        jax.distributed.initialize(args.coordinator, num_processes=args.num_processes, process_id=args.process_id)
    results = []
    try:
        for spec in specs:
            result = run_one(args, spec, folder_of(args, out, spec))
            results += [result] if result else []
    except OutputError as err:  # the folder refused after the checks passed (a pseudo-filesystem), or in use
        return cli.fail(err)
    if several(args) and results:
        print(report.write_comparison(out, specs[0], results))
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
