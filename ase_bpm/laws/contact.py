"""The contact-law protocol, and coefficients by pair of particle types.

A contact law (:class:`PairLaw`) acts between particles closer than its
reach: ``pair_style bpm/spring`` (:class:`ase_bpm.laws.spring.SpringPair`),
``pair_style bpm/peri`` (:class:`ase_bpm.laws.peri.PeriContact`).  It supplies
its coefficient schema (``coefficients`` in LAMMPS ``pair_coeff`` order), its
reach and its radial force; :func:`contact_forces` does the rest for every
law: per-pair coefficients from the table, the touching pairs, the per-atom
sums.  (The granular laws keep shear history and torques per contact and run
through their own kernels, :mod:`ase_bpm.laws.granular`.)

:class:`PairTable` turns ``{(type_i, type_j): coefficients}`` into lookup
tables ``[coefficient][type_i, type_j]`` for the particle types present, mixing
unlisted pairs from the two like-type entries where the law has a mixing rule
(LAMMPS ``pair_modify mix``), or naming the missing pair where it has none.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, ClassVar, Mapping, Optional

import numpy as np

from ..core.arrays import same_array
from .timestep import LawStiffness, Springs

#: a mixing rule: like-type coefficients of the two types -> those of the pair
MixingRule = Callable[[tuple, tuple], tuple]


def geometric(a: float, b: float) -> float:
    return float(np.sqrt(a * b))


def arithmetic(a: float, b: float) -> float:
    return 0.5 * (a + b)


class PairTable:
    """Per-type-pair coefficient tables, built once per set of types present.

    ``coeffs`` maps sorted type pairs to coefficient tuples (checked by the
    caller), ``names`` names the coefficients, ``mix`` is the mixing rule or
    None (every pair present needs an entry).
    """

    def __init__(self, coeffs: Mapping[tuple, tuple], names: tuple,
                 mix: Optional[MixingRule] = None):
        self.coeffs, self.names, self.mix = dict(coeffs), tuple(names), mix
        self._built = {}  # types present -> tables
        #: (a copy of the types, tables, the types array given) of the last
        #: call: a read-only array given again holds those types (Inputs)
        self._last = None
        self._rows = None  # (tables, their rows) of the last call of rows

    def __call__(self, types_n: np.ndarray) -> np.ndarray:
        """``[coefficient, type_i, type_j]`` for the types of ``types_n``."""
        last = self._last
        if last is not None and same_array(last[0], types_n):
            return last[1]
        present = tuple(int(t) for t in np.unique(types_n))
        if present not in self._built:
            size = max(present, default=0) + 1
            tables = np.full((len(self.names), size, size), np.nan)
            for a in present:
                for b in present:
                    tables[:, a, b] = self.of_pair(min(a, b), max(a, b))
            self._built[present] = tables
        self._last = (types_n.copy(), self._built[present], types_n)
        return self._last[1]

    def rows(self, types_n: np.ndarray) -> np.ndarray:
        """The same coefficients as ``[type_i, type_j, coefficient]``,
        C-contiguous: one row per type pair, as the compiled kernels read
        them (kept while the tables are the same)."""
        last, kept = self._last, self._rows
        if kept is not None and last is not None and kept[0] is last[1]:
            if last[2] is types_n and not types_n.flags.writeable:  # given again
                return kept[1]
            if same_array(last[0], types_n):  # the types of the last call, another array
                self._last = (last[0], last[1], types_n)  # (given again next time)
                return kept[1]
        tables = self(types_n)
        if self._rows is None or self._rows[0] is not tables:
            self._rows = (tables, np.ascontiguousarray(np.moveaxis(tables, 0, -1)))
        return self._rows[1]

    def of_pair(self, lo: int, hi: int) -> tuple:
        """The coefficients of types ``lo <= hi``: listed, or mixed."""
        if (lo, hi) in self.coeffs:
            return self.coeffs[lo, hi]
        if self.mix is None:
            raise ValueError(f"unknown particle type pair {(lo, hi)}: pair_coeffs needs an "
                             "entry for every pair of types present (no mixing)")
        if (lo, lo) in self.coeffs and (hi, hi) in self.coeffs:
            return self.mix(self.coeffs[lo, lo], self.coeffs[hi, hi])
        missing = lo if (lo, lo) not in self.coeffs else hi
        raise ValueError(f"unknown particle type {missing}: pair_coeffs has no entry for "
                         f"types ({lo}, {hi}) and none for ({missing}, {missing}) to mix from")


@dataclass(frozen=True)
class PairInput:
    """What a contact law sees of the touching pairs (one row per pair ``p``)."""

    r_pc: np.ndarray  # x[j] - x[i]
    r_p: np.ndarray  # lengths
    coeff: Mapping[str, np.ndarray]  # the law's coefficients, one value per pair
    reach_p: np.ndarray  # contact distance of each pair
    v_pc: Optional[np.ndarray] = None  # v[j] - v[i], when the law uses velocities
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)  # model's per-pair data


@dataclass
class PairForces:
    f_p: np.ndarray  # force on i along r_hat (negative: pushes i away from j)
    energy_p: np.ndarray  # elastic energy
    fd_p: Optional[np.ndarray] = None  # the damping part of f_p (None: undamped)


class PairLaw:
    """One contact law.  Subclasses set the schema and implement the rest."""

    name: ClassVar[str] = ""  # the LAMMPS pair style that runs it
    coefficients: ClassVar[tuple] = ()  # LAMMPS pair_coeff order, after the types
    positive: ClassVar[tuple] = ()
    non_negative: ClassVar[tuple] = ()
    #: the law has a compiled kernel, which the model runs on the compiled route
    compiled: ClassVar[bool] = False

    @staticmethod
    def reach(coeff: Mapping[str, np.ndarray], extra: Mapping[str, np.ndarray]):
        """Contact distance of each pair: closer pairs interact."""
        raise NotImplementedError

    @staticmethod
    def uses_velocities(coeff: Mapping[str, np.ndarray]) -> bool:
        return False

    def forces(self, pairs: PairInput) -> PairForces:
        raise NotImplementedError

    def stiffness(self, pairs: PairInput) -> LawStiffness:
        """The touching pairs as springs and dampers (see
        :meth:`ase_bpm.laws.bond.BondLaw.stiffness`)."""
        raise NotImplementedError(f"contact law {self.name!r} gives no stiffness: "
                                  "stable_timestep cannot bound its timestep")


#: registered contact laws by their LAMMPS pair style: the pair laws (a
#: :class:`PairLaw` each) and the granular models (:mod:`ase_bpm.laws.granular`,
#: ``gran/<model>``); tests/test_every_law.py runs each
CONTACT_LAWS: dict = {}


def register_contact(law, style: Optional[str] = None):
    """Make the contact law ``law`` known as ``style``, its LAMMPS pair style
    (default: the law's ``name``; usable as a class decorator); a style taken
    by another law is refused, naming both."""
    style = law.name if style is None else style
    taken = CONTACT_LAWS.get(style, law)
    if taken is not law:
        raise ValueError(f"register_contact: the contact law name {style!r} is taken by "
                         f"{taken!r}; give {law!r} a name of its own")
    CONTACT_LAWS[style] = law
    return law


@dataclass
class ContactSums:
    """What :func:`contact_forces` returns."""

    f_nc: np.ndarray  # per-atom force of the contacts
    fd_nc: Optional[np.ndarray]  # its damping part
    energy: float
    r_pc: np.ndarray  # the touching pairs' vectors and forces on i, for the virial
    f_pc: np.ndarray
    i_p: np.ndarray  # the touching pairs (i, j)
    j_p: np.ndarray


def contact_forces(law: PairLaw, i_p, j_p, r_pc, types_n, tables, natoms: int,
                   v_nc=None, extra=None) -> ContactSums:
    """``law`` on the candidate pairs ``(i_p, j_p)`` with vectors ``r_pc``:
    coefficients ``tables[k][type_i, type_j]`` (a :class:`PairTable`'s, in the
    order of ``law.coefficients``), the pairs within reach, their forces and
    per-atom sums.  ``v_nc`` is needed when the law uses velocities;
    ``extra`` holds per-pair arrays of the model (for all candidate pairs)."""
    i_p, j_p, r_pc, reach_p, coeff, extra = _touching(law, i_p, j_p, r_pc, types_n, tables,
                                                      extra)
    damped = law.uses_velocities(coeff)
    v_pc = None
    if damped and len(i_p):
        v_pc = np.take(v_nc, j_p, axis=0) - np.take(v_nc, i_p, axis=0)
    r_p = np.sqrt(np.einsum("pc,pc->p", r_pc, r_pc))
    out = law.forces(PairInput(r_pc, r_p, coeff, reach_p, v_pc, extra))
    rinv_p = np.divide(1.0, r_p, out=np.zeros_like(r_p), where=r_p > 0)
    f_pc = r_pc * (out.f_p * rinv_p)[:, None]
    fd_nc = None
    if out.fd_p is not None:
        fd_nc = _sum_pairs(i_p, j_p, r_pc * (out.fd_p * rinv_p)[:, None], natoms)
    return ContactSums(_sum_pairs(i_p, j_p, f_pc, natoms), fd_nc,
                       float(out.energy_p.sum()), r_pc, f_pc, i_p, j_p)


def _touching(law: PairLaw, i_p, j_p, r_pc, types_n, tables, extra) -> tuple:
    """The candidate pairs within reach: ``(i_p, j_p, r_pc, reach_p, coeff, extra)``."""
    ti_p, tj_p = np.take(types_n, i_p), np.take(types_n, j_p)
    coeff = {name: tables[k][ti_p, tj_p] for k, name in enumerate(law.coefficients)}
    extra = extra or {}
    reach_p = law.reach(coeff, extra)
    touch = np.einsum("pc,pc->p", r_pc, r_pc) < reach_p * reach_p
    if not touch.all():
        i_p, j_p, r_pc, reach_p = i_p[touch], j_p[touch], r_pc[touch], reach_p[touch]
        coeff = {name: values[touch] for name, values in coeff.items()}
        extra = {name: values[touch] for name, values in extra.items()}
    return i_p, j_p, r_pc, reach_p, coeff, extra


def contact_springs(law: PairLaw, i_p, j_p, r_pc, types_n, tables, extra=None) -> Springs:
    """The touching pairs among the candidates of :func:`contact_forces` as
    springs and dampers (``law.stiffness``), for the timestep bound."""
    i_p, j_p, r_pc, reach_p, coeff, extra = _touching(law, i_p, j_p, r_pc, types_n, tables,
                                                      extra)
    r_p = np.sqrt(np.einsum("pc,pc->p", r_pc, r_pc))
    out = law.stiffness(PairInput(r_pc, r_p, coeff, reach_p, None, extra))
    rinv_p = np.divide(1.0, r_p, out=np.zeros_like(r_p), where=r_p > 0)
    return Springs(i_p, j_p, r_pc * rinv_p[:, None], out.k_x, out.kt_x, out.c_x)


def _sum_pairs(i_p, j_p, f_pc, natoms: int) -> np.ndarray:
    """Per-atom sums of pair forces: ``+f`` on ``i``, ``-f`` on ``j``."""
    index = np.concatenate([i_p, j_p])
    out = np.empty((natoms, 3))
    for c in range(3):
        out[:, c] = np.bincount(index, np.concatenate([f_pc[:, c], -f_pc[:, c]]),
                                minlength=natoms)
    return out
