"""The import paths of ase_bpm 0.1 (``ase_bpm.md``, ``ase_bpm.lammps``...),
kept working with a ``DeprecationWarning`` that names the public path.

ase_bpm 0.1 was a flat package; each old module is now a module of a layer
folder (its *home*).  An old path is resolved only when it is used, never
registered up front: :class:`OldPathFinder` (on ``sys.meta_path``) answers
``import ase_bpm.md`` and ``from ase_bpm.md import X``, and
:func:`old_path_attribute` (the package's ``__getattr__``) answers
``ase_bpm.md`` as an attribute.  Either way the result is the *same module
object* as its home (classes keep their real ``__module__``, so pickles,
``copy`` and multiprocessing see only the homes).

This module knows its homes by name only: it imports nothing of ase_bpm
until an old path is used.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings

PACKAGE = "ase_bpm"

_DEMOS = "the ase-bpm demo command"

#: each old path (below ``ase_bpm``): its home (below ``ase_bpm``) and the
#: public names a user writes instead (None: the module is internal); a module
#: below an old package path (``kernels.bond``) has the same place below its
#: home (``laws.bond``)
OLD_PATHS = {
    "bonds": ("core.bonds", "ase_bpm.create_bonds, ase_bpm.get_bonds, ase_bpm.take_bonds, "
              "ase_bpm.renew_ids, ase_bpm.repeat, ase_bpm.pad_bonds and "
              "ase_bpm.with_bond_strings"),
    "neighbours": ("core.neighbours", None),
    "params": ("core.params", None),
    "spheres": ("core.spheres", "ase_bpm.rotational_energy"),
    "kernels": ("laws", "ase_bpm.laws.bond (a bond law of your own) and ase_bpm.set_threads; "
                "the rest of it is internal"),
    "kernels.spring": ("laws.spring", None),
    "kernels.peri": ("laws.peri", None),
    "kernels.granular": ("laws.granular", None),
    "kernels.compiled": ("laws.compiled", "ase_bpm.set_threads; the rest of it is internal"),
    "calculator": ("models.base", "ase_bpm.BPMCalculator, ase_bpm.pure, ase_bpm.register_fix, "
                   "ase_bpm.UnstableSimulationError and ase_bpm.SpinNotIntegratedWarning"),
    "bondstate": ("models.bonded", "ase_bpm.NoBondsWarning; the rest of it is internal"),
    "contacts": ("models.contacts", None),
    "spring": ("models.spring", "ase_bpm.BPMSpring"),
    "peri": ("models.peri", "ase_bpm.BPMPeri"),
    "granular": ("models.granular", "ase_bpm.Granular"),
    "fixes": ("scene.fixes", "ase_bpm.SphericalIndenter, ase_bpm.Gravity and "
              "ase_bpm.GranularWall"),
    "md": ("scene.md", "ase_bpm.VelocityVerlet and ase_bpm.SphereVelocityVerlet"),
    "restart": ("scene.restart", "ase_bpm.write_restart and ase_bpm.read_restart"),
    "lammps": ("scene.lammps", "ase_bpm.write_lammps and ase_bpm.read_lammps"),
    "viewing": ("scene.viewing", "ase_bpm.ViewerTrajectory"),
    "cli": ("scene.cli", "the ase-bpm command"),
    "demos": ("scene.demos", _DEMOS),
    "demos.impact": ("scene.demos.impact", _DEMOS),
    "demos.pour": ("scene.demos.pour", _DEMOS),
    "demos.shatter": ("scene.demos.shatter", _DEMOS),
}


def home_of(fullname: str):
    """``(home, advice)`` for an old path such as ``"ase_bpm.md"`` (the home's
    full name and the deprecation message), or None if it is not one."""
    prefix = PACKAGE + "."
    if not fullname.startswith(prefix):
        return None
    parts = fullname[len(prefix):].split(".")
    for cut in range(len(parts), 0, -1):  # the longest old path it starts with
        old = ".".join(parts[:cut])
        if old in OLD_PATHS:
            home, instead = OLD_PATHS[old]
            full_home = ".".join([PACKAGE, home, *parts[cut:]])
            if cut < len(parts):  # a module below an old package path: its home
                use = f"use {full_home}"
            elif instead:
                use = f"use {instead}"
            else:
                use = f"the module is internal ({full_home})"
            return full_home, f"{fullname} is deprecated: {use}"
    return None


def _resolve(fullname: str, stacklevel: int):
    """The home module of the old path ``fullname``, with its warning."""
    home, advice = home_of(fullname)
    warnings.warn(advice, DeprecationWarning, stacklevel=stacklevel + 1)
    return importlib.import_module(home)


class OldPathFinder(importlib.abc.MetaPathFinder, importlib.abc.InspectLoader):
    """Finds ``ase_bpm.<old path>`` and loads it as its home module, which it
    leaves as it was (the home keeps its own ``__spec__``).  An old path
    whose home does not exist is not found (``find_spec`` gives None, an
    import fails as any other would).  ``python -m`` of an old path runs
    its home as ``__main__``, with the warning (:meth:`get_code`)."""

    def find_spec(self, fullname, path=None, target=None):
        found = home_of(fullname)
        if found is None:
            return None
        # (imports the home's parent packages, not the home)
        home = importlib.util.find_spec(found[0])
        if home is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, self, origin=home.origin)

    def create_module(self, spec):
        # the import machinery's own frames are skipped: the warning names the
        # line that imports
        module = _resolve(spec.name, stacklevel=2)
        spec.loader_state = module.__spec__  # the home's own, for exec_module
        return module

    def exec_module(self, module):
        # the import machinery set __spec__ to the old path's: give the home its own back
        module.__spec__ = module.__spec__.loader_state

    def get_code(self, fullname):
        """What ``python -m <old path>`` runs: the home as ``__main__`` (its
        relative imports need its own package), after the warning, which
        ``__main__`` raises so that Python shows it by default."""
        home, advice = home_of(fullname)
        source = ("import runpy, warnings\n"
                  f"warnings.warn({advice!r}, DeprecationWarning)\n"
                  f"runpy.run_module({home!r}, run_name='__main__', alter_sys=True)\n")
        return compile(source, f"<{fullname}: runs {home}>", "exec")

    def get_source(self, fullname):
        """The home's source."""
        home = home_of(fullname)[0]
        return importlib.util.find_spec(home).loader.get_source(home)

    def is_package(self, fullname):
        """Is the home a package?"""
        return importlib.util.find_spec(home_of(fullname)[0]).submodule_search_locations \
            is not None


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (before the path finder,
    which would otherwise load a second copy of a home under its old path);
    once per process."""
    if not any(isinstance(finder, OldPathFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, OldPathFinder())


def old_path_attribute(name: str):
    """``ase_bpm.<name>`` for an old path ``name`` (the package's
    ``__getattr__``), with its warning; AttributeError for any other name."""
    if name not in OLD_PATHS or "." in name:
        raise AttributeError(f"module {PACKAGE!r} has no attribute {name!r}")
    return _resolve(f"{PACKAGE}.{name}", stacklevel=3)
