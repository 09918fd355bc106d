"""Layer 2, laws: the force laws, pure functions over bond and pair arrays.

No ASE and no per-run state: the bond-law protocol and its registry
(:mod:`.bond`), the contact-law protocol with its kernel and the per-type-pair
coefficient tables (:mod:`.contact`), the laws themselves (:mod:`.spring`,
:mod:`.peri`, :mod:`.granular`) and the compiled granular kernels
(:mod:`.compiled`), which replace their NumPy twins one for one.  Imports from
core only.
"""

from .spring import SpringForces, lengths, spring_bonds, spring_pairs

__all__ = ["SpringForces", "granular_kernels", "lengths", "spring_bonds", "spring_pairs"]


def granular_kernels(name: str = "auto"):
    """The module whose ``pair_contacts`` and ``wall_contacts`` to use:
    ``"compiled"`` (C, built at install), ``"numpy"`` or ``"auto"`` (compiled
    where built; else NumPy, with one warning per process)."""
    from . import compiled, granular

    if name == "auto" and compiled.stale:
        _warn_once("ase_bpm: the compiled kernels were built from an older _granular.c and "
                   "are not used (the NumPy kernels run); rebuild them (pip install -e .)")
    elif name == "auto" and not compiled.available:
        _warn_once("ase_bpm: the compiled kernels are not built here: the NumPy kernels run "
                   "(same results, slower); reinstall where a C compiler is at hand")
    if name == "numpy" or (name == "auto" and not compiled.available):
        return granular
    if name in ("auto", "compiled"):
        if compiled.stale:
            raise ValueError("kernels='compiled': the compiled kernels were built from an "
                             "older _granular.c; rebuild them (pip install -e .)")
        if not compiled.available:
            raise ValueError("kernels='compiled': the compiled kernels are not built here "
                             "(reinstall ase_bpm where a C compiler is at hand)")
        return compiled
    raise ValueError(f"kernels must be 'auto', 'compiled' or 'numpy', got {name!r}")


_warned = []  # the NumPy fallback has been announced in this process


def _warn_once(message: str) -> None:
    if not _warned:
        import warnings

        warnings.warn(message, stacklevel=4)
        _warned.append(message)
