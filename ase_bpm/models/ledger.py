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
    """``sum f . dx`` over the atoms (0 without forces).  (The ledger's own
    sums are written out in :func:`dissipated`; kept for code importing it.)"""
    return 0.0 if f_nc is None else dot_sum(f_nc, dx_nc)


def dissipated(atoms: Atoms, ev: Evaluation, timestep: Optional[float]) -> float:
    """Energy the damping forces and torques took in the step from the
    recorded last evaluation to ``ev``: their trapezoidal work (the torques'
    over the turn ``omega * timestep``, only where the timestep is known)."""
    arrays, taken = atoms.arrays, 0.0
    f_nc, f_last = ev.f_damp, arrays.get(FD_LAST)
    if f_nc is not None or f_last is not None:
        dx_nc = atoms.positions - arrays[X_LAST]
        if atoms.pbc.any():
            dx_nc = minimum_image(dx_nc, atoms.cell, atoms.pbc)
        taken -= 0.5 * ((0.0 if f_nc is None else dot_sum(f_nc, dx_nc))
                        + (0.0 if f_last is None else dot_sum(f_last, dx_nc)))
    t_nc, t_last, w_nc = ev.torques, arrays.get(T_LAST), arrays.get("omega")
    if timestep is not None and w_nc is not None and (t_nc is not None or t_last is not None):
        # the same for torques: the spheres turned by omega dt in the step
        taken -= 0.5 * timestep * ((0.0 if t_nc is None else dot_sum(t_nc, w_nc))
                                   + (0.0 if t_last is None else dot_sum(t_last, w_nc)))
    return taken


def book(atoms: Atoms, ev: Evaluation, results: dict) -> None:
    """Add the step's dissipated and released energy to the totals on the
    atoms, and put the ledger's results in ``results``."""
    info = atoms.info
    dissipated = info[DISSIPATED] = float(info.get(DISSIPATED, 0.0)) + ev.dissipated
    broken = info[BROKEN_ENERGY] = float(info.get(BROKEN_ENERGY, 0.0)) + ev.released_energy
    results["dissipated_energy"], results["broken_bond_energy"] = dissipated, broken
    results["step"] = int(info.get(STEP, 0))  # (as ledger_results puts them)


def ledger_results(results: dict, info: dict) -> None:
    """The ledger's results as the atoms' ``info`` holds them: the totals
    ``dissipated_energy`` and ``broken_bond_energy`` (energy units) and the
    ``step`` count."""
    results["dissipated_energy"] = float(info.get(DISSIPATED, 0.0))
    results["broken_bond_energy"] = float(info.get(BROKEN_ENERGY, 0.0))
    results["step"] = int(info.get(STEP, 0))
