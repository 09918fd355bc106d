"""ASE plumbing shared by the ase_bpm calculators.

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
"""

from __future__ import annotations

import hashlib
import math
import warnings
import weakref
from collections.abc import Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Optional

import numpy as np
from ase import Atoms
from ase.calculators.calculator import Calculator, Parameters, all_changes

from ..core.arrays import (Inputs, all_finite, any_nonzero, dot_sum, first_non_finite,  # noqa: F401
                           particle_types, positive_masses, require_finite, same_array,
                           velocities)
from ..core.bonds import ID, id_words, ids_checksum, read_ids, same_checksum
from ..core.neighbours import minimum_image
from ..core.params import check_keywords, outside_stacklevel
from ..core.spheres import OMEGA, SOLID_SPHERE, frozen
from ..laws import timestep as stability
from .evaluation import Clock, Context, Contribution, Evaluation  # noqa: F401 (their old home)

# names of the record of the last evaluation
X_LAST, F_LAST, FD_LAST = "bpm_x_last", "bpm_f_last", "bpm_fd_last"
T_LAST = "bpm_t_last"
STEP, ENERGY, STRESS = "bpm_step", "bpm_energy", "bpm_stress"
#: info: checksum of the atom IDs of the last evaluation (its atoms, any order)
RECORD_IDS = "bpm_record_ids"
DISSIPATED, BROKEN_ENERGY, SIGNATURE = (
    "bpm_dissipated_energy", "bpm_broken_bond_energy", "bpm_signature")


#: the blow-up guard (BPMCalculator._runaway): a run stops when the kinetic
#: energy grows more than RUNAWAY_FACTOR-fold in each of RUNAWAY_STEPS steps
RUNAWAY_FACTOR = 10.0
RUNAWAY_STEPS = 4
#: ... and when its timestep is more than BEYOND_LIMIT times stable_timestep
#: (checked every STABILITY_EVERY steps: the estimate costs about six steps of
#: the impact scene); beyond the estimate itself it warns (TimestepWarning)
BEYOND_LIMIT = 3.0
STABILITY_EVERY = 2000
#: a timestep told by a velocity Verlet drift holds to this relative precision
DRIFT_PRECISION = 1e-6
#: atoms moved as a velocity Verlet drift: each displacement is the timestep
#: times the velocity to this fraction of the largest displacement ...
DRIFT_RESIDUAL = 1e-9
#: ... beyond the round-off of positions: a few units in the last place of
#: the largest coordinate (slow bodies far from the origin move by little more)
POSITION_ROUNDOFF = 8 * np.finfo(float).eps
#: steps in a row whose timestep cannot be told (a thermostat moved the atoms)
#: before TimestepUncheckedWarning (a hand move before a run gives one)
UNTOLD_STEPS = 3
#: evaluations at new positions in a row that find the momenta as they were
#: while forces act before OptimiserStepWarning: a body moved by hand gives
#: one, and so does the first step of ASE's Langevin (it sets the momenta
#: after its evaluation: from rest, that one sees them still zero)
STILL_STEPS = 3
#: ... and when one step's energy ledger is off by more than LEDGER_FACTOR
#: times the kinetic and potential energy of that step and the one before
LEDGER_FACTOR = 10.0


class SpinNotIntegratedWarning(UserWarning):
    """Torques act on spheres whose angular velocities nothing integrates
    (an integrator that moves and kicks but does not turn them)."""


class TimestepWarning(UserWarning):
    """A run's timestep exceeds ``stable_timestep(atoms)`` (but not
    ``BEYOND_LIMIT`` times it, which raises :class:`UnstableSimulationError`):
    velocity Verlet may stay bounded there while bonds break and contacts
    gain energy from the integration alone."""


class TimestepUncheckedWarning(TimestepWarning):
    """The timestep of a run cannot be told (a thermostat such as ASE's
    ``Langevin`` moves the atoms otherwise than a velocity Verlet drift), so
    the guard cannot check it against ``stable_timestep(atoms)``: pass
    ``timestep=`` to the calculator."""


class OptimiserStepWarning(UserWarning):
    """Evaluations at new positions find the momenta unchanged while forces
    act, as under ASE's optimisers and ``ase.vibrations``: each of them is an
    MD step (bonds break, history advances); such evaluations belong inside
    :func:`ase_bpm.pure`."""


#: the end of an UnstableSimulationError's message
RUN_AGAIN = (" (the integrator has moved the atoms for this step all the same: to run "
             "again, start from a copy or restart file of them taken before)")


class UnstableSimulationError(RuntimeError, ValueError):
    """A step gave non-finite positions, forces, torques or energy: the
    simulation blew up (usually a timestep beyond the stable one).  Raised
    before anything of that step is written to the atoms; the message names
    the step, the particle, the quantity and, where the model can estimate
    it, the stable timestep.  (Also a ValueError: non-finite positions are
    bad input too, and were reported as such before the guard existed.)"""


@dataclass
class GuardWatch:
    """What the blow-up guard remembers of the steps of one atoms object."""

    atoms: object  # weak reference to the atoms
    kinetic: float = 0.0  # kinetic energy at the last step
    streak: int = 0  # steps in a row it grew RUNAWAY_FACTOR-fold
    kinetic_steps: int = 0  # steps seen by the runaway check
    total: float = 0.0  # kinetic plus potential energy at the last step
    in_play: float = 0.0  # kinetic plus |potential| at the last step
    balanced: bool = False  # the ledger check has a last step to compare with
    limit: Optional[tuple] = None  # (step, timestep) of the last passed limit check
    #: nothing acted at that check (stable_timestep inf): checked again as
    #: soon as something does (spheres that come to touch)
    idle: bool = False
    #: the fastest particle at that check, if a velocity Verlet drift told its
    #: timestep: its own drift tells each step whether the timestep changed
    probe: Optional[int] = None
    #: (step, stable_timestep) at the state the run's first limit check started from
    first: Optional[tuple] = None
    untold: int = 0  # steps in a row whose timestep could not be told
    momenta: Optional[float] = None  # kinetic energy at the last evaluation (its momenta)
    same_momenta: bool = False  # the last evaluation found them as before
    still: int = 0  # evaluations at new positions in a row with those momenta unchanged

    def forget(self) -> None:
        """Start afresh (after a raise: the step is not taken; the next limit
        check is a first one again; ``first`` stays for the messages)."""
        self.kinetic, self.streak, self.kinetic_steps = 0.0, 0, 0
        self.balanced = False
        self.check_timestep_again()

    def check_timestep_again(self) -> None:
        """The next step checks the timestep as a run's first does (``first``,
        the run's first state, stays)."""
        self.limit, self.idle, self.probe = None, False, None


def digest(*parts) -> str:
    """Short hash of arrays and strings (for the signature of a configuration)."""
    h = hashlib.blake2b(digest_size=16)
    for part in parts:
        h.update(np.ascontiguousarray(part).tobytes() if isinstance(part, np.ndarray)
                 else repr(part).encode())
    return h.hexdigest()


class InputDigests:
    """Digests of per-atom input arrays (types, volumes, radii, masses), each
    recomputed only when the array's content changed since it was last asked
    for: a comparison per evaluation, no hashing."""

    def __init__(self):
        self._kept = {}  # name -> (copy of the array, its digest)

    def __call__(self, name: str, array) -> str:
        kept = self._kept.get(name)
        if kept is not None and (kept[2] is array and array is not None
                                 and not array.flags.writeable or same_array(kept[0], array)):
            return kept[1]  # (a read-only array seen last time: unchanged)
        value = "" if array is None else digest(array)
        self._kept[name] = (None if array is None else np.array(array, copy=True), value, array)
        return value


def state_taken(name: str) -> ValueError:
    """The error of two fixes that keep their state in one array of the atoms."""
    return ValueError(f"two fixes keep their state in atoms.arrays[{name!r}]: give them "
                      "different names")


def _together(fixes) -> list:
    """``fixes`` in their order, in groups of neighbours with the same
    ``together_key`` (a fix without one, or None, is a group of its own)."""
    groups, last = [], None
    for fix in fixes:
        key = getattr(fix, "together_key", None)
        if key is not None and groups and key == last:
            groups[-1].append(fix)
        else:
            groups.append([fix])
        last = key
    return groups


def _add(ev: Evaluation, part: Contribution) -> None:
    """Add a piece's forces, damping forces, torques and energy to the
    evaluation's (in place: its own arrays), unless the piece added them."""
    ev.energy += part.energy
    if part.added:  # the evaluation's arrays, the piece's added in place
        ev.forces = part.forces
        ev.f_damp = ev.f_damp if part.f_damp is None else part.f_damp
        ev.torques = ev.torques if part.torques is None else part.torques
        return
    ev.forces += part.forces
    if part.f_damp is not None:
        if ev.f_damp is None:
            ev.f_damp = part.f_damp.copy()
        else:
            ev.f_damp += part.f_damp
    if part.torques is not None:
        if ev.torques is None:
            ev.torques = part.torques.copy()
        else:
            ev.torques += part.torques


def _work(f_nc: Optional[np.ndarray], dx_nc: np.ndarray) -> float:
    """``sum f . dx`` over the atoms (0 without forces)."""
    return 0.0 if f_nc is None else dot_sum(f_nc, dx_nc)


def virial(r_xc, f_xc) -> np.ndarray:
    """``sum_x r_x (x) f_x`` for pair vectors ``r = x_j - x_i`` and forces on ``i``."""
    return r_xc.T @ f_xc


@contextmanager
def pure(*atoms_objects: Atoms):
    """Pure evaluations of the ase_bpm calculators of ``atoms_objects``.

    Every evaluation at new positions is otherwise an MD step: bonds break,
    history advances (viscoelastic state, breaking thresholds, granular shear),
    the step counter moves and damping work is booked.  Inside this block, for
    ASE optimisers, ``ase.vibrations``, NEB or finite-difference checks,
    forces and energy are a function of the positions and velocities only: a
    bond strained past its breaking criterion acts as a broken bond would but
    stays on the atoms, history is read and not advanced, no step is counted,
    nothing is booked and nothing is written on the atoms::

        with ase_bpm.pure(atoms):
            BFGS(atoms).run(fmax=1e-6)
        atoms.calc.step(atoms)  # commit breaking at the relaxed state

    Leaving the block re-bases the record on the current positions, so the
    next evaluation is not counted as a step (a relaxation is not MD motion);
    back at the positions the block was entered with, the run continues bit
    for bit as if the block had never been.
    """
    calcs = []
    try:
        for atoms in atoms_objects:
            calc = atoms.calc
            if not isinstance(calc, BPMCalculator):
                raise TypeError(f"ase_bpm.pure: atoms.calc is {type(calc).__name__}, not an "
                                "ase_bpm calculator")
            calc.enter_pure(atoms)
            calcs.append((calc, atoms))
        yield
    finally:
        for calc, atoms in calcs:
            calc.leave_pure(atoms)


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


class BPMCalculator(Calculator):
    """Base class: caching, state record and energy ledger (see module doc).

    Subclasses implement :meth:`_evaluate` (compute, touching nothing),
    :meth:`_commit` (write model state back on the atoms) and
    :meth:`_signature` (what, besides positions, the forces depend on).
    """

    implemented_properties = ["energy", "free_energy", "forces", "stress", "torques"]
    #: the model (:class:`ase_bpm.models.model.Model`), made by the subclass
    model = None

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
        #: stop a blowing-up run with UnstableSimulationError (see _guard, _runaway)
        self.guard = bool(guard)
        self._watched = {}  # id(atoms) -> GuardWatch: what the guard saw of their steps
        self._timesteps_warned = set()  # the timesteps TimestepWarning named (as shown)
        self._untold_warned = False  # TimestepUncheckedWarning given
        self._still_warned = False  # OptimiserStepWarning given
        self._quasi_static = False  # the evaluation under way is a calc.step
        self._announced = False  # an integrator announced the step under evaluation
        self._recompute = False
        self._seen = None  # what the last evaluation saw, for check_state
        self.advancing = False  # this evaluation is a step (see calculate)
        self._step_pending = False  # an integrator announced a step (begin_step)
        self._integrator_dt = None  # the timestep announced by the integrator
        self._turning = False  # the announced step's integrator turns the spheres
        #: (omega, did a torque act) after the last evaluation that no turning
        #: integrator announced; see _watch_spin
        self._spin_watch = None
        self._spin_warned = False
        self._virial_later = None  # virial of the last evaluation, if not yet asked
        self._pure_depth = 0  # inside pure evaluations (see pure)
        self._pure_atoms = []  # the atoms objects to re-base on leaving them
        self._digests = InputDigests()  # of the inputs the signature names
        self._signature_cache = (None, None)  # (its parts, the signature)
        self._no_torques = None  # zeros, the torques of models without any
        self.inputs = None  # the checked inputs of the evaluation under way
        self._fixes_described = (None, "")  # (the fixes' todict(), its digest)
        self._timed = (None, None)  # what needs the timestep (see _timed_pieces)
        self._ids_kept = (None, None)  # (the ID array, its checksum)
        self._ids_written = None  # the complete ID array the last record left on the atoms
        super().__init__(**kwargs)

    # -- ASE cache --------------------------------------------------------
    @property
    def atoms(self) -> Optional[Atoms]:
        """The configuration of the last evaluation (built when asked for)."""
        seen = self._seen
        if seen is None:
            return self._atoms
        return Atoms(numbers=seen["numbers"], positions=seen["positions"],
                     cell=seen["cell"], pbc=seen["pbc"])

    @atoms.setter
    def atoms(self, value) -> None:  # ASE's Calculator sets it
        self._atoms = value

    def check_state(self, atoms: Atoms, tol: float = 0.0) -> list:
        """Changes since the last evaluation; positions are compared exactly.

        Positions first: after a move the evaluation runs anyway and reads
        everything itself.  At unchanged positions, the cell, the atomic
        numbers, the watched arrays and the model's own state
        (:meth:`_state_replaced`) are compared.
        """
        seen = self._seen
        if seen is None or seen["natoms"] != len(atoms):
            return list(all_changes)
        if not same_array(seen["positions"], atoms.positions):
            return ["positions", "numbers", "cell", "pbc", *self.watched_arrays]
        changes = []
        if not same_array(seen["numbers"], atoms.numbers):
            changes.append("numbers")
        if not (same_array(seen["cell"], atoms.cell.array) and same_array(seen["pbc"], atoms.pbc)):
            changes += ["cell", "pbc"]
        for name in self.watched_arrays:
            if not same_array(seen.get(name), atoms.arrays.get(name)):
                changes.append(name)
        if self._state_replaced(atoms):
            changes.append("bonds")
        return changes

    def _ids_checksum(self, atoms: Atoms):
        """Checksum of the atoms' IDs (None without IDs), kept while the ID
        array is the same object (ASE's operations make new ones)."""
        ids = atoms.arrays.get(ID)
        if ids is None:
            return None
        if ids is not self._ids_kept[0]:
            self._ids_kept = (ids, ids_checksum(read_ids(atoms, ID)))
        return self._ids_kept[1]

    def _state_replaced(self, atoms: Atoms) -> bool:
        """Has the model state on the atoms (bonds) been replaced since the
        last evaluation?  (:meth:`Model.state_replaced`)"""
        return self.model.state_replaced(atoms)

    def _remember(self, atoms: Atoms, positions=None) -> None:
        """Note what this evaluation saw: ``positions``, a copy the caller
        keeps unchanged (the record's), or a new copy; copies of the other
        arrays (a copy costs less than comparing with the last one)."""
        seen = {"natoms": len(atoms),
                "positions": atoms.positions.copy() if positions is None else positions,
                "numbers": atoms.numbers.copy(), "cell": atoms.cell.array.copy(),
                "pbc": atoms.pbc.copy()}
        for name in self.watched_arrays:
            array = atoms.arrays.get(name)
            seen[name] = None if array is None else array.copy()
        self._seen = seen

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
        changed = super().set(**kwargs)
        try:
            self._setup()
        except Exception:
            if before is not None:  # (a failed constructor leaves no calculator)
                self.parameters = Parameters(kept)
                self._setup()
            raise
        if before is not None and self._param_digest != before:
            self.results = {}  # the signature differs: the next request evaluates
            self._check_timesteps_again()
        return changed

    def _check_timesteps_again(self) -> None:
        """Have the next step of every atoms object check its timestep as a
        run's first does, and warn of any timestep again (the physics, or
        what is known of the atoms, changed)."""
        for watch in self._watched.values():
            watch.check_timestep_again()
        self._timesteps_warned.clear()

    def _setup(self) -> None:
        """Read the parameters into the model's laws and tables, and set
        ``_param_digest``, the digest of everything they decide."""
        self._param_digest = self.model.setup(self.parameters)

    def refresh(self) -> None:
        """Recompute at the current positions on the next request.

        Use it after changing only velocities (momenta): forces are otherwise
        reused while positions stay the same, so damping would still see the
        old velocities.  Also after editing calculator state on the atoms
        (``bond_r0``, ``bpm_*``), which is re-read in full.  Bonds do not break
        and the step count does not advance in a refresh.
        """
        self.results = {}
        self._recompute = True
        self._seen = None
        self._ids_written = None  # the ID array is checked afresh too
        self._check_timesteps_again()
        self._forget()

    def _forget(self) -> None:
        """Drop caches of what was read from the atoms (see :meth:`refresh`)."""
        self.model.forget()

    # -- evaluation ----------------------------------------------------------
    def calculate(self, atoms: Atoms = None, properties=("energy",),
                  system_changes=tuple(all_changes)) -> None:
        if atoms is None:
            atoms = self.atoms
        positions = atoms.positions
        if not all_finite(positions):
            self._non_finite_positions(atoms)
        if self.fixes and not self.pure_mode:
            self._remove_lost_atoms(atoms)
            positions = atoms.positions
        self.inputs = Inputs(atoms)  # this evaluation's checked inputs
        if self.pure_mode:
            self._calculate_pure(atoms, properties)
            return

        x_last = atoms.arrays.get(X_LAST)
        # the record holds for these atoms, whatever their order (not after
        # atoms were deleted, added or combined: then this is a first evaluation)
        first = (x_last is None or x_last.shape != positions.shape
                 or (RECORD_IDS in atoms.info and not same_checksum(
                     atoms.info[RECORD_IDS], self._ids_checksum(atoms))))
        # a step: bonds may break and history advances (not at the first
        # evaluation, nor again at the same configuration unless an
        # integrator announced a step: a scene at rest still ages)
        stepping = self._step_pending and not first
        same_place = not (first or stepping) and same_array(x_last, positions)
        # bond arrays replaced under this calculator at the same place: evaluate
        replaced = self._seen is not None and self._state_replaced(atoms)
        self._announced = self._step_pending
        turned = self._step_pending and self._turning
        self.advancing = not (first or same_place)
        wants_stress = "stress" in properties and bool(atoms.pbc.all())
        if (same_place and not self._recompute and not replaced and F_LAST in atoms.arrays
                and atoms.info.get(SIGNATURE) == self._signature(atoms, None)):
            self._restore(atoms)
            if wants_stress and "stress" not in self.results:
                self._late_stress(atoms)
        else:
            step = int(atoms.info.get(STEP, 0)) + (0 if first or same_place else 1)
            timestep = self._timestep(self.advancing, step)
            if self.advancing and timestep is not None and not self._announced:
                self.check_timestep(atoms, timestep)  # (another integrator's step)
            evaluation = self._evaluate(atoms)
            evaluation.touching = evaluation.energy != 0.0
            self._add_fixes(atoms, evaluation, step, timestep)
            evaluation.dissipated = self._dissipated(atoms, evaluation, first, timestep)
            self._guard(atoms, evaluation, step, timestep)
            # nothing on the atoms has changed so far: now write it all
            self._commit(atoms, evaluation, step)
            self._record(atoms, evaluation, step, first, wants_stress, timestep)
            self._watch_spin(atoms, turned)
        self._recompute = False
        self._step_pending = self._turning = False
        self._remember(atoms, atoms.arrays[X_LAST])

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
                atoms.info[RECORD_IDS] = self._ids_checksum(atoms)
            self._forget()
            self._seen, self._ids_written, self._spin_watch = None, None, None
            self._recompute = True  # (at unchanged positions too: a run's set-up)
            self.results = {}
            watch = self._watched.get(id(atoms))
            if watch is not None:
                watch.forget()

    def _watch_spin(self, atoms: Atoms, turned: bool) -> None:
        """Warn once (:class:`SpinNotIntegratedWarning`) where torques acted on
        spheres free to turn and, a step later, their angular velocities are
        the same: the integrator does not turn them (ASE's VelocityVerlet and
        Langevin move and kick only).  A step announced by an integrator that
        turns them (``begin_step(dt, turns=True)``) needs no watch."""
        if turned or self._spin_warned or not self.produces_torques:
            self._spin_watch = None
            return
        omega = atoms.arrays.get(OMEGA)
        if self.advancing and self._spin_watch is not None:
            before, acted = self._spin_watch
            if acted and same_array(before, omega):
                self._spin_warned = True
                warnings.warn(
                    f"{type(self).__name__}: torques act on the spheres but "
                    f'atoms.arrays["{OMEGA}"] did not change over the step: the integrator '
                    "does not turn them (ASE's VelocityVerlet and Langevin do not), so the "
                    "spheres never spin; use ase_bpm.SphereVelocityVerlet (LAMMPS fix "
                    "nve/sphere)", SpinNotIntegratedWarning, stacklevel=outside_stacklevel())
        torques = self.results.get("torques")
        hold = frozen(atoms)
        acted = torques is not None and any_nonzero(torques if hold is None else torques[~hold])
        self._spin_watch = (None if omega is None else omega.copy(), acted)

    # -- pure evaluations --------------------------------------------------------------
    @property
    def pure_mode(self) -> bool:
        """Are evaluations pure (see :func:`pure`)?"""
        return self._pure_depth > 0

    def _calculate_pure(self, atoms: Atoms, properties) -> None:
        """Forces and energy at these positions and velocities, with nothing
        written and nothing advanced: bonds past their breaking criterion act
        as broken ones would but stay, history is read, the step counter and
        the ledger stand still."""
        self.advancing = False
        step = int(atoms.info.get(STEP, 0))
        timestep = self._timestep(False, step)
        ev = self._evaluate(atoms)
        self._add_fixes(atoms, ev, step, timestep)
        self._guard(atoms, ev, step, timestep)
        self.results = self._results_of(ev, len(atoms))
        if ev.virial is not None and atoms.pbc.all():
            self.results["stress"] = self._stress(atoms, ev.virial)
        self._ledger_results(atoms)
        self._remember(atoms)

    def enter_pure(self, atoms: Atoms) -> None:
        """Start pure evaluations of ``atoms`` (:func:`pure` calls it)."""
        self._pure_depth += 1
        self._pure_atoms.append(atoms)
        self.results = {}
        self._seen = None

    def leave_pure(self, atoms: Atoms) -> None:
        """End pure evaluations of ``atoms``.  If the atoms moved since the last
        recorded evaluation (a relaxation), the record is re-based on where
        they are: the next evaluation is not a step.  If they are back where
        they were, the run goes on as if nothing had happened."""
        self._pure_depth -= 1
        self.results = {}
        self._seen = None
        self._step_pending = False  # a step announced inside is not one
        if self._pure_depth:
            return
        for each in self._pure_atoms:  # every atoms object this calculator served
            x_last = each.arrays.get(X_LAST)
            if x_last is not None and not np.array_equal(x_last, each.positions):
                each.arrays[X_LAST] = each.positions.copy()
                for name in (F_LAST, FD_LAST, T_LAST):
                    each.arrays.pop(name, None)
                each.info.pop(STRESS, None)
        self._pure_atoms = []

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
    def produces_torques(self) -> bool:
        """Can an evaluation give a torque?  The model's own (``own_torques``)
        or a fix's: one that says ``produces_torques`` (a granular wall with
        friction), or any fix that contributes without saying.  When False,
        :class:`ase_bpm.SphereVelocityVerlet` does not integrate ``omega``
        (the torques stay zero)."""
        return self.own_torques or any(
            getattr(fix, "produces_torques", hasattr(fix, "contribute")) for fix in self.fixes)

    def _timestep(self, advancing: bool, step: int = 0):
        """The timestep where the model or a fix uses it (else None).

        It comes from an ase_bpm integrator (``begin_step``) or the
        ``timestep`` parameter.  Missing, it raises where it is needed: by
        history (the model's or a fix's ``needs_timestep``) in an advancing
        evaluation, and by a fix that follows the clock (``needs_time``:
        time = step * timestep) once the clock has started.
        """
        history, clocks = self._timed_pieces()
        if not history and not clocks:
            return None
        timestep = self.parameters.get("timestep") or self._integrator_dt
        if timestep is None:
            needing = ((history if advancing else [])
                       + (clocks if advancing or step > 0 else []))
            if needing:
                raise ValueError(f"{needing[0]} needs the MD timestep: pass timestep= (the "
                                 "integrator's dt) to the calculator, or run it with an "
                                 "ase_bpm integrator (ase_bpm.VelocityVerlet)")
            return None
        return float(timestep)

    def _timed_pieces(self) -> tuple:
        """``(history, clocks)``: the names of what needs the timestep in a step
        (the model, fixes with ``needs_timestep``) and of the fixes that follow
        the clock (``needs_time``); worked out again when the fixes change."""
        key = (tuple(map(id, self.fixes)), self.needs_timestep)
        if self._timed[0] != key:
            history = [type(f).__name__ for f in self.fixes
                       if getattr(f, "needs_timestep", False)]
            if self.needs_timestep:
                history.insert(0, f"the model of {type(self).__name__}")
            clocks = [type(f).__name__ for f in self.fixes if getattr(f, "needs_time", False)]
            self._timed = (key, (history, clocks))
        return self._timed[1]

    def _add_fixes(self, atoms: Atoms, ev: Evaluation, step: int, timestep) -> None:
        """Forces (torques, state) of the external pieces, at time step * timestep.

        A piece either has ``contribute(atoms, clock) -> Contribution`` or the
        simple ``forces(atoms, time) -> (f_nc, energy)`` (see
        :mod:`ase_bpm.scene.fixes`).  Pieces next to each other with the same
        ``together_key`` (walls of one law) contribute in one call of their
        ``contribute_together(pieces, atoms, clock)``.
        """
        if not self.fixes:
            return
        time = step * timestep if timestep is not None else 0.0
        clock = Clock(step=step, time=time, timestep=timestep, advancing=self.advancing,
                      inputs=self.inputs)
        for group in _together(self.fixes):
            fix = group[0]
            clock.into = (ev.forces, ev.f_damp, ev.torques)
            if len(group) > 1:
                part = fix.contribute_together(group, atoms, clock)
            elif hasattr(fix, "contribute"):
                part = fix.contribute(atoms, clock)
            else:
                part = Contribution(*fix.forces(atoms, time))
            _add(ev, part)
            ev.touching = ev.touching or (part.energy != 0.0 and hasattr(fix, "springs"))
            for name in part.arrays:
                if name in ev.fix_arrays:
                    raise state_taken(name)
            ev.fix_arrays.update(part.arrays)

    def _fixes_digest(self) -> str:
        """Digest of the fixes' parameters, recomputed only when they change."""
        if not self.fixes:
            return ""
        described = [fix.todict() for fix in self.fixes]
        if described != self._fixes_described[0]:
            self._fixes_described = (described, digest(described))
        return self._fixes_described[1]

    def check_timestep(self, atoms: Atoms, timestep: float) -> None:
        """Raise if the atoms moved since the last evaluation as a velocity
        Verlet step of a different length than ``timestep``.

        Under velocity Verlet the displacement of every atom is the timestep
        times the velocity the atoms carry at evaluation; other motion
        (thermostats, moved by hand) cannot be judged and passes.
        """
        t = self._drift_time(atoms)
        if t is not None and abs(t - timestep) > DRIFT_PRECISION * abs(timestep):
            given = ("the calculator was given timestep=" if self.parameters.get("timestep")
                     else "the clock runs on the timestep an ase_bpm integrator announced, ")
            raise ValueError(f"timestep mismatch: {given}{timestep:.6g}, but the atoms moved "
                             f"as a velocity Verlet step of {t:.6g}; pass the integrator's "
                             "timestep (timestep= to the calculator)")

    @staticmethod
    def _drift_time(atoms: Atoms) -> Optional[float]:
        """The timestep of the drift since the last evaluation, if the atoms
        moved as under velocity Verlet (every displacement the timestep times
        the velocity the atoms carry now); None for other motion (thermostats,
        moved by hand) or none."""
        x_last = atoms.arrays.get(X_LAST)
        if x_last is None or x_last.shape != atoms.positions.shape:
            return None
        dx = minimum_image(atoms.positions - x_last, atoms.cell, atoms.pbc)
        if not dx.any():  # nothing moved (calc.step at a relaxed state): no step to judge
            return None
        v = atoms.get_velocities()
        vv = float(np.einsum("nc,nc->", v, v))
        if vv == 0.0:
            return None
        t = float(np.einsum("nc,nc->", dx, v)) / vv
        slack = (DRIFT_RESIDUAL * np.abs(dx).max()
                 + POSITION_ROUNDOFF * np.abs(atoms.positions).max())
        ballistic = np.abs(dx - t * v).max() <= slack
        return t if ballistic else None

    def _guard(self, atoms: Atoms, ev: Evaluation, step: int, timestep) -> None:
        """Raise :class:`UnstableSimulationError` if the evaluation's forces,
        torques or energies are not finite (one pass over each when all is
        well) or, in a step, if the timestep is beyond the stable one
        (:meth:`_beyond_limit`, which also warns above the estimate), the
        kinetic energy runs away (:meth:`_runaway`) or the step's ledger is
        out of proportion (:meth:`_unbalanced`).  With ``guard`` off none of
        these is checked and no timestep warning given; evaluations that look
        like an optimiser's are watched either way (:meth:`_still`)."""
        if self.guard:
            for quantity, values in (("force", ev.forces), ("torque", ev.torques)):
                atom = None if values is None else first_non_finite(values)
                if atom is not None:
                    self._unstable(atoms, step, timestep, f"the {quantity} on particle "
                                   f"{atom} is {values[atom]}: the simulation blew up")
            for quantity, value in (("energy", ev.energy),
                                    ("energy of the bonds broken", ev.released_energy)):
                if not math.isfinite(value):
                    self._unstable(atoms, step, timestep,
                                   f"the {quantity} is {value}: the simulation blew up")
        if self.pure_mode:
            return
        # an integrator that announces its steps moves the atoms as MD does
        watches_still = not self._announced
        checks = self.guard and self.advancing
        if not (checks or watches_still):
            return
        watch = self._watch_of(atoms)
        p_nc = atoms.arrays.get("momenta")  # p . v: atoms held by FixAtoms have v = 0
        kinetic = 0.0 if p_nc is None else 0.5 * dot_sum(p_nc, self.inputs.velocities())
        if watches_still:
            self._still(atoms, watch, ev, kinetic)
        if not checks:
            return
        if not self._quasi_static:
            self._beyond_limit(atoms, watch, step, ev.touching)
        self._runaway(atoms, watch, step, timestep, kinetic)
        self._unbalanced(atoms, watch, ev, step, timestep, kinetic)

    def _still(self, atoms: Atoms, watch: "GuardWatch", ev: Evaluation,
               kinetic: float) -> None:
        """Is this an evaluation at new positions that finds the momenta as
        the last evaluation of these atoms left them, while forces act on
        particles free to move, and the atoms did not drift with their
        velocities?  That is how ASE's optimisers and ``ase.vibrations``
        probe positions; under an integrator the forces change the momenta
        (where forces of round-off size do not, as on a body translating
        freely, the atoms moved as a velocity Verlet drift).  ``STILL_STEPS``
        of them in a row warn once per calculator
        (:class:`OptimiserStepWarning`); fewer are a body moved into place by
        hand, or the first step of ASE's Langevin.  The momenta are compared
        through the kinetic energy the guard works out anyway, exactly."""
        before, watch.momenta = watch.momenta, kinetic
        watch.same_momenta = before == kinetic
        still = (self.advancing and watch.same_momenta and self._forces_act(ev)
                 and self._drift_time(atoms) is None)
        watch.still = watch.still + 1 if still else 0
        if watch.still >= STILL_STEPS and not self._still_warned:
            self._still_warned = True
            warnings.warn(
                f"{type(self).__name__}: {watch.still} evaluations in a row at new positions "
                "found the momenta unchanged while forces act, as under an optimiser (BFGS, "
                "FIRE, ...) or ase.vibrations: each evaluation at new positions is an MD step "
                "(bonds past their criterion break, history advances, the step counter "
                "moves); evaluate such probes inside `with ase_bpm.pure(atoms):`",
                OptimiserStepWarning, stacklevel=outside_stacklevel())

    def _forces_act(self, ev: Evaluation) -> bool:
        """Does a force act on a particle free to move (not held by FixAtoms)?"""
        hold = self.inputs.frozen()
        return any_nonzero(ev.forces if hold is None else ev.forces[~hold])

    def _watch_of(self, atoms: Atoms) -> "GuardWatch":
        """What the guard remembers of the steps of ``atoms`` (one record per
        atoms object this calculator steps, so alternating objects do not
        reset each other's)."""
        watch = self._watched.get(id(atoms))
        if watch is None or watch.atoms() is not atoms:
            if len(self._watched) >= 8:  # drop the records of atoms objects gone
                self._watched = {k: w for k, w in self._watched.items()
                                 if w.atoms() is not None}
            watch = self._watched[id(atoms)] = GuardWatch(weakref.ref(atoms))
        return watch

    def _given_timestep(self) -> Optional[float]:
        """The timestep of this step as given: the ``timestep`` parameter, or
        the one an ase_bpm integrator announced for this very step."""
        given = self.parameters.get("timestep")
        if given:
            return float(given)
        return self._integrator_dt if self._announced else None

    def _beyond_limit(self, atoms: Atoms, watch: "GuardWatch", step: int,
                      touching: bool = False) -> None:
        """Raise if the timestep is more than ``BEYOND_LIMIT`` times
        :meth:`stable_timestep`, and warn once per calculator and timestep
        (:class:`TimestepWarning`) if it is more than the estimate.

        Checked at the first step this calculator makes on ``atoms`` with a
        timestep it can tell, every ``STABILITY_EVERY`` steps, when the
        timestep changes (a given one: the parameter, an ase_bpm
        integrator's; under ASE's own integrators, the velocity Verlet
        drift's, told by one particle each step: :meth:`_drift_changed`),
        after :meth:`set` or :meth:`refresh`, and, where nothing acted at the
        last check (the estimate was inf), as soon as something does
        (``touching``: spheres that come to touch).  Not in a quasi-static
        :meth:`step`.

        The first check takes its estimate from :meth:`_first_estimate` and
        warns only above the one at the run's first state; later checks take
        it at the step's positions.  The estimate lies between a third of the true
        limit and the limit (tests/test_stable_timestep.py), so no stable run
        is stopped.  A run whose timestep cannot be told (thermostats) is not
        checked; it is said so once (:meth:`_untold`).
        """
        dt = given = self._given_timestep()
        due = (watch.limit is None or not 0 <= step - watch.limit[0] < STABILITY_EVERY
               or (watch.idle and touching))
        drifted = None  # the timestep of a velocity Verlet drift, where worked out
        if given is None:  # told by the drift (ASE's integrators)
            if not (due or self._drift_changed(atoms, watch)):
                return
            dt = drifted = self._drift_time(atoms)
            if dt is None:
                self._untold(atoms, watch, step)
                return
            if not due and abs(dt - watch.limit[1]) <= DRIFT_PRECISION * dt:
                return  # the same timestep after all (a particle crossed a periodic face)
        elif not due and watch.limit[1] == dt:
            return
        watch.untold = 0
        if watch.limit is None:  # the run's first check
            at, estimate, atom, asked = self._first_estimate(atoms, watch, step, drifted)
        else:
            at, (estimate, atom), asked = step, self._estimate(atoms), None
        if estimate is None:
            return
        ratio = dt / estimate
        where = self._estimated(atoms, at)
        if ratio > BEYOND_LIMIT:
            self._unstable(atoms, step, dt,
                           f"the timestep is {ratio:.3g} times the stable timestep "
                           f"{estimate:.6g} {where} (the stiffest particle is {atom}), more "
                           f"than {BEYOND_LIMIT:g} times: velocity Verlet is unstable there",
                           estimate, at, advise=False)
        watch.limit = (step, dt)  # passed: checked again when due or dt changes
        watch.idle = math.isinf(estimate)  # then again when contacts form
        watch.probe = self._fastest() if given is None else None
        shown = f"{dt:.6g}"  # (a drift's timestep varies in its last digits)
        above = ratio > 1.0 + DRIFT_PRECISION and not (
            asked is not None and dt <= asked * (1.0 + DRIFT_PRECISION))
        if above and shown not in self._timesteps_warned:
            self._timesteps_warned.add(shown)
            warnings.warn(
                f"{type(self).__name__}: the timestep {shown} is {ratio:.3g} times "
                f"stable_timestep(atoms), {estimate:.6g} {where} (the stiffest particle is "
                f"{atom}): above the estimate velocity Verlet is unstable for the stiffest "
                "motions, which can break bonds or heat contacts, slowly or fast, before "
                f"anything blows up (the guard stops a run only above {BEYOND_LIMIT:g} times "
                "it); use a timestep at most the estimate",
                TimestepWarning, stacklevel=outside_stacklevel())

    def _first_estimate(self, atoms: Atoms, watch: "GuardWatch", step: int,
                        drifted: Optional[float]) -> tuple:
        """``(at, estimate, atom, asked)`` for a run's first check: the estimate
        at the state the step started from (step ``at``; there
        ``stable_timestep(atoms)`` was asked before the run: ``asked``, kept
        in ``watch.first``) and, where the atoms did not drift there as
        velocity Verlet moves them (``drifted``, the drift's timestep if
        worked out already: None looks), the one where they are if that is
        less (pressed by hand, a thermostat), with its stiffest atom."""
        at = step - 1
        estimate, atom = self._estimate(atoms, atoms.arrays[X_LAST])
        asked = estimate
        if watch.first is None and estimate is not None:
            watch.first = (at, estimate)
        if drifted is None:
            drifted = self._drift_time(atoms)
        if drifted is None:
            now, atom_now = self._estimate(atoms)
            if now is not None and (estimate is None or now < estimate):
                at, estimate, atom = step, now, atom_now
        return at, estimate, atom, asked

    def _fastest(self) -> int:
        """The particle of the evaluation's largest speed."""
        v_nc = self.inputs.velocities()
        return int(np.argmax(np.einsum("nc,nc->n", v_nc, v_nc)))

    def _drift_changed(self, atoms: Atoms, watch: "GuardWatch") -> bool:
        """Has the timestep of the velocity Verlet drift changed since the last
        check (a new integrator on the same atoms)?  Told by one particle, the
        fastest at that check (``watch.probe``): its displacement is the
        timestep times its velocity.  Round-off aside, a thermostat or a hand
        also make it differ: then the whole drift is looked at."""
        k = watch.probe
        if k is None:
            return False
        x_last = atoms.arrays.get(X_LAST)
        if x_last is None or k >= len(x_last):
            return True
        x_c = atoms.positions[k]
        v_c = self.inputs.velocities()[k]
        vv = float(v_c @ v_c)
        if vv == 0.0:
            return True
        told = watch.limit[1]
        t = float((x_c - x_last[k]) @ v_c) / vv
        slack = (DRIFT_PRECISION * told
                 + POSITION_ROUNDOFF * float(np.abs(x_c).max()) / math.sqrt(vv))
        return abs(t - told) > slack

    def _untold(self, atoms: Atoms, watch: "GuardWatch", step: int) -> None:
        """A step whose timestep cannot be told: neither given nor that of a
        velocity Verlet drift.  ``UNTOLD_STEPS`` of them in a row, each with
        the momenta changed (a thermostat, such as ASE's ``Langevin``), warn
        once per calculator (:class:`TimestepUncheckedWarning`).  Not
        counted: a quasi-static ``calc.step``, and atoms moved with their
        momenta kept (by hand, or by an optimiser: :class:`OptimiserStepWarning`
        is for those, see :meth:`_still`)."""
        if self._announced or watch.same_momenta:
            watch.untold = 0
            return
        watch.untold += 1
        if watch.untold < UNTOLD_STEPS or self._untold_warned:
            return
        self._untold_warned = True
        estimate = self._estimate(atoms)[0]
        now = "" if estimate is None else f" ({estimate:.6g} at step {step}'s positions)"
        warnings.warn(
            f"{type(self).__name__}: in {watch.untold} steps in a row the atoms did not move "
            "as a velocity Verlet drift (a thermostat such as ASE's Langevin, or atoms moved "
            "by hand), so the timestep cannot be told and is not checked against "
            f"stable_timestep(atoms){now}: pass timestep= (the integrator's dt) to the "
            "calculator to have it checked", TimestepUncheckedWarning,
            stacklevel=outside_stacklevel())

    def _estimated(self, atoms: Atoms, at: int) -> str:
        """Which state an estimate at step ``at`` is for, with the estimate at
        the run's first state (``GuardWatch.first``) where that is another."""
        watch = self._watched.get(id(atoms))
        first = watch.first if watch is not None and watch.atoms() is atoms else None
        where = f"at step {at}'s positions"
        if first is None:
            return where
        if first[0] == at:
            return f"{where}, the run's first state"
        if math.isinf(first[1]):  # nothing acted then
            return where
        return f"{where} ({first[1]:.6g} at the run's first state, step {first[0]})"

    def _runaway(self, atoms: Atoms, watch: "GuardWatch", step: int, timestep,
                 kinetic: float) -> None:
        """Raise if the kinetic energy grew more than ``RUNAWAY_FACTOR``-fold in
        each of the last ``RUNAWAY_STEPS`` steps.

        Velocity Verlet beyond its stable timestep multiplies the energy of the
        unstable modes every step (at 1.17 times the limit by 10, at 1.33 times
        by 24), while what fixes and thermostats bring in grows slower: from
        rest, a kinetic energy growing as t^p grows 10-fold in each of steps 2
        to 5 only for p > 10.  The kinetic energy is that of the velocities
        the forces are evaluated with (half-step ones under velocity Verlet).
        """
        grew = watch.kinetic_steps > 0 and kinetic > RUNAWAY_FACTOR * watch.kinetic
        streak = watch.streak + 1 if grew else 0
        if streak >= RUNAWAY_STEPS:
            watch.forget()
            atom = self._fastest()
            v_nc = self.inputs.velocities()
            self._unstable(atoms, step, timestep,
                           f"the kinetic energy grew more than {RUNAWAY_FACTOR:g}-fold in "
                           f"each of the last {RUNAWAY_STEPS} steps, to {kinetic:.6g}; the "
                           f"fastest particle is {atom}, at speed "
                           f"{float(np.linalg.norm(v_nc[atom])):.6g}: the simulation is "
                           "blowing up")
        watch.kinetic, watch.streak = kinetic, streak
        watch.kinetic_steps += 1

    def _unbalanced(self, atoms: Atoms, watch: "GuardWatch", ev: Evaluation, step: int,
                    timestep, kinetic: float) -> None:
        """Raise if the energy one step books as dissipated or released is out
        of all proportion with the energy in play.

        The ledger of one step: kinetic plus potential energy now, minus
        before, plus what damping took and broken bonds released in the step.
        Velocity Verlet keeps it near zero well below the stable timestep, and
        what a fix, a thermostat or a breaking bond brings in during one step
        ends up in the kinetic and potential energy of the two steps, the
        energy in play.  So the ledger can be off by more than
        ``LEDGER_FACTOR`` times that only through the damping work or the
        energy of broken bonds booked in the step: damping or bond breaking
        driven by a blow-up (energy made from nothing in motion is the
        runaway check's).  Only steps that moved the atoms as velocity Verlet
        does are judged: atoms moved by hand or by a thermostat take energy
        from outside.
        """
        total = kinetic + float(ev.energy)
        in_play = kinetic + abs(float(ev.energy))
        before, before_in_play, seen = watch.total, watch.in_play, watch.balanced
        watch.total, watch.in_play, watch.balanced = total, in_play, True
        if not seen:
            return
        off = total - before + ev.dissipated + ev.released_energy
        if (abs(off) > LEDGER_FACTOR * (in_play + before_in_play)
                and self._drift_time(atoms) is not None):
            watch.forget()
            self._unstable(atoms, step, timestep,
                           f"the energy ledger is off by {off:.6g} in this step, more than "
                           f"{LEDGER_FACTOR:g} times the energy in play "
                           f"({in_play + before_in_play:.6g}: kinetic and potential, now "
                           "and before): the simulation blew up")

    def _non_finite_positions(self, atoms: Atoms) -> None:
        """Positions that are not finite: a blow-up when the last recorded
        evaluation of these atoms had finite ones, else bad input."""
        Inputs(atoms).masses()  # a mass that is not positive: the culprit, not the positions
        try:
            require_finite("position", atoms.positions)
        except ValueError as exc:
            x_last = atoms.arrays.get(X_LAST)
            if x_last is None or x_last.shape != atoms.positions.shape:
                raise
            self._unstable(atoms, int(atoms.info.get(STEP, 0)) + 1,
                           self.parameters.get("timestep") or self._integrator_dt, str(exc))

    def _estimate(self, atoms: Atoms, positions: Optional[np.ndarray] = None) -> tuple:
        """``(stable_timestep, stiffest atom)``, or ``(None, None)`` where there
        is no estimate: a model without one, or a state beyond estimating.
        With ``positions``, at those instead of the atoms' own (the record's:
        the state a step started from), everything else as it is now."""
        own = atoms.arrays["positions"]
        if positions is not None:
            atoms.arrays["positions"] = positions
        try:
            return self._stiffest(atoms)
        except (NotImplementedError, ArithmeticError, np.linalg.LinAlgError):
            return None, None
        finally:
            atoms.arrays["positions"] = own

    def _unstable(self, atoms: Atoms, step: int, timestep, what: str,
                  estimate: Optional[float] = None, at: Optional[int] = None,
                  advise: bool = True) -> None:
        """Raise :class:`UnstableSimulationError` for ``what`` at ``step``, with
        the stable timestep (``estimate`` at step ``at``'s positions, worked
        out here at ``step``'s if not given; not again where ``what`` gives
        it: ``advise=False``)."""
        if estimate is None and advise:
            estimate, at = self._estimate(atoms)[0], step
        advice = ("" if estimate is None or not advise else "; stable_timestep(atoms) "
                  f"suggests at most {estimate:.6g} {self._estimated(atoms, at)}")
        if timestep is None:
            timestep = self._given_timestep() or self._drift_time(atoms)
        used = "" if timestep is None else f" (timestep {timestep:.6g})"
        raise UnstableSimulationError(f"step {step}{used}: {what}; nothing of this step "
                                      f"was written{advice}{RUN_AGAIN}")

    def _restore(self, atoms: Atoms) -> None:
        """Results of the recorded last evaluation at this very configuration."""
        self.results = {"forces": atoms.arrays[F_LAST].copy(),
                        "energy": float(atoms.info[ENERGY])}
        self.results["free_energy"] = self.results["energy"]
        torques = atoms.arrays.get(T_LAST)
        self.results["torques"] = (torques.copy() if torques is not None
                                   else np.zeros((len(atoms), 3)))
        if STRESS in atoms.info:
            self.results["stress"] = np.array(atoms.info[STRESS], dtype=float)
        self._ledger_results(atoms)

    def _late_stress(self, atoms: Atoms) -> None:
        """Stress asked for after the evaluation at this configuration: from
        that evaluation's pairs if this calculator made it, else from a fresh
        (pure) evaluation whose forces are not used."""
        virial_of = self._virial_later
        if virial_of is None:
            virial_of = self._evaluate(atoms).virial
        self._set_stress(atoms, virial_of)

    @staticmethod
    def _stress(atoms: Atoms, virial) -> np.ndarray:
        """Stress from a virial (or a function giving it), Voigt order xx yy zz
        yz xz xy from the upper triangle, as LAMMPS tallies it (the contact
        virial of frictional spheres is not symmetric)."""
        s_cc = (virial() if callable(virial) else virial) / atoms.get_volume()
        return np.array([s_cc[0, 0], s_cc[1, 1], s_cc[2, 2], s_cc[1, 2], s_cc[0, 2],
                         s_cc[0, 1]])

    def _set_stress(self, atoms: Atoms, w_cc) -> None:
        stress = self._stress(atoms, w_cc)
        self.results["stress"] = stress
        atoms.info[STRESS] = stress.copy()

    def _dissipated(self, atoms: Atoms, ev: Evaluation, first: bool, timestep) -> float:
        """Energy the damping forces and torques took in the step that led
        here: their trapezoidal work (0 at a first evaluation)."""
        if first:
            return 0.0
        arrays, dissipated = atoms.arrays, 0.0
        if ev.f_damp is not None or FD_LAST in arrays:
            dx_nc = minimum_image(atoms.positions - arrays[X_LAST], atoms.cell, atoms.pbc)
            dissipated -= 0.5 * (_work(ev.f_damp, dx_nc) + _work(arrays.get(FD_LAST), dx_nc))
        dt = timestep if timestep is not None else self._integrator_dt
        if (dt is not None and "omega" in arrays
                and (ev.torques is not None or T_LAST in arrays)):
            # the same for torques: the spheres turned by omega dt in the step
            w_nc = arrays["omega"]
            dissipated -= 0.5 * dt * (_work(ev.torques, w_nc) + _work(arrays.get(T_LAST), w_nc))
        return dissipated

    def _record(self, atoms: Atoms, ev: Evaluation, step: int, first: bool,
                wants_stress: bool = True, timestep=None) -> None:
        """Update step, ledger and the record of this evaluation; set results."""
        info, arrays = atoms.info, atoms.arrays
        info[STEP] = step
        written = arrays.get(ID)
        if written is None or written is not self._ids_written:  # else complete already
            ids = id_words(atoms)
            if arrays.get(ID) is not ids:
                arrays[ID] = ids
            self._ids_written = ids
        info[RECORD_IDS] = self._ids_checksum(atoms)
        for name, values in ev.fix_arrays.items():
            if values is None:  # the fix keeps no such state (any more)
                arrays.pop(name, None)
            else:
                arrays[name] = values
        info[DISSIPATED] = float(info.get(DISSIPATED, 0.0)) + ev.dissipated
        info[BROKEN_ENERGY] = float(info.get(BROKEN_ENERGY, 0.0)) + ev.released_energy
        info[ENERGY] = float(ev.energy)
        info[SIGNATURE] = self._signature(atoms, ev)
        arrays[X_LAST] = atoms.positions.copy()
        arrays[X_LAST].flags.writeable = False  # also what check_state compares with
        arrays[F_LAST] = ev.forces  # shared with results: ASE hands out copies
        if ev.f_damp is not None:
            arrays[FD_LAST] = ev.f_damp
        else:
            arrays.pop(FD_LAST, None)
        if ev.torques is not None:
            arrays[T_LAST] = ev.torques
        else:
            arrays.pop(T_LAST, None)

        self.results = self._results_of(ev, len(atoms))
        info.pop(STRESS, None)
        self._virial_later = None
        if ev.virial is not None and atoms.pbc.all():
            if wants_stress:  # else computed only if asked for (see _late_stress)
                self._set_stress(atoms, ev.virial)
            else:
                self._virial_later = ev.virial
        self._ledger_results(atoms)

    def _results_of(self, ev: Evaluation, natoms: int) -> dict:
        """The ASE results of an evaluation: energy, forces, torques."""
        return {"energy": float(ev.energy), "free_energy": float(ev.energy),
                "forces": ev.forces, "torques": self._torques(ev, natoms)}

    def _torques(self, ev: Evaluation, natoms: int) -> np.ndarray:
        """The evaluation's torques, or zeros (one read-only array, kept: ASE
        hands out copies of results)."""
        if ev.torques is not None:
            return ev.torques
        zeros = self._no_torques
        if zeros is None or len(zeros) != natoms:
            zeros = self._no_torques = np.zeros((natoms, 3))
            zeros.flags.writeable = False
        return zeros

    def _ledger_results(self, atoms: Atoms) -> None:
        self.results["dissipated_energy"] = float(atoms.info.get(DISSIPATED, 0.0))
        self.results["broken_bond_energy"] = float(atoms.info.get(BROKEN_ENERGY, 0.0))
        self.results["step"] = int(atoms.info.get(STEP, 0))

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
        kept = self.inputs
        self.inputs = Inputs(atoms)  # the model's readers take the inputs from here
        try:
            springs = list(self._springs(atoms))
            if self.fixes:
                step = int(atoms.info.get(STEP, 0))
                timestep = self._timestep(False, step)
                clock = Clock(step=step, time=step * timestep if timestep is not None else 0.0,
                              timestep=timestep, advancing=False, inputs=self.inputs)
                springs += [fix.springs(atoms, clock) for fix in self.fixes
                            if hasattr(fix, "springs")]
            springs = [s for s in springs if s is not None and len(s)]
            inertia_n = None
            if any(s.turning for s in springs):
                inertia_n = SOLID_SPHERE * m_n * self.inputs.radii("stable_timestep") ** 2
            return stability.stiffest(springs, m_n, inertia_n, self.inputs.frozen())
        finally:
            self.inputs = kept

    def _springs(self, atoms: Atoms) -> list:
        """The model's bonds and contacts acting now, as
        :class:`ase_bpm.laws.timestep.Springs` (read from the atoms and
        ``self.inputs``, nothing written)."""
        return self.model.springs(atoms, self._context(atoms, advancing=False))

    # -- the model: what the calculator asks of it -------------------------------
    def _context(self, atoms: Atoms, step: Optional[int] = None,
                 advancing: Optional[bool] = None) -> Context:
        """The evaluation under way as the model is told it: ``advancing``
        (default ``self.advancing``), pure or not, ``step`` (default the
        recorded step, plus one in a step), the timestep where the model uses
        it, the checked inputs, the parameters and the fixes."""
        if advancing is None:
            advancing = self.advancing
        if step is None:
            step = int(atoms.info.get(STEP, 0)) + (1 if advancing else 0)
        timestep = self._timestep(advancing, step) if self.model.needs_timestep else None
        return Context(advancing=advancing, pure=self.pure_mode, step=step, timestep=timestep,
                       inputs=self.inputs, parameters=self.parameters, fixes=tuple(self.fixes))

    #: the context of the last evaluation (:meth:`_evaluate`), which its commit reuses
    _evaluating: Optional[Context] = None

    def _evaluate(self, atoms: Atoms) -> Evaluation:
        """Forces and energy from the model, touching nothing on the atoms."""
        self._evaluating = ctx = self._context(atoms)
        return self.model.evaluate(atoms, ctx)

    def _commit(self, atoms: Atoms, evaluation: Evaluation, step: int) -> None:
        """Write model state (broken bonds, reference lengths, outputs)."""
        ctx = self._evaluating
        if ctx is None or ctx.step != step:  # (else the evaluation's own)
            ctx = self._context(atoms, step)
        self.model.commit(atoms, evaluation, ctx)

    def _signature(self, atoms: Atoms, evaluation: Optional[Evaluation]) -> str:
        """What the forces depend on besides positions and velocities: the
        parameters, the fixes and the model's parts (types, bonds...).  With
        ``evaluation``, of the state that evaluation left on the atoms (after
        its commit)."""
        return self.signature_of(*self.model.signature_parts(atoms, evaluation))

    def signature_of(self, *parts) -> str:
        """The signature of the parameters, the fixes and ``parts`` (digests
        and fingerprints of what else the forces depend on)."""
        key = (self._param_digest, self._fixes_digest(), *parts)
        if self._signature_cache[0] != key:
            self._signature_cache = (key, digest(*key))
        return self._signature_cache[1]
