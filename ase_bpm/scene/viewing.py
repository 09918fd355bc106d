"""Trajectories for looking at: extxyz frames for ``ase gui`` and OVITO.

:class:`ViewerTrajectory` writes, per frame, what a viewer shows: the
positions, elements and cell, the particles' radius and the chosen per-atom
outputs (by default ``damage`` and ``nbonds``), with the step and kinetic
energy in the comment line.  It never writes the calculator's state (names
starting ``bpm_``, ``bond_``, ``gran_``, ``peri_``: bonds, contact history,
the record of the last evaluation), so the file stays small and the colour
menus short.  For restarts use :func:`ase_bpm.write_restart`: extxyz keeps 8
decimals only.

What each viewer makes of the columns:

* ``ase gui`` offers "By user-defined <key>" colouring (View -> Colors) for
  every per-atom array, e.g. ``damage``; it draws every particle at the size
  of its element and ignores ``radius``.
* OVITO maps a column named ``radius`` to its standard property ``Radius``
  (the particles are drawn at their size), ``velo`` to ``Velocity`` and
  ``omega`` to ``Angular Velocity``, ``stress`` to ``Stress Tensor`` (ASE's
  own extxyz reader hands that column to the frame's calculator, as
  ``frame.calc.results["stress"]``); ``damage``, ``nbonds`` and ``ncontacts``
  stay properties of their own name (Color coding modifier).  A column named
  ``type`` would become its ``Particle Type``, which the element column (ASE's
  ``species``) already gives: OVITO keeps the element, not the type.
"""

from __future__ import annotations

from typing import Sequence

import ase.io  # (ase.io.write looked up when called: works while ase.io is mid-import)
import numpy as np
from ase import Atoms

#: the calculator's state on the atoms starts with these (bonds, contact
#: history, the record of the last evaluation, PERI's reference state)
STATE_PREFIXES = ("bpm_", "bond_", "gran_", "peri_")
#: state under other names: lammps-data bond strings, the broken-bond log
STATE_NAMES = ("bonds", "broken_bonds")
#: the per-atom outputs a viewing frame carries unless told otherwise
OUTPUTS = ("damage", "nbonds")


def is_state(name: str) -> bool:
    """Is ``name`` (of ``atoms.arrays`` or ``atoms.info``) calculator state,
    which viewing files leave out?"""
    return name.startswith(STATE_PREFIXES) or name in STATE_NAMES


def _refuse_state(names, where: str) -> None:
    for name in names:
        if is_state(name):
            raise ValueError(f"{where}[{name!r}] is calculator state, which viewing files "
                             "leave out; ase_bpm.write_restart keeps the whole state")


def display_radius(atoms: Atoms) -> np.ndarray | None:
    """The radius to draw each particle at (distance units): the spheres'
    ``radius``; for point particles with bonds, half their shortest reference
    bond length (half the lattice spacing of a lattice), the same for all;
    None without either (a viewer then draws the element's size)."""
    if "radius" in atoms.arrays:
        return atoms.arrays["radius"]
    r0 = atoms.arrays.get("bond_r0")
    if r0 is None:
        return None
    r0 = r0[np.isfinite(r0) & (r0 > 0)]  # (NaN or ASE's 0: no reference length yet)
    if not r0.size:
        return None
    return np.full(len(atoms), 0.5 * float(r0.min()))


def viewing_copy(atoms: Atoms, arrays: Sequence[str] = OUTPUTS, info: dict | None = None,
                 velocities: bool = False, stress: bool = False) -> Atoms:
    """What a viewer shows of ``atoms``: positions, elements, cell, the
    :func:`display_radius` as ``radius``, the named per-atom ``arrays`` (those
    present), with ``velocities`` their velocities as ``velo`` (distance/time),
    with ``stress`` the per-atom stress of the calculator's analysis
    (``calc.analyse``: LAMMPS ``compute stress/atom``, six columns ``xx yy zz
    xy xz yz`` in pressure times volume), and ``info``.  Calculator state is
    refused (ValueError naming it)."""
    _refuse_state(arrays, "atoms.arrays")
    _refuse_state(info or {}, "info")
    view = Atoms(numbers=atoms.numbers, positions=atoms.positions, cell=atoms.cell,
                 pbc=atoms.pbc, celldisp=atoms.get_celldisp())
    radius = display_radius(atoms)
    if radius is not None:
        view.arrays["radius"] = np.array(radius, dtype=float)
    for name in arrays:
        if name in atoms.arrays:
            view.arrays[name] = atoms.arrays[name].copy()
    if velocities:
        view.arrays["velo"] = atoms.get_velocities()
    if stress:
        analyse = getattr(atoms.calc, "analyse", None)
        if analyse is None:
            raise ValueError(f"stress=True needs a calculator with analyse(), not "
                             f"{type(atoms.calc).__name__}")
        view.arrays["stress"] = analyse(atoms).stress_n6
    view.info.update(info or {})
    return view


class ViewerTrajectory:
    """Append frames of ``atoms`` to an extxyz file, e.g. as an MD observer::

        traj = ViewerTrajectory("run.extxyz", atoms)
        dyn.attach(traj, interval=100)

    Each frame carries the particles' radius, the per-atom ``arrays``
    (colour by them in ``ase gui`` or OVITO), with ``velocities=True`` the
    velocities (column ``velo``), with ``stress=True`` the per-atom stress
    (column ``stress``, from ``calc.analyse``), and, in its comment line, the
    step and kinetic energy (see :func:`viewing_copy`).
    """

    def __init__(self, filename: str, atoms: Atoms, arrays: Sequence[str] = OUTPUTS,
                 mode: str = "w", velocities: bool = False, stress: bool = False):
        _refuse_state(arrays, "atoms.arrays")
        self.atoms = atoms
        self.arrays = tuple(arrays)
        self.velocities = bool(velocities)
        self.stress = bool(stress)
        self._file = open(filename, mode)
        self.frames = 0

    def write(self, **info) -> None:
        """Write the current state as one frame, with ``info`` in its header."""
        info = {"step": int(self.atoms.info.get("bpm_step", 0)),
                "kinetic_energy": float(self.atoms.get_kinetic_energy()), **info}
        ase.io.write(self._file, viewing_copy(self.atoms, self.arrays, info, self.velocities,
                                              self.stress), format="extxyz")
        self._file.flush()
        self.frames += 1

    __call__ = write

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
