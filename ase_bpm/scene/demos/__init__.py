"""Demo scenes, run by the ``ase-bpm demo`` command."""

from __future__ import annotations

import importlib
from typing import Callable, Sequence

import numpy as np

#: the demos, by name: their modules in this package
DEMOS = ("impact", "shatter", "pour")
#: the time axis of the demos in reduced (LJ) units
REDUCED_TIME = "time (\N{GREEK SMALL LETTER TAU}, reduced LJ units)"
#: resolution of the demos' PNG files (dots per inch)
DPI = 120
#: the colours of damage in the demos' pictures: blue intact, red broken off
DAMAGE_COLOURS = "coolwarm"


def export_demo(name: str, stem: str | None = None, quick: bool = False,
                steps: int | None = None) -> tuple[str, str]:
    """Write demo ``name``'s scene for LAMMPS (:func:`ase_bpm.write_lammps`):
    ``<stem>.data`` and ``in.<stem>`` (stem: the demo's name), a run of
    ``steps`` (the demo's own by default) with its timestep.  Returns both
    paths."""
    from ..lammps import write_lammps

    if name not in DEMOS:
        raise ValueError(f"no demo {name!r}: the demos are {', '.join(DEMOS)}")
    demo = importlib.import_module(f"{__name__}.{name}")
    if steps is None:
        steps = getattr(demo, "QUICK_STEPS", demo.STEPS) if quick else demo.STEPS
    return write_lammps(stem or name, demo.demo_scene(quick), timestep=demo.TIMESTEP,
                        steps=steps)


def drive(dyn, steps: int, *, label: str, record: Callable[[int], None], sample: int,
          writer=None, every: int = 1, timestep: float = 1.0,
          progress: bool = True) -> float:
    """Run the integrator ``dyn`` for ``steps`` steps under a progress bar.

    ``record(n)`` is called at step 0, every ``sample`` steps and at the end;
    ``writer`` (a :class:`ase_bpm.ViewerTrajectory`, closed afterwards) gets a
    frame, with its time, at the same moments every ``every`` steps.
    Returns the wall time in seconds.
    """
    import time

    from tqdm import tqdm

    start = time.perf_counter()
    with tqdm(total=steps, desc=label, unit="step", disable=not progress) as bar:
        for n, _ in enumerate(dyn.irun(steps)):
            if n % sample == 0 or n == steps:
                record(n)
            if writer is not None and (n % every == 0 or n == steps):
                writer.write(time=n * timestep)
            if n:
                bar.update(1)
    wall = time.perf_counter() - start
    if writer is not None:
        writer.close()
    return wall


def save_figure(fig, filename: str):
    """Write the matplotlib figure ``fig`` as a PNG; returns ``fig``."""
    fig.savefig(filename, dpi=DPI)
    return fig


def picture(atoms, values, filename: str, *, title: str, label: str, limits: Sequence[float],
            cmap: str = "viridis", rotation: str = "", radii=None, extend: str = "neither",
            size: Sequence[float] = (6.4, 5.6)):
    """The particles of ``atoms`` drawn as discs (``ase.visualize.plot``), seen
    after ``rotation`` (ASE's rotation string) at their ``radii`` (distance
    units), each coloured by its value of ``values`` through ``cmap`` between
    ``limits``; a ``title`` above and a colour bar saying what the colours
    mean (``label``; ``extend`` "max" where values beyond the top share its
    colour), saved as the PNG ``filename``.  Returns the matplotlib figure."""
    from ase.visualize.plot import plot_atoms
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    norm, colours = Normalize(*limits), colormaps[cmap]
    fig = Figure(figsize=size)
    ax = fig.add_subplot()
    plot_atoms(atoms, ax, rotation=rotation, radii=radii,
               colors=colours(norm(np.asarray(values, dtype=float)))[:, :3])
    ax.set_axis_off()
    ax.set_title(title)
    fig.colorbar(ScalarMappable(norm, colours), ax=ax, label=label, extend=extend, shrink=0.8)
    return save_figure(fig, filename)
