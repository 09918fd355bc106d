"""The timestep: each demo run from a tenth of ``stable_timestep`` to the estimate.

For each demo scene (``tradeoff_scenes``) the reference is a run at a tenth
of the estimate; runs at ``FRACTIONS`` of it and at the demo's own timestep
are compared with it on what a user reads off the run, and on the energy
ledger.  A run at ``CHAOS_FRACTION`` whose positions start moved by
``NUDGE`` (relative to the scene's length scale, about the size of the
timestep's own trajectory error there) shows the floor that chaos puts
under the comparison: an error near that floor is not the timestep's
alone, and any perturbation of that size would cause it.  The errors:

* scalar observables (broken bonds, fragments, packing fraction...):
  ``|x - x_ref| / |x_ref|``;
* the damage histogram: total variation distance, ``0.5 sum |p - p_ref|``
  over the bins (the fraction of atoms that would have to change bins);
* kinetic energy history: ``max_t |K - K_ref| / max_t K_ref``;
* early trajectory: the RMS position difference at the scene's horizon
  (impact: 50 time units, some 20 into the contact; shatter and pour: a
  tenth of the run), over the scene's length scale;
* energy ledger drift (the run alone): ``max_t |L(t) - L(0)| / max_t K_ref``
  with ``L`` kinetic plus potential energy plus what damping took and
  broken bonds released (the shatter indenter does work on the cylinder
  that the ledger does not book: no drift is given for it).

The convergence order is the slope of ``log error`` against ``log dt``
over the runs below the estimate.  The reference is not exact: where the
order ``p`` is positive, Richardson's estimate of its own error is
``e(2 dt_ref) / (2^p - 1)``, given in the table.
"""

from __future__ import annotations

from tradeoff_common import order, pyplot, relative_error, save_figure, table

from pathlib import Path

import numpy as np

from tradeoff_scenes import Impact, Pour, Shatter, scenes, simulate

#: the reference's timestep, as a fraction of the estimate
REFERENCE_FRACTION = 0.1
#: the compared runs, as fractions of the estimate
FRACTIONS = (0.2, 0.5, 1.0)
#: the chaos-floor run: this fraction, positions nudged by NUDGE
CHAOS_FRACTION = 0.2
NUDGE = 1e-6
#: below this order an error is not taken to converge (no Richardson estimate)
MIN_ORDER = 0.5
#: advice: every error within this
TARGET = 0.01
#: length scales for the trajectory error
LENGTH = {Impact: 4 ** (1 / 3), Shatter: 0.0005, Pour: 1.0}

#: filled by ``section``, read by the advice section
RESULTS: dict = {}


def errors(run, ref, scene) -> dict:
    """Each error of ``run`` against the reference ``ref`` (module doc)."""
    out = {}
    for name, value in run.observables.items():
        reference = ref.observables[name]
        if np.ndim(value):
            out[name] = 0.5 * float(np.abs(np.asarray(value) - reference).sum())
        else:
            out[name] = relative_error(value, reference)
    scale = ref.kinetic_n.max()
    out["kinetic energy history"] = float(np.abs(run.kinetic_n - ref.kinetic_n).max() / scale)
    d_nc = run.early_nc - ref.early_nc
    out["early trajectory"] = float(np.sqrt((d_nc ** 2).sum(axis=1).mean())
                                    / LENGTH[type(scene)])
    if not isinstance(scene, Shatter):
        out["energy ledger drift"] = float(np.abs(run.ledger_n - run.ledger_n[0]).max() / scale)
    return out


def sweep(scene) -> dict:
    """The reference, the runs, the chaos floor and their errors."""
    estimate = scene.estimate()
    ref = simulate(scene, REFERENCE_FRACTION * estimate)
    runs = {f: simulate(scene, f * estimate) for f in FRACTIONS}
    runs["demo"] = simulate(scene, scene.demo_dt)
    chaos = simulate(scene, CHAOS_FRACTION * estimate, nudge=NUDGE * LENGTH[type(scene)])
    return {"estimate": estimate, "reference": ref, "runs": runs,
            "errors": {key: errors(run, ref, scene) for key, run in runs.items()},
            "floor": errors(chaos, runs[CHAOS_FRACTION], scene)}


def scene_text(scene, result) -> str:
    estimate, ref, runs = result["estimate"], result["reference"], result["runs"]
    keys = list(runs)
    names = list(result["errors"][keys[0]])
    headers = ["dt / estimate", "dt", "ms/step", "s per unit time"] + names
    rows = []
    for key in keys:
        run = runs[key]
        label = f"{run.dt / estimate:.3g}" + (" (demo)" if key == "demo" else "")
        rows.append([label, f"{run.dt:.4g}", run.ms_per_step, run.seconds / scene.duration]
                    + [result["errors"][key][name] for name in names])
    rows.append(["chaos floor", "", "", ""] + [result["floor"][n] for n in names])
    below = [k for k in FRACTIONS]
    orders = [order([runs[k].dt for k in below], [result["errors"][k][n] for k in below])
              for n in names]
    rows.append(["order", "", "", ""] + [f"{o:.2f}" for o in orders])
    doubled = result["errors"][2 * REFERENCE_FRACTION]
    rows.append(["reference's own error", "", "", ""]
                + [f"{doubled[n] / (2 ** o - 1):.2g}" if o > MIN_ORDER else ""
                   for n, o in zip(names, orders)])
    return (f"### {scene.name}\n\n"
            f"Estimate {estimate:.4g}; the demo runs at {scene.demo_dt:.4g} "
            f"({scene.demo_dt / estimate:.2f} of it).  Reference: {ref.steps} steps of "
            f"{ref.dt:.4g} over {scene.duration:.4g} time units, {ref.ms_per_step:.3g} ms/step; "
            f"its values: "
            + ", ".join(f"{n} {v:.4g}" for n, v in ref.observables.items() if not np.ndim(v))
            + ".\n\n" + table(headers, rows))


def plot(results: dict, figures: Path) -> str:
    plt = pyplot()
    fig, axes = plt.subplots(1, len(results), figsize=(5 * len(results), 4), squeeze=False)
    for ax, (name, result) in zip(axes[0], results.items()):
        fractions = list(FRACTIONS)
        for observable in result["errors"][fractions[0]]:
            err = [result["errors"][f][observable] for f in fractions]
            ax.loglog(fractions, np.maximum(err, 1e-12), marker="o", label=observable)
        ax.axhline(TARGET, color="k", linestyle=":", linewidth=1)
        ax.set_title(name)
        ax.set_xlabel("dt / stable_timestep")
        ax.set_ylabel("error against the reference")
        ax.legend(fontsize=7)
    return save_figure(fig, figures, "timestep")


def section(quick: bool, figures: Path) -> str:
    results = {}
    for scene in scenes(quick):
        results[scene.name] = sweep(scene)
        RESULTS[scene.name] = (scene, results[scene.name])
    parts = [scene_text(scene, result) for scene, result in RESULTS.values()]
    return ("## The timestep\n\n"
            f"Each demo scene{' (--quick sizes)' if quick else ''} at fractions "
            "of its stable-timestep estimate and at its own timestep, against a run at "
            f"{REFERENCE_FRACTION} of the estimate; the errors are defined in "
            "`benchmarks/tradeoff_timestep.py`.  The chaos floor compares two runs at "
            f"{CHAOS_FRACTION} of the estimate whose starts differ by {NUDGE:g} of the "
            "length scale: errors near it come from chaos, not from the timestep alone.  "
            "The order is the slope of log error against log dt.\n\n"
            + "\n\n".join(parts) + "\n\n" + plot(results, figures))
