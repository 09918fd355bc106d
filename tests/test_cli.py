"""The ``ase-bpm`` command and the impact demo (quick variant)."""

import inspect
import shutil
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest
from ase.io import read

import ase_bpm
from ase_bpm.scene.cli import main, parser
from ase_bpm.scene.demos import beam, impact, pour, shatter
from ase_bpm.scene.demos.impact import LATTICE, impact_scene

DEMOS = {"impact": (impact, impact.run_impact), "shatter": (shatter, shatter.run_shatter),
         "pour": (pour, pour.run_pour), "beam": (beam, beam.run_beam)}


def help_text(capsys, monkeypatch, *args) -> str:
    """The help of ``ase-bpm *args``, on one line."""
    monkeypatch.setenv("COLUMNS", "1000")
    with pytest.raises(SystemExit) as exit:
        parser().parse_args([*args, "--help"])
    assert exit.value.code == 0
    return " ".join(capsys.readouterr().out.split())


def test_version_is_the_one_in_the_package_and_its_metadata(capsys):
    with pytest.raises(SystemExit) as exit:
        main(["--version"])
    assert exit.value.code == 0
    assert capsys.readouterr().out == f"ase-bpm {ase_bpm.__version__}\n"
    assert version("ase-bpm") == ase_bpm.__version__  # pyproject reads the same literal


@pytest.mark.parametrize("demo", DEMOS)
@pytest.mark.parametrize("option,value,message", [
    ("--steps", "-5", "must be at least 0, got -5"),
    ("--steps", "ten", "expected an integer, got 'ten'"),
    ("--every", "0", "must be at least 1, got 0"),
    ("--every", "-3", "must be at least 1, got -3"),
    ("--every", "1.5", "expected an integer, got '1.5'"),
])
def test_a_bad_number_is_refused_naming_the_option(demo, option, value, message, capsys):
    with pytest.raises(SystemExit) as exit:
        parser().parse_args(["demo", demo, option, value])
    assert exit.value.code == 2
    assert f"error: argument {option}: {message}" in capsys.readouterr().err


@pytest.mark.parametrize("demo", DEMOS)
def test_the_smallest_numbers_are_taken(demo):
    args = parser().parse_args(["demo", demo, "--steps", "0", "--every", "1"])
    assert (args.steps, args.every) == (0, 1)


def test_zero_steps_writes_the_starting_scene(tmp_path, capsys):
    traj = tmp_path / "impact.extxyz"
    assert main(["demo", "impact", "--quick", "--steps", "0", "--trajectory", str(traj),
                 "--plot", "", "--picture", "", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "0 broken after 0 steps" in out and "ms/step" not in out  # no step to time
    assert len(read(traj, ":")) == 1


@pytest.mark.parametrize("demo", DEMOS)
def test_help_states_the_defaults_that_run(demo, capsys, monkeypatch):
    module, run = DEMOS[demo]
    text = help_text(capsys, monkeypatch, "demo", demo)
    assert f"(default {module.STEPS}, with --quick {module.QUICK_STEPS};" in text
    assert f"{module.QUICK_STEPS:,} steps" in text and f"{module.STEPS:,} steps" in text
    every = parser().parse_args(["demo", demo]).every
    assert every == inspect.signature(run).parameters["every"].default
    assert f"the last one (default {every})" in text


def test_impact_quick_help_states_the_quick_scene(capsys, monkeypatch):
    atoms = impact_scene(**impact.QUICK)
    assert f"--quick a small disk and ball ({len(atoms):,} particles)" in \
        help_text(capsys, monkeypatch, "demo", "impact")


def test_impact_scene_matches_the_lammps_deck():
    """Counts and initial kinetic energy of LAMMPS examples/bpm/impact."""
    atoms = impact_scene()
    body = atoms.arrays["body"]
    assert (body == 0).sum() == 7529 and (body == 1).sum() == 3589
    # LAMMPS log: KinEng 0.0010167873 per atom at step 0
    assert abs(atoms.get_kinetic_energy() / len(atoms) - 0.0010167873) < 5e-11
    from ase_bpm import get_bonds

    i, j, t = get_bonds(atoms)
    # 38559 and 21869 bonds in LAMMPS; our random displacements differ slightly
    assert abs((t == 1).sum() - 38559) < 200 and abs((t == 2).sum() - 21869) < 200
    assert np.all(body[i] == body[j])
    d = np.linalg.norm(atoms.positions[j] - atoms.positions[i], axis=1)
    assert d.max() <= 1.5 and LATTICE == 4 ** (1 / 3)


def test_demo_impact_quick_writes_trajectory_plot_and_picture(tmp_path, capsys):
    traj, plot, picture = (tmp_path / name for name in
                           ("impact.extxyz", "impact.png", "final.png"))
    assert main(["demo", "impact", "--quick", "--steps", "400", "--every", "100",
                 "--trajectory", str(traj), "--plot", str(plot), "--picture", str(picture),
                 "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "broken after 400 steps" in out and "ms/step" in out
    assert (f'(ase gui {traj}; View > Colors ... > By user-defined "damage"; '
            "View > Change view > yz-plane: the disk face-on)") in out
    assert f"picture: {picture}" in out
    frames = read(traj, ":")
    assert len(frames) == 5 and all(map(encloses_its_particles, frames))
    assert {"damage", "nbonds"} <= set(frames[-1].arrays)
    assert frames[-1].info["step"] == 400
    assert frames[-1].arrays["damage"].max() > 0  # the ball has broken bonds by now
    for png in (plot, picture):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def encloses_its_particles(frame) -> bool:
    """Is every particle's centre in the frame's cell as written (the
    cell's origin at zero: extxyz has no other)?"""
    s_nc = frame.cell.scaled_positions(frame.positions)
    return frame.cell.rank == 3 and bool(np.all((s_nc >= 0) & (s_nc <= 1)))


def test_console_script_is_installed():
    script = shutil.which("ase-bpm") or str(Path(sys.executable).parent / "ase-bpm")
    result = subprocess.run([script, "demo", "impact", "--help"], capture_output=True,
                            text=True)
    assert result.returncode == 0 and "--quick" in result.stdout


def test_shatter_scene_matches_the_lammps_deck():
    from ase_bpm import get_bonds
    from ase_bpm.scene.demos.shatter import cylinder

    atoms = cylinder()
    assert len(atoms) == 3487  # LAMMPS: "Created 3487 atoms"
    assert len(get_bonds(atoms)[0]) == 167983  # "Added 167983 bonds"


def test_demo_shatter_writes_trajectory_plot_and_picture(tmp_path, capsys):
    traj, plot, picture = (tmp_path / name for name in
                           ("shatter.extxyz", "shatter.png", "final.png"))
    assert main(["demo", "shatter", "--steps", "120", "--every", "40",
                 "--trajectory", str(traj), "--plot", str(plot), "--picture", str(picture),
                 "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "3487 nodes" in out and "ms/step" in out
    frames = read(traj, ":")
    assert len(frames) == 4 and frames[-1].arrays["damage"].max() > 0  # the indenter hit
    assert all(map(encloses_its_particles, frames))
    for png in (plot, picture):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_pour_scene_starts_apart_and_in_the_box():
    from ase_bpm.scene.demos.pour import FULL, pour_scene
    from ase_bpm.core.neighbours import neighbour_pairs

    atoms = pour_scene(**FULL)
    r = atoms.arrays["radius"]
    assert len(atoms) == 3000 and 0.4 <= r.min() and r.max() <= 0.6
    i, j, _ = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc, r)
    assert len(i) == 0  # no two spheres touch at the release
    assert (atoms.positions[:, :2] - r[:, None]).min() > 0
    assert (atoms.positions[:, :2] + r[:, None]).max() < FULL["width"]
    assert (atoms.positions[:, 2] - r).min() > 0
    assert np.allclose(atoms.get_masses(), 4 / 3 * np.pi * r ** 3)  # density 1


def test_demo_pour_quick_writes_trajectory_plot_and_picture(tmp_path, capsys):
    traj, plot, picture = (tmp_path / name for name in
                           ("pour.extxyz", "pour.png", "final.png"))
    assert main(["demo", "pour", "--quick", "--steps", "3000", "--every", "1000",
                 "--trajectory", str(traj), "--plot", str(plot), "--picture", str(picture),
                 "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "500 spheres" in out and "ms/step" in out
    frames = read(traj, ":")
    assert len(frames) == 4 and frames[-1].info["step"] == 3000
    assert all(map(encloses_its_particles, frames))
    assert {"radius", "ncontacts"} <= set(frames[-1].arrays)
    # the spheres fell: the lowest layer rests on the floor, in many contacts
    assert frames[-1].positions[:, 2].max() < frames[0].positions[:, 2].max() - 2.0
    assert frames[-1].arrays["ncontacts"].sum() > frames[0].arrays["ncontacts"].sum() + 200
    for png in (plot, picture):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# -- ase-bpm export ------------------------------------------------------------------

EXPORT_RUNS = {"impact": ("ase.md.verlet", 1.0), "shatter": ("ase_bpm", 0.0005),
               "pour": ("ase_bpm", 0.8)}  # each demo's integrator module, a length


@pytest.mark.oracle
@pytest.mark.parametrize("name", list(EXPORT_RUNS))
def test_export_writes_a_demo_that_lammps_runs_as_ase_bpm_does(Oracle, tmp_path, capsys,
                                                               name):
    """``ase-bpm export <demo> --quick``: the deck runs in the reference build
    to the positions ase_bpm reaches in the same steps with the demo's
    integrator, and reads back as the demo's scene."""
    import importlib

    from oracle import gather, run_deck

    module, integrator_home = DEMOS[name][0], EXPORT_RUNS[name][0]
    stem = tmp_path / name
    assert main(["export", name, "--quick", "--steps", "20", "--output", str(stem)]) == 0
    data, deck = str(tmp_path / f"{name}.data"), str(tmp_path / f"in.{name}")
    assert f"mpirun -np 4 lmp -in {deck}" in capsys.readouterr().out
    atoms = module.demo_scene(quick=True)
    back = ase_bpm.read_lammps(data, deck)
    assert np.array_equal(back.positions, atoms.positions)
    assert np.array_equal(back.get_masses(), atoms.get_masses())
    lmp = run_deck(deck)
    try:
        integrator = {"impact": "VelocityVerlet", "shatter": "VelocityVerlet",
                      "pour": "SphereVelocityVerlet"}[name]
        dyn = getattr(importlib.import_module(integrator_home), integrator)
        dyn(atoms, module.TIMESTEP).run(20)
        assert np.abs(gather(lmp, "x") - atoms.positions).max() <= 1e-9 * EXPORT_RUNS[name][1]
    finally:
        lmp.close()


def test_export_refuses_a_demo_it_does_not_know(capsys):
    with pytest.raises(SystemExit) as exit:
        main(["export", "avalanche"])
    assert exit.value.code == 2
    assert "invalid choice: 'avalanche'" in capsys.readouterr().err


# -- the demos' pictures say what they show ------------------------------------------

TAU = "time (\N{GREEK SMALL LETTER TAU}, reduced LJ units)"


def discs(ax) -> list:
    """The particles of a picture: one disc each."""
    from matplotlib.patches import Circle

    return [patch for patch in ax.patches if isinstance(patch, Circle)]


def test_the_disk_picture_shows_the_disk_face_on_coloured_by_damage(tmp_path):
    from matplotlib import colormaps

    atoms = impact.demo_scene(quick=True)
    atoms.get_forces()  # (the reference lengths: the particles' size)
    disk = atoms.arrays["body"] == 0
    broken = np.flatnonzero(disk)[:10]
    atoms.arrays["damage"] = np.zeros(len(atoms))
    atoms.arrays["damage"][broken] = 1.0
    path = tmp_path / "disk.png"
    fig = impact.draw_disk(atoms, path, "after 0 steps")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    picture, bar = fig.axes
    assert picture.get_title() == "ase-bpm impact: the disk after 0 steps"
    assert bar.get_ylabel() == "damage (share of the particle's bonds broken)"
    assert bar.get_ylim() == (0.0, 1.0)
    drawn = discs(picture)
    assert len(drawn) == disk.sum()  # the disk's particles, not the ball's
    colours = np.array([d.get_facecolor()[:3] for d in drawn])
    red, blue = (np.array(colormaps["coolwarm"](x)[:3]) for x in (1.0, 0.0))
    assert np.isclose(colours, red).all(axis=1).sum() == len(broken)
    assert np.isclose(colours, blue).all(axis=1).sum() == disk.sum() - len(broken)
    # face-on: the disk is as wide as it is high in the picture
    centres = np.array([d.center for d in drawn])
    width, height = np.ptp(centres, axis=0)
    assert abs(width / height - 1) < 0.05


def test_the_cylinder_picture_says_what_colour_means(tmp_path):
    from ase import Atoms

    atoms = Atoms("Si8", positions=np.indices((2, 2, 2)).reshape(3, -1).T * shatter.SPACING)
    atoms.arrays["damage"] = np.linspace(0.0, 0.9, 8)
    fig = shatter.draw(atoms, tmp_path / "final.png", "after 5 steps")
    assert (tmp_path / "final.png").exists()
    picture, bar = fig.axes
    assert picture.get_title() == "ase-bpm shatter: the cylinder after 5 steps"
    assert bar.get_ylabel() == "damage (share of the node's bond volume lost)"
    assert bar.get_ylim() == (0.0, shatter.DAMAGE_TOP) and len(discs(picture)) == 8


def test_the_pile_picture_says_what_colour_means(tmp_path):
    atoms = pour.pour_scene(count=20, width=5.0)
    fig = pour.draw(atoms, tmp_path / "final.png", "after 0 steps")
    assert (tmp_path / "final.png").exists()
    picture, bar = fig.axes
    assert picture.get_title() == "ase-bpm pour: the pile after 0 steps"
    assert bar.get_ylabel() == "height of the centre above the floor (reduced units)"
    assert bar.get_ylim() == (0.0, atoms.positions[:, 2].max())
    radii = sorted(d.radius for d in discs(picture))  # spheres at their true size
    assert np.allclose(np.array(radii) / sorted(atoms.arrays["radius"]), radii[0] /
                       min(atoms.arrays["radius"]), rtol=1e-9, atol=0)


@pytest.mark.parametrize("plot,series,xlabel,title", [
    (impact.plot_series, {"kinetic_energy": [1.0, 0.5], "intact_bonds": [10, 8]}, TAU,
     "ase-bpm: ball striking a bonded disk"),
    (shatter.plot_damage, {"mean_damage": [0.0, 0.1]}, "time (\N{MICRO SIGN}s)",
     "ase-bpm: brittle cylinder struck by an indenter"),
    (pour.plot_energy, {"kinetic_energy": [1.0, 0.5], "rotational_energy": [0.0, 0.1],
                        "contacts": [0, 5]}, TAU, "ase-bpm: spheres poured into a box"),
])
def test_time_axes_name_their_units(plot, series, xlabel, title, tmp_path):
    fig = plot({"time": [0.0, 1e-5], **series}, tmp_path / "plot.png")
    assert (tmp_path / "plot.png").exists()
    assert fig.axes[0].get_title() == title
    assert fig.axes[-1].get_xlabel() == xlabel  # (the lowest panel's, which shares it)


# -- the rotational impact (in.bpm.impact.rotational) ---------------------------------

#: in.bpm.impact.rotational's two bond_coeff lines
ROTATIONAL_DECK_COEFFS = ("1 1.0 0.2 0.02 0.02 0.05 0.01 0.01 0.01 0.1 0.2 0.002 0.002",
                          "2 1.0 0.2 0.02 0.02 0.20 0.04 0.04 0.04 0.1 0.2 0.002 0.002")


def test_rotational_impact_scene_is_the_lammps_decks():
    """The spring scene's disk and ball as atom_style bpm/sphere particles
    (diameter 1, density 1) at the same places, the ball at the same speed:
    the kinetic energy of LAMMPS's log at step 0; the deck's bond_coeff
    lines and pair style."""
    atoms = impact.demo_scene(bonds="rotational")
    # log.4May2022.impact.rotational.g++.4: KinEng 0.00053238861 per atom at step 0
    assert abs(atoms.get_kinetic_energy() / len(atoms) - 0.00053238861) < 5e-12
    springs = impact.demo_scene()
    assert np.array_equal(atoms.positions, springs.positions)
    assert np.array_equal(atoms.get_velocities(), springs.get_velocities())
    assert np.all(atoms.arrays["radius"] == 0.5)
    assert np.allclose(atoms.get_masses(), np.pi / 6, rtol=1e-15)
    coeffs = atoms.calc.parameters["bond_coeffs"]
    for line in ROTATIONAL_DECK_COEFFS:
        bond_type, *values = line.split()
        assert coeffs[int(bond_type)] == ("bpm/rotational", *map(float, values))
    assert atoms.calc.parameters["granular"] == dict(model="hooke/history", kn=1.0,
                                                     gamma_n=0.5, xmu=0.1, dampflag=1)
    assert atoms.calc.parameters["pair_coeffs"] == {}


def test_impact_refuses_bonds_it_does_not_have(capsys):
    with pytest.raises(ValueError, match="bonds='plastic': the impact demo's bonds are "
                                         "'spring', 'rotational'"):
        impact.demo_scene(quick=True, bonds="plastic")
    with pytest.raises(SystemExit) as exit:
        parser().parse_args(["demo", "impact", "--bonds", "plastic"])
    assert exit.value.code == 2
    assert "argument --bonds: invalid choice: 'plastic'" in capsys.readouterr().err


def test_demo_impact_rotational_writes_trajectory_plot_and_picture(tmp_path, capsys):
    """The quick rotational impact, its first 300 steps (the ball in flight:
    no force acts, so the kinetic energy stays what it was), with
    SphereVelocityVerlet: frames with the spheres' radius and contacts, the
    plot and the picture."""
    traj, plot, picture = (tmp_path / name for name in
                           ("impact.extxyz", "impact.png", "final.png"))
    start = impact.demo_scene(quick=True, bonds="rotational").get_kinetic_energy()
    assert main(["demo", "impact", "--bonds", "rotational", "--quick", "--steps", "300",
                 "--every", "100", "--trajectory", str(traj), "--plot", str(plot),
                 "--picture", str(picture), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "1648 particles, 8393 rotational bonds, 0 broken after 300 steps" in out
    assert f"final kinetic energy {start:.8g}" in out
    frames = read(traj, ":")
    assert len(frames) == 4 and frames[-1].info["step"] == 300
    assert frames[-1].info["time"] == 300 * impact.VARIANTS["rotational"].timestep
    assert {"radius", "damage", "nbonds", "ncontacts"} <= set(frames[-1].arrays)
    assert all(map(encloses_its_particles, frames))
    for png in (plot, picture):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_rotational_impact_defaults_and_help(capsys, monkeypatch):
    rotational = impact.VARIANTS["rotational"]
    assert rotational.steps * rotational.timestep == 375  # the deck's run 7500, 0.05
    assert rotational.quick_steps * rotational.timestep == impact.QUICK_STEPS * impact.TIMESTEP
    text = help_text(capsys, monkeypatch, "demo", "impact")
    assert (f"--bonds rotational: {rotational.steps:,} and {rotational.quick_steps:,} steps "
            f"of {rotational.timestep:g}") in text
    assert "--bonds {spring,rotational}" in text and "default spring" in text
    assert parser().parse_args(["demo", "impact"]).bonds == "spring"


@pytest.mark.oracle
def test_export_impact_rotational_runs_in_lammps_as_in_ase_bpm(tmp_path, capsys):
    """``ase-bpm export impact --bonds rotational --quick``: a bpm/sphere deck
    (bond_style bpm/rotational, pair_style gran/hooke/history, fix
    nve/bpm/sphere) that the reference build runs to the positions,
    orientations and bonds SphereVelocityVerlet reaches, over the ball's
    first contact and the first broken bonds (600 steps)."""
    from oracle import gather, run_deck

    steps = 600
    assert main(["export", "impact", "--bonds", "rotational", "--quick", "--steps",
                 str(steps), "--output", str(tmp_path / "impact")]) == 0
    deck = tmp_path / "in.impact"
    assert f"lmp -in {deck}" in capsys.readouterr().out
    text = deck.read_text()
    assert "atom_style bpm/sphere" in text and "bond_style bpm/rotational" in text
    assert "fix integrate all nve/bpm/sphere" in text and "timestep 0.05" in text
    assert "pair_style gran/hooke/history 1.0 0.2857142857142857 0.5 0.25 0.1 1" in text
    atoms = impact.demo_scene(quick=True, bonds="rotational")
    lmp = run_deck(str(deck))
    try:
        ase_bpm.SphereVelocityVerlet(atoms, impact.VARIANTS["rotational"].timestep).run(steps)
        assert int(atoms.arrays["nbonds"].sum()) // 2 < len(ase_bpm.get_bonds(
            impact.demo_scene(quick=True, bonds="rotational"))[0])  # bonds broke
        assert np.abs(gather(lmp, "x") - atoms.positions).max() <= 1e-9 * LATTICE
        assert np.abs(gather(lmp, "quat") - atoms.arrays["quat"]).max() <= 1e-9
        assert len(np.array(lmp.numpy.gather_bonds()).reshape(-1, 3)) == len(
            ase_bpm.get_bonds(atoms)[0])
    finally:
        lmp.close()


def test_export_takes_bonds_for_the_impact_only(tmp_path, capsys):
    assert main(["export", "pour", "--bonds", "rotational", "--output",
                 str(tmp_path / "pour")]) == 2
    assert ("ase-bpm export: --bonds rotational: only the impact demo has a choice of "
            "bonds, not pour") in capsys.readouterr().err
    assert not (tmp_path / "pour.data").exists()
    with pytest.raises(SystemExit) as exit:
        main(["export", "beam"])  # two bond styles: no one LAMMPS deck
    assert exit.value.code == 2
    assert "invalid choice: 'beam'" in capsys.readouterr().err


def test_the_rotational_impact_picture_shows_the_ball_in_grey(tmp_path):
    from ase_bpm.scene.demos import CONTEXT_COLOUR

    atoms = impact.demo_scene(quick=True, bonds="rotational")
    atoms.get_forces()
    atoms.arrays["damage"] = np.zeros(len(atoms))
    fig = impact.draw_disk(atoms, tmp_path / "final.png", "after 0 steps", "rotational")
    picture, bar = fig.axes
    assert picture.get_title() == ("ase-bpm impact (rotational bonds):\nthe disk and the ball "
                                   "(grey) after 0 steps")
    assert bar.get_ylabel() == "damage (share of the particle's bonds broken)"
    drawn = discs(picture)
    assert len(drawn) == len(atoms)  # the disk and the ball
    grey = [np.allclose(d.get_facecolor()[:3], CONTEXT_COLOUR) for d in drawn]
    assert sum(grey) == (atoms.arrays["body"] == 1).sum()


# -- the beam: what rotational bonds are for ------------------------------------------

def test_demo_beam_quick_sags_as_beam_theory_says_and_the_chain_hangs(tmp_path):
    """The quick beam demo: the wire of rotational bonds settles at the tip
    deflection of a Timoshenko cantilever with EI = k_b a and kGA = k_s a
    (within 3 %; large deflections sag a little less than the linear
    theory); the wire of spring bonds, without bending stiffness, hangs far
    below it."""
    summary = beam.run_beam(quick=True, trajectory=str(tmp_path / "beam.extxyz"),
                            plot=None, picture=None, every=1500, progress=False)
    spheres, length = beam.QUICK, beam.QUICK * beam.SPACING
    theory = summary["theory_tip"]
    assert theory == pytest.approx(beam.SAG * length, rel=1e-12)
    assert 0.97 * theory < summary["rotational_tip"] < theory
    assert summary["rotational_speed"] < 1e-3 * theory / beam.TIMESTEP  # it has settled
    assert summary["spring_tip"] > 0.8 * length  # (it hangs)
    frames = read(tmp_path / "beam.extxyz", ":")
    assert len(frames) == 4 and frames[-1].info["step"] == beam.QUICK_STEPS
    assert list(frames[-1].arrays["wire"]) == [0] * (spheres + 1) + [1] * (spheres + 1)
    assert all(map(encloses_its_particles, frames))


def test_beam_theory_of_the_wire():
    """Without shear compliance the curve is the textbook cantilever under a
    distributed load, q L^4 / 8 EI at the tip; the shear adds q L^2 / 2 kGA;
    the gravity of the demo makes the tip sag SAG of the wire's length."""
    spheres, g = 12, 2e-3
    bending, shear = beam.beam_stiffness()
    q, length = beam.sphere_mass() * g / beam.SPACING, beam.loaded_length(spheres)
    assert length == 12.5 * beam.SPACING
    assert beam.deflection(length, spheres, g) == pytest.approx(
        q * length ** 4 / (8 * bending) + q * length ** 2 / (2 * shear), rel=1e-12)
    assert beam.deflection(0.0, spheres, g) == 0.0
    g = beam.gravity(spheres)
    assert beam.deflection(spheres * beam.SPACING, spheres, g) == pytest.approx(
        beam.SAG * spheres * beam.SPACING, rel=1e-12)


def test_demo_beam_writes_trajectory_plot_and_picture(tmp_path, capsys):
    traj, plot, picture = (tmp_path / name for name in ("beam.extxyz", "beam.png",
                                                         "final.png"))
    assert main(["demo", "beam", "--quick", "--steps", "200", "--every", "100",
                 "--trajectory", str(traj), "--plot", str(plot), "--picture", str(picture),
                 "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert f"two wires of {beam.QUICK} spheres clamped at one end, after 200 steps" in out
    assert "with rotational bonds (beam theory 1)" in out and "with spring bonds" in out
    assert f'(ase gui {traj}; View > Colors ... > By user-defined "wire")' in out
    assert len(read(traj, ":")) == 3
    for png in (plot, picture):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_beam_picture_shows_both_wires_and_the_theory(tmp_path):
    atoms = beam.demo_scene(quick=True)
    g = beam.gravity(beam.QUICK)
    fig = beam.draw(atoms, tmp_path / "final.png", g, "after 0 steps")
    ax, = fig.axes
    assert ax.get_title() == "ase-bpm beam: clamped wires after 0 steps"
    assert ax.get_ylabel() == "z (distance units; gravity along -z)"
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert labels == ["bpm/rotational bonds", "bpm/spring bonds",
                      "beam theory: EI = k_b a, kGA = k_s a"]
    assert len(discs(ax)) == len(atoms)
    curve = ax.get_lines()[-1]
    x, z = curve.get_data()
    assert np.allclose(-z, beam.deflection(x, beam.QUICK, g))
    fig = beam.plot_tips({"time": [0.0, 1.0], "rotational": [0.0, 0.5],
                          "spring": [0.0, 2.0]}, tmp_path / "plot.png", 1.0)
    assert fig.axes[0].get_xlabel() == TAU
    assert fig.axes[0].get_title() == "ase-bpm: two cantilevers under their own weight"
