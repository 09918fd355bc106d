"""Decks of LAMMPS's BPM package that carry orientations: ``atom_style
bpm/sphere`` and ``fix nve/bpm/sphere`` are read (as ``fix nve/sphere`` is:
ase_bpm.SphereVelocityVerlet), and the decks of ``examples/bpm`` are refused
by line, naming the command, where they use what ase_bpm does not have.

The refused lines are those of LAMMPS's decks (pour, wires, metamaterial,
plasticity, poissons_ratio; the few lines each case needs are copied here as
data); where ``ASE_BPM_LAMMPS_EXAMPLES`` names a folder holding LAMMPS's
``examples/`` tree, the shipped decks themselves are read too.
"""

import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import ase_bpm
from ase_bpm.scene.lammps_read import read_lammps
from test_lammps_round_trip import _edited_deck, _replace, spring_wall_scene

#: the set-up every refused-line deck below starts with (a bpm/sphere scene)
HEADER = ["units lj", "dimension 3", "boundary m m m", "atom_style bpm/sphere",
          "region box block -15 15 -15 15 0 60.0", "create_box 1 box bond/types 1"]


def deck_of(tmp_path, lines) -> str:
    path = tmp_path / "in.deck"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def read_quietly(deck, data=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_lammps(data, deck) if data is not None else read_lammps(deck)


# -- refused by line, naming the command ----------------------------------------------

REFUSED_LINES = {  # the deck's line -> what the error says after it
    # examples/bpm/pour
    'molecule my_mol "rect.mol"': "defines a molecule template",
    "fix 4 all deposit 40 0 1500 712511343 mol my_mol region dropzone near 2.0 vz -0.05 -0.05":
        "inserts particles during the run",
    "fix 2 all wall/gran/region hertz/history 1.0 NULL 0.5 NULL 0.1 1 region wall_cyl":
        "a granular wall on a region",
    # examples/bpm/wires
    "atom_style hybrid bpm/sphere dipole": "gives particles a dipole",
    "pair_style granular": "LAMMPS's general granular pair style",
    "fix 6 end1 move transrot -0.001 0 0 0 0 0 1 0 0 1600": "moves atoms on a prescribed path",
    "fix 8 all viscous 5e-5": "adds a drag force",
    # examples/bpm/metamaterial
    "fix 2 magnets efield 0.0 0.0 v_bz": "acts on charges and dipoles",
    "fix 4 all viscous/sphere 1e-3": "adds a rotational drag",
    # examples/bpm/plasticity and poissons_ratio
    "fix wtemp all wall/region pillarw harmonic 1.0 1.0 1.0": "a wall on a region",
    "fix 3 load addforce 0.0 0.0 v_fload": "adds a force ase_bpm has no fix for",
    # a region that moves (as fix wall/gran/region or fix pour would use it)
    "region dropzone cylinder z 0.0 0.0 10.0 40.0 50.0 move NULL NULL v_z":
        "a region that moves or turns during the run",
    "region disk cylinder x 0.0 0.0 20.0 -0.5 0.5 rotate v_a 0 0 0 1 0 0":
        "a region that moves or turns during the run",
    # the names of the BPM package before LAMMPS renamed them (the shipped
    # examples/bpm/impact/in.bpm.impact.rotational of some versions)
    "atom_style sphere/bpm": "is atom_style bpm/sphere under its name before LAMMPS renamed it",
    "fix 1 all nve/sphere/bpm": "is fix nve/bpm/sphere under its name before LAMMPS renamed it",
    "atom_style ellipsoid": "read_lammps reads atom_style bond, bpm/sphere, sphere, peri",
}


@pytest.mark.parametrize("line", list(REFUSED_LINES))
def test_a_command_of_the_bpm_examples_ase_bpm_lacks_is_refused_by_line(tmp_path, line):
    lines = [*HEADER, line, "run 100"]
    quoted = repr(" ".join(line.replace('"', "").split()))  # (as the error quotes its words)
    with pytest.raises(ValueError, match=rf"line {lines.index(line) + 1}: {re.escape(quoted)}: "
                                         rf"{re.escape(REFUSED_LINES[line])}"):
        read_quietly(deck_of(tmp_path, lines))


@pytest.mark.parametrize("style", ["sphere 1", "bpm/sphere 0"])
def test_an_atom_style_read_keeps_its_options(tmp_path, style):
    """(LAMMPS's radius option of the sphere styles: the words after the style
    are LAMMPS's, as before the atom styles were checked by line.)"""
    data, deck = _edited_deck(tmp_path, "spring-wall" if "bpm" in style else "granular-hooke",
                              _replace("atom_style", f"atom_style {style}"))
    assert read_quietly(deck, data).arrays["radius"].min() > 0


def test_replicate_after_the_first_run_is_refused_by_line(tmp_path):
    """examples/bpm/plasticity and poissons_ratio relax, then replicate the
    body: between runs ase_bpm carries out no such command."""
    atoms, _, _ = spring_wall_scene()
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    lines = open(deck).read().splitlines() + ["replicate 4 1 1", "run 10"]
    Path(deck).write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=rf"line {len(lines) - 1}: 'replicate 4 1 1' after "
                                         r"the run of line \d+: no counterpart there"):
        read_quietly(deck, data)


# -- fix nve/bpm/sphere read as the sphere integrator ---------------------------------

def test_fix_nve_bpm_sphere_is_read_as_the_sphere_integrator(tmp_path):
    """A bpm/sphere scene whose deck integrates with nve/bpm/sphere reads as
    the one with nve/sphere: the same calculator and forces; run_lammps
    turns the spheres (SphereVelocityVerlet)."""
    atoms, _, _ = spring_wall_scene()
    data, deck = _edited_deck(tmp_path, "spring-wall",
                              _replace("fix integrate", "fix integrate all nve/bpm/sphere"))
    assert "fix integrate all nve/bpm/sphere" in open(deck).read()
    back = read_quietly(deck, data)
    assert back.calc.todict() == atoms.calc.todict()
    forces = atoms.get_forces()
    assert np.abs(back.get_forces() - forces).max() <= 1e-12 * np.abs(forces).max()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = ase_bpm.run_lammps(deck, data, steps=3)
    assert np.any(result.atoms.arrays["omega"] != 0)  # (the floor's friction spins them)


@pytest.mark.parametrize("options, message", [
    ("disc", r"disc integrates 2-D discs \(moment of inertia m r\^2 / 2; LAMMPS takes it in "
             r"'dimension 2' only\), and ase_bpm's scenes are 3-D"),
    ("update dipole", r"update turns dipoles with the particles, which ase_bpm's particles "
                      r"do not carry")])
def test_the_options_of_fix_nve_bpm_sphere_are_refused_by_line(tmp_path, options, message):
    line = f"fix integrate all nve/bpm/sphere {options}"
    data, deck = _edited_deck(tmp_path, "spring-wall", _replace("fix integrate", line))
    number = open(deck).read().splitlines().index(line) + 1
    with pytest.raises(ValueError, match=rf"line {number}: '{line}': {message}"):
        read_quietly(deck, data)


def test_fix_nve_bpm_sphere_needs_atom_style_bpm_sphere(tmp_path):
    """A Granular scene (atom_style sphere) has no orientations to turn."""
    line = "fix integrate all nve/bpm/sphere"
    data, deck = _edited_deck(tmp_path, "granular-hooke", _replace("fix integrate", line))
    number = open(deck).read().splitlines().index(line) + 1
    with pytest.raises(ValueError, match=rf"line {number}: '{line}': fix nve/bpm/sphere turns "
                                         r"the orientations of atom_style bpm/sphere, not "
                                         r"sphere \(LAMMPS refuses it too\)"):
        read_quietly(deck, data)


# -- the shipped decks ----------------------------------------------------------------

FOLDER = os.environ.get("ASE_BPM_LAMMPS_EXAMPLES")
#: each shipped deck of examples/bpm that ase_bpm cannot run, and the command
#: its first refused line starts with
SHIPPED = {"bpm/pour/in.bpm.pour": "molecule",
           "bpm/wires/in.bpm.wires": "atom_style hybrid bpm/sphere dipole",
           "bpm/metamaterial/in.bpm.metamaterial": "atom_style hybrid bpm/sphere dipole",
           "bpm/plasticity/in.bpm.plasticity": "fix wtemp all wall/region",
           "bpm/poissons_ratio/in.bpm.poissons_ratio": "fix wtemp all wall/region"}


@pytest.mark.skipif(not FOLDER, reason="ASE_BPM_LAMMPS_EXAMPLES names no folder holding "
                                       "LAMMPS's examples/ tree")
@pytest.mark.parametrize("name", list(SHIPPED))
def test_a_shipped_bpm_deck_ase_bpm_cannot_run_is_refused_by_line(name):
    path = Path(FOLDER or ".") / "examples" / name
    if not path.exists():
        pytest.skip(f"{path} is not in ASE_BPM_LAMMPS_EXAMPLES")
    with pytest.raises(ValueError, match=rf"{re.escape(str(path))} line \d+: "
                                         rf"'{re.escape(SHIPPED[name])}"):
        read_quietly(str(path))


# -- orientations in LAMMPS's files ---------------------------------------------------

def oriented_wall_scene(seed=3):
    """The bonded spheres on a floor (bpm/sphere), each turned at random; three
    of them the identity, its opposite and a half turn."""
    atoms, _, _ = spring_wall_scene()
    q_nq = np.random.default_rng(seed).normal(size=(len(atoms), 4))
    q_nq /= np.linalg.norm(q_nq, axis=1)[:, None]
    q_nq[:3] = [(1, 0, 0, 0), (-1, 0, 0, 0), (0, 1, 0, 0)]
    atoms.arrays["quat"] = q_nq
    return atoms


def test_orientations_go_to_a_bpm_sphere_deck_and_back(tmp_path):
    """A bpm/sphere data file has no orientation: the deck sets each that is
    not the identity (set atom <id> quat, a turn in degrees about a unit
    axis), and read_lammps computes them as LAMMPS does."""
    atoms = oriented_wall_scene()
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    lines = [line for line in open(deck).read().splitlines() if " quat " in line]
    assert len(lines) == len(atoms) - 1 and "set atom 1 quat" not in open(deck).read()
    assert lines[0] == "set atom 2 quat 0.0 0.0 1.0 360.0"  # (-1: a whole turn)
    back = read_quietly(deck, data)
    assert back.calc.todict() == atoms.calc.todict()
    assert np.abs(back.arrays["quat"] - atoms.arrays["quat"]).max() <= 1e-15  # (degrees)
    assert np.array_equal(back.arrays["quat"][0], [1.0, 0.0, 0.0, 0.0])


def test_a_scene_without_turns_writes_no_orientations(tmp_path):
    atoms, _, _ = spring_wall_scene()
    atoms.arrays["quat"] = np.tile([1.0, 0.0, 0.0, 0.0], (len(atoms), 1))
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    assert " quat " not in open(deck).read()
    assert "quat" not in read_quietly(deck, data).arrays  # (the identity: none)


@pytest.mark.parametrize("line, why", [
    ("set atom 3 quat 0.0 0.0 1.0", "a word missing"),
    ("set atom 0 quat 0.0 0.0 1.0 30.0", "no atom 0"),
    ("set atom 3 quat 0.0 0.0 one 30.0", "not a number")])
def test_a_set_line_of_another_form_is_refused_by_line(tmp_path, line, why):
    data, deck = _edited_deck(tmp_path, "spring-wall",
                              lambda lines: [*lines[:-1], line, lines[-1]])
    number = open(deck).read().splitlines().index(line) + 1
    with pytest.raises(ValueError, match=rf"line {number}: '{line}': read_lammps reads 'set "
                                         r"atom <id> mass <m>' or 'set atom <id> quat <a> "
                                         r"<b> <c> <theta>'"):
        read_quietly(deck, data)


@pytest.mark.oracle
def test_lammps_takes_the_written_orientations_as_ase_bpm_reads_them(Oracle, tmp_path):
    """LAMMPS's set quat works in degrees: it gets each orientation back
    within round-off, and exactly what read_lammps reads from the deck."""
    from oracle import gather, run_deck

    atoms = oriented_wall_scene(seed=4)
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    back = read_quietly(deck, data)
    lmp = run_deck(deck)
    try:
        q_nq = gather(lmp, "quat")
    finally:
        lmp.close()
    assert np.abs(q_nq - atoms.arrays["quat"]).max() <= 1e-15
    assert np.array_equal(q_nq, back.arrays["quat"])


#: a deck that builds a bpm/sphere scene in LAMMPS and turns two of its spheres
TURNING_DECK = """units lj
dimension 3
boundary m m m
atom_style bpm/sphere
special_bonds lj 0.0 1.0 1.0 coul 0.0 1.0 1.0
newton on off
comm_modify vel yes
region box block -4 4 -4 4 -4 4
create_box 1 box bond/types 1 extra/bond/per/atom 4 extra/special/per/atom 10
create_atoms 1 single 0.0 0.0 0.0
create_atoms 1 single 1.0 0.0 0.0
create_atoms 1 single 0.0 1.0 0.0
set atom 2 quat 1 2 3 40
set atom 3 quat 0.0 0.0 1.0 -75.5
bond_style bpm/spring break no smooth no
bond_coeff 1 1.0 0.5 0.1
pair_style bpm/spring
pair_coeff 1 1 1.0 1.0 0.1
create_bonds many all all 1 0.0 1.2
special_bonds lj 0.0 1.0 1.0 coul 1.0 1.0 1.0
fix 1 all nve/bpm/sphere
run 10
"""


@pytest.mark.oracle
def test_a_scene_built_in_lammps_keeps_its_orientations_bit_for_bit(Oracle, tmp_path):
    """The set-up run in LAMMPS sets them; read_lammps takes LAMMPS's own
    quaternions, and its data file (write_data) has none: read back, the
    identity."""
    from ase_bpm.scene.lammps import load_lammps
    from ase_bpm.scene.lammps_setup import QUIET

    deck = deck_of(tmp_path, TURNING_DECK.splitlines())
    atoms = read_quietly(deck)
    lmp = load_lammps()(cmdargs=QUIET)
    try:
        for line in TURNING_DECK.splitlines()[:-2]:
            lmp.command(line)
        lmp.command(f"write_data {tmp_path / 'turned.data'} nocoeff")
        from oracle import gather
        q_nq = gather(lmp, "quat")
    finally:
        lmp.close()
    assert np.array_equal(atoms.arrays["quat"], q_nq)
    assert np.all(q_nq[1:] != [1.0, 0.0, 0.0, 0.0], axis=1).any()
    built = ("region", "create_box", "create_atoms", "set", "create_bonds")
    lines = [line for line in TURNING_DECK.splitlines() if line.split()[0] not in built]
    data_deck = deck_of(tmp_path, [*lines[:7], "read_data turned.data", *lines[7:]])
    again = read_quietly(data_deck)
    assert "quat" not in again.arrays  # (LAMMPS's data file holds none)
    assert np.array_equal(again.positions, atoms.positions)
