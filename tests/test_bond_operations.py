"""Bonds survive what ASE users do to atoms: they refer to atom IDs, not indices.

Each test builds the expected bond list from the original one by following the
atoms through the operation, and compares it with ``get_bonds`` afterwards;
where a calculator has evaluated the body, reference lengths go along.
"""

import numpy as np
import pytest
from ase import Atoms
from ase.build import sort

import ase_bpm
from scenes import fcc_cluster

COEFFS = dict(bond_coeffs={1: (1.0, 0.1, 0.5), 2: (2.0, 0.2, 0.5)},
              pair_coeffs={(1, 1): (1.0, 1.0, 0.5)})


def body(seed=0, size=2, pbc=False, bond_type=1):
    """A bonded, evaluated FCC block: reference lengths taken."""
    atoms, rng = fcc_cluster(size, seed=seed, pbc=pbc)
    ase_bpm.create_bonds(atoms, 1.5, bond_type=bond_type)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(**COEFFS)
    atoms.get_forces()
    atoms.calc = None
    return atoms


def bond_set(atoms):
    """{(i, j) sorted: (type, r0)} of every listed bond, broken ones too."""
    table = ase_bpm.core.bonds.bond_table(atoms)
    r0 = atoms.arrays["bond_r0"][table.owner_b, table.slot_b]
    return {(min(a, b), max(a, b)): (t, r) for a, b, t, r in
            zip(table.owner_b, table.partner_b, table.type_b, r0)}


def followed(bonds, new_index):
    """The bonds after atom ``k`` became ``new_index[k]`` (-1: gone)."""
    out = {}
    for (a, b), value in bonds.items():
        na, nb = new_index[a], new_index[b]
        if na >= 0 and nb >= 0:
            out[min(na, nb), max(na, nb)] = value
    return out


def assert_same_forces_as_fresh(atoms):
    """A calculator on the result sees exactly the bonds a fresh one does."""
    atoms.calc = ase_bpm.BPMSpring(**COEFFS)
    twin = atoms.copy()
    twin.calc = ase_bpm.BPMSpring(**COEFFS)
    assert np.array_equal(atoms.get_forces(), twin.get_forces())


def test_copy():
    atoms = body()
    assert bond_set(atoms.copy()) == bond_set(atoms)


def test_sum_of_two_bodies_bonded_separately():
    a, b = body(seed=1), body(seed=2, bond_type=2)
    b.positions += [10.0, 0, 0]
    both = a + b
    expected = dict(bond_set(a))
    expected.update(followed(bond_set(b), np.arange(len(b)) + len(a)))
    assert bond_set(both) == expected
    assert_same_forces_as_fresh(both)


@pytest.mark.parametrize("select", ["mask", "index_list", "permutation"])
def test_selections(select):
    atoms = body(seed=3)
    n = len(atoms)
    rng = np.random.default_rng(5)
    if select == "mask":
        keep = rng.random(n) < 0.7
        index = np.flatnonzero(keep)
        result = atoms[keep]
    else:
        index = rng.permutation(n)[: n if select == "permutation" else n // 2]
        result = atoms[index]
    new_index = np.full(n, -1)
    new_index[index] = np.arange(len(index))
    assert bond_set(result) == followed(bond_set(atoms), new_index)
    assert len(bond_set(result)) > 0
    assert_same_forces_as_fresh(result)


def test_ase_build_sort():
    atoms = body(seed=4)
    atoms.set_chemical_symbols(np.random.default_rng(6).choice(["Cu", "Ag", "Au"],
                                                                 len(atoms)))
    result = sort(atoms)
    order = np.argsort(atoms.get_chemical_symbols(), kind="stable")  # what sort does
    assert np.array_equal(result.positions, atoms.positions[order])
    new_index = np.empty(len(atoms), dtype=int)
    new_index[order] = np.arange(len(atoms))
    assert bond_set(result) == followed(bond_set(atoms), new_index)


def test_delete_atoms():
    atoms = body(seed=5)
    before = bond_set(atoms)
    gone = [2, 7, 11]
    del atoms[gone]
    new_index = np.arange(len(atoms) + len(gone))
    new_index[gone] = -1
    keep = new_index >= 0
    new_index[keep] = np.arange(keep.sum())
    assert bond_set(atoms) == followed(before, new_index)
    assert_same_forces_as_fresh(atoms)


def test_broken_bonds_stay_broken_through_operations():
    atoms = body(seed=6)
    atoms.calc = ase_bpm.BPMSpring(**COEFFS)
    atoms.positions[0] += [0.5, 0, 0]  # breaks atom 0's bonds
    atoms.get_forces()
    listed = ase_bpm.core.bonds.read_ids(atoms, "bond_partner") != 0
    assert np.any(atoms.arrays["bond_type"][listed] == 0)
    perm = np.random.default_rng(7).permutation(len(atoms))
    new_index = np.empty(len(atoms), dtype=int)
    new_index[perm] = np.arange(len(atoms))
    assert bond_set(atoms[perm]) == followed(bond_set(atoms), new_index)


def test_same_body_twice_names_the_fix():
    a = body(seed=8)
    twice = a + a.copy()
    with pytest.raises(ValueError, match=r"carry the same ID .* ase_bpm.renew_ids"):
        ase_bpm.get_bonds(twice)
    twice.calc = ase_bpm.BPMSpring(**COEFFS)
    with pytest.raises(ValueError, match=r"a \+ ase_bpm.renew_ids\(a.copy\(\)\)"):
        twice.get_forces()
    fixed = a + ase_bpm.renew_ids(a.copy())
    expected = dict(bond_set(a))
    expected.update(followed(bond_set(a), np.arange(len(a)) + len(a)))
    assert bond_set(fixed) == expected


@pytest.mark.parametrize("how", ["repeat", "multiply"])
def test_ase_repeat_names_the_fix(how):
    atoms = body(seed=9, pbc=True, size=3)
    big = atoms.repeat((2, 1, 1)) if how == "repeat" else atoms * (2, 1, 1)
    with pytest.raises(ValueError, match=r"ase_bpm.repeat\(atoms, reps\)"):
        ase_bpm.get_bonds(big)


def test_bonded_repeat_keeps_bonds_across_periodic_boundaries():
    """ase_bpm.repeat of a periodic bonded block is the block bonded afresh in
    the bigger cell (bonds across the old boundary join the next copy), with
    each bond's reference length."""
    atoms = body(seed=10, pbc=True, size=3)
    i, j, _ = ase_bpm.get_bonds(atoms)
    r = ase_bpm.core.neighbours.minimum_image(atoms.positions[j] - atoms.positions[i],
                                         atoms.cell, atoms.pbc)
    assert np.any(np.abs(atoms.positions[j] - atoms.positions[i] - r) > 1)  # some cross
    big = ase_bpm.repeat(atoms, (2, 1, 2))
    fresh = atoms.repeat((2, 1, 2))
    for name in ("bpm_id", "bond_partner", "bond_type", "bond_r0"):
        del fresh.arrays[name]
    ase_bpm.create_bonds(fresh, 1.5)
    got = bond_set(big)
    fi, fj, _ = ase_bpm.get_bonds(fresh)
    assert set(got) == {(min(a, b), max(a, b)) for a, b in zip(fi, fj)}
    assert len(got) == 4 * len(i)
    assert not any(name.startswith("bpm_") and name != "bpm_id" for name in big.arrays)
    r0 = dict(zip(((min(a, b), max(a, b)) for a, b in zip(i, j)),
                  (v[1] for v in bond_set(atoms).values())))
    n = len(atoms)
    for (a, b), (t, r0_ab) in got.items():
        assert t == 1 and r0_ab == r0[min(a % n, b % n), max(a % n, b % n)]


def test_sum_with_a_body_not_yet_evaluated():
    """ASE fills the arrays that only one body has with zeros: the other body's
    bonds must take their reference lengths now, not break at r0 = 0, and the
    first evaluation of the combined scene is not a step."""
    a = body(seed=11)  # evaluated: reference lengths and a record
    b, _ = fcc_cluster(2, seed=12)
    ase_bpm.create_bonds(b, 1.5)
    b.positions += [10.0, 0, 0]
    both = a + b
    both.calc = ase_bpm.BPMSpring(**COEFFS)
    both.get_forces()
    i, j, t = ase_bpm.get_bonds(both)
    assert len(i) == len(ase_bpm.get_bonds(a)[0]) + len(ase_bpm.get_bonds(b)[0])
    assert np.all(t > 0) and "broken_bonds" not in both.info
    table = ase_bpm.core.bonds.bond_table(both)
    assert np.all(both.arrays["bond_r0"][table.owner_b, table.slot_b] > 0)
    assert both.info["bpm_step"] == a.info["bpm_step"]  # not a step


def test_sum_of_bodies_with_bond_lists_of_different_lengths():
    """Bond arrays are as wide as a power of two (at least 16): a chain and a
    block combine; wider ones are padded with pad_bonds."""
    block = body(seed=13)
    chain = Atoms("H3", positions=[[20, 0, 0], [21, 0, 0], [22, 0, 0]], masses=[1, 1, 1])
    chain.arrays["type"] = np.ones(3, dtype=int)
    ase_bpm.create_bonds(chain, 1.1)
    assert block.arrays["bond_type"].shape[1] == chain.arrays["bond_type"].shape[1]
    both = block + chain
    i, j, _ = ase_bpm.get_bonds(both)
    assert len(i) == len(ase_bpm.get_bonds(block)[0]) + 2
    wide = body(seed=14)
    ase_bpm.create_bonds(wide, 2.6)  # many more bonds per atom
    assert wide.arrays["bond_type"].shape[1] > 16
    ase_bpm.pad_bonds(chain, wide.arrays["bond_type"].shape[1])
    assert len(ase_bpm.get_bonds(wide + chain)[0]) == len(ase_bpm.get_bonds(wide)[0]) + 2


def test_deleting_an_unbonded_atom_at_the_same_positions_recomputes():
    atoms = Atoms("H3", positions=[[0, 0, 0], [0.9, 0, 0], [0, 0, 0.95]], masses=[1, 1, 1])
    atoms.calc = ase_bpm.BPMSpring(pair_coeffs={(1, 1): (1.0, 1.0, 0.0)})
    assert np.abs(atoms.get_forces()).max() > 0
    del atoms[1]  # the same positions for the others: the record no longer holds
    fresh = atoms.copy()
    fresh.calc = ase_bpm.BPMSpring(pair_coeffs={(1, 1): (1.0, 1.0, 0.0)})
    for calc in (atoms.calc, ase_bpm.BPMSpring(pair_coeffs={(1, 1): (1.0, 1.0, 0.0)})):
        atoms.calc = calc
        assert np.array_equal(atoms.get_forces(), fresh.get_forces())


def test_replaced_reference_lengths_are_used_at_the_same_positions():
    atoms = body(seed=15)
    atoms.calc = ase_bpm.BPMSpring(**COEFFS)
    before = atoms.get_forces()
    r0 = atoms.arrays["bond_r0"] * 1.01  # replace the array: a new reference
    atoms.arrays["bond_r0"] = r0
    assert np.abs(atoms.get_forces() - before).max() > 1e-3
    with pytest.raises(ValueError, match="read-only"):
        atoms.arrays["bond_r0"][0, 0] = 1.0  # in place: refused
