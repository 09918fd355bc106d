"""LAMMPS text that every model's export shares.

Numbers written so that they read back bit for bit (:func:`exact`), the box
of a data file (:func:`box`), the unit systems ase_bpm can hand over
(:data:`CONSISTENT_UNITS`) and the densities of sphere styles
(:func:`sphere_densities`).
"""

from __future__ import annotations

import numpy as np
from ase import Atoms

from .spheres import radii

#: LAMMPS unit systems in which ase_bpm's numbers (it converts none) carry over
CONSISTENT_UNITS = ("lj", "si", "cgs", "micro", "nano")


def exact(x: float) -> str:
    """A float written so that it reads back bit for bit."""
    return repr(float(x))


def box(atoms: Atoms, margin: float):
    """LAMMPS box lines and boundary string for the atoms' cell and pbc;
    non-periodic directions span the positions plus ``margin``."""
    pbc, cell = atoms.pbc, np.asarray(atoms.cell)
    if pbc.any():
        off_diagonal = cell[np.triu_indices(3, 1)]
        if np.any(off_diagonal != 0):
            raise ValueError(
                "LAMMPS needs a cell with a along x and b in the xy plane "
                "(lower-triangular cell matrix); rotate the atoms first")
        if not pbc.all() and np.any(cell[np.tril_indices(3, -1)] != 0):
            raise ValueError("a triclinic cell must be periodic in all directions")
    lo, hi = np.zeros(3), np.diag(cell).astype(float).copy()
    pos = atoms.positions
    for k in range(3):
        if not pbc[k]:
            lo[k], hi[k] = pos[:, k].min() - margin, pos[:, k].max() + margin
    lines = [f"{exact(lo[k])} {exact(hi[k])} {a}lo {a}hi" for k, a in enumerate("xyz")]
    if pbc.all() and np.any(cell[np.tril_indices(3, -1)] != 0):
        lines.append(f"{exact(cell[1, 0])} {exact(cell[2, 0])} {exact(cell[2, 1])} xy xz yz")
    boundary = " ".join("p" if p else "m" for p in pbc)
    return lines, boundary


def sphere_densities(atoms: Atoms, who: str = "LAMMPS export"):
    """Densities for LAMMPS' sphere styles that give back ase_bpm's masses.

    LAMMPS reads a diameter and a density and computes the mass as
    ``density * (4 pi / 3 * r * r * r)``.  The density written is the double
    for which that product is the mass bit for bit, where one exists (about
    nine particles in ten); for the others ``set atom <id> mass <m>`` lines
    (returned as the second value) restore the exact mass after reading.
    """
    r_n = radii(atoms, who)
    m_n = atoms.get_masses()
    volume_n = 4.0 * np.pi / 3.0 * r_n * r_n * r_n  # in LAMMPS' order of operations
    density_n = m_n / volume_n
    exact_n = density_n * volume_n == m_n
    for direction in (np.inf, -np.inf):  # the neighbouring doubles
        for _ in range(2):
            trial_n = np.nextafter(density_n, direction)
            hit = ~exact_n & (trial_n * volume_n == m_n)
            density_n = np.where(hit, trial_n, density_n)
            exact_n |= hit
    fix_mass = [f"set atom {n + 1} mass {exact(m_n[n])}" for n in np.flatnonzero(~exact_n)]
    return density_n, fix_mass
