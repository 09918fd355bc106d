"""Bond lists on the atoms: format, create_bonds, ASE lammps-data interplay."""

import io

import numpy as np
import pytest
from ase import Atoms
from ase.io import read, write
from hypothesis import given, settings
from hypothesis import strategies as st

import ase_bpm
from ase_bpm.core.bonds import parse_bonds
from ase_bpm.core.neighbours import minimum_image
from scenes import fcc_cluster


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 9), st.integers(0, 9), st.integers(0, 12)),
                max_size=30))
def test_strings_and_integer_storage_are_inverse(entries):
    """lammps-data strings taken in and written out again are the same strings,
    and the bonds in between are those the strings list."""
    entries = [(i, j, t) for i, j, t in entries if i != j]
    natoms = 10
    listed = [[] for _ in range(natoms)]
    for i, j, t in entries:
        listed[i].append(f"{j}({t})")
    strings = np.array([",".join(e) if e else "_" for e in listed])
    atoms = Atoms(f"H{natoms}", positions=np.arange(3 * natoms).reshape(-1, 3))
    atoms.arrays["bonds"] = strings
    assert ase_bpm.core.bonds.take_bonds(atoms) == len(entries)
    assert "bonds" not in atoms.arrays
    i, j, t = ase_bpm.get_bonds(atoms, include_broken=True)
    by_owner = sorted(range(len(entries)), key=lambda k: entries[k][0])  # stable: slots
    assert list(zip(i, j, t)) == [entries[k] for k in by_owner]
    assert np.array_equal(ase_bpm.core.bonds.bond_strings(atoms), strings)
    table = parse_bonds(strings)
    assert np.array_equal(table.partner_b, j) and np.array_equal(table.owner_b, i)


def brute_force_pairs(atoms, cutoff, mask):
    n = len(atoms)
    i, j = np.triu_indices(n, 1)
    d = minimum_image(atoms.positions[j] - atoms.positions[i], atoms.cell, atoms.pbc)
    keep = (np.linalg.norm(d, axis=1) <= cutoff) & mask[i] & mask[j]
    return set(zip(i[keep].tolist(), j[keep].tolist()))


@pytest.mark.parametrize("pbc", [False, True])
def test_create_bonds_is_create_bonds_many(pbc):
    atoms, rng = fcc_cluster(3, seed=11, pbc=pbc)
    atoms.positions += [0.4, -0.3, 0.2]  # some atoms outside the cell
    mask = rng.random(len(atoms)) < 0.8
    added = ase_bpm.create_bonds(atoms, 1.3, bond_type=2, mask=mask)
    i, j, t = ase_bpm.get_bonds(atoms)
    assert set(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist())) == \
        brute_force_pairs(atoms, 1.3, mask)
    assert added == len(i) and set(t) == {2}
    if pbc:  # bonds across the boundary exist
        assert np.linalg.norm(atoms.positions[j] - atoms.positions[i], axis=1).max() > 3


def test_create_bonds_adds_to_existing_bonds_and_keeps_state_aligned():
    atoms, _ = fcc_cluster(3, seed=12)
    ase_bpm.create_bonds(atoms, 1.2, bond_type=1)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0), 2: (1.0, 0.5, 0.0)})
    atoms.get_forces()
    table = ase_bpm.core.bonds.bond_table(atoms)
    r0_before = {(i, j): atoms.arrays["bond_r0"][i, m]
                 for i, m, j in zip(table.owner_b, table.slot_b, table.partner_b)}
    first = len(ase_bpm.get_bonds(atoms)[0])
    assert ase_bpm.create_bonds(atoms, 1.2, bond_type=2) == 0  # nothing new
    added = ase_bpm.create_bonds(atoms, 1.7, bond_type=2)
    i, j, t = ase_bpm.get_bonds(atoms)
    assert len(i) == first + added and np.sum(t == 2) == added
    # existing reference lengths stay with their bonds; new ones are unset
    table = ase_bpm.core.bonds.bond_table(atoms)
    r0 = atoms.arrays["bond_r0"][table.owner_b, table.slot_b]
    for i_, j_, t_, r_ in zip(table.owner_b, table.partner_b, table.type_b, r0):
        if t_ == 1:
            assert r_ == r0_before[i_, j_]
        else:
            assert np.isnan(r_)
    atoms.get_forces()  # new bonds get their reference lengths now
    r0 = atoms.arrays["bond_r0"][table.owner_b, table.slot_b]
    assert np.all(r0 > 0)


def test_bonds_from_ase_lammps_data_files_are_accepted():
    """ASE's lammps-data writer and reader use the same bonds format."""
    atoms, _ = fcc_cluster(2, seed=13)
    ase_bpm.create_bonds(atoms, 1.3)
    buf = io.StringIO()
    write(buf, ase_bpm.with_bond_strings(atoms), format="lammps-data",
          atom_style="full", bonds=True, units="metal")
    buf.seek(0)
    back = read(buf, format="lammps-data", atom_style="full", units="metal")
    i, j, t = ase_bpm.get_bonds(back)
    i0, j0, _ = ase_bpm.get_bonds(atoms)
    assert {frozenset(p) for p in zip(i, j)} == {frozenset(p) for p in zip(i0, j0)}
    back.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.0)})
    assert np.abs(back.get_forces()).max() < 1e-12  # reference state: no force


def test_bad_bond_strings_name_the_atom():
    with pytest.raises(ValueError, match=r'\["bonds"\]\[1\].*"j\(t\)"'):
        parse_bonds(np.array(["_", "2[1]", "_"]))
    with pytest.raises(ValueError, match="partner index 7 is out of range for 3 atoms"):
        parse_bonds(np.array(["_", "7(1)", "_"]))
    with pytest.raises(ValueError, match="bonded to itself"):
        parse_bonds(np.array(["0(1)", "_"]))


def test_create_bonds_rejects_cutoff_beyond_half_the_cell():
    atoms = Atoms("H2", positions=[[0, 0, 0], [1, 0, 0]], cell=[3, 3, 3], pbc=True)
    with pytest.raises(ValueError, match="half the periodic cell width"):
        ase_bpm.create_bonds(atoms, 1.6)
    with pytest.raises(ValueError, match="bond_type"):
        ase_bpm.create_bonds(atoms, 1.0, bond_type=0)
