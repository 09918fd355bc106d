"""Granular on the pour scene, side by side with LAMMPS.

    python benchmarks/bench_pour.py [--steps 15000] [--quick] [--kernels numpy]

Runs the scene of ``ase-bpm demo pour`` (3,000 polydisperse spheres falling
into a box: gran/hooke/history, fix wall/gran on five sides, fix gravity) in
ase_bpm (Granular under SphereVelocityVerlet) and, exported with
``ase_bpm.lammps.write_lammps``, in the reference LAMMPS build on one core.
Prints seconds and milliseconds per step of both, their ratio, and how far
the two trajectories are apart at the end.  The setup evaluation is not
timed in either.  ``--kernels numpy`` runs ase_bpm's NumPy kernels instead of
the compiled ones.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

from ase_bpm import rotational_energy
from ase_bpm.demos.pour import FULL, QUICK, STEPS, TIMESTEP, pour_calculator, pour_scene
from ase_bpm.kernels import granular_kernels
from ase_bpm.lammps import load_lammps, write_lammps
from ase_bpm.md import SphereVelocityVerlet
from ase_bpm.neighbours import neighbour_pairs


def run_ase(atoms, steps):
    dyn = SphereVelocityVerlet(atoms, TIMESTEP)
    atoms.get_forces()  # setup, as LAMMPS' (untimed) setup
    start = time.perf_counter()
    dyn.run(steps)
    return time.perf_counter() - start


def run_lammps(atoms, steps):
    lmp = load_lammps()(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        _, deck = write_lammps(os.path.join(tmp, "pour"), atoms, timestep=TIMESTEP,
                               steps=0, thermo=100000)
        try:
            os.chdir(tmp)
            lmp.file(os.path.basename(deck))  # ends with "run 0": the setup
        finally:
            os.chdir(cwd)
    start = time.perf_counter()
    lmp.command(f"run {steps}")
    wall = time.perf_counter() - start
    nlocal = lmp.extract_global("nlocal")
    ids = np.array(lmp.numpy.extract_atom("id")[:nlocal]) - 1
    out = {}
    for name in ("x", "v", "omega"):
        values = np.empty((nlocal, 3))
        values[ids] = lmp.numpy.extract_atom(name)[:nlocal]
        out[name] = values
    lmp.close()
    return wall, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=STEPS)
    ap.add_argument("--quick", action="store_true", help="the 500 spheres of --quick")
    ap.add_argument("--kernels", default="auto", choices=("auto", "compiled", "numpy"))
    args = ap.parse_args()
    size = QUICK if args.quick else FULL

    atoms = pour_scene(**size)
    atoms.calc = pour_calculator(size["width"], kernels=args.kernels)
    reference = atoms.copy()
    reference.calc = pour_calculator(size["width"])
    kernels = "compiled" if granular_kernels(args.kernels).__name__.endswith("compiled") \
        else "numpy"
    print(f"scene: {len(atoms)} spheres, {args.steps} steps of {TIMESTEP}; "
          f"{kernels} kernels")

    t_ase = run_ase(atoms, args.steps)
    t_lmp, lmp = run_lammps(reference, args.steps)

    print(f"\n{'run':54s} {'seconds':>9s} {'ms/step':>9s} {'ratio':>7s}")
    for name, wall in ((f"ase_bpm (SphereVelocityVerlet + Granular, {kernels})", t_ase),
                       ("LAMMPS, same scene (exported)", t_lmp)):
        print(f"{name:54s} {wall:9.2f} {1e3 * wall / args.steps:9.3f} {wall / t_lmp:7.2f}")
    print(f"\nase_bpm / LAMMPS: {t_ase / t_lmp:.2f}x")
    m = atoms.get_masses()[:, None]
    ke_lmp = 0.5 * np.sum(m * lmp["v"] ** 2)
    r_n = atoms.arrays["radius"]
    i, j, _ = neighbour_pairs(lmp["x"], atoms.cell, atoms.pbc, r_n)
    contacts_lmp = int(np.sum(np.linalg.norm(lmp["x"][j] - lmp["x"][i], axis=1)
                              < r_n[i] + r_n[j]))
    print(f"after {args.steps} steps: contacts {atoms.arrays['ncontacts'].sum() // 2} "
          f"(LAMMPS {contacts_lmp}); "
          f"kinetic energy {atoms.get_kinetic_energy():.10g} (LAMMPS {ke_lmp:.10g}); "
          f"rotational {rotational_energy(atoms):.6g}; largest difference of positions "
          f"{np.abs(atoms.positions - lmp['x']).max():.2e}, of angular velocities "
          f"{np.abs(atoms.arrays['omega'] - lmp['omega']).max():.2e}")


if __name__ == "__main__":
    main()
