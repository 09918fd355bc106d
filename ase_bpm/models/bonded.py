"""Breakable bonds with a reference state, for any bond law.

LAMMPS equivalent: the machinery every BPM bond style shares (``BondBPM`` and
``fix BOND_HISTORY``): the reference length of each bond taken at its first
evaluation and any other per-bond history, breaking (type 0), the special list
that keeps bonded pairs out of the pair style, the ``store/local`` log of
broken bonds and ``nbond/atom``.

The bonds live on the atoms as integer arrays (:mod:`ase_bpm.core.bonds`).
:class:`BondState` reads them into a :class:`BondSet` when the arrays on the
atoms are not the ones it wrote last (a new calculator, ``atoms.copy()``, an
ASE operation, an array replaced by the user), checks them once, and after
that works on the set: it writes what changed (reference lengths, history,
broken bonds) back into the same arrays, in place, and leaves them read-only,
so nothing needs comparing or hashing at a step to notice edits.
"""

from __future__ import annotations

import copy
import operator
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Optional

import numpy as np
from ase import Atoms

from ..core.arrays import put_rows
from ..core.bond_set import BondSet, pair_keys  # noqa: F401 (BondSet: its old home)
from ..core.bonds import (ID, PARTNER, STRINGS, TYPE, BondTable, atom_ids, bond_table,
                          read_ids, state_slots, stored, write_table)
from ..core.spheres import OMEGA, QUAT
from ..core.neighbours import VerletList, minimum_image, periodic_half_widths
from ..core.params import (check_coeffs, check_type, coeff_tuple, json_coeffs,
                           outside_stacklevel)
from ..laws import COMPILED, compiled, kernel_route, law_routes
from ..laws.bond import (LAWS, TOTAL_ENERGY, TOTAL_RELEASED, BondInput, BondLaw,
                         BondScene, BondSums)
from ..laws.timestep import Springs
from .base import BPMCalculator
from .evaluation import Evaluation
from .model import Model
from .outputs import BOND_COUNTS, DAMAGE, NBONDS

X_REF = "bpm_x_ref"  # per-atom reference position (for the broken-bond log)
BROKEN_LOG = "broken_bonds"  # info: one row per broken bond
BROKEN_LOG_COLUMNS = ("i", "j", "step", "x", "y", "z", "x_ref", "y_ref", "z_ref")

#: listed pairs per piece when a contact list looks their keys up among the
#: bonded pairs' (at a rebuild)
KEYS_PIECE = 2 ** 18


def valid_in_order(law, values, order) -> bool:
    """Are the coefficients ``values`` (a tuple) valid for ``law`` read in
    ``order`` (another order than the law's own, e.g. its legacy LAMMPS
    line; False where ``order`` is the law's own)?"""
    if tuple(order) == tuple(law.coefficients) or len(values) != len(order):
        return False
    try:
        law.check(dict(zip(order, check_coeffs("", "", values, order, law.positive,
                                                law.non_negative))), "")
    except ValueError:
        return False
    return True


class NoBondsWarning(UserWarning):
    """Bond coefficients are given for atoms that carry no bonds at all."""


class BondState:
    """The bonds a calculator works with, cached between evaluations.

    ``check_types`` is called with every newly read table, to reject bond
    types the model has no coefficients for.  ``states`` names the per-bond
    states and the trailing shape of each (``{"r0": ()}`` by default); state
    ``name`` lives in ``atoms.arrays["bond_<name>"]``.
    """

    def __init__(self, check_types=None, states=None):
        self.check_types = check_types
        self.shapes = dict(states or {"r0": ()})
        self.current: Optional[BondSet] = None
        self.reread = True  # the last call read the bonds anew
        self._arrays = None  # name -> the array object on the atoms, read or written last
        #: the next :meth:`write` takes the arrays over, in full (after a read)
        self.takes_over = True

    def _names(self) -> list:
        return [ID, PARTNER, TYPE, STRINGS] + ["bond_" + name for name in self.shapes]

    def replaced(self, atoms: Atoms) -> bool:
        """Are the bond arrays on ``atoms`` other than the very ones this
        state read or wrote last (or none were yet)?"""
        ours = self._arrays
        return not (ours is not None and self.current is not None
                    and self.current.natoms == len(atoms)
                    and all(map(operator.is_, map(atoms.arrays.get, ours), ours.values())))

    def bonds(self, atoms: Atoms, ours: bool = False) -> BondSet:
        """The bonds on ``atoms``: the cached set while the arrays are ours,
        else read and checked anew (nothing on the atoms changes until
        :meth:`write`).  ``ours``: the caller found them the very arrays
        this state left (the ordinary step, ``Context.continues``)."""
        self.reread = not (ours and self.current is not None) and self.replaced(atoms)
        if not self.reread:
            return self.current
        self.current = self._read(atoms)
        self._arrays = {name: atoms.arrays.get(name) for name in self._names()}  # as read
        for array in self._arrays.values():  # from now on, edits replace them (noticed)
            if array is not None:
                array.flags.writeable = False
        self.takes_over = True  # the next write puts ase_bpm's own arrays in their place
        return self.current

    def peek(self, atoms: Atoms) -> BondSet:
        """The bonds on ``atoms`` without taking them over: the cached set while
        the arrays are ours, else a set read anew that this state neither
        keeps nor marks on the atoms (for a look that changes nothing)."""
        return self._read(atoms) if self.replaced(atoms) else self.current

    def aside(self, atoms: Atoms) -> BondSet:
        """:meth:`peek`, compacted and with a cache of its own: what is built on
        it (per-bond columns, sparse matrices, for an estimate) is dropped
        with it rather than kept with the run's set (and carried through
        every breaking)."""
        bonds = copy.copy(self.peek(atoms).compacted())
        bonds.cache = dict(bonds.cache)
        return bonds

    def _read(self, atoms: Atoms) -> BondSet:
        """The bonds on ``atoms``, read and checked."""
        table = bond_table(atoms)
        if self.check_types is not None:
            self.check_types(table)
        state = {}
        width = atoms.arrays[TYPE].shape[1] if PARTNER in atoms.arrays else None
        for name, shape in self.shapes.items():
            rows = np.full((len(table),) + shape, np.nan)
            array = atoms.arrays.get("bond_" + name)
            if array is not None and width is not None:
                size = int(np.prod(shape))
                want = (len(atoms), width * size)
                # (or as ase_bpm stored states of several numbers before: (N, W) + shape)
                if array.shape not in (want, (len(atoms), width) + shape) or \
                        array.dtype.kind not in "fiu":
                    per_slot = "one" if size == 1 else f"{size} numbers"
                    raise ValueError(
                        f'atoms.arrays["bond_{name}"] must be numbers of shape {want}, '
                        f'{per_slot} per slot of atoms.arrays["{TYPE}"], got shape '
                        f"{array.shape} and dtype {array.dtype}")
                array = state_slots(array, width)
            if array is not None and width is not None and len(table):
                rows[...] = array[table.owner_b, table.slot_b]
            if name == "r0":  # a reference length of 0 is none (ASE fills with zeros)
                rows[~(rows > 0)] = np.nan
            state[name] = rows
        ids = (atom_ids(atoms) if len(table) else read_ids(atoms, ID) if ID in atoms.arrays
               else np.zeros(len(atoms), np.int64))
        return BondSet(table, len(atoms), ids, state)

    # -- writing back (commit) ------------------------------------------------------
    def write(self, atoms: Atoms, bonds: BondSet) -> None:
        """Put ``bonds`` on the atoms: in full after a fresh read (ase_bpm's
        integer arrays, read-only), else only what changed, in place."""
        arrays = atoms.arrays
        if self.takes_over or self.replaced(atoms):  # take the arrays over
            # the arrays read last go as their replacements are put in place,
            # not after all of them (at a million particles, 0.38 GB at once)
            self._arrays = None
            if len(bonds.table) or stored(atoms) or STRINGS in arrays:
                write_table(atoms, bonds.ids_n, bonds.table,
                       {"bond_" + name: rows for name, rows in bonds.state.items()})
            for name in self._names():
                if name in arrays:
                    arrays[name].flags.writeable = False
            self._arrays = {name: arrays.get(name) for name in self._names()}
            self.takes_over = False
        else:
            table = bonds.table
            for name, rows in bonds.dirty.items():
                key = name if name == TYPE else "bond_" + name
                values = table.type_b if name == TYPE else bonds.state[name]
                array = arrays[key]
                array.flags.writeable = True
                slots = array if name == TYPE else state_slots(array, arrays[TYPE].shape[1])
                put_rows(slots, values, table.owner_b, table.slot_b, rows)
                array.flags.writeable = False
        bonds.dirty = {}
        self.current = bonds

    def break_bonds(self, atoms: Atoms, bonds: BondSet, broken_b, step: int,
                    r_kc: np.ndarray, log: bool, lazy: bool = False) -> BondSet:
        """The set after the ``broken_b`` intact bonds broke (type 0), to be
        written by :meth:`write` (``r_kc``: their vectors; ``lazy``: as for
        :meth:`BondSet.without`).

        With ``log``, append them to ``atoms.info["broken_bonds"]`` (LAMMPS
        ``store/local``): atoms ``i < j``, step, centre now (``x_i + r/2``) and
        in the reference positions ``bpm_x_ref``.
        """
        i_k, j_k = bonds.i_b[broken_b], bonds.j_b[broken_b]
        new = bonds.without(broken_b, lazy)
        if log:
            centre = np.take(atoms.positions, i_k, axis=0) + 0.5 * r_kc
            x_ref = atoms.arrays[X_REF]
            d_ref = minimum_image(np.take(x_ref, j_k, axis=0) - np.take(x_ref, i_k, axis=0),
                                  atoms.cell, atoms.pbc)
            centre_ref = np.take(x_ref, i_k, axis=0) + 0.5 * d_ref
            rows_log = np.column_stack([np.minimum(i_k, j_k), np.maximum(i_k, j_k),
                                        np.full(len(i_k), step), centre, centre_ref])
            old = atoms.info.get(BROKEN_LOG, np.zeros((0, len(BROKEN_LOG_COLUMNS))))
            atoms.info[BROKEN_LOG] = np.vstack([old, rows_log])
        return new


class ContactList:
    """Pairs that may touch: a Verlet list (``cutoff + skin``) without the pairs
    joined by an intact bond, whatever the periodic image (LAMMPS' special
    list with a 1-2 weight of 0), unless ``overlay``.

    Bonds that broke since the last call join in without a full search.
    """

    def __init__(self, cutoff: float, skin: float, overlay: bool = False, neighbours=None):
        #: the list the pairs come from (``neighbours``: a list kept elsewhere,
        #: such as a granular model's search, which its owner brings up to date)
        self.neighbours = VerletList(cutoff, skin) if neighbours is None else neighbours
        self.overlay = overlay
        self._cache = None  # (list build, bond set serial, allowed_p, select_p)
        #: (select_p, what a model made from those rows of the list, such as a
        #: kernel made ready for them): dropped with the pairs it was made from
        self.prepared = (None, None)

    def pairs(self, atoms: Atoms, bonds: BondSet):
        """``(i_p, j_p, r_pc)`` of the candidate pairs, ``r = x_j - x_i``."""
        nl, select = self.listed(atoms, bonds)
        return nl.i_p[select], nl.j_p[select], nl.pair_vectors(atoms.positions, select)

    def listed(self, atoms: Atoms, bonds: BondSet) -> tuple:
        """``(neighbours, select_p)``: the Verlet list, brought up to date, and
        the rows of its candidate pairs (for kernels that gather the vectors
        themselves): the same array while the list and the bonds stay."""
        nl = self.neighbours
        if nl.stale(atoms.positions, atoms.cell, atoms.pbc):
            # what was made from the old pairs goes before the search (peak memory)
            self._cache, self.prepared = None, (None, None)
            nl.rebuild(atoms.positions, atoms.cell, atoms.pbc)
        return nl, self.rows(len(atoms), bonds)

    def rows(self, natoms: int, bonds: BondSet) -> np.ndarray:
        """The rows of the candidate pairs in the list as it is (the same
        array while the list and the bonds stay)."""
        cached = self._cache
        if cached is not None and cached[0] == self.neighbours.nbuilds \
                and cached[1] == bonds.serial:
            return cached[3]
        return self._select(natoms, bonds)

    def _select(self, natoms: int, bonds: BondSet) -> np.ndarray:
        """The rows of the candidate pairs after the list was built or bonds
        broke (:meth:`listed` keeps them)."""
        nl, cached = self.neighbours, self._cache
        if cached is not None and cached[0] == nl.nbuilds:
            if bonds.parent == cached[1] and bonds.broken_keys is not None:
                allowed = cached[2].copy()
                allowed[_listed(nl.i_p, nl.j_p, bonds.broken_keys, natoms)] = True
                self._cache = (nl.nbuilds, bonds.serial, allowed, np.flatnonzero(allowed))
                return self._cache[3]
        self._cache = None  # the last build's masks go first (peak memory)
        # the pairs' keys, for this search only and a piece at a time (kept, they
        # were 47 MB at a million atoms, and the search's temporaries three
        # times that; the bonds that break later are found through the list)
        allowed = np.ones(len(nl.i_p), dtype=bool)
        if not self.overlay:
            for start in range(0, len(allowed), KEYS_PIECE):
                part = slice(start, start + KEYS_PIECE)
                allowed[part] = ~bonds.bonded(pair_keys(nl.i_p[part], nl.j_p[part], natoms))
        self._cache = (nl.nbuilds, bonds.serial, allowed, np.flatnonzero(allowed))
        return self._cache[3]


def _listed(i_p: np.ndarray, j_p: np.ndarray, wanted: np.ndarray, natoms: int) -> np.ndarray:
    """Rows of the pair list ``(i_p, j_p)`` (in order of ``(i, j)``, ``i <= j``,
    as :class:`VerletList` keeps it) of every pair whose :func:`pair_keys` is
    one of ``wanted`` (a pair may be listed more than once, through several
    periodic images): among the rows of each pair's first atom, those of its
    second."""
    first_k, second_k = np.divmod(wanted, natoms)
    start_k = np.searchsorted(i_p, first_k, side="left")
    count_k = np.searchsorted(i_p, first_k, side="right") - start_k
    # the rows start_k .. start_k + count_k - 1 of every wanted pair, one after another
    of_k = np.repeat(np.arange(len(wanted)), count_k)
    rows = start_k[of_k] + np.arange(len(of_k)) - np.repeat(np.cumsum(count_k) - count_k,
                                                            count_k)
    return rows[j_p[rows] == second_k[of_k]]




def write_bond_counts(atoms: Atoms, bonds: BondSet, broken_ends=None) -> None:
    """Per-atom outputs: ``nbonds`` (intact) and ``damage`` (fraction broken).

    ``broken_ends``: the two atoms of each bond broken since the counts on the
    atoms were written, to update them rather than count afresh.
    """
    table, n = bonds.table, len(atoms)
    listed = bonds.cache.get("keep:listed")  # listed bonds per atom: breaking keeps them
    if broken_ends is not None and listed is not None:
        nbonds = atoms.arrays[NBONDS] - np.bincount(np.concatenate(broken_ends),
                                                      minlength=n)
    else:
        intact = table.type_b > 0
        nbonds = (np.bincount(table.owner_b[intact], minlength=n)
                  + np.bincount(table.partner_b[intact], minlength=n))
        listed = bonds.cache["keep:listed"] = (np.bincount(table.owner_b, minlength=n)
                                               + np.bincount(table.partner_b, minlength=n))
    atoms.arrays[NBONDS] = nbonds
    atoms.arrays[DAMAGE] = np.divide(listed - nbonds, listed, out=np.zeros(n),
                                       where=listed > 0)


# -- the machinery every bonded model shares ---------------------------------------------

#: the key of a bond set's :class:`BondPlan` in its cache
PLAN = "plan"
#: the virial of bonds in an open box, where no stress is asked for (read-only)
NO_VIRIAL = np.zeros((3, 3))
NO_VIRIAL.flags.writeable = False


@dataclass
class LawGroup:
    """The bonds of one law in a bond set, as the compiled route runs them."""

    law: BondLaw
    select: Optional[np.ndarray]  # the law's bonds (None: every bond of the set)
    damped: bool  # the law uses velocities here (damping)
    coeff_t: dict  # the law's coefficients by bond type
    #: the law's compiled twin made ready for these bonds (``BondLaw.prepare``),
    #: at the group's first evaluation
    kernel: Optional[Callable] = None


@dataclass
class BondPlan:
    """What runs on one bond set, worked out at the set's first evaluation
    and kept with it (:data:`PLAN` in ``BondSet.cache``): a new set (bonds
    broke, or the bonds on the atoms were read anew) has a plan of its own,
    so nothing here is looked at again while the set lasts."""

    groups: dict  # law name -> its bonds (BondedModel.law_groups)
    compiled: bool  # every law of these bonds runs its compiled twin
    lazy: bool  # broken bonds may stay listed (BondedModel.breaks_lazily)
    damped: bool  # some law of these bonds uses velocities
    twins: list  # a LawGroup for each law that runs its compiled twin
    twins_damped: bool  # some of them uses velocities
    options: dict  # the model's switches, as the laws get them
    no_breaks: np.ndarray  # all-False, read-only: the set's bonds when none breaks
    #: some of them gives torques (``BondLaw.turns``), and damps them
    twins_turn: bool = False
    twins_turn_damped: bool = False


def _place(full: Optional[np.ndarray], values: np.ndarray, select, nb: int) -> np.ndarray:
    """``values`` of the bonds ``select`` put into ``full`` (zeros for ``nb``
    bonds when None; all bonds: ``values`` itself)."""
    if select is None:
        return values
    if full is None:
        full = np.zeros(nb, dtype=values.dtype)
    full[select] = values
    return full


def _replay_for_virial(scenes: list, x_nc: np.ndarray, r0_b: np.ndarray) -> Callable:
    """The virial of compiled laws' bonds, worked out when asked for: each
    law's kernel runs again on its ``BondScene`` with the virial on, into
    sums of its own (at the positions ``x_nc`` of the evaluation, with the
    reference lengths ``r0_b`` it took; nothing else is written)."""
    def virial() -> np.ndarray:
        sums = None
        for law, scene in scenes:
            if sums is None:
                given = scene.sums
                sums = BondSums.zeros(len(x_nc), len(scene.i_b), given.fd_nc is not None,
                                      scene.breaking)
                if given.t_nc is not None:
                    sums.with_torques(given.td_nc is not None)
            law.add_sums(replace(scene, x_nc=x_nc, r0_b=r0_b, sums=sums, virial=True))
        return np.zeros((3, 3)) if sums is None else sums.virial_cc.copy()
    return virial


@dataclass
class BondPart:
    """What the bonds contributed to one evaluation (typed, for the commit)."""

    bonds: BondSet  # the intact bonds before this evaluation
    r_bc: Optional[np.ndarray]  # bond vectors (None: not kept, on the compiled route)
    r0_b: np.ndarray  # reference lengths (fresh ones taken now)
    fresh_b: Optional[np.ndarray]  # bonds whose reference length is taken now (or None)
    broken_b: np.ndarray  # bonds that break in this step
    f_nc: np.ndarray  # per-atom force of the bonds
    fd_nc: Optional[np.ndarray]  # its damping part
    energy: float  # elastic energy of the bonds that stay
    released: float  # elastic energy of the bonds that broke
    virial_pairs: Optional[tuple]  # (r_bc, f_bc) for the virial (or None: virial_cc)
    history: dict = field(default_factory=dict)  # name -> (selection, values)
    node: dict = field(default_factory=dict)  # per-atom outputs of the laws
    virial_cc: Optional[np.ndarray] = None  # the virial, summed by a compiled kernel
    nodes: Any = None  # what BondedModel._compiled_nodes worked out (compiled route)
    #: the compiled kernels run again with the virial on, when it is first asked for
    virial_replay: Optional[Callable] = None
    r_kc: Optional[np.ndarray] = None  # the broken bonds' vectors, once worked out
    t_nc: Optional[np.ndarray] = None  # per-atom torque of the bonds (laws that turn)
    td_nc: Optional[np.ndarray] = None  # its damping part
    #: per-bond quantities of laws that turn, kept for an analysis only
    #: (``BondLocal.extra``: the torques on each end)
    per_bond: dict = field(default_factory=dict)
    #: (f_b, fj_b): the force on i towards j and on j towards i along each bond
    #: (fj_b None: the same), as the NumPy laws gave them, kept for an analysis
    #: only (``BondedModel._analysing``)
    magnitudes: Optional[tuple] = None

    def virial(self) -> np.ndarray:
        """The bonds' virial, ``sum_b r_b (x) f_b``."""
        if self.virial_cc is None and self.virial_replay is not None:
            self.virial_cc, self.virial_replay = self.virial_replay(), None
        if self.virial_cc is not None:
            return self.virial_cc
        r_bc, f_bc = self.virial_pairs
        return r_bc.T @ f_bc

    def broken_vectors(self, atoms: Atoms) -> np.ndarray:
        """The vectors of the bonds that break now (minimum image; ``atoms``
        at the evaluation's positions), worked out once."""
        if self.r_kc is None:
            if self.r_bc is not None:
                self.r_kc = self.r_bc[self.broken_b]
            else:
                i_k, j_k = self.bonds.i_b[self.broken_b], self.bonds.j_b[self.broken_b]
                self.r_kc = minimum_image(np.take(atoms.positions, j_k, axis=0)
                                          - np.take(atoms.positions, i_k, axis=0),
                                          atoms.cell, atoms.pbc)
        return self.r_kc


def _sum_of(a: Optional[np.ndarray], b: Optional[np.ndarray]) -> Optional[np.ndarray]:
    """``a + b`` of two per-atom sums either of which may be None (none)."""
    return a if b is None else (b if a is None else a + b)


def _joined(twins: BondPart, others: BondPart) -> BondPart:
    """One bond part of the same bonds from two: ``twins``, of the laws run
    compiled, and ``others``, of those run on NumPy (each with the other's
    bonds at zero force and energy, unbroken, their reference lengths NaN
    or not yet taken)."""
    fd_nc = _sum_of(twins.fd_nc, others.fd_nc)
    r0_b = others.r0_b
    if others.fresh_b is not None:  # each part took those of its own laws' bonds
        r0_b = np.where(np.isnan(twins.r0_b), others.r0_b, twins.r0_b)
    part = BondPart(bonds=others.bonds, r_bc=others.r_bc, r0_b=r0_b, fresh_b=others.fresh_b,
                    broken_b=twins.broken_b | others.broken_b, f_nc=twins.f_nc + others.f_nc,
                    fd_nc=fd_nc,
                    energy=twins.energy + others.energy,
                    released=twins.released + others.released, virial_pairs=None,
                    history={**twins.history, **others.history},
                    node={**twins.node, **others.node}, nodes=twins.nodes)
    part.t_nc = _sum_of(twins.t_nc, others.t_nc)
    part.td_nc = _sum_of(twins.td_nc, others.td_nc)
    part.virial_replay = lambda: twins.virial() + others.virial()
    return part


@dataclass(kw_only=True)
class BondedEvaluation(Evaluation):
    """An evaluation of a bonded model: the forces plus its bonds' part."""

    bonds: BondPart
    #: the granular contacts' evaluation, where the model has them (SpringModel)
    granular: Optional[Evaluation] = None


class BondedModel(Model):
    """A model whose bonds follow registered bond laws (:mod:`ase_bpm.laws.bond`).

    Owns what every law shares, as LAMMPS' ``BondBPM``: the coefficient
    tables (checked against each law's schema), the reference length of each
    bond (taken at its first evaluation), per-bond history, breaking (in steps
    only), the broken-bond record, per-atom ``nbonds``/``damage`` and the
    bonds' part of the energy ledger.  A model sets ``family`` (the laws it
    can run) and ``default_law`` (for coefficient tuples without a law name),
    and adds what is its own: contacts, node state.
    """

    family = ""
    default_law: Optional[str] = None
    #: the model's contact law (None: none); it acts where pair_coeffs are given
    PAIR_LAW = None
    #: the laws run in one compiled pass over all the bonds, so they share a
    #: route (:func:`ase_bpm.laws.law_routes`, ``together``); else each law
    #: runs on its own
    laws_together = False
    #: parameters handed to the laws as ``options`` (e.g. smooth, normalize)
    law_options: tuple = ()
    watched_arrays = ("type",)
    per_atom_outputs = BOND_COUNTS
    _warned_no_bonds = False  # (see _check_bond_types)
    _analysing = False  # an analysis (analyse) never tests breaking

    # -- coefficients -----------------------------------------------------------------
    def _law_for(self, t: int, coeffs) -> tuple:
        """The law of bond type ``t`` and its checked coefficients by name:
        ``coeffs`` a tuple in the order of the law's LAMMPS ``bond_coeff``
        line (led by the model's name where the model has no default law),
        or a mapping from the law's coefficient names (and ``"model"``)."""
        given_by_name = isinstance(coeffs, Mapping)
        if given_by_name:
            named = dict(coeffs)
            name = named.pop("model", self.default_law)
            law = LAWS.get(name)
            if law is not None and law.family == self.family:
                coeffs = (name, *coeff_tuple("bond_coeffs for bond type", t, named,
                                             law.coefficients))
            else:
                coeffs = (name,)  # (refused below, naming the models)
        coeffs = tuple(coeffs)
        if coeffs and isinstance(coeffs[0], str):
            name, values, where = coeffs[0], coeffs[1:], f"bond_coeffs for bond type {t}, model"
        elif self.default_law is not None:
            name, values, where = self.default_law, coeffs, "bond_coeffs for bond type"
        else:
            name = coeffs[0] if coeffs else None
            values, where = (), ""
        law = LAWS.get(name)
        if law is None or law.family != self.family:
            known = ", ".join(n for n, k in LAWS.items() if k.family == self.family)
            raise ValueError(f"bond_coeffs for bond type {t}: unknown model {name!r} (one of "
                             f"{known})")
        label = name if where.endswith("model") else t
        try:
            named = dict(zip(law.coefficients, check_coeffs(
                where, label, values, law.coefficients, law.positive, law.non_negative)))
            law.check(named, f"{where} {label}")
        except ValueError as exc:
            note = "" if given_by_name else self._other_order(law, values)
            raise ValueError(f"{exc}{note}") from None
        if given_by_name:
            self._named_types.add(t)
        return law, named

    @staticmethod
    def _other_order(law, values) -> str:
        """A note for an error about the tuple ``values`` where the law's
        legacy LAMMPS order reads them as valid coefficients (else "")."""
        if not valid_in_order(law, values, getattr(law, "legacy_order", law.coefficients)):
            return ""
        return f" (the tuple fits the other order: {law.order_note()})"

    def _setup_bonds(self) -> None:
        """Laws and coefficient tables from ``bond_coeffs``."""
        laws, values = {}, {}
        self._named_types = set()  # bond types given by a mapping (no order to mistake)
        for t, coeffs in self.parameters["bond_coeffs"].items():
            t = check_type("bond_coeffs", t)
            laws[t], values[t] = self._law_for(t, coeffs)
        size = max(laws, default=0) + 1
        self._laws = {law.name: law() for law in laws.values()}
        self._law_names = sorted(self._laws)  # a law's code: its place here
        self._law_code = np.zeros(size, dtype=np.int64)
        self._law_of_type = np.full(size, "", dtype=object)
        names = sorted({n for v in values.values() for n in v})
        self._coeff_table = {n: np.full(size, np.nan) for n in names}
        for t, law in laws.items():
            self._law_of_type[t] = law.name
            self._law_code[t] = self._law_names.index(law.name)
            for n, value in values[t].items():
                self._coeff_table[n][t] = value
        self._bond_values = values
        self.needs_timestep = any(law.needs_timestep for law in laws.values())
        #: some law gives torques from the particles' orientations (bpm/rotational)
        self.own_torques = self.turns = any(law.turns for law in laws.values())
        self.ledger_balances = all(law.has_energy for law in laws.values())
        #: an orientation changed is a new configuration, as a position moved
        self.watched_arrays = type(self).watched_arrays + ((QUAT,) if self.turns else ())
        #: (and the forces depend on it: in the signature too)
        self.signature_arrays = type(self).signature_arrays + ((QUAT,) if self.turns else ())
        self._states = {"r0": ()}
        for law in self._laws.values():
            self._states.update(law.states)
        #: "compiled" or "numpy": the route this calculator resolved
        #: (:func:`ase_bpm.laws.kernel_route`); what each law runs on:
        #: :attr:`kernel_routes`
        self.kernel_route = kernel_route(self.parameters.get("kernels", "auto"))
        #: the route each law runs on: law name (and "contacts", where
        #: pair_coeffs are given) -> "compiled" or "numpy"
        #: (:func:`ase_bpm.laws.law_routes`)
        self.kernel_routes = law_routes(
            self.kernel_route, self._laws.values(),
            self.PAIR_LAW if self.parameters.get("pair_coeffs") else None, self.laws_together)

    def _check_bond_types(self, table: BondTable) -> None:
        if not len(table) and self._bond_values and not self._warned_no_bonds:
            self._warned_no_bonds = True  # (once per calculator: each evaluation reads none)
            warnings.warn(
                f"{self.label}: bond_coeffs gives bond types "
                f"{sorted(self._bond_values)} but the atoms carry no bonds (no "
                f'"{PARTNER}" and "{TYPE}" arrays, as after reading a file that drops '
                "them, e.g. an ASE .traj or .json, or a ViewerTrajectory frame, or after "
                "create_bonds with a cutoff below the "
                "spacing): no bond acts.  ase_bpm.read_restart keeps them, "
                "ase_bpm.create_bonds makes them; a scene meant without bonds needs no "
                "bond_coeffs", NoBondsWarning, stacklevel=outside_stacklevel())
        live = table.type_b > 0
        known = np.zeros(live.shape, dtype=bool)
        inside = table.type_b < len(self._law_of_type)
        known[inside] = self._law_of_type[table.type_b[inside]] != ""
        unknown = live & ~known
        if unknown.any():
            b = int(np.argmax(unknown))
            raise ValueError(f"unknown bond type {table.type_b[b]} (bond {table.owner_b[b]}-"
                             f"{table.partner_b[b]}): bond_coeffs has no entry for it")

    def forget(self) -> None:
        self._bond_state = BondState(self._check_bond_types, self._states)
        #: Model.state_replaced: the bond state's own answer (the calculator
        #: asks at every look at the atoms: one call)
        self.state_replaced = self._bond_state.replaced

    def state_arrays(self) -> Optional[dict]:
        state = self._bond_state  # (its arrays read or written last: what replaced compares)
        return None if state.current is None or state._arrays is None else dict(state._arrays)

    # -- the bonds on the atoms ---------------------------------------------------------
    #: per-atom input arrays the forces depend on, besides the bonds (watched
    #: arrays all: an ordinary step, which finds them unchanged, takes their
    #: digests of the last signature, _array_parts)
    signature_arrays = ("type",)
    _array_parts = None
    #: what else a model's forces depend on, for its signature: a method
    #: ``(atoms) -> tuple`` where a model has more (PeriModel); None: nothing
    _signature_extras = None

    def signature_parts(self, atoms: Atoms, evaluation) -> tuple:
        bonds = (self._bond_state.current if evaluation is not None
                 else self._bond_state.bonds(atoms))
        parts = [bonds.fingerprint]
        if evaluation is not None and self.ctx.continues and self._array_parts is not None:
            parts += self._array_parts  # (the ordinary step: the arrays as last time)
        else:
            array_parts = self._array_parts = []
            for name in self.signature_arrays:
                array_parts.append(self._digests(name, atoms.arrays.get(name)))
            parts += array_parts
        if self._signature_extras is not None:
            parts.extend(self._signature_extras(atoms))
        return tuple(parts)

    def law_groups(self, bonds: BondSet) -> dict:
        """The intact bonds of each law: name -> indices (None: all of them);
        worked out once per bond set."""
        groups = bonds.cache.get("law_groups")
        if groups is None:
            if len(bonds) and len(self._law_names) == 1:  # the model's one law: all bonds
                groups = {self._law_names[0]: None}
            else:
                code_b = self._law_code[bonds.type_b]
                present = np.flatnonzero(np.bincount(code_b, minlength=len(self._law_names)))
                names = [self._law_names[c] for c in present]
                groups = ({names[0]: None} if len(names) == 1 else
                          {name: np.flatnonzero(code_b == c) for name, c in zip(names, present)})
            bonds.cache["law_groups"] = groups
        return groups

    def coefficients(self, bonds: BondSet, name: str, select=None) -> np.ndarray:
        """Coefficient ``name`` of the intact bonds (or those in ``select``).
        On the NumPy route the laws read these columns at every step: they
        are kept with the set (and carried through breaking); the compiled
        kernels read coefficients by type, so there a column is built only
        when asked for (NaN where no bond law has the coefficient)."""
        table = self._coeff_table.get(name)
        if table is None:  # (no bond_coeffs at all: no bonds either)
            table = np.full(len(self._law_of_type), np.nan)
        if self.runs_compiled(bonds):
            return table[bonds.type_b if select is None else bonds.type_b[select]]
        column = bonds.per_bond("coeff:" + name, lambda: table[bonds.type_b])
        return column if select is None else column[select]

    def bond_geometry(self, atoms: Atoms, bonds: BondSet) -> tuple:
        """``(r_bc, r_b, r0_b, fresh_b)``: minimum-image bond vectors, lengths and
        reference lengths (those not yet taken are the lengths now, and marked
        in ``fresh_b``; None when every bond has its reference length)."""
        # (bpm/rotational takes its shear angle as the arccos of a cosine that is 1
        # at rest: a last-bit difference of a length or a reference length is
        # 1e-8 of a force there, so its lengths are summed as LAMMPS sums them)
        r_bc, r_b = bonds.geometry(atoms.positions, atoms.cell, atoms.pbc, in_order=self.turns)
        r0_b = bonds.of_bonds("r0")
        fresh_b = bonds.unset("r0")
        if fresh_b is not None:
            r0_b = np.where(fresh_b, r_b, r0_b)
        if atoms.pbc.any() and len(bonds):
            self._check_reach(atoms, bonds, r0_b)
        return r_bc, r_b, r0_b, fresh_b

    def _check_reach(self, atoms: Atoms, bonds: BondSet, r0_b) -> None:
        """A bond must break before it could reach half the cell: beyond, the
        minimum image would silently flip it to another periodic image.
        (Checked once per bond set and cell when every reference length is
        known.)"""
        cell = np.asarray(atoms.cell)
        checked = cell.tobytes() + atoms.pbc.tobytes()
        if bonds.cache.get("keep:reach checked") == checked:
            return
        half_width = periodic_half_widths(cell, atoms.pbc)
        for name, select in self.law_groups(bonds).items():
            strain = self._laws[name].breaking_strain
            if strain is None:
                continue
            sel = slice(None) if select is None else select
            reach_b = r0_b[sel] * (1.0 + self.coefficients(bonds, strain, select))
            if bonds.dead:  # broken bonds still listed reach nothing (their strain: NaN)
                reach_b = np.where(bonds.type_b[sel] > 0, reach_b, 0.0)
            if reach_b.max() >= half_width:
                b = np.arange(len(bonds))[sel][int(np.argmax(reach_b))]
                raise ValueError(
                    f"periodic cell too small for bond {bonds.i_b[b]}-{bonds.j_b[b]}: with "
                    f"r0 = {r0_b[b]:.6g} and {strain} = "
                    f"{self.coefficients(bonds, strain)[b]} it may stretch to "
                    f"{reach_b.max():.6g}, beyond half the cell width ({half_width:.6g})")
        if bonds.unset("r0") is None:
            bonds.cache["keep:reach checked"] = checked  # holds for fewer bonds too

    # -- forces -------------------------------------------------------------------------
    def plan(self, bonds: BondSet) -> BondPlan:
        """What runs on these bonds (:class:`BondPlan`), worked out once per
        set: the step path looks it up as ``bonds.cache.get(PLAN) or
        self.plan(bonds)``."""
        plan = bonds.cache.get(PLAN)
        if plan is not None:
            return plan
        groups, damped, routes = self.law_groups(bonds), self.damped_laws(bonds), \
            self.kernel_routes
        compiled_route = self.kernel_route == COMPILED and all(
            routes[name] == COMPILED for name in (groups or self._laws))
        twins = [LawGroup(self._laws[name], select, damped[name],
                          {c: self._coeff_table[c] for c in self._laws[name].coefficients})
                 for name, select in groups.items() if routes[name] == COMPILED]
        no_breaks = np.zeros(len(bonds.i_b), dtype=bool)
        no_breaks.flags.writeable = False
        plan = bonds.cache[PLAN] = BondPlan(
            groups=groups, compiled=compiled_route,
            lazy=compiled_route and all(self._laws[name].skips_broken for name in groups),
            damped=any(damped.values()), twins=twins,
            twins_damped=any(group.damped for group in twins),
            twins_turn=any(group.law.turns for group in twins),
            twins_turn_damped=any(group.law.turns and group.damped for group in twins),
            options={name: self.parameters[name] for name in self.law_options},
            no_breaks=no_breaks)
        return plan

    def runs_compiled(self, bonds: BondSet) -> bool:
        """Do all these bonds run on the compiled route (each law of theirs
        runs its compiled twin, :attr:`kernel_routes`; without bonds: each
        law of the model)?"""
        return self.plan(bonds).compiled

    def breaks_lazily(self, bonds: BondSet) -> bool:
        """Can broken bonds stay listed (type 0) in these bonds' set?  When it
        runs compiled and every law's kernel passes over them
        (``BondLaw.skips_broken``)."""
        return self.plan(bonds).lazy

    def bond_forces(self, atoms: Atoms, bonds: BondSet, geometry: Optional[tuple] = None,
                    v_nc=None, extra: Optional[dict] = None, scene=None,
                    groups: Optional[dict] = None) -> BondPart:
        """Every law on its bonds, then breaking and the per-atom sums.
        ``geometry``: as from :meth:`bond_geometry`; None leaves it to this
        method, which runs the compiled twins of the laws where it can (each
        law on its own route: :attr:`kernel_routes`).  ``groups``: the law
        groups to run (:meth:`law_groups`; None: all of them)."""
        plan = bonds.cache.get(PLAN) or self.plan(bonds)
        if geometry is None:
            if plan.compiled:
                return self._compiled_bond_forces(atoms, bonds, v_nc, scene)
            geometry = self.bond_geometry(atoms, bonds)
            if plan.twins:  # some laws compiled, the others NumPy
                twins = [group.law.name for group in plan.twins]
                others = {name: select for name, select in plan.groups.items()
                          if name not in twins}
                return _joined(self._compiled_bond_forces(atoms, bonds, v_nc, scene),
                               self.bond_forces(atoms, bonds, geometry, v_nc, extra, scene,
                                                others))
        r_bc, r_b, r0_b, fresh_b = geometry
        nb = len(bonds)
        f_b = energy_b = breaks_b = fd_b = None  # filled by the laws (see _place)
        fj_parts, turning = [], []  # (select, BondForces) of laws that turn
        energy, history, node = 0.0, {}, {}
        options = plan.options
        timestep = self.ctx.timestep
        testing = self.tests_breaking and nb > 0  # else no law tests its criterion
        v_bc = None
        for name, select in (plan.groups if groups is None else groups).items():
            law = self._laws[name]
            damped = self.damped_laws(bonds)[name]
            if damped and v_bc is None:
                v_bc = bonds.vectors(v_nc)
            out = law.forces(self._law_input(law, bonds, select, geometry,
                                             v_bc if damped else None, self.ctx.advancing,
                                             timestep, options, extra, scene, testing,
                                             spins=True))
            if out.f_bc is not None:  # vectors and torques: summed as such below
                turning.append((select, out))
                out.f_b, out.fd_b = np.zeros_like(out.f_b), None
            f_b = _place(f_b, out.f_b, select, nb)
            energy_b = _place(energy_b, out.energy_b, select, nb)
            if testing and out.breaks_b is not None:  # (None: this law never breaks)
                breaks_b = _place(breaks_b, out.breaks_b, select, nb)
            if out.fd_b is not None:
                fd_b = _place(fd_b, out.fd_b, select, nb)
            if out.fj_b is not None:
                fj_parts.append((select, out.fj_b))
            energy += out.energy
            history.update({s: (select, v) for s, v in out.history.items()})
            node.update(out.node)
        fj_b = None  # on j where a law says (peri ves, eps), else the force on i
        for select, values in fj_parts:
            fj_b = _place(f_b.copy() if fj_b is None else fj_b, values, select, nb)
        if f_b is None:  # no bonds
            f_b, energy_b = np.zeros(nb), np.zeros(nb)

        # bonds break in steps; in pure evaluations they act broken and stay
        breaking = bool(testing and breaks_b is not None and breaks_b.any())
        broken_b = breaks_b if breaking else plan.no_breaks
        released = 0.0
        if breaking:
            energy, released = self._split_energy(atoms, bonds, broken_b, geometry, energy_b,
                                                  energy, extra, scene)
            if self.ctx.pure or not self._acts_while_breaking(bonds, broken_b):
                f_b = np.where(broken_b, 0.0, f_b)
                if fd_b is not None:
                    fd_b = np.where(broken_b, 0.0, fd_b)
                if fj_b is not None:
                    fj_b = np.where(broken_b, 0.0, fj_b)
        else:
            energy += float(energy_b.sum())

        f_nc, fd_nc, f_mean_bc = bonds.sum_forces(r_bc, r_b, f_b, fj_b, fd_b)
        part = BondPart(bonds=bonds, r_bc=r_bc, r0_b=r0_b, fresh_b=fresh_b, broken_b=broken_b,
                        f_nc=f_nc, fd_nc=fd_nc, energy=energy, released=released,
                        virial_pairs=(r_bc, f_mean_bc), history=history, node=node,
                        magnitudes=(f_b, fj_b) if self._analysing else None)
        if turning:
            self._add_turning(part, turning, breaking and (
                self.ctx.pure or not self._acts_while_breaking(bonds, broken_b)))
        return part

    def _add_turning(self, part: BondPart, turning: list, drop_broken: bool) -> None:
        """Add the force vectors and torques of the laws that turn (``turning``:
        ``(select, BondForces)`` of each) to ``part``: forces, damping forces,
        the virial's forces, torques and their damping part (bonds that break
        now left out where ``drop_broken``)."""
        bonds, nb = part.bonds, len(part.bonds)
        keep_b = ~part.broken_b if drop_broken else None

        def full(values, select):
            out = np.zeros((nb, 3))
            out[slice(None) if select is None else select] = values
            return out if keep_b is None else out * keep_b[:, None]

        f_bc, fd_bc, ti_bc, tj_bc = (np.zeros((nb, 3)) for _ in range(4))
        tdi_bc = tdj_bc = None
        for select, out in turning:
            f_bc += full(out.f_bc, select)
            ti_bc += full(out.ti_bc, select)
            tj_bc += full(out.tj_bc, select)
            if out.fd_bc is not None:
                fd_bc += full(out.fd_bc, select)
                tdi_bc = (0.0 if tdi_bc is None else tdi_bc) + full(out.tdi_bc, select)
                tdj_bc = (0.0 if tdj_bc is None else tdj_bc) + full(out.tdj_bc, select)
        part.f_nc = part.f_nc + bonds.forces(f_bc)
        if tdi_bc is not None:
            fd_nc = bonds.forces(fd_bc)
            part.fd_nc = fd_nc if part.fd_nc is None else part.fd_nc + fd_nc
            part.td_nc = bonds.forces(tdi_bc, tdj_bc)
        part.t_nc = bonds.forces(ti_bc, tj_bc)
        if self._analysing:
            part.per_bond = {"torque_i_bc": ti_bc, "torque_j_bc": tj_bc}
        r_bc, f_mean_bc = part.virial_pairs
        part.virial_pairs = (r_bc, f_mean_bc + f_bc)

    def _compiled_bond_forces(self, atoms: Atoms, bonds: BondSet, v_nc, scene=None) -> BondPart:
        """:meth:`bond_forces` on the compiled route: each law that runs its
        compiled twin (all of them, or beside NumPy ones: ``BondPlan.twins``)
        gathers its bonds' vectors, computes and adds the forces to the atoms
        in one pass, through the kernel the plan made ready for these bonds
        (no per-bond arrays but the broken-bond mask and the laws' history);
        ``scene`` goes to :meth:`_compiled_nodes`."""
        plan = bonds.cache.get(PLAN) or self.plan(bonds)
        nb, ctx = len(bonds.i_b), self.ctx
        testing = nb > 0 and self.tests_breaking
        r0_b, fresh_b = bonds.state_of("r0")
        if fresh_b is not None or not r0_b.flags.c_contiguous:
            r0_b = np.array(r0_b)  # the kernels write the lengths they take (NaN rows)
        sums = BondSums.zeros(len(atoms), nb, plan.twins_damped, testing)
        if plan.twins_turn:
            sums.with_torques(plan.twins_turn_damped)
        x_nc, pbc = atoms.positions, atoms.pbc
        box = compiled.box(atoms.cell, pbc)
        nodes = (scene if self._compiled_nodes is None
                 else self._compiled_nodes(atoms, bonds, r0_b, box, scene))
        scenes = []  # each law's, kept for the virial
        for group in plan.twins:
            law = group.law
            bond_scene = BondScene(
                i_b=bonds.i_b, j_b=bonds.j_b, type_b=bonds.type_b, x_nc=x_nc, box=box,
                r0_b=r0_b, coeff_t=group.coeff_t, sums=sums,
                v_nc=v_nc if group.damped else None, select=group.select,
                options=plan.options, breaking=testing, virial=False,
                history={s: bonds.of_bonds(s) for s in law.states} if law.states else {},
                advance=ctx.advancing, timestep=ctx.timestep, nodes=nodes,
                spins=self._spins() if law.turns else {})
            if group.kernel is None:
                group.kernel = law.prepare(bond_scene)
            group.kernel(bond_scene)
            scenes.append((law, bond_scene))
        periodic = pbc.any()
        if periodic and nb:
            self._check_reach(atoms, bonds, r0_b)
        totals_t = sums.totals_t
        part = BondPart(bonds=bonds, r_bc=None, r0_b=r0_b, fresh_b=fresh_b,
                        broken_b=sums.broken_b.view(bool) if sums.nbroken else plan.no_breaks,
                        f_nc=sums.f_nc, fd_nc=sums.fd_nc,
                        energy=float(totals_t[TOTAL_ENERGY]),
                        released=float(totals_t[TOTAL_RELEASED]), virial_pairs=None,
                        history=sums.history, node=sums.node, nodes=nodes,
                        t_nc=sums.t_nc, td_nc=sums.td_nc)
        if periodic:  # the virial only if asked for (stress), as on the NumPy route
            part.virial_replay = _replay_for_virial(scenes, x_nc.copy(), r0_b)
        else:
            part.virial_cc = NO_VIRIAL
        if sums.nbroken:
            self._compiled_split(atoms, part, nodes)
        return part

    @property
    def tests_breaking(self) -> bool:
        """Is the breaking criterion tested in this evaluation?  In steps and
        pure evaluations with ``break_bonds`` on; never in a setup or a
        re-evaluation (nothing breaks there), nor with ``break_bonds=False``
        (as LAMMPS ``break no``: a bond past its criterion keeps acting)."""
        return bool((self.ctx.advancing or self.ctx.pure) and self.parameters["break_bonds"]
                    and not self._analysing)

    def _law_input(self, law, bonds: BondSet, select, geometry: tuple, v_bc, advance: bool,
                   timestep, options: dict, extra: Optional[dict], scene,
                   breaking: bool = False, spins: bool = False) -> BondInput:
        """What ``law`` sees of the bonds ``select`` (None: all of them);
        ``breaking``: whether it tests its breaking criterion; ``spins``:
        whether it gets the orientations and angular velocities (a law
        that turns, computing forces)."""
        r_bc, r_b, r0_b, _ = geometry
        of = (lambda a: a) if select is None else (lambda a: a[select])  # noqa: E731
        return BondInput(
            i_b=of(bonds.i_b), j_b=of(bonds.j_b), r_bc=of(r_bc), r_b=of(r_b), r0_b=of(r0_b),
            coeff={c: self.coefficients(bonds, c, select) for c in law.coefficients},
            history={s: of(bonds.of_bonds(s)) for s in law.states},
            v_bc=None if v_bc is None else of(v_bc), advance=advance, timestep=timestep,
            options=options, extra={k: of(v) for k, v in (extra or {}).items()}, scene=scene,
            breaking=breaking, spins=self._spins() if spins and law.turns else {})

    def _spins(self) -> dict:
        """The orientations and angular velocities of the evaluation's atoms,
        for laws that turn (``BondInput.spins``)."""
        inputs = self.ctx.inputs
        return {QUAT: inputs.orientations, OMEGA: inputs.omega}

    def bond_springs(self, bonds: BondSet, geometry: tuple, extra: Optional[dict] = None,
                     scene=None) -> Optional[Springs]:
        """The intact bonds as springs and dampers (each law's ``stiffness``),
        for :meth:`stable_timestep` (None without bonds); ``geometry`` as from
        :meth:`bond_geometry`, ``extra`` and ``scene`` as for :meth:`bond_forces`."""
        r_bc, r_b = geometry[:2]
        nb = len(bonds)
        if nb == 0:
            return None
        options = {name: self.parameters[name] for name in self.law_options}
        names = ("k_x", "c_x", "kt_x", "ct_x", "kb_x", "ktw_x", "cb_x", "ctw_x")
        parts = dict.fromkeys(names)
        midpoint_b = None  # bonds whose across spring acts at the midpoint
        for name, select in self.law_groups(bonds).items():
            law = self._laws[name]
            out = law.stiffness(self._law_input(law, bonds, select, geometry, None, False, None,
                                                options, extra, scene))
            size = nb if select is None else len(select)
            for key in names:
                values = np.broadcast_to(np.asarray(getattr(out, key), dtype=float), (size,))
                parts[key] = _place(parts[key], values, select, nb)
            if out.midpoint:
                midpoint_b = _place(midpoint_b, np.ones(size, dtype=bool), select, nb)
        rinv_b = np.divide(1.0, r_b, out=np.zeros_like(r_b), where=r_b > 0)
        arms = {}
        if midpoint_b is not None:  # lever arms of half the bond, from each centre
            half_bc = 0.5 * r_bc * midpoint_b[:, None]
            arms = dict(arm_i_xc=half_bc, arm_j_xc=-half_bc)
        return Springs(bonds.i_b, bonds.j_b, r_bc * rinv_b[:, None], **parts, **arms)

    def damped_laws(self, bonds: BondSet) -> dict:
        """For each law of these bonds, does it need velocities (damping)?
        Worked out once per bond set."""
        damped = bonds.cache.get("damped")
        if damped is None:  # asked of the bond types present (as of every bond, but cheaper)
            present_t = np.bincount(bonds.type_b, minlength=len(self._law_of_type)) > 0
            damped = bonds.cache["damped"] = {}
            for name in self.law_groups(bonds):
                types = np.flatnonzero(present_t & (self._law_of_type == name))
                damped[name] = self._laws[name].uses_velocities(
                    {c: self._coeff_table[c][types] for c in self._laws[name].coefficients})
        return damped

    def uses_velocities(self, bonds: BondSet) -> bool:
        """Do the laws of these bonds need velocities (damping)?"""
        return self.plan(bonds).damped

    # hooks a model may refine
    def _acts_while_breaking(self, bonds, broken_b) -> bool:
        return all(self._laws[name].acts_while_breaking for name in self.law_groups(bonds))

    def _split_energy(self, atoms, bonds, broken_b, geometry, energy_b, energy, extra,
                      scene) -> tuple:
        """``(kept, released)``: the bonds' elastic energy once the broken ones
        are gone, and what left with them (``geometry``: as from
        :meth:`bond_geometry`; ``energy``: the laws' energy that belongs to no
        single bond)."""
        released = float(energy_b[broken_b].sum())
        released -= self._handed_over(atoms, bonds, broken_b, geometry[0][broken_b])
        return energy + float(energy_b[~broken_b].sum()), released

    #: on the compiled route, before the laws, a model's pass over all the
    #: bonds (PeriModel: the node state): a method ``(atoms, bonds, r0_b, box,
    #: scene) -> nodes``, what the laws then get as ``BondScene.nodes``
    #: (``scene`` as given to :meth:`bond_forces`; ``r0_b`` holds NaN where a
    #: reference length is taken now, and may be written).  None: no such
    #: pass, the laws get ``scene`` as it is
    _compiled_nodes = None

    def _compiled_split(self, atoms, part: BondPart, nodes) -> None:
        """On the compiled route, when bonds broke: the kernels summed the
        energy of the bonds that stay into ``part.energy`` and that of those
        that break into ``part.released``; correct the two as
        :meth:`_split_energy` would.  Here: what the broken bonds hand over
        (:meth:`_handed_over`) is not released."""
        part.released -= self._handed_over(atoms, part.bonds, part.broken_b,
                                           part.broken_vectors(atoms))

    def _handed_over(self, atoms, bonds, broken_b, r_kc) -> float:
        """Energy that the bonds breaking now (vectors ``r_kc``) hand over to
        another part of the model rather than release (0 here)."""
        return 0.0

    # -- commit ---------------------------------------------------------------------------
    def commit(self, atoms: Atoms, ev: BondedEvaluation, ctx) -> None:
        """Write reference lengths, history and broken bonds (of the bond part
        ``ev.bonds``, at step ``ctx.step``) on the atoms."""
        part, step = ev.bonds, ctx.step
        state, bonds = self._bond_state, part.bonds
        log = self.parameters["store_local"]
        if log and (X_REF not in atoms.arrays
                    or atoms.arrays[X_REF].shape != (len(atoms), 3)):
            atoms.arrays[X_REF] = atoms.positions.copy()
        counts_stale = (state.reread or NBONDS not in atoms.arrays
                        or len(atoms.arrays[NBONDS]) != len(atoms)
                        or DAMAGE not in atoms.arrays)
        if part.fresh_b is not None:
            bonds.set_bonds("r0", part.r0_b, part.fresh_b)
        for name, (select, values) in part.history.items():
            if select is None:
                bonds.set_bonds(name, values)
            else:
                full = np.nan_to_num(bonds.of_bonds(name))
                full[select] = values
                bonds.set_bonds(name, full)
        broken_ends = None
        if part.broken_b.any():
            broken_ends = (bonds.i_b[part.broken_b], bonds.j_b[part.broken_b])
            bonds = state.break_bonds(atoms, bonds, part.broken_b, step,
                                      part.broken_vectors(atoms), log,
                                      lazy=self.breaks_lazily(bonds))
        if bonds.dirty or state.takes_over or bonds is not state.current:
            state.write(atoms, bonds)  # (else the atoms hold these bonds already)
        if counts_stale or broken_ends is not None:
            self.write_counts(atoms, bonds, None if counts_stale else broken_ends)
        # (the same set, written in place; its signature's array parts as last time, no extras)
        ev.kept_state = ctx.continues and bonds is part.bonds and self._signature_extras is None

    def write_counts(self, atoms: Atoms, bonds: BondSet, broken_ends=None) -> None:
        """Per-atom outputs ``nbonds`` and ``damage`` (LAMMPS ``nbond/atom``);
        ``broken_ends`` as for :func:`write_bond_counts`."""
        write_bond_counts(atoms, bonds, broken_ends)


class BondedCalculator(BPMCalculator):
    """What the calculators of the bonded models share (:class:`ase_bpm.BPMSpring`,
    :class:`ase_bpm.BPMPeri`): their parameters as JSON takes them, and the
    public methods of :class:`BondedModel`."""

    def todict(self, skip_default=True) -> dict:
        """Parameters for ASE's trajectory files (JSON: keys become strings,
        which the constructor accepts back)."""
        params = dict(super().todict(skip_default=skip_default))
        for name in ("bond_coeffs", "pair_coeffs"):
            if name in params:
                params[name] = json_coeffs(params[name])
        return params

    def law_groups(self, bonds: BondSet) -> dict:
        """The intact bonds of each law (:meth:`BondedModel.law_groups`)."""
        return self.model.law_groups(bonds)

    def runs_compiled(self, bonds: BondSet) -> bool:
        """Do these bonds run on the compiled route (:meth:`BondedModel.runs_compiled`)?"""
        return self.model.runs_compiled(bonds)

    def analyse(self, atoms: Atoms):
        """LAMMPS' ``compute bond/local``, ``pair/local`` and ``stress/atom`` of
        the atoms now, changing nothing (:mod:`ase_bpm.models.analysis`; the
        model's ``analyse`` says what each model computes)."""
        return self.model.analyse(atoms)
