"""Breakable bonds with a reference state, for any bond law.

LAMMPS equivalent: the machinery every BPM bond style shares (``BondBPM`` and
``fix BOND_HISTORY``): the reference length of each bond taken at its first
evaluation, breaking (type 0), the special list that keeps bonded pairs out of
the pair style, the ``store/local`` log of broken bonds and ``nbond/atom``.

:class:`BondState` keeps a compiled :class:`BondSet` of the intact bonds
between evaluations and rebuilds it only when the bonds on the atoms change.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import scipy.sparse
from ase import Atoms

from .bonds import BondTable, bond_table, format_atom_bonds
from .calculator import digest, same_array
from .neighbours import minimum_image

R0 = "bond_r0"  # per-bond reference length, NaN until the first evaluation
X_REF = "bpm_x_ref"  # per-atom reference position (for the broken-bond log)
BROKEN_LOG = "broken_bonds"  # info: one row per broken bond
BROKEN_LOG_COLUMNS = ("i", "j", "step", "x", "y", "z", "x_ref", "y_ref", "z_ref")


def pair_keys(i, j, natoms: int) -> np.ndarray:
    """One integer per unordered atom pair."""
    return np.minimum(i, j) * natoms + np.maximum(i, j)


@dataclass
class BondSet:
    """The intact bonds of a bond table, ready for the kernels."""

    table: BondTable
    natoms: int
    r0_rows: np.ndarray  # reference length per table row, NaN until taken
    r0_stale: bool  # atoms.arrays["bond_r0"] must be rewritten from r0_rows
    intact_b: np.ndarray = field(init=False)  # table rows of the intact bonds
    i_b: np.ndarray = field(init=False)
    j_b: np.ndarray = field(init=False)
    type_b: np.ndarray = field(init=False)
    digest: str = field(init=False)
    broken_keys: Optional[np.ndarray] = None  # pairs broken since `parent`
    parent: Optional[str] = None  # digest of the set this one came from
    cache: dict = field(default_factory=dict, init=False)  # per-model derived arrays
    _incidence: Optional[scipy.sparse.csr_matrix] = field(default=None, init=False)
    _difference: Optional[scipy.sparse.csr_matrix] = field(default=None, init=False)
    _bonded_keys: Optional[np.ndarray] = field(default=None, init=False)

    def __post_init__(self):
        t = self.table
        self.intact_b = np.flatnonzero(t.type_b > 0)
        self.i_b = t.owner_b[self.intact_b]
        self.j_b = t.partner_b[self.intact_b]
        self.type_b = t.type_b[self.intact_b]
        self.digest = digest(t.owner_b, t.partner_b, t.type_b)

    def __len__(self) -> int:
        return len(self.i_b)

    @property
    def incidence(self) -> scipy.sparse.csr_matrix:
        """Sparse ``(natoms, nbonds)`` matrix, +1 at ``i`` and -1 at ``j``:
        ``incidence @ f_bc`` sums bond forces (on ``i``) per atom."""
        if self._incidence is None:
            b = np.arange(len(self))
            self._incidence = scipy.sparse.csr_matrix(
                (np.r_[np.ones(len(b)), -np.ones(len(b))],
                 (np.r_[self.i_b, self.j_b], np.r_[b, b])),
                shape=(self.natoms, len(b)))
        return self._incidence

    def vectors(self, values_nc: np.ndarray) -> np.ndarray:
        """``values[j] - values[i]`` per bond (positions: bond vectors, velocities:
        relative velocities), through a cached sparse ``(nbonds, natoms)`` matrix."""
        if self._difference is None:
            self._difference = (-self.incidence.T).tocsr()
        return self._difference @ values_nc

    @property
    def bonded_keys(self) -> np.ndarray:
        """Sorted :func:`pair_keys` of the intact bonds."""
        if self._bonded_keys is None:
            self._bonded_keys = np.sort(pair_keys(self.i_b, self.j_b, self.natoms))
        return self._bonded_keys

    def r0_b(self) -> np.ndarray:
        """Reference lengths of the intact bonds (NaN where not yet taken)."""
        return self.r0_rows[self.intact_b]

    def bonded(self, keys: np.ndarray) -> np.ndarray:
        """Which of the pair ``keys`` are joined by an intact bond."""
        bonded = self.bonded_keys
        if len(bonded) == 0:
            return np.zeros(len(keys), dtype=bool)
        pos = np.minimum(np.searchsorted(bonded, keys), len(bonded) - 1)
        return bonded[pos] == keys


def _r0_from_slots(r0_nm, table: BondTable) -> np.ndarray:
    """Reference lengths of the table rows from ``bond_r0`` (slot-aligned)."""
    r0_rows = np.full(len(table), np.nan)
    if r0_nm is not None and r0_nm.ndim == 2 and len(table):
        inside = table.slot_b < r0_nm.shape[1]
        r0_rows[inside] = r0_nm[table.owner_b[inside], table.slot_b[inside]]
    return r0_rows


def _r0_by_pair(old: BondSet, table: BondTable, natoms: int) -> np.ndarray:
    """Reference lengths carried over from an earlier table, bond by bond."""
    old_key = pair_keys(old.table.owner_b, old.table.partner_b, natoms)
    order = np.argsort(old_key, kind="stable")
    r0_rows = np.full(len(table), np.nan)
    if len(order):
        new_key = pair_keys(table.owner_b, table.partner_b, natoms)
        pos = np.minimum(np.searchsorted(old_key[order], new_key), len(order) - 1)
        found = old_key[order][pos] == new_key
        r0_rows[found] = old.r0_rows[order][pos][found]
    return r0_rows


class BondState:
    """The bonds a calculator works with, cached between evaluations.

    ``check_types`` is called with every newly read table, to reject bond
    types the model has no coefficients for.
    """

    def __init__(self, check_types=None):
        self.check_types = check_types
        self.current: Optional[BondSet] = None
        self.reread = True  # the last call read the bonds anew
        self._strings = None  # the bonds strings `current` was read from
        self._r0 = None  # the bond_r0 array it was read from or wrote

    def bonds(self, atoms: Atoms, changes=None) -> BondSet:
        """The bonds on ``atoms``.

        ``changes`` (from the calculator's ``check_state``) lets an unchanged
        configuration skip the comparison of the bonds strings.  When the
        strings change under a known set (bonds added, removed, retyped),
        reference lengths follow their bonds by atom pair; otherwise they are
        read slot by slot from ``bond_r0``.
        """
        strings, r0_nm = atoms.arrays.get("bonds"), atoms.arrays.get(R0)
        current = self.current
        self.reread = False
        if current is not None and current.natoms == len(atoms):
            if changes is not None and "bonds" not in changes:
                return current  # the calculator saw no change (bond_r0 is ours)
            same_strings = same_array(strings, self._strings)
            if same_strings and same_array(r0_nm, self._r0):
                return current
        else:
            same_strings = False
        self.reread = True
        table = bond_table(atoms)
        if self.check_types is not None:
            self.check_types(table)
        if current is not None and not same_strings:
            r0_rows, stale = _r0_by_pair(current, table, len(atoms)), True
        else:
            r0_rows = _r0_from_slots(r0_nm, table)
            stale = r0_nm is None or r0_nm.ndim != 2 or r0_nm.shape[1] < table.nslots
        self.current = BondSet(table, len(atoms), r0_rows, stale)
        self._strings = None if strings is None else strings.copy()
        self._r0 = None if r0_nm is None else r0_nm.copy()
        return self.current

    # -- writing back (commit) ------------------------------------------------------
    def take_reference(self, atoms: Atoms, bonds: BondSet, fresh_b, r0_b) -> bool:
        """Store newly taken reference lengths; rewrite ``bond_r0`` if needed.

        Returns whether ``bond_r0`` on the atoms was rewritten.
        """
        bonds.r0_rows[bonds.intact_b[fresh_b]] = r0_b[fresh_b]
        if not (fresh_b.any() or bonds.r0_stale):
            return False
        table = bonds.table
        r0_nm = np.full((len(atoms), table.nslots), np.nan)
        r0_nm[table.owner_b, table.slot_b] = bonds.r0_rows
        atoms.arrays[R0] = r0_nm
        bonds.r0_stale = False
        self._r0 = r0_nm.copy()
        return True

    def break_bonds(self, atoms: Atoms, bonds: BondSet, broken_b, step: int,
                    r_bc: np.ndarray, log: bool) -> BondSet:
        """Set the ``broken_b`` intact bonds to type 0 on the atoms.

        With ``log``, append them to ``atoms.info["broken_bonds"]`` (LAMMPS
        ``store/local``): atoms ``i < j``, step, centre now (``x_i + r/2``) and
        in the reference positions ``bpm_x_ref``.  Returns the new set.
        """
        table = bonds.table
        rows = bonds.intact_b[broken_b]
        new_type = table.type_b.copy()
        new_type[rows] = 0
        strings = atoms.arrays["bonds"].copy()  # "0" is never longer: fits
        for owner in np.unique(table.owner_b[rows]):
            s = np.searchsorted(table.owner_b, owner)
            e = np.searchsorted(table.owner_b, owner, side="right")
            strings[owner] = format_atom_bonds(table.partner_b[s:e], new_type[s:e])
        atoms.arrays["bonds"] = strings

        i_k, j_k = bonds.i_b[broken_b], bonds.j_b[broken_b]
        if log:
            centre = np.take(atoms.positions, i_k, axis=0) + 0.5 * r_bc[broken_b]
            x_ref = atoms.arrays[X_REF]
            d_ref = minimum_image(np.take(x_ref, j_k, axis=0) - np.take(x_ref, i_k, axis=0),
                                  atoms.cell, atoms.pbc)
            centre_ref = np.take(x_ref, i_k, axis=0) + 0.5 * d_ref
            rows_log = np.column_stack([np.minimum(i_k, j_k), np.maximum(i_k, j_k),
                                        np.full(len(i_k), step), centre, centre_ref])
            old = atoms.info.get(BROKEN_LOG, np.zeros((0, len(BROKEN_LOG_COLUMNS))))
            atoms.info[BROKEN_LOG] = np.vstack([old, rows_log])

        new = BondSet(BondTable(table.owner_b, table.slot_b, table.partner_b, new_type),
                      bonds.natoms, bonds.r0_rows, bonds.r0_stale,
                      broken_keys=pair_keys(i_k, j_k, bonds.natoms), parent=bonds.digest)
        self.current, self._strings = new, strings.copy()
        return new


def write_bond_counts(atoms: Atoms, bonds: BondSet) -> None:
    """Per-atom outputs: ``nbonds`` (intact) and ``damage`` (fraction broken)."""
    table, n = bonds.table, len(atoms)
    intact = table.type_b > 0
    nbonds = (np.bincount(table.owner_b[intact], minlength=n)
              + np.bincount(table.partner_b[intact], minlength=n))
    listed = (np.bincount(table.owner_b, minlength=n)
              + np.bincount(table.partner_b, minlength=n))
    atoms.arrays["nbonds"] = nbonds
    atoms.arrays["damage"] = np.divide(listed - nbonds, listed, out=np.zeros(n),
                                       where=listed > 0)
