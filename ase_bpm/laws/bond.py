"""The bond-law protocol: what one bond law supplies to the shared machinery.

LAMMPS splits ``BondBPM`` (reference state, breaking, the broken-bond record)
from the small subclasses that each compute one kind of bond.  Here the
machinery is :class:`ase_bpm.models.bonded.BondedModel`; a law is a
:class:`BondLaw` subclass that supplies

* its coefficient schema: ``coefficients``, the names in the order of its
  LAMMPS ``bond_coeff`` line (written here once, used for checking, for
  JSON and for export), with ``positive`` and ``non_negative`` among them;
* ``states``: per-bond history it keeps beside the reference length;
* :meth:`BondLaw.forces`: per-bond force, energy, the bonds that break now
  (only where the input asks, ``breaking``) and the updated history, from a
  :class:`BondInput`;
* optionally :meth:`BondLaw.stiffness`: its bonds as springs and dampers
  (:class:`ase_bpm.laws.timestep.LawStiffness`), for the calculators'
  ``stable_timestep``;
* optionally a compiled twin of :meth:`BondLaw.forces`,
  :meth:`BondLaw.add_sums` (``compiled = True``): it sees the whole scene
  (:class:`BondScene`: the atoms' positions, the bonds as atom indices,
  coefficients by type) and gathers the bond vectors, computes the law and
  adds the forces to the atoms in one pass, into a :class:`BondSums`.

Laws register by name (:func:`register`, one line), so that ``bond_coeffs``
entries such as ``("harmonic", k, eps_c)`` find them.  Everything else
(taking the reference length at the first evaluation, breaking in steps only,
pure evaluations, the broken-bond record, restart, per-atom outputs, the energy
ledger) is the machinery's.

Conventions: bond ``b`` joins ``i_b`` and ``j_b``, ``r_bc = x[j] - x[i]``; a
force magnitude ``f_b`` acts on ``i`` along ``r_bc / r_b`` (positive: pulls the
two atoms together) and its opposite on ``j``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Mapping, Optional

import numpy as np

from .timestep import LawStiffness


@dataclass(frozen=True)
class BondInput:
    """What a law sees of the bonds it governs (one row per bond ``b``)."""

    i_b: np.ndarray  # first atom
    j_b: np.ndarray  # second atom
    r_bc: np.ndarray  # bond vectors, minimum image
    r_b: np.ndarray  # lengths
    r0_b: np.ndarray  # reference lengths
    coeff: Mapping[str, np.ndarray]  # the law's coefficients, one value per bond
    history: Mapping[str, np.ndarray]  # the law's states as of the last step (NaN: unset)
    v_bc: Optional[np.ndarray] = None  # v[j] - v[i], when the law uses velocities
    advance: bool = True  # a step: history advances (else it is read only)
    timestep: Optional[float] = None  # the MD timestep, for laws with time in them
    options: Mapping[str, Any] = field(default_factory=dict)  # the model's switches
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)  # model's per-bond data
    scene: Any = None  # what the model computed for all its bonds (peri: node state)
    #: test the breaking criterion (a step or a pure evaluation with breaking
    #: on); False: nothing can break here, and a law need not test it
    breaking: bool = True
    #: per-atom (not per-bond) orientations and angular velocities, for laws
    #: that ``turn`` (``{"quat": q_nq, "omega": w_nc}``); empty for others
    spins: Mapping[str, np.ndarray] = field(default_factory=dict)


@dataclass
class BondForces:
    """What a law returns for its bonds."""

    f_b: np.ndarray  # force magnitude on i (pulling together), elastic + damping
    energy_b: np.ndarray  # elastic energy each bond holds (released when it breaks)
    #: bonds past their breaking criterion at this configuration (None: this
    #: law never breaks, or did not test because ``BondInput.breaking`` is False)
    breaks_b: Optional[np.ndarray]
    fd_b: Optional[np.ndarray] = None  # the damping part of f_b (None: undamped)
    fj_b: Optional[np.ndarray] = None  # on j, where the two ends differ (else -f_b)
    history: dict = field(default_factory=dict)  # name -> the updated per-bond state
    node: dict = field(default_factory=dict)  # per-atom outputs (name -> array)
    energy: float = 0.0  # elastic energy that belongs to no single bond
    #: laws that ``turn``: the force on i as a vector (its opposite on j),
    #: its damping part, and the torques on i and on j with their damping
    #: parts; ``f_b`` is then the force's part along the bond (for analyses)
    f_bc: Optional[np.ndarray] = None
    fd_bc: Optional[np.ndarray] = None
    ti_bc: Optional[np.ndarray] = None
    tj_bc: Optional[np.ndarray] = None
    tdi_bc: Optional[np.ndarray] = None
    tdj_bc: Optional[np.ndarray] = None


#: the places in the totals a bond or pair kernel adds to (BondSums.totals_t;
#: OUT_* in c/bonds.h): the energy that stays, the energy released, a 3x3
#: virial (row-major); and their length
TOTAL_ENERGY, TOTAL_RELEASED, TOTAL_VIRIAL = 0, 1, 2
TOTALS = TOTAL_VIRIAL + 9


def totals_virial(totals_t: np.ndarray) -> np.ndarray:
    """The 3x3 virial in the totals a kernel adds to."""
    return totals_t[TOTAL_VIRIAL:].reshape(3, 3)


@dataclass
class BondSums:
    """What compiled laws add up over their bonds (:meth:`BondLaw.add_sums`)."""

    f_nc: np.ndarray  # per-atom force, elastic + damping
    fd_nc: Optional[np.ndarray]  # its damping part (None: no law damps)
    #: 1 where a bond breaks now (int8, one per bond of the set; None: the
    #: breaking test is not asked for)
    broken_b: Optional[np.ndarray]
    #: energy of the bonds that stay, energy of those that break, and the
    #: virial (row-major 3x3, where asked for) in one array, as the kernels add
    totals_t: np.ndarray = field(default_factory=lambda: np.zeros(TOTALS))
    nbroken: int = 0
    #: updated per-bond history: name -> (the bonds' selection, their values),
    #: as ``BondForces.history`` of each law
    history: dict = field(default_factory=dict)
    node: dict = field(default_factory=dict)  # per-atom outputs (name -> array)
    #: per-atom torque of the laws that turn, and its damping part (None: no
    #: such law, or none of them damps)
    t_nc: Optional[np.ndarray] = None
    td_nc: Optional[np.ndarray] = None

    @classmethod
    def zeros(cls, natoms: int, nbonds: int, damped: bool, breaking: bool) -> "BondSums":
        """Empty sums, of the types the kernels write."""
        return cls(np.zeros((natoms, 3)), np.zeros((natoms, 3)) if damped else None,
                   np.zeros(nbonds, dtype=np.int8) if breaking else None, np.zeros(TOTALS))

    def with_torques(self, damped: bool) -> "BondSums":
        """These sums with empty torques (and their damping part, ``damped``),
        for laws that turn; returns them."""
        self.t_nc = np.zeros_like(self.f_nc)
        self.td_nc = np.zeros_like(self.f_nc) if damped else None
        return self

    @property
    def energy(self) -> float:
        return float(self.totals_t[TOTAL_ENERGY])

    @property
    def released(self) -> float:
        return float(self.totals_t[TOTAL_RELEASED])

    @property
    def virial_cc(self) -> np.ndarray:
        return totals_virial(self.totals_t)


@dataclass(frozen=True)
class BondScene:
    """What a compiled law sees: the atoms and the bonds it governs, by index."""

    i_b: np.ndarray  # first atom of every bond of the set
    j_b: np.ndarray  # second atom
    type_b: np.ndarray  # bond type (0: broken, still listed; see BondLaw.skips_broken)
    x_nc: np.ndarray  # positions
    box: np.ndarray  # the cell, packed for the kernels (ase_bpm.laws.compiled.box)
    #: reference lengths, writable; NaN ones are taken now (the kernel writes
    #: the length there)
    r0_b: np.ndarray
    coeff_t: Mapping[str, np.ndarray]  # the law's coefficients by bond type (NaN: not its)
    sums: BondSums  # where the law adds its part
    v_nc: Optional[np.ndarray] = None  # velocities, when the law damps
    select: Optional[np.ndarray] = None  # the bonds of this law (None: all)
    options: Mapping[str, Any] = field(default_factory=dict)  # the model's switches
    breaking: bool = True  # test the breaking criterion (write sums.broken_b)
    virial: bool = False  # add the virial to the sums
    #: the law's states for every bond of the set, as of the last step (NaN: unset)
    history: Mapping[str, np.ndarray] = field(default_factory=dict)
    advance: bool = True  # a step: history advances (else it is read only)
    timestep: Optional[float] = None  # the MD timestep, for laws with time in them
    #: what the model worked out over all its bonds before the laws (peri:
    #: node state, :meth:`ase_bpm.models.bonded.BondedModel._compiled_nodes`)
    nodes: Any = None
    #: per-atom orientations and angular velocities, for laws that ``turn``
    #: (as ``BondInput.spins``: ``{"quat": q_nq, "omega": w_nc}``); empty for others
    spins: Mapping[str, np.ndarray] = field(default_factory=dict)


class BondLaw:
    """One kind of bond.  Subclasses set the schema and implement :meth:`forces`."""

    name: ClassVar[str] = ""  # the word that selects it in bond_coeffs tuples
    #: models that can run it: "" needs nothing but the bonds (any bonded
    #: model), "peri" the node state of BPMPeri (volumes, dilatation)
    family: ClassVar[str] = ""
    coefficients: ClassVar[tuple] = ()  # LAMMPS bond_coeff order, after the type
    positive: ClassVar[tuple] = ()
    non_negative: ClassVar[tuple] = ()
    states: ClassVar[dict] = {}  # per-bond history: name -> trailing shape
    #: a bond that breaks still acts in the step it breaks (legacy PERI), or
    #: gives no force from that step on (bpm styles)
    acts_while_breaking: ClassVar[bool] = False
    needs_timestep: ClassVar[bool] = False  # history advances by the MD timestep
    #: the LAMMPS bond style that runs this law with ``coefficients`` as its
    #: ``bond_coeff`` line (None: none in LAMMPS; such bonds cannot be exported)
    lammps_style: ClassVar[Optional[str]] = None
    #: the coefficient that bounds a bond's strain before it breaks (bonds
    #: must not reach half a periodic cell); None: no bound known
    breaking_strain: ClassVar[Optional[str]] = None
    #: the law has a compiled twin (:meth:`add_sums`), which the model runs
    #: on the compiled route
    compiled: ClassVar[bool] = False
    #: the law gives forces across the bond and torques (``BondForces.f_bc``,
    #: ``ti_bc``, ``tj_bc``) from the particles' orientations and angular
    #: velocities (``BondInput.spins``), as ``bpm/rotational``
    turns: ClassVar[bool] = False
    #: ``energy_b`` is the energy of the elastic forces (False: the law's
    #: forces derive from no energy, and the ledger cannot balance)
    has_energy: ClassVar[bool] = True
    #: its compiled twin passes over bonds of type 0 (broken, still listed):
    #: a model whose laws all do keeps broken bonds listed until its set sheds
    #: them (:meth:`ase_bpm.models.bonded.BondSet.without`, ``lazy``)
    skips_broken: ClassVar[bool] = False

    @classmethod
    def check(cls, values: dict, where: str) -> None:
        """Checks beyond signs and finiteness (``values`` by name); raise
        ``ValueError`` starting with ``where``."""

    @staticmethod
    def uses_velocities(coeff: Mapping[str, np.ndarray]) -> bool:
        """Does the law need relative velocities (damping) for these bonds?"""
        return False

    def forces(self, bonds: BondInput) -> BondForces:
        raise NotImplementedError

    def add_sums(self, scene: BondScene) -> None:
        """The compiled twin of :meth:`forces` (laws with ``compiled``): add
        the forces of the bonds ``scene.select`` to ``scene.sums``, their
        energy to its totals (bonds that break now: to the released energy),
        and mark the bonds that break.  A bond that breaks gives no force in
        its step (bpm styles), or, with ``acts_while_breaking``, still does
        in a step (``scene.advance``) but not in a pure evaluation.  Updated
        history goes to ``scene.sums.history``, per-atom outputs to
        ``scene.sums.node``; a law that ``turns`` adds its torques to
        ``scene.sums.t_nc`` (damping part to ``td_nc``), reading
        ``scene.spins``."""
        raise NotImplementedError(f"bond law {self.name!r} has no compiled kernel")

    def prepare(self, scene: BondScene) -> Callable[[BondScene], None]:
        """:meth:`add_sums` made ready for the bonds of ``scene``: a callable
        that adds the sums of a scene of the same bonds (the same ``i_b``,
        ``j_b``, ``select``, ``coeff_t`` and ``options``; positions,
        velocities, reference lengths, history, types and sums may be
        others) as :meth:`add_sums` does.  The model prepares it at the first
        evaluation of a bond set and calls it at every one after, until bonds
        break or are read anew, so that what stays (the arrays C reads) is
        converted once.  By default :meth:`add_sums` itself."""
        return self.add_sums

    def stiffness(self, bonds: BondInput) -> LawStiffness:
        """The bonds as springs and dampers at this configuration, bounding
        what :meth:`forces` does near it: stiffness along each bond at least
        its tangent ``dF/dr``, the damping coefficient, the tension over the
        length across it.  ``bonds`` comes as to :meth:`forces`, with
        ``advance=False`` and no velocities."""
        raise NotImplementedError(f"bond law {self.name!r} gives no stiffness: "
                                  "stable_timestep cannot bound its timestep")


#: registered bond laws by name
LAWS: dict = {}


def register(law: type) -> type:
    """Make a bond law available by its ``name`` (usable as a class decorator).

    A name taken by another law is refused (a law of one's own takes a name
    of its own); the same class defined again, as a notebook cell run twice
    defines it (same module and qualified name), takes the place of the
    first."""
    if not (isinstance(law, type) and issubclass(law, BondLaw) and law.name):
        raise TypeError(f"register: {law!r} is not a named BondLaw subclass")
    taken = LAWS.get(law.name)
    if taken is not None and _where(taken) != _where(law):
        raise ValueError(f"register: the bond law name {law.name!r} is taken by "
                         f"{_where(taken)}; give {_where(law)} a name of its own")
    LAWS[law.name] = law
    return law


def _where(law: type) -> str:
    """A law class by its module and qualified name."""
    return f"{law.__module__}.{law.__qualname__}"
