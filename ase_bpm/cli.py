"""The ``ase-bpm`` command.

    ase-bpm demo impact  [--quick] [--steps N] [--trajectory FILE] [--plot FILE]
    ase-bpm demo shatter [--quick] [--steps N] [--trajectory FILE] [--plot FILE]
                         [--picture FILE]
    ase-bpm demo pour    [--quick] [--steps N] [--trajectory FILE] [--plot FILE]
                         [--picture FILE]
"""

from __future__ import annotations

import argparse
import sys


def _impact(args) -> int:
    from .demos.impact import QUICK_STEPS, STEPS, run_impact

    steps = args.steps if args.steps is not None else (QUICK_STEPS if args.quick else STEPS)
    summary = run_impact(steps=steps, quick=args.quick,
                         trajectory=args.trajectory or None, plot=args.plot or None,
                         every=args.every, progress=not args.no_progress)
    print(f"{summary['atoms']} particles, {summary['bonds']} bonds, "
          f"{summary['broken']} broken after {summary['steps']} steps; "
          f"final kinetic energy {summary['kinetic_energy']:.8g}")
    print(f"{summary['wall_seconds']:.1f} s, {summary['ms_per_step']:.2f} ms/step")
    if summary["trajectory"]:
        print(f"trajectory: {summary['trajectory']}  (ase gui {summary['trajectory']}; "
              "View > Colors > By user-defined damage)")
    if summary["plot"]:
        print(f"plot: {summary['plot']}")
    return 0


def _shatter(args) -> int:
    from .demos.shatter import QUICK_STEPS, STEPS, run_shatter

    steps = args.steps if args.steps is not None else (QUICK_STEPS if args.quick else STEPS)
    summary = run_shatter(steps=steps,
                          trajectory=args.trajectory or None, plot=args.plot or None,
                          picture=args.picture or None, every=args.every,
                          progress=not args.no_progress)
    print(f"{summary['nodes']} nodes, {summary['broken']} bonds broken after "
          f"{summary['steps']} steps; mean damage {summary['mean_damage']:.4f}")
    print(f"{summary['wall_seconds']:.1f} s, {summary['ms_per_step']:.2f} ms/step")
    for key, label in (("trajectory", "trajectory"), ("plot", "plot"), ("picture", "picture")):
        if summary[key]:
            print(f"{label}: {summary[key]}")
    return 0


def _pour(args) -> int:
    from .demos.pour import QUICK_STEPS, STEPS, run_pour

    steps = args.steps if args.steps is not None else (QUICK_STEPS if args.quick else STEPS)
    summary = run_pour(steps=steps, quick=args.quick, trajectory=args.trajectory or None,
                       plot=args.plot or None, picture=args.picture or None,
                       every=args.every, progress=not args.no_progress)
    print(f"{summary['spheres']} spheres, {summary['contacts']} contacts after "
          f"{summary['steps']} steps; kinetic energy {summary['kinetic_energy']:.4g} "
          f"(peak {summary['peak_kinetic_energy']:.4g}); pile height "
          f"{summary['height']:.3f}")
    print(f"{summary['wall_seconds']:.1f} s, {summary['ms_per_step']:.2f} ms/step")
    if summary["trajectory"]:
        print(f"trajectory: {summary['trajectory']}  (ase gui {summary['trajectory']}; "
              "View > Colors > By user-defined ncontacts)")
    for key in ("plot", "picture"):
        if summary[key]:
            print(f"{key}: {summary[key]}")
    return 0


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(prog="ase-bpm", description=(
        "LAMMPS bonded-particle models in ASE: demos and tools."))
    commands = top.add_subparsers(dest="command", required=True)
    demo = commands.add_parser("demo", help="run a demonstration scene")
    demos = demo.add_subparsers(dest="demo", required=True)

    impact = demos.add_parser("impact", help=(
        "LAMMPS examples/bpm/impact: a bonded ball shatters a bonded disk "
        "(11,118 particles, 60k bonds, 7,500 steps)"))
    impact.add_argument("--quick", action="store_true",
                        help="a small disk and ball (about 900 particles), 1500 steps")
    impact.add_argument("--steps", type=int, help="number of MD steps")
    impact.add_argument("--trajectory", default="impact.extxyz",
                        help="extxyz file for ase gui ('' for none; default %(default)s)")
    impact.add_argument("--every", type=int, default=250,
                        help="write a frame every N steps (default %(default)s)")
    impact.add_argument("--plot", default="impact.png",
                        help="PNG of kinetic energy and intact bonds ('' for none; "
                             "default %(default)s)")
    impact.add_argument("--no-progress", action="store_true", help="no progress bar")
    impact.set_defaults(run=_impact)

    shatter = demos.add_parser("shatter", help=(
        "LAMMPS examples/bpm/peri: a spherical indenter shatters a brittle "
        "peridynamic cylinder (3,487 nodes, 168k bonds, 2,000 steps)"))
    shatter.add_argument("--quick", action="store_true",
                         help="the first 400 steps only (the crater forming)")
    shatter.add_argument("--steps", type=int, help="number of MD steps")
    shatter.add_argument("--trajectory", default="shatter.extxyz",
                         help="extxyz file for ase gui ('' for none; default %(default)s)")
    shatter.add_argument("--every", type=int, default=100,
                         help="write a frame every N steps (default %(default)s)")
    shatter.add_argument("--plot", default="shatter.png",
                         help="PNG of mean damage against time ('' for none; "
                              "default %(default)s)")
    shatter.add_argument("--picture", default="shatter-final.png",
                         help="PNG picture of the fractured cylinder ('' for none; "
                              "default %(default)s)")
    shatter.add_argument("--no-progress", action="store_true", help="no progress bar")
    shatter.set_defaults(run=_shatter)

    pour = demos.add_parser("pour", help=(
        "granular pour: 3,000 polydisperse frictional spheres fall into a box "
        "and settle (gran/hooke/history, 15,000 steps)"))
    pour.add_argument("--quick", action="store_true",
                      help="500 spheres in a smaller box, 6000 steps")
    pour.add_argument("--steps", type=int, help="number of MD steps")
    pour.add_argument("--trajectory", default="pour.extxyz",
                      help="extxyz file for ase gui ('' for none; default %(default)s)")
    pour.add_argument("--every", type=int, default=500,
                      help="write a frame every N steps (default %(default)s)")
    pour.add_argument("--plot", default="pour.png",
                      help="PNG of the kinetic energy decay ('' for none; "
                           "default %(default)s)")
    pour.add_argument("--picture", default="pour-final.png",
                      help="PNG picture of the settled pile ('' for none; "
                           "default %(default)s)")
    pour.add_argument("--no-progress", action="store_true", help="no progress bar")
    pour.set_defaults(run=_pour)
    return top


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
