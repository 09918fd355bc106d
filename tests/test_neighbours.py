"""The Verlet list: complete between rebuilds, rebuilt exactly when needed."""

import numpy as np
from ase import Atoms
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_bpm.core.neighbours import SphereVerletList, VerletList, minimum_image, neighbour_pairs


def all_pairs_within(positions, cell, pbc, cutoff):
    """Brute force over a 3x3x3 block of images (cells much larger than cutoff)."""
    found = set()
    shifts = [np.array(s) for s in np.ndindex(3, 3, 3)]
    for s in shifts:
        s = (s - 1) * np.asarray(pbc, dtype=int)
        if not any(pbc) and s.any():
            continue
        d = positions[None, :, :] + s @ cell - positions[:, None, :]
        r = np.linalg.norm(d, axis=2)
        for i, j in zip(*np.nonzero(r < cutoff)):
            if i != j or s.any():
                found.add((min(i, j), max(i, j)))
    return found


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), pbc=st.booleans())
def test_list_stays_complete_until_it_rebuilds(seed, pbc):
    rng = np.random.default_rng(seed)
    cell = np.diag([6.0, 7.0, 8.0])
    x = rng.uniform(0, 6, (60, 3))
    nl = VerletList(cutoff=1.5, skin=0.4)
    assert nl.update(x, cell, [pbc] * 3)
    for _ in range(8):
        step = rng.normal(0, 0.05, x.shape)
        x = x + step
        rebuilt = nl.update(x, cell, [pbc] * 3)
        listed = {(min(i, j), max(i, j)) for i, j, in zip(nl.i_p, nl.j_p)}
        r_pc = nl.pair_vectors(x)
        close = np.linalg.norm(r_pc, axis=1) < 1.5
        assert all_pairs_within(x, cell, [pbc] * 3, 1.5) <= listed
        assert {(min(i, j), max(i, j)) for i, j in zip(nl.i_p[close], nl.j_p[close])} == \
            all_pairs_within(x, cell, [pbc] * 3, 1.5)
        if not rebuilt:
            moved = np.linalg.norm(x - nl._x_build, axis=1).max()
            assert moved <= 0.2


def test_rebuild_exactly_at_half_the_skin():
    x = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    nl = VerletList(cutoff=1.5, skin=0.4)
    nl.update(x, np.eye(3), [False] * 3)
    x[0, 0] = 0.2 - 1e-12
    assert not nl.update(x, np.eye(3), [False] * 3)
    x[0, 0] = 0.2 + 1e-12
    assert nl.update(x, np.eye(3), [False] * 3)
    assert nl.nbuilds == 2


def touching(x, cell, pbc, r_n):
    """Pairs of spheres closer than the sum of their radii (brute force)."""
    found = set()
    for i, j in all_pairs_within(x, cell, pbc, 2.0 * r_n.max()):
        d = x[j] - x[i]
        if any(pbc):
            d = minimum_image(d[None], cell, pbc)[0]
        if np.linalg.norm(d) < r_n[i] + r_n[j]:
            found.add((i, j))
    return found


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), pbc=st.booleans(), drift=st.floats(0.0, 0.5))
def test_sphere_list_keeps_every_touching_pair_while_spheres_drift(seed, pbc, drift):
    """Spheres jostling while the whole heap drifts (``drift`` per step, many
    skins in all): every touching pair is listed at every step, and the list
    is rebuilt only when the spheres moved away from their common drift by
    more than half the skin."""
    rng = np.random.default_rng(seed)
    cell = np.diag([7.0, 8.0, 9.0])
    x = rng.uniform(0, 7, (60, 3))
    r_n = rng.uniform(0.4, 0.7, 60)
    nl = SphereVerletList(skin=0.3)
    nl.update(x, cell, [pbc] * 3, r_n)
    for _ in range(10):
        x = x + rng.normal(0, 0.03, x.shape) + np.array([0.0, 0.0, -drift])
        rebuilt = nl.update(x, cell, [pbc] * 3, r_n)
        r_pc = nl.pair_vectors(x)
        close = np.linalg.norm(r_pc, axis=1) < r_n[nl.i_p] + r_n[nl.j_p]
        assert set(zip(nl.i_p[close].tolist(), nl.j_p[close].tolist())) == \
            touching(x, cell, [pbc] * 3, r_n)
        if not rebuilt:  # measured from the build, carried along with the drift
            assert np.linalg.norm(x - nl._x_build, axis=1).max() <= 0.15


def test_sphere_list_rebuilds_for_relative_motion_not_for_a_shared_drift():
    x = np.array([[0.0, 0, 0], [1.2, 0, 0], [2.4, 0, 0], [3.6, 0, 0]])
    r_n = np.full(4, 0.5)
    nl = SphereVerletList(skin=0.4)
    nl.update(x, np.eye(3), [False] * 3, r_n)
    y = x + [0.0, 0.0, -5.0]
    assert not nl.update(y, np.eye(3), [False] * 3, r_n)  # all fell together
    y[1, 0] += 0.8 / 3 - 1e-9  # one sphere moves against the others: 3/4 of it off the mean
    assert not nl.update(y, np.eye(3), [False] * 3, r_n)
    y[1, 0] += 2e-9  # now 3/4 of it is beyond half the skin
    assert nl.update(y, np.eye(3), [False] * 3, r_n)
    assert nl.nbuilds == 2


def test_wrapping_atoms_triggers_a_rebuild_and_keeps_pairs_right():
    atoms = Atoms("H2", positions=[[0.1, 1, 1], [-0.5, 1, 1]], cell=[5, 5, 5], pbc=True)
    nl = VerletList(cutoff=1.0, skin=0.2)
    nl.update(atoms.positions, atoms.cell, atoms.pbc)
    d_before = nl.pair_vectors(atoms.positions)
    atoms.wrap()
    assert nl.update(atoms.positions, atoms.cell, atoms.pbc)
    assert np.allclose(np.abs(nl.pair_vectors(atoms.positions)), np.abs(d_before))


def test_clusters_without_a_cell_and_far_from_the_origin():
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 30, (3000, 3)) + 1e4
    i, j, shift = neighbour_pairs(x, np.zeros((3, 3)), [False] * 3, 1.0)
    d = np.linalg.norm(x[j] - x[i], axis=1)
    assert (i < j).all() and (d < 1.0).all() and not shift.any()
    i2, j2, _ = neighbour_pairs(x - 1e4, np.zeros((3, 3)), [False] * 3, 1.0)
    assert set(zip(i, j)) == set(zip(i2, j2))


def test_minimum_image_in_a_triclinic_cell():
    cell = np.array([[4.0, 0, 0], [1.5, 4.0, 0], [0.5, -0.7, 5.0]])
    rng = np.random.default_rng(2)
    r = rng.uniform(-1, 1, (50, 3))
    shifted = r + rng.integers(-2, 3, (50, 3)) @ cell
    assert np.allclose(minimum_image(shifted, cell, [True] * 3), r)


def test_an_open_list_keeps_no_shifts_and_its_vectors_stay():
    """Built with no periodic direction, a Verlet list keeps no image shifts
    (None, not zeros: 24 bytes a pair); its pair vectors are the ones a list
    with zero shifts gives, bit for bit.  Periodic along one axis, it keeps
    them."""
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 6, (400, 3))
    nl = VerletList(cutoff=1.0, skin=0.2)
    nl.update(x, np.eye(3) * 6, np.array([False] * 3))
    assert nl.shift_pc is None and len(nl.i_p) > 400
    i, j, shift = neighbour_pairs(x, np.eye(3) * 6, [False] * 3, 1.2)
    order = np.lexsort((j, i))
    assert np.array_equal(nl.i_p, i[order]) and np.array_equal(nl.j_p, j[order])
    assert not shift.any()
    with_zeros = x[nl.j_p] - x[nl.i_p] + shift[order]
    assert np.array_equal(nl.pair_vectors(x), with_zeros)
    assert np.array_equal(nl.pair_vectors(x, [3, 1]), with_zeros[[3, 1]])
    periodic = VerletList(cutoff=1.0, skin=0.2)
    periodic.update(x, np.eye(3) * 6, np.array([True, False, False]))
    assert periodic.shift_pc is not None and periodic.shift_pc[:, 0].any()
