"""python -m hopper_mjx.model --export monoped.xml [--urdf PATH] [--timestep S]"""

import sys

from hopper_mjx import cli


def main(argv=None) -> int:
    parser = cli.parser("python -m hopper_mjx.model", __doc__)
    parser.add_argument("--export", required=True, metavar="FILE.xml", help="where to write the MJCF")
    parser.add_argument("--urdf", default=None, help="monoped URDF (default: the shipped seed monoped)")
    parser.add_argument("--timestep", type=float, default=cli.DEFAULT_TIMESTEP, help="physics step, s")
    args = parser.parse_args(argv)
    try:
        cli.check_writable("--export", args.export)
        cli.check_range("--timestep", args.timestep, low=0, high=cli.MAX_TIMESTEP, open_low=True)
        cli.check_urdf(args.urdf)
        from hopper_mjx.model.loader import build_spec

        spec = build_spec(args.urdf, timestep=args.timestep)
        model = spec.compile()
    except ValueError as err:  # includes URDFError
        return cli.fail(err)
    with open(args.export, "w") as f:
        f.write(spec.to_xml())
    print(f"wrote {args.export}: {model.nbody - 1} bodies, {model.njnt} joints, "
          f"{model.nu} motors, {model.nsensor} sensors, mass {model.body_mass.sum():.3f} kg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
