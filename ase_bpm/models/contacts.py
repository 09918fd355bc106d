"""Per-contact history of touching spheres, stored on the atoms.

LAMMPS equivalent: ``fix neigh/history``, which the ``gran/*/history`` pair
styles create to keep one shear displacement per touching pair.

The history lives on the atoms, so ``atoms.copy()`` and restart files carry
it: each contact ``(i, j)`` with ``i < j`` sits on atom ``i``, in the first
free slot of ``atoms.arrays["gran_partner"]`` (N x 2 slots, the partner's ID,
``atoms.arrays["bpm_id"]``, in two int32 words as for bonds, 0 for an empty
slot; the code works on its int64 keys, :func:`~ase_bpm.core.bonds.keys_of`) with its shear
in ``atoms.arrays["gran_shear"]`` (N x 3 slots).  Partners named by ID keep
their shear through ASE's atom operations (deleting, selecting, reordering,
combining atoms); a contact whose partner is gone is dropped.  These arrays
belong to the calculator: after editing one by hand, call the calculator's
``refresh()``.

:class:`ContactHistory` keeps what it last wrote in memory, aligned with the
neighbour list of that evaluation, so a step within one neighbour-list build
finds the shear of its contacts by index instead of reading the arrays back.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms

from ..core.arrays import same_array
from ..core.bonds import CONTACT_PARTNER as PARTNER
from ..core.bonds import ID, id_words, keys_of, read_ids, resolve, stored_ids

SHEAR = "gran_shear"


def read_contacts(atoms: Atoms):
    """The stored contacts: sorted keys ``i * N + j`` (``i < j``) and their
    shear (k x 3), as seen from ``i``."""
    n = len(atoms)
    partner_nk = atoms.arrays.get(PARTNER)
    if partner_nk is None:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    shear = atoms.arrays.get(SHEAR)
    if np.issubdtype(partner_nk.dtype, np.integer) and (partner_nk < 0).any():
        raise ValueError(f'atoms.arrays["{PARTNER}"] holds partner indices, as ase_bpm 0.1 '
                         f'wrote them: delete atoms.arrays["{PARTNER}"] and ["{SHEAR}"] to '
                         "start the contacts without shear history")
    stored_shape = partner_nk.shape
    partner_nk = read_ids(atoms, PARTNER)  # IDs: integers, as written
    width = partner_nk.shape[1]
    if shear is None or shear.shape != (n, 3 * width) or shear.dtype.kind != "f":
        raise ValueError(f'the contact history atoms.arrays["{PARTNER}"] and '
                         f'atoms.arrays["{SHEAR}"] do not fit together (shapes '
                         f'{stored_shape} and '
                         f'{None if shear is None else (shear.shape, str(shear.dtype))})')
    if ID not in atoms.arrays:
        raise ValueError(f'the contact history atoms.arrays["{PARTNER}"] names partners by '
                         f'ID: atoms.arrays["{ID}"] is missing')
    table = resolve(read_ids(atoms, ID), partner_nk, np.ones_like(partner_nk), PARTNER)
    i_k, j_k = table.owner_b, table.partner_b
    shear_kc = shear.reshape(n, width, 3)[i_k, table.slot_b]
    flip = i_k > j_k  # reordered atoms: the contact seen from its other sphere
    shear_kc[flip] *= -1.0
    keys_k = np.minimum(i_k, j_k) * n + np.maximum(i_k, j_k)
    order = np.argsort(keys_k, kind="stable")
    return keys_k[order], shear_kc[order]


def lookup_shear(keys_k, shear_kc, keys_p) -> np.ndarray:
    """Shear of the contacts ``keys_p`` among sorted stored ones (zero for new
    contacts)."""
    shear_pc = np.zeros((len(keys_p), 3))
    if len(keys_k) and len(keys_p):
        at = np.minimum(np.searchsorted(keys_k, keys_p), len(keys_k) - 1)
        known = keys_k[at] == keys_p
        shear_pc[known] = shear_kc[at[known]]
    return shear_pc


def write_contacts(atoms: Atoms, i_p, j_p, shear_pc, reuse: bool = False, occupied=None,
                   place=None):
    """Store the contacts (``i < j``, in order of ``(i, j)``) and their shear
    on atom ``i``, partners by ID; return the two arrays written.  With
    ``reuse``, arrays on the atoms of the width needed are overwritten in
    place (the caller owns them, and the complete IDs on the atoms) rather
    than replaced; ``occupied``, if given, are the flat slots in use there
    (every other slot is empty): only those the new contacts leave are
    cleared.  Returns the two arrays and each contact's flat slot (row of
    ``shear.reshape(-1, 3)``, of the partners' keys ``keys_of(partner)``).
    ``place``: the compiled twin of the array work below
    (:func:`ase_bpm.laws.compiled.place_contacts`), or None."""
    n = len(atoms)
    words_n = atoms.arrays[ID] if reuse else id_words(atoms)
    if atoms.arrays.get(ID) is not words_n:
        atoms.arrays[ID] = words_n
    ids_n = keys_of(words_n)[:, 0]
    if place is not None:
        return _placed(atoms, i_p, j_p, ids_n, shear_pc, reuse, occupied, place)
    count_n = np.bincount(i_p, minlength=n)
    width = max(int(count_n.max(initial=0)), 1)
    first_n = np.cumsum(count_n) - count_n
    slot_p = np.arange(len(i_p)) - np.take(first_n, i_p)
    at_p = i_p * width + slot_p  # flat slot index: cheaper to scatter to than (i, slot)
    partner, shear = atoms.arrays.get(PARTNER), atoms.arrays.get(SHEAR)
    partner_nk = None if partner is None else keys_of(partner)
    if reuse and partner_nk is not None and partner_nk.shape == (n, width):
        if occupied is None:
            partner_nk.fill(0)
            shear.fill(0.0)
        else:  # empty the slots left (a few: most contacts stay where they were)
            taken = np.zeros(partner_nk.size, dtype=bool)
            taken[at_p] = True
            left = occupied[~taken[occupied]]
            partner_nk.reshape(-1)[left] = 0
            scatter_rows(shear, left, np.zeros((len(left), 3)))
    else:
        partner_nk = np.zeros((n, width), dtype=np.int64)
        partner = atoms.arrays[PARTNER] = stored_ids(partner_nk)
        shear = atoms.arrays[SHEAR] = np.zeros((n, 3 * width))
    partner_nk.reshape(-1)[at_p] = np.take(ids_n, j_p)
    scatter_rows(shear, at_p, shear_pc)
    return partner, shear, at_p


def _placed(atoms: Atoms, i_p, j_p, ids_n, shear_pc, reuse: bool, occupied, place):
    """:func:`write_contacts` with the compiled ``place``: into the arrays on
    the atoms where they are ours and of the width needed, else into new
    ones of that width."""
    n = len(atoms)
    partner, shear = atoms.arrays.get(PARTNER), atoms.arrays.get(SHEAR)
    at_p = None
    if reuse and partner is not None:
        partner_nk = keys_of(partner)  # the kernel writes keys, into the words
        if occupied is None:
            partner_nk.fill(0)
            shear.fill(0.0)
        width, at_p = place(i_p, j_p, ids_n, shear_pc, partner_nk, shear, occupied)
    else:
        width = max(int(np.bincount(i_p, minlength=n).max(initial=0)), 1)
    if at_p is None:
        partner_nk = np.zeros((n, width), dtype=np.int64)
        partner = atoms.arrays[PARTNER] = stored_ids(partner_nk)
        shear = atoms.arrays[SHEAR] = np.zeros((n, 3 * width))
        _, at_p = place(i_p, j_p, ids_n, shear_pc, partner_nk, shear, None)
    return partner, shear, at_p


#: three float64 as one item: numpy moves rows of three numbers several times
#: faster as such items (np.put) than as rows
ROW = np.dtype((np.void, 24))


def scatter_rows(target: np.ndarray, rows, values_xc: np.ndarray) -> None:
    """``target.reshape(-1, 3)[rows] = values_xc``, in place, the rows moved
    as single items.  ``target`` is a C-contiguous float array (made by this
    module), so its view of rows is a view."""
    values = np.ascontiguousarray(values_xc, dtype=np.float64)
    np.put(target.view(ROW).reshape(-1), rows, values.view(ROW).reshape(-1))


class ContactHistory:
    """The shear history a calculator reads and writes, cached between steps.

    :meth:`shear_rows` gives the stored shear of the pairs of a neighbour list;
    :meth:`write` stores the new history on the atoms.  Contacts are named
    by their row in the neighbour list (``l_p``) and by the list's build
    number: while both the list and the arrays on the atoms are the ones of
    the last write, no array is read back, and the shear of every row that
    the kernel gave with the contacts written (``shear_lc``) is the next
    step's stored shear as it is.  ``place``: the compiled
    :func:`~ase_bpm.laws.compiled.place_contacts` that writes the arrays
    (None: NumPy, in :func:`write_contacts`).
    """

    def __init__(self, place=None):
        self.place = place
        self._arrays = (None, None, None)  # the gran_partner, gran_shear, bpm_id written
        self._build = None  # neighbour-list build of the last write
        self._l_k = np.zeros(0, dtype=np.int64)
        self._ij_k = (self._l_k, self._l_k)  # the contacts written last
        self._shear_kc = np.zeros((0, 3))
        self._at = None  # flat slots (shear.reshape(-1, 3) rows) of the contacts written last
        self._rows = None  # the shear of every row of that build's list (read-only)

    def forget(self, atoms: Atoms) -> None:
        """Drop the stored contacts from the atoms (a law without history
        keeps none), and what was remembered of the last write, if there was
        one (a frictionless run calls this every step: no allocation then)."""
        atoms.arrays.pop(PARTNER, None)
        atoms.arrays.pop(SHEAR, None)
        if self._build is not None:
            self.__init__(self.place)

    def _ours(self, atoms: Atoms) -> bool:
        partner, shear, ids = self._arrays
        return (partner is not None and atoms.arrays.get(PARTNER) is partner
                and atoms.arrays.get(SHEAR) is shear and atoms.arrays.get(ID) is ids)

    def shear_rows(self, atoms: Atoms, i_l, j_l, build: int) -> np.ndarray:
        """Stored shear of each pair ``(i_l, j_l)`` of neighbour-list build
        ``build`` (zero for pairs not in contact)."""
        ours = self._ours(atoms)
        if ours and build == self._build:
            return self._rows  # as the last write left them
        if ours:  # the contacts written last, in order (i, j)
            i_k, j_k = self._ij_k
            keys_k, shear_kc = i_k * len(atoms) + j_k, self._shear_kc
        else:
            keys_k, shear_kc = read_contacts(atoms)
        return lookup_shear(keys_k, shear_kc, i_l * len(atoms) + j_l)

    def write(self, atoms: Atoms, i_p, j_p, shear_pc, l_p, build: int, shear_lc,
              read_lc=None) -> bool:
        """Store the contacts and remember them; return whether the set of
        contacts changed (else only their shear did, written in place).

        The contacts come in order of ``(i, j)``, ``i < j``, as rows ``l_p``
        of a neighbour list that keeps that order (:class:`SphereVerletList`).
        ``shear_lc``: the same shear on every row of that list, zero on the
        rows not touching (kept, read-only, for the next step of that list).
        ``read_lc``: the stored shear the evaluation read (:meth:`shear_rows`
        of this build).  Where that is the rows kept at the last write, the
        arrays on the atoms were the ones written then, for this very list
        build (nothing is written between an evaluation and its commit), and
        only the shear moves when the same rows touch.
        """
        shear_lc.flags.writeable = False
        kept = read_lc is not None and read_lc is self._rows
        self._rows = shear_lc
        l_p = np.asarray(l_p, dtype=np.int64)
        if kept and same_array(l_p, self._l_k):
            scatter_rows(atoms.arrays[SHEAR], self._at, shear_pc)
            self._shear_kc = shear_pc
            return False
        ours = self._ours(atoms)
        partner, shear, self._at = write_contacts(atoms, i_p, j_p, shear_pc, reuse=ours,
                                                occupied=self._at if ours else None,
                                                place=self.place)
        self._arrays = (partner, shear, atoms.arrays[ID])
        self._ij_k = (i_p, j_p)
        self._shear_kc = shear_pc
        self._l_k, self._build = l_p, build
        return True
