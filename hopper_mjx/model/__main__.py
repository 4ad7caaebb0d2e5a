"""python -m hopper_mjx.model --export monoped.xml [--urdf PATH] [--timestep S]
python -m hopper_mjx.model --export-urdf monoped_display.urdf [--urdf PATH] [--frame-prefix monoped_0/]   (- for stdout)

--export writes the simulated model as MJCF; --export-urdf writes the URDF the simulation loads,
with colours and resolvable mesh paths, for a viewer such as Foxglove's 3D panel."""

import sys

from hopper_mjx import checks, command
from hopper_mjx.files import atomic_write_text
from hopper_mjx.model.checks import check_urdf


def export_urdf(args) -> int:
    from hopper_mjx.model.display_urdf import display_urdf

    text = display_urdf(args.urdf, args.frame_prefix)
    if args.export_urdf == "-":
        sys.stdout.write(text)
    else:
        atomic_write_text(args.export_urdf, text)
        print(f"wrote {args.export_urdf}: the URDF of {args.urdf or 'the seed monoped'} for display")
    return 0


def main(argv=None) -> int:
    parser = checks.parser("python -m hopper_mjx.model", __doc__)
    out = parser.add_mutually_exclusive_group(required=True)
    out.add_argument("--export", metavar="FILE.xml", help="where to write the MJCF")
    out.add_argument("--export-urdf", metavar="FILE.urdf", help="where to write the URDF for display (- for stdout)")
    parser.add_argument("--urdf", default=None, help="monoped URDF (default: the shipped seed monoped)")
    parser.add_argument("--frame-prefix", default="", metavar="PREFIX",
                        help="with --export-urdf: prefix every link name (monoped_0/: a robot of a multi-robot stream)")
    parser.add_argument("--timestep", type=float, default=checks.DEFAULT_TIMESTEP, help="physics step, s")
    args = parser.parse_args(argv)
    try:
        if args.export_urdf is not None:
            if args.export_urdf != "-":
                checks.check_writable("--export-urdf", args.export_urdf)
            check_urdf(args.urdf)
            return export_urdf(args)
        checks.check_writable("--export", args.export)
        checks.check_range("--timestep", args.timestep, low=0, high=checks.MAX_TIMESTEP, open_low=True)
        check_urdf(args.urdf)
        from hopper_mjx.model.loader import build_spec

        spec = build_spec(args.urdf, timestep=args.timestep)
        model = spec.compile()
    except ValueError as err:  # includes URDFError
        return checks.fail(err)
    atomic_write_text(args.export, spec.to_xml())
    print(f"wrote {args.export}: {model.nbody - 1} bodies, {model.njnt} joints, "
          f"{model.nu} motors, {model.nsensor} sensors, mass {model.body_mass.sum():.3f} kg")
    return 0


if __name__ == "__main__":
    sys.exit(command.run(main))
