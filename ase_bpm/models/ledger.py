"""The energy ledger: what damping took and broken bonds released.

``energy`` is the elastic energy.  The work done by velocity-dependent
(damping) forces and torques is accumulated, trapezoidally over each step, in
``atoms.info[DISSIPATED]``; the elastic energy of bonds that broke in
``atoms.info[BROKEN_ENERGY]``.  For a run,
``kinetic + energy + dissipated_energy + broken_bond_energy`` is conserved up
to the integrator's error.  The totals ride on the atoms with the record
(:mod:`.record`), so a restarted run books on from where it stopped.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from ase import Atoms

from ..core.arrays import dot_sum
from ..core.neighbours import minimum_image
from .evaluation import Evaluation
from .record import BROKEN_ENERGY, DISSIPATED, FD_LAST, STEP, T_LAST, X_LAST


def _work(f_nc: Optional[np.ndarray], dx_nc: np.ndarray) -> float:
    """``sum f . dx`` over the atoms (0 without forces)."""
    return 0.0 if f_nc is None else dot_sum(f_nc, dx_nc)


def dissipated(atoms: Atoms, ev: Evaluation, timestep: Optional[float]) -> float:
    """Energy the damping forces and torques took in the step from the
    recorded last evaluation to ``ev``: their trapezoidal work (the torques'
    over the turn ``omega * timestep``, only where the timestep is known)."""
    arrays, taken = atoms.arrays, 0.0
    if ev.f_damp is not None or FD_LAST in arrays:
        dx_nc = minimum_image(atoms.positions - arrays[X_LAST], atoms.cell, atoms.pbc)
        taken -= 0.5 * (_work(ev.f_damp, dx_nc) + _work(arrays.get(FD_LAST), dx_nc))
    if (timestep is not None and "omega" in arrays
            and (ev.torques is not None or T_LAST in arrays)):
        # the same for torques: the spheres turned by omega dt in the step
        w_nc = arrays["omega"]
        taken -= 0.5 * timestep * (_work(ev.torques, w_nc) + _work(arrays.get(T_LAST), w_nc))
    return taken


def book(atoms: Atoms, ev: Evaluation, results: dict) -> None:
    """Add the step's dissipated and released energy to the totals on the
    atoms, and put the ledger's results in ``results``."""
    info = atoms.info
    info[DISSIPATED] = float(info.get(DISSIPATED, 0.0)) + ev.dissipated
    info[BROKEN_ENERGY] = float(info.get(BROKEN_ENERGY, 0.0)) + ev.released_energy
    ledger_results(results, info)


def ledger_results(results: dict, info: dict) -> None:
    """The ledger's results as the atoms' ``info`` holds them: the totals
    ``dissipated_energy`` and ``broken_bond_energy`` (energy units) and the
    ``step`` count."""
    results["dissipated_energy"] = float(info.get(DISSIPATED, 0.0))
    results["broken_bond_energy"] = float(info.get(BROKEN_ENERGY, 0.0))
    results["step"] = int(info.get(STEP, 0))
