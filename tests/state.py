"""Snapshots of the state on atoms, to check that a failed call lost none."""

import numpy as np


def snapshot(atoms):
    """Copies of every per-atom array and ``info`` entry."""
    return ({k: v.copy() for k, v in atoms.arrays.items()},
            {k: np.copy(v) for k, v in atoms.info.items()})


def assert_unchanged(atoms, before):
    """Every array and ``info`` entry as in the snapshot ``before``."""
    arrays, info = before
    assert set(atoms.arrays) == set(arrays)
    for k, v in arrays.items():
        assert np.array_equal(atoms.arrays[k], v, equal_nan=v.dtype.kind == "f"), k
    assert set(atoms.info) == set(info)
    for k, v in info.items():
        assert np.array_equal(np.asarray(atoms.info[k]), v,
                              equal_nan=np.asarray(v).dtype.kind == "f"), k
