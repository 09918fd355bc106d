"""BPMPeri physics: continuum elasticity, energy, conservation, state."""

import warnings

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from scenes import BULK, DENSITY, HORIZON, NODE_VOLUME, SPACING, peri_model, sc_block

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


@pytest.mark.parametrize("name", ["lps", "ves", "eps"])
def test_a_uniformly_dilated_periodic_block_stays_in_equilibrium(name):
    """Every node of a periodic lattice is alike, so a uniform dilatation of
    block and cell leaves no force on any node.  Following legacy, the nodes
    within a horizon of a face carry the reference build's weighted volume
    (summed across the cell without the minimum image) and are pushed."""
    forces = {}
    for follows in ("bpm/peri", "legacy"):
        atoms = sc_block(10, pbc=True)
        atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model(name)}, follows=follows,
                                     timestep=DT)
        atoms.get_forces()
        atoms.set_cell(atoms.cell * (1 + 1e-4), scale_atoms=True)
        forces[follows] = atoms.get_forces()
        if follows == "bpm/peri":  # one dilatation everywhere, 3 times the stretch
            assert np.allclose(atoms.arrays["dilatation"], 3e-4, rtol=1e-9, atol=0)
    scale = np.abs(forces["legacy"]).max()
    assert scale > 0
    assert np.abs(forces["bpm/peri"]).max() <= 1e-9 * scale


def lattice_frequency(model, k):
    """omega of the longitudinal wave ``u_x = sin(k x)`` on an unbounded simple
    cubic lattice: the linearised force on a node, summed over its bonds
    (direction ``n``, length ``r0``, partial volume ``s``, 1/2 at the horizon):

    pmb: ``rho omega^2 = c V sum s n_x^2 (1 - cos k xi_x) / r0``;
    lps: ``rho omega^2 = 3 (3K - 5G) V^2 S1^2 / m^2 + 30 G V S2 / m`` with
    ``S1 = sum s n_x sin k xi_x``, ``S2`` pmb's sum and ``m = V sum s r0``.
    As ``k -> 0`` both give ``(K + 4G/3) k^2`` with the sums replaced by
    integrals over the horizon (Silling 2000, 2007)."""
    cells = int(HORIZON / SPACING) + 1
    reach = np.arange(-cells, cells + 1)
    xi_bc = np.array(np.meshgrid(reach, reach, reach, indexing="ij")).reshape(3, -1).T
    r0_b = np.linalg.norm(xi_bc, axis=1) * SPACING
    inside = (r0_b > 0) & (r0_b <= HORIZON)
    xi_b, r0_b = xi_bc[inside, 0] * SPACING, r0_b[inside]
    s_b = np.minimum(1.0, (HORIZON + SPACING / 2 - r0_b) / SPACING)
    s2 = np.sum(s_b * (xi_b / r0_b) ** 2 * (1 - np.cos(k * xi_b)) / r0_b)
    if model[0] == "pmb":
        return np.sqrt(model[1] * NODE_VOLUME * s2 / DENSITY)
    _, bulk, shear = model[:3]
    m = NODE_VOLUME * np.sum(s_b * r0_b)
    s1 = np.sum(s_b * xi_b / r0_b * np.sin(k * xi_b))
    return np.sqrt((3 * (3 * bulk - 5 * shear) * (NODE_VOLUME * s1 / m) ** 2
                    + 30 * shear * NODE_VOLUME * s2 / m) / DENSITY)


# s00 = 0.01: a bond's reach (1 + s00) r0 stays within half the narrow periodic cell
@pytest.mark.parametrize("model, quadrature", [
    (peri_model("pmb", s00=0.01, alpha=0.0), 0.09),
    (("lps", BULK, BULK, HORIZON, 0.01, 0.0), 0.04),  # G = K: the dilatation term acts
])
def test_a_standing_wave_follows_the_lattice_dispersion_relation(model, quadrature):
    """``u_x = a sin(k x)`` in a block periodic along x is a normal mode, so under
    velocity Verlet from rest its amplitude is exactly ``a cos(j theta)`` at step
    j, ``cos theta = 1 - (omega dt)^2 / 2``, with omega from the lattice sums.
    Its speed ``omega / k`` is the P-wave speed ``sqrt((K + 4G/3) / rho)`` up to
    the quadrature of a 3-spacing horizon and the dispersion at
    ``lambda = 8 horizons`` (pmb 8 %, lps 3 % slow: benchmarks/tradeoff_horizon.py)."""
    atoms = sc_block(24, 7, 7, pbc=True)  # 7 spacings across: one image per bonded pair
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: model}, break_bonds=False)
    atoms.get_forces()  # reference lengths at rest
    k = 2 * np.pi / atoms.cell[0, 0]
    shape_n = np.sin(k * atoms.positions[:, 0])
    x0_n = atoms.positions[:, 0].copy()
    amplitude = 1e-5 / k  # strain 1e-5
    atoms.positions[:, 0] += amplitude * shape_n
    omega = lattice_frequency(model, k)
    theta = np.arccos(1 - (omega * DT) ** 2 / 2)
    dyn = VelocityVerlet(atoms, timestep=DT)
    mode = []
    dyn.attach(lambda: mode.append(shape_n @ (atoms.positions[:, 0] - x0_n)
                                   / (shape_n @ shape_n) / amplitude))
    dyn.run(int(2 * np.pi / theta) + 1)  # one period
    # exact but for round-off and terms of order strain^2 (1e-10); velocity Verlet's
    # phase error (theta against omega dt) alone would be 6e-3 here
    assert np.abs(np.array(mode) - np.cos(theta * np.arange(len(mode)))).max() < 1e-8
    shear = 0.6 * BULK if model[0] == "pmb" else model[2]  # pmb: Poisson ratio 1/4
    p_wave = np.sqrt((BULK + 4 * shear / 3) / DENSITY)
    assert omega / k == pytest.approx(p_wave, rel=quadrature)
    assert omega / k < p_wave


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
    with pytest.warns(ase_bpm.OptimiserStepWarning):  # steps by hand, the momenta kept
        for k in range(200):
            atoms.positions[0, 0] += 1e-16 * (-1) ** k
            forces.append(atoms.get_forces())
    ves = ase_bpm.core.bonds.state_slots(atoms.arrays["bond_ves"], atoms.arrays["bond_type"].shape[1])
    ed, edb = ves[..., 0], ves[..., 1]
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


@pytest.mark.parametrize("model", ["pmb", "lps"])
def test_energy_released_by_breaking_is_that_of_the_broken_bonds(model):
    """The step that breaks bonds books their elastic energy as released:
    the energy left plus the energy released is the energy of the same
    configuration with every bond intact (a calculator that does not break
    them, evaluated on a copy)."""
    atoms = sc_block(4)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model(model, s00=0.0005)}, guard=False)
    atoms.get_forces()  # reference lengths
    atoms.set_velocities(2e3 * (atoms.positions - atoms.positions.mean(axis=0)))
    dyn = ase_bpm.VelocityVerlet(atoms, timestep=1e-7)
    for _ in range(20):
        intact = atoms.copy()
        released_before = atoms.calc.results.get("broken_bond_energy", 0.0)
        dyn.run(1)
        released = atoms.calc.results["broken_bond_energy"] - released_before
        if released:
            break
    assert released > 0
    whole = intact.copy()
    whole.positions = atoms.positions
    whole.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model(model, s00=0.0005)},
                                 break_bonds=False, guard=False)
    assert atoms.get_potential_energy() + released == pytest.approx(
        whole.get_potential_energy(), rel=1e-12)


def test_following_another_style_later_warns_that_the_weighted_volumes_stay():
    """In a periodic cell the legacy styles take the weighted volumes
    otherwise; they are taken once, at the reference state, so a change of
    ``follows`` between the two afterwards keeps them, and says so."""
    atoms = sc_block(10, pbc=True)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("lps")}, timestep=DT)
    atoms.get_forces()
    taken = atoms.arrays["peri_wvolume"].copy()
    atoms.calc.set(follows="legacy")
    with pytest.warns(UserWarning, match=r"BPMPeri follows 'legacy' on periodic atoms whose "
                                         r"weighted volumes .* were taken at the reference "
                                         r"state following 'bpm/peri'"):
        atoms.get_forces()
    assert np.array_equal(atoms.arrays["peri_wvolume"], taken)
    open_block = sc_block(6)  # an open block: no difference, no warning
    open_block.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("lps")}, timestep=DT)
    open_block.get_forces()
    open_block.calc.set(follows="legacy")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        open_block.get_forces()


def test_a_change_of_follows_applies_at_the_same_positions():
    """``calc.set(follows=...)`` changes the physics (ves: one deviatoric
    extension per bond, or one per bond end): the next request evaluates
    anew, at the same positions too, as after a refresh."""
    atoms = sc_block(6)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("ves")}, timestep=DT)
    atoms.get_forces()
    rng = np.random.default_rng(5)
    atoms.positions = atoms.positions + rng.uniform(-0.02, 0.02, atoms.positions.shape) * SPACING
    before = atoms.get_forces()
    atoms.calc.set(follows="legacy")
    after = atoms.get_forces()
    assert not np.allclose(after, before, rtol=1e-6, atol=0)
    atoms.calc.refresh()
    assert np.array_equal(atoms.get_forces(), after)
