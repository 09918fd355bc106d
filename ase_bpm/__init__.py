"""ase_bpm: LAMMPS bonded-particle models as ASE calculators.

* :class:`BPMSpring` -- ``bond_style bpm/spring`` + ``pair_style bpm/spring``
* :class:`BPMPeri` -- peridynamics (pmb, lps, ves, eps) as bonds, ``bpm/peri``
* :class:`Granular` -- frictional spheres, ``gran/hooke``, ``gran/hooke/history``,
  ``gran/hertz/history``; with :class:`ase_bpm.md.SphereVelocityVerlet`
  (``fix nve/sphere``), :class:`Gravity` and :class:`GranularWall`
* :func:`create_bonds` -- ``create_bonds many``; :func:`get_bonds` -- bonds as arrays;
  :func:`take_bonds`, :func:`renew_ids`, :func:`repeat` -- bonds through ASE's
  atom operations (:mod:`ase_bpm.bonds`)
* :func:`write_restart` / :func:`read_restart` -- lossless simulation state
* :class:`ViewerTrajectory` -- extxyz frames that ``ase gui`` colours by damage
"""

from .bonds import create_bonds, get_bonds, renew_ids, repeat, take_bonds
from .calculator import BPMCalculator
from .fixes import Gravity, GranularWall, SphericalIndenter
from .granular import Granular
from .restart import read_restart, write_restart
from .peri import BPMPeri
from .spring import BPMSpring
from .spheres import rotational_energy
from .viewing import ViewerTrajectory

__version__ = "0.1.0"

__all__ = ["BPMCalculator", "BPMPeri", "BPMSpring", "Granular", "Gravity", "GranularWall",
           "SphericalIndenter", "ViewerTrajectory", "create_bonds", "get_bonds",
           "read_restart", "renew_ids", "repeat", "rotational_energy", "take_bonds",
           "write_restart"]
