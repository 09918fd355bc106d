"""Shared fixtures and markers.  What CI must have fails there when missing
(``CI`` set) and is skipped elsewhere, with the reason: the LAMMPS oracle
(the ``Oracle`` fixture), the compiled kernels (tests marked ``compiled``,
and any test given ``"compiled"`` as a parameter: the kernels it runs on)
and their OpenMP build (tests marked ``threads``).

The tests import the ``ase_bpm`` that Python finds first: ``python -m
pytest`` in a clone puts the clone first, so they test its sources, built
in place or not; ``pytest`` (or ``python -m pytest`` run from another
folder) finds an installed copy first.  The header of the run names the
folder and whether its compiled kernels load.

LAMMPS's own example decks (``test_lammps_examples.py``) are not something
CI must have: they run where ``ASE_BPM_LAMMPS_EXAMPLES`` names a folder
holding LAMMPS's ``examples/`` tree and are skipped elsewhere, CI included
(a plain ``skipif``, not :func:`missing`); CI runs their twins in
``tests/decks``.
"""

import functools
import os
from pathlib import Path

import pytest

#: the parameter value that puts a test on the compiled kernels
COMPILED = "compiled"


def missing(what: str, reason: str):
    """Fail in CI (which must have ``what``), else skip with the reason."""
    if os.environ.get("CI"):
        pytest.fail(f"CI requires {what}: {reason}", pytrace=False)
    pytest.skip(reason)


@pytest.fixture(scope="session")
def Oracle():
    try:
        from oracle import Oracle, load_lammps

        load_lammps()
    except Exception as exc:  # ImportError, OSError from the MPI library
        missing("the LAMMPS oracle", f"LAMMPS oracle not available: {exc}")
    return Oracle


#: the clone the tests are in
CLONE = Path(__file__).resolve().parent.parent


@functools.cache
def kernels_missing() -> str | None:
    """Why the compiled kernels of the ase_bpm imported cannot run, or None."""
    import ase_bpm
    from ase_bpm.laws import compiled, kernel_route

    try:
        kernel_route(COMPILED)
    except ValueError as exc:
        folder = Path(ase_bpm.__file__).resolve().parent
        if folder.parent == CLONE and not compiled.stale:
            return (f"ase_bpm from {folder}, this clone's sources (Python finds them before "
                    "any installed copy), has no compiled kernels built in place: "
                    "pip install -e . builds them (or run pytest, not python -m pytest, "
                    "to test the installed copy)")
        return f"ase_bpm from {folder}: {exc}"
    return None


def pytest_report_header(config) -> str:
    """Which ase_bpm the tests import, and its compiled kernels."""
    import ase_bpm
    from ase_bpm.laws import compiled

    why = kernels_missing()
    if why is not None:
        return why
    openmp = "with" if compiled.threads_available else "without"
    return f"ase_bpm from {Path(ase_bpm.__file__).parent}: compiled kernels, {openmp} OpenMP"


def pytest_collection_modifyitems(items):
    """Mark ``compiled`` every test that takes ``"compiled"`` as a parameter."""
    for item in items:
        params = getattr(getattr(item, "callspec", None), "params", {})
        if any(isinstance(value, str) and value == COMPILED for value in params.values()):
            item.add_marker(pytest.mark.compiled)


def pytest_runtest_setup(item):
    if item.get_closest_marker("compiled") or item.get_closest_marker("threads"):
        why = kernels_missing()
        if why is not None:
            missing("the compiled kernels", why)
    if item.get_closest_marker("threads"):
        from ase_bpm.laws import compiled

        if not compiled.threads_available:
            missing("OpenMP", "the compiled kernels were built without OpenMP")
