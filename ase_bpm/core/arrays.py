"""Per-atom inputs every model reads, checked, with errors that name the atom.

The names of the per-atom arrays live with what they describe:
:mod:`ase_bpm.core.bonds` (``bpm_id``, ``bond_*``), :mod:`ase_bpm.core.spheres`
(``radius``, ``omega``); particle types are ``atoms.arrays["type"]``.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms

TYPE = "type"  # LAMMPS atom type of each particle (all 1 when absent)


def require_finite(name: str, values: np.ndarray) -> None:
    """Raise ``ValueError`` naming the array and the first bad atom."""
    bad = ~np.isfinite(values)
    if bad.any():
        atom = np.argwhere(bad)[0][0]
        raise ValueError(f"{name} of atom {atom} is not finite: {values[atom]}")


def particle_types(atoms: Atoms) -> np.ndarray:
    """``atoms.arrays["type"]`` (all 1 when absent), checked to be ints >= 1."""
    if "type" not in atoms.arrays:
        return np.ones(len(atoms), dtype=np.int64)
    types = atoms.arrays["type"]
    if types.ndim != 1 or not (np.issubdtype(types.dtype, np.integer)
                               or np.all(np.mod(types, 1) == 0)):
        raise ValueError('atoms.arrays["type"] must hold one integer per atom')
    types = types.astype(np.int64)
    if len(types) and types.min() < 1:
        atom = int(np.argmin(types))
        raise ValueError(f'particle type {types[atom]} of atom {atom} is invalid: '
                         'types are integers >= 1')
    return types


def velocities(atoms: Atoms) -> np.ndarray:
    """Velocities from momenta and masses, checked to be finite; zero for
    atoms held by ``FixAtoms`` (which do not move, whatever momenta they carry)."""
    from .spheres import frozen

    masses = atoms.get_masses()
    if len(masses) and not masses.min() > 0:
        atom = int(np.argmin(masses))
        raise ValueError(f"mass of atom {atom} is {masses[atom]}: masses must be positive")
    v_nc = atoms.get_velocities()
    require_finite("velocity", v_nc)
    hold = frozen(atoms)
    if hold is not None:
        v_nc[hold] = 0.0
    return v_nc


def same_array(a, b) -> bool:
    """Both absent, or arrays with the same bytes (so NaN equals NaN).

    Raw memory is compared in 8-byte words: for strings much faster than a
    string comparison.
    """
    if a is None or b is None:
        return a is None and b is None
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    a, b = np.ascontiguousarray(a).reshape(-1), np.ascontiguousarray(b).reshape(-1)
    word = np.uint64 if a.nbytes % 8 == 0 else np.uint8
    return bool(np.array_equal(a.view(np.uint8).view(word), b.view(np.uint8).view(word)))
