"""Every scene the reference LAMMPS build can express goes over and comes back:
``write_lammps`` writes files that LAMMPS runs, as they are, to ase_bpm's forces
and 200-step trajectory; ``read_lammps`` reads them back into the same scene;
what a deck cannot express stops at export, naming the limitation."""

import os

import numpy as np
import pytest
from ase.constraints import FixAtoms
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm import SphereVelocityVerlet
from scenes import (FCC, HORIZON, MICROMODULUS, NODE_VOLUME, SPACING, fcc_cluster, peri_model, sc_block,
                    sphere_pile)

STEPS = 200


def spring_scene():
    """Two bond types breaking, two particle types in contact (mixed), store/local."""
    atoms, rng = fcc_cluster(4, seed=5, ntypes=2)
    ase_bpm.create_bonds(atoms, 1.5, bond_type=1)
    ase_bpm.create_bonds(atoms, 1.6, bond_type=2, mask=atoms.arrays["type"] == 2)
    atoms.set_velocities(rng.normal(0, 0.08, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.06, 0.2), 2: (1.5, 0.09, 0.4)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5),
                                                (2, 2): (1.0, 1.1, 0.3)},
                                   mix="arithmetic", timestep=0.1)
    return atoms, VelocityVerlet, FCC


def spring_contacts_scene():
    """BPMSpring without bonds: contacts only (the deck then has no bond_style,
    which LAMMPS refuses without bonds to store)."""
    atoms, rng = fcc_cluster(3, seed=8, ntypes=2)
    atoms.set_velocities(rng.normal(0, 0.1, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(pair_coeffs={(1, 1): (1.0, 1.2, 0.5),
                                                (2, 2): (1.0, 1.3, 0.3)}, timestep=0.1)
    return atoms, VelocityVerlet, FCC


def spring_fixes_scene():
    """Gravity, a moving indenter and two held particles on a bonded body."""
    atoms, rng = fcc_cluster(3, seed=6)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.set_velocities(rng.normal(0, 0.02, atoms.positions.shape))
    atoms.set_constraint(FixAtoms(indices=[0, 5]))
    top = atoms.positions[:, 2].max()
    fixes = [ase_bpm.Gravity(0.01, (0.0, 0.3, -1.0)),
             ase_bpm.SphericalIndenter(2.0, 1.5, (2.4, 2.4, top + 1.6), (0.0, 0.0, -0.01))]
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.3)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.2)}, smooth=False,
                                   normalize=True, fixes=fixes, timestep=0.05)
    return atoms, ase_bpm.VelocityVerlet, FCC


def spring_wall_scene():
    """A bonded body of spheres dropped on a frictional floor (bpm/sphere)."""
    atoms, rng = fcc_cluster(3, seed=7)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.arrays["radius"] = np.full(len(atoms), 0.5)
    atoms.positions[:, 2] += 0.45 - atoms.positions[:, 2].min()
    atoms.set_velocities(rng.normal(0, 0.02, atoms.positions.shape) + [0.0, 0.0, -0.3])
    floor = ase_bpm.GranularWall("hooke/history", kn=200.0, gamma_n=5.0, xmu=0.5, axis="z",
                                 lo=0.0)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.2, 0.3)}, fixes=[floor],
                                   timestep=0.02)
    return atoms, SphereVelocityVerlet, 1.0


def granular_scene(model):
    def scene():
        atoms = sphere_pile(seed=8, lift=0.5)
        atoms.set_constraint(FixAtoms(indices=[2, 40]))
        kn = 6000.0 if model == "hertz/history" else 1000.0
        walls = [ase_bpm.GranularWall(model, kn=kn, gamma_n=30.0, xmu=0.5, axis="z", lo=0.0),
                 ase_bpm.GranularWall(model, kn=0.8 * kn, kt=0.3 * kn, gamma_n=10.0,
                                      gamma_t=3.0, xmu=0.3, axis="x", lo=-0.3, hi=3.3,
                                      limit_damping=True)]
        atoms.calc = ase_bpm.Granular(model, kn=kn, kt=0.4 * kn, gamma_n=20.0, gamma_t=8.0,
                                      xmu=0.4, dampflag=1, limit_damping=model != "hooke",
                                      fixes=[ase_bpm.Gravity(9.81)] + walls, timestep=1e-3)
        return atoms, SphereVelocityVerlet, 2 * 0.45
    return scene


def peri_scene():
    """A pmb block, moving, struck by an indenter, under gravity."""
    atoms = sc_block(6)
    rng = np.random.default_rng(9)
    atoms.set_velocities(rng.normal(0, 1.0, atoms.positions.shape))
    top = atoms.positions[:, 2].max()
    fixes = [ase_bpm.SphericalIndenter(1e17 * NODE_VOLUME, 4 * SPACING,
                                       (0.0012, 0.0012, top + 4.5 * SPACING), (0.0, 0.0, -30.0)),
             ase_bpm.Gravity(9.81)]
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb")},
                                 pair_coeffs={(1, 1): (MICROMODULUS, HORIZON)}, fixes=fixes,
                                 timestep=1e-7, follows="legacy")
    return atoms, VelocityVerlet, SPACING


SCENES = {"spring": spring_scene, "spring-contacts": spring_contacts_scene,
          "spring-fixes": spring_fixes_scene,
          "spring-wall": spring_wall_scene, "peri-pmb": peri_scene,
          **{f"granular-{m}": granular_scene(m)
             for m in ("hooke", "hooke/history", "hertz/history")}}


def true_forces(lmp, atoms):
    """LAMMPS' f as true forces (legacy PERI holds force densities)."""
    from oracle import gather

    f = gather(lmp, "f")
    return f * atoms.arrays["vfrac"][:, None] if "vfrac" in atoms.arrays else f


@pytest.mark.oracle
@pytest.mark.parametrize("name", list(SCENES))
def test_the_exported_deck_runs_to_ase_bpms_forces_and_trajectory(Oracle, tmp_path, name):
    from oracle import gather, run_deck

    atoms, integrator, length = SCENES[name]()
    _, setup = ase_bpm.write_lammps(str(tmp_path / "setup"), atoms)
    lmp = run_deck(setup)
    try:
        forces = atoms.get_forces()
        assert np.abs(forces).max() > 0
        assert np.abs(true_forces(lmp, atoms) - forces).max() <= 1e-9 * np.abs(forces).max()
    finally:
        lmp.close()
    atoms, integrator, length = SCENES[name]()
    _, deck = ase_bpm.write_lammps(str(tmp_path / "run"), atoms, steps=STEPS)
    start = atoms.positions.copy()
    lmp = run_deck(deck)
    try:
        integrator(atoms, atoms.calc.parameters["timestep"]).run(STEPS)
        x = gather(lmp, "x")
        moved = np.abs(atoms.positions - start).max()
        assert moved > 1e-3 * length  # a run where things happen
        assert np.abs(x - atoms.positions).max() <= 1e-9 * length
    finally:
        lmp.close()


def scene_of(atoms):
    """What a scene is, for comparison: per-atom arrays (velocities of the
    particles free to move), bonds, the calculator's parameters and fixes."""
    from ase_bpm.core.spheres import frozen

    hold = frozen(atoms)
    free = np.ones(len(atoms), bool) if hold is None else ~hold
    arrays = {name: atoms.arrays[name].copy()
              for name in ("positions", "radius", "vfrac", "numbers") if name in atoms.arrays}
    if "radius" in arrays:  # (no omega array: at rest)
        arrays["omega"] = atoms.arrays.get("omega", np.zeros((len(atoms), 3)))
    i, j, t = ase_bpm.get_bonds(atoms)
    return dict(arrays=arrays, masses=atoms.get_masses(), free=free,
                velocities=atoms.get_velocities()[free], pbc=atoms.pbc.tolist(),
                types=atoms.arrays.get("type", np.ones(len(atoms), int)),
                bonds={(min(a, b), max(a, b), c) for a, b, c in zip(i, j, t)},
                calc=type(atoms.calc).__name__,
                fixes=[fix.todict() for fix in atoms.calc.fixes])


@pytest.mark.parametrize("name", list(SCENES))
def test_a_scene_comes_back_from_its_lammps_files(tmp_path, name):
    """ase_bpm -> data file and deck -> ase_bpm keeps the scene: its arrays bit
    for bit, bonds, calculator and fixes; both then run the same 20 steps."""
    atoms, integrator, length = SCENES[name]()
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=STEPS)
    back = ase_bpm.read_lammps(data, deck)
    ours, theirs = scene_of(atoms), scene_of(back)
    for key in ("arrays",):
        assert ours[key].keys() == theirs[key].keys()
        for array in ours[key]:
            assert np.array_equal(ours[key][array], theirs[key][array]), array
    for key in ("masses", "free", "velocities", "types"):
        assert np.array_equal(ours[key], theirs[key]), key
    assert ours["bonds"] == theirs["bonds"] and ours["calc"] == theirs["calc"]
    assert ours["pbc"] == theirs["pbc"]
    assert len(ours["fixes"]) == len(theirs["fixes"])
    for mine, read in zip(ours["fixes"], theirs["fixes"]):
        assert mine.keys() == read.keys()
        for key, value in mine.items():
            assert np.allclose(value, read[key], rtol=1e-15, atol=0) if isinstance(
                value, (float, list)) else value == read[key], key
    assert atoms.calc.parameters["timestep"] == back.calc.parameters["timestep"]
    forces = atoms.get_forces()
    assert np.abs(back.get_forces() - forces).max() <= 1e-12 * np.abs(forces).max()
    integrator(atoms, atoms.calc.parameters["timestep"]).run(20)
    integrator(back, back.calc.parameters["timestep"]).run(20)
    assert np.abs(back.positions - atoms.positions).max() <= 1e-12 * length


# -- what a deck cannot express, and what a deck read back cannot hold ------------------

def test_a_body_off_its_reference_lengths_is_not_exported(tmp_path):
    atoms, _, _ = spring_scene()
    atoms.get_forces()  # the reference lengths taken
    atoms.positions[0] += 0.01
    with pytest.raises(ValueError, match=r"bonds are not at their reference length \(bond 0-"
                                         r".* a LAMMPS data file has no place for reference"):
        ase_bpm.write_lammps(str(tmp_path / "strained"), atoms)
    atoms.positions[0] -= 0.01  # back at the reference: fine
    ase_bpm.write_lammps(str(tmp_path / "relaxed"), atoms)


def test_a_run_without_a_timestep_is_not_exported(tmp_path):
    atoms, _, _ = spring_scene()
    atoms.calc.set(timestep=None)
    with pytest.raises(ValueError, match="a run of 10 steps needs a timestep"):
        ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10, timestep=0.1)


@pytest.mark.parametrize("line,says", [
    ("fix heat all langevin 1.0 1.0 1.0 48279", "adds a thermostat's random forces"),
    ("fix heat all temp/berendsen 1.0 1.0 1.0", "has no ase_bpm counterpart"),
    ("minimize 1e-6 1e-8 100 1000", "relaxes the scene before the run")])
def test_a_command_without_counterpart_is_refused_by_line(tmp_path, line, says):
    atoms, _, _ = SCENES["granular-hooke"]()
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    lines = open(deck).read().splitlines()
    lines.insert(-1, line)
    with open(deck, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=rf"line {len(lines) - 1}: '{line}': {says}"):
        ase_bpm.read_lammps(data, deck)


def test_a_deck_written_by_hand_is_read(tmp_path):
    """Comments, continuation lines, NULL coefficients (LAMMPS' defaults) and
    units si: the same Granular as the keywords."""
    atoms = sphere_pile(seed=3)
    atoms.calc = ase_bpm.Granular("hooke/history", kn=1000.0, gamma_n=20.0, xmu=0.3,
                                  timestep=1e-3)
    data, _ = ase_bpm.write_lammps(str(tmp_path / "pile"), atoms)
    deck = tmp_path / "in.hand"
    deck.write_text("# a pile of spheres\nunits si\natom_style sphere\nboundary m m m\n"
                    f"read_data {os.path.basename(data)}\n"
                    "pair_style gran/hooke/history 1000.0 NULL 20.0 NULL &\n"
                    "    0.3 1  # Kn Kt gamma_n gamma_t xmu dampflag\n"
                    "pair_coeff * *\nneighbor 0.2 bin\n"
                    "fix 1 all nve/sphere\ntimestep 0.001\nrun 100\n")
    back = ase_bpm.read_lammps(data, deck)
    assert back.info["lammps_units"] == "si"
    assert back.calc.law == atoms.calc.law
    forces = atoms.get_forces()  # (another skin: the contacts summed in another order)
    assert np.abs(back.get_forces() - forces).max() <= 1e-12 * np.abs(forces).max()


def _edited_deck(tmp_path, name, edit):
    """Scene ``name`` written, its deck's lines changed by ``edit(lines)``."""
    atoms, _, _ = SCENES[name]()
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    lines = open(deck).read().splitlines()
    with open(deck, "w") as fh:
        fh.write("\n".join(edit(lines)) + "\n")
    return data, deck


def _replace(old, new):
    return lambda lines: [new if line.startswith(old) else line for line in lines]


def _before_run(*extra):
    return lambda lines: lines[:-1] + list(extra) + lines[-1:]


@pytest.mark.parametrize("name,edit,message", [
    ("spring", _replace("dimension", "dimension 2"), r"'dimension 2': read_lammps reads "
                                                       r"'dimension 3'"),
    ("spring", _before_run("neigh_modify exclude type 1 1"), r"neigh_modify with every"),
    # (volume/factor is read: its bond_coeff lines then need a_v)
    ("spring", _replace("bond_style", "bond_style bpm/spring volume/factor yes"),
     r"'bond_coeff 1 1.0 0.06 0.2': read_lammps reads 'bond_coeff <type> k eps_c gamma a_v'"),
    ("spring", _replace("bond_style", "bond_style bpm/spring volume/factor maybe"),
     r"'bond_style bpm/spring volume/factor maybe': read_lammps reads"),
    # (a '*' range is read, as LAMMPS reads it: test_rotational_io.py; one that is no
    # range is refused)
    ("spring", _replace("bond_coeff 1", "bond_coeff 1*x 1.0 0.06 0.2"),
     r"'bond_coeff 1\*x 1.0 0.06 0.2': read_lammps reads 'bond_coeff <type> k eps_c gamma'"),
    ("granular-hooke", _replace("fix integrate", "fix integrate all nve/sphere disc"),
     r"'fix integrate all nve/sphere disc': disc integrates 2-D discs \(moment of "
     r"inertia m r\^2 / 2; LAMMPS takes it in 'dimension 2' only\), and ase_bpm's scenes "
     r"are 3-D"),
    ("granular-hooke", _replace("fix ase_bpm_freeze", "fix ase_bpm_freeze ase_bpm_frozen "
                                                      "setforce 0.0 0.0 0.0"),
     r"setforce 0.0 0.0 0.0 for point particles"),
    ("granular-hooke", lambda lines: lines + ["fix again all nve/sphere", "run 10"],
     r"'fix again all nve/sphere' after the run of line \d+: fix nve/sphere is not one "
     r"ase_bpm defines anew between runs; ase_bpm carries out unfix <id>, fix <id> <group> "
     r"gravity\|wall/gran\|indent\|freeze\|setforce, velocity <group> set, timestep, .* and run "
     r"N \[upto\] between runs"),
    ("granular-hooke", lambda lines: lines + ["fix heat all langevin 1.0 1.0 1.0 9",
                                              "run 10"],
     r"'fix heat all langevin 1.0 1.0 1.0 9': adds a thermostat's random forces"),
    ("spring-fixes", _replace("fix ase_bpm_indent1 ", "fix i all indent 2.0 sphere 0 0 0 1.5 "
                                                      "side in units box"),
     r"read_lammps reads 'fix <id> all indent K sphere x y z R units box'"),
    ("granular-hooke", lambda lines: lines[:-1] + ["fix heat all langevin 1.0 1.0 1.0 9 &",
                                                   "  zero yes"] + lines[-1:],
     r"'fix heat all langevin 1.0 1.0 1.0 9 zero yes': adds a thermostat's random forces"),
])
def test_a_deck_that_would_run_other_physics_is_refused_by_line(tmp_path, name, edit, message):
    data, deck = _edited_deck(tmp_path, name, edit)
    with pytest.raises(ValueError, match=r"line \d+: .*" + message):
        ase_bpm.read_lammps(data, deck)


def test_data_file_sections_beyond_the_scene_are_refused(tmp_path):
    atoms, _, _ = spring_scene()
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms)
    with open(data, "a") as fh:
        fh.write("\nPair Coeffs\n\n1 1.0 1.0 0.5\n")
    with pytest.raises(ValueError, match=r"section 'Pair Coeffs': read_lammps reads Masses, "
                                         r"Atoms, Velocities, Bonds"):
        ase_bpm.read_lammps(data, deck)


def test_held_particles_of_two_groups_are_held_together(tmp_path):
    def two_groups(lines):
        out = []
        for line in lines:
            if line.startswith("group ase_bpm_frozen"):
                out += ["group a id 3 5:6", "group b id 41"]
            elif line.startswith("fix ase_bpm_freeze"):
                out += ["fix ha a freeze", "fix hb b freeze"]
            else:
                out.append(line)
        return out

    data, deck = _edited_deck(tmp_path, "granular-hooke", two_groups)
    back = ase_bpm.read_lammps(data, deck)
    assert [c.todict() for c in back.constraints] == [
        {"name": "FixAtoms", "kwargs": {"indices": [2, 4, 5, 40]}}]


def test_a_peri_scene_lammps_would_run_otherwise_is_not_exported(tmp_path):
    atoms = sc_block(5)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb")}, timestep=1e-7,
                                 follows="legacy")
    with pytest.raises(ValueError, match=r"legacy PERI always pushes nodes apart at short "
                                         r"range: .* pair_coeffs=\{\(1, 1\): "):
        ase_bpm.write_lammps(str(tmp_path / "bare"), atoms)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb")}, timestep=1e-7,
                                 pair_coeffs={(1, 1): (MICROMODULUS, HORIZON)},
                                 follows="legacy")
    with pytest.raises(ValueError, match="no LAMMPS export of BPMPeri in lj units"):
        ase_bpm.write_lammps(str(tmp_path / "lj"), atoms, units="lj")


def test_a_timestep_among_the_extra_lines_is_a_timestep(tmp_path):
    atoms, _, _ = spring_scene()
    atoms.calc.set(timestep=None)
    _, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10,
                                   extra=["timestep 0.05"])
    assert "timestep 0.05" in open(deck).read()


# -- fix IDs as LAMMPS keeps them (issue 30) --------------------------------------------

@pytest.mark.oracle
@pytest.mark.parametrize("lines,g", [
    (["fix 2 all gravity 1.0 vector 0 0 -1", "fix 2 all gravity 2.0 vector 0 0 -1"], 2.0),
    (["fix 2 all gravity 1.0 vector 0 0 -1", "fix 3 all gravity 0.5 vector 0 0 -1",
      "unfix 2"], 0.5),
    (["fix 2 all gravity 1.0 vector 0 0 -1", "unfix 2"], 0.0),
], ids=["defined-again", "unfix", "unfix-all"])
def test_fix_ids_as_lammps_keeps_them(Oracle, tmp_path, lines, g):
    """A fix defined again with its ID replaces the first, and unfix removes
    one: the same forces as the reference build (before, the two gravities
    of the first case added up to 3)."""
    atoms, _, _ = spring_scene()
    free = atoms.get_forces()
    back = _read_with_lammps(tmp_path, atoms, lines)
    expected = free + g * atoms.get_masses()[:, None] * np.array([0.0, 0.0, -1.0])
    assert np.abs(back.get_forces() - expected).max() <= 1e-12 * np.abs(expected).max()


def _read_with_lammps(tmp_path, atoms, lines):
    """``atoms`` written for LAMMPS with ``lines`` before the deck's run 0,
    read back; their forces checked against the reference build's."""
    from oracle import run_deck

    data, deck = ase_bpm.write_lammps(str(tmp_path / "setup"), atoms)
    text = open(deck).read().splitlines()
    with open(deck, "w") as fh:
        fh.write("\n".join(text[:-1] + lines + text[-1:]) + "\n")
    back = ase_bpm.read_lammps(data, deck)
    forces = back.get_forces()
    lmp = run_deck(deck)
    try:
        assert np.abs(true_forces(lmp, back) - forces).max() <= 1e-9 * np.abs(forces).max()
    finally:
        lmp.close()
    return back


def test_a_fix_id_again_with_another_style_is_refused(tmp_path):
    data, deck = _edited_deck(tmp_path, "granular-hooke", _before_run(
        "fix 2 all gravity 1.0 vector 0 0 -1",
        "fix 2 all wall/gran hooke 1000.0 NULL 20.0 NULL 0.3 1 zplane 0.0 NULL"))
    with pytest.raises(ValueError, match=r"line \d+: 'fix 2 all wall/gran .*': fix ID 2 is "
                                         r"a fix gravity already"):
        ase_bpm.read_lammps(data, deck)


@pytest.mark.oracle
@pytest.mark.parametrize("style", ["vector 0.3 -0.2 -1.0", "spherical 30.0 60.0",
                                   "spherical 0.0 -180.0", "chute 24.0"])
def test_every_3d_gravity_style_is_the_reference_builds(Oracle, tmp_path, style):
    """fix gravity vector, spherical and chute (examples/pour uses chute 0.0 and
    spherical 0.0 -180.0): the same forces as the reference build."""
    atoms, _, _ = spring_scene()
    back = _read_with_lammps(tmp_path, atoms, [f"fix g all gravity 1.5 {style}"])
    (gravity,) = back.calc.fixes
    assert np.isclose(np.linalg.norm(gravity.acceleration), 1.5)


def test_a_gravity_style_ase_bpm_lacks_is_refused(tmp_path):
    data, deck = _edited_deck(tmp_path, "granular-hooke", _before_run(
        "fix g all gravity 1.0 gradient 0.0 0.0 1.0 0.0"))
    with pytest.raises(ValueError, match=r"'fix g all gravity 1.0 gradient .*': read_lammps "
                                         r"reads 'fix <id> all gravity g vector x y z' \(or "
                                         r"'spherical phi theta', 'chute angle'\)"):
        ase_bpm.read_lammps(data, deck)
