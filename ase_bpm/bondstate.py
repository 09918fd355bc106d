"""Breakable bonds with a reference state, for any bond law.

LAMMPS equivalent: the machinery every BPM bond style shares (``BondBPM`` and
``fix BOND_HISTORY``): the reference length of each bond taken at its first
evaluation and any other per-bond history, breaking (type 0), the special list
that keeps bonded pairs out of the pair style, the ``store/local`` log of
broken bonds and ``nbond/atom``.

Per-bond state ``name`` lives on the atoms as ``atoms.arrays["bond_<name>"]``,
shape ``(natoms, nslots, ...)``, entry ``[i, m]`` for the ``m``-th bond listed
on atom ``i`` (NaN where unset).  These arrays belong to the calculator: after
editing one by hand, call the calculator's ``refresh()``.

:class:`BondState` keeps a compiled :class:`BondSet` of the intact bonds
between evaluations and rebuilds it only when the bonds on the atoms change.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse
from ase import Atoms

from .bonds import BondTable, bond_table, format_atom_bonds
from .calculator import same_array
from .neighbours import VerletList, minimum_image

R0 = "bond_r0"  # per-bond reference length, NaN until the first evaluation
X_REF = "bpm_x_ref"  # per-atom reference position (for the broken-bond log)
BROKEN_LOG = "broken_bonds"  # info: one row per broken bond
BROKEN_LOG_COLUMNS = ("i", "j", "step", "x", "y", "z", "x_ref", "y_ref", "z_ref")


def pair_keys(i, j, natoms: int) -> np.ndarray:
    """One integer per unordered atom pair."""
    return np.minimum(i, j) * natoms + np.maximum(i, j)


_MIX = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9,
                 0x27D4EB2F165667C5], dtype=np.uint64)


def _row_hashes(table: BondTable, rows=slice(None)) -> np.ndarray:
    """A 64-bit hash of each (owner, slot, partner, type) table row."""
    with np.errstate(over="ignore"):
        h = (table.owner_b[rows].astype(np.uint64) * _MIX[0]
             ^ table.partner_b[rows].astype(np.uint64) * _MIX[1]
             ^ (table.type_b[rows].astype(np.uint64) + np.uint64(1)) * _MIX[2]
             ^ (table.slot_b[rows].astype(np.uint64) + np.uint64(1)) * _MIX[3])
        h ^= h >> np.uint64(29)
        h *= _MIX[1]
        h ^= h >> np.uint64(32)
    return h


def _checksum(hashes: np.ndarray) -> np.uint64:
    with np.errstate(over="ignore"):
        return np.add.reduce(hashes, dtype=np.uint64) if len(hashes) else np.uint64(0)


class BondSet:
    """The intact bonds of a bond table, ready for the kernels.

    ``i_b``, ``j_b``, ``type_b``: the two atoms and the type of each intact
    bond; ``intact_b``: their rows in the table.  Derived structures (sparse
    sum and difference matrices, per-atom groupings, model coefficients) are
    built when first needed and, when bonds break, carried over to the set
    without them (:meth:`without`) instead of being rebuilt.
    """

    def __init__(self, table: BondTable, natoms: int, state: dict, stale: set):
        self.table, self.natoms = table, natoms
        self.state = state  # name -> array, one row per table row (NaN until set)
        self.stale = stale  # state names whose atoms.arrays copy must be rewritten
        self.intact_b = np.flatnonzero(table.type_b > 0)
        self.i_b = table.owner_b[self.intact_b]
        self.j_b = table.partner_b[self.intact_b]
        self.type_b = table.type_b[self.intact_b]
        self._sum = _checksum(_row_hashes(table))
        self.broken_keys = None  # pairs broken since `parent`
        self.parent = None  # digest of the set this one came from
        self.cache = {}

    @property
    def digest(self) -> str:
        """Identifies the bond table (atoms, slots, types) independent of history."""
        return f"{len(self.table)}:{int(self._sum):016x}"

    def __len__(self) -> int:
        return len(self.i_b)

    # -- derived structures ------------------------------------------------------------
    def per_bond(self, name: str, compute):
        """A per-bond array (bonds along the last axis) cached under ``name``."""
        key = "bond:" + name
        if key not in self.cache:
            self.cache[key] = compute()
        return self.cache[key]

    @property
    def incidence(self) -> scipy.sparse.csc_matrix:
        """Sparse ``(natoms, nbonds)`` matrix, +1 at ``i`` and -1 at ``j``:
        ``incidence @ f_bc`` sums bond forces (on ``i``) per atom."""
        if "incidence" not in self.cache:
            b = np.arange(len(self))
            self.cache["incidence"] = scipy.sparse.csc_matrix(
                (np.r_[np.ones(len(b)), -np.ones(len(b))],
                 (np.r_[self.i_b, self.j_b], np.r_[b, b])),
                shape=(self.natoms, len(b)))
        return self.cache["incidence"]

    def ends(self) -> tuple:
        """Sparse ``(natoms, nbonds)`` matrices with 1 at ``i`` (first) and at
        ``j`` (second): per-atom sums of quantities on one bond end."""
        if "ends" not in self.cache:
            b, shape = np.arange(len(self)), (self.natoms, len(self))
            ones = np.ones(len(self))
            self.cache["ends"] = (scipy.sparse.csc_matrix((ones, (self.i_b, b)), shape=shape),
                                  scipy.sparse.csc_matrix((ones, (self.j_b, b)), shape=shape))
        return self.cache["ends"]

    def forces(self, fi_bc: np.ndarray, fj_bc: Optional[np.ndarray] = None) -> np.ndarray:
        """Per-atom sums of bond forces: ``fi_bc`` on ``i`` and ``fj_bc`` on ``j``
        (default ``-fi_bc``, Newton's third law)."""
        if fj_bc is None:
            return self.incidence @ fi_bc
        on_i, on_j = self.ends()
        return on_i @ fi_bc + on_j @ fj_bc

    def node_min(self, values_b: np.ndarray) -> np.ndarray:
        """Smallest value over each atom's bonds (NaN for atoms without bonds)."""
        if "by_node" not in self.cache:
            node = np.concatenate([self.i_b, self.j_b])
            order = np.argsort(node, kind="stable")
            self.cache["by_node"] = (node[order],
                                     np.concatenate([np.arange(len(self))] * 2)[order])
        node, bond = self.cache["by_node"]
        out = np.full(self.natoms, np.nan)
        if len(bond):
            start = np.flatnonzero(np.r_[True, node[1:] != node[:-1]])
            out[node[start]] = np.minimum.reduceat(values_b[bond], start)
        return out

    def vectors(self, values_nc: np.ndarray) -> np.ndarray:
        """``values[j] - values[i]`` per bond (positions: bond vectors, velocities:
        relative velocities), through a cached sparse ``(nbonds, natoms)`` matrix."""
        if "difference" not in self.cache:
            self.cache["difference"] = (-self.incidence.T).tocsr()
        return self.cache["difference"] @ values_nc

    @property
    def bonded_keys(self) -> np.ndarray:
        """Sorted :func:`pair_keys` of the intact bonds."""
        if "bonded_keys" not in self.cache:
            self.cache["bonded_keys"] = np.sort(pair_keys(self.i_b, self.j_b, self.natoms))
        return self.cache["bonded_keys"]

    def bonded(self, keys: np.ndarray) -> np.ndarray:
        """Which of the pair ``keys`` are joined by an intact bond."""
        bonded = self.bonded_keys
        if len(bonded) == 0:
            return np.zeros(len(keys), dtype=bool)
        pos = np.minimum(np.searchsorted(bonded, keys), len(bonded) - 1)
        return bonded[pos] == keys

    # -- state ------------------------------------------------------------------------
    def of_bonds(self, name: str) -> np.ndarray:
        """State ``name`` of the intact bonds (a copy; NaN where unset)."""
        return self.state[name][self.intact_b]

    def set_bonds(self, name: str, values_b: np.ndarray, where_b=None) -> None:
        """Set state ``name`` of the intact bonds (those in ``where_b``)."""
        rows = self.intact_b if where_b is None else self.intact_b[where_b]
        self.state[name][rows] = values_b if where_b is None else values_b[where_b]
        self.stale.add(name)

    # -- breaking ------------------------------------------------------------------------
    def without(self, broken_b: np.ndarray) -> "BondSet":
        """The set after the ``broken_b`` bonds broke (type 0 in the table),
        sharing the state and carrying derived structures over."""
        keep = np.flatnonzero(~broken_b)  # indices: faster than a mask to gather
        rows = self.intact_b[broken_b]
        t = self.table
        new_type = t.type_b.copy()
        new_type[rows] = 0
        child = BondSet.__new__(BondSet)
        child.table = BondTable(t.owner_b, t.slot_b, t.partner_b, new_type)
        child.natoms, child.state, child.stale = self.natoms, self.state, self.stale
        child.intact_b, child.i_b = self.intact_b[keep], self.i_b[keep]
        child.j_b, child.type_b = self.j_b[keep], self.type_b[keep]
        with np.errstate(over="ignore"):
            child._sum = (self._sum - _checksum(_row_hashes(t, rows))
                          + _checksum(_row_hashes(child.table, rows)))
        child.broken_keys = pair_keys(self.i_b[broken_b], self.j_b[broken_b], self.natoms)
        child.parent = self.digest
        child.cache = {}
        cache = self.cache
        for name in ("incidence", "difference"):
            if name in cache:
                m = cache[name]
                child.cache[name] = m[:, keep] if name == "incidence" else m[keep]
        if "ends" in cache:
            child.cache["ends"] = tuple(m[:, keep] for m in cache["ends"])
        if "by_node" in cache:
            node, bond = cache["by_node"]
            stays = ~broken_b[bond]
            renumber = np.cumsum(~broken_b) - 1
            child.cache["by_node"] = (node[stays], renumber[bond[stays]])
        if "bonded_keys" in cache:
            keys = cache["bonded_keys"]
            gone = np.searchsorted(keys, np.unique(child.broken_keys))
            child.cache["bonded_keys"] = np.delete(keys, gone)
        for name, value in cache.items():
            if name.startswith("bond:"):
                child.cache[name] = np.take(value, keep, axis=-1)
            elif name.startswith("keep:"):  # valid for any subset of the bonds
                child.cache[name] = value
        return child


def _from_slots(array_nm, table: BondTable, shape: tuple) -> np.ndarray:
    """Per-row state from a slot-aligned per-atom array (NaN where missing)."""
    rows = np.full((len(table),) + shape, np.nan)
    if (array_nm is not None and array_nm.ndim == 2 + len(shape)
            and array_nm.shape[2:] == shape and len(table)):
        inside = table.slot_b < array_nm.shape[1]
        rows[inside] = array_nm[table.owner_b[inside], table.slot_b[inside]]
    return rows


def _by_pair(old: BondSet, name: str, table: BondTable, natoms: int,
             shape: tuple) -> np.ndarray:
    """Per-row state carried over from an earlier table, bond by bond."""
    old_key = pair_keys(old.table.owner_b, old.table.partner_b, natoms)
    order = np.argsort(old_key, kind="stable")
    rows = np.full((len(table),) + shape, np.nan)
    if len(order):
        new_key = pair_keys(table.owner_b, table.partner_b, natoms)
        pos = np.minimum(np.searchsorted(old_key[order], new_key), len(order) - 1)
        found = old_key[order][pos] == new_key
        rows[found] = old.state[name][order][pos][found]
    return rows


class BondState:
    """The bonds a calculator works with, cached between evaluations.

    ``check_types`` is called with every newly read table, to reject bond
    types the model has no coefficients for.  ``states`` names the per-bond
    states and the trailing shape of each (``{"r0": ()}`` by default).
    """

    def __init__(self, check_types=None, states=None):
        self.check_types = check_types
        self.shapes = dict(states or {"r0": ()})
        self.current: Optional[BondSet] = None
        self.reread = True  # the last call read the bonds anew
        self._strings = None  # the bonds strings `current` was read from
        self._arrays = {}  # the bond_<name> array objects read or written

    def bonds(self, atoms: Atoms, changes=None) -> BondSet:
        """The bonds on ``atoms``.

        ``changes`` (from the calculator's ``check_state``) lets an unchanged
        configuration skip the comparison of the bonds strings.  When the
        strings change under a known set (bonds added, removed, retyped), the
        state follows its bonds by atom pair; otherwise it is read slot by slot
        from the ``bond_<name>`` arrays.
        """
        strings = atoms.arrays.get("bonds")
        current = self.current
        self.reread = False
        same_strings = False
        if current is not None and current.natoms == len(atoms):
            same_strings = ((changes is not None and "bonds" not in changes)
                            or same_array(strings, self._strings))
            if same_strings and all(self._ours(atoms, name) for name in self.shapes):
                return current
        self.reread = True
        table = bond_table(atoms)
        if self.check_types is not None:
            self.check_types(table)
        state, stale = {}, set()
        for name, shape in self.shapes.items():
            array = atoms.arrays.get("bond_" + name)
            if current is not None and not same_strings:
                state[name] = _by_pair(current, name, table, len(atoms), shape)
                stale.add(name)
            else:
                state[name] = _from_slots(array, table, shape)
                if array is None or array.shape[1:2] < (table.nslots,):
                    stale.add(name)
            self._arrays[name] = array
        self.current = BondSet(table, len(atoms), state, stale)
        self._strings = None if strings is None else strings.copy()
        return self.current

    def _ours(self, atoms: Atoms, name: str) -> bool:
        """The ``bond_<name>`` array is the one read or written last."""
        return atoms.arrays.get("bond_" + name) is self._arrays.get(name)

    # -- writing back (commit) ------------------------------------------------------
    def write(self, atoms: Atoms, bonds: BondSet) -> list:
        """Rewrite the stale ``bond_<name>`` arrays; return their names."""
        written = []
        table = bonds.table
        for name in sorted(bonds.stale):
            shape = self.shapes[name]
            array = np.full((len(atoms), table.nslots) + shape, np.nan)
            array[table.owner_b, table.slot_b] = bonds.state[name]
            atoms.arrays["bond_" + name] = self._arrays[name] = array
            written.append("bond_" + name)
        bonds.stale.clear()
        return written

    def break_bonds(self, atoms: Atoms, bonds: BondSet, broken_b, step: int,
                    r_bc: np.ndarray, log: bool) -> BondSet:
        """Set the ``broken_b`` intact bonds to type 0 on the atoms.

        With ``log``, append them to ``atoms.info["broken_bonds"]`` (LAMMPS
        ``store/local``): atoms ``i < j``, step, centre now (``x_i + r/2``) and
        in the reference positions ``bpm_x_ref``.  Returns the new set.
        """
        new = bonds.without(broken_b)
        table = new.table
        strings = atoms.arrays["bonds"].copy()  # "0" is never longer: fits
        for owner in np.unique(table.owner_b[bonds.intact_b[broken_b]]):
            s = np.searchsorted(table.owner_b, owner)
            e = np.searchsorted(table.owner_b, owner, side="right")
            strings[owner] = format_atom_bonds(table.partner_b[s:e], table.type_b[s:e])
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

        self.current, self._strings = new, strings.copy()
        return new


class ContactList:
    """Pairs that may touch: a Verlet list (``cutoff + skin``) without the pairs
    joined by an intact bond, whatever the periodic image (LAMMPS' special
    list with a 1-2 weight of 0), unless ``overlay``.

    Bonds that broke since the last call join in without a full search.
    """

    def __init__(self, cutoff: float, skin: float, overlay: bool = False):
        self.neighbours = VerletList(cutoff, skin)
        self.overlay = overlay
        self._cache = None  # (list build, bond set digest, allowed_p, select_p)

    def pairs(self, atoms: Atoms, bonds: BondSet):
        """``(i_p, j_p, r_pc)`` of the candidate pairs, ``r = x_j - x_i``."""
        nl = self.neighbours
        nl.update(atoms.positions, atoms.cell, atoms.pbc)
        select = self._select(len(atoms), bonds)
        return nl.i_p[select], nl.j_p[select], nl.pair_vectors(atoms.positions, select)

    def _select(self, natoms: int, bonds: BondSet) -> np.ndarray:
        nl, cached = self.neighbours, self._cache
        if cached is not None and cached[0] == nl.nbuilds:
            if cached[1] == bonds.digest:
                return cached[3]
            if bonds.parent == cached[1] and bonds.broken_keys is not None:
                keys = pair_keys(nl.i_p, nl.j_p, natoms)
                allowed = cached[2] | np.isin(keys, bonds.broken_keys)
                self._cache = (nl.nbuilds, bonds.digest, allowed, np.flatnonzero(allowed))
                return self._cache[3]
        if self.overlay:
            allowed = np.ones(len(nl.i_p), dtype=bool)
        else:
            allowed = ~bonds.bonded(pair_keys(nl.i_p, nl.j_p, natoms))
        self._cache = (nl.nbuilds, bonds.digest, allowed, np.flatnonzero(allowed))
        return self._cache[3]


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
