"""The sums of a step outside the kernels (the energy ledger's work, the
guard's kinetic energy and finite checks): C where the compiled route runs,
NumPy's otherwise (``ase_bpm.laws.compiled.dot_sum``, ``all_finite``).

The C sums take C-contiguous float64 arrays; anything else goes to NumPy's
versions, so every input gives NumPy's answer (the dot product to
round-off: C keeps four running sums).
"""

import math
import os

import numpy as np
import pytest

from ase_bpm.core import arrays
from ase_bpm.laws import KERNELS_VARIABLE, compiled


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


def test_dot_sum_is_numpys_to_round_off():
    rng = np.random.default_rng(1)
    for a, b in inputs(rng):
        expected = arrays.dot_sum(a, b)
        got = compiled.dot_sum(a, b)
        assert isinstance(got, float)
        assert abs(got - expected) <= 1e-13 * float(np.abs(a * b).sum()) + 1e-300


@pytest.mark.parametrize("bad", [np.inf, -np.inf, np.nan])
@pytest.mark.parametrize("where", [0, 5, 110])  # in the fours, and in the remainder
def test_all_finite_finds_any_non_finite_value(bad, where):
    values = np.random.default_rng(2).normal(size=(37, 3))
    assert compiled.all_finite(values) is True
    values.reshape(-1)[where] = bad
    assert compiled.all_finite(values) is False
    assert compiled.first_non_finite(values) == where // 3
    assert compiled.all_finite(values[:, :2]) is arrays.all_finite(values[:, :2])
    assert not math.isfinite(compiled.dot_sum(values, np.ones_like(values)))


def test_huge_finite_values_are_finite():
    # (x * 0 is 0 for the largest doubles too: no overflow to inf)
    values = np.full(9, np.finfo(float).max)
    values[::2] *= -1
    assert compiled.all_finite(values) is True
    assert compiled.first_non_finite(values) is None


def test_the_route_decides():
    native = (compiled.available and not compiled.stale
              and os.environ.get(KERNELS_VARIABLE, "auto") != "numpy")
    assert compiled.NATIVE_SUMS is native
    assert (compiled.dot_sum is arrays.dot_sum) is (not native)
    assert (compiled.all_finite is arrays.all_finite) is (not native)
