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


def _steps(args, quick_steps: int, steps: int) -> int:
    return args.steps if args.steps is not None else (quick_steps if args.quick else steps)


def _report(summary: dict, colour_by: str) -> None:
    """The timing line and the files written (``None`` where not asked for)."""
    print(f"{summary['wall_seconds']:.1f} s, {summary['ms_per_step']:.2f} ms/step")
    if summary["trajectory"]:
        print(f"trajectory: {summary['trajectory']}  (ase gui {summary['trajectory']}; "
              f"View > Colors > By user-defined {colour_by})")
    for key in ("plot", "picture"):
        if summary.get(key):
            print(f"{key}: {summary[key]}")


def _impact(args) -> int:
    from .demos.impact import QUICK_STEPS, STEPS, run_impact

    summary = run_impact(steps=_steps(args, QUICK_STEPS, STEPS), quick=args.quick,
                         trajectory=args.trajectory or None, plot=args.plot or None,
                         every=args.every, progress=not args.no_progress)
    print(f"{summary['atoms']} particles, {summary['bonds']} bonds, "
          f"{summary['broken']} broken after {summary['steps']} steps; "
          f"final kinetic energy {summary['kinetic_energy']:.8g}")
    _report(summary, "damage")
    return 0


def _shatter(args) -> int:
    from .demos.shatter import QUICK_STEPS, STEPS, run_shatter

    summary = run_shatter(steps=_steps(args, QUICK_STEPS, STEPS),
                          trajectory=args.trajectory or None, plot=args.plot or None,
                          picture=args.picture or None, every=args.every,
                          progress=not args.no_progress)
    print(f"{summary['nodes']} nodes, {summary['broken']} bonds broken after "
          f"{summary['steps']} steps; mean damage {summary['mean_damage']:.4f}")
    _report(summary, "damage")
    return 0


def _pour(args) -> int:
    from .demos.pour import QUICK_STEPS, STEPS, run_pour

    summary = run_pour(steps=_steps(args, QUICK_STEPS, STEPS), quick=args.quick,
                       trajectory=args.trajectory or None, plot=args.plot or None,
                       picture=args.picture or None, every=args.every,
                       progress=not args.no_progress)
    print(f"{summary['spheres']} spheres, {summary['contacts']} contacts after "
          f"{summary['steps']} steps; kinetic energy {summary['kinetic_energy']:.4g} "
          f"(peak {summary['peak_kinetic_energy']:.4g}); pile height "
          f"{summary['height']:.3f}")
    _report(summary, "ncontacts")
    return 0


def _add_demo(demos, name: str, run, *, about: str, quick: str, every: int, plot: str,
              picture: str | None = None) -> None:
    """A ``demo <name>`` subcommand with the options every demo shares."""
    demo = demos.add_parser(name, help=about)
    demo.add_argument("--quick", action="store_true", help=quick)
    demo.add_argument("--steps", type=int, help="number of MD steps")
    demo.add_argument("--trajectory", default=f"{name}.extxyz",
                      help="extxyz file for ase gui ('' for none; default %(default)s)")
    demo.add_argument("--every", type=int, default=every,
                      help="write a frame every N steps (default %(default)s)")
    demo.add_argument("--plot", default=f"{name}.png",
                      help=f"PNG of {plot} ('' for none; default %(default)s)")
    if picture:
        demo.add_argument("--picture", default=f"{name}-final.png",
                          help=f"PNG picture of {picture} ('' for none; "
                               "default %(default)s)")
    demo.add_argument("--no-progress", action="store_true", help="no progress bar")
    demo.set_defaults(run=run)


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(prog="ase-bpm", description=(
        "LAMMPS bonded-particle models in ASE: demos and tools."))
    commands = top.add_subparsers(dest="command", required=True)
    demo = commands.add_parser("demo", help="run a demonstration scene")
    demos = demo.add_subparsers(dest="demo", required=True)
    _add_demo(demos, "impact", _impact, about=(
        "LAMMPS examples/bpm/impact: a bonded ball shatters a bonded disk "
        "(11,118 particles, 60k bonds, 7,500 steps)"),
        quick="a small disk and ball (about 900 particles), 1500 steps", every=250,
        plot="kinetic energy and intact bonds")
    _add_demo(demos, "shatter", _shatter, about=(
        "LAMMPS examples/bpm/peri: a spherical indenter shatters a brittle "
        "peridynamic cylinder (3,487 nodes, 168k bonds, 2,000 steps)"),
        quick="the first 400 steps only (the crater forming)", every=100,
        plot="mean damage against time", picture="the fractured cylinder")
    _add_demo(demos, "pour", _pour, about=(
        "granular pour: 3,000 polydisperse frictional spheres fall into a box "
        "and settle (gran/hooke/history, 15,000 steps)"),
        quick="500 spheres in a smaller box, 8000 steps", every=500,
        plot="the kinetic energy decay", picture="the settled pile")
    return top


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
