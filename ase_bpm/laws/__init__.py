"""Layer 2, laws: the force laws, pure functions over bond and pair arrays.

No ASE and no per-run state: the bond-law protocol and its registry
(:mod:`.bond`), the contact-law protocol with its kernel and the per-type-pair
coefficient tables (:mod:`.contact`), the laws themselves (:mod:`.spring`,
:mod:`.peri`, :mod:`.granular`) and the compiled kernels
(:mod:`.compiled`), which replace their NumPy twins one for one.  Imports from
core only.
"""

from importlib import import_module
from types import ModuleType

#: the environment variable that sets what ``kernels="auto"`` means: "numpy"
#: runs the NumPy kernels everywhere, and NumPy's sums of a step outside them
#: (``compiled.NATIVE_SUMS``; CI runs the suite so, and once as is)
KERNELS_VARIABLE = "ASE_BPM_KERNELS"
ROUTES = ("auto", "compiled", "numpy")
#: the two routes a law runs on (what :func:`kernel_route` resolves to)
COMPILED, NUMPY = "compiled", "numpy"
#: the key of a model's contact law in :func:`law_routes` (bond laws and
#: contact laws may share a name: "bpm/spring")
CONTACTS = "contacts"

# (below the names above: laws.compiled, which spring imports, reads them)
from .spring import SpringForces, lengths, spring_bonds, spring_pairs  # noqa: E402

__all__ = ["SpringForces", "granular_kernels", "kernel_route", "law_routes", "lengths",
           "spring_bonds", "spring_pairs"]


def kernel_route(name: str = "auto") -> str:
    """``"compiled"`` or ``"numpy"``: the kernels a calculator asking for
    ``name`` runs.  ``"compiled"`` (C, built at install) and ``"numpy"`` are
    taken as said; ``"auto"`` is compiled where built, else NumPy with one
    warning per process, unless the environment variable ``ASE_BPM_KERNELS``
    says ``numpy`` or ``compiled``."""
    import os

    from . import compiled

    if name not in ROUTES:
        raise ValueError(f"kernels must be 'auto', 'compiled' or 'numpy', got {name!r}")
    if name == "auto":
        said = os.environ.get(KERNELS_VARIABLE, "auto")
        if said not in ROUTES:
            raise ValueError(f"the environment variable {KERNELS_VARIABLE} must be 'auto', "
                             f"'compiled' or 'numpy', not {said!r}")
        name = said
    if name == "auto" and compiled.stale:
        _warn_once("ase_bpm: the compiled kernels were built from older C sources and "
                   "are not used (the NumPy kernels run); rebuild them (pip install -e .)")
    elif name == "auto" and not compiled.available:
        _warn_once("ase_bpm: the compiled kernels are not built here: the NumPy kernels run "
                   "(same results, slower); reinstall where a C compiler is at hand")
    if name == "numpy" or (name == "auto" and not compiled.available):
        return "numpy"
    if compiled.stale:
        raise ValueError("kernels='compiled': the compiled kernels were built from "
                         "older C sources; rebuild them (pip install -e .)")
    if not compiled.available:
        raise ValueError("kernels='compiled': the compiled kernels are not built here "
                         "(reinstall ase_bpm where a C compiler is at hand)")
    return "compiled"


def law_routes(route: str, laws, contact_law=None, together: bool = False) -> dict:
    """The route each law runs on, for a calculator on ``route`` (what
    :func:`kernel_route` resolved): bond-law name (and :data:`CONTACTS` for
    ``contact_law``, when given) -> ``"compiled"`` or ``"numpy"``.

    Each law runs its compiled twin (its ``compiled`` flag) where it has one
    and the route is compiled, and its NumPy kernel otherwise, beside laws on
    the other route.  ``together``: the model runs its laws in one compiled
    pass over all the bonds (BPMPeri's node state), so a law without a
    compiled twin puts every law, the contacts included, on NumPy."""
    laws = list(laws)
    every = laws + ([] if contact_law is None else [contact_law])

    def of(law) -> str:
        if route != COMPILED or not law.compiled:
            return NUMPY
        return NUMPY if together and not all(other.compiled for other in every) else COMPILED

    routes = {law.name: of(law) for law in laws}
    if contact_law is not None:
        routes[CONTACTS] = of(contact_law)
    return routes


def granular_kernels(name: str = "auto"):
    """The module whose ``pair_contacts`` and ``walls_contacts`` to use, for
    ``kernels=name`` (:func:`kernel_route`)."""
    from . import compiled, granular

    return compiled if kernel_route(name) == "compiled" else granular


class _ModuleName(str):
    """A kernels module's name, standing for the module in a pickled state."""


def _by_name(value):
    """``value`` with a module in it (or in a tuple of it) given by name."""
    if isinstance(value, ModuleType):
        return _ModuleName(value.__name__)
    if isinstance(value, tuple) and any(isinstance(v, ModuleType) for v in value):
        return tuple(_by_name(v) for v in value)
    return value


def _from_name(value):
    """:func:`_by_name` undone."""
    if isinstance(value, _ModuleName):
        return import_module(value)
    if isinstance(value, tuple) and any(isinstance(v, _ModuleName) for v in value):
        return tuple(_from_name(v) for v in value)
    return value


class HoldsKernels:
    """Pickling and ``copy.deepcopy`` of an object that holds a kernels
    module (:func:`granular_kernels`; a module cannot be pickled): the module
    goes by its name, and comes back as the same module."""

    def __getstate__(self) -> dict:
        return {name: _by_name(value) for name, value in self.__dict__.items()}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update({name: _from_name(value) for name, value in state.items()})


_warned = []  # the NumPy fallback has been announced in this process


def _warn_once(message: str) -> None:
    if not _warned:
        import warnings

        warnings.warn(message, stacklevel=4)
        _warned.append(message)
