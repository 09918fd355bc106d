"""Properties every calculator must have, over random small scenes
(hypothesis): finite forces, no net force without fixes, invariance under
translation, rotation and permutation of the atoms, and, for the conservative
parts (no damping, nothing breaking, pure evaluations), forces that are minus
the gradient of the energy."""

import numpy as np
import pytest
from ase import Atoms
from ase.lattice.cubic import FaceCenteredCubic
from hypothesis import given, settings
from hypothesis import strategies as st

import ase_bpm
from scenes import BULK, DENSITY, FCC, HORIZON, MICROMODULUS, NODE_VOLUME, SPACING

MODELS = ["spring", "spring-damped", "pmb", "lps", "hooke", "hertz/history"]
CONSERVATIVE = {"spring", "pmb", "lps", "hooke"}  # no damping, no path dependence


def scene(model: str, seed: int):
    """A jittered block, bonded where the model has bonds, with random
    velocities (and spins for spheres), strained below breaking."""
    rng = np.random.default_rng(seed)
    if model in ("pmb", "lps"):
        grid = np.indices((3, 3, 3)).reshape(3, -1).T.astype(float)
        atoms = Atoms(f"Si{len(grid)}", positions=grid * SPACING)
        atoms.arrays["vfrac"] = np.full(len(atoms), NODE_VOLUME)
        atoms.set_masses(np.full(len(atoms), DENSITY * NODE_VOLUME))
        ase_bpm.create_bonds(atoms, HORIZON)
        coeffs = {"pmb": ("pmb", MICROMODULUS, HORIZON, 10.0, 0.0),
                  "lps": ("lps", BULK, 0.4 * BULK, HORIZON, 10.0, 0.0)}[model]
        atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: coeffs}, lattice_spacing=SPACING)
        scale, speed = SPACING, 1.0
    elif model in ("hooke", "hertz/history"):
        atoms = FaceCenteredCubic("Ar", size=(2, 2, 2), latticeconstant=np.sqrt(2.0),
                                  pbc=False)
        atoms.arrays["radius"] = 0.5 * rng.uniform(1.0, 1.06, len(atoms))
        atoms.set_masses(rng.uniform(0.8, 1.2, len(atoms)))
        atoms.arrays["omega"] = rng.normal(0, 0.3, (len(atoms), 3))
        law = dict(kn=200.0, gamma_n=0.0, xmu=0.0) if model == "hooke" else \
            dict(kn=200.0, gamma_n=5.0, xmu=0.5)
        atoms.calc = ase_bpm.Granular(model, **law)
        scale, speed = 1.0, 0.2
    else:
        atoms = FaceCenteredCubic("Cu", size=(2, 2, 2), latticeconstant=FCC, pbc=False)
        atoms.set_masses(rng.uniform(0.8, 1.2, len(atoms)))
        ase_bpm.create_bonds(atoms, 1.25)
        gamma = 1.0 if model == "spring-damped" else 0.0
        atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, gamma)},
                                       pair_coeffs={(1, 1): (1.0, 1.0, gamma)}, smooth=False)
        scale, speed = 1.0, 0.1
    atoms.get_forces()  # reference lengths at the lattice
    atoms.positions += rng.uniform(-0.04, 0.04, atoms.positions.shape) * scale
    atoms.set_velocities(rng.normal(0, speed, atoms.positions.shape))
    return atoms


def fresh(atoms):
    """The same scene (bonds with their reference lengths, history) under a
    new calculator of the same parameters, with no record of the last step."""
    copy = atoms.copy()
    for name in ("bpm_x_last", "bpm_f_last", "bpm_fd_last", "bpm_t_last"):
        copy.arrays.pop(name, None)
    copy.calc = type(atoms.calc)(**atoms.calc.parameters)
    return copy


def pure_forces(atoms):
    with ase_bpm.pure(atoms):
        return atoms.get_forces(), atoms.get_potential_energy()


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10_000))
@pytest.mark.parametrize("model", MODELS)
def test_finite_and_no_net_force(model, seed):
    atoms = scene(model, seed)
    f_nc, _ = pure_forces(atoms)
    assert np.isfinite(f_nc).all() and np.abs(f_nc).max() > 0
    assert np.abs(f_nc.sum(axis=0)).max() <= 1e-12 * np.abs(f_nc).max() * len(atoms)


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10_000), angle=st.floats(0.1, 3.0),
       axis=st.sampled_from([(0, 0, 1), (1, 1, 0), (1, -2, 3)]),
       shift=st.tuples(*[st.floats(-50, 50)] * 3))
@pytest.mark.parametrize("model", MODELS)
def test_translation_and_rotation_move_the_forces_along(model, seed, angle, axis, shift):
    atoms = scene(model, seed)
    f_nc, energy = pure_forces(atoms)
    u = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    rot = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    moved = fresh(atoms)
    scale = np.abs(atoms.positions).max()
    moved.positions = atoms.positions @ rot.T + np.asarray(shift) * scale / 10
    moved.set_velocities(atoms.get_velocities() @ rot.T)
    if "omega" in atoms.arrays:
        moved.arrays["omega"] = atoms.arrays["omega"] @ rot.T
    g_nc, moved_energy = pure_forces(moved)
    assert moved_energy == pytest.approx(energy, rel=1e-9, abs=1e-300)
    assert np.allclose(g_nc, f_nc @ rot.T, rtol=0, atol=1e-9 * np.abs(f_nc).max())


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10_000), order=st.randoms(use_true_random=False))
@pytest.mark.parametrize("model", MODELS)
def test_permuting_the_atoms_permutes_the_forces(model, seed, order):
    atoms = scene(model, seed)
    f_nc, energy = pure_forces(atoms)
    perm = list(range(len(atoms)))
    order.shuffle(perm)
    shuffled = fresh(atoms)[perm]
    shuffled.calc = type(atoms.calc)(**atoms.calc.parameters)
    g_nc, shuffled_energy = pure_forces(shuffled)
    assert shuffled_energy == pytest.approx(energy, rel=1e-12, abs=1e-300)
    assert np.allclose(g_nc, f_nc[perm], rtol=0, atol=1e-12 * np.abs(f_nc).max())


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000))
@pytest.mark.parametrize("model", sorted(CONSERVATIVE))
def test_forces_are_minus_the_energy_gradient(model, seed):
    atoms = scene(model, seed)
    atoms.set_velocities(np.zeros((len(atoms), 3)))
    f_nc, _ = pure_forces(atoms)
    rng = np.random.default_rng(seed)
    h = 1e-6 * (SPACING if model in ("pmb", "lps") else 1.0)
    with ase_bpm.pure(atoms):
        for atom, c in zip(rng.integers(0, len(atoms), 5), rng.integers(0, 3, 5)):
            x = atoms.positions.copy()
            energies = []
            for step in (h, -h):
                atoms.positions = x
                atoms.positions[atom, c] += step
                energies.append(atoms.get_potential_energy())
            atoms.positions = x
            slope = (energies[0] - energies[1]) / (2 * h)
            assert -slope == pytest.approx(f_nc[atom, c], rel=1e-5,
                                           abs=1e-6 * np.abs(f_nc).max())
