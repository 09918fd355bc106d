"""BPMSpring against the reference LAMMPS build (bond + pair bpm/spring)."""

import itertools
import os

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.scene.lammps import lammps_commands, load_lammps, write_lammps
from oracle import gather, read_dump_local, run_deck
from scenes import MULTI_TYPE_COEFFS, deform_below_breaking, fcc_cluster, multi_type_cluster

pytestmark = pytest.mark.oracle

COMBINATIONS = list(itertools.product(
    [True, False], [False, True], [False, True], ["geometric", "arithmetic"]))


def intact_pairs(atoms):
    i, j, _ = ase_bpm.get_bonds(atoms)
    return {(min(a, b), max(a, b)) for a, b in zip(i, j)}


@pytest.mark.parametrize("smooth,normalize,overlay,mix", COMBINATIONS)
def test_forces_at_deformed_state(Oracle, smooth, normalize, overlay, mix):
    """Forces after the reference state was taken, strains up to 0.97 eps_c."""
    atoms, rng = multi_type_cluster(seed=1)
    calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, mix=mix, smooth=smooth,
                             normalize=normalize, overlay_pair=overlay)
    atoms.calc = calc
    lmp = Oracle(atoms, calc)
    try:
        f_ref = atoms.get_forces()
        lmp.run(0)
        assert np.abs(f_ref - lmp.forces()).max() <= 1e-9 * np.abs(f_ref).max()

        positions = deform_below_breaking(atoms, rng)
        velocities = rng.normal(0, 0.1, positions.shape)
        atoms.positions = positions
        atoms.set_velocities(velocities)
        forces = atoms.get_forces()
        lmp.set_state(positions, velocities)
        lmp.run(0)
        expected = lmp.forces()
        assert np.abs(forces - expected).max() <= 1e-9 * np.abs(expected).max()
        assert intact_pairs(atoms) == lmp.intact_bonds()
    finally:
        lmp.close()


@pytest.mark.parametrize("overlay", [False, True])
def test_force_scene_exercises_contacts_and_mixing(overlay):
    """On the parity scene, contacts and the mixing rule both change the
    forces, so the parity test above can tell a wrong pair law or a wrong
    mixing rule from a right one."""
    forces = {}
    for mix, pairs in (("geometric", True), ("arithmetic", True), ("geometric", False)):
        atoms, rng = multi_type_cluster(seed=1)
        coeffs = dict(MULTI_TYPE_COEFFS)
        if not pairs:
            coeffs["pair_coeffs"] = {}
        atoms.calc = ase_bpm.BPMSpring(**coeffs, mix=mix, overlay_pair=overlay)
        atoms.get_forces()
        atoms.positions = deform_below_breaking(atoms, rng)
        forces[mix, pairs] = atoms.get_forces()
    scale = np.abs(forces["geometric", True]).max()
    assert np.abs(forces["geometric", True] - forces["geometric", False]).max() > 0.1 * scale
    assert np.abs(forces["geometric", True] - forces["arithmetic", True]).max() > 1e-3 * scale


def breaking_cluster(pbc=False, seed=3):
    atoms, rng = fcc_cluster(4, seed=seed, ntypes=2, pbc=pbc)
    ase_bpm.create_bonds(atoms, 1.5, bond_type=1)
    ase_bpm.create_bonds(atoms, 1.6, bond_type=2, mask=atoms.arrays["type"] == 2)
    atoms.set_velocities(rng.normal(0, 0.08, atoms.positions.shape))
    calc = ase_bpm.BPMSpring(
        bond_coeffs={1: (1.0, 0.06, 0.2), 2: (1.5, 0.09, 0.4)},
        pair_coeffs={(1, 1): (1.0, 1.0, 0.5), (2, 2): (1.0, 1.1, 0.3)})
    atoms.calc = calc
    return atoms, calc


def test_trajectory_with_breaking_bonds(Oracle):
    """ASE VelocityVerlet against LAMMPS fix nve: 500 steps, hundreds of breaks."""
    atoms, calc = breaking_cluster()
    lmp = Oracle(atoms, calc, timestep=0.1)
    try:
        before = intact_pairs(atoms)
        VelocityVerlet(atoms, timestep=0.1).run(500)
        lmp.run(500)
        after = intact_pairs(atoms)
        assert len(before) - len(after) > 100  # bonds did break
        assert after == lmp.intact_bonds()
        assert lmp.position_error(atoms.positions).max() <= 1e-9
        assert np.abs(lmp.velocities() - atoms.get_velocities()).max() <= 1e-9
        # the broken-bond log names exactly the bonds that broke
        log = atoms.info["broken_bonds"]
        assert {(int(i), int(j)) for i, j in log[:, :2]} == before - after
        assert atoms.info["bpm_step"] == 500
    finally:
        lmp.close()


@pytest.mark.parametrize("normalize", [False, True])
def test_bonds_past_eps_c_keep_acting_with_break_no(Oracle, normalize):
    """``smooth no break no``: stretched to 1.7 and 2.5 times their critical
    strains, the bonds keep acting, in LAMMPS as here: forces at the
    stretched state and a 300-step trajectory agree to round-off, and no
    bond breaks."""
    atoms, _ = breaking_cluster()
    calc = ase_bpm.BPMSpring(**{name: atoms.calc.parameters[name]
                                for name in ("bond_coeffs", "pair_coeffs")},
                             smooth=False, normalize=normalize, break_bonds=False)
    atoms.calc = calc
    lmp = Oracle(atoms, calc, timestep=0.1)
    try:
        assert "break no" in " ".join(lammps_commands(atoms, calc, "scene.data"))
        atoms.get_forces()  # the reference lengths
        lmp.run(0)
        before = intact_pairs(atoms)
        centre = atoms.positions.mean(axis=0)
        atoms.positions = centre + 1.15 * (atoms.positions - centre)  # strain 0.15
        forces = atoms.get_forces()
        lmp.set_state(atoms.positions, atoms.get_velocities())
        lmp.run(0)
        assert np.abs(forces - lmp.forces()).max() <= 1e-12 * np.abs(forces).max()
        assert intact_pairs(atoms) == before == lmp.intact_bonds()

        VelocityVerlet(atoms, timestep=0.1).run(300)
        lmp.run(300)
        assert intact_pairs(atoms) == before == lmp.intact_bonds()
        assert lmp.position_error(atoms.positions).max() <= 1e-9
        assert np.abs(lmp.velocities() - atoms.get_velocities()).max() <= 1e-9
        assert "broken_bonds" not in atoms.info or len(atoms.info["broken_bonds"]) == 0
    finally:
        lmp.close()


def test_periodic_bonds_across_the_boundary(Oracle):
    """Periodic block, atoms outside the cell, bonds across the boundary:
    forces, stress (virial) and a 300-step trajectory with breaking."""
    atoms, calc = periodic_breaking_cluster()
    assert_periodic_run_is_lammps(Oracle, atoms, calc)


def periodic_breaking_cluster():
    """:func:`breaking_cluster` periodic, some atoms outside the cell, faster."""
    atoms, calc = breaking_cluster(pbc=True, seed=4)
    atoms.positions += [0.3, -0.2, 0.5]  # some atoms now lie outside the cell
    atoms.set_velocities(1.5 * atoms.get_velocities())
    return atoms, calc


def assert_periodic_run_is_lammps(Oracle, atoms, calc):
    """Bonds across the boundary: forces, stress (virial) and a 300-step
    trajectory with breaking, against LAMMPS."""
    i, j, _ = ase_bpm.get_bonds(atoms)
    crossing = np.linalg.norm(atoms.positions[j] - atoms.positions[i], axis=1) > 2
    assert crossing.sum() > 50
    lmp = Oracle(atoms, calc, timestep=0.1, virial=True)
    try:
        forces = atoms.get_forces()
        lmp.run(0)
        assert np.abs(forces - lmp.forces()).max() <= 1e-9 * np.abs(forces).max()
        pxx, pyy, pzz, pxy, pxz, pyz = lmp.virial_pressure()
        expected = -np.array([pxx, pyy, pzz, pyz, pxz, pxy])
        assert np.abs(atoms.get_stress() - expected).max() <= 1e-9 * np.abs(expected).max()

        before = intact_pairs(atoms)
        VelocityVerlet(atoms, timestep=0.1).run(300)
        lmp.run(300)
        assert len(before - intact_pairs(atoms)) > 20
        assert intact_pairs(atoms) == lmp.intact_bonds()
        assert lmp.position_error(atoms.positions).max() <= 1e-9
    finally:
        lmp.close()


def test_exported_deck_runs_in_lammps(tmp_path):
    """``write_lammps`` writes a deck that LAMMPS runs as it is, to the same
    trajectory and the same record of broken bonds (store/local)."""
    try:
        load_lammps()
    except Exception as exc:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"LAMMPS oracle not available: {exc}")
    atoms, calc = breaking_cluster(seed=5)
    _, deck = write_lammps(str(tmp_path / "scene"), atoms, calc, timestep=0.1, steps=200,
                           thermo=50)
    lmp = run_deck(deck)
    VelocityVerlet(atoms, timestep=0.1).run(200)
    x = gather(lmp, "x")
    lmp.close()
    assert np.abs(x - atoms.positions).max() <= 1e-9

    theirs = read_dump_local(tmp_path / "scene.broken")
    ours = atoms.info["broken_bonds"]
    assert len(ours) > 50 and len(theirs) == len(ours)
    theirs[:, :2] = np.sort(theirs[:, :2] - 1, axis=1)  # 0-based, i < j
    key = lambda rows: np.lexsort((rows[:, 1], rows[:, 0], rows[:, 2]))  # noqa: E731
    theirs, ours = theirs[key(theirs)], ours[key(ours)]
    assert np.array_equal(theirs[:, :3], ours[:, :3])  # atoms and step
    assert np.abs(theirs[:, 3:] - ours[:, 3:]).max() <= 1e-9  # centres now and at reference
