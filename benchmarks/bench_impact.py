"""BPMSpring on the LAMMPS examples/bpm/impact scene, side by side with LAMMPS.

    python benchmarks/bench_impact.py [--steps 7500] [--quick]

Runs the same scene (built by ase_bpm.demos.impact) three ways and prints
milliseconds per step and the ratio:

1. ase_bpm: BPMSpring under ASE's VelocityVerlet;
2. LAMMPS (the reference build, one core) on the very same scene, exported
   with ase_bpm.lammps; the two trajectories are compared;
3. the original LAMMPS deck (its own lattice and random displacements), whose
   published log ends at kinetic energy 0.00036136735 per atom after 7,500 steps.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
from ase.md.verlet import VelocityVerlet

from ase_bpm import BPMSpring, get_bonds
from ase_bpm.demos.impact import (BOND_COEFFS, FULL, PAIR_COEFFS, QUICK, TIMESTEP,
                                  impact_scene)
from ase_bpm.lammps import lammps_commands, lammps_data, load_lammps

ORIGINAL_DECK = """
units lj
dimension 3
boundary f f f
atom_style bond
special_bonds lj 0.0 1.0 1.0 coul 0.0 1.0 1.0
newton on off
comm_modify vel yes cutoff 2.6
lattice fcc 1.0
region box block -25 15 -22 22 -22 22
create_box 1 box bond/types 2 extra/bond/per/atom 20
region disk cylinder x 0.0 0.0 20.0 -0.5 0.5
create_atoms 1 region disk
group plate region disk
region ball sphere 8.0 0.0 0.0 6.0
create_atoms 1 region ball
group projectile region ball
displace_atoms all random 0.1 0.1 0.1 134598738
mass 1 1.0
neighbor 1.0 bin
pair_style bpm/spring
pair_coeff 1 1 1.0 1.0 1.0
fix 1 all nve
create_bonds many plate plate 1 0.0 1.5
create_bonds many projectile projectile 2 0.0 1.5
neighbor 0.3 bin
special_bonds lj 0.0 1.0 1.0 coul 1.0 1.0 1.0
bond_style bpm/spring
bond_coeff 1 1.0 0.04 1.0
bond_coeff 2 1.0 0.20 1.0
velocity projectile set -0.05 0.0 0.0
timestep 0.1
thermo_modify lost ignore lost/bond ignore
"""


def lammps_instance():
    return load_lammps()(cmdargs=["-log", "none", "-screen", "none", "-nocite"])


def run_ase(atoms, steps):
    atoms.calc = BPMSpring(bond_coeffs=BOND_COEFFS, pair_coeffs=PAIR_COEFFS)
    dyn = VelocityVerlet(atoms, timestep=TIMESTEP)
    atoms.get_forces()  # setup, as LAMMPS' (untimed) setup
    start = time.perf_counter()
    dyn.run(steps)
    return time.perf_counter() - start


def run_lammps_same_scene(atoms, steps):
    lmp = lammps_instance()
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "impact.data")
        with open(data, "w") as fh:
            fh.write(lammps_data(atoms, BPMSpring(bond_coeffs=BOND_COEFFS,
                                                  pair_coeffs=PAIR_COEFFS)))
        calc = BPMSpring(bond_coeffs=BOND_COEFFS, pair_coeffs=PAIR_COEFFS)
        lmp.commands_list(lammps_commands(atoms, calc, data, timestep=TIMESTEP))
        lmp.commands_list(["thermo 100000", "run 0"])
        start = time.perf_counter()
        lmp.command(f"run {steps}")
        wall = time.perf_counter() - start
    nlocal = lmp.extract_global("nlocal")
    ids = np.array(lmp.numpy.extract_atom("id")[:nlocal]) - 1
    x, v = np.empty((nlocal, 3)), np.empty((nlocal, 3))
    x[ids] = lmp.numpy.extract_atom("x")[:nlocal]
    v[ids] = lmp.numpy.extract_atom("v")[:nlocal]
    bonds = len(np.array(lmp.numpy.gather_bonds()).reshape(-1, 3))
    lmp.close()
    return wall, x, v, bonds


def run_original_deck(steps):
    lmp = lammps_instance()
    lmp.commands_string(ORIGINAL_DECK)
    lmp.commands_list(["thermo 100000", "run 0"])
    start = time.perf_counter()
    lmp.command(f"run {steps}")
    wall = time.perf_counter() - start
    ke = lmp.get_thermo("ke")
    natoms = lmp.get_natoms()
    lmp.close()
    return wall, ke, natoms


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=7500)
    ap.add_argument("--quick", action="store_true", help="the small scene of --quick demos")
    args = ap.parse_args()
    geometry = QUICK if args.quick else FULL

    atoms = impact_scene(**geometry)
    reference = atoms.copy()
    nbonds = len(get_bonds(atoms)[0])
    print(f"scene: {len(atoms)} particles, {nbonds} bonds, {args.steps} steps")

    t_ase = run_ase(atoms, args.steps)
    t_lmp, x_lmp, v_lmp, bonds_lmp = run_lammps_same_scene(reference, args.steps)
    bonds_ase = len(get_bonds(atoms)[0])
    ke_ase = atoms.get_kinetic_energy() / len(atoms)
    ke_lmp = 0.5 * np.sum(atoms.get_masses()[:, None] * v_lmp ** 2) / len(atoms)
    dx = np.abs(atoms.positions - x_lmp).max()

    rows = [("ase_bpm (VelocityVerlet + BPMSpring)", t_ase),
            ("LAMMPS, same scene (exported)", t_lmp)]
    if not args.quick:
        t_orig, ke_orig, n_orig = run_original_deck(args.steps)
        rows.append(("LAMMPS, original deck", t_orig))
    print(f"\n{'run':40s} {'seconds':>9s} {'ms/step':>9s} {'ratio':>7s}")
    for name, wall in rows:
        print(f"{name:40s} {wall:9.2f} {1e3 * wall / args.steps:9.3f} {wall / t_lmp:7.2f}")
    print(f"\nase_bpm / LAMMPS (same scene): {t_ase / t_lmp:.2f}x")
    print(f"same scene, ase_bpm vs LAMMPS after {args.steps} steps: intact bonds "
          f"{bonds_ase} vs {bonds_lmp}; kinetic energy/atom {ke_ase:.10g} vs "
          f"{ke_lmp:.10g}; largest position difference {dx:.2e}")
    if not args.quick:
        print(f"original deck: {n_orig} particles, kinetic energy/atom {ke_orig:.11g} "
              "(published log, 7500 steps: 0.00036136735)")


if __name__ == "__main__":
    main()
