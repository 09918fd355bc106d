"""What one evaluation is, and its stages in one fixed order.

:func:`run` is the body of ``BPMCalculator.calculate``.  It decides what the
evaluation is:

* **pure** (inside :func:`ase_bpm.pure`): forces and energy at these
  positions and velocities; nothing written, nothing advanced;
* **first**: no record on the atoms holds for them (none yet, or atoms were
  deleted, added or combined since): nothing breaks, no step is counted;
* **same place**: at the recorded positions, no step announced: the record's
  results when its signature still holds, else a **re-evaluation**
  (``refresh``, parameters or bonds changed) that is not a step;
* **step**: new positions, or a step an integrator announced (a scene at rest
  still ages): bonds may break, history advances, the step counter moves.

It then runs the stages, each skipped where it has nothing to do: the model's
evaluation (``calc.model.evaluate``), the fixes (:func:`add_fixes`), the ledger
(:func:`.ledger.dissipated`), the guard (:class:`.guard.Guard`), the model's
commit (``calc.model.commit``), the record (:class:`.record.Record`, then
:func:`.ledger.book`) and the spin watch (:class:`SpinWatch`).  Nothing on the
atoms is written before the commit: a raise leaves them as they were (and
leaves no :class:`Seen`: the next evaluation looks afresh).

The **ordinary step** is a step of atoms as the last evaluation left them
but for their positions and velocities (:meth:`Seen.continued_by`: the
record, the IDs and the model's state the very objects it left, the inputs
it takes from that evaluation the same values): it takes the record as
holding, the checked inputs that keep their values (masses, types, radii)
and the model's signature digests of its unchanged arrays from that
evaluation; everything else is read as in any step.
"""

from __future__ import annotations

import warnings
from functools import partial
from typing import Optional

from ase import Atoms
from ase.calculators.calculator import all_changes

from ..core.arrays import Inputs, all_finite, any_nonzero, same_array
from ..core.bonds import ID
from ..core.params import outside_stacklevel
from ..core.spheres import OMEGA, frozen
from . import ledger
from .evaluation import Clock, Context, Contribution, Evaluation
from .record import F_LAST, RECORD_IDS, SIGNATURE, STEP, X_LAST, digest, stress_of


class SpinNotIntegratedWarning(UserWarning):
    """Torques act on spheres whose angular velocities nothing integrates
    (an integrator that moves and kicks but does not turn them)."""


def run(calc, atoms: Optional[Atoms] = None, properties=("energy",),
        system_changes=tuple(all_changes)) -> None:
    """Evaluate ``atoms`` (default: ``calc.atoms``) for ``calc`` (a
    ``BPMCalculator``) as what the evaluation is (see the module doc), and
    set ``calc.results``: ``BPMCalculator.calculate``.  ``system_changes``
    (ASE's) is not needed: what changed is told from the record."""
    if atoms is None:
        atoms = calc.atoms
    positions = atoms.positions
    if not all_finite(positions):
        calc._guard.non_finite_positions(
            atoms, calc.parameters.get("timestep") or calc._integrator_dt, calc._stiffest)
    plan = plan_of(calc)
    pure = calc._pure.depth > 0
    if plan.removes_atoms and not pure:
        calc._remove_lost_atoms(atoms)
        positions = atoms.positions
    seen = calc._seen
    # the ordinary step: the atoms as the last evaluation left them, but for
    # their positions and velocities (see Seen.continued_by)
    continues = not (pure or calc._recompute) and seen is not None and seen.continued_by(
        atoms, plan)
    # (set again when this evaluation is done: one that raises leaves none, and
    # the next looks afresh, the model's state and inputs read again)
    calc._seen = None
    inputs = Inputs(atoms, seen.inputs if continues else None)  # checked, read once
    record = calc._record
    if pure:
        first = same_place = turned = advancing = False
        announced = calc._announced  # (the last step's: the guard's messages name its timestep)
    else:
        x_last = atoms.arrays.get(X_LAST)
        # the record holds for these atoms, whatever their order (not after
        # atoms were deleted, added or combined: then this is a first
        # evaluation); in the ordinary step it is the last evaluation's own
        first = not continues and (x_last is None or x_last.shape != positions.shape
                                   or not record.holds_for(atoms))
        # a step: bonds may break and history advances (not at the first
        # evaluation, nor again at the same configuration unless an
        # integrator announced a step: a scene at rest still ages)
        announced = calc._announced = calc._step_pending
        same_place = not (first or announced) and same_array(x_last, positions)
        turned = announced and calc._turning
        advancing = not (first or same_place)
        wants_stress = "stress" in properties and bool(atoms.pbc.all())
        if same_place and _record_holds(calc, atoms, plan, seen):
            calc.results = record.restore(atoms)
            ledger.ledger_results(calc.results, atoms.info)
            if wants_stress and "stress" not in calc.results:
                record.late_stress(atoms, calc.results, calc._evaluate_aside)
            calc._recompute = calc._step_pending = calc._turning = False
            calc._seen = Seen(atoms, atoms.arrays[X_LAST], calc.model, plan, inputs)
            return
    step = int(atoms.info.get(STEP, 0)) + advancing
    timestep = timestep_of(calc, advancing, step, plan) if plan.history or plan.clocks else None
    ctx = Context(advancing=advancing, pure=pure, step=step, timestep=timestep,
                  inputs=inputs, parameters=calc.parameters, fixes=calc.fixes,
                  continues=continues)
    if advancing and timestep is not None and not announced:  # (another integrator's step)
        calc._guard.check_timestep(atoms, timestep, bool(calc.parameters.get("timestep")))

    evaluation = calc.model.evaluate(atoms, ctx)
    evaluation.touching = evaluation.energy != 0.0
    if plan.groups:
        add_fixes(atoms, evaluation, ctx, plan.groups)
    if not (pure or first):
        evaluation.dissipated = ledger.dissipated(
            atoms, evaluation, timestep if timestep is not None else calc._integrator_dt)
    given = calc.parameters.get("timestep")
    calc._guard.check(atoms, evaluation, ctx, on=calc.guard, announced=announced,
                      quasi_static=calc._quasi_static, stiffest=calc._stiffest,
                      given=float(given) if given else calc._integrator_dt if announced
                      else None)
    if pure:
        calc.results = record.results_of(evaluation, len(atoms))
        if evaluation.virial is not None and atoms.pbc.all():
            calc.results["stress"] = stress_of(atoms, evaluation.virial)
        ledger.ledger_results(calc.results, atoms.info)
        calc._seen = Seen(atoms, None, calc.model)  # (no plan: never continued)
        return
    # nothing on the atoms has changed so far: now write it all
    calc.model.commit(atoms, evaluation, ctx)
    signature = (seen.signature if continues and evaluation.kept_state
                 else partial(calc._signature, plan=plan))
    calc.results = record.write(atoms, evaluation, step, signature, wants_stress)
    ledger.book(atoms, evaluation, calc.results)
    if calc._spin.last is not None or (plan.torques and not turned):  # (else nothing to watch)
        calc._spin.watch(calc, atoms, turned, advancing, plan.torques)
    # the step announced is taken; what it saw is noted for check_state and
    # the next step (in the ordinary step only the record and the model's
    # state are new: the rest is as it was)
    calc._recompute = calc._step_pending = calc._turning = False
    if continues:
        calc._seen = seen
        seen.positions = atoms.arrays[X_LAST]
        if not evaluation.kept_state:
            seen.state = calc.model.state_arrays()
        seen.ids, seen.ids_checksum = atoms.arrays.get(ID), atoms.info.get(RECORD_IDS)
        seen.signature = atoms.info[SIGNATURE]
        if not seen.inputs:  # (none read at the last look: a record restored)
            seen.inputs = inputs.kept()
    else:
        calc._seen = Seen(atoms, atoms.arrays[X_LAST], calc.model, plan, inputs)


class Seen:
    """What the last evaluation saw and left, for ``check_state`` and for
    telling the ordinary step (:meth:`continued_by`): copies of the atoms'
    numbers, cell, periodicity, watched arrays (the model's) and the other
    inputs an evaluation keeps (:data:`KEPT_INPUTS`: a copy costs less than
    comparing with the last one), the positions (``positions``: a copy the
    caller keeps unchanged, the record's, else a new copy), the model's state
    arrays as it left them (:meth:`Model.state_arrays`), the record's own
    objects on the atoms (ID array, its checksum, the signature), the
    calculator's :class:`Plan` and the inputs read (``inputs``: name ->
    checked value, for the next :class:`~ase_bpm.core.arrays.Inputs`)."""

    __slots__ = ("natoms", "positions", "numbers", "cell", "pbc", "watched", "kept",
                 "state", "ids", "ids_checksum", "signature", "plan", "inputs")

    def __init__(self, atoms: Atoms, positions, model, plan=None, inputs=None):
        arrays, info = atoms.arrays, atoms.info
        self.natoms = len(atoms)
        self.positions = arrays["positions"].copy() if positions is None else positions
        self.numbers = arrays["numbers"].copy()
        self.cell = atoms.cell.array.copy()
        self.pbc = atoms.pbc.copy()
        self.watched = _copies(arrays, model.watched_arrays)
        # (without a plan, never continued: no inputs to compare then)
        self.kept = [] if plan is None else _copies(arrays, plan.kept)
        self.state = model.state_arrays()
        self.ids, self.ids_checksum = arrays.get(ID), info.get(RECORD_IDS)
        self.signature = info.get(SIGNATURE)
        self.plan = plan
        #: the inputs read, by Inputs' names, as the next evaluation may take them
        self.inputs = None if inputs is None else inputs.kept()

    def continued_by(self, atoms: Atoms, plan) -> bool:
        """Is an evaluation of ``atoms`` with ``plan`` the ordinary step after
        this one: the record, the IDs and the model's state on the atoms the
        very objects it left, the plan the same, and the inputs that step
        takes from this one the same values: the numbers (masses come from
        them where no masses are given), the watched arrays (whose digests
        the model's signature takes) and :data:`KEPT_INPUTS`.  (The cell and
        the periodicity, the velocities, spins and constraints are read at
        every evaluation.)"""
        arrays, info = atoms.arrays, atoms.info
        if (self.natoms != len(atoms) or self.state is None or plan is not self.plan
                or arrays.get(X_LAST) is not self.positions or arrays.get(ID) is not self.ids
                or info.get(RECORD_IDS) is not self.ids_checksum
                or info.get(SIGNATURE) is not self.signature):
            return False
        for name, array in self.state.items():
            if arrays.get(name) is not array:
                return False
        return same_array(self.numbers, arrays["numbers"],
                          *zip(self.watched, map(arrays.get, plan.watched)),
                          *zip(self.kept, map(arrays.get, plan.kept)))


def _copies(arrays: dict, names) -> list:
    """Copies of the arrays ``names`` (None for one the atoms lack)."""
    return [None if arrays.get(name) is None else arrays[name].copy() for name in names]


#: inputs that ``Seen`` keeps copies of, besides the model's watched arrays,
#: so that an ordinary step takes the checked values of the last evaluation
#: (:meth:`ase_bpm.core.arrays.Inputs.kept`)
KEPT_INPUTS = ("masses", "type", "radius")


class Plan:
    """What the evaluations of one calculator take from its fixes and its
    model, worked out once while the fixes (the objects) and the parameters
    stay (:func:`plan_of`; ``refresh`` works it out again, for fixes changed
    in place)."""

    def __init__(self, calc, key: tuple):
        fixes, model = calc.fixes, calc.model
        self.key = key
        #: the fixes in groups of neighbours that contribute together (add_fixes)
        self.groups = _together(fixes)
        #: some fix removes atoms before a step (``lost_atoms``, LostAtoms)
        self.removes_atoms = any(getattr(fix, "lost_atoms", None) is not None for fix in fixes)
        #: the names of what needs the timestep in a step (the model, fixes
        #: with ``needs_timestep``) and of the fixes that follow the clock
        #: (``needs_time``): see timestep_of
        self.history = [type(f).__name__ for f in fixes if getattr(f, "needs_timestep", False)]
        if model.needs_timestep:
            self.history.insert(0, f"the model of {type(calc).__name__}")
        self.clocks = [type(f).__name__ for f in fixes if getattr(f, "needs_time", False)]
        #: an evaluation can give a torque (BPMCalculator.produces_torques)
        self.torques = model.own_torques or any(
            getattr(fix, "produces_torques", hasattr(fix, "contribute")) for fix in fixes)
        #: the digest of the fixes' parameters (for the signature)
        self.fixes_digest = digest([fix.todict() for fix in fixes]) if fixes else ""
        #: the model's watched arrays and the other inputs kept (see Seen)
        self.watched = model.watched_arrays
        self.kept = tuple(name for name in KEPT_INPUTS if name not in self.watched)


def plan_of(calc) -> Plan:
    """``calc``'s :class:`Plan`, worked out again when its fixes (the list's
    objects) or its parameters (their digest) changed."""
    plan, key = calc._plan, (calc._param_digest, *map(id, calc.fixes))
    if plan is None or plan.key != key:
        plan = calc._plan = Plan(calc, key)
    return plan


def timestep_of(calc, advancing: bool, step: int = 0, plan: Optional[Plan] = None):
    """The timestep of ``calc``'s evaluation where the model or a fix uses
    it (else None).

    It comes from an ase_bpm integrator (``begin_step``) or the
    ``timestep`` parameter.  Missing, it raises where it is needed: by
    history (the model's or a fix's ``needs_timestep``) in an advancing
    evaluation, and by a fix that follows the clock (``needs_time``:
    time = step * timestep) once the clock has started.  ``plan``: the
    calculator's :class:`Plan`, where worked out already.
    """
    plan = plan or plan_of(calc)
    if not plan.history and not plan.clocks:
        return None
    timestep = calc.parameters.get("timestep") or calc._integrator_dt
    if timestep is None:
        needing = ((plan.history if advancing else [])
                   + (plan.clocks if advancing or step > 0 else []))
        if needing:
            integrator = ("ase_bpm.SphereVelocityVerlet, which turns the spheres too"
                          if plan.torques else "ase_bpm.VelocityVerlet")
            raise ValueError(f"{needing[0]} needs the MD timestep: pass timestep= (the "
                             "integrator's dt) to the calculator, or run it with an "
                             f"ase_bpm integrator ({integrator})")
        return None
    return float(timestep)


def _record_holds(calc, atoms: Atoms, plan: Plan, seen: Optional["Seen"]) -> bool:
    """Do the record's results hold at these (recorded) positions: no
    refresh asked, the model's state on the atoms not replaced, and the
    signature unchanged?  (``plan``: the calculator's; ``seen``: what the
    last evaluation saw, None where none is known.)"""
    replaced = seen is not None and calc.model.state_replaced(atoms)
    return (not calc._recompute and not replaced and F_LAST in atoms.arrays
            and atoms.info.get(SIGNATURE) == calc._signature(atoms, None, plan))


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


def add_fixes(atoms: Atoms, ev: Evaluation, ctx: Context, groups: list) -> None:
    """Forces (torques, state) of the external pieces ``ctx.fixes``, at time
    step * timestep.

    A piece either has ``contribute(atoms, clock) -> Contribution`` or the
    simple ``forces(atoms, time) -> (f_nc, energy)`` (see
    :mod:`ase_bpm.scene.fixes`).  Pieces next to each other with the same
    ``together_key`` (walls of one law) contribute in one call of their
    ``contribute_together(pieces, atoms, clock)``: ``groups``, the fixes in
    those groups (:attr:`Plan.groups`).
    """
    clock = Clock.of(ctx)
    # (where the model's torques are partly elastic, the fixes' are all dissipative)
    elastic = None if ev.t_damp is None else ev.torques - ev.t_damp
    for group in groups:
        fix = group[0]
        clock.into = (ev.forces, ev.f_damp, ev.torques)
        if len(group) > 1:
            part = fix.contribute_together(group, atoms, clock)
        elif hasattr(fix, "contribute"):
            part = fix.contribute(atoms, clock)
        else:
            part = Contribution(*fix.forces(atoms, clock.time))
        _add(ev, part)
        ev.touching = ev.touching or (part.energy != 0.0 and hasattr(fix, "springs"))
        for name in part.arrays:
            if name in ev.fix_arrays:
                raise state_taken(name)
        ev.fix_arrays.update(part.arrays)
    if elastic is not None:
        ev.t_damp = ev.torques - elastic


class SpinWatch:
    """Whether the integrator turns the spheres torques act on."""

    def __init__(self):
        #: (omega, did a torque act) after the last evaluation that no turning
        #: integrator announced
        self.last = None
        self.warned = False

    def watch(self, calc, atoms: Atoms, turned: bool, advancing: bool,
              torques: bool) -> None:
        """Warn once (:class:`SpinNotIntegratedWarning`) where torques acted on
        spheres free to turn and, a step later, their angular velocities are
        the same: the integrator does not turn them (ASE's VelocityVerlet and
        Langevin move and kick only).  A step announced by an integrator that
        turns them (``begin_step(dt, turns=True)``) needs no watch;
        ``advancing``: the evaluation is a step; ``torques``: the calculator
        can give torques (``produces_torques``)."""
        if turned or self.warned or not torques:
            self.last = None
            return
        omega = atoms.arrays.get(OMEGA)
        if advancing and self.last is not None:
            before, acted = self.last
            if acted and same_array(before, omega):
                self.warned = True
                warnings.warn(
                    f"{type(calc).__name__}: torques act on the spheres but "
                    f'atoms.arrays["{OMEGA}"] did not change over the step: the integrator '
                    "does not turn them (ASE's VelocityVerlet and Langevin do not), so the "
                    "spheres never spin; use ase_bpm.SphereVelocityVerlet (LAMMPS fix "
                    "nve/sphere)", SpinNotIntegratedWarning, stacklevel=outside_stacklevel())
        torques = calc.results.get("torques")
        hold = frozen(atoms)
        acted = torques is not None and any_nonzero(torques if hold is None else torques[~hold])
        self.last = (None if omega is None else omega.copy(), acted)
