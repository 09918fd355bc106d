"""Decks between the cases the example twins pick: a fix on a group after a
run, '$' substitution, 'run v_n', two granular walls on one axis, and a
legacy PERI deck saved before its first step (found by review)."""

import warnings
from pathlib import Path

import numpy as np
import pytest

import ase_bpm
from ase_bpm.scene.lammps_read import read_lammps

DECKS = Path(__file__).parent / "decks"
PMB = DECKS / "in.twin.peri.pmb"


def deck_with(tmp_path, before_run=(), after_run=()) -> str:
    """The pmb twin with lines put before its run and after it."""
    lines = PMB.read_text().splitlines()
    run = next(k for k, line in enumerate(lines) if line.startswith("run"))
    path = tmp_path / "in.edge"
    path.write_text("\n".join([*lines[:run], *before_run, lines[run], *after_run]) + "\n")
    return str(path)


def read_quietly(deck):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_lammps(deck)


@pytest.mark.oracle
@pytest.mark.parametrize("where", ["before_run", "after_run"])
@pytest.mark.parametrize("fix", ["fix 3 top gravity 9.8 vector 0 -1 0",
                                 "fix 2 top indent 1e17 sphere 0.0 0.01 0.0 0.0015 units box"])
def test_a_force_fix_on_a_group_is_refused_by_line(Oracle, tmp_path, where, fix):
    """LAMMPS applies it to the group only; ase_bpm's fixes act on every atom.
    After a run it was dropped without a word (and fix 2 kept the old
    indenter)."""
    lines = ["group top id 1:50", fix] + (["run 10"] if where == "after_run" else [])
    deck = deck_with(tmp_path, **{where: lines})
    with pytest.raises(ValueError, match=rf"line \d+: '{fix.split()[0]} {fix.split()[1]} top "
                                         rf".*acts on every atom, not on a group"):
        read_quietly(deck)


@pytest.mark.parametrize("line, words", [
    ("variable s equal 0.0005\nlattice sc ${s}", r"'lattice sc \$\{s\}': '\$' puts a "
                                                 r"variable's value into the line"),
    ("run v_n", r"'run v_n': read_lammps reads 'run N' with N a number of steps")])
def test_substitution_and_a_run_of_a_variable_are_refused_by_line(tmp_path, line, words):
    deck = deck_with(tmp_path, after_run=line.splitlines())
    with pytest.raises(ValueError, match=words):
        read_quietly(deck)


def test_a_dollar_in_an_ignored_line_is_left_to_it(tmp_path):
    deck = deck_with(tmp_path, before_run=['print "step $s"'])
    with pytest.warns(ase_bpm.IgnoredCommandsWarning, match="print"):
        read_lammps(deck)


@pytest.mark.oracle
def test_two_walls_on_one_axis_run_as_in_lammps(Oracle):
    """A floor and a ceiling on z, each named after its fix ID: they keep
    their contacts apart (both shared gran_wall_z before, and the run
    stopped at its first evaluation)."""
    from deck_oracle import position_error, run_deck_for

    deck = str(DECKS / "in.two.walls")
    steps = 800
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = ase_bpm.run_lammps(deck, steps=steps)
    assert sorted(f.name for f in result.atoms.calc.fixes if hasattr(f, "name")) == \
        ["ceiling", "floor"]
    lmp = run_deck_for(deck, steps)
    try:
        assert position_error(lmp, result.atoms) <= 1e-9  # (diameter 1)
    finally:
        lmp.close()
    # (without walls, gravity alone: v_z = -1 - t (lower layer), 1 - t (upper), t = 0.8)
    v_z = result.atoms.get_velocities()[:, 2]
    upper = result.atoms.positions[:, 2] > 1.5
    assert np.all(np.abs(v_z[~upper]) < 0.05)  # the floor stopped the lower layer
    assert np.all(v_z[upper] < -0.3)  # the ceiling threw the upper one down


@pytest.mark.oracle
def test_a_legacy_deck_saved_before_its_first_step_stays_legacy(Oracle, tmp_path):
    """read_lammps records which LAMMPS the atoms follow at once: a restart
    written before any step, given a BPMPeri without follows=, runs legacy
    PERI (it ran bpm/peri's)."""
    atoms = read_quietly(str(PMB))
    assert atoms.calc.parameters["follows"] == "legacy"
    ase_bpm.write_restart(str(tmp_path / "saved.npz"), atoms)
    again = ase_bpm.read_restart(str(tmp_path / "saved.npz"))
    p = atoms.calc.parameters
    fresh = ase_bpm.BPMPeri(bond_coeffs=p["bond_coeffs"], pair_coeffs=p["pair_coeffs"])
    assert fresh.followed(again) == "legacy"
    assert fresh.followed(atoms.copy()) == "legacy"
    assert np.array_equal(again.positions, atoms.positions)
