"""Checks of calculator coefficients, with errors that name the culprit."""

from __future__ import annotations

import difflib
import inspect
from collections.abc import Mapping

import numpy as np


def check_type(kind: str, t) -> int:
    """A particle or bond type: an integer >= 1 (or its decimal string, as
    JSON turns dictionary keys into strings)."""
    try:
        value = int(t) if isinstance(t, str) else t
        ok = not isinstance(value, bool) and int(value) == value and value >= 1
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"{kind}: type {t!r} must be an integer >= 1")
    return int(value)


def type_pair(kind: str, key) -> tuple:
    """A pair of types, sorted: ``(i, j)`` or the string ``"i j"``."""
    parts = key.replace(",", " ").split() if isinstance(key, str) else key
    try:
        ti, tj = parts
    except (TypeError, ValueError):
        raise ValueError(f"{kind} key {key!r} must be a pair of particle types") from None
    return tuple(sorted((check_type(kind, ti), check_type(kind, tj))))


def json_coeffs(coeffs: dict) -> dict:
    """Coefficient tables with string keys (``1``, ``"1 2"``) for JSON; each
    entry a list, or a dictionary where given as a mapping."""
    return {(" ".join(map(str, k)) if isinstance(k, tuple) else str(k)):
            dict(v) if isinstance(v, Mapping) else list(v) for k, v in coeffs.items()}


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


def did_you_mean(word, valid) -> str:
    """`` (did you mean 'x'?)`` naming the valid word nearest ``word`` (letter
    case aside), or ``""`` where none is near."""
    by_lower = {str(v).lower(): v for v in valid}
    near = difflib.get_close_matches(str(word).lower(), list(by_lower), n=1)
    return f" (did you mean {by_lower[near[0]]!r}?)" if near else ""


def check_keywords(who: str, given, valid) -> None:
    """Refuse the keywords in ``given`` that ``who`` does not take (stored, a
    misspelt one would be ignored): TypeError naming the first unknown word,
    the nearest valid one, and all valid ones."""
    valid = list(valid)
    for word in given:
        if word not in valid:
            raise TypeError(f"{who}: unknown keyword {word!r}{did_you_mean(word, valid)}; "
                            f"the keywords are {', '.join(valid)}")


def check_name(who: str, kind: str, name, valid, prefix: str = "") -> str:
    """``name`` (a model's, say) without ``prefix``, if that is one of
    ``valid``; else ValueError naming it, the nearest valid one, and all
    valid ones."""
    valid = list(valid)
    bare = name.removeprefix(prefix) if isinstance(name, str) else name
    if bare not in valid:
        raise ValueError(f"{who}: unknown {kind} {name!r}{did_you_mean(bare, valid)}; "
                         f"choose one of {', '.join(repr(v) for v in valid)}")
    return bare


def coeff_tuple(kind: str, key, values, names) -> tuple:
    """A coefficient entry as a tuple in ``names``' order: ``values`` is that
    tuple already, or a mapping from each of ``names`` to its value (every one
    given, no other)."""
    if not isinstance(values, Mapping):
        return tuple(values)
    missing = [n for n in names if n not in values]
    unknown = [n for n in values if n not in names]
    if unknown:
        check_keywords(f"{kind} {key}", unknown, names)
    if missing:
        raise ValueError(f"{kind} {key}: the mapping lacks {', '.join(missing)} (it needs "
                         f"{', '.join(names)})")
    return tuple(values[n] for n in names)


def keyword_names(function) -> list:
    """The names ``function`` takes by keyword (the valid ones for
    :func:`check_keywords` of a ``**unknown`` catch-all)."""
    kinds = (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return [name for name, p in inspect.signature(function).parameters.items()
            if p.kind in kinds and name != "self"]


def outside_stacklevel() -> int:
    """The ``stacklevel`` for ``warnings.warn`` that names the first frame
    outside ase_bpm and ASE (the user's line that asked for the evaluation),
    counted from the function that calls this one."""
    frame, level = inspect.currentframe().f_back, 1
    while frame is not None:
        name = frame.f_globals.get("__name__", "")
        if not (name.startswith("ase_bpm.") or name == "ase_bpm" or name.startswith("ase.")):
            return level
        frame, level = frame.f_back, level + 1
    return level
