"""The blow-up guard: a run that blows up stops, naming why.

Every evaluation's forces, torques and energies are checked to be finite; in
an MD step also that the timestep is not beyond the stable one
(:meth:`Guard._beyond_limit`, which warns above the estimate), that the
kinetic energy does not run away (:meth:`Guard._runaway`) and that the step's
energy ledger is in proportion (:meth:`Guard._unbalanced`).  It also says
when the timestep cannot be checked (:class:`TimestepUncheckedWarning`) and
when evaluations look like an optimiser's (:class:`OptimiserStepWarning`).

A :class:`Guard` belongs to one calculator and remembers, per atoms object
(:class:`GuardWatch`), what it saw of their steps.  It is told everything
else: the atoms, the evaluation, its :class:`~.evaluation.Context`, the
timestep as given, and ``stiffest(atoms) -> (stable_timestep, atom)``, the
calculator's estimate.
"""

from __future__ import annotations

import math
import warnings
import weakref
from dataclasses import dataclass
from typing import Optional

import numpy as np
from ase import Atoms

from ..core.arrays import (Inputs, all_finite, any_nonzero, dot_sum, first_non_finite,
                           require_finite)
from ..core.neighbours import minimum_image
from ..core.spheres import OMEGA, RADIUS, spin_energy
from ..core.params import outside_stacklevel
from .evaluation import Context, Evaluation
from .record import STEP, X_LAST

#: the blow-up guard (Guard._runaway): a run stops when the kinetic
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


def drift_time(atoms: Atoms, v_nc: Optional[np.ndarray] = None) -> Optional[float]:
    """The timestep of the drift since the last evaluation, if the atoms
    moved as under velocity Verlet (every displacement the timestep times
    the velocity the atoms carry now: ``v_nc``, where worked out already,
    else ``atoms.get_velocities()``); None for other motion (thermostats,
    moved by hand) or none.  A few passes over the atoms, without BLAS."""
    x_last = atoms.arrays.get(X_LAST)
    x_nc = atoms.positions
    if x_last is None or x_last.shape != x_nc.shape:
        return None
    dx = x_nc - x_last
    if atoms.pbc.any():
        dx = minimum_image(dx, atoms.cell, atoms.pbc)
    if not any_nonzero(dx):  # nothing moved (calc.step at a relaxed state): no step to judge
        return None
    v = atoms.get_velocities() if v_nc is None else v_nc
    vv = dot_sum(v, v)
    if vv == 0.0:
        return None
    t = dot_sum(dx, v) / vv
    slack = (DRIFT_RESIDUAL * max(dx.max(), -dx.min())
             + POSITION_ROUNDOFF * max(x_nc.max(), -x_nc.min()))
    residual = t * v
    residual -= dx
    return t if max(residual.max(), -residual.min()) <= slack else None


def _fastest(inputs: Inputs) -> int:
    """The particle of the evaluation's largest speed."""
    v_nc = inputs.velocities
    return int(np.argmax(np.einsum("nc,nc->n", v_nc, v_nc)))


def _estimate(atoms: Atoms, stiffest, positions: Optional[np.ndarray] = None) -> tuple:
    """``(stable_timestep, stiffest atom)`` by ``stiffest(atoms)``, or
    ``(None, None)`` where there is no estimate: a model without one, or a
    state beyond estimating.  With ``positions``, at those instead of the
    atoms' own (the record's: the state a step started from), everything
    else as it is now."""
    own = atoms.arrays["positions"]
    if positions is not None:
        atoms.arrays["positions"] = positions
    try:
        return stiffest(atoms)
    except (NotImplementedError, ArithmeticError, np.linalg.LinAlgError):
        return None, None
    finally:
        atoms.arrays["positions"] = own


def _spin_energy(atoms: Atoms, ev: Evaluation, inputs) -> float:
    """The spheres' kinetic energy of rotation, ``sum I w^2 / 2``, where the
    evaluation has torques and the atoms spin (radii and ``omega``); else 0."""
    if ev.torques is None or OMEGA not in atoms.arrays or RADIUS not in atoms.arrays:
        return 0.0
    return spin_energy(inputs.masses, inputs.radii("the guard's energy ledger"), inputs.omega)


class Guard:
    """The blow-up guard of one calculator (``name``, its class's name, as
    the warnings say it): what it saw of the steps of each atoms object, and
    which warnings it gave."""

    def __init__(self, name: str):
        self.name = name
        self._watched = {}  # id(atoms) -> GuardWatch: what the guard saw of their steps
        self._timesteps_warned = set()  # the timesteps TimestepWarning named (as shown)
        self._untold_warned = False  # TimestepUncheckedWarning given
        self._still_warned = False  # OptimiserStepWarning given

    def check_again(self) -> None:
        """Have the next step of every atoms object check its timestep as a
        run's first does, and warn of any timestep again (the physics, or
        what is known of the atoms, changed)."""
        for watch in self._watched.values():
            watch.check_timestep_again()
        self._timesteps_warned.clear()

    def forget(self, atoms: Atoms) -> None:
        """Start afresh on ``atoms`` (atoms were removed from them)."""
        watch = self._watched.get(id(atoms))
        if watch is not None:
            watch.forget()

    @staticmethod
    def check_timestep(atoms: Atoms, timestep: float, parameter: bool) -> None:
        """Raise if the atoms moved since the last evaluation as a velocity
        Verlet step of a different length than ``timestep`` (``parameter``:
        given to the calculator as ``timestep=``, else announced by an ase_bpm
        integrator).

        Under velocity Verlet the displacement of every atom is the timestep
        times the velocity the atoms carry at evaluation; other motion
        (thermostats, moved by hand) cannot be judged and passes.
        """
        t = drift_time(atoms)
        if t is not None and abs(t - timestep) > DRIFT_PRECISION * abs(timestep):
            given = ("the calculator was given timestep=" if parameter
                     else "the clock runs on the timestep an ase_bpm integrator announced, ")
            raise ValueError(f"timestep mismatch: {given}{timestep:.6g}, but the atoms moved "
                             f"as a velocity Verlet step of {t:.6g}; pass the integrator's "
                             "timestep (timestep= to the calculator)")

    def check(self, atoms: Atoms, ev: Evaluation, ctx: Context, *, on: bool,
              announced: bool, quasi_static: bool, given: Optional[float], stiffest) -> None:
        """Raise :class:`UnstableSimulationError` if the evaluation's forces,
        torques or energies are not finite (one pass over each when all is
        well) or, in a step, if the timestep is beyond the stable one
        (:meth:`_beyond_limit`, which also warns above the estimate), the
        kinetic energy runs away (:meth:`_runaway`) or the step's ledger is
        out of proportion (:meth:`_unbalanced`).  With the guard off (``on``
        False) none of these is checked and no timestep warning given;
        evaluations that look like an optimiser's are watched either way
        (:meth:`_still`).

        ``announced``: an integrator announced this step (it moves the atoms
        as MD does); ``quasi_static``: a ``calc.step`` (no timestep to check);
        ``given``: the timestep of this step as given (the ``timestep``
        parameter, or the one an ase_bpm integrator announced for it);
        ``stiffest(atoms)``: ``(stable_timestep, stiffest atom)``.

        The usual step is this one call: each check's arithmetic is here,
        and its method runs only where the check trips or is due.
        """
        step, timestep = ctx.step, ctx.timestep
        if on:
            forces, torques = ev.forces, ev.torques
            if not all_finite(forces, torques):
                for quantity, values in (("force", forces), ("torque", torques)):
                    atom = None if values is None else first_non_finite(values)
                    if atom is not None:
                        self._unstable(atoms, step, timestep, given, stiffest,
                                       f"the {quantity} on particle {atom} is {values[atom]}: "
                                       "the simulation blew up")
            for quantity, value in (("energy", ev.energy),
                                    ("energy of the bonds broken", ev.released_energy)):
                if not math.isfinite(value):
                    self._unstable(atoms, step, timestep, given, stiffest,
                                   f"the {quantity} is {value}: the simulation blew up")
        if ctx.pure:
            return
        # an integrator that announces its steps moves the atoms as MD does
        watches_still = not announced
        checks = on and ctx.advancing
        if not (checks or watches_still):
            return
        watch = self._watched.get(id(atoms))
        if watch is None or watch.atoms() is not atoms:
            watch = self._watch_of(atoms)
        inputs = ctx.inputs
        p_nc = atoms.arrays.get("momenta")  # p . v: atoms held by FixAtoms have v = 0
        v_nc = None if p_nc is None else inputs.velocities
        kinetic = 0.0 if p_nc is None else 0.5 * dot_sum(p_nc, v_nc)
        if watches_still:  # the momenta compared through the kinetic energy (see _still)
            watch.same_momenta = watch.momenta == kinetic
            watch.momenta = kinetic
            if ctx.advancing and watch.same_momenta:
                self._still(atoms, watch, ev, ctx)
            else:
                watch.still = 0
        if not checks:
            return
        if not quasi_static:  # the timestep against the stable one, when due (_beyond_limit)
            limit = watch.limit
            due = (limit is None or not 0 <= step - limit[0] < STABILITY_EVERY
                   or (watch.idle and ev.touching))
            k = watch.probe
            if due or given is not None:
                changed = due or limit[1] != given
            elif k is None:
                changed = False
            else:  # a new integrator on the same atoms?  Told by one particle, the
                # fastest at the last check: its displacement is the timestep times
                # its velocity.  Round-off aside, a thermostat or a hand also make it
                # differ; where it cannot tell, the whole drift is looked at.
                x_last, changed = atoms.arrays.get(X_LAST), True
                if v_nc is not None and x_last is not None and k < len(x_last):
                    # (three numbers: Python's floats cost less than NumPy's calls)
                    (x, y, z), (vx, vy, vz) = atoms.positions[k].tolist(), v_nc[k].tolist()
                    lx, ly, lz = x_last[k].tolist()
                    dx, dy, dz = x - lx, y - ly, z - lz
                    vv, told = vx * vx + vy * vy + vz * vz, limit[1]
                    if vv != 0.0:
                        t = (dx * vx + dy * vy + dz * vz) / vv
                        changed = abs(t - told) > (DRIFT_PRECISION * told + POSITION_ROUNDOFF
                                                   * max(abs(x), abs(y), abs(z)) / math.sqrt(vv))
            if changed:
                self._beyond_limit(atoms, watch, step, due, inputs, announced, given,
                                   stiffest)
        # the kinetic energy's runaway (_runaway)
        grew = watch.kinetic_steps > 0 and kinetic > RUNAWAY_FACTOR * watch.kinetic
        streak = watch.streak + 1 if grew else 0
        if streak >= RUNAWAY_STEPS:
            self._runaway(atoms, watch, step, timestep, kinetic, inputs, given, stiffest)
        watch.kinetic, watch.streak = kinetic, streak
        watch.kinetic_steps += 1
        # the step's energy ledger (_unbalanced)
        # (with the spheres' rotation where torques act: damping that slows a
        # spinning sphere takes its energy from there)
        moving = kinetic + _spin_energy(atoms, ev, inputs)
        total = moving + float(ev.energy)
        in_play = moving + abs(float(ev.energy))
        before, before_in_play, seen = watch.total, watch.in_play, watch.balanced
        watch.total, watch.in_play, watch.balanced = total, in_play, True
        if seen:
            off = total - before + ev.dissipated + ev.released_energy
            if abs(off) > LEDGER_FACTOR * (in_play + before_in_play):
                self._unbalanced(atoms, watch, off, in_play + before_in_play, step, timestep,
                                 given, stiffest)

    def _still(self, atoms: Atoms, watch: GuardWatch, ev: Evaluation, ctx: Context) -> None:
        """An evaluation at new positions that finds the momenta as the last
        evaluation of these atoms left them (:meth:`check` tells): do forces
        act on particles free to move, and the atoms did not drift with their
        velocities (:func:`_drifted`)?  That is how ASE's optimisers and ``ase.vibrations``
        probe positions; under an integrator the forces change the momenta
        (where forces of round-off size do not, as on a body translating
        freely, the atoms moved as a velocity Verlet drift).  ``STILL_STEPS``
        of them in a row warn once per calculator
        (:class:`OptimiserStepWarning`); fewer are a body moved into place by
        hand, or the first step of ASE's Langevin.  The momenta are compared
        through the kinetic energy the guard works out anyway, exactly."""
        hold = ctx.inputs.frozen  # (atoms held by FixAtoms: not free to move)
        forces_act = any_nonzero(ev.forces if hold is None else ev.forces[~hold])
        still = forces_act and not _drifted(atoms, watch, ctx.inputs, hold)
        watch.still = watch.still + 1 if still else 0
        if watch.still >= STILL_STEPS and not self._still_warned:
            self._still_warned = True
            warnings.warn(
                f"{self.name}: {watch.still} evaluations in a row at new positions "
                "found the momenta unchanged while forces act, as under an optimiser (BFGS, "
                "FIRE, ...) or ase.vibrations: each evaluation at new positions is an MD step "
                "(bonds past their criterion break, history advances, the step counter "
                "moves); evaluate such probes inside `with ase_bpm.pure(atoms):`",
                OptimiserStepWarning, stacklevel=outside_stacklevel())

    def _watch_of(self, atoms: Atoms) -> GuardWatch:
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

    def _beyond_limit(self, atoms: Atoms, watch: GuardWatch, step: int, due: bool,
                      inputs: Inputs, announced: bool, given: Optional[float],
                      stiffest) -> None:
        """Raise if the timestep is more than ``BEYOND_LIMIT`` times
        ``stable_timestep``, and warn once per calculator and timestep
        (:class:`TimestepWarning`) if it is more than the estimate.

        Checked at the first step this calculator makes on ``atoms`` with a
        timestep it can tell, every ``STABILITY_EVERY`` steps, when the
        timestep changes (a given one: the parameter, an ase_bpm
        integrator's; under ASE's own integrators, the velocity Verlet
        drift's, told by one particle each step, in :meth:`check`),
        after the calculator's ``set`` or ``refresh`` (:meth:`check_again`),
        and, where nothing acted at the last check (the estimate was inf), as
        soon as something does (``touching``: spheres that come to touch).
        Not in a quasi-static ``calc.step``.

        The first check takes its estimate from :meth:`_first_estimate` and
        warns only above the one at the run's first state; later checks take
        it at the step's positions.  The estimate lies between a third of the true
        limit and the limit (tests/test_stable_timestep.py), so no stable run
        is stopped.  A run whose timestep cannot be told (thermostats) is not
        checked; it is said so once (:meth:`_untold`).
        """
        dt = given
        drifted = None  # the timestep of a velocity Verlet drift, where worked out
        if given is None:  # told by the drift (ASE's integrators)
            dt = drifted = drift_time(atoms)
            if dt is None:
                self._untold(atoms, watch, step, announced, stiffest)
                return
            if not due and abs(dt - watch.limit[1]) <= DRIFT_PRECISION * dt:
                return  # the same timestep after all (a particle crossed a periodic face)
        watch.untold = 0
        if watch.limit is None:  # the run's first check
            at, estimate, atom, asked = _first_estimate(atoms, watch, step, drifted, stiffest)
        else:
            at, (estimate, atom), asked = step, _estimate(atoms, stiffest), None
        if estimate is None:
            return
        ratio = dt / estimate
        where = self._estimated(atoms, at)
        if ratio > BEYOND_LIMIT:
            self._unstable(atoms, step, dt, given, stiffest,
                           f"the timestep is {ratio:.3g} times the stable timestep "
                           f"{estimate:.6g} {where} (the stiffest particle is {atom}), more "
                           f"than {BEYOND_LIMIT:g} times: velocity Verlet is unstable there",
                           estimate, at, advise=False)
        watch.limit = (step, dt)  # passed: checked again when due or dt changes
        watch.idle = math.isinf(estimate)  # then again when contacts form
        watch.probe = _fastest(inputs) if given is None else None
        shown = f"{dt:.6g}"  # (a drift's timestep varies in its last digits)
        above = ratio > 1.0 + DRIFT_PRECISION and not (
            asked is not None and dt <= asked * (1.0 + DRIFT_PRECISION))
        if above and shown not in self._timesteps_warned:
            self._timesteps_warned.add(shown)
            warnings.warn(
                f"{self.name}: the timestep {shown} is {ratio:.3g} times "
                f"stable_timestep(atoms), {estimate:.6g} {where} (the stiffest particle is "
                f"{atom}): above the estimate velocity Verlet is unstable for the stiffest "
                "motions, which can break bonds or heat contacts, slowly or fast, before "
                f"anything blows up (the guard stops a run only above {BEYOND_LIMIT:g} times "
                "it); use a timestep at most the estimate",
                TimestepWarning, stacklevel=outside_stacklevel())

    def _untold(self, atoms: Atoms, watch: GuardWatch, step: int, announced: bool,
                stiffest) -> None:
        """A step whose timestep cannot be told: neither given nor that of a
        velocity Verlet drift.  ``UNTOLD_STEPS`` of them in a row, each with
        the momenta changed (a thermostat, such as ASE's ``Langevin``), warn
        once per calculator (:class:`TimestepUncheckedWarning`).  Not
        counted: a quasi-static ``calc.step``, and atoms moved with their
        momenta kept (by hand, or by an optimiser: :class:`OptimiserStepWarning`
        is for those, see :meth:`_still`)."""
        if announced or watch.same_momenta:
            watch.untold = 0
            return
        watch.untold += 1
        if watch.untold < UNTOLD_STEPS or self._untold_warned:
            return
        self._untold_warned = True
        estimate = _estimate(atoms, stiffest)[0]
        now = "" if estimate is None else f" ({estimate:.6g} at step {step}'s positions)"
        warnings.warn(
            f"{self.name}: in {watch.untold} steps in a row the atoms did not move "
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

    def _runaway(self, atoms: Atoms, watch: GuardWatch, step: int, timestep,
                 kinetic: float, inputs: Inputs, given: Optional[float], stiffest) -> None:
        """Raise if the kinetic energy grew more than ``RUNAWAY_FACTOR``-fold in
        each of the last ``RUNAWAY_STEPS`` steps.

        Velocity Verlet beyond its stable timestep multiplies the energy of the
        unstable modes every step (at 1.17 times the limit by 10, at 1.33 times
        by 24), while what fixes and thermostats bring in grows slower: from
        rest, a kinetic energy growing as t^p grows 10-fold in each of steps 2
        to 5 only for p > 10.  The kinetic energy is that of the velocities
        the forces are evaluated with (half-step ones under velocity Verlet).
        """
        watch.forget()
        atom = _fastest(inputs)
        v_nc = inputs.velocities
        self._unstable(atoms, step, timestep, given, stiffest,
                       f"the kinetic energy grew more than {RUNAWAY_FACTOR:g}-fold in "
                       f"each of the last {RUNAWAY_STEPS} steps, to {kinetic:.6g}; the "
                       f"fastest particle is {atom}, at speed "
                       f"{float(np.linalg.norm(v_nc[atom])):.6g}: the simulation is "
                       "blowing up")

    def _unbalanced(self, atoms: Atoms, watch: GuardWatch, off: float, in_play: float,
                    step: int, timestep, given: Optional[float], stiffest) -> None:
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
        if drift_time(atoms) is not None:
            watch.forget()
            self._unstable(atoms, step, timestep, given, stiffest,
                           f"the energy ledger is off by {off:.6g} in this step, more than "
                           f"{LEDGER_FACTOR:g} times the energy in play "
                           f"({in_play:.6g}: kinetic and potential, now "
                           "and before): the simulation blew up")

    def non_finite_positions(self, atoms: Atoms, timestep: Optional[float], stiffest) -> None:
        """Positions that are not finite: a blow-up when the last recorded
        evaluation of these atoms had finite ones, else bad input
        (``timestep``: the one given or last announced, for the message)."""
        Inputs(atoms).masses  # a mass that is not positive: the culprit, not the positions
        try:
            require_finite("position", atoms.positions)
        except ValueError as exc:
            x_last = atoms.arrays.get(X_LAST)
            if x_last is None or x_last.shape != atoms.positions.shape:
                raise
            self._unstable(atoms, int(atoms.info.get(STEP, 0)) + 1, timestep, None,
                           stiffest, str(exc))

    def _unstable(self, atoms: Atoms, step: int, timestep, given: Optional[float], stiffest,
                  what: str, estimate: Optional[float] = None, at: Optional[int] = None,
                  advise: bool = True) -> None:
        """Raise :class:`UnstableSimulationError` for ``what`` at ``step``, with
        the stable timestep (``estimate`` at step ``at``'s positions, worked
        out here at ``step``'s if not given; not again where ``what`` gives
        it: ``advise=False``) and the timestep (``timestep``, else the one
        ``given``, else the drift's)."""
        if estimate is None and advise:
            estimate, at = _estimate(atoms, stiffest)[0], step
        advice = ("" if estimate is None or not advise else "; stable_timestep(atoms) "
                  f"suggests at most {estimate:.6g} {self._estimated(atoms, at)}")
        if timestep is None:
            timestep = given or drift_time(atoms)
        used = "" if timestep is None else f" (timestep {timestep:.6g})"
        raise UnstableSimulationError(f"step {step}{used}: {what}; nothing of this step "
                                      f"was written{advice}{RUN_AGAIN}")


def _drifted(atoms: Atoms, watch: GuardWatch, inputs: Inputs, hold) -> bool:
    """Did the atoms move as a velocity Verlet drift since the last
    evaluation (:func:`drift_time`)?  Told at once where one moving
    particle (the guard's probe, else the fastest) moved forward along its
    velocity, to ``DRIFT_RESIDUAL`` of its displacement beyond the round-off
    of its position: an optimiser's step is not along the velocities.  Else
    the whole drift is looked at.  ``hold``: the mask of atoms held by
    FixAtoms (``inputs.frozen``)."""
    v_nc = inputs.velocities if hold is None else None  # (= get_velocities())
    x_last = atoms.arrays.get(X_LAST)
    if v_nc is not None and x_last is not None and x_last.shape == v_nc.shape:
        k = watch.probe if watch.probe is not None and watch.probe < len(v_nc) else (
            _fastest(inputs))
        # (three numbers: Python's floats cost less than NumPy's calls)
        (x, y, z), (vx, vy, vz) = atoms.positions[k].tolist(), v_nc[k].tolist()
        lx, ly, lz = x_last[k].tolist()
        dx, dy, dz = x - lx, y - ly, z - lz
        vv = vx * vx + vy * vy + vz * vz
        t = (dx * vx + dy * vy + dz * vz) / vv if vv > 0.0 else 0.0
        if t > 0.0 and (max(abs(dx - t * vx), abs(dy - t * vy), abs(dz - t * vz))
                        <= DRIFT_RESIDUAL * max(abs(dx), abs(dy), abs(dz))
                        + POSITION_ROUNDOFF * max(abs(x), abs(y), abs(z))):
            return True
    return drift_time(atoms, v_nc) is not None


def _first_estimate(atoms: Atoms, watch: GuardWatch, step: int, drifted: Optional[float],
                    stiffest) -> tuple:
    """``(at, estimate, atom, asked)`` for a run's first check: the estimate
    at the state the step started from (step ``at``; there
    ``stable_timestep(atoms)`` was asked before the run: ``asked``, kept
    in ``watch.first``) and, where the atoms did not drift there as
    velocity Verlet moves them (``drifted``, the drift's timestep if
    worked out already: None looks), the one where they are if that is
    less (pressed by hand, a thermostat), with its stiffest atom."""
    at = step - 1
    estimate, atom = _estimate(atoms, stiffest, atoms.arrays[X_LAST])
    asked = estimate
    if watch.first is None and estimate is not None:
        watch.first = (at, estimate)
    if drifted is None:
        drifted = drift_time(atoms)
    if drifted is None:
        now, atom_now = _estimate(atoms, stiffest)
        if now is not None and (estimate is None or now < estimate):
            at, estimate, atom = step, now, atom_now
    return at, estimate, atom, asked
