"""Pure evaluations: forces and energy as a function of positions and velocities only.

Every evaluation at new positions is otherwise an MD step (bonds break,
history advances, the step counter moves, damping work is booked).  Inside
:func:`pure`, for ASE optimisers, ``ase.vibrations``, NEB or finite-difference
checks, nothing is written and nothing advances; leaving it re-bases the
record on where the atoms are (:func:`.record.rebase`).
"""

from __future__ import annotations

from contextlib import contextmanager

from ase import Atoms

from .record import rebase


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
    from .base import BPMCalculator  # (base imports this module)

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


class PureEvaluations:
    """How deep a calculator is inside pure evaluations, and the atoms
    objects whose records to re-base when it leaves the outermost."""

    def __init__(self):
        self.depth = 0
        self._atoms = []

    def enter(self, atoms: Atoms) -> None:
        """Start pure evaluations of ``atoms``."""
        self.depth += 1
        self._atoms.append(atoms)

    def leave(self) -> None:
        """End pure evaluations of one atoms object; on leaving the
        outermost, re-base the record of every atoms object evaluated inside
        where they moved (a relaxation: the next evaluation is not a step);
        atoms back where they were go on as if nothing had happened."""
        self.depth -= 1
        if self.depth:
            return
        for atoms in self._atoms:
            rebase(atoms)
        self._atoms = []
