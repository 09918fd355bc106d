"""Force kernels: pure vectorised functions over bond and pair arrays."""

from .spring import SpringForces, lengths, spring_bonds, spring_pairs

__all__ = ["SpringForces", "lengths", "spring_bonds", "spring_pairs"]
