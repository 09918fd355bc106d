"""Pure evaluations (``ase_bpm.pure``): forces and energy as functions of the
positions and velocities only, for ASE optimisers, vibrations and checks."""

import numpy as np
import pytest
from ase.lattice.cubic import FaceCenteredCubic
from ase.md.verlet import VelocityVerlet
from ase.optimize import BFGS

import ase_bpm
from ase_bpm import SphereVelocityVerlet
from scenes import FCC, HORIZON, SPACING, deform_below_breaking, peri_model, sc_block, \
    sphere_pile
from state import assert_unchanged, snapshot


def jittered_block(eps_c=0.04, gamma=0.0):
    """4x4x2 bonded FCC block, reference taken, then jittered below eps_c."""
    atoms = FaceCenteredCubic("Cu", size=(4, 4, 2), latticeconstant=FCC, pbc=False)
    atoms.set_masses(np.ones(len(atoms)))
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, eps_c, gamma)})
    atoms.get_forces()  # reference lengths
    rng = np.random.default_rng(2)
    atoms.positions = deform_below_breaking(atoms, rng, fraction=0.9)
    return atoms


def test_bfgs_relaxation_counts_no_step_and_keeps_all_history():
    atoms = jittered_block()
    atoms.get_forces()  # the jitter as a step: the record of where the run stands
    before = snapshot(atoms)
    with ase_bpm.pure(atoms):
        opt = BFGS(atoms, logfile=None)
        assert opt.run(fmax=1e-4, steps=300)
        assert opt.nsteps > 10  # a real relaxation happened
        relaxed = atoms.positions.copy()
        atoms.positions = before[0]["positions"]  # compare all but the positions:
        assert_unchanged(atoms, before)  # nothing written while relaxing
        atoms.positions = relaxed
    assert atoms.info["bpm_step"] == before[1]["bpm_step"]
    for name in ("bond_type", "bond_r0", "bond_partner", "bpm_id", "damage"):
        assert np.array_equal(atoms.arrays[name], before[0][name], equal_nan=True)
    # after leaving, the relaxed state is not a step either
    atoms.get_forces()
    assert atoms.info["bpm_step"] == before[1]["bpm_step"]
    assert atoms.info["bpm_dissipated_energy"] == before[1].get("bpm_dissipated_energy", 0.0)


def test_trial_position_and_back_changes_nothing(tmp_path):
    """A trial move that would break bonds in a step, evaluated purely, then
    undone: the atoms are bit-identical and the run continues bit for bit."""
    straight = jittered_block(gamma=0.5)
    straight.set_velocities(np.random.default_rng(3).normal(0, 0.02, (len(straight), 3)))
    probed = straight.copy()
    straight.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.04, 0.5)})
    probed.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.04, 0.5)})
    VelocityVerlet(straight, 0.1).run(20)
    VelocityVerlet(probed, 0.1).run(10)
    before = snapshot(probed)
    energy = probed.get_potential_energy()
    with ase_bpm.pure(probed):
        probed.positions[5] += [0.3, 0.0, 0.0]  # strains its bonds past eps_c
        trial = probed.get_potential_energy()
        assert np.isfinite(probed.get_forces()).all() and trial != energy
        probed.positions[5] -= [0.3, 0.0, 0.0]
        assert probed.get_potential_energy() == energy
    assert_unchanged(probed, before)
    ase_bpm.write_restart(tmp_path / "probed.bpm", probed)
    resumed = ase_bpm.read_restart(tmp_path / "probed.bpm")
    resumed.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.04, 0.5)})
    VelocityVerlet(resumed, 0.1).run(10)
    assert np.array_equal(resumed.positions, straight.positions)
    assert np.array_equal(resumed.get_momenta(), straight.get_momenta())
    assert resumed.info["bpm_step"] == straight.info["bpm_step"]


def test_over_strained_bond_acts_broken_and_stays():
    atoms = jittered_block()
    i, j, _ = ase_bpm.get_bonds(atoms)
    with ase_bpm.pure(atoms):
        atoms.positions[i[0]] -= 0.5 * (atoms.positions[j[0]] - atoms.positions[i[0]])
        f = atoms.get_forces()
    assert np.isfinite(f).all()
    assert len(ase_bpm.get_bonds(atoms)[0]) == len(i)  # nothing broke for good
    assert "broken_bonds" not in atoms.info


def central_differences(atoms, which, h):
    """-dE/dx at the atoms ``which``, all three directions."""
    out = np.zeros((len(which), 3))
    for k, a in enumerate(which):
        for c in range(3):
            x0 = atoms.positions[a, c]
            atoms.positions[a, c] = x0 + h
            e_plus = atoms.get_potential_energy()
            atoms.positions[a, c] = x0 - h
            e_minus = atoms.get_potential_energy()
            atoms.positions[a, c] = x0
            out[k, c] = -(e_plus - e_minus) / (2 * h)
    return out


def spring_scene():
    atoms = jittered_block(eps_c=0.2)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.2, 0.0)},
                                   pair_coeffs={(1, 1): (2.0, 1.5, 0.0)})
    return atoms, 1e-6


def peri_scene(model):
    def build():
        atoms = sc_block(4)
        atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model(model)},
                                     pair_coeffs={(1, 1): (1e22, HORIZON)}, timestep=1e-8)
        atoms.get_forces()
        atoms.positions += np.random.default_rng(4).uniform(-0.02, 0.02, atoms.positions.shape) \
            * SPACING
        return atoms, 1e-6 * SPACING
    return build


def granular_scene():
    atoms = sphere_pile(n=3, seed=11)
    atoms.set_velocities(np.zeros((len(atoms), 3)))
    atoms.arrays["omega"] = np.zeros((len(atoms), 3))
    atoms.calc = ase_bpm.Granular("hertz/history", kn=1000.0, gamma_n=0.0, xmu=0.0,
                                  timestep=1e-3)
    return atoms, 1e-7


@pytest.mark.parametrize("build", [spring_scene, peri_scene("pmb"), peri_scene("lps"),
                                   granular_scene],
                         ids=["spring", "pmb", "lps", "hertz"])
def test_forces_are_minus_the_energy_gradient(build):
    """The conservative models (ves and eps are not: each bond end uses its
    own dilatation, as in the legacy styles)."""
    atoms, h = build()
    with ase_bpm.pure(atoms):
        f = atoms.get_forces()
        which = np.argsort(-np.linalg.norm(f, axis=1))[:4]
        numeric = central_differences(atoms, which, h)
    scale = np.abs(f).max()
    assert scale > 0
    assert np.allclose(numeric, f[which], rtol=0, atol=1e-6 * scale)


def test_history_is_read_not_advanced():
    """Viscoelastic bond history and granular shear stay as they are."""
    atoms, _ = peri_scene("ves")()
    VelocityVerlet(atoms, 1e-8).run(3)
    ves = atoms.arrays["bond_ves"].copy()
    pile = sphere_pile(n=3, seed=11)
    pile.calc = ase_bpm.Granular("hooke/history", kn=1000.0, gamma_n=10.0, xmu=0.3)
    SphereVelocityVerlet(pile, 1e-3).run(5)
    shear = pile.arrays["gran_shear"].copy()
    with ase_bpm.pure(atoms, pile):
        for scene in (atoms, pile):
            scene.positions *= 1.0001
            scene.get_forces()
    assert np.array_equal(atoms.arrays["bond_ves"], ves, equal_nan=True)
    assert np.array_equal(pile.arrays["gran_shear"], shear)
    with pytest.raises(RuntimeError, match="inside pure evaluations"):
        with ase_bpm.pure(atoms):
            atoms.calc.step(atoms)


def test_quasi_static_loading_commits_breaking_after_relaxing():
    """Relax inside pure, then commit the breaking at the relaxed state."""
    atoms = jittered_block(eps_c=0.04)
    top = atoms.positions[:, 2] > atoms.positions[:, 2].max() - 0.5
    bottom = atoms.positions[:, 2] < atoms.positions[:, 2].min() + 0.5
    from ase.constraints import FixAtoms
    atoms.set_constraint(FixAtoms(mask=top | bottom))
    atoms.positions[top, 2] += 0.3  # pull the top layer up: some bonds past eps_c
    step = atoms.info["bpm_step"]
    with ase_bpm.pure(atoms):
        BFGS(atoms, logfile=None).run(fmax=1e-5, steps=300)
    assert "broken_bonds" not in atoms.info
    atoms.calc.step(atoms)
    assert len(atoms.info["broken_bonds"]) > 0
    assert atoms.info["bpm_step"] == step + 1  # one step, at the relaxed positions


def test_trial_move_that_rebuilds_the_contact_list_changes_nothing():
    """Contact pairs are kept in (i, j) order: a trial move far enough to rebuild
    the neighbour list, and back, leaves the run bit for bit."""
    atoms = jittered_block(eps_c=0.2)
    atoms.set_velocities(np.random.default_rng(5).normal(0, 0.05, (len(atoms), 3)))
    coeffs = dict(bond_coeffs={1: (1.0, 0.2, 0.5)}, pair_coeffs={(1, 1): (1.0, 1.5, 0.5)})
    twin = atoms.copy()
    atoms.calc, twin.calc = ase_bpm.BPMSpring(**coeffs), ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(atoms, 0.1).run(5)
    VelocityVerlet(twin, 0.1).run(5)
    builds = atoms.calc.model._contacts.neighbours.nbuilds
    with ase_bpm.pure(atoms):
        atoms.positions[7] += [3.0, 0, 0]
        atoms.get_forces()
        atoms.positions[7] -= [3.0, 0, 0]
        atoms.get_forces()
    assert atoms.calc.model._contacts.neighbours.nbuilds > builds
    VelocityVerlet(atoms, 0.1).run(10)
    VelocityVerlet(twin, 0.1).run(10)
    assert np.array_equal(atoms.positions, twin.positions)


def test_pure_with_one_calculator_for_several_images():
    """NEB-like: one calculator shared by two images; leaving re-bases both."""
    images = [jittered_block(), jittered_block()]
    calc = images[0].calc
    for image in images:
        image.calc = calc
        image.get_forces()
    steps = [image.info["bpm_step"] for image in images]
    with ase_bpm.pure(*images):
        for image in images:
            image.positions[0] += [0.2, 0, 0]
            image.get_forces()
    for image, step in zip(images, steps):
        image.get_forces()  # the relaxed place is not a step
        assert image.info["bpm_step"] == step and "broken_bonds" not in image.info


def test_step_at_a_relaxed_state_with_velocities_and_a_timed_fix():
    from ase_bpm import SphericalIndenter

    atoms = jittered_block()
    atoms.set_velocities(np.random.default_rng(6).normal(0, 0.02, (len(atoms), 3)))
    far = SphericalIndenter(1.0, 1.0, centre=(50.0, 50.0, 50.0))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.04, 0.0)}, fixes=[far],
                                   timestep=0.1)
    atoms.get_forces()
    with ase_bpm.pure(atoms):
        BFGS(atoms, logfile=None).run(fmax=1e-3, steps=50)
    step = atoms.info["bpm_step"]
    atoms.calc.step(atoms)  # no false "timestep mismatch": nothing moved
    assert atoms.info["bpm_step"] == step + 1
