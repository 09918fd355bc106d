"""LAMMPS's own example decks, read by ``read_lammps`` as shipped, where the
environment variable ``ASE_BPM_LAMMPS_EXAMPLES`` names a folder holding
LAMMPS's ``examples/`` tree (skipped otherwise, in CI too: the decks are
LAMMPS's, GPL, and not part of this repository; CI runs their twins,
``test_lammps_decks.py``).

Each deck the reference build runs is run by LAMMPS itself (its first run
shortened to 100 steps) and by ase_bpm from what ``read_lammps`` gives: the
positions agree to 1e-9 of the lattice spacing or the diameter.  The
bpm/peri decks, which the reference build cannot run, are held against the
rows of LAMMPS's published logs.
"""

import os
from pathlib import Path

import numpy as np
import pytest

import ase_bpm
from ase_bpm.scene import lammps_setup
from test_lammps_decks import (SPACING, STEPS, advance, pile_runs_as_in_lammps,
                               pour_in_lammps, read,
                               the_deck_out_reads_back_as_the_scene,
                               the_deck_out_runs_to_our_forces)

FOLDER = os.environ.get("ASE_BPM_LAMMPS_EXAMPLES")
pytestmark = [pytest.mark.skipif(not FOLDER, reason="ASE_BPM_LAMMPS_EXAMPLES names no "
                                 "folder holding LAMMPS's examples/ tree"),
              pytest.mark.oracle]
EXAMPLES = Path(FOLDER or ".") / "examples"

def read_shipped(deck):
    """read_lammps of a shipped deck."""
    return read(str(deck))[0]


def deck(path):
    path = EXAMPLES / path
    if not path.exists():
        pytest.skip(f"{path} is not in ASE_BPM_LAMMPS_EXAMPLES")
    return path


RUNS = {"bpm/impact/in.bpm.impact.spring": 1.0, "bpm/impact/in.bpm.impact.rotational": 1.0,
        **{f"peri/in.peri.{m}": SPACING for m in ("pmb", "lps", "ves", "eps")},
        "bpm/peri/benchmark/in.bench.legacy.pmb": SPACING}


#: how close the positions come, in those lengths (1e-9 where not listed; the
#: rotational impact's plate rests: test_lammps_decks.TWIN_TOLERANCE says why)
TOLERANCE = {"bpm/impact/in.bpm.impact.rotational": 1e-8}


@pytest.mark.parametrize("name", list(RUNS))
def test_a_shipped_deck_runs_in_ase_bpm_as_in_lammps(Oracle, name):
    from deck_oracle import position_error, run_deck_for

    path = deck(name)
    atoms = read_shipped(path)
    start = atoms.positions.copy()
    advance(atoms)
    lmp = run_deck_for(str(path), STEPS)
    try:
        assert lmp.get_natoms() == len(atoms)
        assert position_error(lmp, atoms) <= TOLERANCE.get(name, 1e-9) * RUNS[name]
    finally:
        lmp.close()
    if "benchmark" not in name:  # (the benchmark's block rests at its reference state)
        assert np.abs(atoms.positions - start).max() > 1e-3 * RUNS[name]


@pytest.mark.parametrize("name", [f"bpm/peri/in.bpm.peri.{m}" for m in
                                  ("pmb", "lps", "ves", "eps")]
                         + ["bpm/peri/benchmark/in.bench.bpm.pmb"])
def test_a_shipped_bpm_peri_deck_builds_its_scene(Oracle, name):
    """The scene the deck builds (LAMMPS's set-up with pair zero and bond
    zero standing in for the bpm/peri styles): node volume and mass as the
    deck sets them, bonds within the horizon; then the whole deck."""
    path = deck(name)
    atoms, _ = lammps_setup.read_scene(str(path))
    periodic = "benchmark" in name
    assert len(atoms) == (16 ** 3 if periodic else 3487)  # (3487: as in.peri.* builds)
    assert np.all(atoms.arrays["vfrac"] == 1.25e-10)
    assert np.all(atoms.get_masses() == 2.75e-7)
    i, j, _ = ase_bpm.get_bonds(atoms)
    within = atoms.copy()
    ase_bpm.create_bonds(within, 0.0015001)
    k, m, _ = ase_bpm.get_bonds(within)
    assert {tuple(sorted(b)) for b in zip(i, j)} == {tuple(sorted(b)) for b in zip(k, m)}
    if periodic:
        assert len(i) == 16 ** 3 * 122 // 2  # (122 bonds per node, as its README says)
    assert isinstance(read_shipped(path).calc, ase_bpm.BPMPeri)


#: rows of LAMMPS's published logs of examples/bpm/peri (23 Aug 2026, the same
#: for pmb, lps, ves and eps): step -> (atoms in the box, mean damage)
PUBLISHED_ROWS = {200: (3403, 0.012456098)}
#: the last digit the logs print of the damage
LOG_DIGIT = 1e-9


def test_the_shipped_bpm_peri_deck_runs_to_its_published_log(Oracle):
    """ase-bpm run of in.bpm.peri.pmb as shipped: the indenter throws nodes
    out of the fixed box, LostAtoms removes them as LAMMPS's thermo_modify
    lost ignore does, and the rows are the log's (atoms; damage to the
    digits it prints, half a unit of its last)."""
    result = ase_bpm.run_lammps(str(deck("bpm/peri/in.bpm.peri.pmb")),
                                steps=max(PUBLISHED_ROWS))
    rows = {row["step"]: row for row in result.rows}
    for step, (atoms, damage) in PUBLISHED_ROWS.items():
        assert rows[step]["atoms"] == atoms
        assert rows[step]["damage"] == pytest.approx(damage, rel=0, abs=LOG_DIGIT / 2)


def test_the_shipped_pour_is_refused_naming_fix_pour():
    with pytest.raises(ValueError, match=r"in.pour line 30: 'fix ins all pour 3000 1 300719 "
                                         r"vol 0.13 50 region slab': inserts particles"):
        ase_bpm.read_lammps(str(deck("pour/in.pour")))


def test_the_pile_the_shipped_pour_makes_runs_in_ase_bpm_as_in_lammps(Oracle, tmp_path):
    """LAMMPS pours with the shipped deck (POUR_STEPS steps), write_data
    keeps the pile, and our deck of its chute stage (the shipped deck's
    styles and coefficients) runs it in both codes."""
    pile_runs_as_in_lammps(pour_in_lammps(deck("pour/in.pour"), tmp_path))


BPM_PERI = [f"bpm/peri/in.bpm.peri.{m}" for m in ("pmb", "lps", "ves", "eps")] + [
    "bpm/peri/benchmark/in.bench.bpm.pmb"]


@pytest.mark.parametrize("name", [*RUNS, *BPM_PERI, "pour/in.pour"])
def test_a_scene_read_from_a_shipped_deck_goes_out_as_a_deck(Oracle, tmp_path, name):
    """Decks in, decks out: write_lammps of what read_lammps gives runs in the
    reference build to ase_bpm's forces; a bpm/peri deck's reads back as the
    same scene (in.pour: the pile LAMMPS pours with it, its box fixed at the
    bottom only, boundary p p fm)."""
    if name == "pour/in.pour":
        atoms = read_shipped(pour_in_lammps(deck(name), tmp_path))
        the_deck_out_runs_to_our_forces(atoms, tmp_path, 2 * atoms.arrays["radius"].min())
    elif name in BPM_PERI:
        the_deck_out_reads_back_as_the_scene(read_shipped(deck(name)), tmp_path, SPACING)
    else:
        the_deck_out_runs_to_our_forces(read_shipped(deck(name)), tmp_path, RUNS[name])
