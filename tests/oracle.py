"""The reference LAMMPS build (``lammps[mpi]==2025.7.22.4.0``) as a test oracle.

Scenes are handed over through :mod:`ase_bpm.scene.lammps`, the same export users
run, so every oracle test also checks that an exported scene runs in LAMMPS.
LAMMPS re-sorts atoms: everything read back is put in atom-ID order.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from ase_bpm.scene.lammps import lammps_commands, lammps_data, load_lammps
from ase_bpm.scene.lammps_setup import QUIET  # (no log, no screen output)
from ase_bpm.core.neighbours import minimum_image


def run_deck(deck: str):
    """A LAMMPS instance that has run an exported deck, in the deck's folder
    (the deck names its files relative to it); the caller closes it."""
    lmp = load_lammps()(cmdargs=QUIET)
    cwd = os.getcwd()
    try:
        os.chdir(os.path.dirname(os.path.abspath(deck)))
        lmp.file(os.path.basename(deck))
    finally:
        os.chdir(cwd)
    return lmp


def gather(lmp, name: str) -> np.ndarray:
    """Per-atom ``name`` (``x``, ``v``, ``f``, ``omega``...) in atom-ID order."""
    nlocal = lmp.extract_global("nlocal")
    index = np.array(lmp.numpy.extract_atom("id")[:nlocal]) - 1
    values = np.array(lmp.numpy.extract_atom(name)[:nlocal])
    out = np.empty_like(values)
    out[index] = values
    return out


class LammpsScene:
    """A fresh LAMMPS instance with a scratch directory for its files;
    per-atom data read and written in atom-ID order."""

    def __init__(self):
        self.lmp = load_lammps()(cmdargs=QUIET)
        self._dir = tempfile.TemporaryDirectory()

    def close(self):
        self.lmp.close()
        self._dir.cleanup()

    def _order(self):
        nlocal = self.lmp.extract_global("nlocal")
        return nlocal, np.array(self.lmp.numpy.extract_atom("id")[:nlocal]) - 1

    def get(self, name):
        return gather(self.lmp, name)

    def set(self, name, values):
        nlocal, index = self._order()
        self.lmp.numpy.extract_atom(name)[:nlocal] = np.asarray(values)[index]

    def run(self, steps: int) -> None:
        self.lmp.command(f"run {steps}")

    def virial_pressure(self) -> np.ndarray:
        """Virial pressure tensor (pxx, pyy, pzz, pxy, pxz, pyz)."""
        from lammps import LMP_STYLE_GLOBAL, LMP_TYPE_VECTOR

        return np.array(self.lmp.numpy.extract_compute("vir", LMP_STYLE_GLOBAL,
                                                       LMP_TYPE_VECTOR))


class Oracle(LammpsScene):
    """A LAMMPS instance holding an exported ase_bpm scene."""

    def __init__(self, atoms, calc, timestep: float = 0.1, virial: bool = False,
                 broken_log: bool = False):
        super().__init__()
        self.natoms = len(atoms)
        self.pbc = atoms.pbc.copy()
        self.cell = atoms.cell.array.copy()
        data = os.path.join(self._dir.name, "scene.data")
        with open(data, "w") as fh:
            fh.write(lammps_data(atoms, calc))
        cmds = lammps_commands(atoms, calc, data, timestep=timestep,
                               broken_bonds_fix="broken" if broken_log else None)
        thermo = "thermo_style custom step pe"
        if virial:
            cmds.append("compute vir all pressure NULL virial")
            thermo += " c_vir[1]"
        self.lmp.commands_list(cmds + [thermo, "thermo 1000000"])

    def set_state(self, positions, velocities) -> None:
        """New positions and velocities (the bond reference state is kept)."""
        self.set("x", np.asarray(positions, dtype=float))
        self.set("v", np.asarray(velocities, dtype=float))

    def forces(self) -> np.ndarray:
        return self.get("f")

    def velocities(self) -> np.ndarray:
        return self.get("v")

    def position_error(self, positions) -> np.ndarray:
        """Per-atom distance to ``positions``, minimum image under pbc."""
        d = minimum_image(self.get("x") - positions, self.cell, self.pbc)
        return np.linalg.norm(d, axis=1)

    def intact_bonds(self) -> set:
        """Intact bonds as ``{(i, j)}`` with 0-based ``i < j``."""
        return intact_bonds(self.lmp)


def intact_bonds(lmp) -> set:
    """The intact bonds LAMMPS holds, ``{(i, j)}`` with 0-based ``i < j``."""
    bonds = np.array(lmp.numpy.gather_bonds())
    if bonds.size == 0:
        return set()
    bonds = bonds.reshape(-1, 3)
    bonds = bonds[bonds[:, 0] > 0]
    return {(min(a, b) - 1, max(a, b) - 1) for a, b in bonds[:, 1:]}


def read_dump_local(path):
    """Rows of a LAMMPS ``dump local`` file (the broken-bond log a deck of
    write_lammps writes: nine columns)."""
    rows, take = [], False
    for line in path.read_text().splitlines():
        if line.startswith("ITEM:"):
            take = line.startswith("ITEM: ENTRIES")
        elif take and line.strip():
            rows.append([float(v) for v in line.split()])
    return np.array(rows).reshape(-1, 9)


def broken_log(rows):
    """``{(i, j, step)}`` of a broken-bond log's rows, ``i < j`` (the IDs or
    indices as the rows give them)."""
    return {(min(int(i), int(j)), max(int(i), int(j)), int(step)) for i, j, step in rows[:, :3]}
