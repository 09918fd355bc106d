"""Coefficients of contact laws by pair of particle types (LAMMPS ``pair_coeff``).

:class:`PairTable` turns ``{(type_i, type_j): coefficients}`` into lookup
tables ``[coefficient][type_i, type_j]`` for the particle types present, mixing
unlisted pairs from the two like-type entries where the law has a mixing rule
(LAMMPS ``pair_modify mix``), or naming the missing pair where it has none.
"""

from __future__ import annotations

from typing import Callable, Mapping, Optional

import numpy as np

from ..core.arrays import same_array

#: a mixing rule: like-type coefficients of the two types -> those of the pair
MixingRule = Callable[[tuple, tuple], tuple]


def geometric(a: float, b: float) -> float:
    return float(np.sqrt(a * b))


def arithmetic(a: float, b: float) -> float:
    return 0.5 * (a + b)


class PairTable:
    """Per-type-pair coefficient tables, built once per set of types present.

    ``coeffs`` maps sorted type pairs to coefficient tuples (checked by the
    caller), ``names`` names the coefficients, ``mix`` is the mixing rule or
    None (every pair present needs an entry).
    """

    def __init__(self, coeffs: Mapping[tuple, tuple], names: tuple,
                 mix: Optional[MixingRule] = None):
        self.coeffs, self.names, self.mix = dict(coeffs), tuple(names), mix
        self._built = {}  # types present -> tables
        self._last = None  # (types array, tables) of the last call

    def __call__(self, types_n: np.ndarray) -> np.ndarray:
        """``[coefficient, type_i, type_j]`` for the types of ``types_n``."""
        last = self._last
        if last is not None and same_array(last[0], types_n):
            return last[1]
        present = tuple(int(t) for t in np.unique(types_n))
        if present not in self._built:
            size = max(present, default=0) + 1
            tables = np.full((len(self.names), size, size), np.nan)
            for a in present:
                for b in present:
                    tables[:, a, b] = self.of_pair(min(a, b), max(a, b))
            self._built[present] = tables
        self._last = (types_n.copy(), self._built[present])
        return self._last[1]

    def of_pair(self, lo: int, hi: int) -> tuple:
        """The coefficients of types ``lo <= hi``: listed, or mixed."""
        if (lo, hi) in self.coeffs:
            return self.coeffs[lo, hi]
        if self.mix is None:
            raise ValueError(f"unknown particle type pair {(lo, hi)}: pair_coeffs needs an "
                             "entry for every pair of types present (no mixing)")
        if (lo, lo) in self.coeffs and (hi, hi) in self.coeffs:
            return self.mix(self.coeffs[lo, lo], self.coeffs[hi, hi])
        missing = lo if (lo, lo) not in self.coeffs else hi
        raise ValueError(f"unknown particle type {missing}: pair_coeffs has no entry for "
                         f"types ({lo}, {hi}) and none for ({missing}, {missing}) to mix from")
