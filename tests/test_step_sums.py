"""The sums of a step outside the kernels (the energy ledger's work, the
guard's kinetic energy and finite checks, the Verlet skin check, the
integrators' kicks, drifts and turns): C twins
(``ase_bpm.core.arrays.NATIVE``, installed by ``ase_bpm.laws.compiled``)
where the compiled route runs, NumPy's otherwise.

The C twins take C-contiguous float64 arrays; anything else goes NumPy's
way, so every input gives NumPy's answer (the dot product to round-off: C
keeps four running sums).  Each test runs with the twins of this route and
again without any.
"""

import math
import os

import numpy as np
import pytest

from ase_bpm.core import arrays
from ase_bpm.core.neighbours import SphereVerletList, VerletList, largest_square
from ase_bpm.laws import KERNELS_VARIABLE, compiled
from ase_bpm.models import ledger


@pytest.fixture(params=["this route", "numpy"])
def twins(request, monkeypatch):
    """The route's C twins, or none (NumPy's way throughout)."""
    if request.param == "numpy":
        monkeypatch.setattr(arrays, "NATIVE", {})
        import ase_bpm.core.neighbours as neighbours
        monkeypatch.setattr(neighbours, "NATIVE", arrays.NATIVE)
        monkeypatch.setattr(ledger, "NATIVE", arrays.NATIVE)
    return request.param


def numpy_dot(a, b) -> float:
    return float(np.einsum("i,i->", np.ravel(a), np.ravel(b)))


def inputs(rng):
    """Arrays of several layouts, sizes and types, with their partners."""
    a = rng.normal(size=(37, 3))
    b = rng.normal(size=(37, 3))
    yield a, b  # C-contiguous doubles
    yield a[:, :2], b[:, :2]  # strided: NumPy's way
    yield a.T, b.T  # Fortran order
    yield a.astype(np.float32), b.astype(np.float32)  # another type
    yield np.zeros((0, 3)), np.zeros((0, 3))  # empty
    yield a[:1, :1].copy(), b[:1, :1].copy()  # one element, below the four running sums
    yield rng.normal(size=100003), rng.normal(size=100003)  # a remainder after the fours


def test_dot_sum_is_numpys_to_round_off(twins):
    rng = np.random.default_rng(1)
    for a, b in inputs(rng):
        got = arrays.dot_sum(a, b)
        assert isinstance(got, float)
        assert abs(got - numpy_dot(a, b)) <= 1e-13 * float(np.abs(a * b).sum()) + 1e-300


def test_the_ledgers_damping_work_is_its_dot_sums_bit_for_bit(twins):
    """The work the ledger books, -(f . dx + f_last . dx) / 2, is the same
    number as from dot_sum over the displacements, at every layout and size,
    with either force missing and with the displacements given (x_last None)."""
    rng = np.random.default_rng(6)
    for f, x in inputs(rng):
        f_last, x_last = 0.5 * f + 1.0, x + 1e-3 * rng.normal(size=x.shape).astype(x.dtype)
        dx = x - x_last
        for ff, fl in ((f, f_last), (None, f_last), (f, None), (None, None)):
            expected = 0.0 - 0.5 * ((0.0 if ff is None else arrays.dot_sum(ff, dx))
                                    + (0.0 if fl is None else arrays.dot_sum(fl, dx)))
            got = ledger.damping_work(ff, fl, x, x_last)
            assert isinstance(got, float) and got == expected
            assert ledger.damping_work(ff, fl, dx, None) == expected


@pytest.mark.compiled
def test_damping_work_twin_takes_only_what_it_can():
    from ase_bpm.laws import _kernels  # (the twin itself, whatever the route)

    twin = _kernels.damping_work
    f, x = np.ones((4, 3)), np.arange(12.0).reshape(4, 3)
    assert twin(f, None, x, None) == -0.5 * 66.0
    assert twin(f, f, x, x) == 0.0
    assert twin(f[:3], None, x, None) is NotImplemented  # sizes differ
    assert twin(f, None, x, x[:3]) is NotImplemented
    assert twin(f, None, x[:, :2], None) is NotImplemented  # strided
    assert twin(f, None, None, None) is NotImplemented  # no positions
    with pytest.raises(TypeError, match="damping_work takes f, f_last, x, x0"):
        twin(f, None, x)


@pytest.mark.parametrize("bad", [np.inf, -np.inf, np.nan])
@pytest.mark.parametrize("where", [0, 5, 110])  # in the fours, and in the remainder
def test_all_finite_finds_any_non_finite_value(twins, bad, where):
    values = np.random.default_rng(2).normal(size=(37, 3))
    assert arrays.all_finite(values) is True
    values.reshape(-1)[where] = bad
    assert arrays.all_finite(values) is False
    assert arrays.first_non_finite(values) == where // 3
    assert arrays.all_finite(values[:, :2]) is bool(np.isfinite(values[:, :2]).all())
    assert not math.isfinite(arrays.dot_sum(values, np.ones_like(values)))
    # several arrays (None: none) at once, as the guard checks forces and torques
    fine = np.ones((4, 3))
    assert arrays.all_finite(fine, None, fine[:, ::2]) is True
    assert arrays.all_finite(fine, None, values) is False
    assert arrays.all_finite(values, fine) is False


def test_huge_finite_values_are_finite(twins):
    # (x * 0 is 0 for the largest doubles too: no overflow to inf)
    values = np.full(9, np.finfo(float).max)
    values[::2] *= -1
    assert arrays.all_finite(values) is True
    assert arrays.first_non_finite(values) is None


@pytest.mark.parametrize("kind", ["atoms", "spheres"])
def test_the_skin_check_decides_as_numpy_at_the_threshold(twins, kind):
    """A list is rebuilt exactly when some atom has moved more than half the
    skin (spheres: two of them, the other way, together more than the skin),
    on either route, at displacements a hair below and above it."""
    rng = np.random.default_rng(3)
    x_nc = rng.uniform(0, 10, size=(50, 3))
    cell, pbc = np.eye(3) * 12, np.zeros(3, dtype=bool)
    for scale in (1 - 1e-12, 1 + 1e-12):
        for along in (np.array([1.0, 0, 0]), np.array([0.6, 0.0, 0.8]),
                      np.array([1.0, 1.0, 1.0]) / np.sqrt(3)):
            if kind == "atoms":
                nl = VerletList(1.0, 0.4)
                nl.update(x_nc, cell, pbc)
            else:
                nl = SphereVerletList(0.4)
                nl.update(x_nc, cell, pbc, np.full(50, 0.5))
            moved = x_nc.copy()
            moved[7] += scale * 0.2 * along  # half the skin, along a direction
            if kind == "spheres":  # (relative motion: a second sphere the other way)
                moved[8] -= scale * 0.2 * along
            d = moved - nl._x_build
            expected = largest_square(d.copy()) > 0.2 ** 2
            if kind == "spheres":  # and the two largest from the mean drift beyond the skin
                d -= d.mean(axis=0)
                first, second = np.sort(np.sqrt(np.einsum("nc,nc->n", d, d)))[-2:][::-1]
                expected = expected and bool(first + second > 0.4)
            assert nl.needs_rebuild(moved, cell, pbc) is expected


@pytest.mark.compiled
def test_largest_displacement_twin_takes_only_what_it_can():
    from ase_bpm.laws import _kernels  # (the twin itself, whatever the route)

    twin = _kernels.largest_displacement_squared
    x = np.random.default_rng(4).normal(size=(11, 3))
    x0 = np.zeros((11, 3))
    assert twin(x, x0, None) == largest_square(x.copy())
    assert twin(x, x0, np.array([0.5, 0.0, -1.0])) == largest_square(
        x - np.array([0.5, 0.0, -1.0]))
    assert twin(x[:, :2], x0[:, :2], None) is NotImplemented
    assert twin(x, x0[:10], None) is NotImplemented
    assert twin(x.astype(np.float32), x0, None) is NotImplemented
    x[3, 1] = np.nan
    assert math.isnan(twin(x, x0, None))


def test_the_route_decides():
    native = (compiled.available and not compiled.stale
              and os.environ.get(KERNELS_VARIABLE, "auto") != "numpy")
    assert compiled.NATIVE_SUMS is native
    expected = ({"dot_sum", "damping_work", "all_finite", "same_bytes",
                 "largest_displacement_squared", "add_to", "any_nonzero", "put_rows",
                 "pairs_in_order", "members"}
                if native else set())
    assert set(arrays.NATIVE) == expected


def test_same_array_compares_bytes(twins):
    """Arrays are the same when shape, type and every byte agree (so NaN
    equals NaN, and 0.0 differs from -0.0), at every size and layout."""
    rng = np.random.default_rng(5)
    for n in (1, 500, 20000):  # below and above SMALL_BYTES
        a = rng.normal(size=(n, 3))
        a[0, 0] = np.nan
        b = a.copy()
        assert arrays.same_array(a, b)
        b[-1, 2] = np.nextafter(b[-1, 2], np.inf)  # the last bit of the last element
        assert not arrays.same_array(a, b)
        assert not arrays.same_array(a, a.reshape(3, n))  # shape
        assert not arrays.same_array(a, a.astype(np.float32))  # type
        assert arrays.same_array(a[:, :2], a[:, :2].copy())  # strided: NumPy's way
        z = np.zeros((n, 3))
        assert not arrays.same_array(z, -z)
    assert arrays.same_array(np.zeros((0, 3)), np.zeros((0, 3)))
    assert arrays.same_array(None, None) and not arrays.same_array(None, np.zeros(1))


@pytest.mark.parametrize("how", ["plain", "times", "divided"])
def test_add_to_is_numpys_arithmetic_bit_for_bit(twins, how):
    """The integrators' ``a += s * b`` (times or divided by ``c``) in place:
    the same bits as NumPy's expression, for every layout and type (what the
    twin does not take goes NumPy's way); the inputs are left as they were."""
    rng = np.random.default_rng(6)
    s = 0.5 * 1.7e-3
    for a, b in inputs(rng):
        c = None if how == "plain" else np.abs(b) + 0.5
        expected = a.copy()
        if c is None:
            expected += s * b
        elif how == "divided":
            expected += s * b / c
        else:
            expected += s * b * c
        got, b_before, c_before = a.copy(), b.copy(), None if c is None else c.copy()
        arrays.add_to(got, s, b, c, divide=how == "divided")
        assert np.array_equal(got, expected) and got.dtype == a.dtype
        assert np.array_equal(b, b_before)
        assert c is None or np.array_equal(c, c_before)
    # b overlapping a, shifted by one element: NumPy's expression, evaluated
    # into a temporary first, decides
    x, reference = np.arange(1.0, 8.0), np.arange(1.0, 8.0)
    c = None if how == "plain" else np.arange(2.0, 8.0)
    if c is None:
        reference[1:] += s * reference[:-1]
    elif how == "divided":
        reference[1:] += s * reference[:-1] / c
    else:
        reference[1:] += s * reference[:-1] * c
    arrays.add_to(x[1:], s, x[:-1], c, divide=how == "divided")
    assert np.array_equal(x, reference)


@pytest.mark.compiled
def test_add_to_changes_nothing_it_cannot_take():
    """The twin itself: arrays of other shapes (which NumPy broadcasts or
    refuses), types or layouts, or a read-only target, are left to NumPy
    (NotImplemented), unchanged."""
    from ase_bpm.laws import _kernels

    a, b = np.ones((5, 3)), np.full((5, 3), 2.0)
    for args in ((a, 1.0, b[:4], None, False), (a, 1.0, b, b[:, :2], False),
                 (a, 1.0, b.reshape(-1), None, False), (a, 1.0, b, b.reshape(3, 5), True),
                 (a, 1.0, b.astype(np.float32), None, False), (a.T, 1.0, b.T, None, False),
                 (a, "one", b, None, False)):
        assert _kernels.add_to(*args) is NotImplemented
        assert np.array_equal(a, np.ones((5, 3)))
    frozen = a.copy()
    frozen.flags.writeable = False
    assert _kernels.add_to(frozen, 1.0, b, None, False) is NotImplemented
    assert _kernels.add_to(a, 1.0, b, None, False) is None and (a == 3.0).all()


@pytest.mark.parametrize("where", [None, 0, 7, 110])
def test_any_nonzero_finds_a_value_anywhere(twins, where):
    values = np.zeros((37, 3))
    if where is not None:
        values.reshape(-1)[where % values.size] = -1e-300
    assert arrays.any_nonzero(values) is (where is not None)
    values.reshape(-1)[5] = np.nan  # NaN is not zero
    assert arrays.any_nonzero(values) is True
    assert arrays.any_nonzero(np.zeros((0, 3))) is False
    assert arrays.any_nonzero(np.ones((4, 3))[:, :2]) is True  # strided: NumPy's way


def put_rows_cases(rng):
    """(dst, src, at_b, slot_b, rows): per-bond rows put into atom slots of
    several widths (with and without slots), index types, row selections
    (all, some by index, some by mask, one twice) and repeated targets."""
    natoms, nslots, nb = 9, 5, 23
    at_b, slot_b = rng.integers(0, natoms, nb), rng.integers(0, nslots, nb)
    for width in ((), (1,), (4,)):
        for kind in (np.int64, np.int32):
            for rows in (None, rng.permutation(nb)[:11], rng.random(nb) < 0.5,
                         np.array([3, 3, 7])):
                yield (rng.normal(size=(natoms, nslots) + width), rng.normal(size=(nb,) + width),
                       at_b.astype(kind), slot_b.astype(kind), rows)
                yield (rng.normal(size=(nb + 4,) + width), rng.normal(size=(nb,) + width),
                       rng.permutation(nb + 4)[:nb].astype(kind), None, rows)


def test_put_rows_is_numpys_assignment(twins):
    """Per-bond state put back in place: the values of NumPy's fancy
    assignment (the last of repeated targets wins), the source untouched."""
    rng = np.random.default_rng(8)
    for dst, src, at_b, slot_b, rows in put_rows_cases(rng):
        expected = dst.copy()
        pick = slice(None) if rows is None else rows
        where = at_b[pick] if slot_b is None else (at_b[pick], slot_b[pick])
        expected[where] = src[pick]
        src_before = src.copy()
        arrays.put_rows(dst, src, at_b, slot_b, rows)
        assert np.array_equal(dst, expected)
        assert np.array_equal(src, src_before)


def test_put_rows_refuses_what_numpy_refuses(twins):
    """An index beyond the target fails with NumPy's IndexError on either
    route; the C twin leaves such a call to NumPy and writes nothing."""
    dst, src = np.zeros((4, 3, 2)), np.ones((5, 2))
    at_b, slot_b = np.array([0, 1, 2, 3, 4]), np.zeros(5, np.int64)
    with pytest.raises(IndexError, match="out of bounds"):
        arrays.put_rows(dst, src, at_b, slot_b)
    with pytest.raises(IndexError, match="out of bounds"):
        arrays.put_rows(dst, src, np.zeros(5, np.int64), np.full(5, 3))
    if twins == "this route" and "put_rows" in arrays.NATIVE:
        assert arrays.NATIVE["put_rows"](dst, src, at_b, slot_b, None) is NotImplemented
        assert not dst.any()
        # rows beyond the source, a target of other widths, a read-only target
        assert arrays.NATIVE["put_rows"](dst, src, at_b[:4], slot_b[:4], np.array([4])) \
            is NotImplemented
        assert arrays.NATIVE["put_rows"](np.zeros((4, 3, 3)), src, at_b[:4], slot_b[:4],
                                         None) is NotImplemented
        frozen = np.zeros((4, 3, 2))
        frozen.flags.writeable = False
        assert arrays.NATIVE["put_rows"](frozen, src[:4], at_b[:4], slot_b[:4], None) \
            is NotImplemented
        assert not dst.any()


def test_atom_list_update_decides_as_needs_rebuild(twins):
    """A Verlet list's update, which runs needs_rebuild's checks itself in
    one call, rebuilds exactly where needs_rebuild (asked of a copy) says:
    within half the skin and just beyond it, a new cell, periodicity, atom
    count; on either route."""
    import copy

    rng = np.random.default_rng(7)
    x = rng.uniform(0, 6, size=(40, 3))
    cell, pbc = np.eye(3) * 8, np.zeros(3, dtype=bool)
    nl = VerletList(1.0, 0.4)
    nl.update(x, cell, pbc)
    one_moves = [x.copy() for _ in range(2)]
    one_moves[0][5] += [0.0, 0.19, 0.0]  # (within half the skin)
    one_moves[1][5] += [0.0, 0.21, 0.0]  # (beyond it)
    paths = [x, *one_moves, (x, cell * 1.01, pbc), (x, cell, np.ones(3, dtype=bool)), x[:39]]
    verdicts = []
    for path in paths:
        y, c, p = path if isinstance(path, tuple) else (path, cell, pbc)
        expected = copy.deepcopy(nl).needs_rebuild(y, c, p)
        builds = nl.nbuilds
        assert nl.update(y, c, p) is expected
        assert nl.nbuilds == builds + expected
        verdicts.append(expected)
    assert verdicts == [False, False, True, True, True, True]


def test_sphere_list_update_decides_as_needs_rebuild(twins):
    """A sphere list's update, which checks everything in one call, rebuilds
    exactly where needs_rebuild (asked of a copy) says: a shared drift, one
    sphere running off, a new cell, periodicity, atom count; and for new
    radii, on either route.  Where it does not rebuild, it carries the
    build's positions along the drift as needs_rebuild does."""
    import copy

    rng = np.random.default_rng(5)
    x = rng.uniform(0, 6, size=(40, 3))
    cell, pbc = np.eye(3) * 8, np.zeros(3, dtype=bool)
    r_n = np.full(40, 0.3)
    nl = SphereVerletList(0.4)
    nl.update(x, cell, pbc, r_n)
    runs_off = x.copy()
    runs_off[3] += [0.45, 0.0, 0.0]  # (beyond the skin from the rest)
    paths = [x + [0.0, 0.0, -0.3], x + [0.0, 0.0, -0.6], runs_off, runs_off + 0.1,
             (x, cell * 1.01, pbc), (x, cell, np.ones(3, dtype=bool)), x[:39]]
    verdicts = []
    for path in paths:
        y, c, p = path if isinstance(path, tuple) else (path, cell, pbc)
        r_n = r_n[:len(y)]
        probe = copy.deepcopy(nl)
        expected = probe.needs_rebuild(y, c, p)
        assert nl.update(y, c, p, r_n) is expected
        if not expected:
            assert np.array_equal(nl._x_build, probe._x_build)
        verdicts.append(expected)
    assert verdicts == [False, False, True, False, True, True, True]
    # the same radii given again do not rebuild; new ones do, given in place or anew
    assert not nl.update(y, c, p, r_n)
    r_n[0] = 0.35
    assert nl.update(y, c, p, r_n)
    fixed = np.full(len(y), 0.3)
    fixed.flags.writeable = False
    assert nl.update(y, c, p, fixed)
    assert not nl.update(y, c, p, fixed)
