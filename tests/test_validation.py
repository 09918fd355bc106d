"""Bad input: a clear exception naming the culprit, and no state lost."""

import numpy as np
import pytest
from ase import Atoms

import ase_bpm
from scenes import fcc_cluster
from state import assert_unchanged, snapshot

GOOD = dict(bond_coeffs={1: (1.0, 0.1, 0.5)}, pair_coeffs={(1, 1): (1.0, 1.0, 0.5)})


def bonded(seed=0):
    atoms, rng = fcc_cluster(2, seed=seed)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    return atoms


@pytest.mark.parametrize("coeffs,message", [
    (dict(bond_coeffs={1: (0.0, 0.1, 0.5)}), r"bond type 1: k = 0.0 must be positive"),
    (dict(bond_coeffs={1: (1.0, -0.1, 0.5)}), r"bond type 1: eps_c = -0.1 must be positive"),
    (dict(bond_coeffs={1: (1.0, 0.1, -0.5)}), r"bond type 1: gamma = -0.5 must be non-neg"),
    (dict(bond_coeffs={1: (1.0, 0.1)}), r"expected 3 coefficients \(k, eps_c, gamma\)"),
    (dict(pair_coeffs={(1, 1): (-1.0, 1.0, 0.5)}), r"types \(1, 1\): k = -1.0 must be pos"),
    (dict(pair_coeffs={(1, 2): (1.0, 0.0, 0.5)}), r"types \(1, 2\): r_c = 0.0 must be pos"),
    (dict(pair_coeffs={(1, 1): (1.0, 1.0, -2.0)}), r"types \(1, 1\): gamma = -2.0 must be"),
    (dict(pair_coeffs={(1, 1): (1.0, np.nan, 0.0)}), r"r_c = nan is not finite"),
    (dict(bond_coeffs={0: (1.0, 0.1, 0.5)}), r"type 0 must be an integer >= 1"),
    (dict(mix="sixthpower"), r'mix must be "geometric" or "arithmetic"'),
    (dict(smooth=True, break_bonds=False), r"smooth=True needs break_bonds=True"),
])
def test_bad_coefficients(coeffs, message):
    with pytest.raises(ValueError, match=message):
        ase_bpm.BPMSpring(**coeffs)


def evaluate_raises(atoms, message, calc=None):
    atoms.calc = calc or ase_bpm.BPMSpring(**GOOD)
    before = snapshot(atoms)
    with pytest.raises(ValueError, match=message):
        atoms.get_forces()
    assert_unchanged(atoms, before)


def test_unknown_bond_type():
    atoms = bonded()
    retyped = atoms.arrays["bond_type"].copy()
    retyped[retyped == 1] = 4
    atoms.arrays["bond_type"] = retyped
    evaluate_raises(atoms, r"unknown bond type 4 \(bond 0-\d+\): bond_coeffs has no entry")


def test_unknown_particle_type():
    atoms = bonded()
    atoms.arrays["type"] = np.ones(len(atoms), dtype=int)
    atoms.arrays["type"][5] = 3
    evaluate_raises(atoms, r"unknown particle type 3: pair_coeffs has no entry")


def test_invalid_particle_type():
    atoms = bonded()
    atoms.arrays["type"] = np.zeros(len(atoms), dtype=int)
    evaluate_raises(atoms, r"particle type 0 of atom 0 is invalid")


def test_partner_index_out_of_range():
    atoms = ase_bpm.with_bond_strings(bonded())  # lammps-data strings
    atoms.arrays["bonds"][1] = "99(1)"
    evaluate_raises(atoms, r'\["bonds"\]\[1\].*partner index 99 is out of range')


def test_atom_deleted_after_bonding():
    """Bonds refer to atom IDs: deleting an atom drops its bonds and keeps the
    rest, with their reference lengths."""
    atoms = bonded()
    atoms.calc = ase_bpm.BPMSpring(**GOOD)
    atoms.get_forces()
    table = ase_bpm.core.bonds.bond_table(atoms)
    r0 = {(a, b): atoms.arrays["bond_r0"][a, m]
          for a, b, m in zip(table.owner_b, table.partner_b, table.slot_b)}
    i, j, t = ase_bpm.get_bonds(atoms)
    assert np.any((i == 3) | (j == 3))
    del atoms[3]
    kept = (i != 3) & (j != 3)
    renumber = lambda k: k - (k > 3)  # noqa: E731
    i2, j2, t2 = ase_bpm.get_bonds(atoms)
    assert list(zip(i2, j2, t2)) == list(zip(renumber(i[kept]), renumber(j[kept]), t[kept]))
    table = ase_bpm.core.bonds.bond_table(atoms)
    for a, b, m in zip(table.owner_b, table.partner_b, table.slot_b):
        assert atoms.arrays["bond_r0"][a, m] == r0[a + (a >= 3), b + (b >= 3)]
    # the same calculator and a fresh one see the same remaining bonds
    twin = atoms.copy()
    twin.calc = ase_bpm.BPMSpring(**GOOD)
    assert np.array_equal(atoms.get_forces(), twin.get_forces())


@pytest.mark.parametrize("what", ["position", "velocity"])
def test_non_finite_positions_or_velocities(what):
    atoms = bonded()
    atoms.calc = ase_bpm.BPMSpring(**GOOD)
    atoms.get_forces()
    if what == "position":
        atoms.positions[2, 1] = np.nan
    else:
        v = atoms.get_velocities()
        v[2, 1] = np.inf
        atoms.set_velocities(v)
        atoms.positions[0, 0] += 1e-3
    evaluate_raises(atoms, rf"{what} of atom 2 is not finite", atoms.calc)


def test_periodic_cell_too_small_for_its_bonds():
    """A bond that could stretch past half the cell before breaking would
    silently flip to another periodic image."""
    atoms = Atoms("H2", positions=[[0, 0, 0], [1.4, 0, 0]], cell=[3, 3, 3], pbc=True,
                  masses=[1, 1])
    atoms.arrays["bonds"] = np.array(["1(1)", "_"])
    evaluate_raises(atoms, r"periodic cell too small for bond 0-1: with r0 = 1.4 and "
                           r"eps_c = 0.5 it may stretch to 2.1, beyond half the cell",
                    ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0)}))


def test_same_array_compares_bytes_in_place():
    """The state checks' comparison: same shape, type and bytes, so a NaN
    equals itself, -0.0 differs from 0.0, and an edit anywhere is seen."""
    from ase_bpm.core.arrays import same_array

    a = np.arange(12.0).reshape(4, 3)
    a[1, 2] = np.nan
    assert same_array(a, a.copy()) and same_array(None, None)
    edited = a.copy()
    edited[3, 0] = np.nextafter(edited[3, 0], 1e9)
    assert not same_array(a, edited)
    assert not same_array(np.zeros(3), -np.zeros(3))
    assert not same_array(a, a.reshape(3, 4)) and not same_array(a, a.astype(np.float32))
    assert not same_array(a, None)
    assert same_array(a[:, 1], a.copy()[:, 1])  # not contiguous: compared all the same
    strings = np.array(["a", "bc"])
    assert same_array(strings, strings.copy()) and not same_array(strings, strings[::-1])
