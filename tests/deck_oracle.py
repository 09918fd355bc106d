"""LAMMPS running an input deck as a user would, for comparison with
``read_lammps`` of the same deck: LAMMPS reads the deck's own text up to its
first run, which this harness shortens (and, for the legacy state-based PERI
styles, repairs first: ``s0``, see ``peri_oracle.PeriOracle``)."""

from __future__ import annotations

import os
import tempfile

import numpy as np

from ase_bpm.core.neighbours import minimum_image
from ase_bpm.scene.lammps_deck import read_deck
from oracle import QUIET, gather, load_lammps

#: the legacy styles whose breaking stretch s0 the reference build leaves unset
REPAIR_S0 = ("peri/lps", "peri/ves", "peri/eps")


def run_setup(deck: str):
    """A LAMMPS instance that has read the deck's lines before its first run
    (in the deck's folder, as ``lmp -in`` there would); the caller closes it."""
    commands = read_deck(deck)
    first = commands.first_run()
    stop = commands.commands[first][0] if first < len(commands.commands) else None
    with open(deck) as fh:
        lines = fh.read().splitlines()
    head = lines if stop is None else lines[:stop - 1]
    lmp = load_lammps()(cmdargs=QUIET)
    cwd = os.getcwd()
    with tempfile.NamedTemporaryFile("w", suffix=".in", delete=False) as fh:
        fh.write("\n".join(head) + "\n")
    try:
        os.chdir(os.path.dirname(os.path.abspath(deck)))
        lmp.file(fh.name)
    finally:
        os.chdir(cwd)
        os.unlink(fh.name)
    if any(w[:2] in (["pair_style", s] for s in REPAIR_S0) for _, w in commands.commands):
        lmp.command("run 0")
        lmp.numpy.extract_atom("s0")[:lmp.extract_global("nlocal")] = np.finfo(float).max
        lmp.command("run 0")
    return lmp


def run_deck_for(deck: str, steps: int):
    """A LAMMPS instance that has run the deck's set-up, then ``steps``
    steps (its first run, shortened); the caller closes it."""
    lmp = run_setup(deck)
    lmp.command(f"run {steps}")
    return lmp


def position_error(lmp, atoms) -> float:
    """The largest distance between LAMMPS' atoms and ``atoms`` (in atom-ID
    order), minimum image under periodic boundaries."""
    d = minimum_image(gather(lmp, "x") - atoms.positions, atoms.cell.array, atoms.pbc)
    return float(np.linalg.norm(d, axis=1).max())
