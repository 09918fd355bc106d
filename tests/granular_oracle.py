"""The reference LAMMPS build's granular styles as an oracle for Granular.

Scenes go over through :mod:`ase_bpm.scene.lammps` (``atom_style sphere``, ``pair_style
gran/*``, ``fix nve/sphere``, ``fix wall/gran``, ``fix gravity``, ``fix freeze``), the
export users run.  LAMMPS derives each mass from diameter and density; the export
makes that give back ase_bpm's masses exactly, as checked on reading.
"""

from __future__ import annotations

import os

import numpy as np

from ase_bpm.scene.lammps import granular_commands, granular_data
from oracle import LammpsScene


class GranularOracle(LammpsScene):
    """A LAMMPS instance holding an exported Granular scene."""

    def __init__(self, atoms, calc, timestep: float, virial: bool = False):
        super().__init__()
        data = os.path.join(self._dir.name, "granular.data")
        with open(data, "w") as fh:
            fh.write(granular_data(atoms))
        cmds = granular_commands(atoms, calc, data, timestep=timestep)
        if virial:
            cmds += ["compute vir all pressure NULL virial",
                     "thermo_style custom step pe c_vir[1]"]
        self.lmp.commands_list(cmds + ["thermo 1000000"])
        # the export restores every mass bit for bit (see sphere_densities)
        assert np.array_equal(self.get("rmass"), atoms.get_masses())
