"""Checks of calculator coefficients, with errors that name the culprit."""

from __future__ import annotations

import numpy as np


def check_type(kind: str, t) -> int:
    """A particle or bond type: an integer >= 1."""
    if isinstance(t, bool) or int(t) != t or t < 1:
        raise ValueError(f"{kind}: type {t!r} must be an integer >= 1")
    return int(t)


def check_coeffs(kind: str, key, values, names, positive=(), non_negative=()) -> tuple:
    """One coefficient tuple, in LAMMPS order, as floats.

    ``names`` are the coefficients expected (their count is checked), those in
    ``positive`` must be > 0 and those in ``non_negative`` >= 0; all finite.
    """
    values = tuple(values)
    if len(values) != len(names):
        raise ValueError(f"{kind} {key}: expected {len(names)} coefficients "
                         f"({', '.join(names)}), got {len(values)}")
    values = tuple(float(v) for v in values)
    for name, value in zip(names, values):
        if not np.isfinite(value):
            raise ValueError(f"{kind} {key}: {name} = {value} is not finite")
        if name in positive and not value > 0:
            raise ValueError(f"{kind} {key}: {name} = {value} must be positive")
        if name in non_negative and not value >= 0:
            raise ValueError(f"{kind} {key}: {name} = {value} must be non-negative")
    return values
