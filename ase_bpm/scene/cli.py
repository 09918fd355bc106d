"""The ``ase-bpm`` command.

    ase-bpm --version
    ase-bpm demo impact  [--bonds {spring,rotational}] [--quick] [--steps N]
                         [--trajectory FILE] [--every N] [--plot FILE]
                         [--picture FILE] [--no-progress]
    ase-bpm demo shatter [--quick] [--steps N] [--trajectory FILE] [--every N]
                         [--plot FILE] [--picture FILE] [--no-progress]
    ase-bpm demo pour    [--quick] [--steps N] [--trajectory FILE] [--every N]
                         [--plot FILE] [--picture FILE] [--no-progress]
    ase-bpm demo beam    [--quick] [--steps N] [--trajectory FILE] [--every N]
                         [--plot FILE] [--picture FILE] [--no-progress]
    ase-bpm export {impact,shatter,pour} [--bonds {spring,rotational}] [--quick]
                                         [--steps N] [--output STEM]
    ase-bpm run DECK [--data FILE] [--steps N] [--output FILE] [--no-progress]
"""

from __future__ import annotations

import argparse
import os
import sys

from ..core._version import __version__
from .demos import EXPORTS, beam, export_demo, impact, pour, shatter


def at_least(minimum: int):
    """An argparse type: an integer no smaller than ``minimum`` (argparse
    names the option in its message)."""
    def integer(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value
    return integer


def _steps(args, quick_steps: int, steps: int) -> int:
    return args.steps if args.steps is not None else (quick_steps if args.quick else steps)


def _shared(args) -> dict:
    """The options every demo takes, as its run function takes them (an
    empty file name: no such file)."""
    return dict(trajectory=args.trajectory or None, plot=args.plot or None,
                picture=args.picture or None, every=args.every,
                progress=not args.no_progress)


def _report(summary: dict, colour_by: str, view: str = "") -> None:
    """The timing line and the files written (``None`` where not asked for),
    with the ``ase gui`` menus that colour the particles by ``colour_by``
    (and, ``view``, that turn the scene)."""
    timing = f"{summary['wall_seconds']:.1f} s"
    if summary["steps"]:
        timing += f", {summary['ms_per_step']:.2f} ms/step"
    print(timing)
    if summary["trajectory"]:
        print(f"trajectory: {summary['trajectory']}  (ase gui {summary['trajectory']}; "
              f'View > Colors ... > By user-defined "{colour_by}"{view})')
    for key in ("plot", "picture"):
        if summary.get(key):
            print(f"{key}: {summary[key]}")


def _impact(args) -> int:
    _, steps, quick_steps = impact.variant(args.bonds)
    summary = impact.run_impact(steps=_steps(args, quick_steps, steps), quick=args.quick,
                                bonds=args.bonds, **_shared(args))
    print(f"{summary['atoms']} particles, {summary['bonds']} {args.bonds} bonds, "
          f"{summary['broken']} broken after {summary['steps']} steps; "
          f"final kinetic energy {summary['kinetic_energy']:.8g}")
    _report(summary, "damage", "; View > Change view > yz-plane: the disk face-on")
    return 0


def _shatter(args) -> int:
    summary = shatter.run_shatter(steps=_steps(args, shatter.QUICK_STEPS, shatter.STEPS),
                                  **_shared(args))
    print(f"{summary['nodes']} nodes, {summary['broken']} bonds broken after "
          f"{summary['steps']} steps; mean damage {summary['mean_damage']:.4f}")
    _report(summary, "damage")
    return 0


def _pour(args) -> int:
    summary = pour.run_pour(steps=_steps(args, pour.QUICK_STEPS, pour.STEPS),
                            quick=args.quick, **_shared(args))
    print(f"{summary['spheres']} spheres, {summary['contacts']} contacts after "
          f"{summary['steps']} steps; kinetic energy {summary['kinetic_energy']:.4g} "
          f"(peak {summary['peak_kinetic_energy']:.4g}); pile height "
          f"{summary['height']:.3f}")
    _report(summary, "ncontacts")
    return 0


def _beam(args) -> int:
    summary = beam.run_beam(steps=_steps(args, beam.QUICK_STEPS, beam.STEPS),
                            quick=args.quick, **_shared(args))
    print(f"two wires of {summary['spheres']} spheres clamped at one end, after "
          f"{summary['steps']} steps under gravity {summary['gravity']:.4g}: tip "
          f"deflection {summary['rotational_tip']:.4g} with rotational bonds (beam theory "
          f"{summary['theory_tip']:.4g}), {summary['spring_tip']:.4g} with spring bonds "
          f"(wire length {summary['length']:g})")
    _report(summary, "wire")
    return 0


def _export(args) -> int:
    try:
        data, deck = export_demo(args.demo, args.output, quick=args.quick, steps=args.steps,
                                 bonds=args.bonds)
    except ValueError as exc:  # (--bonds given to a demo without that choice)
        print(f"ase-bpm export: {exc}", file=sys.stderr)
        return 2
    print(f"{data}\n{deck}\nrun it: lmp -in {deck}  (or: mpirun -np 4 lmp -in {deck})")
    return 0


def _run(args) -> int:
    from .lammps_run import run_lammps

    output = args.output or frames_of(args.deck)
    try:
        result = run_lammps(args.deck, args.data, steps=args.steps,
                            output=output, progress=not args.no_progress,
                            echo=print)
    except (ValueError, OSError, ImportError) as exc:  # (a deck refused by line, a file
        # missing, a deck that builds its scene without the LAMMPS module)
        print(f"ase-bpm run: {exc}", file=sys.stderr)
        return 1
    print(f"{result.steps} steps in {result.wall_seconds:.3g} s"
          + (f", {1e3 * result.wall_seconds / result.steps:.2f} ms/step" if result.steps
             else ""))
    for number, command in result.ignored:
        print(f"ignored: line {number} {command!r}")
    print(f"frames: {output}  (ase gui {output})")
    return 0


def frames_of(deck: str) -> str:
    """The frames ``ase-bpm run`` writes by default: the deck's name without
    LAMMPS's ``in.`` prefix, as ``.extxyz`` in the working folder
    (``in.pour`` -> ``pour.extxyz``)."""
    name = os.path.basename(deck)
    return f"{name.removeprefix('in.') or name}.extxyz"


def _add_demo(demos, name: str, run, module, *, about: str, quick: str, every: int,
              plot: str, picture: str, steps_note: str = ""):
    """A ``demo <name>`` subcommand with the options every demo shares;
    ``module`` (the demo's) has its numbers of steps, STEPS and QUICK_STEPS
    (``steps_note``: what the help of ``--steps`` adds about other choices).
    Returns the subcommand's parser."""
    demo = demos.add_parser(name, help=about, description=about)
    demo.add_argument("--quick", action="store_true", help=quick)
    demo.add_argument("--steps", type=at_least(0), metavar="N",
                      help=f"number of MD steps (default {module.STEPS}, with --quick "
                           f"{module.QUICK_STEPS}{steps_note}; 0: just the starting "
                           "scene)")
    demo.add_argument("--trajectory", default=f"{name}.extxyz",
                      help="extxyz file for ase gui ('' for none; default %(default)s)")
    demo.add_argument("--every", type=at_least(1), default=every, metavar="N",
                      help="write a frame every N steps, and the last one "
                           "(default %(default)s)")
    demo.add_argument("--plot", default=f"{name}.png",
                      help=f"PNG of {plot} ('' for none; default %(default)s)")
    demo.add_argument("--picture", default=f"{name}-final.png",
                      help=f"PNG picture of {picture} ('' for none; default %(default)s)")
    demo.add_argument("--no-progress", action="store_true", help="no progress bar")
    demo.set_defaults(run=run)
    return demo


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(prog="ase-bpm", description=(
        "LAMMPS bonded-particle models in ASE: demos and tools."))
    top.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = top.add_subparsers(dest="command", required=True)
    demo = commands.add_parser("demo", help="run a demonstration scene")
    demos = demo.add_subparsers(dest="demo", required=True)
    rotational = impact.VARIANTS["rotational"]
    impact_demo = _add_demo(demos, "impact", _impact, impact, about=(
        "LAMMPS examples/bpm/impact: a bonded ball shatters a bonded disk "
        f"(11,118 particles, 60k bonds, {impact.STEPS:,} steps)"),
        quick=f"a small disk and ball (1,648 particles), {impact.QUICK_STEPS:,} steps",
        every=250, plot="kinetic energy and intact bonds",
        picture="the broken disk, face-on, coloured by damage (--bonds rotational: "
                "the ball too, in grey, seen from its side)",
        steps_note=f"; --bonds rotational: {rotational.steps:,} and "
                   f"{rotational.quick_steps:,} steps of {rotational.timestep:g}")
    impact_demo.add_argument("--bonds", choices=impact.VARIANTS, default="spring",
                             help="the bonds of the scene: spring (in.bpm.impact.spring, "
                                  "bond_style bpm/spring) or rotational "
                                  "(in.bpm.impact.rotational: bond_style bpm/rotational "
                                  "between spheres, pair_style gran/hooke/history, "
                                  "SphereVelocityVerlet); default %(default)s")
    _add_demo(demos, "shatter", _shatter, shatter, about=(
        "LAMMPS examples/bpm/peri: a spherical indenter shatters a brittle "
        f"peridynamic cylinder (3,487 nodes, 168k bonds, {shatter.STEPS:,} steps)"),
        quick=f"the first {shatter.QUICK_STEPS:,} steps only (the crater forming)",
        every=100, plot="mean damage against time", picture="the fractured cylinder")
    _add_demo(demos, "pour", _pour, pour, about=(
        f"granular pour: {pour.FULL['count']:,} polydisperse frictional spheres fall "
        f"into a box and settle (gran/hooke/history, {pour.STEPS:,} steps)"),
        quick=(f"{pour.QUICK['count']:,} spheres in a smaller box, "
               f"{pour.QUICK_STEPS:,} steps"),
        every=500, plot="the kinetic energy decay and the contacts",
        picture="the pile at the last step")
    _add_demo(demos, "beam", _beam, beam, about=(
        f"what rotational bonds are for: two wires of {beam.FULL} spheres, clamped at one "
        "end, bend under their own weight, one with bpm/rotational bonds (a beam: it sags "
        "as beam theory says), one with bpm/spring bonds (a chain: it hangs down) "
        f"({beam.STEPS:,} steps)"),
        quick=f"wires of {beam.QUICK} spheres, {beam.QUICK_STEPS:,} steps",
        every=250, plot="the tip deflections against time",
        picture="both wires from the side, with the beam theory's curve")
    export = commands.add_parser(
        "export", help="write a demo's scene for LAMMPS (data file and input deck)",
        description="Write a demo's scene as a LAMMPS data file and input deck "
                    "(ase_bpm.write_lammps), a run of the demo's steps with its timestep.")
    export.add_argument("demo", choices=EXPORTS)
    export.add_argument("--bonds", choices=impact.VARIANTS, default=None,
                        help="impact only: the bonds of its scene, spring (the default) or "
                             "rotational")
    export.add_argument("--quick", action="store_true", help="the demo's --quick scene")
    export.add_argument("--steps", type=at_least(0), metavar="N",
                        help="steps of the deck's run (default: the demo's)")
    export.add_argument("--output", metavar="STEM",
                        help="write STEM.data and in.STEM (default: the demo's name)")
    export.set_defaults(run=_export)
    run = commands.add_parser(
        "run", help="run a LAMMPS input deck in ase_bpm",
        description="Run every run of a LAMMPS input deck in ase_bpm (read_lammps, then what "
                    "the deck changes between runs), printing the thermo quantities ase_bpm "
                    "has at the deck's thermo steps and the lines it ignored.")
    run.add_argument("deck", help="the input deck (its read_data, if any, names the data "
                                  "file)")
    run.add_argument("--data", metavar="FILE",
                     help="the data file (default: read_data's, next to the deck)")
    run.add_argument("--steps", type=at_least(0), metavar="N",
                     help="stop after N steps in all (default: every run to its end)")
    run.add_argument("--output", metavar="FILE", default="",
                     help="extxyz frames for ase gui or OVITO, one per thermo line "
                          "(default: the deck's name without 'in.', e.g. in.pour -> "
                          "pour.extxyz)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.set_defaults(run=_run)
    return top


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
