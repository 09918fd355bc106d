"""Shared fixtures.  The LAMMPS oracle must be present in CI (``CI`` set):
there a missing oracle fails the run; locally the oracle tests are skipped."""

import os

import pytest


@pytest.fixture(scope="session")
def Oracle():
    try:
        from oracle import Oracle, load_lammps

        load_lammps()
    except Exception as exc:  # ImportError, OSError from the MPI library
        if os.environ.get("CI"):
            pytest.fail(f"the LAMMPS oracle is required in CI but cannot be loaded: {exc}")
        pytest.skip(f"LAMMPS oracle not available: {exc}")
    return Oracle
