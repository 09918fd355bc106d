"""NumPy against compiled kernels, where both exist (the granular contacts).

The pour runs over its whole duration at its own timestep with each route
(``kernels="numpy"`` and ``"compiled"``).  Both compute the same arithmetic
contact by contact and differ only in the order of the per-atom sums, so the
forces agree to round-off; over a whole pour that round-off grows as any
perturbation of a chaotic flow does, so the settled piles are compared with
each other as the chaos floor of the timestep section compares two runs.
"""

from __future__ import annotations

from tradeoff_common import relative_error, table

from pathlib import Path

import numpy as np

from ase_bpm.laws import compiled
from tradeoff_scenes import Pour, simulate

def parity(quick: bool, pile) -> float:
    """Largest force difference of the routes on the settled ``pile``, over
    the largest force."""
    f_nc = {}
    for kernels in ("compiled", "numpy"):
        pile.calc = Pour(quick, kernels=kernels).build().calc  # the shear history is on the atoms
        f_nc[kernels] = pile.get_forces()
    return float(np.abs(f_nc["numpy"] - f_nc["compiled"]).max()
                 / np.abs(f_nc["compiled"]).max())


def section(quick: bool, figures: Path) -> str:
    if not compiled.available:
        return ("## NumPy against compiled kernels\n\nThe compiled kernels are not built "
                "here (`pip install -e .` with a C compiler): nothing measured.")
    runs = {k: simulate(Pour(quick, kernels=k), Pour.demo_dt, keep_atoms=True)
            for k in ("numpy", "compiled")}
    names = list(runs["compiled"].observables)
    rows = [[k, run.ms_per_step] + [run.observables[n] for n in names]
            for k, run in runs.items()]
    rows.append(["difference", ""] + [
        f"{relative_error(runs['numpy'].observables[n], runs['compiled'].observables[n]):.2e}"
        for n in names])
    speedup = runs["numpy"].ms_per_step / runs["compiled"].ms_per_step
    return ("## NumPy against compiled kernels\n\n"
            f"The pour{' (quick size)' if quick else ''}, {runs['compiled'].steps} steps at "
            f"dt {Pour.demo_dt:g} with each route of the granular kernels.  The compiled "
            f"route is {speedup:.2f} times as fast per step.  On the settled pile the "
            f"forces differ by {parity(quick, runs['compiled'].extra['atoms']):.1e} of the largest "
            "force; over the whole pour that round-off grows as any perturbation of a "
            "granular flow does, and the settled piles differ as below (compare the chaos "
            "floor of the pour in the timestep section).\n\n"
            + table(["kernels", "ms/step"] + names, rows))
