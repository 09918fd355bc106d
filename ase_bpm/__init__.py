"""ase_bpm: LAMMPS bonded-particle models as ASE calculators.

* :class:`BPMSpring` -- ``bond_style bpm/spring`` + ``pair_style bpm/spring``
* :class:`BPMPeri` -- peridynamics (pmb, lps, ves, eps) as bonds, ``bpm/peri``
* :class:`Granular` -- frictional spheres, ``gran/hooke``, ``gran/hooke/history``,
  ``gran/hertz/history``; with :class:`ase_bpm.md.SphereVelocityVerlet`
  (``fix nve/sphere``), :class:`Gravity` and :class:`GranularWall`
* :func:`create_bonds` -- ``create_bonds many``; :func:`get_bonds` -- bonds as arrays;
  :func:`take_bonds`, :func:`renew_ids`, :func:`repeat` -- bonds through ASE's
  atom operations (:mod:`ase_bpm.core.bonds`)
* :func:`pure` -- evaluations without side effects (optimisers, vibrations, NEB)
* :func:`write_restart` / :func:`read_restart` -- lossless simulation state
* :func:`write_lammps` / :func:`read_lammps` -- the scene as a LAMMPS data file and deck, and back
* :class:`ViewerTrajectory` -- extxyz frames that ``ase gui`` colours by damage

The package has four layers, each importing only from those before it
(``docs/architecture.md``): ``core`` (per-atom arrays, bond storage, neighbour
search) -> ``laws`` (force laws, pure functions over arrays) -> ``models`` (the
calculators) -> ``scene`` (fixes, integrators, restart, LAMMPS export, demos,
command line).
"""

import importlib
import sys

from .core.bonds import create_bonds, get_bonds, pad_bonds, renew_ids, repeat, take_bonds
from .core.spheres import rotational_energy
from .models.base import BPMCalculator, SpinNotIntegratedWarning, UnstableSimulationError, pure
from .models.base import (OptimiserStepWarning, TimestepUncheckedWarning,
                          TimestepWarning)
from .models.bonded import NoBondsWarning
from .models.granular import Granular
from .models.peri import BPMPeri
from .models.spring import BPMSpring
from .scene.fixes import Gravity, GranularWall, SphericalIndenter
from .scene.lammps import write_lammps
from .scene.lammps_read import read_lammps
from .scene.restart import read_restart, write_restart
from .scene.viewing import ViewerTrajectory

from .core._version import __version__  # noqa: F401

__all__ = ["BPMCalculator", "BPMPeri", "BPMSpring", "create_bonds", "get_bonds",
           "Granular", "GranularWall", "Gravity", "NoBondsWarning", "pad_bonds", "pure",
           "read_lammps", "read_restart", "renew_ids", "repeat", "rotational_energy",
           "SphericalIndenter", "SpinNotIntegratedWarning", "take_bonds",
           "UnstableSimulationError", "ViewerTrajectory", "write_lammps", "write_restart",
           "OptimiserStepWarning", "TimestepUncheckedWarning", "TimestepWarning"]

#: import paths of ase_bpm 0.1 (``ase_bpm.md``, ``ase_bpm.lammps``...), kept working:
#: each is the same module object as its new home
OLD_PATHS = {
    "bonds": "core.bonds", "neighbours": "core.neighbours", "params": "core.params",
    "spheres": "core.spheres",
    "kernels": "laws", "kernels.spring": "laws.spring", "kernels.peri": "laws.peri",
    "kernels.granular": "laws.granular", "kernels.compiled": "laws.compiled",
    "calculator": "models.base", "bondstate": "models.bonded", "contacts": "models.contacts",
    "spring": "models.spring", "peri": "models.peri", "granular": "models.granular",
    "fixes": "scene.fixes", "md": "scene.md", "restart": "scene.restart",
    "lammps": "scene.lammps", "viewing": "scene.viewing", "cli": "scene.cli",
    "demos": "scene.demos", "demos.impact": "scene.demos.impact",
    "demos.pour": "scene.demos.pour", "demos.shatter": "scene.demos.shatter",
}
for _old, _new in OLD_PATHS.items():
    _module = importlib.import_module(f"{__name__}.{_new}")
    sys.modules[f"{__name__}.{_old}"] = _module
    if "." not in _old:
        globals()[_old] = _module
del _old, _new, _module
