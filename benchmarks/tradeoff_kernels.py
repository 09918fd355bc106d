"""NumPy against compiled kernels, on each demo.

Each demo runs over its whole duration at its own timestep with each route
(``kernels="numpy"`` and ``"compiled"``).  Both compute the same arithmetic
bond by bond and contact by contact and differ only in the order of the
per-atom sums, so the forces agree to round-off; over a whole run that
round-off grows as any perturbation of fracture or granular flow does, so
what a user reads off the two runs is compared, as the chaos floor of the
timestep section compares two runs.
"""

from __future__ import annotations

from tradeoff_common import relative_error, table

from pathlib import Path

import numpy as np

from ase_bpm.laws import compiled
from tradeoff_scenes import Impact, Pour, Shatter, simulate

ROUTES = ("numpy", "compiled")
X_LAST = "bpm_x_last"  # the record of the last evaluation (ase_bpm.models.base)


def parity(scene, final, dt: float) -> float:
    """Largest force difference of the routes on the ``final`` atoms of a run
    at timestep ``dt``, over the largest force: a fresh calculator of each
    route evaluates them from the state on the atoms (bonds, history; the
    record of the run's last evaluation removed, so that neither returns the
    recorded forces; ``dt`` for the fixes that move with time)."""
    f_nc = {}
    for kernels in ROUTES:
        atoms = final.copy()
        atoms.arrays.pop(X_LAST, None)
        atoms.calc = scene.build().calc
        atoms.calc.set(kernels=kernels, timestep=dt)
        f_nc[kernels] = atoms.get_forces()
    return float(np.abs(f_nc["numpy"] - f_nc["compiled"]).max()
                 / np.abs(f_nc["compiled"]).max())


def compare(scene) -> str:
    """The two routes on ``scene``: a sentence and a table."""
    runs = {k: simulate(scene, scene.demo_dt, keep_atoms=True, kernels=k) for k in ROUTES}
    names = [n for n, v in runs["compiled"].observables.items() if np.ndim(v) == 0]
    rows = [[k, run.ms_per_step] + [run.observables[n] for n in names]
            for k, run in runs.items()]
    rows.append(["difference", ""] + [
        f"{relative_error(runs['numpy'].observables[n], runs['compiled'].observables[n]):.2e}"
        for n in names])
    speedup = runs["numpy"].ms_per_step / runs["compiled"].ms_per_step
    return (f"### {scene.name}\n\n{runs['compiled'].steps} steps at dt {scene.demo_dt:g}. "
            f"The compiled route is {speedup:.2f} times as fast per step.  On the final "
            f"state the forces of the two routes differ by "
            f"{parity(scene, runs['compiled'].extra['atoms'], runs['compiled'].dt):.1e} of the largest force.\n\n"
            + table(["kernels", "ms/step"] + names, rows))


def section(quick: bool, figures: Path) -> str:
    if not compiled.available:
        return ("## NumPy against compiled kernels\n\nThe compiled kernels are not built "
                "here (`pip install -e .` with a C compiler): nothing measured.")
    return ("## NumPy against compiled kernels\n\n"
            f"Each demo{' (quick sizes)' if quick else ''} over its whole duration with each "
            "route of the kernels.  The differences of what a run gives are round-off "
            "grown by the chaos of fracture and granular flow: compare the chaos floor of "
            "each demo in the timestep section.\n\n"
            + "\n\n".join(compare(cls(quick)) for cls in (Impact, Shatter, Pour)))
