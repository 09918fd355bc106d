"""Function calls per MD step, the measure of issue 31's "lean step".

    python benchmarks/calls_per_step.py [--steps 300] [--scene impact|pour|all]

Counts, with cProfile, every call made in ``--steps`` MD steps (after 20
untimed ones), rebuilds of the neighbour lists included, and divides by the
steps: all calls (C builtins included) and the calls to ase_bpm's own
functions (whose file is in the ase_bpm package), with the ten ase_bpm
functions called most.  The scenes are those of the --quick demos:

* impact: ``ase-bpm demo impact --quick`` (BPMSpring, bonds and contacts),
  driven by ASE's ``VelocityVerlet``;
* pour: ``ase-bpm demo pour --quick`` (Granular, 500 spheres, gravity and
  walls), driven by ``ase_bpm.SphereVelocityVerlet`` (its own calls count).

A count, not a time: it does not need a quiet machine.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
from pathlib import Path

import ase_bpm

PACKAGE = str(Path(ase_bpm.__file__).parent)
WARM_STEPS = 20


def scene(name: str):
    """The demo scene and the integrator that drives it."""
    if name == "impact":
        from ase.md.verlet import VelocityVerlet

        from ase_bpm.scene.demos import impact
        atoms = impact.demo_scene(quick=True)
        return VelocityVerlet(atoms, timestep=impact.TIMESTEP)
    from ase_bpm.scene.demos import pour
    from ase_bpm.scene.md import SphereVelocityVerlet
    atoms = pour.demo_scene(quick=True)
    return SphereVelocityVerlet(atoms, pour.TIMESTEP)


def count(name: str, steps: int) -> dict:
    dyn = scene(name)
    dyn.run(WARM_STEPS)
    profile = cProfile.Profile()
    profile.enable()
    dyn.run(steps)
    profile.disable()
    stats = pstats.Stats(profile).stats  # (file, line, function) -> (cc, nc, tt, ct, callers)
    total = sum(nc for _, nc, _, _, _ in stats.values())
    ours = {key: nc for key, (_, nc, _, _, _) in stats.items() if key[0].startswith(PACKAGE)}
    top = sorted(ours.items(), key=lambda item: -item[1])[:10]
    return {"scene": name, "all": total / steps, "ase_bpm": sum(ours.values()) / steps,
            "functions": len(ours),
            "top": [(f"{Path(f).name}:{fn}", n / steps) for (f, _, fn), n in top]}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--scene", choices=("impact", "pour", "all"), default="all")
    args = parser.parse_args(argv)
    for name in (("impact", "pour") if args.scene == "all" else (args.scene,)):
        result = count(name, args.steps)
        print(f"{name}: {result['all']:.0f} calls a step, {result['ase_bpm']:.0f} of them to "
              f"{result['functions']} ase_bpm functions")
        for where, n in result["top"]:
            print(f"    {n:6.2f}  {where}")


if __name__ == "__main__":
    main()
