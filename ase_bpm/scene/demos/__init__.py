"""Demo scenes, run by the ``ase-bpm demo`` command."""

from __future__ import annotations

import importlib
from typing import Callable

#: the demos, by name: their modules in this package
DEMOS = ("impact", "shatter", "pour")


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
