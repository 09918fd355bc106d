"""BPMPeri physics: continuum elasticity, energy, conservation, state."""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from scenes import BULK, HORIZON, SPACING, peri_model, sc_block

DT = 1e-7


def strained_stress(model, strain, n=12):
    """Stress of a periodic block after a homogeneous strain from its reference."""
    atoms = sc_block(n, pbc=True)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: model})
    atoms.get_forces()
    atoms.set_cell(atoms.cell @ (np.eye(3) + strain), scale_atoms=True)
    return atoms.get_stress(voigt=False)


def test_pmb_block_is_a_continuum_with_bulk_modulus_k_and_poisson_ratio_quarter():
    """c = 18 K / (pi horizon^4): bulk modulus K and Poisson ratio 1/4, up to the
    discretisation of the horizon sum (3 lattice spacings: about 10 %)."""
    eps = 1e-5
    model = peri_model("pmb")
    stress = strained_stress(model, eps * np.eye(3))
    assert np.trace(stress) / 3 == pytest.approx(3 * BULK * eps, rel=0.12)
    assert np.allclose(stress - np.diag(np.diag(stress)), 0, atol=1e-9 * BULK * eps)
    uniaxial = strained_stress(model, np.diag([eps, 0, 0]))
    shear_modulus = 3 * BULK / 5  # Poisson ratio 1/4
    assert uniaxial[0, 0] == pytest.approx(3 * shear_modulus * eps, rel=0.15)
    # lambda = mu for nu = 1/4: transverse over axial stress is 1/3
    assert uniaxial[1, 1] / uniaxial[0, 0] == pytest.approx(1 / 3, abs=0.04)


def test_lps_reproduces_bulk_and_shear_moduli():
    eps, shear = 1e-5, 0.3 * BULK
    model = ("lps", BULK, shear, HORIZON, 0.5, 0.25)
    stress = strained_stress(model, eps * np.eye(3))
    assert np.trace(stress) / 3 == pytest.approx(3 * BULK * eps, rel=1e-3)
    uniaxial = strained_stress(model, np.diag([eps, 0, 0]))
    assert uniaxial[0, 0] == pytest.approx((BULK + 4 * shear / 3) * eps, rel=0.05)
    assert uniaxial[1, 1] == pytest.approx((BULK - 2 * shear / 3) * eps, rel=0.05)
    gamma = np.zeros((3, 3))
    gamma[0, 1] = gamma[1, 0] = eps / 2
    assert strained_stress(model, gamma)[0, 1] == pytest.approx(shear * eps, rel=0.08)


def deformed_block(name, seed=3, amplitude=0.02, **kwargs):
    atoms = sc_block(6)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model(name)}, timestep=DT, **kwargs)
    atoms.get_forces()
    rng = np.random.default_rng(seed)
    atoms.positions += rng.uniform(-amplitude, amplitude, atoms.positions.shape) * SPACING
    return atoms


@pytest.mark.parametrize("name", ["pmb", "lps"])
def test_forces_are_minus_energy_gradient(name):
    atoms = deformed_block(name)
    forces = atoms.get_forces()
    h = 1e-6 * SPACING
    scale = np.abs(forces).max()
    for n in range(0, len(atoms), 23):
        for c in range(3):
            energies = []
            for sign in (1, -1):
                probe = atoms.copy()
                probe.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model(name)})
                probe.positions[n, c] += sign * h
                probe.calc.refresh()
                energies.append(probe.get_potential_energy())
            assert forces[n, c] == pytest.approx(-(energies[0] - energies[1]) / (2 * h),
                                                 abs=1e-6 * scale)


@pytest.mark.parametrize("name", ["pmb", "lps"])
def test_newtons_third_law_with_unequal_volumes(name):
    atoms = sc_block(5)
    rng = np.random.default_rng(4)
    atoms.arrays["vfrac"] *= rng.uniform(0.5, 1.5, len(atoms))
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model(name)}, lattice_spacing=SPACING)
    atoms.get_forces()
    atoms.positions += rng.uniform(-0.03, 0.03, atoms.positions.shape) * SPACING
    forces = atoms.get_forces()
    assert np.abs(forces.sum(axis=0)).max() < 1e-12 * np.abs(forces).max()


def pmb_energy_drift(dt, time=3e-5):
    atoms = deformed_block("pmb")
    atoms.set_velocities(np.random.default_rng(5).normal(0, 0.5, atoms.positions.shape))
    e0 = atoms.get_total_energy()
    drift = 0.0
    for _ in VelocityVerlet(atoms, timestep=dt).irun(int(round(time / dt))):
        drift = max(drift, abs(atoms.get_total_energy() - e0))
    return drift, e0


def test_energy_conserved_in_an_elastic_pmb_run():
    """The LAMMPS example's 1e-7 s is near this material's stability limit
    (omega dt about 0.5); the energy error falls as dt^2."""
    drift_1, e0 = pmb_energy_drift(DT)
    drift_2, _ = pmb_energy_drift(DT / 2)
    assert drift_1 < 0.1 * e0
    assert 3.0 < drift_1 / drift_2 < 5.0


def test_restart_continues_viscoelastic_history_bit_identically(tmp_path):
    straight = deformed_block("ves")
    straight.set_velocities(np.random.default_rng(6).normal(0, 1.0, straight.positions.shape))
    interrupted = straight.copy()
    coeffs = straight.calc.parameters
    straight.calc = ase_bpm.BPMPeri(**coeffs)
    interrupted.calc = ase_bpm.BPMPeri(**coeffs)
    VelocityVerlet(straight, DT).run(60)
    VelocityVerlet(interrupted, DT).run(30)
    ase_bpm.write_restart(tmp_path / "ves.bpm", interrupted)
    resumed = ase_bpm.read_restart(tmp_path / "ves.bpm")
    resumed.calc = ase_bpm.BPMPeri(**coeffs)
    VelocityVerlet(resumed, DT).run(30)
    assert np.array_equal(resumed.positions, straight.positions)
    assert np.array_equal(resumed.arrays["bond_ves"], straight.arrays["bond_ves"],
                          equal_nan=True)


def test_ves_history_advances_once_per_step_and_relaxes():
    """Held at a fixed deformation, the viscous back extension relaxes towards
    the deviatoric extension with time constant tau; repeated requests at one
    configuration do not advance it."""
    atoms = deformed_block("ves", amplitude=0.05)
    atoms.set_velocities(np.zeros((len(atoms), 3)))
    forces = [atoms.get_forces()]
    history = atoms.arrays["bond_ves"].copy()
    atoms.calc.refresh()
    assert np.array_equal(atoms.get_forces(), forces[0])
    assert np.array_equal(atoms.arrays["bond_ves"], history, equal_nan=True)
    # nudge positions by a hair each "step" so each evaluation is a new one
    for k in range(200):
        atoms.positions[0, 0] += 1e-16 * (-1) ** k
        forces.append(atoms.get_forces())
    ed, edb = atoms.arrays["bond_ves"][..., 0], atoms.arrays["bond_ves"][..., 1]
    done = ~np.isnan(ed) & (np.abs(ed) > 1e-12 * SPACING)
    # after 200 steps of dt = tau/10 the back extension has caught up
    assert np.abs(edb[done] - ed[done]).max() < 1e-6 * np.abs(ed[done]).max()
    assert np.abs(forces[-1] - forces[1]).max() > 1e-3 * np.abs(forces[1]).max()


def test_a_timestep_different_from_the_integrators_is_caught():
    atoms = deformed_block("ves")
    atoms.set_velocities(np.random.default_rng(8).normal(0, 1.0, atoms.positions.shape))
    with pytest.raises(ValueError, match=r"timestep mismatch: the calculator was given "
                                         r"timestep=1e-07, but the atoms moved as a "
                                         r"velocity Verlet step of 2e-07"):
        VelocityVerlet(atoms, timestep=2 * DT).run(2)


def test_damage_and_dilatation_outputs():
    atoms = sc_block(8, 4, 4)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("lps", s00=0.001)}, timestep=DT)
    atoms.get_forces()
    assert np.all(atoms.arrays["damage"] == 0) and np.all(atoms.arrays["nbonds"] > 0)
    right = atoms.positions[:, 0] > 3.5 * SPACING
    atoms.positions[right, 0] += 0.01 * SPACING  # every bond across x = 3.5 stretches
    atoms.get_forces()
    # the stretched bonds dilate the nodes beside the crack, and break
    assert atoms.arrays["dilatation"][right].max() > 1e-3
    damage = atoms.arrays["damage"]
    assert damage[~right].max() > 0.2 and damage[right].max() > 0.2
    far = np.abs(atoms.positions[:, 0] - 3.5 * SPACING) > 3.2 * SPACING
    assert np.all(damage[far] == 0)  # beyond the horizon from the crack
    # damage is the share of the initial interaction volume lost (uniform volumes)
    broken = atoms.info["broken_bonds"][:, :2].astype(int)
    lost = np.bincount(broken.ravel(), minlength=len(atoms))
    assert np.allclose(damage, lost / (lost + atoms.arrays["nbonds"]))
    # once the crack is open, the two halves move apart freely
    atoms.positions[right, 0] += 0.01 * SPACING
    assert np.abs(atoms.get_forces()).max() < 1e-9 * np.abs(atoms.positions).max()
