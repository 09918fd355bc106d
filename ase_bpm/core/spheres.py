"""Finite-size spheres on ASE atoms: radius, angular velocity, inertia.

ASE atoms are points.  Granular particles are spheres, as in LAMMPS
``atom_style sphere``: each carries a radius (``atoms.arrays["radius"]``;
LAMMPS stores the diameter) and an angular velocity (``atoms.arrays["omega"]``,
N x 3, radians per time unit).  The mass is the atom's mass; the moment of
inertia that of a solid sphere, ``I = 2/5 m r^2`` (LAMMPS ``fix nve/sphere``).

Particles of ``atom_style bpm/sphere`` also carry an orientation: a unit
quaternion per atom (``atoms.arrays["quat"]``, N x 4, in LAMMPS's component
order ``(w, i, j, k)``; the identity ``(1, 0, 0, 0)`` when absent), which
rotational bonds measure bending and twisting against and
:class:`ase_bpm.SphereVelocityVerlet` turns with ``omega`` (LAMMPS ``fix
nve/bpm/sphere``).

Particles held by ASE's ``FixAtoms`` count as LAMMPS ``fix freeze`` does: they
do not move or spin, and a contact with one has the effective mass of the
other particle alone.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms

from .arrays import all_finite, first_non_finite, same_array
from .quaternions import IDENTITY

RADIUS, OMEGA, QUAT = "radius", "omega", "quat"
#: how far from 1 the norm of a given orientation may be (LAMMPS data files
#: hold quaternions to the digits written; ase_bpm's integrator keeps them
#: normalised to round-off)
QUAT_NORM_TOLERANCE = 1e-6
#: moment of inertia of a solid sphere in units of m r^2
SOLID_SPHERE = 0.4


def radii(atoms: Atoms, who: str = "granular contacts") -> np.ndarray:
    """``atoms.arrays["radius"]``, checked: one finite positive number per atom."""
    r_n = atoms.arrays.get(RADIUS)
    if r_n is None:
        raise ValueError(f'{who}: atoms.arrays["radius"] (the sphere radius of each atom) '
                         'is missing')
    kept = _checked_radii[0]
    if kept is not None and r_n.shape == (len(atoms),) and same_array(kept, r_n):
        return _checked_radii[1]  # the same values as the last radii checked
    if r_n.shape != (len(atoms),) or not np.issubdtype(r_n.dtype, np.number):
        raise ValueError(f'atoms.arrays["radius"] must hold one number per atom, got '
                         f'shape {r_n.shape} and dtype {r_n.dtype}')
    if not np.all((r_n > 0) & (r_n < np.inf)):  # one pass when all is well
        atom = int(np.argmax(~((r_n > 0) & (r_n < np.inf))))
        raise ValueError(f'atoms.arrays["radius"] of atom {atom} is {r_n[atom]}: radii must '
                         'be positive and finite')
    checked = r_n.astype(float)  # a copy, kept with the values it was checked as
    checked.flags.writeable = False
    _checked_radii[:] = [r_n.copy(), checked]
    return checked


#: the radii checked last, as given and as returned (scenes keep their radii)
_checked_radii = [None, None]


def angular_velocities(atoms: Atoms) -> np.ndarray:
    """``atoms.arrays["omega"]`` (zeros when absent), checked: N x 3, finite."""
    w_nc = atoms.arrays.get(OMEGA)
    if w_nc is None:
        return np.zeros((len(atoms), 3))
    return _finite_rows(atoms, OMEGA, 3, "angular velocities").astype(float, copy=False)


def _finite_rows(atoms: Atoms, name: str, width: int, what: str) -> np.ndarray:
    """``atoms.arrays[name]``, checked: N x ``width`` numbers (``what``), all
    finite; ValueError naming the array, or the first atom not finite."""
    x_nw = atoms.arrays[name]
    if x_nw.shape != (len(atoms), width) or not (x_nw.dtype == np.float64
                                                 or np.issubdtype(x_nw.dtype, np.number)):
        raise ValueError(f'atoms.arrays["{name}"] must be an N x {width} array of {what} '
                         f'(N = {len(atoms)}), got shape {x_nw.shape} and dtype {x_nw.dtype}')
    if not all_finite(x_nw):
        atom = first_non_finite(x_nw)
        raise ValueError(f'atoms.arrays["{name}"] of atom {atom} is not finite: {x_nw[atom]}')
    return x_nw


def orientations(atoms: Atoms) -> np.ndarray:
    """``atoms.arrays["quat"]`` (the identity for every atom when absent),
    checked: N x 4 ``(w, i, j, k)``, finite, of unit norm within
    :data:`QUAT_NORM_TOLERANCE`."""
    q_nq = atoms.arrays.get(QUAT)
    if q_nq is None:
        return np.tile(IDENTITY, (len(atoms), 1))
    _finite_rows(atoms, QUAT, 4, "unit quaternions (w, i, j, k)")
    norm_n = np.sqrt(np.einsum("nq,nq->n", q_nq, q_nq))
    off = np.abs(norm_n - 1.0) > QUAT_NORM_TOLERANCE
    if off.any():
        atom = int(np.argmax(off))
        if norm_n[atom] == 0.0:  # (what ASE puts in the rows of atoms added without one)
            raise ValueError(f'atoms.arrays["quat"] of atom {atom} is all zero, as ASE fills '
                             'the rows of atoms that had no orientation when atoms were '
                             'added (a + b, extend, where b has no "quat"): give b its '
                             'orientations before adding it (the identity: '
                             'b.arrays["quat"] = np.tile([1.0, 0.0, 0.0, 0.0], (len(b), 1)))')
        raise ValueError(f'atoms.arrays["quat"] of atom {atom} is {q_nq[atom]}, of norm '
                         f'{norm_n[atom]:.9g}: orientations must be unit quaternions '
                         '(w, i, j, k); divide each row by its norm')
    return q_nq.astype(float, copy=False)


def frozen(atoms: Atoms) -> np.ndarray | None:
    """Mask of the atoms held by ``FixAtoms`` (None when there are none)."""
    mask = None
    for constraint in atoms.constraints:
        if isinstance(constraint, FixAtoms):
            if mask is None:
                mask = np.zeros(len(atoms), dtype=bool)
            mask[constraint.index] = True
    return mask


def moments_of_inertia(atoms: Atoms) -> np.ndarray:
    """``2/5 m r^2`` of every sphere (mass x distance^2)."""
    return SOLID_SPHERE * atoms.get_masses() * radii(atoms, "rotating spheres") ** 2


def rotational_energy(atoms: Atoms) -> float:
    """Kinetic energy of rotation, ``sum 1/2 I omega^2`` (0 without ``omega``)."""
    if OMEGA not in atoms.arrays:
        return 0.0
    return spin_energy(atoms.get_masses(), radii(atoms, "rotating spheres"),
                       angular_velocities(atoms))


def spin_energy(m_n: np.ndarray, r_n: np.ndarray, w_nc: np.ndarray) -> float:
    """``sum 1/2 I omega^2`` of solid spheres of masses ``m_n`` and radii
    ``r_n`` turning at ``w_nc``."""
    return float(0.5 * np.sum(SOLID_SPHERE * m_n * r_n ** 2 * np.einsum("nc,nc->n", w_nc, w_nc)))
