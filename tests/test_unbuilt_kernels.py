"""Where the compiled kernels cannot be imported (a clone's sources, not
built in place), the tests of the compiled route skip with the reason, and
in CI they fail: run on a copy of the package without its library."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import ase_bpm

TESTS = Path(__file__).resolve().parent
#: a compiled test by parameter, one by marker, and one on NumPy
PROBE = '''
import pytest

import ase_bpm


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_route(kernels):
    ase_bpm.Granular("hooke", kn=1.0, gamma_n=0.0, xmu=0.0, kernels=kernels)


@pytest.mark.threads
def test_threads():
    pass
'''


@pytest.fixture(scope="module")
def unbuilt_clone(tmp_path_factory):
    clone = tmp_path_factory.mktemp("clone")
    shutil.copytree(Path(ase_bpm.__file__).parent, clone / "ase_bpm",
                    ignore=shutil.ignore_patterns("_kernels*", "__pycache__"))
    shutil.copy(TESTS.parent / "pyproject.toml", clone)
    (clone / "tests").mkdir()
    shutil.copy(TESTS / "conftest.py", clone / "tests")
    (clone / "tests" / "test_probe.py").write_text(PROBE)
    return clone


def run_tests(clone: Path, ci: bool) -> subprocess.CompletedProcess:
    """``python -m pytest`` in the clone (which imports its own ase_bpm)."""
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "PYTHONPATH")}
    env.update({"CI": "1"} if ci else {})
    return subprocess.run([sys.executable, "-m", "pytest", "-rA", "-p", "no:cacheprovider"],
                          cwd=clone, env=env, capture_output=True, text=True)


def test_compiled_tests_skip_with_the_reason(unbuilt_clone):
    result = run_tests(unbuilt_clone, ci=False)
    assert result.returncode == 0, result.stdout
    assert "1 passed, 2 skipped" in result.stdout
    reason = (f"ase_bpm from {unbuilt_clone.resolve() / 'ase_bpm'}, this clone's sources "
              "(Python finds them before any installed copy), has no compiled kernels built "
              "in place: pip install -e . builds them (or run pytest, not python -m pytest, "
              "to test the installed copy)")
    header, skips = result.stdout.splitlines()[2], result.stdout.splitlines()[-2]
    assert header == reason
    assert skips.startswith("SKIPPED [2] tests/conftest.py") and reason in skips
    assert "PASSED tests/test_probe.py::test_route[numpy]" in result.stdout


def test_compiled_tests_fail_in_ci(unbuilt_clone):
    result = run_tests(unbuilt_clone, ci=True)
    assert result.returncode == 1, result.stdout
    assert "1 passed, 2 errors" in result.stdout
    for test in ("test_route[compiled]", "test_threads"):  # (pytest 7 prints no "Failed: ")
        assert f"ERROR tests/test_probe.py::{test}" in result.stdout
    assert "CI requires the compiled kernels: ase_bpm from" in result.stdout
