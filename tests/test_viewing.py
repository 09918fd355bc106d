"""Viewing files: what a viewer shows and nothing of the calculator's state;
OVITO reads the radius and the damage from them."""

import numpy as np
import pytest
from ase.io import read

import ase_bpm
from ase_bpm import SphereVelocityVerlet, VelocityVerlet
from ase_bpm.scene.viewing import ViewerTrajectory, display_radius, is_state, viewing_copy
from scenes import fcc_cluster, sphere_pile


def breaking_block():
    """A bonded block whose bonds break within a few dozen steps, with an
    indenter (a fix) and the whole calculator state on the atoms."""
    atoms, rng = fcc_cluster(4, seed=3)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.08, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.06, 0.2)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)})
    return atoms, VelocityVerlet(atoms, timestep=0.1)


def pile():
    atoms = sphere_pile(n=3, seed=4, lift=0.3)
    atoms.calc = ase_bpm.Granular("hooke/history", kn=2000.0, gamma_n=50.0, xmu=0.5,
                                  fixes=[ase_bpm.Gravity(9.81)])
    return atoms, SphereVelocityVerlet(atoms, timestep=1e-3)


def test_frames_carry_what_a_viewer_shows_and_no_state(tmp_path):
    atoms, dyn = breaking_block()
    with ViewerTrajectory(tmp_path / "run.extxyz", atoms, velocities=True) as traj:
        dyn.attach(traj, interval=20)
        dyn.run(60)
    assert sorted(name for name in atoms.arrays if is_state(name)) == [
        "bond_partner", "bond_r0", "bond_type", "bpm_f_last", "bpm_fd_last", "bpm_id",
        "bpm_x_last", "bpm_x_ref"]  # the state the atoms carry, which the frames leave out
    frames = read(tmp_path / "run.extxyz", ":")
    assert len(frames) == 4
    for frame in frames:
        assert set(frame.arrays) == {"numbers", "positions", "radius", "damage", "nbonds",
                                     "velo"}
        assert set(frame.info) == {"step", "kinetic_energy"}
        assert frame.calc is None
    last = frames[-1]
    assert last.info["step"] == 60 and (last.arrays["damage"] > 0).sum() > 5
    assert np.allclose(last.positions, atoms.positions, rtol=0, atol=1e-8)
    assert np.allclose(last.arrays["velo"], atoms.get_velocities(), rtol=0, atol=1e-8)
    assert np.array_equal(last.arrays["nbonds"], atoms.arrays["nbonds"])


def test_state_is_refused_by_name(tmp_path):
    atoms, dyn = breaking_block()
    dyn.run(2)
    for name in ("bond_r0", "bpm_x_last", "gran_shear", "peri_theta0", "bonds"):
        with pytest.raises(ValueError, match=rf"\['{name}'\] is calculator state.*write_restart"):
            viewing_copy(atoms, arrays=("damage", name))
    with pytest.raises(ValueError, match=r"\['bpm_f_last'\] is calculator state"):
        ViewerTrajectory(tmp_path / "x.extxyz", atoms, arrays=("bpm_f_last",))
    traj = ViewerTrajectory(tmp_path / "y.extxyz", atoms)
    with pytest.raises(ValueError, match=r"info\['broken_bonds'\] is calculator state"):
        traj.write(broken_bonds=np.zeros((0, 9)))
    traj.close()


def test_display_radius():
    """Spheres: their radius.  Point particles with bonds: half their
    shortest reference bond length, the bonds' length at the first
    evaluation.  Neither: none (a viewer draws the element's size)."""
    spheres, _ = pile()
    assert display_radius(spheres) is spheres.arrays["radius"]

    atoms, dyn = breaking_block()
    assert display_radius(atoms) is None  # bonds without reference lengths yet
    i, j, _ = ase_bpm.get_bonds(atoms)
    shortest = np.linalg.norm(atoms.positions[j] - atoms.positions[i], axis=1).min()
    dyn.run(30)
    assert np.array_equal(display_radius(atoms), np.full(len(atoms), 0.5 * shortest))
    assert "radius" not in viewing_copy(fcc_cluster(2)[0]).arrays


def ovito_frames(path):
    """The particle properties OVITO reads from each frame of ``path``."""
    pytest.importorskip("ovito")
    from ovito.io import import_file

    pipeline = import_file(str(path))
    return [pipeline.compute(n).particles for n in range(pipeline.source.num_frames)]


def test_ovito_reads_radius_and_damage(tmp_path):
    atoms, dyn = breaking_block()
    with ViewerTrajectory(tmp_path / "run.extxyz", atoms, velocities=True) as traj:
        dyn.attach(traj, interval=30)
        dyn.run(60)
    frames = read(tmp_path / "run.extxyz", ":")
    seen = ovito_frames(tmp_path / "run.extxyz")
    assert len(seen) == len(frames) == 3
    for particles, frame in zip(seen, frames):
        # OVITO's standard Radius (the drawn size) and Velocity; damage its own
        assert np.allclose(particles["Radius"], frame.arrays["radius"], rtol=1e-6, atol=0)
        assert np.array_equal(particles["damage"], frame.arrays["damage"])
        assert np.allclose(particles["Velocity"], frame.arrays["velo"], rtol=1e-6, atol=0)
    assert np.asarray(seen[-1]["damage"]).max() > 0


def test_ovito_draws_spheres_at_their_radius(tmp_path):
    atoms, dyn = pile()
    with ViewerTrajectory(tmp_path / "pour.extxyz", atoms, arrays=("ncontacts", "omega")) as traj:
        dyn.attach(traj, interval=10)
        dyn.run(20)
    (particles,) = ovito_frames(tmp_path / "pour.extxyz")[-1:]
    assert np.allclose(particles["Radius"], atoms.arrays["radius"], rtol=1e-6, atol=0)
    assert np.array_equal(particles["ncontacts"], atoms.arrays["ncontacts"])
    assert np.allclose(particles["Angular Velocity"], atoms.arrays["omega"], rtol=0, atol=1e-8)


def test_frames_carry_the_per_atom_stress_on_request(tmp_path):
    """``stress=True``: the analysis' per-atom stress (compute stress/atom),
    which OVITO reads as its Stress Tensor; a model without one says so."""
    atoms, dyn = breaking_block()
    dyn.run(10)
    with ViewerTrajectory(tmp_path / "run.extxyz", atoms, stress=True) as traj:
        traj.write()
    frame = read(tmp_path / "run.extxyz")
    expected = atoms.calc.analyse(atoms).stress_n6
    assert np.abs(expected).max() > 1e-3
    # (ASE's extxyz reader hands a column named stress to the frame's calculator)
    assert np.allclose(frame.calc.results["stress"], expected, rtol=0, atol=1e-8)
    ovito = pytest.importorskip("ovito.io")
    data = ovito.import_file(str(tmp_path / "run.extxyz")).compute()
    assert np.allclose(np.asarray(data.particles["Stress Tensor"]), expected, atol=1e-8)
    from ase.calculators.emt import EMT

    spheres, _ = pile()
    assert viewing_copy(spheres, stress=True).arrays["stress"].shape == (len(spheres), 6)
    spheres.calc = EMT()
    with pytest.raises(ValueError, match="stress=True needs a calculator with analyse"):
        viewing_copy(spheres, stress=True)
