"""python -m hopper_mjx.model --export monoped.xml [--urdf PATH] [--timestep S]"""

import argparse
import sys

from hopper_mjx.model.loader import DEFAULT_TIMESTEP, URDFError, build_spec


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hopper_mjx.model", description=__doc__)
    parser.add_argument("--export", required=True, metavar="FILE.xml", help="where to write the MJCF")
    parser.add_argument("--urdf", default=None, help="monoped URDF (default: the shipped seed monoped)")
    parser.add_argument("--timestep", type=float, default=DEFAULT_TIMESTEP, help="physics step, s")
    args = parser.parse_args(argv)
    try:
        spec = build_spec(args.urdf, timestep=args.timestep)
        model = spec.compile()
    except (URDFError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    with open(args.export, "w") as f:
        f.write(spec.to_xml())
    print(f"wrote {args.export}: {model.nbody - 1} bodies, {model.njnt} joints, "
          f"{model.nu} motors, {model.nsensor} sensors, mass {model.body_mass.sum():.3f} kg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
