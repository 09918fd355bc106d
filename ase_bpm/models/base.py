"""The ASE adapter shared by the ase_bpm calculators.

What every ase_bpm calculator does the same way:

* **One force evaluation per configuration.**  Forces are computed once when
  the positions (or the cell, the atom count, the particle types or the bonds)
  change, with the velocities the atoms have at that moment, and reused for
  every further request at the same configuration.  That is what LAMMPS does
  (one evaluation per step, after the drift, with half-step velocities) and
  what ASE's integrators expect: ``VelocityVerlet`` asks for forces twice per
  step at unchanged positions.  Bonds break, and history advances, once per
  step.  After changing *only* velocities, call :meth:`BPMCalculator.refresh`
  to have the damping forces recomputed.
* **State on the atoms.**  Everything a run needs to continue lives in
  ``atoms.arrays`` and ``atoms.info`` (names starting with ``bpm_`` or
  ``bond_``), so ``atoms.copy()`` and :func:`ase_bpm.write_restart` carry it.
  The last evaluation is recorded there too (positions, forces, energy), so a
  new calculator attached at the same configuration returns the same forces
  and a restarted run follows the uninterrupted one bit for bit.
* **An energy ledger.**  ``energy`` is the elastic energy.  The work done by
  velocity-dependent (damping) forces is accumulated, trapezoidally over each
  step, in ``dissipated_energy``; energy that vanishes with broken bonds in
  ``broken_bond_energy``.  For a run,
  ``kinetic + energy + dissipated_energy + broken_bond_energy`` is conserved
  up to the integrator's error: O(dt^2) over a run, plus O(dt) at each bond
  break (forces switch off or on within one step).
* **Clear errors, no lost state.**  Inputs are checked before anything on the
  atoms is touched; a failed evaluation leaves the atoms as they were.

The machinery lives beside this module: :mod:`.lifecycle` (what an
evaluation is, and its stages in order), :mod:`.guard` (the blow-up guard),
:mod:`.ledger` (the energy ledger), :mod:`.record` (the record on the atoms)
and :mod:`.pure` (pure evaluations).  Every name this module defined before
them is still importable from here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Optional

import numpy as np
from ase import Atoms
from ase.calculators.calculator import Calculator, Parameters, all_changes
from ase.calculators.calculator import equal as ase_equal

from ..core.arrays import (Inputs, all_finite, any_nonzero, dot_sum, first_non_finite,  # noqa: F401
                           particle_types, positive_masses, require_finite, same_array,
                           velocities)
from ..core.params import check_keywords
from ..core.spheres import SOLID_SPHERE
from ..laws import timestep as stability
from . import lifecycle
from .evaluation import Clock, Context, Contribution, Evaluation  # noqa: F401 (their old home)
from .guard import (BEYOND_LIMIT, DRIFT_PRECISION, DRIFT_RESIDUAL, LEDGER_FACTOR,  # noqa: F401
                    POSITION_ROUNDOFF, RUN_AGAIN, RUNAWAY_FACTOR, RUNAWAY_STEPS,
                    STABILITY_EVERY, STILL_STEPS, UNTOLD_STEPS, Guard, GuardWatch,
                    OptimiserStepWarning, TimestepUncheckedWarning, TimestepWarning,
                    UnstableSimulationError)
from .ledger import _work  # noqa: F401 (its old home)
from .lifecycle import (Seen, SpinNotIntegratedWarning, SpinWatch, _add,  # noqa: F401
                        _together, state_taken)
from .pure import PureEvaluations, pure  # noqa: F401
from .record import (BROKEN_ENERGY, DISSIPATED, ENERGY, F_LAST, FD_LAST, RECORD_IDS,  # noqa: F401
                     SIGNATURE, STEP, STRESS, T_LAST, X_LAST, InputDigests, Record, digest)


def virial(r_xc, f_xc) -> np.ndarray:
    """``sum_x r_x (x) f_x`` for pair vectors ``r = x_j - x_i`` and forces on ``i``."""
    return r_xc.T @ f_xc


#: the fixes calculators rebuild from their ``todict()`` (``"type"`` -> class;
#: :mod:`ase_bpm.scene.fixes` registers its own, :func:`register_fix` others)
FIX_TYPES: dict = {}


def register_fix(cls):
    """Let calculators rebuild fixes of class ``cls`` from ``todict()``,
    whose ``"type"`` is the class name (usable as a class decorator)."""
    FIX_TYPES[cls.__name__] = cls
    return cls


def fix_from_dict(described: Mapping):
    """The fix a ``todict()`` describes (through JSON too): its class
    (``"type"``, one of :data:`FIX_TYPES`) built from the other entries, by
    the class's ``from_dict`` where it has one."""
    kind = described.get("type")
    cls = FIX_TYPES.get(kind)
    if cls is None:
        raise ValueError(f"fix {dict(described)!r}: unknown type {kind!r}; known: "
                         f"{', '.join(sorted(FIX_TYPES))} (ase_bpm.register_fix "
                         "adds a class)")
    fields = {key: value for key, value in described.items() if key != "type"}
    return cls.from_dict(fields) if hasattr(cls, "from_dict") else cls(**fields)


def _same_value(a, b) -> bool:
    """ASE's comparison of a parameter's new and old value; values NumPy
    cannot compare (a string against a boolean, in NumPy 2.0) differ, so
    that the model's own check names the bad one."""
    try:
        return bool(ase_equal(a, b))
    except (AttributeError, TypeError, ValueError):
        return False


class BPMCalculator(Calculator):
    """Base class: the ASE adapter (see module doc).

    It holds a model (``calc.model``, :class:`ase_bpm.models.model.Model`),
    which computes; each public calculator is a thin subclass that gives its
    constructor and parameters and makes its model.  What an evaluation is
    and its stages are :func:`ase_bpm.models.lifecycle.run`'s.
    """

    implemented_properties = ["energy", "free_energy", "forces", "stress", "torques"]
    #: the model (:class:`ase_bpm.models.model.Model`), made by the subclass
    model = None
    #: the class of that model (each public calculator names its own)
    model_class = None

    @property
    def watched_arrays(self) -> tuple:
        """Per-atom arrays whose change means a new configuration (the model's)."""
        return self.model.watched_arrays

    @property
    def per_atom_outputs(self) -> tuple:
        """The per-atom outputs each evaluation writes to ``atoms.arrays``
        (names; what :class:`ase_bpm.ViewerTrajectory` writes by default)."""
        return self.model.per_atom_outputs

    #: the keywords of ASE's Calculator that ase_bpm's calculators pass on
    ASE_KEYWORDS = ("restart", "ignore_bad_restart_file", "label", "atoms", "directory")

    def __init__(self, fixes=(), guard: bool = True, **kwargs):
        check_keywords(type(self).__name__, kwargs,
                       [*self.default_parameters, *self.ASE_KEYWORDS, "fixes", "guard"])
        # external force pieces (ase_bpm.scene.fixes), or their todict()s
        self.fixes = [fix_from_dict(f) if isinstance(f, Mapping) else f for f in fixes or ()]
        #: stop a blowing-up run with UnstableSimulationError (see guard.Guard)
        self.guard = bool(guard)
        self._guard = Guard(type(self).__name__)  # what the guard saw and said
        self._record = Record()  # writes and reads the record on the atoms
        self._pure = PureEvaluations()  # inside pure evaluations (see pure)
        self._spin = SpinWatch()  # does the integrator turn the spheres?
        self._quasi_static = False  # the evaluation under way is a calc.step
        self._announced = False  # an integrator announced the step under evaluation
        self._recompute = False
        self._seen = None  # what the last evaluation saw, for check_state
        self._step_pending = False  # an integrator announced a step (begin_step)
        self._integrator_dt = None  # the timestep announced by the integrator
        self._turning = False  # the announced step's integrator turns the spheres
        self._signature_cache = (None, None)  # (its parts, the signature)
        #: what evaluations take from the fixes and the model (lifecycle.Plan)
        self._plan = None
        super().__init__(**kwargs)

    # -- ASE cache --------------------------------------------------------
    @property
    def atoms(self) -> Optional[Atoms]:
        """The configuration of the last evaluation (built when asked for)."""
        seen = self._seen
        if seen is None:
            return self._atoms
        return Atoms(numbers=seen.numbers, positions=seen.positions, cell=seen.cell,
                     pbc=seen.pbc)

    @atoms.setter
    def atoms(self, value) -> None:  # ASE's Calculator sets it
        self._atoms = value

    def check_state(self, atoms: Atoms, tol: float = 0.0) -> list:
        """Changes since the last evaluation; positions are compared exactly.

        ASE asks at every request for a property, three times a step, twice
        with nothing changed: one comparison of the positions, the atomic
        numbers, the cell, the periodicity and the watched arrays (the
        model's) with the copies the last evaluation kept, and a look at
        whether the model's state arrays are the very ones it left
        (:meth:`Model.state_arrays`).  After a move the evaluation reads
        everything itself: only the positions are named.  The copies are
        :class:`.lifecycle.Seen`'s.
        """
        seen = self._seen
        if seen is None or seen.natoms != len(atoms):
            return list(all_changes)
        arrays, names = atoms.arrays, self.model.watched_arrays
        if not same_array(seen.positions, arrays["positions"],
                          (seen.numbers, arrays["numbers"]), (seen.cell, atoms.cell.array),
                          (seen.pbc, atoms.pbc), *zip(seen.watched, map(arrays.get, names))):
            if not same_array(seen.positions, arrays["positions"]):
                return ["positions", "numbers", "cell", "pbc", *names]
            return self._changes(atoms, seen, names)
        if seen.state is None:  # (the model cannot tell its arrays: it is asked)
            return ["bonds"] if self.model.state_replaced(atoms) else []
        for name, array in seen.state.items():
            if arrays.get(name) is not array:
                return ["bonds"]
        return []

    def _changes(self, atoms: Atoms, seen: Seen, names: tuple) -> list:
        """:meth:`check_state`'s answer where something changed but the
        positions: what changed."""
        changes = []
        if not same_array(seen.numbers, atoms.numbers):
            changes.append("numbers")
        if not same_array(seen.cell, atoms.cell.array, (seen.pbc, atoms.pbc)):
            changes += ["cell", "pbc"]
        for name, kept in zip(names, seen.watched):
            if not same_array(kept, atoms.arrays.get(name)):
                changes.append(name)
        if self.model.state_replaced(atoms):
            changes.append("bonds")
        return changes

    def todict(self, skip_default=True) -> dict:
        """The parameters, as ASE's trajectories and databases store them,
        with the fixes' own ``todict()`` under ``fixes`` (and ``guard=False``
        where set): ``type(calc)(**calc.todict())``, or
        :func:`ase_bpm.scene.aseio.calculator_from_dict` by name, builds the
        calculator again, through JSON too."""
        params = dict(super().todict(skip_default=skip_default))
        if self.fixes:
            params["fixes"] = [fix.todict() for fix in self.fixes]
        if not self.guard:
            params["guard"] = False
        return params

    def set(self, **kwargs):
        """ASE's ``set``, then the model set up anew (:meth:`_setup`).  A
        change of the physics applies from the next request, at the same
        positions too (ASE keeps results until the atoms change).

        Keywords the model does not take raise TypeError (naming them and the
        valid ones); parameters that fail their checks raise ValueError and
        leave the calculator as it was."""
        if "parameters" in kwargs:  # ASE's: read them from a file
            kwargs = {**Parameters.read(kwargs.pop("parameters")), **kwargs}
        check_keywords(type(self).__name__, kwargs, self.default_parameters)
        before = getattr(self, "_param_digest", None)
        kept = dict(self.parameters)
        changed = {}  # (ASE's set, with a comparison that never raises)
        for key, value in kwargs.items():
            if key not in self.parameters or not _same_value(value, self.parameters.get(key)):
                changed[key] = value
                self.parameters[key] = value
        if changed and getattr(self, "discard_results_on_any_change", False):
            self.reset()
        try:
            self._setup()
        except Exception:
            if before is not None:  # (a failed constructor leaves no calculator)
                self.parameters = Parameters(kept)
                self._setup()
            raise
        if before is not None and self._param_digest != before:
            self.results = {}  # the signature differs: the next request evaluates
            self._guard.check_again()
        return changed

    def _setup(self) -> None:
        """Read the parameters into the model's laws and tables, and set
        ``_param_digest``, the digest of everything they decide."""
        self._param_digest = self.model.setup(self.parameters)

    def refresh(self) -> None:
        """Recompute at the current positions on the next request.

        Use it after changing only velocities (momenta): forces are otherwise
        reused while positions stay the same, so damping would still see the
        old velocities.  Also after editing calculator state on the atoms
        (``bond_r0``, ``bpm_*``), which is re-read in full, and after changing
        a fix in place (its ``todict()`` is read again).  Bonds do not break
        and the step count does not advance in a refresh.
        """
        self.results = {}
        self._recompute = True
        self._seen = None
        self._plan = None  # (the fixes are described afresh: changed in place)
        self._record.forget_ids()  # the ID array is checked afresh too
        self._guard.check_again()
        self.model.forget()

    # -- evaluation ----------------------------------------------------------
    #: ASE's ``calculate(atoms, properties, system_changes)``: evaluate the
    #: atoms (what the evaluation is, and its stages in order) and set
    #: ``results``; it is :func:`.lifecycle.run` itself (one call less a step)
    calculate = lifecycle.run

    def _remove_lost_atoms(self, atoms: Atoms) -> None:
        """Let the fixes that remove atoms (``lost_atoms(atoms, stepping)``,
        :class:`ase_bpm.LostAtoms`) remove them before this evaluation, as
        LAMMPS does between the drift and the forces.  The record on the
        atoms (sliced by ``del atoms[...]``) then holds for the atoms left, so
        a step stays a step; what the calculator read from the atoms is read
        afresh."""
        for fix in self.fixes:
            remove = getattr(fix, "lost_atoms", None)
            if remove is None:
                continue
            x_last = atoms.arrays.get(X_LAST)
            stepping = self._step_pending or (
                x_last is not None and not same_array(x_last, atoms.positions))
            gone = remove(atoms, stepping)
            if not len(gone):
                continue
            del atoms[gone]
            if RECORD_IDS in atoms.info:
                atoms.info[RECORD_IDS] = self._record.ids_checksum(atoms)
            self.model.forget()
            self._seen, self._spin.last = None, None
            self._record.forget_ids()
            self._recompute = True  # (at unchanged positions too: a run's set-up)
            self.results = {}
            self._guard.forget(atoms)

    # -- pure evaluations --------------------------------------------------------------
    @property
    def pure_mode(self) -> bool:
        """Are evaluations pure (see :func:`pure`)?"""
        return self._pure.depth > 0

    def enter_pure(self, atoms: Atoms) -> None:
        """Start pure evaluations of ``atoms`` (:func:`pure` calls it)."""
        self._pure.enter(atoms)
        self.results = {}
        self._seen = None

    def leave_pure(self, atoms: Atoms) -> None:
        """End pure evaluations of ``atoms``.  If the atoms moved since the last
        recorded evaluation (a relaxation), the record is re-based on where
        they are: the next evaluation is not a step.  If they are back where
        they were, the run goes on as if nothing had happened."""
        self.results = {}
        self._seen = None
        self._step_pending = False  # a step announced inside is not one
        self._pure.leave()

    def step(self, atoms: Atoms) -> None:
        """Evaluate ``atoms`` as one step at the positions they have: bonds past
        their breaking criterion break, history advances.  For quasi-static
        loading: relax inside :func:`pure`, then commit the breaking with
        ``calc.step(atoms)``."""
        if self.pure_mode:
            raise RuntimeError("calc.step(atoms) inside pure evaluations: leave the "
                               "ase_bpm.pure block first")
        self._step_pending = True
        self._turning = True  # (quasi-static: no integrator, so none to turn the spheres)
        self._quasi_static = True  # no timestep to check against stable_timestep
        self.results = {}
        try:
            self.get_property("energy", atoms)
        finally:
            self._quasi_static = False

    def begin_step(self, timestep: float, turns: bool = False) -> None:
        """Called by ase_bpm integrators between the drift and the force
        evaluation of each MD step: the next evaluation is the next step, even
        if no atom moved, and ``timestep`` is the integrator's; ``turns``: the
        integrator turns the spheres with the torques (see :meth:`_watch_spin`)."""
        if not timestep > 0:
            raise ValueError(f"timestep must be positive, got {timestep!r}")
        given = self.parameters.get("timestep")
        if given is not None and abs(float(given) - timestep) > 1e-12 * timestep:
            raise ValueError(f"timestep mismatch: the calculator was given timestep="
                             f"{float(given):.6g}, the integrator steps {timestep:.6g}")
        self._integrator_dt = float(timestep)
        self._step_pending = True
        self._turning = bool(turns)
        self.results = {}

    @property
    def needs_timestep(self) -> bool:
        """The model itself advances history by the MD timestep in each step
        (e.g. viscoelastic bonds, shear history)."""
        return self.model.needs_timestep

    @property
    def own_torques(self) -> bool:
        """The model's own forces come with torques (frictional granular contacts)."""
        return self.model.own_torques

    @property
    def kernel_route(self) -> str:
        """``"compiled"`` or ``"numpy"``: the route this calculator resolved
        (:func:`ase_bpm.laws.kernel_route`); what runs on it: :attr:`kernel_routes`."""
        return self.model.kernel_route

    @property
    def kernel_routes(self) -> dict:
        """The route each law runs on: a bond law's name (and ``"contacts"``,
        where contacts act) -> ``"compiled"`` or ``"numpy"``."""
        return self.model.kernel_routes

    @property
    def ledger_balances(self) -> bool:
        """Is kinetic + rotational + ``energy`` + ``dissipated_energy`` +
        ``broken_bond_energy`` conserved (to the integrator's error)?  False
        where some force or torque derives from no energy the calculator
        reports (``bpm/rotational`` bonds: the ledger books their damping's
        work, not their elastic work; :mod:`ase_bpm.models.ledger`)."""
        return self.model.ledger_balances

    @property
    def produces_torques(self) -> bool:
        """Can an evaluation give a torque?  The model's own (``own_torques``)
        or a fix's: one that says ``produces_torques`` (a granular wall with
        friction), or any fix that contributes without saying.  When False,
        :class:`ase_bpm.SphereVelocityVerlet` does not integrate ``omega``
        (the torques stay zero)."""
        return lifecycle.plan_of(self).torques

    def check_timestep(self, atoms: Atoms, timestep: float) -> None:
        """Raise if the atoms moved since the last evaluation as a velocity
        Verlet step of a different length than ``timestep`` (see
        :meth:`.guard.Guard.check_timestep`)."""
        self._guard.check_timestep(atoms, timestep, bool(self.parameters.get("timestep")))

    # -- the stable timestep -------------------------------------------------------
    def stable_timestep(self, atoms: Atoms) -> float:
        """The largest timestep (in the scene's time unit) at which velocity
        Verlet stays stable on ``atoms`` with this model and its fixes, times
        a safety factor: ``dt = calc.stable_timestep(atoms)``.

        Each bond and contact acting now is taken as a linear spring and
        damper (its law's ``stiffness``: the tangent stiffness along it, the
        tension across it, tangential springs and dampers of granular
        contacts, Hertzian stiffness at each contact's present overlap);
        fixes that push (granular walls, the indenter) add theirs.  The
        largest frequency ``w`` and damping rate ``c`` are bounded per node
        (the largest eigenvalue of each atom's block of projected stiffness,
        or damping, over its mass and, for spheres, its moment of inertia
        ``2/5 m r^2``, taken twice for springs between two moving atoms), and
        the estimate is ``SAFETY * 4 / (c + sqrt(c^2 + 4 w^2))``, the limit of
        a damped mode under velocity Verlet with half-step velocities
        (``2/w`` without damping), ``SAFETY = 0.9``.  Formulas and sources:
        :mod:`ase_bpm.laws.timestep`.

        The estimate holds for the configuration given: contacts that form
        later, or Hertzian overlaps that grow, may need less; it is a
        stability limit, not an accuracy target (velocity Verlet's energy
        error grows as ``(w dt)^2``: a third of it or less keeps the ledger
        within a few per cent).  ``inf`` for no atoms, and for atoms with no
        bond or contact acting.  Raises ``ValueError`` for a mass that is not
        finite and positive, naming the atom.

        Nothing changes: no step is counted, no bond breaks, no history
        advances and nothing on the atoms or in this calculator's record is
        written (the bonds and contacts are read as a pure evaluation reads
        them).
        """
        return self._stiffest(atoms)[0]

    def _stiffest(self, atoms: Atoms) -> tuple:
        """``(stable_timestep(atoms), the atom with the largest frequency
        bound)``; the atom is None where nothing acts."""
        if len(atoms) == 0:
            return float("inf"), None
        m_n = positive_masses(atoms.get_masses())
        require_finite("position", atoms.positions)
        inputs = Inputs(atoms)  # the model's and the fixes' readers take them from here
        ctx = self._context(atoms, inputs)
        springs = list(self.model.springs(atoms, ctx))
        if self.fixes:  # (their clock has the timestep where a fix needs it)
            clock = Clock.of(replace(ctx, timestep=lifecycle.timestep_of(self, False, ctx.step)))
            springs += [fix.springs(atoms, clock) for fix in self.fixes
                        if hasattr(fix, "springs")]
        springs = [s for s in springs if s is not None and len(s)]
        inertia_n = None
        if any(s.turning for s in springs):
            inertia_n = SOLID_SPHERE * m_n * inputs.radii("stable_timestep") ** 2
        return stability.stiffest(springs, m_n, inertia_n, inputs.frozen)

    # -- the model: what the calculator asks of it -------------------------------
    def _context(self, atoms: Atoms, inputs: Inputs) -> Context:
        """A look at the atoms that is not a step (``advancing`` False), pure
        or not as evaluations are now, at the recorded step, with the checked
        ``inputs``, the parameters and the fixes."""
        step = int(atoms.info.get(STEP, 0))
        timestep = lifecycle.timestep_of(self, False, step) if self.model.needs_timestep else None
        return Context(advancing=False, pure=self.pure_mode, step=step, timestep=timestep,
                       inputs=inputs, parameters=self.parameters, fixes=tuple(self.fixes))

    def _evaluate_aside(self, atoms: Atoms) -> Evaluation:
        """A pure evaluation of the model at this configuration, whose forces
        are not used (the stress of an evaluation this calculator did not make)."""
        return self.model.evaluate(atoms, self._context(atoms, Inputs(atoms)))

    def _signature(self, atoms: Atoms, evaluation: Optional[Evaluation],
                   plan: Optional[lifecycle.Plan] = None) -> str:
        """What the forces depend on besides positions and velocities: the
        parameters, the fixes (their ``todict()``, read again when the fixes
        are replaced, at ``set`` and at ``refresh``) and the model's parts
        (types, bonds...: :meth:`Model.signature_parts`).  With
        ``evaluation``, of the state that evaluation left on the atoms (after
        its commit).  Hashed again only when one of them changed.  ``plan``:
        the calculator's :class:`~.lifecycle.Plan`, where worked out already."""
        key = (self._param_digest, (plan or lifecycle.plan_of(self)).fixes_digest,
               *self.model.signature_parts(atoms, evaluation))
        if self._signature_cache[0] != key:
            self._signature_cache = (key, digest(*key))
        return self._signature_cache[1]
