"""Advice per demo: the cheapest settings that keep every observable within 1 %.

Read off the timestep section (run here if it has not run) and the skin
section (if it ran).  For each demo scene the candidate settings are the
timesteps tried there; the advice is the cheapest (seconds per unit of
simulated time) whose every error is within ``TARGET``, counting only the
observables that the timestep decides to that precision.  An observable is
listed apart, as chaotic, when its chaos floor (two runs at the same
timestep from starts a millionth apart) is itself beyond ``TARGET``, or when
its errors exceed ``TARGET`` without falling as the timestep falls (order at
most ``MIN_ORDER``): then the run-to-run spread, not the timestep, sets
them, and no timestep brings one run closer to one reference run.
"""

from __future__ import annotations

from tradeoff_common import order, table

from pathlib import Path

import tradeoff_skin
import tradeoff_timestep
from tradeoff_scenes import scenes
from tradeoff_timestep import FRACTIONS, MIN_ORDER, REFERENCE_FRACTION, TARGET


def chaotic(name: str, result) -> bool:
    """Is ``name`` set by the run-to-run spread rather than by the timestep?"""
    runs, errors = result["runs"], result["errors"]
    error_r = [errors[f][name] for f in FRACTIONS]
    if result["floor"][name] > TARGET:
        return True
    converging = order([runs[f].dt for f in FRACTIONS], error_r) > MIN_ORDER
    return max(error_r) > TARGET and not converging


def advise(scene, result) -> list:
    floor, errors = result["floor"], result["errors"]
    told = [n for n in floor if not chaotic(n, result)]
    spread = [f"{n} (floor {floor[n]:.1%}, errors {min(errors[f][n] for f in FRACTIONS):.1%}"
              f"-{max(errors[f][n] for f in FRACTIONS):.1%})" for n in floor if n not in told]
    ok = [key for key, errors in result["errors"].items()
          if all(errors[n] <= TARGET for n in told)]
    runs = result["runs"]
    if ok:
        best = min(ok, key=lambda key: runs[key].seconds)
        run = runs[best]
        worst = max(result["errors"][best][n] for n in told)
    else:
        best, run, worst = None, result["reference"], 0.0
    estimate = result["estimate"]
    reference_cost = result["reference"].seconds
    skin = tradeoff_skin.CHEAPEST.get(scene.name)
    return [scene.name,
            f"{run.dt:.4g} ({run.dt / estimate:.2f} of the estimate"
            + (", the demo's)" if best == "demo" else ")")
            + ("" if ok else f": no tried timestep above {REFERENCE_FRACTION} of it"),
            f"{run.seconds:.3g} s ({reference_cost / run.seconds:.1f}x faster than the "
            "reference)",
            f"{worst:.2%}",
            "default" if skin in (None, 1.0) else f"{skin:g} x default",
            ", ".join(told) or "none",
            ", ".join(spread) or "none"]


def section(quick: bool, figures: Path) -> str:
    if not tradeoff_timestep.RESULTS:
        for scene in scenes(quick):
            tradeoff_timestep.RESULTS[scene.name] = (scene, tradeoff_timestep.sweep(scene))
    rows = [advise(scene, result) for scene, result in tradeoff_timestep.RESULTS.values()]
    return ("## Advice per demo\n\n"
            f"The cheapest settings tried that keep every observable within {TARGET:.0%} "
            "of the reference (`benchmarks/tradeoff_advice.py`).  Observables that chaos "
            "rather than the timestep sets (a chaos floor beyond 1 %, or errors beyond it "
            "that do not fall with the timestep) are listed apart with their floor and "
            "the range of their errors: for them a single run is a sample, and several "
            "runs (other seeds) give the spread.  "
            "The skin is the cheapest of the skin section (it changes no result); "
            "use the compiled kernels where they are built (they agree with NumPy to "
            "round-off, and are faster).\n\n"
            + table(["demo", "timestep", "run time", "largest error",
                     "skin", "within 1 %", "beyond one run's resolution (chaos floor)"],
                    rows))
