"""Run a LAMMPS deck in ase_bpm, every run of it: ``ase-bpm run DECK``.

:func:`run_lammps` reads the scene of the deck's first run
(:func:`ase_bpm.read_lammps`), then carries out each run in turn, with what
the deck changes between runs (:mod:`ase_bpm.scene.lammps_stages`), under
ase_bpm's velocity Verlet (``fix nve``; ``fix nve/sphere`` for spheres).
At the steps the deck's ``thermo N`` names (and at the start and end of
each run, as LAMMPS prints them) it gives the deck's thermo quantities that
ase_bpm has: the step, the atoms (fewer once atoms leave a fixed box), the
kinetic energy (``ke``: per atom where ``thermo_modify norm`` says so, as
LAMMPS' default in lj units; over the node volume for legacy PERI, whose
masses are densities, as LAMMPS gives it), the intact bonds and those
broken since the deck's first run (or gone with atoms lost), and the mean
damage of peridynamic scenes (LAMMPS' ``damage/atom``).
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np
from ase import Atoms

from ..core.bonds import get_bonds, stored
from ..core.spheres import RADIUS
from ..models.peri import BPMPeri
from .lammps_deck import Deck
from .lammps_read import read_first_run
from .lammps_setup import Reading
from .lammps_stages import (LAMMPS_ID, Progress, begin_stage, first_stage, later_stages,
                            stage_timestep)


@dataclass
class DeckRun:
    """What :func:`run_lammps` did: the ``atoms`` at the end, the thermo
    ``rows`` (dicts of :data:`COLUMNS` names), the deck's lines it
    ``ignored`` (``(line, command)``), the ``steps`` run and the wall time."""

    atoms: Atoms
    rows: list = field(default_factory=list)
    ignored: list = field(default_factory=list)
    steps: int = 0
    wall_seconds: float = 0.0


#: the thermo columns, with their LAMMPS names
COLUMNS = {"step": "Step", "atoms": "Atoms", "ke": "KinEng", "bonds": "Bonds",
           "broken": "Broken", "damage": "Damage"}


def ignored_lines(reading: Reading) -> list:
    """``(line, command)`` of the deck's lines that change nothing in ase_bpm
    (those read_lammps names as ignored), but for what run_lammps takes
    from them: ``thermo N`` (when it prints) and ``thermo_modify norm``
    (KinEng per atom)."""
    return [(number, " ".join(words)) for number, words in reading.ignored
            if words[0] != "thermo" and not (words[0] == "thermo_modify"
                                             and "norm" in words[1:-1])]


def thermo_rows(atoms: Atoms, normalise: bool, bonds_at_start: int | None = None,
                lammps_per_true_mass: float = 1.0) -> dict:
    """The thermo quantities of the atoms now (see :data:`COLUMNS`):
    ``broken``, the bonds intact at ``bonds_at_start`` (default: now) that
    are not now (broken, or gone with atoms lost); ``ke`` with the masses
    LAMMPS has, ``lammps_per_true_mass`` times the true ones (legacy PERI's
    are densities: one over the node volume)."""
    v_nc = atoms.get_velocities()
    ke = 0.5 * lammps_per_true_mass * float(np.einsum("n,nc,nc->", atoms.get_masses(), v_nc,
                                                      v_nc))
    row = {"step": int(atoms.info.get("bpm_step", 0)), "atoms": len(atoms),
           "ke": ke / max(len(atoms), 1) if normalise else ke}
    if stored(atoms):
        _, _, type_b = get_bonds(atoms, include_broken=True)
        row["bonds"] = int(np.count_nonzero(type_b))
        start = row["bonds"] if bonds_at_start is None else bonds_at_start
        row["broken"] = start - row["bonds"]
    if isinstance(atoms.calc, BPMPeri):  # (LAMMPS' damage/atom; BPMSpring's damage
        # counts the bonds still listed, and a lost atom takes its bonds along)
        row["damage"] = float(np.mean(atoms.arrays["damage"])) if len(atoms) else 0.0
    return row


def _normalised(prefix: Deck, units: str) -> bool:
    """``thermo_modify norm`` as it holds at the run (``thermo_style``
    resets it; default yes in lj units, no in others)."""
    norm = units == "lj"
    for _, words in prefix.commands:
        if words[0] == "thermo_style":
            norm = units == "lj"
        elif words[0] == "thermo_modify" and "norm" in words[:-1]:
            norm = words[words.index("norm") + 1] == "yes"
    return norm


def _thermo_every(prefix: Deck) -> int:
    found = prefix.last("thermo", ["0"])
    return int(found[0]) if found[0].isdigit() else 0


def run_lammps(deck: str | os.PathLike, data: str | os.PathLike | None = None, *,
               steps: int | None = None, output: str | None = None, progress: bool = False,
               echo=None) -> DeckRun:
    """Run every run of a LAMMPS ``deck`` in ase_bpm.  The scene of its
    first run is read as :func:`ase_bpm.read_lammps` reads it: ``data``
    stands for the file its ``read_data`` names (default: that file, next
    to the deck), and a deck that builds its scene has its set-up run in
    the LAMMPS Python module.

    ``steps``: stop after so many steps in all (default: every run to its
    end); ``output``: an extxyz file for ``ase gui`` or OVITO, a frame at
    each thermo row (:class:`ase_bpm.ViewerTrajectory`); ``progress``: a
    progress bar; ``echo(text)``: called with each thermo line (header
    first).  A line of the deck ase_bpm cannot carry out raises ValueError
    naming it before anything runs (ImportError where the set-up needs the
    LAMMPS module and it is missing)."""
    from tqdm import tqdm

    from .md import SphereVelocityVerlet, VelocityVerlet
    from .viewing import ViewerTrajectory

    atoms, reading = read_first_run(deck, data)
    stages = [first_stage(reading), *later_stages(atoms, reading)]
    atoms.arrays[LAMMPS_ID] = reading.ids_n
    result = DeckRun(atoms, ignored=ignored_lines(reading))
    integrator = SphereVelocityVerlet if atoms.has(RADIUS) else VelocityVerlet
    # (LAMMPS's masses per true mass: legacy PERI's f and mass are both densities)
    lammps_per_true_mass = 1.0 / reading.force_per_lammps_force
    writer = ViewerTrajectory(output, atoms) if output else None
    now, budget = Progress(), steps
    total = sum(s.steps if s.upto is None else 0 for s in stages)
    start = time.perf_counter()
    header = None
    try:
        with tqdm(total=steps if steps is not None else total or None, unit="step",
                  disable=not progress, file=sys.stderr) as bar:
            for stage in stages:
                if budget == 0:
                    break
                count = begin_stage(atoms, reading, stage, now)
                count = count if budget is None else min(count, budget)
                prefix = reading.deck.up_to(stage.end)
                dt = stage_timestep(prefix, reading)
                every = _thermo_every(prefix)
                norm = _normalised(prefix, reading.units)
                dyn = integrator(atoms, timestep=dt)
                for n, _ in enumerate(dyn.irun(count)):
                    if n == 0 or n == count or (every and (now.step + n) % every == 0):
                        row = thermo_rows(atoms, norm, result.rows[0].get("bonds")
                                          if result.rows else None, lammps_per_true_mass)
                        if header is None or header.keys() != row.keys():
                            header = row
                            if norm:
                                _echo(echo, "(KinEng per atom: thermo_modify norm yes, "
                                            "LAMMPS' default in lj units)", bar)
                            if lammps_per_true_mass != 1.0:
                                _echo(echo, "(KinEng as LAMMPS's legacy peri styles give it, "
                                            "their masses densities: the kinetic energy over "
                                            f"the node volume {reading.force_per_lammps_force:g})",
                                      bar)
                            _echo(echo, "  ".join(f"{COLUMNS[k]:>12}" for k in row), bar)
                        result.rows.append(row)
                        _echo(echo, "  ".join(_cell(v) for v in row.values()), bar)
                        if writer is not None and (n or not result.steps):
                            writer.write(time=now.time + n * dt)
                    if n:
                        bar.update(1)
                now.step += count
                now.time += count * dt
                result.steps += count
                if budget is not None:
                    budget -= count
    finally:
        if writer is not None:
            writer.close()
    result.wall_seconds = time.perf_counter() - start
    return result


def _cell(value) -> str:
    return f"{value:>12d}" if isinstance(value, int) else f"{value:>12.6g}"


def _echo(echo, text: str, bar) -> None:
    """``echo(text)``, above the progress bar."""
    if echo is None:
        return
    if bar.disable:
        echo(text)
    else:
        with bar.external_write_mode():
            echo(text)
