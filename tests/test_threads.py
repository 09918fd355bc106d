"""The bpm/spring kernels on threads (``compiled.set_threads``).

Two threads split the bonds (listed pairs) into two contiguous ranges and
add up their force buffers in a fixed order: on the same configuration they
agree with one thread to round-off (1e-12 of the largest magnitude) and
break the same bonds, and a run on two threads repeats bit for bit.  The
tests skip where the library was built without OpenMP (CI builds it with).
"""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.laws import compiled
from scenes import MULTI_TYPE_COEFFS, fcc_cluster, multi_type_cluster

pytestmark = pytest.mark.skipif(not compiled.threads_available,
                                reason="compiled kernels not built with OpenMP")

RELATIVE = 1e-12
#: a lowered threshold, so that small scenes run on threads (bonds and pairs)
FEW = 64


@pytest.fixture(autouse=True)
def thread_count():
    """The thread count a test sets is put back afterwards."""
    before = compiled.set_threads(None)
    yield
    compiled.set_threads(before)


@pytest.fixture
def calls(monkeypatch):
    """The thread count each kernel call takes, in order."""
    taken, chosen = [], compiled._threads_for

    def spy(items, natoms):
        taken.append(chosen(items, natoms))
        return taken[-1]

    monkeypatch.setattr(compiled, "_threads_for", spy)
    return taken


def evaluate(atoms, count, displacements=()):
    """A copy of ``atoms`` on ``count`` threads: the first evaluation, then
    one step per displacement.  Returns the copy."""
    compiled.set_threads(count)
    a = atoms.copy()
    a.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, kernels="compiled", guard=False)
    a.get_forces()
    for dx in displacements:
        a.positions = a.positions + dx
        a.get_forces()
    return a


def outputs(atoms) -> dict:
    """Every output of an evaluated copy that threads could change."""
    out = dict(forces=atoms.get_forces(), energy=atoms.get_potential_energy(),
               damping=atoms.arrays["bpm_fd_last"],
               released=atoms.info.get("bpm_broken_bond_energy", 0.0),
               r0=np.nan_to_num(atoms.arrays["bond_r0"]))
    if atoms.pbc.any():
        out["stress"] = atoms.get_stress()
    return out


def close(ours, reference, what):
    scale = max(np.abs(reference).max(initial=0.0), 1e-300)
    error = np.abs(np.asarray(ours) - reference).max(initial=0.0) / scale
    assert error <= RELATIVE, f"{what}: relative difference {error:.3g}"


def same_bonds(a, b):
    assert np.array_equal(a.arrays["bond_type"], b.arrays["bond_type"])
    assert np.array_equal(a.info.get("broken_bonds", np.zeros((0, 9))),
                          b.info.get("broken_bonds", np.zeros((0, 9))))


@pytest.mark.parametrize("cell", ["open", "orthorhombic", "triclinic"])
def test_two_threads_agree_with_one(calls, monkeypatch, cell):
    """Bonds and pairs on threads, with a pull that breaks some bonds: the
    same outputs to round-off, the same bonds broken."""
    monkeypatch.setattr(compiled, "THREADED_FROM", FEW)
    atoms, _ = multi_type_cluster(size=6, pbc=cell != "open",
                                  shear=0.3 if cell == "triclinic" else 0.0)
    rng = np.random.default_rng(1)
    steps = [rng.normal(0, 0.01, atoms.positions.shape),
             rng.normal(0, 0.05, atoms.positions.shape)]
    one = evaluate(atoms, 1, steps)
    assert set(calls) == {1}
    two = evaluate(atoms, 2, steps)
    assert set(calls) == {1, 2}
    assert 0 < len(two.info["broken_bonds"]) < len(ase_bpm.get_bonds(atoms)[0])
    reference = outputs(one)
    for name, value in outputs(two).items():
        close(value, reference[name], name)
    same_bonds(one, two)


def test_threads_only_for_enough_bonds(calls):
    """Below THREADED_FROM bonds (pairs), or THREADED_PER_ATOM per atom, a
    call runs on one thread; else on those set (a block of about 24,000
    bonds)."""
    atoms, _ = fcc_cluster(10)
    ase_bpm.create_bonds(atoms, 1.25, bond_type=1)
    nb, natoms = len(ase_bpm.get_bonds(atoms)[0]), len(atoms)
    assert nb >= max(compiled.THREADED_FROM, compiled.THREADED_PER_ATOM * natoms)
    compiled.set_threads(2)
    assert compiled._threads_for(nb, natoms) == 2
    assert compiled._threads_for(compiled.THREADED_FROM - 1, natoms) == 1
    assert compiled._threads_for(nb, int(nb / compiled.THREADED_PER_ATOM) + 1) == 1
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.04, 1.0)}, kernels="compiled",
                                   guard=False)
    two = atoms.get_forces()
    assert 2 in calls
    atoms.calc.reset()
    compiled.set_threads(1)
    close(two, atoms.get_forces(), "forces")


def test_a_run_on_two_threads_repeats_bit_for_bit(monkeypatch):
    """Fifty steps of ASE's VelocityVerlet, fast enough that bonds break and
    pairs touch, twice on two threads: the same positions, forces and broken
    bonds, bit for bit."""
    monkeypatch.setattr(compiled, "THREADED_FROM", FEW)
    atoms, _ = multi_type_cluster(seed=2, size=6)
    atoms.set_velocities(np.random.default_rng(3).normal(0, 0.3, atoms.positions.shape))
    runs = []
    for _ in range(2):
        a = evaluate(atoms, 2)
        VelocityVerlet(a, timestep=0.02).run(50)
        runs.append(a)
    first, second = runs
    assert len(first.info["broken_bonds"]) > 0
    assert np.array_equal(first.positions, second.positions)
    assert np.array_equal(first.get_velocities(), second.get_velocities())
    assert np.array_equal(first.get_forces(), second.get_forces())
    assert first.get_potential_energy() == second.get_potential_energy()
    same_bonds(first, second)


def test_the_thread_count_is_checked_and_read_from_the_environment(monkeypatch):
    for wrong in (0, -1, 1.5, "2", True):
        with pytest.raises(ValueError, match="positive integer"):
            compiled.set_threads(wrong)
    monkeypatch.delenv(compiled.THREADS_VARIABLE, raising=False)
    assert compiled.threads() == 1  # by default
    monkeypatch.setenv(compiled.THREADS_VARIABLE, "2")
    assert compiled.threads() == 2
    assert compiled.set_threads(1) is None  # none was set: the environment's
    assert compiled.threads() == 1
    assert compiled.set_threads(None) == 1
    for wrong in ("0", "many", "-2"):
        monkeypatch.setenv(compiled.THREADS_VARIABLE, wrong)
        with pytest.raises(ValueError, match=compiled.THREADS_VARIABLE):
            compiled.threads()
