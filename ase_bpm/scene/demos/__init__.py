"""Demo scenes, run by the ``ase-bpm demo`` command."""

from __future__ import annotations

import importlib
from typing import Callable, Sequence

import numpy as np

#: the demos, by name: their modules in this package
DEMOS = ("impact", "shatter", "pour", "beam")
#: the demos ``ase-bpm export`` writes for LAMMPS (the beam's two wires have
#: bonds of two bond styles, which no one LAMMPS deck holds)
EXPORTS = ("impact", "shatter", "pour")
#: the time axis of the demos in reduced (LJ) units
REDUCED_TIME = "time (\N{GREEK SMALL LETTER TAU}, reduced LJ units)"
#: resolution of the demos' PNG files (dots per inch)
DPI = 120
#: the colours of damage in the demos' pictures: blue intact, red broken off
DAMAGE_COLOURS = "coolwarm"
#: the colour of particles a picture shows for context, outside its colour
#: scale (dark grey, RGB: no colour of DAMAGE_COLOURS)
CONTEXT_COLOUR = (0.3, 0.3, 0.3)


def export_demo(name: str, stem: str | None = None, quick: bool = False,
                steps: int | None = None, bonds: str | None = None) -> tuple[str, str]:
    """Write demo ``name``'s scene for LAMMPS (:func:`ase_bpm.write_lammps`):
    ``<stem>.data`` and ``in.<stem>`` (stem: the demo's name), a run of
    ``steps`` (the demo's own by default) with its timestep.  ``bonds``: the
    impact demo's choice of bonds ("spring", the default, or "rotational").
    Returns both paths."""
    from ..lammps import write_lammps

    if name not in EXPORTS:
        raise ValueError(f"no demo {name!r} to export: the demos written for LAMMPS are "
                         f"{', '.join(EXPORTS)}")
    demo = importlib.import_module(f"{__name__}.{name}")
    if bonds is not None and name != "impact":
        raise ValueError(f"--bonds {bonds}: only the impact demo has a choice of bonds, "
                         f"not {name}")
    if bonds is None:
        timestep, full, quick_steps = (demo.TIMESTEP, demo.STEPS,
                                       getattr(demo, "QUICK_STEPS", demo.STEPS))
        atoms = demo.demo_scene(quick)
    else:
        timestep, full, quick_steps = demo.variant(bonds)
        atoms = demo.demo_scene(quick, bonds)
    if steps is None:
        steps = quick_steps if quick else full
    return write_lammps(stem or name, atoms, timestep=timestep, steps=steps)


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
            size: Sequence[float] = (6.4, 5.6), context=None):
    """The particles of ``atoms`` drawn as discs (``ase.visualize.plot``), seen
    after ``rotation`` (ASE's rotation string) at their ``radii`` (distance
    units), each coloured by its value of ``values`` through ``cmap`` between
    ``limits``; a ``title`` above and a colour bar saying what the colours
    mean (``label``; ``extend`` "max" where values beyond the top share its
    colour), saved as the PNG ``filename``.  ``context``: a mask of particles
    drawn in :data:`CONTEXT_COLOUR` instead, outside the colour scale (shown
    for where they are).  Returns the matplotlib figure."""
    from ase.visualize.plot import plot_atoms
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    norm, colours = Normalize(*limits), colormaps[cmap]
    rgb_n = colours(norm(np.asarray(values, dtype=float)))[:, :3]
    if context is not None:
        rgb_n[np.asarray(context, dtype=bool)] = CONTEXT_COLOUR
    fig = Figure(figsize=size)
    ax = fig.add_subplot()
    plot_atoms(atoms, ax, rotation=rotation, radii=radii, colors=rgb_n)
    ax.set_axis_off()
    ax.set_title(title)
    fig.colorbar(ScalarMappable(norm, colours), ax=ax, label=label, extend=extend, shrink=0.8)
    return save_figure(fig, filename)
