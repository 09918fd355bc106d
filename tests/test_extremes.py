"""The edges of the input space: no atoms, one atom, bad masses, coincident
particles, a particle moved far away.  Each gives correct forces or a clear
error naming the problem, never a crash from inside the code."""

import numpy as np
import pytest
from ase import Atoms

import ase_bpm
from ase_bpm import VelocityVerlet
from test_only_what_is_needed import Calls

# scenes at the edges: many hold no bond, which the bonded models warn of
pytestmark = pytest.mark.filterwarnings("ignore::ase_bpm.NoBondsWarning")

SPRING = dict(bond_coeffs={1: (1.0, 0.1, 0.0)}, pair_coeffs={(1, 1): (1.0, 1.0, 0.0)})
PERI = dict(bond_coeffs={1: ("pmb", 1.0, 1.5, 10.0, 0.0)}, pair_coeffs={(1, 1): (1.0, 1.0)},
            lattice_spacing=0.5)
GRANULAR = dict(model="hooke", kn=100.0, gamma_n=0.0, xmu=0.0)


def calculator(name):
    return {"spring": lambda: ase_bpm.BPMSpring(**SPRING),
            "peri": lambda: ase_bpm.BPMPeri(**PERI),
            "granular": lambda: ase_bpm.Granular(**GRANULAR)}[name]()


def particles(name, positions, masses=None):
    atoms = Atoms(f"H{len(positions)}" if len(positions) else "", positions=positions,
                  masses=masses if masses is not None else np.ones(len(positions)))
    if name == "granular":
        atoms.arrays["radius"] = np.full(len(atoms), 0.5)
    if name == "peri":
        atoms.arrays["vfrac"] = np.full(len(atoms), 0.125)
    atoms.calc = calculator(name)
    return atoms


@pytest.mark.parametrize("name", ["spring", "peri", "granular"])
def test_no_atoms(name):
    atoms = particles(name, np.zeros((0, 3)))
    assert atoms.get_forces().shape == (0, 3)
    assert atoms.get_potential_energy() == 0.0
    assert atoms.calc.stable_timestep(atoms) == np.inf


@pytest.mark.parametrize("name", ["spring", "peri", "granular"])
def test_one_atom_and_no_bonds_feel_nothing(name):
    one = particles(name, [[0.0, 0.0, 0.0]])
    assert np.array_equal(one.get_forces(), np.zeros((1, 3)))
    apart = particles(name, [[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])  # beyond every cutoff
    assert np.array_equal(apart.get_forces(), np.zeros((2, 3)))
    assert apart.calc.stable_timestep(apart) == np.inf


@pytest.mark.parametrize("name", ["spring", "peri", "granular"])
@pytest.mark.parametrize("gap", [0.0, 1e-300, 1e-155, 1e-12])
def test_coincident_particles_get_finite_forces(name, gap):
    atoms = particles(name, [[0.0, 0.0, 0.0], [gap, 0.0, 0.0], [0.3, 0.4, 0.0]])
    if name == "granular" and gap < 1e-150:  # 1 / r^2 overflows: a contact without a normal
        with pytest.raises(ValueError, match="spheres 0 and 1 are at the same position"):
            atoms.get_forces()
        return
    f_nc = atoms.get_forces()
    assert np.isfinite(f_nc).all() and np.isfinite(atoms.get_potential_energy())
    assert np.abs(f_nc.sum(axis=0)).max() <= 1e-12 * max(1.0, np.abs(f_nc).max())


@pytest.mark.parametrize("name", ["spring", "peri", "granular"])
@pytest.mark.parametrize("mass", [0.0, -1.0, np.nan])
def test_a_bad_mass_is_named_not_the_positions(name, mass):
    atoms = particles(name, [[0.0, 0.0, 0.0], [0.9, 0.0, 0.0]], masses=[1.0, mass])
    atoms.set_velocities([[0.1, 0.0, 0.0], [0.0, 0.0, 0.0]])
    dyn = (ase_bpm.SphereVelocityVerlet if name == "granular" else VelocityVerlet)
    with pytest.raises(ValueError, match=r"mass of atom 1 is (0\.0|-1\.0|nan): masses must "
                                         r"be finite and positive"), \
            np.errstate(divide="ignore", invalid="ignore"):
        dyn(atoms, timestep=0.01).run(3)


def test_a_tiny_mass_gets_a_tiny_stable_timestep():
    atoms = particles("spring", [[0.0, 0.0, 0.0], [0.9, 0.0, 0.0]], masses=[1.0, 1e-30])
    dt = atoms.calc.stable_timestep(atoms)
    assert 0 < dt < 1e-14
    assert np.isfinite(atoms.get_forces()).all()


@pytest.mark.parametrize("name", ["spring", "peri", "granular"])
def test_a_particle_moved_many_skins_away_gets_a_fresh_calculators_forces(name):
    rng = np.random.default_rng(1)
    x = rng.uniform(0.0, 2.0, (12, 3))
    atoms = particles(name, x)
    atoms.get_forces()
    with pytest.warns(ase_bpm.OptimiserStepWarning):  # steps by hand, the momenta kept
        for far in (40.0, 1e4, 1e9):  # many skin widths, then an exploded box
            atoms.positions[5] = x[5] + [far, -far, 0.5 * far]
            fresh = particles(name, atoms.positions.copy())
            assert np.array_equal(atoms.get_forces(), fresh.get_forces())
            assert np.array_equal(atoms.get_forces()[5], np.zeros(3))


@pytest.mark.parametrize("pbc", [(False,) * 3, (True, True, False), (True,) * 3])
@pytest.mark.parametrize("per_atom", [False, True])
def test_the_tree_search_finds_the_pairs_binning_finds(per_atom, pbc, monkeypatch):
    """The same pairs and image shifts, periodic or not (some atoms lie
    outside the periodic cell)."""
    from ase_bpm.core import neighbours

    rng = np.random.default_rng(3)
    x = rng.uniform(0.0, 6.0, (300, 3))
    x[::7] += [6.0, -6.0, 0.0]  # outside the cell: images of atoms inside
    cutoff = rng.uniform(0.2, 0.6, 300) if per_atom else 0.9
    cell = 6.0 * np.eye(3) if any(pbc) else np.zeros((3, 3))
    binned = neighbours.neighbour_pairs(x, cell, pbc, cutoff)
    monkeypatch.setattr(neighbours, "MAX_BINS", 0)
    monkeypatch.setattr(neighbours, "BINS_PER_ATOM", 0)
    trees = Calls(monkeypatch, neighbours, "_tree_pairs")
    tree = neighbours.neighbour_pairs(x, cell, pbc, cutoff)
    assert trees.count == 1
    assert len(binned[0]) > 300

    def as_set(p):
        return set(zip(p[0].tolist(), p[1].tolist(), map(tuple, np.round(p[2], 9).tolist())))

    assert as_set(tree) == as_set(binned)
    assert tree[2].any() == any(pbc)


def test_a_slab_exploding_across_its_open_direction_is_searched_by_a_tree(monkeypatch):
    """A periodic slab whose particle flies off along the open direction:
    the tree takes the search (matscipy would bin the whole height), the
    forces are a fresh calculator's."""
    from ase_bpm.core import neighbours

    rng = np.random.default_rng(4)
    x = rng.uniform(0.0, 4.0, (40, 3))
    atoms = particles("spring", x)
    atoms.set_cell(4.0 * np.eye(3))
    atoms.pbc = (True, True, False)
    atoms.get_forces()
    trees = Calls(monkeypatch, neighbours, "_tree_pairs")
    atoms.positions[5] = x[5] + [0.0, 0.0, 1e9]
    fresh = atoms.copy()
    fresh.calc = calculator("spring")
    assert np.array_equal(atoms.get_forces(), fresh.get_forces())
    assert np.array_equal(atoms.get_forces()[5], np.zeros(3))
    assert trees.count >= 1
