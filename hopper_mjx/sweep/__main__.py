"""python -m hopper_mjx.sweep gravity | gains | compare — hopping across gravity (and a gain).

    python -m hopper_mjx.sweep gravity                          # the main job, ~1000 monopeds
    python -m hopper_mjx.sweep gravity --controller policy:runs/hop-ppo     # a trained policy, same kicks
    python -m hopper_mjx.sweep compare --controllers raibert,policy:runs/hop-ppo   # side by side
    python -m hopper_mjx.sweep gains --param speed_gain --values 0.1,0.3,0.6 --gravity 1.62,3.71,9.81

Rerunning with the same --out resumes an interrupted sweep; finished chunks are not recomputed.
Several processes (hosts) share one sweep with --coordinator HOST:PORT --num-processes P --process-id I.
"""

from __future__ import annotations

import argparse
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

from hopper_mjx import cli, runtime
from hopper_mjx.sweep.grid import DEFAULT_GRAVITY, KICK


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m hopper_mjx.sweep", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="kind", required=True)
    kinds = (("gravity", DEFAULT_GRAVITY, 112, 10.0), ("gains", (1.62, 3.71, 9.81), 32, 10.0),
             ("compare", DEFAULT_GRAVITY, 112, 10.0))
    for kind, gravity, num, duration in kinds:
        s = sub.add_parser(kind, help=f"sweep {kind}" if kind != "compare" else "gravity sweeps of several "
                           "controllers, one table and plot")
        flag = "--gravity" if kind == "gains" else "--values"
        s.add_argument(flag, dest="gravity", type=cli.floats(flag), default=list(gravity),
                       help=f"gravity values in m/s² (default: {','.join(map(str, gravity))})")
        if kind == "gains":
            s.add_argument("--param", required=True, help="Raibert gain to sweep (a RaibertConfig field)")
            s.add_argument("--values", type=cli.floats("--values"), required=True, help="its values")
        if kind == "gravity":
            s.add_argument("--controller", default="raibert", help="raibert or policy:PATH (experiments/train.py)")
        if kind == "compare":
            s.add_argument("--controllers", required=True,
                           help="comma-separated: raibert and/or policy:PATH, each swept with the same kicks")
        s.add_argument("--num", type=int, default=num, help=f"replicates per grid point (default {num})")
        s.add_argument("--duration", type=float, default=duration, help="simulated seconds per instance")
        s.add_argument("--height", type=float, default=0.10, help="commanded apex rise over standing height, m")
        s.add_argument("--speed", type=cli.floats("--speed"), default=[0.0, 0.0], help="VX,VY m/s")
        s.add_argument("--kick", type=float, default=KICK, help="std of the random initial velocity, m/s and rad/s")
        s.add_argument("--seed", type=int, default=0)
        s.add_argument("--chunk", type=int, default=256, help="instances per compiled call")
        s.add_argument("--out", type=Path, default=None, help="output folder (default runs/<kind>-<UTC time>)")
        s.add_argument("--no-progress", action="store_true")
        s.add_argument("--coordinator", default=None, help="HOST:PORT of process 0, for a multi-process sweep")
        s.add_argument("--num-processes", type=int, default=1)
        s.add_argument("--process-id", type=int, default=0)
    return p


def specs(args) -> list:
    """One SweepSpec per controller (a compare sweeps several), every argument checked."""
    from hopper_mjx.sweep.grid import SweepSpec

    names = args.controllers.split(",") if args.kind == "compare" else [getattr(args, "controller", "raibert")]
    out = []
    for name in names:
        cli.check_controller(name, args.height, args.speed)
        out.append(SweepSpec(kind="gains" if args.kind == "gains" else "gravity", gravity=tuple(args.gravity),
                             num=args.num, duration=args.duration, height=args.height, speed=tuple(args.speed),
                             seed=args.seed, kick=args.kick, chunk=args.chunk, param=getattr(args, "param", None),
                             values=tuple(args.values) if args.kind == "gains" else (), controller=name))
    if len(set(names)) != len(names):
        raise ValueError(f"--controllers lists one twice: {args.controllers}")
    return out


def label(controller: str) -> str:
    return "raibert" if controller == "raibert" else "policy-" + Path(controller.removeprefix("policy:")).name


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    runtime.configure()
    from hopper_mjx.sweep import report, runner

    try:
        sweeps = specs(args)
    except ValueError as err:
        return cli.fail(err)
    if args.coordinator:
        import jax

        jax.distributed.initialize(args.coordinator, num_processes=args.num_processes, process_id=args.process_id)
    out = args.out or Path("runs") / f"{args.kind}-{datetime.now(timezone.utc):%Y%m%d-%H%M%S}"
    results = []
    for spec in sweeps:
        folder = out / label(spec.controller) if args.kind == "compare" else out
        start = time.perf_counter()
        try:
            instances, table, facts = runner.run(spec, folder, progress=not args.no_progress)
        except runner.ManifestMismatch as err:
            return cli.fail(err)
        except KeyboardInterrupt:
            print(f"\ninterrupted: finished chunks are saved in {folder}; rerun the same command to resume",
                  file=sys.stderr)
            return 130
        facts["total_wall_s"] = time.perf_counter() - start
        if facts["processes"] > 1 and args.process_id != 0:
            continue
        text = report.write(folder, spec, instances, table, runner.COLUMNS, facts)
        results.append((label(spec.controller), report.group_summary(spec, instances, table, runner.COLUMNS)))
        print(text if args.kind != "compare" else f"{label(spec.controller)}: outputs in {folder}/")
        rate = f", {facts['steps_per_s']:,.0f} steps/s" if facts["steps_per_s"] else " (all chunks were already done)"
        print(f"\n{len(instances)} instances x {spec.duration:g} s in {facts['total_wall_s']:.0f} s{rate}; "
              f"outputs in {folder}/")
    if args.kind == "compare" and results:
        print(report.write_comparison(out, sweeps[0], results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
