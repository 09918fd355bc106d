"""Smoothing of breaking springs: the energy error at fracture.

``bpm/spring`` with ``smooth yes`` multiplies the bond force by
``1 - (strain/eps_c)^8``, so a bond's force falls to zero as it reaches its
critical strain; with ``smooth no`` the force drops from ``k r0 eps_c`` to
zero in one step when the bond breaks.  Velocity Verlet's error is of second
order in dt for smooth forces and of first order across such jumps, so
without smoothing the energy ledger (kinetic plus potential plus damping
work plus the energy of broken bonds) drifts more, and converges more slowly.
The impact scene (``--quick`` size in both modes: 36 runs of the full scene
would take half an hour) runs at ``FRACTIONS`` of its estimate with smoothing
on and off; the drift is ``max_t |L(t) - L(0)|`` over the starting kinetic
energy, and the broken bonds are compared with the run at the smallest
timestep of the same setting.
"""

from __future__ import annotations

from tradeoff_common import order, pyplot, relative_error, save_figure, table

from pathlib import Path

import numpy as np

from tradeoff_scenes import Impact, simulate

FRACTIONS = (0.1, 0.2, 0.5, 1.0)


def section(quick: bool, figures: Path) -> str:
    scene = Impact(quick=True)
    estimate = scene.estimate()
    drift, rows = {}, []
    for smooth in (True, False):
        runs = [simulate(scene, f * estimate, smooth=smooth) for f in FRACTIONS]
        drift[smooth] = [float(np.abs(r.ledger_n - r.ledger_n[0]).max() / r.kinetic_n[0])
                         for r in runs]
        broken0 = runs[0].observables["broken bonds"]
        for f, run, d in zip(FRACTIONS, runs, drift[smooth]):
            rows.append(["yes" if smooth else "no", f"{f:g}", run.ms_per_step, f"{d:.2e}",
                         run.observables["broken bonds"],
                         f"{relative_error(run.observables['broken bonds'], broken0):.3f}"])
        rows.append(["yes" if smooth else "no", "order", "",
                     f"{order([r.dt for r in runs], drift[smooth]):.2f}", "", ""])
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for smooth, values in drift.items():
        ax.loglog(FRACTIONS, values, marker="o", label=f"smooth {'yes' if smooth else 'no'}")
    ax.set_xlabel("dt / stable_timestep")
    ax.set_ylabel("energy ledger drift / starting kinetic energy")
    ax.legend()
    return ("## Smoothing of breaking springs\n\n"
            f"The impact scene (quick size), estimate {estimate:.4g}; see "
            "`benchmarks/tradeoff_smoothing.py` for what is measured.\n\n"
            + table(["smooth", "dt / estimate", "ms/step", "ledger drift", "broken bonds",
                     "broken: error against the smallest dt"], rows)
            + "\n\n" + save_figure(fig, figures, "smoothing"))
