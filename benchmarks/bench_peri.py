"""BPMPeri on the LAMMPS PERI benchmark, side by side with legacy peri/pmb.

    python benchmarks/bench_peri.py [--steps 200] [--shatter]

The benchmark block (LAMMPS examples/bpm/peri/benchmark): periodic 16^3
simple cubic nodes, spacing 0.0005 m, horizon 0.0015001 m (122 bonds per
node, 249,856 bonds), pmb c = 1.6863e22, s00 = 0.5, 200 steps of 1e-7 s from
the reference configuration.  With ``--shatter`` also the shatter demo scene
(3,487 nodes, 167,983 bonds, indenter, fracture) for the same number of steps.
Prints milliseconds per step and the ratio to LAMMPS, and how far apart the
two trajectories end.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
from ase import Atoms

import ase_bpm
from ase_bpm.fixes import SphericalIndenter
from ase_bpm.lammps import load_lammps, peri_commands, peri_data
from ase_bpm.md import VelocityVerlet

SPACING, HORIZON, VOLUME, DENSITY = 0.0005, 0.0015001, 1.25e-10, 2200.0
PMB = ("pmb", 1.6863e22, HORIZON, 0.5, 0.25)


def block(n=16) -> Atoms:
    grid = np.array(np.meshgrid(*[np.arange(n)] * 3, indexing="ij")).reshape(3, -1).T
    atoms = Atoms(f"Si{len(grid)}", positions=grid * SPACING, cell=np.eye(3) * n * SPACING,
                  pbc=True)
    atoms.arrays["vfrac"] = np.full(len(atoms), VOLUME)
    atoms.set_masses(np.full(len(atoms), DENSITY * VOLUME))
    ase_bpm.create_bonds(atoms, HORIZON)
    return atoms


def run_ase(atoms, steps):
    atoms.get_forces()  # setup (LAMMPS' setup is not timed either)
    start = time.perf_counter()
    VelocityVerlet(atoms, timestep=1e-7).run(steps)
    return time.perf_counter() - start


def run_lammps(atoms, calc, steps):
    lmp = load_lammps()(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "scene.data")
        with open(data, "w") as fh:
            fh.write(peri_data(atoms))
        lmp.commands_list(peri_commands(atoms, calc, data, timestep=1e-7, spacing=SPACING)
                          + ["thermo 100000", "run 0"])
        # legacy PERI leaves s0 unset after its first setup (see tests/peri_oracle.py)
        nlocal = lmp.extract_global("nlocal")
        lmp.numpy.extract_atom("s0")[:nlocal] = np.finfo(float).max
        lmp.command("run 0")
        start = time.perf_counter()
        lmp.command(f"run {steps}")
        wall = time.perf_counter() - start
    nlocal = lmp.extract_global("nlocal")
    ids = np.array(lmp.numpy.extract_atom("id")[:nlocal]) - 1
    x = np.full((len(atoms), 3), np.nan)
    x[ids] = lmp.numpy.extract_atom("x")[:nlocal]
    lmp.close()
    return wall, x


def compare(name, make, steps):
    ours = make()
    reference = ours.copy()
    reference.calc = make().calc
    reference.get_forces()
    t_ase = run_ase(ours, steps)
    t_lmp, x_lmp = run_lammps(reference, reference.calc, steps)
    d = ase_bpm.neighbours.minimum_image(ours.positions - x_lmp, ours.cell, ours.pbc)
    print(f"\n{name}: {len(ours)} nodes, {len(ase_bpm.get_bonds(reference)[0])} bonds, "
          f"{steps} steps")
    print(f"{'run':34s} {'seconds':>9s} {'ms/step':>9s} {'ratio':>7s}")
    print(f"{'ase_bpm BPMPeri':34s} {t_ase:9.2f} {1e3 * t_ase / steps:9.2f} "
          f"{t_ase / t_lmp:7.2f}")
    print(f"{'LAMMPS legacy peri/pmb':34s} {t_lmp:9.2f} {1e3 * t_lmp / steps:9.2f} {1.0:7.2f}")
    print(f"largest position difference: {np.nanmax(np.abs(d)) / SPACING:.2e} spacings")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--shatter", action="store_true", help="also the shatter scene")
    args = ap.parse_args()

    def benchmark_block():
        atoms = block()
        atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: PMB}, lattice_spacing=SPACING)
        return atoms

    compare("PERI benchmark block", benchmark_block, args.steps)
    if args.shatter:
        from ase_bpm.demos import shatter

        def shatter_scene():
            atoms = shatter.cylinder()
            atoms.calc = ase_bpm.BPMPeri(
                bond_coeffs=shatter.BOND_COEFFS, pair_coeffs=shatter.PAIR_COEFFS,
                fixes=[SphericalIndenter(**shatter.INDENTER)], timestep=1e-7)
            return atoms

        compare("shatter demo (cylinder, indenter, fracture)", shatter_scene, args.steps)


if __name__ == "__main__":
    main()
