"""What LAMMPS users compute for analysis, as typed arrays.

A calculator's ``analyse(atoms)`` gives, at the atoms' state and without
changing it (nothing breaks, no history advances, nothing is written):

* :class:`BondLocal`, per intact bond: LAMMPS ``compute bond/local dist force
  fx fy fz`` with the strain beside them;
* :class:`PairLocal`, per touching pair of the contact law: ``compute
  pair/local dist force fx fy fz``;
* the per-atom stress, ``compute stress/atom NULL``: ``-(m v v + W)`` per atom
  with ``W`` half the virial ``r f`` of each bond and pair it takes part in,
  in LAMMPS' order ``xx yy zz xy xz yz`` and units (pressure times volume,
  i.e. energy: divide by a volume per atom for a stress).

The sign of ``force`` is LAMMPS': negative where the two particles pull
each other together (a stretched bond), positive where they push apart.
``fx fy fz`` are the force on the first particle, ``i``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

#: LAMMPS' order of the six components of a symmetric tensor
VOIGT_ROWS, VOIGT_COLS = np.array([0, 1, 2, 0, 0, 1]), np.array([0, 1, 2, 1, 2, 2])


@dataclass(frozen=True)
class BondLocal:
    """Per intact bond (``_b``): the two particles, the type, the length, the
    strain ``(r - r0) / r0``, LAMMPS' signed ``force`` and the force on ``i``;
    the reference length ``r0_b`` (LAMMPS ``b1`` of the bpm bond styles);
    where the model has ``bpm/spring/plastic`` bonds, their plastic strain
    as of the last step, ``plastic_b`` (NaN for bonds of other laws; LAMMPS
    ``b2`` is ``(1 + plastic) r0``); ``extra``, what a law gives beyond
    these (bonds of other laws: zero), for ``bpm/rotational`` as LAMMPS's
    ``bond/local`` of it does: the reference direction ``r0_dir_bc`` (from
    ``i`` to ``j`` in the reference state) and the torques on the two
    particles, ``torque_i_bc`` and ``torque_j_bc``."""

    i_b: np.ndarray
    j_b: np.ndarray
    type_b: np.ndarray
    length_b: np.ndarray
    strain_b: np.ndarray
    force_b: np.ndarray
    f_bc: np.ndarray
    r0_b: np.ndarray | None = None
    plastic_b: np.ndarray | None = None
    extra: dict = field(default_factory=dict)


@dataclass(frozen=True)
class PairLocal:
    """Per touching pair (``_p``): the two particles, the distance, LAMMPS'
    signed ``force`` (along the line of centres) and the force on ``i``;
    for frictional contacts its tangential part ``ft_pc`` (LAMMPS' gran
    ``pair/local`` gives the normal part as ``fx fy fz``, the tangential
    one as ``p1 p2 p3``), else None."""

    i_p: np.ndarray
    j_p: np.ndarray
    dist_p: np.ndarray
    force_p: np.ndarray
    f_pc: np.ndarray
    ft_pc: np.ndarray | None = None


@dataclass(frozen=True)
class Analysis:
    """A calculator's ``analyse(atoms)``: bonds, pairs (None where the model
    has none) and the per-atom stress, ``stress_n6``."""

    bonds: BondLocal | None
    pairs: PairLocal | None
    stress_n6: np.ndarray


def signed_force(r_xc: np.ndarray, f_xc: np.ndarray) -> tuple:
    """``(length_x, force_x)`` of pair vectors ``r = x_j - x_i`` with forces
    ``f`` on ``i``: LAMMPS' ``force``, ``-(f . r) / |r|``."""
    length_x = np.sqrt(np.einsum("xc,xc->x", r_xc, r_xc))
    force_x = -np.divide(np.einsum("xc,xc->x", f_xc, r_xc), length_x,
                         out=np.zeros_like(length_x), where=length_x > 0)
    return length_x, force_x


def bond_local(bonds, r_bc: np.ndarray, f_bc: np.ndarray, r0_b: np.ndarray,
               plastic_b: np.ndarray | None = None,
               extra: Optional[dict] = None) -> BondLocal:
    """:class:`BondLocal` of a bond set (its ``i_b``, ``j_b``, ``type_b``),
    the bond vectors ``r = x_j - x_i``, the forces on ``i``, the reference
    lengths, the plastic strains (None: no plastic bonds) and the laws'
    ``extra`` per-bond quantities."""
    length_b, force_b = signed_force(r_bc, f_bc)
    return BondLocal(bonds.i_b, bonds.j_b, bonds.type_b, length_b, (length_b - r0_b) / r0_b,
                     force_b, f_bc, r0_b, plastic_b, dict(extra or {}))


def pair_local(sums) -> PairLocal:
    """:class:`PairLocal` of the touching pairs of a contact law's sums
    (:class:`ase_bpm.laws.contact.ContactSums`)."""
    return PairLocal(sums.i_p, sums.j_p, *signed_force(sums.r_pc, sums.f_pc), sums.f_pc)


def add_pair_virials(w_n6: np.ndarray, i_x, j_x, r_xc, f_xc, fj_xc=None) -> None:
    """Each pair's virial to its two particles, in place (LAMMPS' per-atom
    virial of a bond or pair): ``i`` gets half of ``(x_i - x_j) (x) f_i``,
    ``j`` half of ``(x_j - x_i) (x) f_j``, ``f_j = fj_xc`` (default
    ``-f_i``: then each gets half of the same)."""
    vi_x6 = -r_xc[:, VOIGT_ROWS] * f_xc[:, VOIGT_COLS]
    vj_x6 = vi_x6 if fj_xc is None else r_xc[:, VOIGT_ROWS] * fj_xc[:, VOIGT_COLS]
    for column in range(6):
        w_n6[:, column] += 0.5 * (np.bincount(i_x, vi_x6[:, column], minlength=len(w_n6))
                                  + np.bincount(j_x, vj_x6[:, column], minlength=len(w_n6)))


def stress_per_atom(masses_n, v_nc, w_n6) -> np.ndarray:
    """``-(m v v + W)`` per atom (LAMMPS ``compute stress/atom NULL``)."""
    kinetic_n6 = masses_n[:, None] * v_nc[:, VOIGT_ROWS] * v_nc[:, VOIGT_COLS]
    return -(kinetic_n6 + w_n6)
