"""The neighbour skin: what it costs, and that it changes no result.

The contact list is rebuilt whenever an atom has moved more than half the
skin since the last build (spheres: away from their mean drift), so the
forces are exact whatever the skin: a thin
skin costs rebuilds, a thick one costs pairs checked every step.  Each demo
scene runs ``steps(scene, quick)`` steps at its own timestep (the impact and the
shatter into the contact, the pour its falling half) with the skin at ``FACTORS``
times the calculator's default; the table gives the cost per step, the
rebuilds and the largest difference of the final forces from the default
skin's run, over the largest force (round-off: the pairs are summed in
another order).
"""

from __future__ import annotations

from tradeoff_common import pyplot, save_figure, table, timed

from pathlib import Path

import numpy as np

from tradeoff_scenes import Pour, scenes

#: skins tried, as multiples of the calculator's default
FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0)
#: steps of the impact and shatter runs (quick, full); the pour runs half its duration
STEPS = {True: 500, False: 1000}

#: filled by ``section``: scene name -> the cheapest skin factor
CHEAPEST: dict = {}


def verlet_list(calc):
    """The calculator's contact neighbour list (private attributes: each
    model keeps its own; a benchmark may look)."""
    for name in ("_search", "_contact_list", "_contacts"):
        found = getattr(calc, name, None)
        if found is not None and not callable(found):
            return getattr(found, "neighbours", found)
    raise LookupError(f"{type(calc).__name__} keeps no contact list")


def steps(scene, quick: bool) -> int:
    if isinstance(scene, Pour):
        return round(0.5 * scene.duration / scene.demo_dt)
    return STEPS[quick]


def run(scene, count: int, skin: float | None):
    """ms/step, rebuilds, final forces and the skin used."""
    atoms = scene.build()
    if skin is not None:
        atoms.calc.set(skin=skin)
    dyn = scene.integrator(atoms, scene.demo_dt)
    atoms.get_forces()  # setup, untimed
    _, seconds = timed(dyn.run, count)
    search = verlet_list(atoms.calc)
    return 1e3 * seconds / count, search.nbuilds, atoms.get_forces().copy(), search.skin


def section(quick: bool, figures: Path) -> str:
    parts, curves = [], {}
    for scene in scenes(quick):
        count = steps(scene, quick)
        ms0, builds0, f0_nc, default = run(scene, count, None)
        rows, costs = [], []
        for factor in FACTORS:
            if factor == 1.0:
                ms, builds, f_nc = ms0, builds0, f0_nc
            else:
                ms, builds, f_nc, _ = run(scene, count, factor * default)
            diff = float(np.abs(f_nc - f0_nc).max() / max(np.abs(f0_nc).max(), 1e-300))
            rows.append([f"{factor:g}", f"{factor * default:.4g}", ms, builds, f"{diff:.1e}"])
            costs.append(ms)
        CHEAPEST[scene.name] = FACTORS[int(np.argmin(costs))]
        curves[scene.name] = costs
        parts.append(f"### {scene.name}\n\n{count} steps at dt {scene.demo_dt:g}; default "
                     f"skin {default:.4g}.\n\n"
                     + table(["skin / default", "skin", "ms/step", "rebuilds",
                              "force difference"], rows))
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for name, costs in curves.items():
        ax.plot(FACTORS, np.asarray(costs) / costs[FACTORS.index(1.0)], marker="o", label=name)
    ax.set_xscale("log")
    ax.set_xlabel("skin / default")
    ax.set_ylabel("cost per step / cost at the default")
    ax.legend()
    return ("## Neighbour skin and rebuilds\n\n"
            "The skin changes the cost, never the forces (see "
            "`benchmarks/tradeoff_skin.py`): the force difference is round-off.\n\n"
            + "\n\n".join(parts) + "\n\n" + save_figure(fig, figures, "skin"))
