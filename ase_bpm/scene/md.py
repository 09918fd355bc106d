"""Integrators that keep ase_bpm calculators informed of time.

ASE's calculators see positions, not time: under ASE's own integrators an
ase_bpm calculator counts a step whenever the positions change.  A scene at
rest (no force, no motion) therefore does not age, and a moving indenter would
never arrive.  The integrators here tell the calculator, at every step, that a
step happens and with which timestep (``calc.begin_step(dt)``), so time-
dependent pieces and history models get the integrator's own timestep.

LAMMPS equivalents: ``fix nve`` (:class:`VelocityVerlet`), ``fix nve/sphere``
and, for particles with an orientation, ``fix nve/bpm/sphere``
(:class:`SphereVelocityVerlet`).
"""

from __future__ import annotations

import numpy as np
from ase import Atoms
from ase.calculators.calculator import PropertyNotImplementedError
from ase.md.verlet import VelocityVerlet as _AseVelocityVerlet

from ..core.arrays import add_to, any_nonzero, per_component, same_array
from ..models.base import BPMCalculator
from ..core.quaternions import turned
from ..core.spheres import (OMEGA, QUAT, RADIUS, angular_velocities, frozen,
                            moments_of_inertia, orientations)


class VelocityVerlet(_AseVelocityVerlet):
    """ASE's velocity Verlet (LAMMPS ``fix nve``), announcing each step to the
    calculator.  Same arguments and behaviour as
    ``ase.md.verlet.VelocityVerlet``."""

    #: does the integrator turn the spheres with the torques
    #: (:class:`SphereVelocityVerlet`, which defines ``_turn``)?
    turns_spheres = False
    #: ``nsteps`` after the last step, whose evaluation an ase_bpm calculator holds
    _fresh = None
    #: (a copy of the masses array, the masses n x 3) of the last drift
    _kept_masses = None

    def step(self, forces=None):
        """One step, top to bottom: half a kick (and, for spheres, half a
        turn), a drift, the step announced to the calculator, the forces (and
        torques) at the new positions, the second half kick (and turn).  The
        kicks and the drift work in place in the atoms' own momenta and
        positions, with ASE's arithmetic, where nothing stands in the way (no
        constraints, float N x 3 momenta and positions); else through ASE's
        setters (:meth:`_kick_and_drift`)."""
        atoms = self.atoms
        calc = atoms.calc
        ours = isinstance(calc, BPMCalculator)
        # (an ase_bpm calculator says when no torque can act: the spheres keep their spin)
        turning = self.turns_spheres and not (ours and not calc.produces_torques)
        torques = None
        if forces is None:
            forces = forces_of(atoms)
            if turning and ours:  # the same evaluation's: nothing changed since forces_of looked
                torques = calc.results.get("torques")
        if turning and torques is None:
            torques = torques_of(atoms)  # (at the positions before the drift)
        dt = self.dt
        p, x = atoms.arrays.get("momenta"), atoms.arrays["positions"]
        in_place = not (atoms.constraints or p is None or p.dtype != np.float64
                        or x.dtype != np.float64 or p.shape != x.shape)
        if in_place:
            add_to(p, 0.5 * dt, forces)
            add_to(x, dt, p, self._masses_nc(), divide=True)
        else:
            self._kick_and_drift(forces)
        rate = self._turn(torques) if turning else None
        if turning and QUAT in atoms.arrays:
            self._orient()
        if ours:
            calc.begin_step(dt, turns=turning)
        elif hasattr(calc, "begin_step"):  # a calculator of another package that keeps time
            calc.begin_step(dt)
        natoms = len(atoms)
        forces = atoms.get_forces(md=True)
        if in_place:  # (the evaluation may have removed atoms, ase_bpm.LostAtoms: new arrays)
            add_to(atoms.arrays["momenta"], 0.5 * dt, forces)
        else:
            atoms.set_momenta(atoms.get_momenta() + 0.5 * dt * forces)
        if turning:
            # torques of the evaluation that gave these forces, just made
            torques = calc.results.get("torques") if ours else None
            self._turn(torques_of(atoms) if torques is None else torques,
                       rate if len(atoms) == natoms else None)
        self._fresh = self.nsteps + 1 if ours else None
        return forces

    def _refresh_properties(self):
        """ASE asks for the forces after each step so that loggers and
        observers find them cached.  An ase_bpm calculator holds them already
        when the step evaluated them at these very positions (the kick after
        it changed only momenta and spins), right before: then nothing is
        asked."""
        if self._fresh == self.nsteps:  # ASE counted the step just made
            self._fresh = None
            return
        super()._refresh_properties()

    def _kick_and_drift(self, forces) -> None:
        """Half a kick of the momenta, then a full drift of the positions,
        through ASE's getters and setters (constraints applied)."""
        atoms = self.atoms
        p = atoms.get_momenta()
        p += 0.5 * self.dt * forces
        masses = atoms.get_masses()[:, None]
        r = atoms.get_positions()
        atoms.set_positions(r + self.dt * p / masses)
        if atoms.constraints:
            p = (atoms.get_positions() - r) * masses / self.dt
        atoms.set_momenta(p, apply_constraint=False)

    def _masses_nc(self) -> np.ndarray:
        """The masses as an n x 3 array (the quotients of ``[:, None]``,
        computed faster), kept while ``atoms.arrays["masses"]`` holds the
        same values."""
        given = self.atoms.arrays.get("masses")
        kept = self._kept_masses
        if given is None or kept is None or not same_array(kept[0], given):
            m_nc = per_component(self.atoms.get_masses())
            kept = self._kept_masses = (None if given is None else given.copy(), m_nc)
        return kept[1]


def forces_of(atoms: Atoms) -> np.ndarray:
    """``atoms.get_forces(md=True)``; from an ase_bpm calculator's results when
    nothing changed since they were computed (as after the last step),
    without a second request.  Without constraints that is the calculator's
    own array: read it, do not change it."""
    calc = atoms.calc
    if isinstance(calc, BPMCalculator) and "forces" in calc.results \
            and not calc.check_state(atoms):
        forces = calc.results["forces"]
        if not atoms.constraints:
            return forces  # only read (the integrators kick with it)
        forces = forces.copy()
        for constraint in atoms.constraints:
            constraint.adjust_forces(atoms, forces)
        return forces
    return atoms.get_forces(md=True)


def torques_of(atoms: Atoms) -> np.ndarray:
    """Torques from the calculator (zeros for calculators without them).

    Called right after the forces at the same positions: an ase_bpm
    calculator's results of that evaluation hold them already (no second
    request), unless something changed since."""
    calc = atoms.calc
    if calc is None or "torques" not in getattr(calc, "implemented_properties", ()):
        return np.zeros((len(atoms), 3))
    if isinstance(calc, BPMCalculator) and "torques" in calc.results \
            and not calc.check_state(atoms):
        return calc.results["torques"]
    try:
        return calc.get_property("torques", atoms)
    except PropertyNotImplementedError:
        return np.zeros((len(atoms), 3))


class SphereVelocityVerlet(VelocityVerlet):
    """Velocity Verlet for spheres that translate and rotate: LAMMPS ``fix
    nve/sphere``, and ``fix nve/bpm/sphere`` where the atoms carry an
    orientation (``atoms.arrays["quat"]``, made the identity for a
    calculator whose bonds turn with the particles, ``bpm/rotational``):
    after the drift and the first half kick of ``omega``, the orientation
    turns by that ``omega`` for the whole step.

    Positions and momenta advance as in ASE's ``VelocityVerlet``; the angular
    velocity ``atoms.arrays["omega"]`` (created as zeros if absent) advances
    with the calculator's ``torques`` and the moment of inertia of a solid
    sphere, ``2/5 m r^2`` (``atoms.arrays["radius"]``, needed once a torque
    acts).  When the ase_bpm calculator says it gives no torques
    (``calc.produces_torques``: no friction in its contacts or its fixes)
    nothing about rotation is computed and ``omega`` stays as it is.  Each step is announced to ase_bpm calculators with its timestep
    (shear history, time-dependent fixes), as by :class:`VelocityVerlet`.  Calculators without torques (any ASE calculator)
    run unchanged; their spheres keep their spin.  Atoms held by ``FixAtoms``
    neither move nor turn (LAMMPS ``fix freeze``).

    Same arguments as ASE's ``VelocityVerlet``: ``atoms``, ``timestep`` (ASE
    time units, i.e. the calculator's time unit), ``trajectory``,
    ``logfile``, ``loginterval``.
    """

    turns_spheres = True

    def __init__(self, atoms: Atoms, timestep: float, trajectory=None, logfile=None,
                 loginterval: int = 1, **kwargs):
        if RADIUS in atoms.arrays:
            moments_of_inertia(atoms)  # checks the radii (needed once torques act)
        angular_velocities(atoms)  # checks omega, if present
        if OMEGA not in atoms.arrays:
            atoms.arrays[OMEGA] = np.zeros((len(atoms), 3))
        orientations(atoms)  # checks the orientations, if present
        calc = atoms.calc
        if QUAT not in atoms.arrays and getattr(getattr(calc, "model", None), "turns", False):
            atoms.arrays[QUAT] = orientations(atoms)  # (the identity: bpm/sphere's start)
        self._inertia = (None,) * 5  # (radii, masses, inertia, dt / 2I, dt) kept
        super().__init__(atoms, timestep=timestep, trajectory=trajectory, logfile=logfile,
                         loginterval=loginterval, **kwargs)

    def inertia(self) -> np.ndarray:
        """``2/5 m r^2`` of every sphere, recomputed when radii or masses change."""
        return self._inertia_and_rate()[0]

    def _inertia_and_rate(self) -> tuple:
        """The moments of inertia and ``dt / 2I`` (n x 3, the same for the three
        components), the change of omega per unit torque in half a kick; kept
        while radii and masses stay."""
        atoms = self.atoms
        radius, masses = atoms.arrays.get(RADIUS), atoms.get_masses()  # numbers give some
        kept_r, kept_m, inertia, rate, dt = self._inertia
        if inertia is None or not (same_array(kept_r, radius, (kept_m, masses))
                                   and len(inertia) == len(atoms)):
            inertia, dt = moments_of_inertia(atoms), None
        if dt != self.dt:  # (ASE's dynamics let the timestep be changed during a run)
            rate = per_component(0.5 * self.dt / inertia)  # (a column, as n x 3)
            self._inertia = (None if radius is None else radius.copy(), masses, inertia, rate,
                             self.dt)
        return inertia, rate

    def _orient(self) -> None:
        """Turn the orientations ``quat`` by the angular velocities of the
        half step for the whole step (LAMMPS ``fix nve/bpm/sphere``,
        :func:`ase_bpm.core.quaternions.turned`); spheres held by
        ``FixAtoms`` keep theirs."""
        atoms = self.atoms
        q_nq = orientations(atoms)
        new_nq = turned(q_nq, angular_velocities(atoms), self.dt)
        if atoms.constraints:
            hold = frozen(atoms)
            if hold is not None:
                new_nq[hold] = q_nq[hold]
        atoms.arrays[QUAT] = new_nq

    def _turn(self, torques: np.ndarray, rate=None):
        """Half a kick of the angular velocities (in place, as the momenta);
        returns ``dt / 2I`` (None if nothing turned), which the second half
        kick of the same step may pass as ``rate``."""
        atoms = self.atoms
        torques = np.asarray(torques, dtype=float)
        if not any_nonzero(torques):
            return rate  # nothing turns the spheres (e.g. a translational calculator)
        if rate is None:
            rate = self._inertia_and_rate()[1]
        if atoms.constraints:  # (FixAtoms: those spheres do not turn)
            hold = frozen(atoms)
            if hold is not None:
                torques = np.where(hold[:, None], 0.0, torques)
        w_nc = atoms.arrays[OMEGA]
        if (w_nc.dtype == np.float64 and w_nc.shape == (len(atoms), 3)
                and w_nc.flags.writeable):
            add_to(w_nc, 1.0, torques, rate)
        else:  # checks it (the calculator checks it too)
            atoms.arrays[OMEGA] = angular_velocities(atoms) + torques * rate
        return rate
