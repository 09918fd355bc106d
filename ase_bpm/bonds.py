"""Bond lists kept on ``ase.Atoms``, in ASE's own lammps-data format.

``atoms.arrays["bonds"]`` holds one string per atom: comma-separated ``j(t)``
entries, ``j`` the 0-based index of the partner and ``t`` the bond type, or
``"_"`` when the atom lists no bond.  Each bond is listed once, on either of its
two atoms (the *owner*).  This is what ``ase.io.read(..., format="lammps-data",
atom_style="full")`` produces and what ASE's lammps-data writer reads.  A bond
that has broken stays listed with type 0, as LAMMPS marks it.

Per-bond state (for example the reference length ``bond_r0``) lives in per-atom
arrays named ``bond_*`` of shape ``(natoms, nslots, ...)``: entry ``[i, m]``
belongs to the ``m``-th bond listed on atom ``i``.  So ``atoms.copy()`` carries
the bonds and their state together.

LAMMPS equivalents: the ``Bonds`` section of a data file, ``create_bonds many``,
and the per-bond history that BPM bond styles keep (``fix BOND_HISTORY``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from ase import Atoms

from .neighbours import neighbour_pairs, periodic_half_widths

NO_BONDS = "_"
BOND_STATE_PREFIX = "bond_"


@dataclass(frozen=True)
class BondTable:
    """Every bond listed in ``atoms.arrays["bonds"]``, one row per bond.

    Rows are ordered by owner, then by position in the owner's string.
    """

    owner_b: np.ndarray  # atom whose string lists the bond
    slot_b: np.ndarray  # position of the bond in that string
    partner_b: np.ndarray  # the other atom
    type_b: np.ndarray  # bond type, 0 for a broken bond

    @property
    def nslots(self) -> int:
        """Width a per-bond state array needs (longest list on one atom)."""
        return int(self.slot_b.max()) + 1 if len(self.slot_b) else 0

    def __len__(self) -> int:
        return len(self.owner_b)


def empty_table() -> BondTable:
    z = np.zeros(0, dtype=np.int64)
    return BondTable(z, z.copy(), z.copy(), z.copy())


def parse_bonds(bonds_n: np.ndarray, natoms: int | None = None) -> BondTable:
    """Read ``atoms.arrays["bonds"]`` strings into a :class:`BondTable`.

    Raises ``ValueError`` naming the atom and the entry for a malformed entry,
    a partner index out of range, a bond of an atom to itself or a negative
    bond type.
    """
    natoms = len(bonds_n) if natoms is None else natoms
    owner, slot, partner, btype = [], [], [], []
    for i, text in enumerate(bonds_n):
        text = str(text).strip()
        if text in (NO_BONDS, ""):
            continue
        for m, entry in enumerate(text.split(",")):
            try:
                j_text, t_text = entry.strip().rstrip(")").split("(")
                j, t = int(j_text), int(t_text)
            except ValueError:
                raise ValueError(
                    f'atoms.arrays["bonds"][{i}] = {text!r}: entry {entry!r} '
                    'is not of the form "j(t)"'
                ) from None
            if not 0 <= j < natoms:
                raise ValueError(
                    f'atoms.arrays["bonds"][{i}] = {text!r}: partner index {j} '
                    f"is out of range for {natoms} atoms (were atoms deleted "
                    "after bonding?)"
                )
            if j == i:
                raise ValueError(
                    f'atoms.arrays["bonds"][{i}]: atom {i} is bonded to itself'
                )
            if t < 0:
                raise ValueError(
                    f'atoms.arrays["bonds"][{i}]: bond {i}-{j} has negative type {t}'
                )
            owner.append(i)
            slot.append(m)
            partner.append(j)
            btype.append(t)
    as_int = lambda values: np.asarray(values, dtype=np.int64)  # noqa: E731
    return BondTable(as_int(owner), as_int(slot), as_int(partner), as_int(btype))


def format_atom_bonds(partners, types) -> str:
    """The bonds string of one atom: ``"j(t),k(t)"`` or ``"_"``."""
    if len(partners) == 0:
        return NO_BONDS
    return ",".join(f"{j:d}({t:d})" for j, t in zip(partners, types))


def format_bonds(table: BondTable, natoms: int) -> np.ndarray:
    """Inverse of :func:`parse_bonds`: one string per atom."""
    strings = [NO_BONDS] * natoms
    if len(table):
        starts = np.flatnonzero(np.r_[True, np.diff(table.owner_b) != 0])
        ends = np.r_[starts[1:], len(table)]
        for s, e in zip(starts, ends):
            strings[table.owner_b[s]] = format_atom_bonds(
                table.partner_b[s:e], table.type_b[s:e]
            )
    return np.array(strings, dtype=str)


def bond_table(atoms: Atoms) -> BondTable:
    """The bonds of ``atoms`` as a :class:`BondTable` (empty without bonds)."""
    if "bonds" not in atoms.arrays:
        return empty_table()
    return parse_bonds(atoms.arrays["bonds"], len(atoms))


def get_bonds(atoms: Atoms, include_broken: bool = False):
    """The bond list as arrays ``(i_b, j_b, type_b)``.

    ``i_b`` is the atom that lists the bond, ``j_b`` its partner.  Broken bonds
    (type 0) are left out unless ``include_broken``.
    """
    table = bond_table(atoms)
    keep = slice(None) if include_broken else table.type_b > 0
    return table.owner_b[keep], table.partner_b[keep], table.type_b[keep]


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
        The atoms; ``atoms.arrays["bonds"]`` is created or extended in place.
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

    table = bond_table(atoms)
    intact = table.type_b > 0
    lo = np.minimum(table.owner_b[intact], table.partner_b[intact])
    hi = np.maximum(table.owner_b[intact], table.partner_b[intact])
    new = ~np.isin(i_p * natoms + j_p, lo * natoms + hi)
    i_p, j_p = i_p[new], j_p[new]
    if len(i_p) == 0:
        return 0

    # Append to each owner's list: slot = bonds already listed + rank among new.
    order = np.lexsort((j_p, i_p))
    i_p, j_p = i_p[order], j_p[order]
    listed_n = np.bincount(table.owner_b, minlength=natoms)
    first = np.searchsorted(i_p, i_p)
    slot_p = listed_n[i_p] + np.arange(len(i_p)) - first
    new_table = BondTable(
        np.r_[table.owner_b, i_p],
        np.r_[table.slot_b, slot_p],
        np.r_[table.partner_b, j_p],
        np.r_[table.type_b, np.full(len(i_p), bond_type, dtype=np.int64)],
    )
    order = np.lexsort((new_table.slot_b, new_table.owner_b))
    new_table = BondTable(*(a[order] for a in (
        new_table.owner_b, new_table.slot_b, new_table.partner_b, new_table.type_b)))
    atoms.arrays["bonds"] = format_bonds(new_table, natoms)
    for name in list(atoms.arrays):
        if name.startswith(BOND_STATE_PREFIX):
            state = widen_bond_state(atoms.arrays[name], new_table.nslots)
            state[i_p, slot_p] = np.nan
            atoms.arrays[name] = state
    return int(len(i_p))


def widen_bond_state(state: np.ndarray, nslots: int) -> np.ndarray:
    """A per-bond state array padded with NaN to at least ``nslots`` slots."""
    if state.shape[1] >= nslots:
        return state.copy()
    pad = np.full((state.shape[0], nslots - state.shape[1]) + state.shape[2:], np.nan)
    return np.concatenate([state, pad], axis=1)
