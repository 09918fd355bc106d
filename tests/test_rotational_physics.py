"""bpm/rotational's physics beyond the oracle: balance laws, objectivity,
analyses, pure evaluations and what the ledger books."""

import warnings

import numpy as np
import pytest

import ase_bpm
from ase_bpm import SphereVelocityVerlet
from ase_bpm.core.quaternions import multiply
from test_rotational_oracle import SOFT, UNDAMPED, rotational_cluster, turned_state

#: (scenes turned a little before their bonds take the reference state)
pytestmark = pytest.mark.filterwarnings("ignore::ase_bpm.RotatedReferenceWarning")


def turned_scene(**options):
    """The oracle's cluster after its reference state, moved and turned
    (every bond bent, twisted and sheared, none past breaking)."""
    atoms, calc, rng = rotational_cluster(pair=False, **options)
    atoms.get_forces()
    positions, quat, velocities, omega = turned_state(atoms, rng)
    atoms.positions = positions
    atoms.arrays["quat"] = quat
    atoms.arrays["omega"] = omega
    atoms.set_velocities(velocities)
    return atoms, calc


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_forces_and_torques_balance(kernels):
    """Newton's third law and the balance of angular momentum: the bonds'
    forces sum to zero, and so do their moments about the origin plus the
    torques."""
    atoms, calc = turned_scene(kernels=kernels)
    forces, torques = atoms.get_forces(), calc.results["torques"]
    scale = np.abs(forces).max() * np.abs(atoms.positions).max()
    assert np.abs(torques).max() > 0.1 * np.abs(forces).max()
    assert np.abs(forces.sum(axis=0)).max() <= 1e-13 * np.abs(forces).max()
    moments = np.cross(atoms.positions, forces).sum(axis=0) + torques.sum(axis=0)
    assert np.abs(moments).max() <= 1e-13 * scale


def rotation(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    matrix = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    quat = np.r_[np.cos(angle / 2), np.sin(angle / 2) * axis]
    return matrix, quat


def test_a_rigid_turn_after_the_reference_state_turns_forces_and_torques():
    """Objectivity: the whole body turned rigidly (positions, orientations,
    velocities and spins) after its reference state gives the forces and
    torques turned, within round-off (LAMMPS keeps the reference direction
    in the laboratory frame and measures the bond in the particles' frame)."""
    atoms, calc = turned_scene()
    forces, torques = atoms.get_forces(), calc.results["torques"].copy()
    matrix, quat = rotation([0.3, -1.0, 0.4], 0.7)
    centre = atoms.positions.mean(axis=0)
    atoms.positions = (atoms.positions - centre) @ matrix.T + centre
    atoms.arrays["quat"] = multiply(np.tile(quat, (len(atoms), 1)), atoms.arrays["quat"])
    atoms.set_velocities(atoms.get_velocities() @ matrix.T)
    atoms.arrays["omega"] = atoms.arrays["omega"] @ matrix.T
    with ase_bpm.pure(atoms):  # (a look at the turned state, not a step)
        turned = atoms.get_forces()
        turned_torques = calc.results["torques"]
    # (1e-11: the turned positions and orientations carry round-off, which the
    # law's arccos near rest enlarges)
    assert np.abs(turned - forces @ matrix.T).max() <= 1e-11 * np.abs(forces).max()
    assert np.abs(turned_torques - torques @ matrix.T).max() <= 1e-11 * np.abs(torques).max()


def test_the_analysis_gives_each_bond_its_force_torques_and_reference():
    """calc.analyse's bonds: forces and torques per bond add up to the
    evaluation's; the reference length and direction are the bond's at the
    reference state (unit vectors along it)."""
    atoms, calc = turned_scene()
    forces, torques = atoms.get_forces(), calc.results["torques"]
    bonds = calc.analyse(atoms).bonds
    n = len(atoms)
    summed_f = np.zeros((n, 3))
    np.add.at(summed_f, bonds.i_b, bonds.f_bc)
    np.add.at(summed_f, bonds.j_b, -bonds.f_bc)
    summed_t = np.zeros((n, 3))
    np.add.at(summed_t, bonds.i_b, bonds.extra["torque_i_bc"])
    np.add.at(summed_t, bonds.j_b, bonds.extra["torque_j_bc"])
    assert np.abs(summed_f - forces).max() <= 1e-12 * np.abs(forces).max()
    assert np.abs(summed_t - torques).max() <= 1e-12 * np.abs(torques).max()
    assert np.allclose(np.linalg.norm(bonds.extra["r0_dir_bc"], axis=1), 1.0, rtol=0, atol=1e-15)
    x_ref = atoms.arrays["bpm_x_ref"]  # (where the reference state was taken)
    r_ref_bc = x_ref[bonds.j_b] - x_ref[bonds.i_b]
    length_ref_b = np.linalg.norm(r_ref_bc, axis=1)
    assert np.allclose(bonds.r0_b, length_ref_b, rtol=1e-14, atol=0)
    assert np.allclose(bonds.extra["r0_dir_bc"], r_ref_bc / length_ref_b[:, None], rtol=0,
                       atol=1e-15)
    assert np.abs(bonds.strain_b).max() > 1e-3  # (the bonds moved since)


def test_a_pure_evaluation_breaks_nothing_and_the_step_after_it_does():
    """Inside ase_bpm.pure a bond past its criterion acts broken and stays;
    the orientations, spins and bonds are left as they were."""
    atoms, calc, rng = rotational_cluster(pair=False)
    atoms.get_forces()
    before = len(ase_bpm.get_bonds(atoms)[0])
    positions, quat, velocities, omega = turned_state(atoms, rng, shift=0.02, angle=0.1)
    atoms.positions, atoms.arrays["quat"] = positions, quat
    quat_before = atoms.arrays["quat"].copy()
    with ase_bpm.pure(atoms):
        atoms.get_forces()
    assert len(ase_bpm.get_bonds(atoms)[0]) == before
    assert np.array_equal(atoms.arrays["quat"], quat_before)
    calc.step(atoms)  # the step at these positions: now they break
    assert len(ase_bpm.get_bonds(atoms)[0]) < before


@pytest.mark.parametrize("coeffs,damped", [((SOFT, SOFT), True),
                                           ((UNDAMPED, UNDAMPED), False)])
def test_the_ledger_books_the_damping_and_says_it_cannot_balance(coeffs, damped):
    """The damping's work is booked (none without damping); the elastic work
    of rotational bonds has no energy to book it against, which the
    calculator says (ledger_balances False; BPMSpring's springs: True)."""
    atoms, calc, _ = rotational_cluster(coeffs=coeffs, pair=False, break_bonds=False,
                                        smooth=False)
    assert not calc.ledger_balances
    assert ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.1)}).ledger_balances
    SphereVelocityVerlet(atoms, timestep=0.1).run(50)
    assert atoms.get_potential_energy() == 0.0  # (as LAMMPS reports it)
    dissipated = calc.results["dissipated_energy"]
    assert (dissipated > 0.0) if damped else (dissipated == 0.0)


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_reordering_the_atoms_changes_nothing(kernels):
    """Which end of a bond is LAMMPS's particle 1 (the law is not symmetric
    in its two ends) is settled when the bond takes its reference state and
    kept with it: a run goes on the same after the atoms are put in another
    order (ase.build.sort, atoms[order]), to round-off."""
    # (undamped: a new calculator on the atoms as they were left takes the
    # record's forces, and one on reordered atoms evaluates them afresh at the
    # full-step velocities; without damping the two are the same forces)
    atoms, calc, _ = rotational_cluster(coeffs=(UNDAMPED, UNDAMPED), pair=False,
                                        kernels=kernels)
    SphereVelocityVerlet(atoms, timestep=0.1).run(20)
    order = np.random.default_rng(9).permutation(len(atoms))
    shuffled = atoms[order]
    shuffled.calc = ase_bpm.BPMSpring(**{k: v for k, v in calc.parameters.items()})
    atoms.calc = ase_bpm.BPMSpring(**{k: v for k, v in calc.parameters.items()})
    for scene in (atoms, shuffled):
        SphereVelocityVerlet(scene, timestep=0.1).run(30)
    scale = np.abs(atoms.positions).max()
    assert np.abs(shuffled.positions - atoms.positions[order]).max() <= 1e-12 * scale
    assert np.abs(shuffled.arrays["quat"] - atoms.arrays["quat"][order]).max() <= 1e-12


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_bonds_taking_their_reference_between_turned_particles_are_named(kernels):
    """Orientations away from the identity when the bonds take their
    reference state strain them from the start (as in the reference build):
    RotatedReferenceWarning names how many, the most turned atom and what to
    do; orientations at the identity (or none) give no warning."""
    from ase_bpm.laws.rotational import RotatedReferenceWarning

    atoms, calc, _ = rotational_cluster(pair=False, kernels=kernels, angle=0.3)
    with pytest.warns(RotatedReferenceWarning, match=r"bonds take their reference state "
                      r"between particles turned away from the identity .* Set "
                      r'atoms.arrays\["quat"\] to the identity'):
        atoms.get_forces()
    calm, calc, _ = rotational_cluster(pair=False, kernels=kernels)
    calm.arrays["quat"] = np.tile([1.0, 0.0, 0.0, 0.0], (len(calm), 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RotatedReferenceWarning)
        calm.get_forces()
        SphereVelocityVerlet(calm, timestep=0.1).run(5)  # (turned now, references kept)
