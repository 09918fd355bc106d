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
            moved = np.sort(np.linalg.norm(x - nl._x_build, axis=1))
            assert moved[-1] + moved[-2] <= 0.3


def test_sphere_list_rebuilds_for_relative_motion_not_for_a_shared_drift():
    x = np.array([[0.0, 0, 0], [1.2, 0, 0], [2.4, 0, 0], [3.6, 0, 0]])
    r_n = np.full(4, 0.5)
    nl = SphereVerletList(skin=0.4)
    nl.update(x, np.eye(3), [False] * 3, r_n)
    y = x + [0.0, 0.0, -5.0]
    assert not nl.update(y, np.eye(3), [False] * 3, r_n)  # all fell together
    # one sphere moves against the others: 3/4 of it off the mean, 1/4 the
    # others', the two largest together all of it
    y[1, 0] += 0.4 - 1e-9
    assert not nl.update(y, np.eye(3), [False] * 3, r_n)
    y[1, 0] += 2e-9  # now the two together are beyond the skin
    assert nl.update(y, np.eye(3), [False] * 3, r_n)
    assert nl.nbuilds == 2


def touching_now(x, cell, pbc, r_n):
    """:func:`touching`, vectorised: pairs ``i < j`` closer than ``r_i + r_j``
    through some image (the cells here are wider than twice the contact)."""
    images = [np.array(s) - 1 for s in np.ndindex(3, 3, 3)] if any(pbc) else [np.zeros(3)]
    found = np.zeros((len(x), len(x)), dtype=bool)
    for s in images:
        d_nnc = x[None, :, :] + (s * np.asarray(pbc)) @ cell - x[:, None, :]
        found |= np.einsum("ijc,ijc->ij", d_nnc, d_nnc) < (r_n[:, None] + r_n[None, :]) ** 2
    i, j = np.nonzero(np.triu(found, 1))
    return set(zip(i.tolist(), j.tolist()))


def lammps_rebuilds(x_t, skin):
    """How often LAMMPS' test (some atom more than half the skin from where
    it was at the last build) rebuilds along the positions ``x_t``."""
    builds, x_build = 1, x_t[0]
    for x in x_t[1:]:
        if np.linalg.norm(x - x_build, axis=1).max() > 0.5 * skin:
            builds, x_build = builds + 1, x
    return builds


def test_two_spheres_closing_head_on_are_listed_when_they_touch():
    """The edge of the rule: two spheres start just beyond the list's reach
    (a gap of the skin and a hair) and close on each other at the same
    speed, the other spheres at rest: the list is rebuilt at the step where
    together they have moved more than the skin, before they touch, not at
    the step where each has moved half of it (LAMMPS), nor later."""
    r_n = np.full(6, 0.5)
    skin, step = 0.4, 0.01
    x = np.array([[0.0, 0, 0], [1.0 + skin + 1e-9, 0, 0],
                  [0, 4, 0], [4, 4, 0], [0, 0, 4], [4, 0, 4]])
    nl = SphereVerletList(skin=skin)
    nl.update(x, np.eye(3) * 8, [False] * 3, r_n)
    assert len(nl.i_p) == 0
    rebuilt_at = []
    for k in range(1, 30):
        y = x.copy()
        y[0, 0] += k * step
        y[1, 0] -= k * step
        if nl.update(y, np.eye(3) * 8, [False] * 3, r_n):
            rebuilt_at.append(k)
        gap = y[1, 0] - y[0, 0] - 1.0
        if gap < 0:
            assert (0, 1) in set(zip(nl.i_p.tolist(), nl.j_p.tolist()))
    # each moved k * step from the mean (zero): together 2 k step > skin first at k = 21
    # (LAMMPS: k step > skin / 2, the same step here: the two move alike)
    assert rebuilt_at == [21]


def run_fast_spheres(seed: int, pbc: bool, fast: int = 1, steps: int = 40):
    """A crowded box of jostling spheres through which ``fast`` of them run
    ten times as fast, in random directions: at every step each touching
    pair must be listed (asserted).  Returns the list's builds and the
    builds LAMMPS' rule would have made on the same path."""
    rng = np.random.default_rng(seed)
    cell = np.diag([7.0, 8.0, 9.0])
    x = rng.uniform(0, 7, (120, 3))
    r_n = rng.uniform(0.3, 0.5, 120)
    v_nc = rng.normal(0, 0.004, x.shape)
    v_nc[rng.choice(120, fast, replace=False)] *= 10.0
    nl = SphereVerletList(skin=0.25)
    nl.update(x, cell, [pbc] * 3, r_n)
    x_t = [x]
    for _ in range(steps):
        x = x + v_nc + rng.normal(0, 0.002, x.shape)
        nl.update(x, cell, [pbc] * 3, r_n)
        x_t.append(x)
        r_pc = nl.pair_vectors(x)
        close = np.linalg.norm(r_pc, axis=1) < r_n[nl.i_p] + r_n[nl.j_p]
        assert set(zip(nl.i_p[close].tolist(), nl.j_p[close].tolist())) == \
            touching_now(x, cell, [pbc] * 3, r_n)
    return nl.nbuilds, lammps_rebuilds(x_t, 0.25)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000), pbc=st.booleans(), fast=st.integers(1, 4))
def test_fast_spheres_among_slow_ones_are_never_missed(seed, pbc, fast):
    run_fast_spheres(seed, pbc, fast)


def test_one_fast_sphere_costs_fewer_rebuilds_than_lammps_rule():
    """Where the rule gains on LAMMPS' (which rebuilds as soon as the
    fastest sphere has run half the skin): a rattler may run nearly the
    whole skin.  Fewer rebuilds in all, none of the runs with more."""
    ours, theirs = np.array([run_fast_spheres(seed, pbc) for seed in range(3)
                             for pbc in (False, True)]).T
    assert (ours <= theirs).all() and ours.sum() < 0.7 * theirs.sum()


def test_minimum_image_gives_short_vectors_back_as_they_are():
    """In an orthorhombic cell, vectors with no component beyond half the
    shortest periodic edge (a step's displacements) come back as given, no
    copy made; with one beyond it (or NaN), every vector is mapped per axis,
    as the rounding does, and the input is left alone."""
    cell = np.diag([4.0, 5.0, 6.0])
    pbc = np.array([True, True, False])

    def rounded(r_xc):
        out = r_xc.copy()
        for k in (0, 1):
            out[:, k] -= cell[k, k] * np.round(out[:, k] / cell[k, k])
        return out

    r_xc = np.random.default_rng(5).uniform(-2.0, 2.0, (100, 3))
    r_xc[0, 0] = 2.0  # half the shortest periodic edge: still its own image
    assert minimum_image(r_xc, cell, pbc) is r_xc
    assert np.array_equal(r_xc, rounded(r_xc))
    for row, column, value in [(5, 1, 2.6), (6, 2, 7.0), (7, 0, -2.01), (8, 0, np.nan)]:
        given = r_xc.copy()
        given[row, column] = value
        kept = given.copy()
        out = minimum_image(given, cell, pbc)
        assert out is not given and np.array_equal(given, kept, equal_nan=True)
        assert np.array_equal(out, rounded(given), equal_nan=True)
    assert minimum_image(np.zeros((0, 3)), cell, pbc).shape == (0, 3)


def test_a_list_says_whether_a_pair_can_touch_through_two_images():
    """``one_image``: in a periodic cell wider than twice the list's reach
    no pair is listed twice; in a narrower one, a pair listed through two
    images (or a sphere with its own image) is seen, and a list without
    such pairs says so too (checked on the pairs)."""
    r_n = np.full(2, 0.5)
    x = np.array([[0.5, 0.5, 0.5], [1.6, 0.5, 0.5]])
    for width, expected in [(10.0, True), (2.1, False), (2.4, True)]:
        nl = SphereVerletList(skin=0.2)
        nl.update(x, np.diag([width, 10.0, 10.0]), np.array([True, False, False]), r_n)
        keys = list(zip(nl.i_p.tolist(), nl.j_p.tolist()))
        twice = len(keys) != len(set(keys)) or any(i == j for i, j in keys)
        assert nl.one_image is expected is not twice
    alone = SphereVerletList(skin=0.2)  # a sphere near its own image
    alone.update(x[:1], np.diag([1.1, 10.0, 10.0]), np.array([True, False, False]), r_n[:1])
    assert (0, 0) in zip(alone.i_p.tolist(), alone.j_p.tolist()) and not alone.one_image


def scenes_to_put_in_order():
    """Positions, cell, periodicity and cutoff (one, or one reach per atom) of
    lists of every kind: open, periodic in all or some directions, a skewed
    cell, atoms near their own images and pairs listed through two images,
    an atom with more pairs than the C twin sorts (NumPy's way then), and a
    scene spread so thin that the k-d tree searches it."""
    rng = np.random.default_rng(31)
    skewed = np.diag([5.0, 5.5, 4.5]) + np.array([[0, 0, 0], [0.3, 0, 0], [0, 0, 0]])
    every, some, none = (True, True, True), (True, False, True), (False, False, False)
    yield rng.uniform(0, 6, (400, 3)), np.zeros((3, 3)), none, 1.3
    yield rng.uniform(0, 5, (500, 3)), skewed, every, 1.5
    yield rng.uniform(0, 5, (500, 3)), skewed, some, rng.uniform(0.3, 0.7, 500)
    yield rng.uniform(0, 2, (10, 3)), np.eye(3) * 2.0, every, 2.5  # own images, twice
    crowded = rng.uniform(0, 6, (600, 3))  # atom 0 reaches all the others
    yield crowded, np.zeros((3, 3)), none, np.r_[12.0, np.full(599, 0.4)]
    spread = rng.uniform(0, 1, (50, 3))
    spread[-1] = 1e4  # one far particle: the k-d tree
    yield spread, np.zeros((3, 3)), none, 0.3


def test_pairs_in_order_are_those_sorted_by_numpy(monkeypatch):
    """``neighbour_pairs(..., in_order=True)`` gives the very pairs and
    shifts of the unordered list in the order of ``in_pair_order`` (a stable
    sort by ``(i, j)``), with the C twin and without it."""
    from ase_bpm.core import arrays, neighbours
    from ase_bpm.core.neighbours import in_pair_order

    for x, cell, pbc, cutoff in scenes_to_put_in_order():
        unordered = neighbour_pairs(x, cell, pbc, cutoff, open_shifts=False)
        expected = in_pair_order(len(x), *unordered)
        for twins in (arrays.NATIVE, {}):
            monkeypatch.setattr(neighbours, "NATIVE", twins)
            got = neighbour_pairs(x, cell, pbc, cutoff, open_shifts=False, in_order=True)
            assert got[0].dtype == got[1].dtype == np.int64
            assert np.array_equal(got[0], expected[0]) and np.array_equal(got[1], expected[1])
            assert (got[2] is None) is (expected[2] is None) is (not any(pbc))
            assert got[2] is None or np.array_equal(got[2], expected[2])
            assert len(got[0]) == len(unordered[0]) > 0


def test_the_twin_that_puts_pairs_in_order_refuses_what_it_cannot_do():
    """The C twin answers NotImplemented (NumPy sorts then) for indices not
    in ascending order, more pairs than its outputs hold, outputs of another
    type or read-only, and inputs of other lengths or types."""
    from ase_bpm.core.arrays import NATIVE

    twin = NATIVE.get("pairs_in_order")
    if twin is None:
        return  # the NumPy route: no twin
    i_p = np.array([0, 0, 0, 1, 1, 2], dtype=np.int32)
    j_p = np.array([3, 1, 2, 2, 0, 1], dtype=np.int32)
    keep = i_p < j_p

    def outputs(count=4, dtype=np.int64):
        return np.empty(count, dtype), np.empty(count, dtype), np.empty(count, dtype)

    i_k, j_k, rows_k = outputs()
    assert twin(i_p, j_p, keep, i_k, j_k, rows_k) is None
    assert i_k.tolist() == [0, 0, 0, 1] and j_k.tolist() == [1, 2, 3, 2]
    assert rows_k.tolist() == [1, 2, 0, 3]  # their places among the kept pairs
    assert twin(i_p, j_p, keep, i_k, j_k, None) is None
    assert twin(i_p[::-1].copy(), j_p, keep, *outputs()) is NotImplemented
    assert twin(i_p, j_p, keep, *outputs(3)) is NotImplemented
    assert twin(i_p, j_p, keep, *outputs(5)) is NotImplemented
    assert twin(i_p, j_p, keep, *outputs(dtype=np.int32)) is NotImplemented
    frozen = outputs()
    frozen[1].flags.writeable = False
    assert twin(i_p, j_p, keep, *frozen) is NotImplemented
    assert twin(i_p, j_p[:5], keep, *outputs()) is NotImplemented
    assert twin(i_p.astype(float), j_p, keep, *outputs()) is NotImplemented
    assert twin(i_p, j_p, keep.astype(np.int64), *outputs()) is NotImplemented


def scenes_with_bonds():
    """Atoms with bonds, and the reach of a Verlet list over them: an open
    and a periodic FCC block bonded to the nearest neighbours within a list
    that also reaches the second ones, the periodic block with a third of
    its bonds broken (the set without them) and with a few broken (a set
    that keeps them listed with type 0), a block with no bonds, and one bonded to every
    listed pair."""
    from ase.build import bulk

    from ase_bpm import create_bonds
    from ase_bpm.core import bond_set
    from ase_bpm.models.bonded import BondState

    def block(pbc, bond_cutoff):
        atoms = bulk("Cu", "fcc", a=1.6, cubic=True).repeat((4, 4, 4))
        atoms.pbc = pbc
        atoms.rattle(0.02, seed=3)
        if bond_cutoff:
            create_bonds(atoms, bond_cutoff)
        return atoms, BondState().peek(atoms)

    reach = 1.8  # nearest neighbours at 1.13, second at 1.6
    yield "open", *block(False, 1.3), reach
    atoms, bonds = block(True, 1.3)
    yield "periodic", atoms, bonds, reach
    share_b = np.random.default_rng(7).uniform(size=len(bonds))
    yield "broken", atoms, bonds.without(share_b < 1 / 3), reach
    listed = bonds.without(share_b < bond_set.DEAD_SHARE / 2, lazy=True)
    assert listed.dead > 0  # the broken ones listed with type 0
    yield "broken, listed", atoms, listed, reach
    yield "none bonded", *block(True, 0.0), reach
    yield "all bonded", *block(True, reach + 0.5), reach


def test_the_bonded_pairs_of_a_new_list_are_those_numpy_finds(monkeypatch):
    """``BondSet.bonded`` of a new Verlet list's pair keys (ascending) picks
    the same pairs with the C twin ``members`` (a merge with the sorted
    bond keys) as with NumPy's binary search, and both are the pairs joined
    by an intact bond; keys in another order too."""
    from ase_bpm.core import bond_set
    from ase_bpm.core.arrays import NATIVE
    from ase_bpm.core.bond_set import pair_keys

    counted = set()
    for name, atoms, bonds, reach in scenes_with_bonds():
        nl = VerletList(reach, 0.2)
        nl.update(atoms.positions, atoms.cell, atoms.pbc)
        keys = pair_keys(nl.i_p, nl.j_p, len(atoms))
        assert np.all(np.diff(keys) >= 0), name  # a new list's keys ascend
        live = bonds.type_b > 0
        joined = set(pair_keys(bonds.i_b[live], bonds.j_b[live], len(atoms)).tolist())
        expected = np.array([k in joined for k in keys.tolist()], dtype=bool)
        shuffled = np.random.default_rng(1).permutation(len(keys))
        for twins in (NATIVE, {}):
            monkeypatch.setattr(bond_set, "NATIVE", twins)
            for order in (slice(None), slice(None, None, -1), shuffled):
                got = bonds.bonded(keys[order])
                assert got.dtype == bool and np.array_equal(got, expected[order]), name
        counted.add((name, int(expected.sum()), len(expected)))
    found = {name: (n, total) for name, n, total in counted}
    assert found["none bonded"][0] == 0 and found["all bonded"][0] == found["all bonded"][1]
    assert 0 < found["broken"][0] < found["broken, listed"][0] < found["periodic"][0]
    assert found["open"][0] < found["open"][1]


def test_the_twin_that_finds_bonded_pairs_refuses_what_it_cannot_do():
    """``members`` answers NotImplemented (NumPy searches then) for keys or
    a set that are not integers, flags of another length, type or read-only;
    and finds keys below and above the whole set, repeated keys and a set
    with repeats."""
    from ase_bpm.core.arrays import NATIVE

    twin = NATIVE.get("members")
    if twin is None:
        return  # the NumPy route: no twin
    bonded = np.array([3, 5, 5, 9, 40], dtype=np.int64)
    keys = np.array([0, 3, 3, 4, 5, 9, 9, 41, 40, 2, 5], dtype=np.int32)
    found = np.empty(len(keys), dtype=bool)
    assert twin(keys, bonded, found) is None
    assert found.tolist() == [k in bonded for k in keys.tolist()]
    assert twin(keys.astype(float), bonded, found) is NotImplemented
    assert twin(keys, bonded.astype(float), found) is NotImplemented
    assert twin(keys, bonded, found[:-1]) is NotImplemented
    assert twin(keys, bonded, found.astype(np.int64)) is NotImplemented
    found.flags.writeable = False
    assert twin(keys, bonded, found) is NotImplemented
