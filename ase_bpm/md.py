"""Integrators that keep ase_bpm calculators informed of time.

ASE's calculators see positions, not time: under ASE's own integrators an
ase_bpm calculator counts a step whenever the positions change.  A scene at
rest (no force, no motion) therefore does not age, and a moving indenter would
never arrive.  The integrators here tell the calculator, at every step, that a
step happens and with which timestep (``calc.begin_step(dt)``), so time-
dependent pieces and history models get the integrator's own timestep.

LAMMPS equivalents: ``fix nve`` (:class:`VelocityVerlet`).
"""

from __future__ import annotations

from ase.md.verlet import VelocityVerlet as _AseVelocityVerlet


def _announce(atoms, dt: float) -> None:
    calc = atoms.calc
    if hasattr(calc, "begin_step"):
        calc.begin_step(dt)


class VelocityVerlet(_AseVelocityVerlet):
    """ASE's velocity Verlet (LAMMPS ``fix nve``), announcing each step to the
    calculator.  Same arguments and behaviour as
    ``ase.md.verlet.VelocityVerlet``."""

    def step(self, forces=None):
        atoms = self.atoms
        if forces is None:
            forces = atoms.get_forces(md=True)
        p = atoms.get_momenta()
        p += 0.5 * self.dt * forces
        masses = atoms.get_masses()[:, None]
        r = atoms.get_positions()
        atoms.set_positions(r + self.dt * p / masses)
        if atoms.constraints:
            p = (atoms.get_positions() - r) * masses / self.dt
        atoms.set_momenta(p, apply_constraint=False)
        _announce(atoms, self.dt)
        forces = atoms.get_forces(md=True)
        atoms.set_momenta(atoms.get_momenta() + 0.5 * self.dt * forces)
        return forces
