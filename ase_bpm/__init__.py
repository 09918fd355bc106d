"""ase_bpm: LAMMPS bonded-particle models as ASE calculators.

* :class:`BPMSpring` -- ``bond_style bpm/spring`` + ``pair_style bpm/spring``
* :func:`create_bonds` -- ``create_bonds many``; :func:`get_bonds` -- bonds as arrays
* :func:`write_restart` / :func:`read_restart` -- lossless simulation state
* :class:`ViewerTrajectory` -- extxyz frames that ``ase gui`` colours by damage
"""

from .bonds import create_bonds, get_bonds
from .calculator import BPMCalculator
from .restart import read_restart, write_restart
from .spring import BPMSpring
from .viewing import ViewerTrajectory

__version__ = "0.1.0"

__all__ = ["BPMCalculator", "BPMSpring", "ViewerTrajectory", "create_bonds", "get_bonds",
           "read_restart", "write_restart"]
