"""Granular on the pour scene, side by side with LAMMPS.

    python benchmarks/bench_pour.py [--steps 15000] [--repeats 3] [--quick]
                                    [--spheres N] [--kernels numpy] [--threads 1]

Runs the scene of ``ase-bpm demo pour`` (3,000 polydisperse spheres falling
into a box: gran/hooke/history, fix wall/gran on five sides, fix gravity) in
ase_bpm (Granular under SphereVelocityVerlet) and, exported with
``ase_bpm.scene.lammps.write_lammps``, in the reference LAMMPS build, each engine in
its own process on one thread (``engines.py``).  The cost of a step grows as
the spheres land and touch, so every repeat is a fresh process that runs the
same steps from the release: ``--repeats`` rounds, each running the engines
in turn.  The setup (building the scene, the first force evaluation; LAMMPS'
deck up to its ``run 0``) is not timed in either.  Prints per engine the wall
time (median), ms/step (median, min-max), peak memory (the largest of its
processes) and the ratio to LAMMPS (median, min-max of the ratios of the
rounds), and how far the two trajectories are apart at the end.
``--quick``: the 500 spheres of ``ase-bpm demo pour --quick``.  ``--spheres
N``: N spheres in the quick box instead (``--spheres 20``: a scene so small
that a step is all fixed cost, the calculator's and the integrator's, next
to LAMMPS's).  ``--kernels numpy`` runs ase_bpm's NumPy kernels instead of
the compiled ones.  ``--threads n``: ase_bpm's compiled contact kernel on n
threads (``ase_bpm.laws.compiled.set_threads``; the rest of ase_bpm and
LAMMPS stay on one).
"""

from __future__ import annotations

import argparse
import os
import tempfile

import numpy as np

import engines
from ase_bpm import rotational_energy
from ase_bpm.scene.demos.pour import FULL, QUICK, STEPS, TIMESTEP, pour_calculator, pour_scene
from ase_bpm.laws import granular_kernels
from ase_bpm import write_lammps
from ase_bpm import SphereVelocityVerlet
from ase_bpm.core.neighbours import neighbour_pairs


# -- the children -------------------------------------------------------------------

def child_ase(args) -> dict:
    """ase_bpm on the scene it builds (``--kernels``); final positions and
    angular velocities to ``--state``."""
    from ase_bpm.laws import compiled

    compiled.set_threads(args.threads)
    size = scene_size(args)
    atoms = pour_scene(**size)
    atoms.calc = pour_calculator(size["width"], kernels=args.kernels)
    dyn = SphereVelocityVerlet(atoms, TIMESTEP)
    atoms.get_forces()  # setup, as LAMMPS' (untimed) run 0
    seconds = engines.timed(dyn.run, args.steps)
    np.savez(args.state, x=atoms.positions, omega=atoms.arrays["omega"])
    return dict(seconds=seconds, peak_mb=engines.peak_memory_mb(),
                contacts=int(atoms.arrays["ncontacts"].sum() // 2),
                ke=atoms.get_kinetic_energy(), rotational=rotational_energy(atoms))


def child_lammps(args) -> dict:
    """LAMMPS on the exported deck (``--deck``, which ends with ``run 0``, and
    reads its data file from its own folder); final positions, velocities and
    angular velocities to ``--state``."""
    lmp = engines.new_lammps()
    cwd = os.getcwd()
    try:
        os.chdir(os.path.dirname(args.deck))
        lmp.file(os.path.basename(args.deck))
    finally:
        os.chdir(cwd)
    seconds = engines.timed(lambda n: lmp.command(f"run {n}"), args.steps)
    count = lmp.get_natoms()
    np.savez(args.state, **{name: engines.lammps_per_atom(lmp, name, count)
                            for name in ("x", "v", "omega")})
    lmp.close()
    return dict(seconds=seconds, peak_mb=engines.peak_memory_mb())


CHILDREN = {"ase_bpm": child_ase, "lammps": child_lammps}


# -- the parent ---------------------------------------------------------------------

def scene_size(args) -> dict:
    """The pour_scene arguments of ``--quick`` / ``--spheres`` (else the full scene)."""
    if args.spheres is not None:
        return dict(QUICK, count=args.spheres)
    return QUICK if args.quick else FULL


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=STEPS, help=f"steps per run ({STEPS})")
    ap.add_argument("--repeats", type=int, default=3, help="fresh runs per engine (3)")
    ap.add_argument("--quick", action="store_true", help="the 500 spheres of --quick")
    ap.add_argument("--spheres", type=int, default=None,
                    help="this many spheres in the box of --quick")
    ap.add_argument("--kernels", default="auto", choices=("auto", "compiled", "numpy"))
    ap.add_argument("--threads", type=int, default=1,
                    help="threads of ase_bpm's compiled contact kernel (1)")
    ap.add_argument("--deck", help=argparse.SUPPRESS)
    engines.add_child_options(ap, CHILDREN)
    args = ap.parse_args()
    if args.spheres is not None and args.spheres < 1:
        ap.error(f"--spheres {args.spheres}: give at least one sphere")
    if args.threads < 1:
        ap.error(f"--threads {args.threads}: give at least one thread")
    if args.child:
        engines.answer(CHILDREN, args)
        return

    size = scene_size(args)
    atoms = pour_scene(**size)
    kernels = "compiled" if granular_kernels(args.kernels).__name__.endswith("compiled") \
        else "numpy"
    threads = f", the contact kernel on {args.threads} threads" if args.threads > 1 else ""
    print(f"scene: {len(atoms)} spheres, {args.steps} steps of {TIMESTEP}; "
          f"{kernels} kernels{threads}", flush=True)
    common = (["--steps", str(args.steps)] + (["--quick"] if args.quick else [])
              + ([] if args.spheres is None else ["--spheres", str(args.spheres)]))
    with tempfile.TemporaryDirectory() as tmp:
        _, deck = write_lammps(os.path.join(tmp, "pour"), atoms,
                               pour_calculator(size["width"]), timestep=TIMESTEP,
                               steps=0, thermo=engines.NO_THERMO)
        runs = {"ase_bpm": [*common, "--kernels", args.kernels, "--threads", str(args.threads)],
                "lammps": [*common, "--deck", deck]}
        results, states = engines.fresh_runs(__file__, runs, args.repeats, tmp)
    ours, lmp = states["ase_bpm"], states["lammps"]

    labels = {"ase_bpm": f"ase_bpm (SphereVelocityVerlet + Granular, {kernels})",
              "lammps": "LAMMPS, same scene (exported)"}
    print("\n" + engines.engine_table({labels[role]: results[role] for role in results},
                                      args.steps, labels["lammps"]))
    ratios = engines.per_round_ratios(results["ase_bpm"], results["lammps"])
    print(f"\nase_bpm / LAMMPS: {engines.spread(ratios, 2)}x")
    ase = results["ase_bpm"][-1]
    ke_lmp = 0.5 * np.sum(atoms.get_masses()[:, None] * lmp["v"] ** 2)
    r_n = atoms.arrays["radius"]
    i, j, _ = neighbour_pairs(lmp["x"], atoms.cell, atoms.pbc, r_n)
    contacts_lmp = int(np.sum(np.linalg.norm(lmp["x"][j] - lmp["x"][i], axis=1)
                              < r_n[i] + r_n[j]))
    print(f"after {args.steps} steps: contacts {ase['contacts']} (LAMMPS {contacts_lmp}); "
          f"kinetic energy {ase['ke']:.10g} (LAMMPS {ke_lmp:.10g}); "
          f"rotational {ase['rotational']:.6g}; largest difference of positions "
          f"{np.abs(ours['x'] - lmp['x']).max():.2e}, of angular velocities "
          f"{np.abs(ours['omega'] - lmp['omega']).max():.2e}")


if __name__ == "__main__":
    main()
