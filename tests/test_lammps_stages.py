"""What a LAMMPS deck does after its first run, carried out as LAMMPS carries it
out (issue 30): fixes removed, defined again and moved by equal-style variables
between runs, velocities set, the timestep changed, atoms leaving a fixed box
removed at the step LAMMPS removes them; and ``ase-bpm run DECK``.  The decks
are our own, written by ``write_lammps`` and extended line by line; the
reference build runs the same files."""

import os
import re

import warnings

import ase.io
import numpy as np
import pytest
from ase.constraints import FixAtoms
from ase.md.verlet import VelocityVerlet as AseVelocityVerlet

import ase_bpm
from ase_bpm.core.lammps_text import exact
from ase_bpm.scene.aseio import calculator_from_dict
from ase_bpm.scene.lammps_read import read_first_run
from ase_bpm.scene.lammps_run import run_lammps
from ase_bpm.scene.lammps_stages import LAMMPS_ID, LaterRunsWarning
from ase_bpm.scene.lammps_variables import RunClock, Variables, VariableError
from ase_bpm.scene.lost_atoms import LostAtoms
from scenes import fcc_cluster, sphere_pile

TIMESTEP = 0.05
FIRST_RUN = 20


def pressed_body(held=(0, 1)):
    """A bonded FCC body under gravity, an indenter already pressing on its
    top and moving down, two particles held."""
    atoms, rng = fcc_cluster(3, seed=11)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.set_velocities(rng.normal(0, 0.02, atoms.positions.shape))
    if held:
        atoms.set_constraint(FixAtoms(indices=list(held)))
    top = atoms.positions[:, 2].max()
    centre = atoms.positions[:, :2].mean(axis=0)
    fixes = [ase_bpm.Gravity(0.05, (0.0, 0.0, -1.0)),
             ase_bpm.SphericalIndenter(2.0, 1.5, (*centre, top + 1.2), (0.0, 0.0, -0.2))]
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.2, 0.3)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.2)}, fixes=fixes,
                                   timestep=TIMESTEP)
    return atoms


def deck_with(tmp_path, atoms, later, before_run=(), name="scene"):
    """``atoms`` written for LAMMPS with a first run of FIRST_RUN steps,
    ``before_run`` lines before it and ``later`` lines after it."""
    data, deck = ase_bpm.write_lammps(str(tmp_path / name), atoms, steps=FIRST_RUN)
    lines = open(deck).read().splitlines()
    with open(deck, "w") as fh:
        fh.write("\n".join(lines[:-1] + list(before_run) + lines[-1:] + list(later)) + "\n")
    return data, deck


def lammps_positions(deck, natoms, log=None):
    """The reference build's positions at the end of the deck, by atom ID
    (rows of atoms lost: NaN), and the step it ended at."""
    from oracle import QUIET, load_lammps

    args = QUIET if log is None else ["-log", str(log), "-screen", "none", "-nocite"]
    lmp = load_lammps()(cmdargs=args)
    cwd = os.getcwd()
    try:
        os.chdir(os.path.dirname(deck))
        lmp.file(os.path.basename(deck))
        nlocal = lmp.extract_global("nlocal")
        ids = np.array(lmp.numpy.extract_atom("id")[:nlocal])
        x = np.array(lmp.numpy.extract_atom("x")[:nlocal])
        out = np.full((natoms, 3), np.nan)
        out[ids - 1] = x
        return out, lmp.extract_global("ntimestep")
    finally:
        os.chdir(cwd)
        lmp.close()


def ase_bpm_positions(atoms, natoms):
    """The positions of ``atoms`` by LAMMPS ID (rows of atoms lost: NaN)."""
    out = np.full((natoms, 3), np.nan)
    out[atoms.arrays[LAMMPS_ID] - 1] = atoms.positions
    return out


def agree(deck, natoms):
    """Run the deck in ase_bpm and in the reference build; positions by ID."""
    ours = run_lammps(deck)
    theirs, step = lammps_positions(deck, natoms)
    assert ours.steps == step
    mine = ase_bpm_positions(ours.atoms, natoms)
    assert np.array_equal(np.isnan(mine[:, 0]), np.isnan(theirs[:, 0]))
    return np.nanmax(np.abs(mine - theirs)), ours


# -- the stages after the first run, against the reference build ------------------------

INDENT = "fix ase_bpm_indent1 all indent 2.0 sphere v_ase_bpm_indent1_x v_ase_bpm_indent1_y"
STAGES = {
    "unfix": ["unfix ase_bpm_gravity0", "run 15"],
    "fix-again": ["fix ase_bpm_gravity0 all gravity 0.2 chute 30.0", "run 15"],
    "fix-added": ["fix g2 all gravity 0.1 spherical 20.0 150.0", "run 15"],
    "velocity-set": ["group moving id 3:60", "velocity moving set 0.1 NULL -0.05 units box",
                     "run 15"],
    "velocity-sum-lattice": ["group light type 1", "velocity light set NULL 0.02 NULL sum yes",
                             "run 15"],
    # step*dt with the timestep changed: LAMMPS' step*dt jumps with dt (the centre too)
    "step-dt-new-timestep": ["timestep 0.03", "run 15"],
    # elapsed starts again at each run: the centre steps back and moves on
    "elapsed": [f"{INDENT} v_z2 1.5 units box",
                'variable z2 equal "v_ase_bpm_indent1_z - elapsed*dt*0.5"', "run 15",
                "run 10"],
    # time runs on across a timestep change
    "time-new-timestep": [f"{INDENT} v_z3 1.5 units box", "timestep 0.03",
                          'variable z3 equal "v_ase_bpm_indent1_z + 0.1 - time*0.3"',
                          "run 15", "timestep 0.04", "run 10"],
    "variable-again": ['variable ase_bpm_indent1_z equal "4.5 - step*dt*0.1"', "run 15"],
    "run-upto": ["unfix ase_bpm_gravity0", "run 32 upto"],
}


@pytest.mark.oracle
@pytest.mark.parametrize("name", list(STAGES))
def test_a_later_run_goes_as_in_lammps(Oracle, tmp_path, name):
    """Each change between runs that ase_bpm carries out: positions at the end
    within 1e-9 of the reference build's (spacing about 1.6)."""
    # (held atoms: LAMMPS's fix order decides what holds them, see the refusals)
    atoms = pressed_body(held=(0, 1) if name in ("unfix", "elapsed", "run-upto") else ())
    natoms = len(atoms)
    _, deck = deck_with(tmp_path, atoms, STAGES[name])
    error, ours = agree(deck, natoms)
    assert error <= 1e-9
    assert ours.steps > FIRST_RUN


@pytest.mark.oracle
def test_the_changes_matter(Oracle, tmp_path):
    """The cases above are not idle: without the later run's change (here the
    indenter's new formula, which starts again at elapsed 0) the scene ends
    elsewhere."""
    atoms = pressed_body()
    _, changed = deck_with(tmp_path, atoms, STAGES["elapsed"], name="changed")
    _, plain = deck_with(tmp_path, atoms, ["run 15", "run 10"], name="plain")
    a, b = run_lammps(changed).atoms, run_lammps(plain).atoms
    assert np.abs(a.positions - b.positions).max() > 1e-3


def test_read_lammps_gives_the_first_runs_scene_and_says_more_follows(tmp_path):
    atoms = pressed_body()
    data, deck = deck_with(tmp_path, atoms, STAGES["unfix"])
    with pytest.warns(LaterRunsWarning, match=r"read_lammps gives the scene of the first run "
                                              r"\(line \d+\); the deck runs again after it "
                                              r"\(runs at lines \d+\): ase_bpm.run_lammps"):
        back = ase_bpm.read_lammps(data, deck)
    assert [type(f).__name__ for f in back.calc.fixes] == ["Gravity", "SphericalIndenter"]


# -- refusals -----------------------------------------------------------------------------

@pytest.mark.parametrize("later,message", [
    (["fix heat all langevin 1.0 1.0 1.0 9", "run 10"],  # (refused anywhere: the table's
     # reason)
     r"'fix heat all langevin 1.0 1.0 1.0 9': adds a thermostat's random forces"),
    (["fix again all nve", "run 10"],
     r"'fix again all nve' after the run of line \d+: fix nve is not one ase_bpm defines "
     r"anew between runs"),
    (["unfix nothing", "run 10"], r"'unfix nothing' after the run of line \d+: no fix nothing "
                                  r"to remove"),
    (["unfix integrate", "run 10"], r"fix integrate is a fix nve, which ase_bpm does not "
                                    r"remove between runs"),
    (["pair_coeff 1 1 2.0 1.0 0.2", "run 10"], r"'pair_coeff 1 1 2.0 1.0 0.2' after the run "
                                               r"of line \d+: no counterpart there"),
    (["velocity all create 1.0 4928", "run 10"], r"velocity <group> set vx vy vz"),
    (["run 10 every 5 NULL"], r"a run is 'run N' or 'run N upto'"),
    (["fix g2 all gravity 0.1 vector 0 0 -1", "run 10"],
     r"'fix g2 all gravity 0.1 vector 0 0 -1' comes after fix ase_bpm_freeze, which holds "
     r"atoms: LAMMPS adds its force after the held atoms' forces were zeroed, so they move"),
    (['variable ase_bpm_indent1_z equal "sqrt(v_a) + step"', "run 10"],
     r"line \d+: variable ase_bpm_indent1_z = 'sqrt\(v_a\) \+ step': sqrt\(\) is a function"),
    (["group moving id 1:10", "velocity moving set 0.0 0.0 0.1 units box", "run 10"],
     r"'velocity moving set 0.0 0.0 0.1 units box': it gives held atoms \(fix freeze or "
     r"setforce 0 0 0\) a velocity"),
])
def test_a_line_after_a_run_ase_bpm_cannot_carry_out_is_refused_by_line(tmp_path, later,
                                                                        message):
    """Refused when the deck is read, before anything runs, naming the line."""
    atoms = pressed_body()
    data, deck = deck_with(tmp_path, atoms, later)
    with pytest.raises(ValueError, match=r"line \d+: .*" + message):
        ase_bpm.read_lammps(data, deck)
    with pytest.raises(ValueError, match=message):
        run_lammps(deck)


# -- equal-style variables ----------------------------------------------------------------

FORMULAS = ["v_a + step*dt*v_b", "v_a - elapsed*dt*v_b", "v_a + elaplong*v_b", "2*time - dt",
            "-2^2 + 2^3^2 - 8/2/2 + PI", "(v_a - 1.5e-1)*(3 - step/4)", "v_b*-time/3"]


@pytest.mark.oracle
def test_equal_style_variables_are_the_reference_builds(Oracle, tmp_path):
    """Each formula's value during a run, after two runs and a timestep change,
    as the reference build evaluates it (step runs on, elapsed starts again,
    dt is the new timestep, time runs on from the time of the change)."""
    from oracle import QUIET, load_lammps

    log = tmp_path / "log.lammps"
    lmp = load_lammps()(cmdargs=["-log", str(log), "-screen", "none", "-nocite"])
    variables = Variables()
    names = []
    for k, formula in enumerate(["0.25", "-1.5"] + FORMULAS):
        name = "ab"[k] if k < 2 else f"f{k}"
        lmp.command(f'variable {name} equal "{formula}"')
        variables.define(k + 1, [name, "equal", formula])
        names.append(name)
    lmp.commands_string("units lj\nregion b block 0 1 0 1 0 1\ncreate_box 1 b\nmass 1 1.0\n"
                        "timestep 0.02\nrun 7\ntimestep 0.03\n"
                        f"thermo_style custom step {' '.join('v_' + n for n in names)}\n"
                        "thermo_modify format float %.17g\nrun 5\n")
    lmp.close()
    values = next(line.split() for line in reversed(open(log).read().splitlines())
                  if line.split()[:1] == ["12"])
    clock = RunClock(first_step=7, timestep=0.03, time_at_first_step=7 * 0.02)
    for name, expected in zip(names, values[1:]):
        formula = variables.formulas[name][1]
        assert np.isclose(variables.linear(name, clock).at(12), float(expected), rtol=1e-14,
                          atol=1e-14), formula


@pytest.mark.parametrize("formula,message", [
    ("step*step", "a product of two step-dependent parts is not linear in the step"),
    ("ke + 1", "'ke' is a thermo keyword, reference or name ase_bpm does not evaluate"),
    ("v_nowhere", "v_nowhere names no equal-style variable defined"),
    ("2 +", "the formula ends early"),
    ("(1 + step", r"a '\(' without its '\)'"),
    ("1 / (step - 3)", "a division by a step-dependent part"),
    ("x[3] + 1", r"'x\[3\]' is a thermo keyword, reference or name"),
])
def test_a_formula_ase_bpm_cannot_evaluate_is_named(formula, message):
    variables = Variables("in.deck")
    variables.define(4, ["y", "equal", formula])
    with pytest.raises(VariableError, match=rf"in.deck(: | line 4: variable y = .*){message}"):
        variables.linear("y", RunClock(0, 0.1))


def test_the_indenter_refusal_names_the_variable_not_the_form(tmp_path):
    """(Before, the refusal quoted the line's own form back at the user.)"""
    atoms = pressed_body()
    data, deck = deck_with(tmp_path, atoms, [], before_run=[
        'variable ase_bpm_indent1_z equal "4.0 + ramp(0, 1)"'])
    with pytest.raises(ValueError, match=r"variable ase_bpm_indent1_z = '4.0 \+ ramp\(0, 1\)': "
                                         r"ramp\(\) is a function; ase_bpm evaluates numbers"):
        ase_bpm.read_lammps(data, deck)


# -- lost atoms ---------------------------------------------------------------------------

def escaping_body(lost="lost ignore lost/bond ignore", skin=1.0, moving=3):
    """A bonded body whose ``moving`` right-most particles fly off along +x,
    out of a box with fixed faces (write_lammps's box: the body plus 1.0)."""
    atoms, rng = fcc_cluster(3, seed=3)
    ase_bpm.create_bonds(atoms, 1.25)
    v_nc = rng.normal(0, 0.02, atoms.positions.shape)
    fastest = np.argsort(atoms.positions[:, 0])[-moving:]
    v_nc[fastest, 0] += 1.5
    atoms.set_velocities(v_nc)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.05, 0.3)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.2)}, timestep=TIMESTEP)
    after = ["boundary f f f", f"neighbor {skin} bin"]
    return atoms, after, [f"thermo_modify {lost}"] if lost else []


def escaping_spheres():
    """Frictional spheres with shear history, the four top-most shot up out of
    a box with fixed faces through the others (write_lammps's box: the pile
    plus 1.0)."""
    atoms = sphere_pile(seed=4, lift=0.5)
    v_nc = atoms.get_velocities()
    v_nc[np.argsort(atoms.positions[:, 2])[-4:], 2] += 40.0
    atoms.set_velocities(v_nc)
    atoms.calc = ase_bpm.Granular("hooke/history", kn=1000.0, kt=400.0, gamma_n=20.0,
                                  gamma_t=8.0, xmu=0.4, dampflag=1, timestep=2e-3)
    return atoms, ["boundary f f f", "neighbor 0.4 bin"], ["thermo_modify lost ignore"]


def lost_deck(tmp_path, atoms, frame, modify, steps=40, thermo=1):
    """The deck: boundary and skin changed, thermo every step with the atoms
    counted, ``modify`` after the thermo_style."""
    data, deck = ase_bpm.write_lammps(str(tmp_path / "lost"), atoms, steps=steps)
    lines = []
    for line in open(deck).read().splitlines():
        if line.startswith("boundary"):
            line = frame[0]
        elif line.startswith("neighbor"):
            line = frame[1]
        elif line.startswith("thermo "):
            line = f"thermo {thermo}"
        elif line.startswith("thermo_style"):
            line = "thermo_style custom step atoms ke"
        lines.append(line)
        if line.startswith("thermo_style"):
            lines += modify
    with open(deck, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    return data, deck


def thermo_log(log) -> dict:
    """Step -> (atoms, ke), from a LAMMPS log with ``thermo_style custom step
    atoms ke``."""
    rows, reading = {}, False
    for line in open(log):
        words = line.split()
        if words[:3] == ["Step", "Atoms", "KinEng"]:
            reading = True
        elif reading and len(words) == 3 and words[0].isdigit():
            rows[int(words[0])] = (int(words[1]), float(words[2]))
        elif words[:1] != ["WARNING:"]:  # (a warning between the rows: they go on)
            reading = False
    return rows


@pytest.mark.oracle
@pytest.mark.parametrize("scene", [escaping_body, escaping_spheres])
def test_atoms_leaving_a_fixed_box_go_at_the_step_lammps_removes_them(Oracle, tmp_path,
                                                                      scene):
    """thermo_modify lost ignore: the same atoms go at the same step as in the
    reference build (at its first neighbour-list rebuild after they left, not
    the step they left), with ase_bpm's integrator and ASE's own; the atoms
    left end where LAMMPS's do (bonds and contact history of the atoms gone
    go with them)."""
    atoms, frame, modify = scene()
    natoms = len(atoms)
    timestep = atoms.calc.parameters["timestep"]
    data, deck = lost_deck(tmp_path, atoms, frame, modify)
    theirs, step = lammps_positions(deck, natoms, log=tmp_path / "log.lammps")
    log = thermo_log(tmp_path / "log.lammps")
    counts = {k: atoms for k, (atoms, _) in log.items()}
    assert counts[0] == natoms and natoms - 4 <= counts[step] < natoms

    ours = run_lammps(deck)
    assert {row["step"]: row["atoms"] for row in ours.rows} == counts
    # (ke per atom, as LAMMPS prints it in lj units; LAMMPS prints 6 digits)
    assert all(np.isclose(row["ke"], log[row["step"]][1], rtol=1e-5) for row in ours.rows)
    mine = ase_bpm_positions(ours.atoms, natoms)
    assert np.array_equal(np.isnan(mine[:, 0]), np.isnan(theirs[:, 0]))
    assert np.nanmax(np.abs(mine - theirs)) <= 1e-9

    # the rebuild rule matters: at the first step outside, they would go earlier
    naive = read_first_run(deck, data)[0]
    naive.calc.fixes[-1].rebuilds = False
    seen = {}
    integrator = ase_bpm.SphereVelocityVerlet if "radius" in atoms.arrays else \
        ase_bpm.VelocityVerlet
    dyn = integrator(naive, timestep=timestep)
    dyn.attach(lambda: seen.setdefault(int(naive.info.get("bpm_step", 0)), len(naive)))
    dyn.run(step)
    assert seen != counts  # (the bonded body's third atom would go at step 15, not 21)

    with warnings.catch_warnings():
        warnings.simplefilter("error", LaterRunsWarning)  # (one run: nothing follows)
        back = ase_bpm.read_lammps(data, deck)
    back.arrays[LAMMPS_ID] = np.arange(1, natoms + 1)
    seen = {}
    dyn = (integrator if "radius" in atoms.arrays else AseVelocityVerlet)(
        back, timestep=timestep)  # (ASE's own moves point particles only)
    dyn.attach(lambda: seen.setdefault(int(back.info.get("bpm_step", 0)), len(back)))
    dyn.run(step)
    assert seen == counts
    assert np.nanmax(np.abs(ase_bpm_positions(back, natoms) - theirs)) <= 1e-9


@pytest.mark.parametrize("modify,message", [
    ([], r"\d atoms left the box through a fixed face \(indices .*\): LAMMPS stops here "
         r"\('Lost atoms'"),
    (["thermo_modify lost ignore"], r"atoms left the box \(indices .*\) with \d+ intact bonds "
                                    r"to atoms in it: LAMMPS stops here \('Bond atoms missing'"),
])
def test_lost_atoms_lammps_would_stop_at_stop_the_run(tmp_path, modify, message):
    """LAMMPS' defaults (lost error, lost/bond error) stop the run; so does
    ase_bpm, naming the atoms, where before they flew on silently."""
    atoms, frame, _ = escaping_body(lost="", moving=108)  # (the body flies off whole)
    data, deck = lost_deck(tmp_path, atoms, frame, modify)
    with pytest.raises(ValueError, match=message):
        run_lammps(deck)


@pytest.mark.parametrize("boundary,faces", [("f f f", 6), ("m m f", 2), ("p p fm", 1),
                                            ("m m m", 0), ("s s m", 0)])
def test_only_fixed_faces_remove_atoms(tmp_path, boundary, faces):
    atoms, frame, modify = escaping_body()
    data, deck = lost_deck(tmp_path, atoms, [f"boundary {boundary}", frame[1]], modify)
    atoms_read, _ = read_first_run(deck, data)
    lost = [f for f in atoms_read.calc.fixes if isinstance(f, LostAtoms)]
    assert sum(v is not None for f in lost for v in f.lo + f.hi) == faces
    if "p" in boundary and faces:
        assert not lost[0].rebuilds  # (LAMMPS' box moves: at the first step outside)


@pytest.mark.oracle
def test_a_scene_that_loses_atoms_goes_back_to_lammps(Oracle, tmp_path):
    """write_lammps of a scene read from a deck with lost ignore on fixed
    faces writes those faces where they were and the lost settings after its
    thermo_style: the reference build loses the same atoms at the same steps
    running either deck."""
    atoms, frame, modify = escaping_body()
    data, deck = lost_deck(tmp_path, atoms, frame, modify)
    back = ase_bpm.read_lammps(data, deck)
    _, again = ase_bpm.write_lammps(str(tmp_path / "again"), back, steps=40)
    lines = open(again).read().splitlines()
    with open(again, "w") as fh:
        fh.write("\n".join("thermo_style custom step atoms ke" if line.startswith("thermo_style")
                           else "thermo 1" if line.startswith("thermo ") else line
                           for line in lines) + "\n")
    logs = []
    for name, path in (("first", deck), ("again", again)):
        lammps_positions(path, len(atoms), log=tmp_path / f"log.{name}")
        logs.append({k: n for k, (n, _) in thermo_log(tmp_path / f"log.{name}").items()})
    assert logs[0] == logs[1] and logs[0][40] < len(atoms)


def test_a_scene_that_loses_atoms_reads_back_from_the_deck_it_was_written_to(tmp_path,
                                                                          monkeypatch):
    """write_lammps's change_box (the fixed faces where they were) is read
    on the data path, no LAMMPS needed: the same box, faces, LostAtoms and
    atoms, and run_lammps loses the same atoms at the same steps from
    either deck."""
    from ase_bpm.scene import lammps

    monkeypatch.setattr(lammps, "load_lammps", lambda: pytest.fail("LAMMPS loaded"))
    atoms, frame, modify = escaping_body()
    data, deck = lost_deck(tmp_path, atoms, frame, modify, thermo=5)
    back = ase_bpm.read_lammps(data, deck)
    _, again = ase_bpm.write_lammps(str(tmp_path / "again"), back, steps=40, thermo=5)
    assert any(line.startswith("change_box all ") for line in open(again))
    with warnings.catch_warnings():
        warnings.simplefilter("error", ase_bpm.IgnoredCommandsWarning)  # (its own deck)
        read_again = ase_bpm.read_lammps(again)
    assert np.array_equal(read_again.cell.array, back.cell.array)
    assert np.array_equal(read_again.pbc, back.pbc)
    assert np.array_equal(read_again.positions, back.positions)
    (fix,), (fix_again,) = ([f for f in a.calc.fixes if isinstance(f, LostAtoms)]
                            for a in (back, read_again))
    assert fix_again.todict() == fix.todict()
    counts = [[row["atoms"] for row in run_lammps(path).rows] for path in (deck, again)]
    assert counts[0] == counts[1] and counts[0][-1] < len(atoms)


@pytest.mark.oracle
def test_a_box_fixed_on_one_face_of_an_axis_goes_to_lammps_and_back(Oracle, tmp_path):
    """One fixed face of an axis (boundary mf, as in.pour's fm) is written
    with the other where the data file puts it ('$(xlo)'); read back on the
    data path it is the same LostAtoms, and the reference build loses the
    same atoms at the same steps through it as run_lammps (before, the
    export was refused)."""
    atoms, _, _ = escaping_body()
    face = float(atoms.positions[:, 0].max()) + 1.0
    fix = LostAtoms([None] * 3, [face, None, None], skin=1.0, lost="ignore",
                    lost_bonds="ignore")
    atoms.calc.fixes = [fix]
    _, deck = ase_bpm.write_lammps(str(tmp_path / "one"), atoms, steps=40, thermo=1)
    text = open(deck).read()
    assert f"change_box all x final $(xlo) {exact(face)} boundary mf m m units box" in text
    with open(deck, "w") as fh:
        fh.write(text.replace("thermo_style custom step ke pe c_tbond",
                              "thermo_style custom step atoms ke"))
    back = ase_bpm.read_lammps(deck)
    (fix_back,) = [f for f in back.calc.fixes if isinstance(f, LostAtoms)]
    assert fix_back.todict() == fix.todict()
    lammps_positions(deck, len(atoms), log=tmp_path / "log.one")
    theirs = {step: n for step, (n, _) in thermo_log(tmp_path / "log.one").items()}
    ours = {row["step"]: row["atoms"] for row in run_lammps(deck).rows}
    assert ours == theirs and theirs[40] < len(atoms)


def test_thermo_style_resets_the_lost_settings_as_in_lammps(tmp_path):
    """'thermo_modify lost warn' before the thermo_style is lost (measured in
    the reference build: a warning, then 'Lost atoms' stops the run); one
    after it holds."""
    atoms, frame, _ = escaping_body()
    data, deck = lost_deck(tmp_path, atoms, frame, [])
    lines = open(deck).read().splitlines()
    at = next(k for k, line in enumerate(lines) if line.startswith("thermo_style"))
    for after, lost in (([], "error"), (["thermo_modify lost ignore"], "ignore")):
        with open(deck, "w") as fh:
            fh.write("\n".join(lines[:at] + ["thermo_modify lost warn", lines[at], *after]
                               + lines[at + 1:]) + "\n")
        (fix,) = [f for f in read_first_run(deck, data)[0].calc.fixes
                  if isinstance(f, LostAtoms)]
        assert fix.lost == lost


def test_lost_atoms_go_with_their_record_and_the_run_goes_on():
    """Removing atoms mid-run loses no state: the step counter runs on, the
    bonds among the atoms left stay, a restart of the scene carries the fix."""
    atoms, _, _ = escaping_body()
    box_lo = atoms.positions.min(axis=0) - 1.0
    box_hi = atoms.positions.max(axis=0) + 1.0
    atoms.calc.fixes = [LostAtoms(box_lo, box_hi, skin=0.3)]
    dyn = ase_bpm.VelocityVerlet(atoms, timestep=TIMESTEP)
    dyn.run(40)
    assert len(atoms) < 108 and atoms.info["bpm_step"] == 40
    _, _, type_b = ase_bpm.get_bonds(atoms, include_broken=True)
    assert np.count_nonzero(type_b) > 300
    again = calculator_from_dict("BPMSpring", atoms.calc.todict())
    assert again.fixes[0].todict() == atoms.calc.fixes[0].todict()


# -- ase-bpm run ------------------------------------------------------------------------

def test_ase_bpm_run_prints_the_thermo_writes_frames_and_names_what_it_ignored(
        tmp_path, capsys):
    from ase_bpm.scene.cli import main

    atoms, frame, modify = escaping_body()
    _, deck = lost_deck(tmp_path, atoms, frame, modify, steps=30, thermo=10)
    lines = open(deck).read().splitlines()  # (as by hand: write_lammps's own output lines
    with open(deck, "w") as fh:  # are named as ignored only in a deck it did not write)
        fh.write("\n".join(["# the deck, by hand", *lines[1:]]) + "\n")
    out = tmp_path / "frames.extxyz"
    assert main(["run", deck, "--steps", "25", "--output", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    header = next(line for line in text.splitlines() if "Step" in line).split()
    assert header == ["Step", "Atoms", "KinEng", "Bonds", "Broken"]
    rows = [line.split() for line in text.splitlines()
            if re.match(r"^\s+\d+\s+\d+\s", line)]
    assert [int(r[0]) for r in rows] == [0, 10, 20, 25]
    assert int(rows[-1][1]) < int(rows[0][1])  # (atoms left the box)
    bonds = [int(r[3]) for r in rows]
    assert [int(r[4]) for r in rows] == [bonds[0] - b for b in bonds]  # (broken since 0)
    assert bonds[-1] < bonds[0]
    assert re.search(r"ignored: line \d+ 'thermo_style custom step atoms ke'", text)
    assert re.search(r"ignored: line \d+ 'dump broken all local", text)
    assert not re.search(r"ignored: line \d+ '(thermo_modify lost|thermo \d)", text)
    frames = ase.io.read(str(out), ":")
    assert len(frames) == len(rows)
    assert [len(f) for f in frames] == [int(r[1]) for r in rows]


def test_ase_bpm_run_writes_frames_named_after_the_deck_by_default(tmp_path, monkeypatch,
                                                                  capsys):
    """Without --output, the frames go to the deck's name without LAMMPS's
    ``in.`` prefix, in the working folder (``in.body`` -> ``body.extxyz``)."""
    from ase_bpm.scene.cli import main

    atoms, frame, modify = escaping_body()
    _, deck = lost_deck(tmp_path, atoms, frame, modify, steps=20, thermo=10)
    assert os.path.basename(deck).startswith("in.")
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["run", deck, "--no-progress"]) == 0
    name = os.path.basename(deck).removeprefix("in.") + ".extxyz"
    assert f"frames: {name}" in capsys.readouterr().out
    assert len(ase.io.read(str(work / name), ":")) == 3  # (steps 0, 10, 20)


def test_a_peridynamic_deck_reports_its_mean_damage(tmp_path):
    """(LAMMPS' compute damage/atom, averaged: the bpm/peri examples' thermo.)"""
    from scenes import HORIZON, MICROMODULUS, peri_model, sc_block

    atoms = sc_block(5)
    atoms.set_velocities(np.random.default_rng(2).normal(0, 40.0, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb", s00=0.0005)},
                                 pair_coeffs={(1, 1): (MICROMODULUS, HORIZON)}, timestep=1e-7)
    _, deck = ase_bpm.write_lammps(str(tmp_path / "peri"), atoms, steps=30, thermo=10)
    result = run_lammps(deck)
    assert [row["step"] for row in result.rows] == [0, 10, 20, 30]
    damage = [row["damage"] for row in result.rows]
    assert damage[0] == 0.0 < damage[-1] == result.atoms.arrays["damage"].mean()
