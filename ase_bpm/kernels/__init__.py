"""Force kernels: pure vectorised functions over bond and pair arrays."""

from .spring import SpringForces, bond_strain, spring_bonds, spring_pairs

__all__ = ["SpringForces", "bond_strain", "spring_bonds", "spring_pairs"]
