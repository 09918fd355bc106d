"""ase_bpm: LAMMPS bonded-particle models as ASE calculators.

The public API is the names below (``ase_bpm.__all__``) and the module
:mod:`ase_bpm.laws.bond` (a bond law of your own); every other module is
internal.

* :class:`BPMSpring` -- ``bond_style bpm/spring`` + ``pair_style bpm/spring``
* :class:`BPMPeri` -- peridynamics (pmb, lps, ves, eps) as bonds, ``bpm/peri``
* :class:`Granular` -- frictional spheres, ``gran/hooke``, ``gran/hooke/history``,
  ``gran/hertz/history``
* fixes: :class:`SphericalIndenter`, :class:`Gravity`, :class:`GranularWall`;
  :func:`register_fix` for a fix class of your own
* integrators: :class:`VelocityVerlet` (``fix nve``) and
  :class:`SphereVelocityVerlet` (``fix nve/sphere``), ASE's algorithm that
  announces each step to the calculator
* :func:`create_bonds` -- ``create_bonds many``; :func:`get_bonds` -- bonds as arrays;
  :func:`take_bonds`, :func:`renew_ids`, :func:`repeat`, :func:`pad_bonds`,
  :func:`with_bond_strings` -- bonds through ASE's atom operations and files
* :func:`pure` -- evaluations without side effects (optimisers, vibrations, NEB)
* :func:`write_restart` / :func:`read_restart` -- lossless simulation state;
  :func:`calculator_from_dict` -- a calculator from ASE's stored ``todict()``
* :func:`write_lammps` / :func:`read_lammps` -- the scene as a LAMMPS data file and deck, and back;
  :func:`run_lammps` -- every run of a deck (``ase-bpm run``); :class:`LostAtoms` --
  atoms leaving a box with fixed faces removed, as LAMMPS removes them
* :class:`ViewerTrajectory` -- extxyz frames that ``ase gui`` colours by damage
* :func:`set_threads` -- threads for the compiled kernels

The package has four layers, each importing only from those before it
(``docs/architecture.md``): ``core`` (per-atom arrays, bond storage, neighbour
search) -> ``laws`` (force laws, pure functions over arrays) -> ``models`` (the
calculators) -> ``scene`` (fixes, integrators, restart, LAMMPS export, demos,
command line).
"""

from .core.bonds import (NoBondsCreatedWarning, create_bonds, get_bonds, pad_bonds, renew_ids,
                         repeat, take_bonds, with_bond_strings)
from .core.old_paths import install as _install_old_paths, old_path_attribute as _old_path
from .core.spheres import rotational_energy
from .laws.compiled import set_threads
from .laws.rotational import RotatedReferenceWarning
from .models.base import (BPMCalculator, OptimiserStepWarning, SpinNotIntegratedWarning,
                          TimestepUncheckedWarning, TimestepWarning, UnstableSimulationError,
                          pure, register_fix)
from .models.bonded import NoBondsWarning
from .models.granular import Granular
from .models.peri import BPMPeri
from .models.spring import BPMSpring
from .scene.aseio import calculator_from_dict
from .scene.fixes import Gravity, GranularWall, SphericalIndenter
from .scene.lammps import write_lammps
from .scene.lammps_commands import IgnoredCommandsWarning
from .scene.lammps_read import read_lammps
from .scene.md import SphereVelocityVerlet, VelocityVerlet
from .scene.restart import read_restart, write_restart
from .scene.viewing import ViewerTrajectory
from .scene.lammps_run import run_lammps
from .scene.lammps_stages import LaterRunsWarning
from .scene.lost_atoms import LostAtoms, LostAtomsWarning

from .core._version import __version__  # noqa: F401

__all__ = [
    "BPMCalculator",
    "BPMPeri",
    "BPMSpring",
    "calculator_from_dict",
    "create_bonds",
    "get_bonds",
    "Granular",
    "GranularWall",
    "Gravity",
    "IgnoredCommandsWarning",
    "LaterRunsWarning",
    "LostAtoms",
    "LostAtomsWarning",
    "NoBondsCreatedWarning",
    "NoBondsWarning",
    "OptimiserStepWarning",
    "pad_bonds",
    "pure",
    "read_lammps",
    "read_restart",
    "register_fix",
    "renew_ids",
    "repeat",
    "RotatedReferenceWarning",
    "rotational_energy",
    "run_lammps",
    "set_threads",
    "SphereVelocityVerlet",
    "SphericalIndenter",
    "SpinNotIntegratedWarning",
    "take_bonds",
    "TimestepUncheckedWarning",
    "TimestepWarning",
    "UnstableSimulationError",
    "VelocityVerlet",
    "ViewerTrajectory",
    "with_bond_strings",
    "write_lammps",
    "write_restart",
]

#: import paths of ase_bpm 0.1 (``ase_bpm.md``, ``ase_bpm.lammps``...) keep working,
#: with a DeprecationWarning naming the public path (:mod:`ase_bpm.core.old_paths`)
_install_old_paths()


def __getattr__(name: str):
    return _old_path(name)
