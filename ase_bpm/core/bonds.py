"""Bonds stored as integers on ``ase.Atoms``, safe under ASE's atom operations.

Every atom that takes part in bonds carries an ID, and bonds refer to their
partners by ID, as LAMMPS refers to atom IDs rather than to positions in its
arrays.  So bonds stay right whatever ASE does to the atoms: ``atoms.copy()``,
``atoms[mask]``, ``atoms[index_list]`` (any order, ``ase.build.sort`` too),
``del atoms[i]`` (bonds to the deleted atom go, the rest stay) and ``a + b`` of
two bodies bonded separately.

The arrays (``_n`` per atom, ``_nw`` per atom and slot; ``W`` is the longest
bond list of one atom):

==========================  =================================================
``arrays["bpm_id"]``         ``(N, 2)`` int32: the atom's ID, a random 62-bit
                             number stored as two words (0: none given yet)
``arrays["bond_partner"]``   ``(N, 2 W)`` int32: per slot, the partner's ID (two
                             words), 0 for an empty slot
``arrays["bond_type"]``      ``_nw`` int: bond type (>= 1), 0 once broken
``arrays["bond_<state>"]``   ``(N, W k)`` float: per-bond state of ``k`` numbers
                             per slot, side by side, NaN where unset
                             (``bond_r0``: the reference length, ``k = 1``)
==========================  =================================================

Each bond is listed once, on one of its two atoms (its *owner*); a broken bond
stays listed with type 0, as LAMMPS marks it.

*IDs as two words.*  An ID is a random number below 2**62 (so two bodies bonded
apart hardly ever share one), stored as two int32 words, its low and its high
31 bits: ASE's extxyz reader reads integer columns as int32, and takes these
back exactly.  In memory the code works on *keys*, the two words of an ID
read as one int64 (a view, no copy: :func:`keys_of`); :func:`read_ids` reads
any ID array, also the plain numbers (int64, one per ID) that ase_bpm wrote
before, and :func:`id_numbers` gives the numbers back (for checksums, which
thus do not depend on the stored form).  The calculators make these
arrays read-only after each evaluation: to edit bonds, replace an array
(``atoms.arrays["bond_type"] = new``), which the next evaluation picks up and
checks, or use :func:`create_bonds`.  Every array is one or two-dimensional,
as ASE's extxyz format needs.

``a + a.copy()``, ``atoms.repeat`` and ``atoms * (n, m, k)`` hold the same IDs
more than once; the next evaluation stops with an error that names the fix
(:func:`renew_ids` before combining, or :func:`repeat`).

The lammps-data strings that ``ase.io.read(..., format="lammps-data",
atom_style="full")`` gives (``arrays["bonds"]``: ``"j(t),k(t)"`` per atom,
0-based partner *index*, ``"_"`` for none) are taken in once, by
:func:`take_bonds`, :func:`create_bonds` or a calculator's first evaluation,
and :func:`with_bond_strings` gives a copy for ASE's lammps-data writer.  Being
indices, such strings do not survive reordering or combining atoms: take them
in first.

LAMMPS equivalents: the ``Bonds`` section of a data file, ``create_bonds
many``, and the per-bond history that BPM bond styles keep (``fix
BOND_HISTORY``).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from ase import Atoms
from ase.geometry.cell import complete_cell

from .neighbours import minimum_image, neighbour_pairs, periodic_half_widths
from .params import outside_stacklevel

ID, PARTNER, TYPE = "bpm_id", "bond_partner", "bond_type"
R0 = "bond_r0"  # per-bond reference length
CONTACT_PARTNER = "gran_partner"  # granular contact history, partners by ID too
REFERENCES = (PARTNER, CONTACT_PARTNER)  # arrays that hold other atoms' IDs
REPEAT_DROPS = (CONTACT_PARTNER, "gran_shear", "broken_bonds")  # see repeat
STRINGS = "bonds"  # ASE's lammps-data bonds strings
NO_BONDS = "_"
BOND_PREFIX = "bond_"  # every per-bond array: partner, type and state
NO_ID = 0  # an empty slot's partner, an atom without an ID
MIN_SLOTS = 16  # the narrowest per-bond arrays (see slot_width)
MAX_BUCKET = 64  # find_sorted: keys in one bucket beyond which it halves instead
KEYS_PER_CHUNK = 1 << 18  # find_sorted: keys looked for at a time
SLOT_TYPE = np.int32  # BondTable.slot_b as read from the atoms (a slot index)
WORD = np.int32  # the stored form of an ID: two words, each below 2**31
WORD_BITS = 31  # the bits of an ID in one word (ASE's extxyz reads int32)
ID_WORDS = 2  # words per ID
_ID_BITS = WORD_BITS * ID_WORDS  # IDs are numbers in [1, 2**62)
_WORD_MASK = 2 ** WORD_BITS - 1
#: checksums of IDs keep 63 bits: ASE's extxyz reader reads larger integers
#: in atoms.info as floats
CHECKSUM_MASK = 2 ** 63 - 1


class NoBondsCreatedWarning(UserWarning):
    """:func:`create_bonds` found no two (selected) atoms within its cutoff."""


@dataclass(frozen=True)
class BondTable:
    """The bonds listed on the atoms, one row per bond, ordered by owner and
    then by slot.  ``partner_b`` is the partner's index (not its ID)."""

    owner_b: np.ndarray  # atom that lists the bond
    slot_b: np.ndarray  # its slot on that atom (SLOT_TYPE when read from the atoms)
    partner_b: np.ndarray  # the other atom
    type_b: np.ndarray  # bond type, 0 for a broken bond

    @property
    def nslots(self) -> int:
        """Width the per-bond arrays need (the longest list on one atom)."""
        return int(self.slot_b.max()) + 1 if len(self.slot_b) else 0

    def __len__(self) -> int:
        return len(self.owner_b)


def empty_table() -> BondTable:
    z = np.zeros(0, dtype=np.int64)
    return BondTable(z, z.copy(), z.copy(), z.copy())


# -- IDs ------------------------------------------------------------------------------

def keys_of(words: np.ndarray) -> np.ndarray:
    """The keys (int64) of IDs in the stored form (int32, two words per ID,
    C-contiguous, as this module writes them): a view, ``(N, k)`` for
    ``(N, 2 k)``."""
    return words.view(np.int64)


def stored_ids(keys: np.ndarray) -> np.ndarray:
    """Keys ``(N,)`` or ``(N, k)`` (C-contiguous) in the stored form, ``(N, 2)``
    or ``(N, 2 k)`` int32: a view."""
    words = keys.view(WORD)
    return words.reshape(len(keys), ID_WORDS) if keys.ndim == 1 else words


def id_keys(numbers) -> np.ndarray:
    """The keys of IDs given as numbers (integers in ``[0, 2**62)``, as ase_bpm
    stored them before the two-word form), of the same shape."""
    numbers = np.asarray(numbers, dtype=np.int64)
    words = np.empty(numbers.shape + (ID_WORDS,), dtype=WORD)
    np.bitwise_and(numbers, _WORD_MASK, out=words[..., 0], casting="unsafe")
    np.right_shift(numbers, WORD_BITS, out=words[..., 1], casting="unsafe")
    return words.view(np.int64)[..., 0]


def id_numbers(keys: np.ndarray) -> np.ndarray:
    """The numbers of IDs given as keys (the inverse of :func:`id_keys`)."""
    words = np.ascontiguousarray(keys, dtype=np.int64)[..., None].view(WORD)
    return words[..., 0].astype(np.int64) | (words[..., 1].astype(np.int64) << WORD_BITS)


def read_ids(atoms: Atoms, name: str) -> np.ndarray:
    """The keys of the IDs in ``atoms.arrays[name]``: ``(N,)`` for the atoms'
    own (``bpm_id``), ``(N, slots)`` for partners (``bond_partner``,
    ``gran_partner``).

    Takes the stored form (int32, two words per ID) and IDs as numbers (any
    other integer type, one per ID: as ase_bpm wrote them before, or as a
    user gives them).  Raises ``ValueError`` naming the array, its shape and
    dtype for anything else (a wrong shape, floats, words or numbers out of
    range).
    """
    array = atoms.arrays[name]
    natoms, own = len(atoms), name == ID
    words = array.dtype == WORD
    if words:
        fits = array.ndim == 2 and array.shape[1] % ID_WORDS == 0 and (
            array.shape[1] == ID_WORDS or not own)
        top = _WORD_MASK
    else:
        fits = array.ndim == (1 if own else 2)
        top = 2 ** _ID_BITS - 1
    if not (np.issubdtype(array.dtype, np.integer) and fits and len(array) == natoms):
        numbers = "of another integer type (numbers, e.g. int64)"
        shapes = (f"({natoms}, 2) int32 (two words) or ({natoms},) {numbers}" if own else
                  f"({natoms}, 2 x slots) int32 (two words per ID) or ({natoms}, slots) "
                  f"{numbers}")
        # int32 of the numbers' shape: numbers taken for words
        taken = words and array.ndim == (1 if own else 2) and len(array) == natoms
        why = (f": {WORD.__name__} is read as two words per ID, not as numbers; give numbers "
               f'as int64 (atoms.arrays["{name}"] = ids.astype(np.int64))' if taken else "")
        raise ValueError(f'atoms.arrays["{name}"] must be an integer array of shape {shapes}, '
                         f"got shape {array.shape} and dtype {array.dtype}{why}")
    if array.size and (array.min() < 0 or array.max() > top):
        raise ValueError(f'atoms.arrays["{name}"] holds {"words" if words else "IDs"} '
                         f"outside [0, {top}]: these are no ase_bpm IDs")
    if not words:
        return id_keys(array)
    keys = keys_of(np.ascontiguousarray(array))
    return keys[:, 0] if own else keys


def store_ids(atoms: Atoms) -> Atoms:
    """Put ID arrays given as numbers (``int64``, as ase_bpm wrote them before
    the two-word form: an old restart file, a pickle) in the stored form, in
    place; returns ``atoms``.  (Calculators read either form; atoms in one
    form combine with ``a + b`` only with atoms in the same.)"""
    for name in (ID, *REFERENCES):
        if name in atoms.arrays and atoms.arrays[name].dtype != WORD:
            atoms.arrays[name] = stored_ids(np.ascontiguousarray(read_ids(atoms, name)))
    return atoms


def store_states(atoms: Atoms) -> Atoms:
    """Put per-bond states of several numbers given with three axes, ``(N, W,
    k)`` (as ase_bpm stored them before the two-axis form: an old restart
    file, a pickle), in the stored form ``(N, W k)``, each slot's numbers side
    by side, in place; returns ``atoms``.  (Calculators read either form;
    ASE's extxyz writer and ``a + b`` with atoms in the stored form take only
    the stored one.)"""
    for name in state_names(atoms):
        array = atoms.arrays[name]
        if array.ndim > 2:
            atoms.arrays[name] = np.ascontiguousarray(array).reshape(len(array), -1)
    return atoms


def new_ids(count: int) -> np.ndarray:
    """``count`` fresh IDs (keys), distinct from each other (and, being random
    62-bit numbers, from those of any other body in practice)."""
    rng = np.random.default_rng()
    while True:
        words = rng.integers(0, _WORD_MASK + 1, size=(count, ID_WORDS), dtype=WORD)
        ids = keys_of(words)[:, 0]
        if len(np.unique(ids)) == count and not (ids == NO_ID).any():
            return ids


def id_words(atoms: Atoms) -> np.ndarray:
    """``atoms.arrays["bpm_id"]`` in the stored form, with fresh IDs for atoms
    that have none: the atoms' own array when it is complete and stored, else
    a new one (the atoms are not changed)."""
    array = atoms.arrays.get(ID)
    if array is None:
        return stored_ids(new_ids(len(atoms)))
    ids = read_ids(atoms, ID)
    missing = ids == NO_ID
    if not missing.any() and array.dtype == WORD and array.flags.c_contiguous:
        return array
    ids = ids.copy()
    ids[missing] = new_ids(int(missing.sum()))
    return stored_ids(ids)


def atom_ids(atoms: Atoms) -> np.ndarray:
    """The keys of the atoms' IDs, with fresh ones for atoms that have none
    (:func:`id_words`; the atoms are not changed)."""
    return keys_of(id_words(atoms))[:, 0]


def renew_ids(atoms: Atoms) -> Atoms:
    """Give every atom a new ID, keeping its bonds (and contacts); returns
    ``atoms``.

    Use it on a copy before combining it with its original:
    ``a + renew_ids(a.copy())``.
    """
    old = read_ids(atoms, ID) if ID in atoms.arrays else None
    ids = new_ids(len(atoms))
    if old is not None:
        order = np.argsort(old, kind="stable")
        for name in REFERENCES:
            if name in atoms.arrays:
                refs = read_ids(atoms, name)
                at = np.minimum(np.searchsorted(old[order], refs), len(old) - 1)
                found = (old[order][at] == refs) & (refs != NO_ID)
                atoms.arrays[name] = stored_ids(np.where(found, ids[order][at], NO_ID))
    atoms.arrays[ID] = stored_ids(ids)
    return atoms


# -- reading ---------------------------------------------------------------------------

def parse_bonds(bonds_n: np.ndarray, natoms: int | None = None) -> BondTable:
    """Read lammps-data bonds strings into a :class:`BondTable`.

    Raises ``ValueError`` naming the atom and the entry for a malformed entry,
    a partner index out of range, a bond of an atom to itself or a negative
    bond type.
    """
    natoms = len(bonds_n) if natoms is None else natoms
    owner, slot, partner, btype = [], [], [], []
    where = f'atoms.arrays["{STRINGS}"]'
    for i, text in enumerate(bonds_n):
        text = str(text).strip()
        if text in (NO_BONDS, ""):
            continue
        for m, entry in enumerate(text.split(",")):
            try:
                j_text, t_text = entry.strip().rstrip(")").split("(")
                j, t = int(j_text), int(t_text)
            except ValueError:
                raise ValueError(f'{where}[{i}] = {text!r}: entry {entry!r} is not of the '
                                 'form "j(t)"') from None
            if not 0 <= j < natoms:
                raise ValueError(f"{where}[{i}] = {text!r}: partner index {j} is out of "
                                 f"range for {natoms} atoms")
            if j == i:
                raise ValueError(f"{where}[{i}]: atom {i} is bonded to itself")
            if t < 0:
                raise ValueError(f"{where}[{i}]: bond {i}-{j} has negative type {t}")
            owner.append(i)
            slot.append(m)
            partner.append(j)
            btype.append(t)
    as_int = lambda values: np.asarray(values, dtype=np.int64)  # noqa: E731
    return BondTable(as_int(owner), as_int(slot), as_int(partner), as_int(btype))


def int_array(atoms: Atoms, name: str, shape: tuple) -> np.ndarray:
    """``atoms.arrays[name]``, checked to be integers of ``shape`` (its second
    entry, if any, named "slots" in the error)."""
    array = atoms.arrays[name]
    if array.shape[:len(shape)] != shape or array.ndim != len(shape) or \
            not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f'atoms.arrays["{name}"] must be an integer array of shape '
                         f"{shape[:1] + ('slots',) * (len(shape) - 1)}, got shape "
                         f"{array.shape} and dtype {array.dtype}")
    return array


def resolve(ids_n: np.ndarray, partner_nw: np.ndarray, type_nw: np.ndarray,
            name: str = PARTNER) -> BondTable:
    """The bonds of ID-keyed arrays as a :class:`BondTable` of indices.

    Bonds whose partner ID belongs to no atom (deleted, or left out by a
    selection) are left out.  Raises ``ValueError`` for IDs held twice, a bond
    of an atom to itself and negative bond types.
    """
    if partner_nw.shape != type_nw.shape:
        raise ValueError(f'atoms.arrays["{PARTNER}"] and atoms.arrays["{TYPE}"] must have '
                         f"the same shape, got {partner_nw.shape} and {type_nw.shape}")
    # (the per-bond temporaries below are few and made in place where they can
    # be: at a million particles this read is the peak of a first evaluation)
    # (np.nonzero would give owners and slots as views of one block, which the
    # table would then hold whole)
    owner_b, slot_b = np.divmod(np.flatnonzero(partner_nw != NO_ID), partner_nw.shape[1])
    slot_b = slot_b.astype(SLOT_TYPE)  # slots are few (slot_width): half of int64
    if len(owner_b) == 0:
        return empty_table()
    order = np.argsort(ids_n, kind="stable")
    sorted_ids = ids_n[order]
    twice = np.flatnonzero((sorted_ids[1:] == sorted_ids[:-1]) & (sorted_ids[1:] != NO_ID))
    if len(twice):
        a, b = sorted(order[twice[0]:twice[0] + 2])
        raise ValueError(
            f"atoms {a} and {b} carry the same ID (atoms.arrays['{ID}']): the atoms hold "
            "one bonded body more than once (a + a.copy(), atoms.repeat or atoms * n), so "
            "bonds are ambiguous. Give the copy new IDs before combining, "
            "a + ase_bpm.renew_ids(a.copy()), or repeat with ase_bpm.repeat(atoms, reps)")
    pid_b = partner_nw[owner_b, slot_b]
    at = find_sorted(sorted_ids, pid_b)
    found = np.equal(sorted_ids[at], pid_b, out=np.empty(len(pid_b), dtype=bool))
    del pid_b
    if not found.all():
        owner_b, slot_b, at = owner_b[found], slot_b[found], at[found]
    del found
    partner_b = order[at].astype(np.int64, copy=False)
    del at
    type_b = type_nw[owner_b, slot_b].astype(np.int64, copy=False)
    itself = partner_b == owner_b
    if itself.any():
        b = int(np.argmax(itself))
        raise ValueError(f'atoms.arrays["{name}"]: atom {owner_b[b]} names itself as partner')
    if len(type_b) and type_b.min() < 0:
        b = int(np.argmin(type_b))
        raise ValueError(f'atoms.arrays["{TYPE}"]: bond {owner_b[b]}-{partner_b[b]} has '
                         f"negative type {type_b[b]}")
    return BondTable(owner_b.astype(np.int64, copy=False), slot_b, partner_b, type_b)


def find_sorted(sorted_keys: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Where each of ``keys`` stands in ``sorted_keys`` (ascending, distinct,
    int64): its index there, and for a key not among them some index, at
    which another key stands.

    ``np.searchsorted`` halves the range some twenty times a key, a cache
    miss each at a million keys; here the keys' span is cut into about one
    bucket per sorted key and each key looked for in its own bucket, key by
    key (IDs spread evenly over their span: random, or numbered), a chunk of
    keys at a time.  Keys bunched in few buckets are searched by halving."""
    count = len(sorted_keys)
    if count == 0 or len(keys) < count or sorted_keys[0] < 0:
        # (few keys: halving is as quick; negative keys: a span beyond int64)
        return np.minimum(np.searchsorted(sorted_keys, keys), max(count - 1, 0))
    lo, scale = sorted_keys[0], count / (float(sorted_keys[-1] - sorted_keys[0]) + 1.0)

    def bucket(k):  # (non-decreasing in k: the same steps for every key)
        b = ((k - lo).astype(np.float64) * scale).astype(np.int64)
        return np.clip(b, 0, count - 1, out=b)

    starts = np.searchsorted(bucket(sorted_keys), np.arange(count + 1))
    if np.diff(starts).max() > MAX_BUCKET:
        return np.minimum(np.searchsorted(sorted_keys, keys), count - 1)
    out = np.empty(len(keys), np.int64)
    for first in range(0, len(keys), KEYS_PER_CHUNK):
        part = keys[first:first + KEYS_PER_CHUNK]
        b = bucket(part)
        at, end = starts[b], starts[b + 1]
        todo = np.flatnonzero(at < end)
        while len(todo):  # step through each bucket until the key is met
            todo = todo[sorted_keys[at[todo]] != part[todo]]
            at[todo] += 1
            todo = todo[at[todo] < end[todo]]
        np.minimum(at, count - 1, out=out[first:first + len(part)])
    return out


def stored(atoms: Atoms) -> bool:
    """Are the bonds in ase_bpm's integer storage (rather than strings or absent)?"""
    return PARTNER in atoms.arrays


def bond_table(atoms: Atoms) -> BondTable:
    """The bonds of ``atoms`` as a :class:`BondTable` (empty without bonds),
    from the integer storage or from lammps-data strings not yet taken in."""
    if stored(atoms):
        if STRINGS in atoms.arrays:
            raise ValueError(
                f'atoms.arrays["{STRINGS}"] (lammps-data strings, which name partners by '
                f'index) and ase_bpm\'s atoms.arrays["{PARTNER}"] are both present: atoms '
                "were combined or reordered before their strings were taken in. Call "
                "ase_bpm.take_bonds(atoms) on each body before combining them, or delete "
                "one of the two")
        if TYPE not in atoms.arrays:
            raise ValueError(f'atoms.arrays["{PARTNER}"] needs atoms.arrays["{TYPE}"]')
        partner = read_ids(atoms, PARTNER)
        types = int_array(atoms, TYPE, (len(atoms), atoms.arrays[TYPE].shape[-1]))
        if partner.shape != types.shape:
            raise ValueError(
                f'atoms.arrays["{PARTNER}"] (shape {atoms.arrays[PARTNER].shape}, dtype '
                f'{atoms.arrays[PARTNER].dtype}) and atoms.arrays["{TYPE}"] (shape '
                f"{types.shape}) must list the same slots: two int32 words per slot, or one "
                "number")
        if ID not in atoms.arrays:
            raise ValueError(f'atoms.arrays["{PARTNER}"] needs the atom IDs it refers to, '
                             f'atoms.arrays["{ID}"]')
        return resolve(read_ids(atoms, ID), partner, types)
    if STRINGS in atoms.arrays:
        return parse_bonds(atoms.arrays[STRINGS], len(atoms))
    return empty_table()


def get_bonds(atoms: Atoms, include_broken: bool = False):
    """The bond list as index arrays ``(i_b, j_b, type_b)``.

    ``i_b`` is the atom that lists the bond, ``j_b`` its partner.  Broken bonds
    (type 0) are left out unless ``include_broken``.

    These are copies, to read.  The bonds live in ``atoms.arrays``
    (``bond_type``, ``bond_partner``, ``bond_r0``, ...), which a calculator
    makes read-only between evaluations: an edit in place stops with NumPy's
    "assignment destination is read-only".  To change bonds, replace the
    array, and the next evaluation reads and checks it; e.g. to break every
    bond of type 2::

        types = atoms.arrays["bond_type"].copy()
        types[types == 2] = 0
        atoms.arrays["bond_type"] = types

    Add bonds with :func:`create_bonds`; ``del atoms[i]`` takes atom ``i``'s
    bonds with it; after deleting ``bond_r0`` (or putting NaN in it) the next
    evaluation takes the reference lengths anew.
    """
    table = bond_table(atoms)
    if include_broken or table.type_b.min(initial=1) > 0:  # the table's own arrays
        return table.owner_b, table.partner_b, table.type_b
    keep = table.type_b > 0
    return table.owner_b[keep], table.partner_b[keep], table.type_b[keep]


def state_names(atoms: Atoms) -> list:
    """Names of the per-bond state arrays on the atoms (``bond_r0``, ...)."""
    return [name for name in atoms.arrays
            if name.startswith(BOND_PREFIX) and name not in (PARTNER, TYPE)]


def state_slots(array: np.ndarray, nslots: int) -> np.ndarray:
    """A per-bond state array ``(N, nslots k)`` (as stored: each slot's ``k``
    numbers side by side) as ``(N, nslots)`` or ``(N, nslots, k)``: a view.
    An array of more dimensions, ``(N, nslots, ...)`` (as ase_bpm stored
    states of several numbers before), is returned as it is."""
    if array.ndim != 2:
        return array
    if nslots == 0 or array.shape[1] % nslots:
        raise ValueError(f"a per-bond state array of shape {array.shape} does not hold the "
                         f"same numbers for each of {nslots} slots")
    k = array.shape[1] // nslots
    return array if k == 1 else array.reshape(len(array), nslots, k)


def _state_rows(atoms: Atoms, name: str, table: BondTable) -> np.ndarray:
    """Per-bond state ``name`` of the table's bonds, one row per bond."""
    array = atoms.arrays[name]
    if stored(atoms) and TYPE in atoms.arrays:
        try:
            array = state_slots(array, atoms.arrays[TYPE].shape[1])
        except ValueError as error:
            raise ValueError(f'atoms.arrays["{name}"]: {error}') from None
    rows = np.full((len(table),) + array.shape[2:], np.nan)
    inside = table.slot_b < array.shape[1]
    rows[inside] = array[table.owner_b[inside], table.slot_b[inside]]
    if name == R0:  # a reference length of 0 is none: ASE fills with zeros
        rows[~(rows > 0)] = np.nan
    return rows


# -- writing ---------------------------------------------------------------------------

def slot_width(nslots: int) -> int:
    """The width of the per-bond arrays for ``nslots`` bonds on one atom: a
    power of two, at least 16, so that bodies bonded separately (with bond
    lists of different lengths) mostly have the same width and combine with
    ``a + b`` (ASE needs equal widths); :func:`pad_bonds` widens the others."""
    width = MIN_SLOTS
    while width < nslots:
        width *= 2
    return width


def write_table(atoms: Atoms, ids_n, table: BondTable, state: dict, nslots: int = 0) -> None:
    """Store ``table`` (with per-row ``state``) on the atoms as integer arrays
    (``ids_n``: the atoms' IDs as keys)."""
    natoms = len(atoms)
    width = slot_width(max(table.nslots, nslots))
    atoms.arrays.pop(STRINGS, None)
    atoms.arrays[ID] = stored_ids(np.ascontiguousarray(ids_n, dtype=np.int64))
    # one array at a time, each replacing the old one (which can then go)
    partner = np.zeros((natoms, width), dtype=np.int64)
    partner[table.owner_b, table.slot_b] = ids_n[table.partner_b]
    atoms.arrays[PARTNER] = stored_ids(partner)
    types = np.zeros((natoms, width), dtype=np.int64)
    types[table.owner_b, table.slot_b] = table.type_b
    atoms.arrays[TYPE] = types
    for name, rows in state.items():
        array = np.full((natoms, width) + rows.shape[1:], np.nan)
        array[table.owner_b, table.slot_b] = rows
        atoms.arrays[name] = array.reshape(natoms, -1)  # (extxyz writes up to 2 axes)


def take_bonds(atoms: Atoms) -> int:
    """Take lammps-data bonds strings (``atoms.arrays["bonds"]``) into ase_bpm's
    integer storage, in place; returns the number of bonds listed.

    Call it before combining or reordering atoms read from a lammps-data file.
    Per-bond state arrays (``bond_*``, aligned with the strings' entries) are
    kept with their bonds.  Atoms without strings, or already taken in, are
    left as they are.
    """
    if STRINGS not in atoms.arrays or stored(atoms):
        return len(bond_table(atoms))
    table = parse_bonds(atoms.arrays[STRINGS], len(atoms))
    state = {name: _state_rows(atoms, name, table) for name in state_names(atoms)}
    write_table(atoms, atom_ids(atoms), table, state)
    return len(table)


def bond_strings(atoms: Atoms) -> np.ndarray:
    """The bonds as lammps-data strings (one per atom, ``"j(t),k(t)"`` or
    ``"_"``, 0-based partner indices, broken bonds with type 0), for ASE's
    lammps-data writer: ``atoms.arrays["bonds"] = bond_strings(atoms)``."""
    table = bond_table(atoms)
    strings = [[] for _ in range(len(atoms))]
    for i, j, t in zip(table.owner_b, table.partner_b, table.type_b):
        strings[i].append(f"{j:d}({t:d})")
    return np.array([",".join(s) if s else NO_BONDS for s in strings], dtype=str)


def pad_bonds(atoms: Atoms, nslots: int) -> Atoms:
    """Widen the per-bond arrays of ``atoms`` to at least ``nslots`` slots (a
    power of two), in place; returns ``atoms``.  ``a + b`` needs the same width
    on both: ``pad_bonds(b, a.arrays["bond_type"].shape[1])``."""
    table = bond_table(atoms)
    write_table(atoms, atom_ids(atoms), table,
                {name: _state_rows(atoms, name, table) for name in state_names(atoms)},
                nslots=nslots)
    return atoms


def ids_checksum(ids_n: np.ndarray) -> int:
    """A checksum of a set of atom IDs (keys), whatever their order: 63 bits
    (:data:`CHECKSUM_MASK`), of the IDs' numbers."""
    with np.errstate(over="ignore"):
        h = id_numbers(ids_n).astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        h ^= h >> np.uint64(31)
        return int(np.add.reduce(h, dtype=np.uint64)) & CHECKSUM_MASK if len(h) else 0


def same_checksum(recorded, checksum) -> bool:
    """Is ``recorded`` (a checksum as :func:`ids_checksum` gives it, or its 64
    bits as ase_bpm recorded them before) the checksum ``checksum``?"""
    return (checksum is not None and isinstance(recorded, (int, np.integer))
            and int(recorded) & CHECKSUM_MASK == checksum)


def with_bond_strings(atoms: Atoms) -> Atoms:
    """A copy of ``atoms`` whose bonds are lammps-data strings, for ASE's
    writer: ``ase.io.write(f, with_bond_strings(atoms), format="lammps-data",
    atom_style="full", bonds=True)``."""
    copy = atoms.copy()
    copy.arrays[STRINGS] = bond_strings(atoms)
    for name in (ID, PARTNER, TYPE, *state_names(atoms)):
        copy.arrays.pop(name, None)
    return copy


def create_bonds(
    atoms: Atoms,
    cutoff: float,
    bond_type: int = 1,
    mask: np.ndarray | None = None,
) -> int:
    """Bond every pair of atoms closer than ``cutoff``: LAMMPS ``create_bonds many``.

    Parameters
    ----------
    atoms:
        The atoms; their bonds are created or extended in place (see the
        module documentation for the arrays).
    cutoff:
        Largest bond length (distance units).  Under periodic boundaries the
        minimum image is used, so ``cutoff`` must stay below half the cell width.
    bond_type:
        Type (int >= 1) given to the new bonds.
    mask:
        Boolean per atom; both ends of a new bond must be selected (LAMMPS'
        group).  Default: all atoms.

    Pairs that already share an intact bond are skipped.  New bonds are listed
    on their lower-index atom and start with no reference state (NaN in every
    ``bond_*`` state array), so a calculator takes their reference length at
    its next evaluation.  Returns the number of bonds added.

    Warns (:class:`NoBondsCreatedWarning`, naming the cutoff and the shortest
    distance between two selected atoms) when no two selected atoms lie
    within ``cutoff``: a cutoff below the spacing bonds nothing.
    """
    natoms = len(atoms)
    if int(bond_type) != bond_type or bond_type < 1:
        raise ValueError(f"bond_type must be an integer >= 1, got {bond_type!r}")
    if not cutoff > 0:
        raise ValueError(f"cutoff must be positive, got {cutoff!r}")
    half_width = periodic_half_widths(atoms.cell, atoms.pbc)
    if cutoff >= half_width:
        raise ValueError(
            f"cutoff {cutoff} reaches half the periodic cell width ({half_width}): "
            "bonds would not have a unique minimum image"
        )
    if mask is None:
        mask = np.ones(natoms, dtype=bool)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != (natoms,):
        raise ValueError(f"mask must have one entry per atom ({natoms}), got {mask.shape}")

    i_p, j_p, shift_pc = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc, cutoff)
    d_p = np.linalg.norm(atoms.positions[j_p] + shift_pc - atoms.positions[i_p], axis=1)
    keep = (d_p <= cutoff) & mask[i_p] & mask[j_p]
    i_p, j_p = i_p[keep], j_p[keep]
    if len(i_p) == 0:
        _warn_none_within(atoms, mask, cutoff, half_width)
        return 0

    table = bond_table(atoms)
    intact = table.type_b > 0
    lo = np.minimum(table.owner_b[intact], table.partner_b[intact])
    hi = np.maximum(table.owner_b[intact], table.partner_b[intact])
    new = ~np.isin(i_p * natoms + j_p, lo * natoms + hi)
    i_p, j_p = i_p[new], j_p[new]
    if len(i_p) == 0:
        return 0

    # append to each owner's list: slot = bonds already listed + rank among new
    order = np.lexsort((j_p, i_p))
    i_p, j_p = i_p[order], j_p[order]
    listed_n = np.bincount(table.owner_b, minlength=natoms)
    first = np.searchsorted(i_p, i_p)
    slot_p = listed_n[i_p] + np.arange(len(i_p)) - first
    rows = np.r_[np.arange(len(table)), np.full(len(i_p), -1)]
    wide = BondTable(np.r_[table.owner_b, i_p], np.r_[table.slot_b, slot_p],
                     np.r_[table.partner_b, j_p],
                     np.r_[table.type_b, np.full(len(i_p), bond_type, dtype=np.int64)])
    order = np.lexsort((wide.slot_b, wide.owner_b))
    wide = BondTable(*(a[order] for a in (wide.owner_b, wide.slot_b, wide.partner_b,
                                          wide.type_b)))
    rows = rows[order]
    state = {}
    for name in state_names(atoms):
        old = _state_rows(atoms, name, table)
        state[name] = np.full((len(wide),) + old.shape[1:], np.nan)
        state[name][rows >= 0] = old[rows[rows >= 0]]
    write_table(atoms, atom_ids(atoms), wide, state)
    return int(len(i_p))


def _warn_none_within(atoms: Atoms, mask: np.ndarray, cutoff: float, half_width: float):
    """:class:`NoBondsCreatedWarning` for :func:`create_bonds`, which found no
    two selected atoms within ``cutoff``: with the shortest distance between
    two of them, searched within reaches doubling from ``cutoff`` (below
    ``half_width`` in periodic cells, and the selection's extent)."""
    x_n = atoms.positions[mask]
    selected = "selected atoms" if not mask.all() else "atoms"
    shortest = None
    if len(x_n) > 1:
        extent = float(np.linalg.norm(np.ptp(x_n, axis=0)))
        limit = min(np.nextafter(half_width, 0.0), np.nextafter(extent, np.inf))
        reach = cutoff
        while shortest is None and reach < limit:
            reach = min(2.0 * reach, limit)
            i_p, j_p, shift_pc = neighbour_pairs(x_n, atoms.cell, atoms.pbc, reach)
            if len(i_p):
                shortest = float(np.linalg.norm(x_n[j_p] + shift_pc - x_n[i_p], axis=1).min())
    if shortest is not None:
        found = f"the shortest distance between two {selected} is {shortest:.6g}"
    elif len(x_n) > 1:
        found = f"no two {selected} are closer than {limit:.6g}, half the periodic cell"
    else:
        found = f"{len(x_n)} atom{'s' * (len(x_n) != 1)} selected"
    warnings.warn(f"create_bonds made no bonds: no two {selected} lie within the cutoff "
                  f"{cutoff} ({found}); bonding a body needs a cutoff above its spacing",
                  NoBondsCreatedWarning, stacklevel=outside_stacklevel())


def repeat(atoms: Atoms, reps) -> Atoms:
    """``atoms.repeat(reps)`` with every bond kept right: each copy gets its own
    IDs, and a bond that crossed a periodic boundary joins the neighbouring
    copy, as the minimum image says (``atoms * reps`` would hold each ID
    ``n m k`` times).  Per-bond state (reference lengths) goes along; the
    calculators' record of their last evaluation (``bpm_*`` arrays and info),
    granular contact history and the broken-bond log do not: the result is a
    new scene."""
    reps = np.broadcast_to(np.asarray(reps, dtype=int), (3,))
    if np.any(reps < 1):
        raise ValueError(f"repeat: counts must be >= 1, got {reps.tolist()}")
    table = bond_table(atoms)
    state = {name: _state_rows(atoms, name, table) for name in state_names(atoms)}
    big = atoms.repeat(tuple(reps))
    # the record of the last evaluation, contact history and the broken-bond log
    # (atom indices of the small cell) belong to the old scene
    for record in [name for name in big.arrays if (name.startswith("bpm_") and name != ID)
                   or name in REPEAT_DROPS]:
        del big.arrays[record]
    for record in [key for key in big.info if str(key).startswith("bpm_")
                   or key in REPEAT_DROPS]:
        del big.info[record]
    natoms, copies = len(atoms), int(np.prod(reps))
    # ASE tiles the atoms copy by copy, the x copy index varying slowest
    offsets = np.array([(a, b, c) for a in range(reps[0]) for b in range(reps[1])
                        for c in range(reps[2])])
    cell = complete_cell(atoms.cell)  # zero vectors (no cell) become unit vectors
    x_n = atoms.positions
    r_bc = minimum_image(x_n[table.partner_b] - x_n[table.owner_b], atoms.cell, atoms.pbc)
    # the partner's image that the bond reaches, in whole cells from its own copy
    reach_bc = x_n[table.owner_b] + r_bc - x_n[table.partner_b]
    shift_b = np.round(np.linalg.solve(cell.T, reach_bc.T).T).astype(int) \
        if len(table) else np.zeros((0, 3), dtype=int)
    owner, partner = [], []
    for k, offset in enumerate(offsets):
        target = (offset + shift_b) % reps
        copy = (target[:, 0] * reps[1] + target[:, 1]) * reps[2] + target[:, 2]
        owner.append(table.owner_b + k * natoms)
        partner.append(table.partner_b + copy * natoms)
    big_table = BondTable(np.concatenate(owner), np.tile(table.slot_b, copies),
                          np.concatenate(partner), np.tile(table.type_b, copies))
    write_table(big, new_ids(len(big)), big_table,
           {name: np.concatenate([rows] * copies) for name, rows in state.items()},
           nslots=table.nslots)
    return big
