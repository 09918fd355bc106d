"""Broken bonds kept listed (type 0) on the compiled route, as LAMMPS keeps
them in its bond list until it rebuilds it.

A bond set whose laws' kernels pass over type-0 bonds marks the bonds that
break in place instead of copying every bond array (``BondSet.without(...,
lazy=True)``), and sheds them once they are ``DEAD_SHARE`` of the set.  What
the calculator gives must not depend on when that happens: the same forces
bit for bit (the live bonds keep their order), the same bond topology for
the restart record, the same contacts, the same checks.
"""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.core import bond_set
from ase_bpm.models.bonded import BondState
from test_compiled_spring import bonded_scene, coefficients

pytestmark = pytest.mark.compiled


def run(atoms, steps: int, kernels: str = "compiled"):
    """``atoms`` (a copy) after ``steps`` steps of the damped multi-type
    cluster, on the given route; the calculator on it."""
    a = atoms.copy()
    a.calc = ase_bpm.BPMSpring(**coefficients(), kernels=kernels, guard=False)
    VelocityVerlet(a, timestep=0.02).run(steps)
    return a


def flying_cluster():
    atoms = bonded_scene("open", seed=4)
    atoms.set_velocities(np.random.default_rng(5).normal(0, 0.3, atoms.positions.shape))
    return atoms


def fresh(atoms):
    """The bonds on ``atoms`` as a new calculator reads them."""
    return BondState().peek(atoms)


def test_broken_bonds_stay_listed_and_the_set_sheds_them():
    """After bonds break on the compiled route the run's set still lists them
    (type 0), and the set without them is what a fresh read gives; a run
    that sheds them at every breaking gives the same trajectory bit for bit."""
    atoms = flying_cluster()
    lazy = run(atoms, 60)
    bonds = lazy.calc.model._bond_state.current
    intact = len(ase_bpm.get_bonds(lazy)[0])
    assert 0 < bonds.dead == len(bonds) - intact == int((bonds.type_b == 0).sum())
    read = fresh(lazy)
    assert read.dead == 0 and len(read) == intact
    compact = bonds.compacted()
    for name in ("i_b", "j_b", "type_b", "intact_b"):
        assert np.array_equal(getattr(compact, name), getattr(read, name)), name
    assert bonds.fingerprint == compact.fingerprint == read.fingerprint

    share = bond_set.DEAD_SHARE
    try:
        bond_set.DEAD_SHARE = 0.0  # shed at every breaking: the eager set
        eager = run(atoms, 60)
    finally:
        bond_set.DEAD_SHARE = share
    assert eager.calc.model._bond_state.current.dead == 0
    assert np.array_equal(eager.positions, lazy.positions)
    assert np.array_equal(eager.get_forces(), lazy.get_forces())
    assert np.array_equal(eager.arrays["bond_type"], lazy.arrays["bond_type"])


def test_the_numpy_route_sheds_at_once_with_the_same_bonds():
    atoms = flying_cluster()
    a = run(atoms, 60, kernels="numpy")
    assert a.calc.model._bond_state.current.dead == 0
    b = run(atoms, 60)
    assert np.array_equal(a.arrays["bond_type"], b.arrays["bond_type"])


def test_a_set_with_listed_broken_bonds_excludes_only_intact_pairs_from_contacts():
    """The sorted keys of the bonded pairs (which keep bonded pairs out of
    the pair law) worked out afresh on a set that lists broken bonds leave
    those out."""
    bonds = run(flying_cluster(), 60).calc.model._bond_state.current
    assert bonds.dead > 0
    bonds.cache.pop("bonded_keys", None)
    bonds.cache.pop("bonded_keys_since", None)
    assert np.array_equal(bonds.bonded_keys, fresh(run(flying_cluster(), 60)).bonded_keys)


def test_the_periodic_reach_check_sees_past_listed_broken_bonds():
    """A periodic cell shrunk below what the intact bonds may stretch to is
    refused while broken bonds are still listed (their coefficients are
    NaN: they must not hide the intact ones)."""
    atoms = bonded_scene("orthorhombic", seed=2)
    atoms.calc = ase_bpm.BPMSpring(**coefficients(), kernels="compiled", guard=False)
    atoms.get_forces()
    rng = np.random.default_rng(3)
    atoms.positions = atoms.positions + rng.normal(0, 0.03, atoms.positions.shape)
    atoms.get_forces()  # a step in which a few bonds break (2 %: they stay listed)
    bonds = atoms.calc.model._bond_state.current
    assert bonds.dead > 0
    longest = float(np.nanmax(bonds.of_bonds("r0")))
    atoms.set_cell(atoms.cell * (1.9 * longest / atoms.cell.lengths().min()),
                   scale_atoms=True)
    with pytest.raises(ValueError, match="periodic cell too small"):
        atoms.get_forces()


def test_state_handed_out_keeps_its_values_when_the_state_is_set():
    """A set that lists every row of its table hands out the state's own
    array (read-only, no copy); setting the state then writes a new array,
    seen by every set that shares the state, while what was handed out keeps
    the values it had (a virial replayed after the commit reads them)."""
    atoms = flying_cluster()
    bonds = fresh(atoms)
    assert bonds.whole and len(bonds) > 10
    before = bonds.of_bonds("r0")
    assert before is bonds.state["r0"] and not before.flags.writeable
    kept = before.copy()
    child = bonds.without(np.zeros(len(bonds), dtype=bool))  # shares the state
    new_b = np.arange(1.0, len(bonds) + 1.0)
    bonds.set_bonds("r0", new_b, new_b > 5)
    np.testing.assert_array_equal(before, kept)
    assert bonds.state["r0"] is not before and child.state["r0"] is bonds.state["r0"]
    expected = np.where(new_b > 5, new_b, kept)
    np.testing.assert_array_equal(bonds.of_bonds("r0"), expected)
    np.testing.assert_array_equal(child.state["r0"], expected)
    pieces = list(bonds.pieces(4))  # not whole: copies
    assert all(piece.of_bonds("r0") is not bonds.state["r0"] for piece in pieces)
    np.testing.assert_array_equal(np.concatenate([p.of_bonds("r0") for p in pieces]), expected)


def test_whole_state_set_takes_the_new_array_over():
    """Setting every bond's state of a whole set whose state was handed out
    takes a fresh array of the state's shape over as the state, read-only
    (no copy: the history a kernel wrote); the array handed out keeps its
    values, and every set sharing the state sees the new one.  A view, or
    an array of another type, is copied."""
    atoms = flying_cluster()
    bonds = fresh(atoms)
    before = bonds.of_bonds("r0")
    kept = before.copy()
    child = bonds.without(np.zeros(len(bonds), dtype=bool))
    new_b = np.arange(1.0, len(bonds) + 1.0)
    bonds.set_bonds("r0", new_b)
    assert bonds.state["r0"] is new_b and child.state["r0"] is new_b
    assert not new_b.flags.writeable
    np.testing.assert_array_equal(before, kept)
    with pytest.raises(ValueError, match="read-only"):
        new_b[0] = 0.0
    bonds.of_bonds("r0")
    wider = np.arange(2.0, 2 * len(bonds) + 2.0)
    bonds.set_bonds("r0", wider[::2])  # a view: copied
    assert bonds.state["r0"] is not new_b and bonds.state["r0"].base is None
    np.testing.assert_array_equal(bonds.of_bonds("r0"), wider[::2])
    np.testing.assert_array_equal(new_b, np.arange(1.0, len(bonds) + 1.0))
