"""Trajectories for looking at: extxyz frames that ``ase gui`` colours.

``ase gui`` offers "By user-defined <key>" colouring (View -> Colors) for every
per-atom array in the file it opens.  :class:`ViewerTrajectory` writes just
the positions and the chosen per-atom outputs (by default ``damage`` and
``nbonds``), not the calculator state, so the file stays small and the colour
menu short.  For restarts use :func:`ase_bpm.write_restart`: extxyz keeps
8 decimals only.
"""

from __future__ import annotations

from typing import Sequence

from ase import Atoms
from ase.io import write


def viewing_copy(atoms: Atoms, arrays: Sequence[str] = ("damage", "nbonds"),
                 info: dict | None = None) -> Atoms:
    """Positions, cell and the named per-atom arrays (those present) of ``atoms``."""
    view = Atoms(numbers=atoms.numbers, positions=atoms.positions, cell=atoms.cell,
                 pbc=atoms.pbc, celldisp=atoms.get_celldisp())
    for name in arrays:
        if name in atoms.arrays:
            view.arrays[name] = atoms.arrays[name].copy()
    view.info.update(info or {})
    return view


class ViewerTrajectory:
    """Append frames of ``atoms`` to an extxyz file, e.g. as an MD observer::

        traj = ViewerTrajectory("run.extxyz", atoms)
        dyn.attach(traj, interval=100)

    Each frame carries the per-atom ``arrays`` (colour by them in ``ase gui``)
    and, in its comment line, the step and kinetic energy.
    """

    def __init__(self, filename: str, atoms: Atoms,
                 arrays: Sequence[str] = ("damage", "nbonds"), mode: str = "w"):
        self.atoms = atoms
        self.arrays = tuple(arrays)
        self._file = open(filename, mode)
        self.frames = 0

    def write(self, **info) -> None:
        """Write the current state as one frame, with ``info`` in its header."""
        info = {"step": int(self.atoms.info.get("bpm_step", 0)),
                "kinetic_energy": float(self.atoms.get_kinetic_energy()), **info}
        write(self._file, viewing_copy(self.atoms, self.arrays, info), format="extxyz")
        self._file.flush()
        self.frames += 1

    __call__ = write

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
