"""Export an ase_bpm scene to LAMMPS: a data file and an input deck.

BPMSpring scenes go to ``bond_style``/``pair_style bpm/spring`` (with
``atom_style bpm/sphere`` and ``fix nve/sphere`` when granular walls touch
them); Granular scenes to ``pair_style gran/hooke``, ``gran/hooke/history`` or
``gran/hertz/history`` (``atom_style sphere``); BPMPeri scenes to
``bond_style``/``pair_style bpm/peri`` (``atom_style bond``) or, following
the legacy styles, to ``peri/pmb``, ``peri/lps``, ``peri/ves`` or
``peri/eps`` (``atom_style peri``), the peridynamics of the reference LAMMPS
build, which bonds every pair of nodes within the horizon by itself: each
written by :mod:`.lammps_export`.  Gravity, granular
walls, the spherical indenter and ``FixAtoms`` go over as ``fix gravity``,
``fix wall/gran``, ``fix indent`` and ``fix freeze`` (``fix setforce`` for
point particles).

A scene built and tested with ase_bpm moves to LAMMPS (for MPI runs) unchanged:
:func:`write_lammps` writes ``<name>.data`` (``atom_style bond``: box, masses,
types, positions, velocities and intact bonds, all floats to full precision)
and ``in.<name>`` (units, boundaries, special bonds, the bond and pair styles
with the calculator's coefficients, neighbour skin, ``fix nve`` and the
timestep).  ase_bpm uses no unit conversions, so the numbers carry over as they
are into any consistent LAMMPS unit system: ``lj``, ``si``, ``cgs``, ``micro``
or ``nano``.

As with any LAMMPS data file, bond reference lengths are not part of it:
LAMMPS takes them at its first run.  Export before the first evaluation (or
when the current state may serve as the reference).

This module knows no model and no fix.  Each model's scene is written by
:mod:`.lammps_export`, beside the reader (``lammps_scene(atoms, calc,
data_file, units=..., timestep=..., thermo=...)`` returns a
:class:`ase_bpm.core.lammps_text.LammpsScene`: data file, commands, output
lines), each fix writes its own commands (``fix.lammps_commands(index,
force_per_lammps_force)``); the deck is the scene's commands, the fixes',
``FixAtoms``, the output and the run.  A new model brings its scene in
:data:`.lammps_export.SCENES`, a new fix its commands in its own class.
"""

from __future__ import annotations

import ctypes
import os
import sys
from typing import Sequence

import numpy as np
from ase import Atoms

# densities and units are names of this module too (for the tests)
from ..core import lammps_text
from ..core.lammps_text import (CONSISTENT_UNITS, LammpsScene,  # noqa: F401
                                sphere_densities, write_data)
from .lammps_commands import WRITTEN_BY
from .lammps_export import lammps_scene
from .lammps_read import read_lammps  # noqa: F401 (the way back, beside write_lammps)


#: how a deck written with ``driver_repairs_s0`` is run (its first line)
S0_REPAIR = ("from Python, repairing s0 before the run: run 0, s0 set to the largest double "
             "through extract_atom, run 0")


def load_lammps():
    """The ``lammps`` Python class (pip ``lammps[mpi]``), ready to use.

    The MPICH wheel's ``libmpi.so.12`` is not on the loader path; it is loaded
    first, globally.  Usage: ``lmp = load_lammps()(cmdargs=["-screen", "none"])``.
    """
    libmpi = os.path.join(sys.prefix, "lib", "libmpi.so.12")
    if os.path.exists(libmpi):
        ctypes.CDLL(libmpi, mode=ctypes.RTLD_GLOBAL)
    from lammps import lammps

    return lammps


def scene_commands(atoms: Atoms, calc, scene: LammpsScene) -> list[str]:
    """The scene's commands, then those of the calculator's fixes and of
    ``FixAtoms``: a deck without output and run."""
    return [*scene.commands, *fix_commands(calc.fixes, scene.force_per_lammps_force),
            *freeze_commands(atoms, scene.spheres)]


def write_lammps(name: str, atoms: Atoms, calc=None, *, timestep: float | None = None,
                 steps: int = 0, units: str | None = None, thermo: int = 100,
                 extra: Sequence[str] = (),
                 driver_repairs_s0: bool = False) -> tuple[str, str]:
    """Write ``<name>.data`` and ``in.<name>``, a deck that runs the scene.

    ``calc`` (default ``atoms.calc``) is a BPMSpring (bpm/spring styles, default
    ``units="lj"``), a Granular (``pair_style gran/*``, ``atom_style sphere``,
    ``fix nve/sphere``, default ``units="lj"``; a scene whose contacts hold
    shear history is refused: a data file has no place for it) or a BPMPeri
    (legacy ``peri/pmb``, default ``units="si"``; legacy PERI bonds every pair
    within the horizon itself and takes the reference at its first run, so
    export an unbroken scene): any calculator :data:`.lammps_export.SCENES`
    lists.
    What the files cannot express raises ValueError naming it.  ``steps`` is the ``run``
    length, ``timestep`` defaults to the calculator's; ``extra`` lines go just
    before the run.  BPMSpring with ``store_local`` dumps broken bonds every
    ``thermo`` steps to ``<name>.broken`` (columns as
    ``atoms.info["broken_bonds"]``, 1-based atom IDs); BPMPeri reports the
    mean damage in the thermo output.  Returns both paths.

    Legacy ``peri/lps``, ``peri/ves`` and ``peri/eps`` are refused: the
    reference LAMMPS leaves their breaking stretch ``s0`` unset at the first
    set-up and no command sets it.  ``driver_repairs_s0=True`` writes them
    anyway for a caller that runs the deck from Python and repairs ``s0``
    (``run 0``, ``s0`` set to the largest double through ``extract_atom``,
    ``run 0`` again; the deck's first line says so), as ``tests/peri_oracle.py``
    does.
    """
    calc = atoms.calc if calc is None else calc
    directory, base = os.path.split(name)
    data_path = os.path.join(directory, f"{base}.data")
    deck_path = os.path.join(directory, f"in.{base}")
    repair = {"driver_repairs_s0": True} if driver_repairs_s0 else {}
    scene = lammps_scene(atoms, calc, f"{base}.data", units=units, timestep=timestep,
                         thermo=thermo, **repair)
    if steps > 0 and not any(c.startswith("timestep ") for c in [*scene.commands, *extra]):
        raise ValueError(f"write_lammps: a run of {steps} steps needs a timestep (give "
                         "timestep=, or the calculator's): the deck would run LAMMPS's "
                         "default")
    after_thermo = [line for fix in calc.fixes
                    for line in getattr(fix, "lammps_after_thermo", list)()]
    cmds = [*scene_commands(atoms, calc, scene), *scene.thermo, f"thermo {thermo}",
            *after_thermo, *scene.dumps, *extra, f"run {steps}"]
    with open(data_path, "wb") as fh:
        write_data(fh, scene.data)
    with open(deck_path, "w") as fh:
        fh.write(f"{WRITTEN_BY}; run: "
                 + (S0_REPAIR if driver_repairs_s0 else f"lmp -in {os.path.basename(deck_path)}")
                 + "\n")
        fh.write("\n".join(cmds) + "\n")
    return data_path, deck_path


# -- the parts of a deck, per model (lammps_export.lammps_scene) ---------------------

def lammps_data(atoms: Atoms, calc) -> str:
    """The text of the scene's LAMMPS data file (for BPMSpring ``atom_style
    bond``, or ``bpm/sphere`` when the scene has granular walls)."""
    return str(lammps_scene(atoms, calc, "unused.data").data)


def peri_data(atoms: Atoms) -> str:
    """The text of a BPMPeri scene's data file (``atom_style peri``)."""
    return str(lammps_text.peri_data(atoms))


def granular_data(atoms: Atoms) -> str:
    """The text of a Granular scene's data file (``atom_style sphere``)."""
    return str(lammps_text.sphere_data(atoms))


def lammps_commands(atoms: Atoms, calc, data_file: str, *, units: str = "lj",
                    timestep: float | None = None, broken_bonds_fix: str | None = None,
                    every: int = 1) -> list[str]:
    """LAMMPS commands that set up a BPMSpring scene from ``data_file`` (no
    ``run``).

    ``broken_bonds_fix`` names a ``store/local`` fix that records broken bonds
    (``id1 id2 time x y z x/ref y/ref z/ref``), kept for ``every`` steps.
    """
    scene = lammps_scene(atoms, calc, data_file, units=units, timestep=timestep,
                         thermo=every, broken_bonds_fix=broken_bonds_fix)
    return scene_commands(atoms, calc, scene)


def peri_commands(atoms: Atoms, calc, data_file: str, *, units: str = "si",
                  timestep: float | None = None, spacing: float | None = None,
                  driver_repairs_s0: bool = False) -> list[str]:
    """LAMMPS commands for a BPMPeri scene in the legacy ``peri/<model>``
    style (``driver_repairs_s0``: see :func:`.lammps_export.legacy_peri_scene`)."""
    scene = lammps_scene(atoms, calc, data_file, units=units, timestep=timestep,
                         spacing=spacing, driver_repairs_s0=driver_repairs_s0)
    return scene_commands(atoms, calc, scene)


def granular_commands(atoms: Atoms, calc, data_file: str, *, units: str = "lj",
                      timestep: float | None = None) -> list[str]:
    """LAMMPS commands for a :class:`ase_bpm.Granular` scene (no ``run``):
    ``pair_style gran/<model>``, ``fix nve/sphere``, the fixes and ``fix
    freeze`` for ``FixAtoms``."""
    return scene_commands(atoms, calc, lammps_scene(atoms, calc, data_file, units=units,
                                                    timestep=timestep))


# -- fixes ---------------------------------------------------------------------------

def fix_commands(fixes, force_per_lammps_force: float = 1.0) -> list[str]:
    """LAMMPS commands for ase_bpm fixes, each written by the fix itself
    (``lammps_commands``): ``fix indent`` (SphericalIndenter), ``fix
    gravity`` (Gravity), ``fix wall/gran`` (GranularWall)...

    ``force_per_lammps_force`` converts ase_bpm's true forces to what LAMMPS
    adds to ``f``: 1 for ordinary styles, the node volume for legacy PERI,
    whose ``f`` holds force densities.
    """
    cmds = []
    for index, fix in enumerate(fixes):
        export = getattr(fix, "lammps_commands", None)
        if export is None:
            raise ValueError(f"no LAMMPS export for {type(fix).__name__} in this scene")
        cmds += export(index, force_per_lammps_force)
    return cmds


def freeze_commands(atoms: Atoms, spheres: bool = True) -> list[str]:
    """Hold the atoms of ``FixAtoms`` (none: no commands): ``fix freeze`` for
    spheres (which also counts in granular effective masses), ``fix
    setforce 0 0 0`` for point particles."""
    from ..core.spheres import frozen

    hold = frozen(atoms)
    if hold is None or not hold.any():
        return []
    ids = " ".join(str(i + 1) for i in np.flatnonzero(hold))
    hold_them = ("fix ase_bpm_freeze ase_bpm_frozen freeze" if spheres
                 else "fix ase_bpm_freeze ase_bpm_frozen setforce 0.0 0.0 0.0")
    return [f"group ase_bpm_frozen id {ids}", hold_them]
