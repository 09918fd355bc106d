"""The energy ledger: what damping took and broken bonds released.

``energy`` is the elastic energy.  The work done by velocity-dependent
(damping) forces and torques is accumulated, trapezoidally over each step, in
``atoms.info[DISSIPATED]``; the elastic energy of bonds that broke in
``atoms.info[BROKEN_ENERGY]``.  For a run,
``kinetic + energy + dissipated_energy + broken_bond_energy`` is conserved up
to the integrator's error, but for rotational bonds (``bpm/rotational``),
whose forces and torques derive from no energy: their elastic work is in no
entry (LAMMPS reports their energy as zero too), and only the work of their
damping is booked.  The totals ride on the atoms with the record
(:mod:`.record`), so a restarted run books on from where it stopped.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from ase import Atoms

from ..core.arrays import NATIVE, dot_sum
from ..core.neighbours import minimum_image
from .evaluation import Evaluation
from .record import BROKEN_ENERGY, DISSIPATED, FD_LAST, STEP, T_LAST, TD_LAST, X_LAST


def _work(f_nc: Optional[np.ndarray], dx_nc: np.ndarray) -> float:
    """``sum f . dx`` over the atoms (0 without forces)."""
    return 0.0 if f_nc is None else dot_sum(f_nc, dx_nc)


def dissipated(atoms: Atoms, ev: Evaluation, timestep: Optional[float]) -> float:
    """Energy the damping forces and torques took in the step from the
    recorded last evaluation to ``ev``: their trapezoidal work (the torques'
    over the turn ``omega * timestep``, only where the timestep is known).
    Each work is one pass over the atoms (:func:`damping_work`)."""
    arrays, works = atoms.arrays, []  # (scale, f_nc, f_last, x_nc, x_last) for damping_work
    f_nc, f_last = ev.f_damp, arrays.get(FD_LAST)
    if f_nc is not None or f_last is not None:
        x_nc, x_last = atoms.positions, arrays[X_LAST]
        if atoms.pbc.any():  # the displacements through the nearest images
            x_nc, x_last = minimum_image(x_nc - x_last, atoms.cell, atoms.pbc), None
        works.append((1.0, f_nc, f_last, x_nc, x_last))
    t_nc, t_last, w_nc = ev.torques, arrays.get(T_LAST), arrays.get("omega")
    if ev.t_damp is not None or TD_LAST in arrays:  # (some torques elastic: rotational bonds)
        t_nc, t_last = ev.t_damp, arrays.get(TD_LAST)
    if timestep is not None and w_nc is not None and (t_nc is not None or t_last is not None):
        # the same for torques: the spheres turned by omega dt in the step
        works.append((timestep, t_nc, t_last, w_nc, None))
    # (the C twin called here itself, the NumPy sums where it declines: one call less a step)
    twin, taken = NATIVE.get("damping_work", _damping_work_numpy), 0.0
    for scale, *work in works:
        done = twin(*work)
        taken += scale * (_damping_work_numpy(*work) if done is NotImplemented else done)
    return taken


def damping_work(f_nc: Optional[np.ndarray], f_last: Optional[np.ndarray], x_nc: np.ndarray,
                 x_last: Optional[np.ndarray]) -> float:
    """The trapezoidal work of damping forces ``f_last`` (at the step's
    start) and ``f_nc`` (at its end) over the step from ``x_last`` to
    ``x_nc``, negated (the energy they took): ``-(f . dx + f_last . dx) / 2``
    with ``dx = x_nc - x_last`` (``x_last`` None: ``x_nc`` is ``dx``); a
    force that is None does no work.  Each sum is :func:`dot_sum`'s (the
    same number); the C twin makes them in one call, without ``dx``."""
    twin = NATIVE.get("damping_work")
    if twin is not None:
        taken = twin(f_nc, f_last, x_nc, x_last)
        if taken is not NotImplemented:
            return taken
    return _damping_work_numpy(f_nc, f_last, x_nc, x_last)


def _damping_work_numpy(f_nc, f_last, x_nc, x_last) -> float:
    """:func:`damping_work` in NumPy (its C twin's numbers)."""
    dx_nc = x_nc if x_last is None else x_nc - x_last
    return 0.0 - 0.5 * (_work(f_nc, dx_nc) + _work(f_last, dx_nc))


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
