"""python -m hopper_mjx.model --export monoped.xml [--urdf PATH] [--timestep S] [--terrain SPEC]
python -m hopper_mjx.model --export-urdf monoped_display.urdf [--urdf PATH] [--frame-prefix monoped_0/]   (- for stdout)
python -m hopper_mjx.model --map ground.png --terrain SPEC

--export writes the simulated model as MJCF (on a terrain, its height field's data beside it in
FILE_terrain.bin, MuJoCo's binary hfield format, which MuJoCo reads back exactly); --export-urdf writes
the URDF the simulation loads, with colours and resolvable mesh paths, for a viewer such as Foxglove's 3D panel;
--map draws the --terrain's heights from above (a course's tiles labelled by kind and level)."""

import sys

from hopper_mjx.model.urdf_checks import check_urdf
from hopper_mjx.shell import checks, process
from hopper_mjx.shell.files import atomic_write_text
from hopper_mjx.terrain.spec import check_terrain, refuse_each, terrain_help


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
    out.add_argument("--map", metavar="FILE.png", help="where to draw the --terrain's plan view (its heights in m)")
    parser.add_argument("--urdf", default=None, help="monoped URDF (default: the shipped seed monoped)")
    parser.add_argument("--frame-prefix", default="", metavar="PREFIX",
                        help="with --export-urdf: prefix every link name (monoped_0/: a robot of a multi-robot stream)")
    parser.add_argument("--timestep", type=float, default=checks.DEFAULT_TIMESTEP, help="physics step, s")
    parser.add_argument("--terrain", default="flat", metavar="SPEC", help=terrain_help())
    args = parser.parse_args(argv)
    try:
        if args.export_urdf is not None:
            if args.terrain != "flat":
                raise ValueError("--terrain goes with --export; a URDF holds the robot, not the ground")
            if args.export_urdf != "-":
                checks.check_writable("--export-urdf", args.export_urdf, suffixes=(".urdf",))
            check_urdf(args.urdf)
            return export_urdf(args)
        if args.map is not None:
            checks.check_writable("--map", args.map, suffixes=(".png",))
            ground = check_terrain(args.terrain)
            refuse_each(ground, "model --map")
            if ground.is_flat:
                raise ValueError("--map draws a --terrain's heights; the flat plane has none: give --terrain")
            from hopper_mjx.terrain.plan import save_map

            save_map(ground, args.map)
            print(f"wrote {args.map}: the plan view of {ground}")
            return 0
        checks.check_writable("--export", args.export, suffixes=(".xml",))
        checks.check_range("--timestep", args.timestep, low=0, high=checks.MAX_TIMESTEP, open_low=True)
        ground = check_terrain(args.terrain)
        refuse_each(ground, "model --export")
        check_urdf(args.urdf)
        from hopper_mjx.model.loader import build_spec
        from hopper_mjx.terrain import write_mjcf

        spec = build_spec(args.urdf, timestep=args.timestep, terrain=ground.terrain())
        model = spec.compile()
    except ValueError as err:  # includes URDFError and TerrainError
        return checks.fail(err)
    written = write_mjcf(spec, args.export)
    print(f"wrote {', '.join(written)}: {model.nbody - 1} bodies, {model.njnt} joints, "
          f"{model.nu} motors, {model.nsensor} sensors, mass {model.body_mass.sum():.3f} kg, ground {ground}")
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
