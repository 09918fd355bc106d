"""The intact bonds of a bond table, ready for the kernels (:class:`BondSet`).

A :class:`BondSet` is read from the integer bond arrays of
:mod:`ase_bpm.core.bonds` (by :class:`ase_bpm.models.bonded.BondState`, the
only one that touches the atoms): the two atoms, the type and the per-bond
state of each intact bond, the derived structures the kernels use (sparse sum
and difference matrices, per-atom groupings), built when first needed and
carried over when bonds break, and the checksum that identifies the bonds
whatever the order of the atoms.
"""

from __future__ import annotations

import copy
import functools
import itertools
from typing import Optional

import numpy as np
import scipy.sparse

from .arrays import NATIVE, put_rows
from .bonds import TYPE, BondTable, id_numbers
from .neighbours import minimum_image


def pair_keys(i, j, natoms: int) -> np.ndarray:
    """One integer per unordered atom pair."""
    return np.minimum(i, j) * natoms + np.maximum(i, j)


_MIX = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9],
                dtype=np.uint64)


def bond_checksum(id_a, id_b, type_b, *other_types) -> int:
    """A checksum of bonds (the IDs of their two atoms as numbers,
    :func:`~ase_bpm.core.bonds.id_numbers`, either order, and their types),
    added up over the bonds: it identifies the bond topology in the record of
    the last evaluation, whatever the order of the atoms.

    With ``other_types``: the checksum of the bonds as typed ``type_b`` minus
    that of the same bonds typed ``other_types[0]`` (modulo 2**64), the change
    of a checksum when these bonds change type.
    """
    lo = np.minimum(id_a, id_b).astype(np.uint64)
    hi = np.maximum(id_a, id_b).astype(np.uint64)
    if not len(lo):
        return 0
    with np.errstate(over="ignore"):
        ends = lo * _MIX[0] ^ hi * _MIX[1]
        sums = []
        for types in (type_b, *other_types):
            h = ends ^ (np.asarray(types).astype(np.uint64) + np.uint64(1)) * _MIX[2]
            h ^= h >> np.uint64(29)
            h *= _MIX[1]
            h ^= h >> np.uint64(32)
            sums.append(int(np.add.reduce(h, dtype=np.uint64)))
    return (sums[0] - sums[1]) % 2 ** 64 if other_types else sums[0]


_serials = itertools.count(1)


#: cache entries a lazily marked set carries over (by prefix): its bonds keep
#: their places, so what a model worked out for them holds (its law groups,
#: damping and plan of what runs, ``ase_bpm.models.bonded.BondPlan``)
#: (the sorted keys of bonded pairs go along as every child's do, see _child)
_LAZY_CARRIED = ("bond:", "rows:", "keep:", "unset:", "law_groups", "damped", "plan")
#: a set that keeps broken bonds listed (``without(..., lazy=True)``) sheds
#: them once they are this share of its bonds
DEAD_SHARE = 0.125


class BondSet:
    """The intact bonds of a bond table, ready for the kernels.

    ``i_b``, ``j_b``, ``type_b``: the two atoms and the type of each intact
    bond; ``intact_b``: their rows in the table.  Derived structures (sparse
    sum and difference matrices, per-atom groupings, model coefficients) are
    built when first needed and, when bonds break, carried over to the set
    without them (:meth:`without`) instead of being rebuilt.

    A set made by ``without(..., lazy=True)`` may still list bonds broken
    since it was compacted, with type 0 in ``type_b`` (``dead`` of them), as
    LAMMPS keeps a broken bond in its bond list until it rebuilds the list:
    only compiled kernels that pass over type-0 bonds (laws with
    ``skips_broken``) take such a set; :meth:`compacted` gives the set
    without them for everything else.
    """

    def __init__(self, table: BondTable, natoms: int, ids_n: np.ndarray, state: dict):
        self.table, self.natoms, self.ids_n = table, natoms, ids_n
        self.state = state  # name -> array, one row per table row (NaN until set)
        self.dirty = {}  # name -> table rows changed since the last write
        self.intact_b = np.flatnonzero(table.type_b > 0)
        #: the set lists every row of the table, in order: its columns are the
        #: table's own (no copies; a lazily marked child keeps this)
        self.whole = len(self.intact_b) == len(table)
        if self.whole:
            self.i_b, self.j_b, self.type_b = table.owner_b, table.partner_b, table.type_b
        else:
            self.i_b = table.owner_b[self.intact_b]
            self.j_b = table.partner_b[self.intact_b]
            self.type_b = table.type_b[self.intact_b]
        numbers_n = id_numbers(ids_n)
        self.checksum = bond_checksum(numbers_n[table.owner_b], numbers_n[table.partner_b],
                                      table.type_b)
        del numbers_n
        self.serial = next(_serials)  # this set, for caches that follow it
        self.broken_keys = None  # pairs broken since `parent`
        self.parent = None  # serial of the set this one came from
        self.dead = 0  # broken bonds still listed, with type 0 (see the class doc)
        self.cache = {}

    @functools.cached_property
    def fingerprint(self) -> str:
        """Identifies the bonds (atoms by ID, types) whatever the atoms' order
        (worked out once: a set's bonds stay what they are)."""
        return f"{len(self.table)}:{len(self.i_b) - self.dead}:{self.checksum:016x}"

    def __len__(self) -> int:
        return len(self.i_b)

    # -- derived structures ------------------------------------------------------------
    def per_bond(self, name: str, compute):
        """A per-bond array (bonds along the last axis) cached under ``name``."""
        key = "bond:" + name
        if key not in self.cache:
            self.cache[key] = compute()
        return self.cache[key]

    def _pattern(self) -> tuple:
        """``(data, indices, indptr)`` of the incidence matrix: column ``b``
        holds +1 at ``i_b`` and -1 at ``j_b`` (rows of the difference matrix
        are the same, negated)."""
        if "pattern" not in self.cache:
            nb = len(self)
            indices = np.empty(2 * nb, dtype=np.int64)
            indices[0::2], indices[1::2] = self.i_b, self.j_b
            data = np.empty(2 * nb)
            data[0::2], data[1::2] = 1.0, -1.0
            self.cache["pattern"] = (data, indices, np.arange(0, 2 * nb + 1, 2))
        return self.cache["pattern"]

    @property
    def incidence(self) -> scipy.sparse.csc_matrix:
        """Sparse ``(natoms, nbonds)`` matrix, +1 at ``i`` and -1 at ``j``:
        ``incidence @ f_bc`` sums bond forces (on ``i``) per atom."""
        if "incidence" not in self.cache:
            self.cache["incidence"] = scipy.sparse.csc_matrix(
                self._pattern(), shape=(self.natoms, len(self)))
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

    def geometry(self, x_nc, cell, pbc, in_order: bool = False) -> tuple:
        """``(r_bc, r_b)``: the bond vectors ``x[j] - x[i]`` (minimum image
        along periodic directions) and their lengths; ``in_order``: each
        length summed ``x^2 + y^2 + z^2`` in this order, as LAMMPS and the C
        kernels sum it (einsum's sum, the default, differs in the last bit
        for about one bond in ten: runs recorded with it go on bit for bit)."""
        r_bc = self.vectors(x_nc)
        if np.any(pbc):
            r_bc = minimum_image(r_bc, cell, pbc)
        if in_order:
            x, y, z = r_bc[:, 0], r_bc[:, 1], r_bc[:, 2]
            return r_bc, np.sqrt(x * x + y * y + z * z)
        return r_bc, np.sqrt(np.einsum("bc,bc->b", r_bc, r_bc))

    def sum_forces(self, r_bc, r_b, f_b, fj_b=None, fd_b=None) -> tuple:
        """Per-atom sums of bond forces given as magnitudes along ``r_bc``:
        ``f_b`` on ``i`` (towards ``j``), ``fj_b`` on ``j`` (towards ``i``;
        default ``f_b``), and the damping part ``fd_b`` of ``f_b``.  Returns
        ``(f_nc, fd_nc, fmean_bc)``, the last the mean force on ``i`` per
        bond (for the virial); ``fd_nc`` is None without ``fd_b``."""
        rinv_b = np.divide(1.0, r_b, out=np.zeros_like(r_b), where=r_b > 0)
        f_bc = r_bc * (f_b * rinv_b)[:, None]
        if fj_b is None:
            f_nc, fmean_bc = self.incidence @ f_bc, f_bc
        else:
            fj_bc = -r_bc * (fj_b * rinv_b)[:, None]
            f_nc, fmean_bc = self.forces(f_bc, fj_bc), 0.5 * (f_bc - fj_bc)
        fd_nc = None if fd_b is None else self.incidence @ (r_bc * (fd_b * rinv_b)[:, None])
        return f_nc, fd_nc, fmean_bc

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
            data, indices, indptr = self._pattern()
            self.cache["difference"] = scipy.sparse.csr_matrix(
                (-data, indices, indptr), shape=(len(self), self.natoms))
        return self.cache["difference"] @ values_nc

    @property
    def bonded_keys(self) -> np.ndarray:
        """Sorted :func:`pair_keys` of the intact bonds."""
        if "bonded_keys" not in self.cache:
            since = self.cache.pop("bonded_keys_since", None)
            if since is None:
                live = slice(None) if not self.dead else self.type_b > 0
                keys = np.sort(pair_keys(self.i_b[live], self.j_b[live], self.natoms))
            else:  # an earlier set's keys, without the bonds broken since
                keys, broken = since
                for gone in broken:  # step by step: a pair bonded twice loses one a step
                    keys = np.delete(keys, np.searchsorted(keys, np.unique(gone)))
            self.cache["bonded_keys"] = keys
        return self.cache["bonded_keys"]

    def bonded(self, keys: np.ndarray) -> np.ndarray:
        """Which of the pair ``keys`` are joined by an intact bond.

        Keys in any order; a new Verlet list's come in ascending order, and
        the C twin ``members`` then merges them with :attr:`bonded_keys` in
        one pass instead of a binary search for each."""
        bonded = self.bonded_keys
        if len(bonded) == 0:
            return np.zeros(len(keys), dtype=bool)
        twin = NATIVE.get("members")
        if twin is not None:
            found = np.empty(len(keys), dtype=bool)
            if twin(keys, bonded, found) is not NotImplemented:
                return found
        pos = np.minimum(np.searchsorted(bonded, keys), len(bonded) - 1)
        return bonded[pos] == keys

    # -- state ------------------------------------------------------------------------
    def of_bonds(self, name: str) -> np.ndarray:
        """State ``name`` of the intact bonds (read-only, kept until the state
        is set again; NaN where unset).  A set that lists every row of its
        table hands out the state's own array, read-only from then on (a copy
        of it was 51 MB held at a million particles); :meth:`set_bonds`
        writes a read-only state into a new array, so what was handed out
        keeps this evaluation's values (a virial replayed after the commit
        must see them)."""
        key = "rows:state:" + name
        values = self.cache.get(key)
        if values is None:
            values = self.state[name] if self.whole else self.state[name][self.intact_b]
            values.flags.writeable = False
            self.cache[key] = values
        return values

    def unset(self, name: str):
        """Which intact bonds have no ``name`` yet (None: all have one)."""
        key = "unset:" + name
        if key not in self.cache:
            unset_b = np.isnan(self.of_bonds(name))
            while unset_b.ndim > 1:
                unset_b = unset_b.any(axis=-1)
            self.cache[key] = unset_b if unset_b.any() else None
        return self.cache[key]

    def state_of(self, name: str) -> tuple:
        """``(of_bonds(name), unset(name))`` in one look-up, once both are
        known (a step asks for the reference lengths and which are not yet
        taken)."""
        cache = self.cache
        values, unset_key = cache.get("rows:state:" + name), "unset:" + name
        if values is None or unset_key not in cache:
            return self.of_bonds(name), self.unset(name)
        return values, cache[unset_key]

    def set_bonds(self, name: str, values_b: np.ndarray, where_b=None) -> None:
        """Set state ``name`` of the intact bonds (those in ``where_b``).  A
        whole set whose state was handed out takes a new array of the state's
        shape and type (``values_b`` owning its data: the history a kernel
        wrote) over as its state, read-only, rather than copying it."""
        self.cache.pop("rows:state:" + name, None)
        self.cache.pop("unset:" + name, None)
        rows = self.intact_b if where_b is None else self.intact_b[where_b]
        old = self.state[name]
        if not old.flags.writeable:  # handed out by of_bonds: left as it is
            # (for every set sharing the state; every row set anew: nothing to copy)
            every = self.whole and where_b is None
            if every and values_b.flags.owndata and values_b.flags.c_contiguous and \
                    values_b.shape == old.shape and values_b.dtype == old.dtype:
                values_b.flags.writeable = False
                self.state[name] = values_b
            else:
                self.state[name] = (np.empty_like if every else np.copy)(old)
        if self.state[name] is not values_b:
            put_rows(self.state[name], values_b, self.intact_b, rows=where_b)
        self.dirty[name] = (rows if name not in self.dirty
                            else np.union1d(self.dirty[name], rows))

    # -- breaking ------------------------------------------------------------------------
    def without(self, broken_b: np.ndarray, lazy: bool = False) -> "BondSet":
        """The set after the ``broken_b`` bonds broke (type 0 in the table),
        sharing the state and carrying derived structures over.

        ``lazy``: keep them listed with type 0 (the set's arrays are shared,
        marked in place: no array scales with the bonds unless the broken
        ones reach :data:`DEAD_SHARE` of the set, which sheds them all)."""
        rows = self.intact_b[broken_b]
        t = self.table
        dead = self.dead + len(rows)
        if lazy and dead < DEAD_SHARE * len(self):
            return self._marked(broken_b, rows, dead)
        gone_b = broken_b if not self.dead else broken_b | (self.type_b == 0)
        keep = np.flatnonzero(~gone_b)  # indices: faster than a mask to gather
        new_type = t.type_b.copy()
        new_type[rows] = 0
        child = self._child(BondTable(t.owner_b, t.slot_b, t.partner_b, new_type), broken_b,
                            rows)
        child.intact_b, child.i_b = self.intact_b[keep], self.i_b[keep]
        child.j_b, child.type_b = self.j_b[keep], self.type_b[keep]
        cache = self.cache
        # the sparse sum and difference matrices are built anew when needed:
        # cheaper than slicing the parent's
        if "by_node" in cache:
            node, bond = cache["by_node"]
            stays = ~gone_b[bond]
            renumber = np.cumsum(~gone_b) - 1
            child.cache["by_node"] = (node[stays], renumber[bond[stays]])
        groups = cache.get("law_groups")
        if groups is not None and list(groups.values()) == [None]:  # one law: still so
            child.cache["law_groups"] = groups
            if "damped" in cache:
                child.cache["damped"] = cache["damped"]
        for name, value in cache.items():
            if name.startswith("bond:"):
                child.cache[name] = np.take(value, keep, axis=-1)
            elif name.startswith("rows:"):  # per-bond rows (state, with trailing axes)
                child.cache[name] = np.take(value, keep, axis=0)
            elif name.startswith("keep:"):  # valid for any subset of the bonds
                child.cache[name] = value
        return child

    def _child(self, table: BondTable, broken_b, rows) -> "BondSet":
        """A set of ``table`` after the ``broken_b`` bonds (table ``rows``)
        broke: state, dirty rows, checksum and lineage; the arrays and the
        cache are the caller's to fill."""
        t = self.table
        child = BondSet.__new__(BondSet)
        child.table = table
        child.natoms, child.ids_n, child.state = self.natoms, self.ids_n, self.state
        child.dirty = self.dirty
        child.dirty[TYPE] = (rows if TYPE not in self.dirty
                             else np.union1d(self.dirty[TYPE], rows))
        ids, owner, partner = self.ids_n, t.owner_b[rows], t.partner_b[rows]
        # (the types before: the rows' types are 0 now when the table is marked in place)
        before = self.type_b[broken_b]
        child.checksum = (self.checksum - bond_checksum(
            id_numbers(ids[owner]), id_numbers(ids[partner]), before,
            np.zeros_like(before))) % 2 ** 64
        child.serial = next(_serials)
        child.broken_keys = pair_keys(self.i_b[broken_b], self.j_b[broken_b], self.natoms)
        child.parent = self.serial
        child.dead = 0
        child.whole = False
        child.cache = {}
        # the sorted keys of the intact bonds: updated when next asked for (the
        # contact list asks only when it is rebuilt)
        if "bonded_keys" in self.cache:
            child.cache["bonded_keys_since"] = (self.cache["bonded_keys"], [child.broken_keys])
        elif "bonded_keys_since" in self.cache:
            keys, broken = self.cache["bonded_keys_since"]
            child.cache["bonded_keys_since"] = (keys, broken + [child.broken_keys])
        return child

    def _marked(self, broken_b, rows, dead: int) -> "BondSet":
        """:meth:`without`, lazily: the ``broken_b`` bonds stay listed with
        type 0, marked in place in this set's arrays (which the child shares:
        this set is spent) and in the table's."""
        child = self._child(self.table, broken_b, rows)
        self.type_b[broken_b] = 0
        self.table.type_b[rows] = 0
        child.intact_b, child.i_b, child.j_b = self.intact_b, self.i_b, self.j_b
        child.type_b, child.dead, child.whole = self.type_b, dead, self.whole
        # what the compiled route keeps keeps its meaning: no bond changed its
        # place (the NumPy route's sparse matrices are not carried: it takes
        # compacted sets)
        child.cache.update({name: value for name, value in self.cache.items()
                            if name.startswith(_LAZY_CARRIED)})
        return child

    def pieces(self, size: int):
        """The set in consecutive pieces of at most ``size`` bonds, each a set
        of its own over views of this one's arrays (for work that makes
        per-bond arrays: one piece's at a time).  A set that lists broken
        bonds is compacted first."""
        whole = self.compacted()
        if len(whole) <= size:
            yield whole
            return
        for first in range(0, len(whole), size):
            piece = copy.copy(whole)
            part = slice(first, first + size)
            piece.intact_b, piece.i_b = whole.intact_b[part], whole.i_b[part]
            piece.j_b, piece.type_b = whole.j_b[part], whole.type_b[part]
            piece.whole = False
            piece.cache = {}
            piece.__dict__.pop("fingerprint", None)  # (the whole set's, if worked out)
            yield piece

    def compacted(self) -> "BondSet":
        """This set without the broken bonds it still lists (itself if none)."""
        if not self.dead:
            return self
        return self.without(np.zeros(len(self), dtype=bool))
