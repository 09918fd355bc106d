"""The ``ase-bpm`` command and the impact demo (quick variant)."""

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
from ase.io import read

from ase_bpm.cli import main
from ase_bpm.demos.impact import LATTICE, impact_scene


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


def test_demo_impact_quick_writes_trajectory_and_plot(tmp_path, capsys):
    traj, plot = tmp_path / "impact.extxyz", tmp_path / "impact.png"
    assert main(["demo", "impact", "--quick", "--steps", "400", "--every", "100",
                 "--trajectory", str(traj), "--plot", str(plot), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "broken after 400 steps" in out and "ms/step" in out
    frames = read(traj, ":")
    assert len(frames) == 5
    assert {"damage", "nbonds"} <= set(frames[-1].arrays)
    assert frames[-1].info["step"] == 400
    assert frames[-1].arrays["damage"].max() > 0  # the ball has broken bonds by now
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_console_script_is_installed():
    script = shutil.which("ase-bpm") or str(Path(sys.executable).parent / "ase-bpm")
    result = subprocess.run([script, "demo", "impact", "--help"], capture_output=True,
                            text=True)
    assert result.returncode == 0 and "--quick" in result.stdout


def test_shatter_scene_matches_the_lammps_deck():
    from ase_bpm import get_bonds
    from ase_bpm.demos.shatter import cylinder

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
    for png in (plot, picture):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_pour_scene_starts_apart_and_in_the_box():
    from ase_bpm.demos.pour import FULL, pour_scene
    from ase_bpm.neighbours import neighbour_pairs

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
    assert {"radius", "ncontacts"} <= set(frames[-1].arrays)
    # the spheres fell: the lowest layer rests on the floor, in many contacts
    assert frames[-1].positions[:, 2].max() < frames[0].positions[:, 2].max() - 2.0
    assert frames[-1].arrays["ncontacts"].sum() > frames[0].arrays["ncontacts"].sum() + 200
    for png in (plot, picture):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
