"""The bpm/spring kernels and the granular pair kernel on threads
(``compiled.set_threads``).

Two threads split the bonds (listed pairs) into two contiguous ranges and
add up their force buffers in a fixed order: on the same configuration they
agree with one thread to round-off (1e-12 of the largest magnitude) and
break the same bonds, and a run on two threads repeats bit for bit.  The
tests skip where the library was built without OpenMP, except in CI, which
builds it with (``tests/conftest.py``).
"""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.laws import compiled
from scenes import MULTI_TYPE_COEFFS, fcc_cluster, multi_type_cluster

pytestmark = pytest.mark.threads

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

    def spy(items, natoms, *fewest):
        taken.append(chosen(items, natoms, *fewest))
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


@pytest.mark.parametrize("say", ["set_threads", "environment"])
def test_a_kernel_made_ready_takes_the_count_asked_for_since(calls, monkeypatch, say):
    """The bpm/spring kernels made ready for a bond set and a contact list
    keep the thread count they worked out between calls (no thread count is
    worked out at a step), and work it out anew, and take it, once another
    is asked for (``set_threads``, or ``ASE_BPM_THREADS`` where none is
    set): a run that changes it goes on bit for bit as one that had it from
    the start."""
    monkeypatch.setattr(compiled, "THREADED_FROM", FEW)
    atoms, _ = multi_type_cluster(size=6)
    a, b = atoms.copy(), atoms.copy()
    for copy in (a, b):
        copy.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, kernels="compiled", guard=False)
    VelocityVerlet(a, timestep=0.02).run(3)
    worked_out = len(calls)
    VelocityVerlet(a, timestep=0.02).run(3)
    assert len(calls) == worked_out and set(calls) == {1}  # kept between calls
    if say == "set_threads":
        compiled.set_threads(2)
    else:
        monkeypatch.setenv(compiled.THREADS_VARIABLE, "2")
    VelocityVerlet(a, timestep=0.02).run(2)
    assert calls[worked_out:] == [2, 2]  # bonds and pairs, once each
    compiled.set_threads(1)
    VelocityVerlet(b, timestep=0.02).run(6)
    compiled.set_threads(2)
    VelocityVerlet(b, timestep=0.02).run(2)
    assert np.array_equal(a.positions, b.positions)


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


# -- the granular pair kernel -------------------------------------------------------------

def sphere_scene(seed=5, n=6):
    """A dense periodic pile's neighbour list and per-sphere inputs, with
    stored shear on every row and two frozen spheres."""
    from ase_bpm.core.neighbours import neighbour_pairs
    from scenes import sphere_pile

    atoms = sphere_pile(n=n, seed=seed, speed=1.0, spin=3.0)
    atoms.cell, atoms.pbc = [n, n, n], [True, True, False]
    r = atoms.arrays["radius"]
    i_l, j_l, shift_lc = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc, r + 0.1)
    hold = np.zeros(len(atoms), dtype=bool)
    hold[[4, 70]] = True
    shear_lc = np.random.default_rng(seed).normal(0.0, 0.05, (len(i_l), 3))
    return (i_l, j_l, shift_lc, atoms.positions, atoms.get_velocities(),
            atoms.arrays["omega"], r, atoms.get_masses(), hold, shear_lc)


CONTACT_LAWS = {"hooke/history": dict(hertz=False, history=True, frictional=True),
                "hertz/history": dict(hertz=True, history=True, frictional=True),
                "hooke": dict(hertz=False, history=False, frictional=True),
                "frictionless": dict(hertz=False, history=False, frictional=False)}


def contacts(args, law, count):
    compiled.set_threads(count)
    return compiled.pair_contacts(*args, kn=2000.0, kt=600.0, gamma_n=40.0, gamma_t=10.0,
                                  xmu=0.0 if not law["frictional"] else 0.4, dt=1e-3,
                                  update=True, virial=True, **law)


@pytest.mark.parametrize("count", [2, 3, 4])
@pytest.mark.parametrize("name", CONTACT_LAWS)
def test_contacts_on_threads_agree_with_one(calls, monkeypatch, name, count):
    """The listed sphere pairs in ranges (the touching rows of later ranges
    moved up behind ranges that were moved themselves): the same forces,
    damping parts, torques, energy and virial to round-off; the same
    touching pairs in the same order, the same new shear and contact counts,
    bit for bit."""
    monkeypatch.setattr(compiled, "CONTACTS_THREADED_FROM", FEW)
    args, law = sphere_scene(), CONTACT_LAWS[name]
    one = contacts(args, law, 1)
    two = contacts(args, law, count)
    assert calls == [1, count]
    assert len(one.touch) > 100 and len(one.touch) < len(args[0])  # half the rows touch
    for what in ("touch", "i_p", "j_p", "count_n", "shear_xc", "shear_lc"):
        ours, reference = getattr(two, what), getattr(one, what)
        assert (ours is None) == (reference is None) and (ours is None or np.array_equal(
            ours, reference)), what
    for what in ("f_nc", "fd_nc", "t_nc", "energy", "virial"):
        if getattr(one, what) is not None:
            close(getattr(two, what), getattr(one, what), what)
    assert (two.t_nc is None) == (name == "frictionless")


def test_contacts_on_two_threads_repeat_bit_for_bit(monkeypatch):
    monkeypatch.setattr(compiled, "CONTACTS_THREADED_FROM", FEW)
    args, law = sphere_scene(seed=6), CONTACT_LAWS["hooke/history"]
    first, second = contacts(args, law, 2), contacts(args, law, 2)
    for what in ("f_nc", "fd_nc", "t_nc", "virial", "touch", "shear_xc", "count_n"):
        assert np.array_equal(getattr(first, what), getattr(second, what)), what
    assert first.energy == second.energy


def coincident(args, fraction):
    """``args`` with the spheres of a row past ``fraction`` of the list (one
    without an image shift) moved onto each other; returns that row."""
    i_l, j_l, shift_lc = args[0], args[1], args[2]
    row = int(fraction * len(i_l))
    while shift_lc[row].any():
        row += 1
    x = args[3].copy()
    x[j_l[row]] = x[i_l[row]]
    args[3] = x
    return row


def test_coincident_spheres_in_a_later_range_are_named(monkeypatch):
    """A pair at zero distance among the rows of a later thread stops the
    kernel and is named, as on one thread; with two such pairs in two
    ranges, the lower row is named on any number of threads."""
    monkeypatch.setattr(compiled, "CONTACTS_THREADED_FROM", FEW)
    args = list(sphere_scene(seed=7))
    i_l, j_l = args[0], args[1]
    row = coincident(args, 0.75)
    for count in (1, 2, 3):
        with pytest.raises(ValueError, match=f"spheres {i_l[row]} and {j_l[row]} are at the "
                                             "same position"):
            contacts(args, CONTACT_LAWS["hooke/history"], count)
    first = coincident(args, 0.4)
    for count in (1, 2, 3):
        with pytest.raises(ValueError, match=f"spheres {i_l[first]} and {j_l[first]} are "
                                             "at the same position"):
            contacts(args, CONTACT_LAWS["hooke/history"], count)


def test_a_pour_on_two_threads_repeats_bit_for_bit(calls, monkeypatch):
    """Granular contacts with walls and gravity, forty steps of
    SphereVelocityVerlet on two threads, twice: the same positions, spins
    and shear history, bit for bit; and the first forces agree with one
    thread to round-off."""
    from ase_bpm import SphereVelocityVerlet
    from scenes import sphere_pile

    monkeypatch.setattr(compiled, "CONTACTS_THREADED_FROM", FEW)
    runs, first_forces = [], []
    for count in (2, 2, 1):
        compiled.set_threads(count)
        atoms = sphere_pile(n=5, seed=3, speed=0.5, spin=1.0, lift=0.45)
        law = dict(kn=2000.0, gamma_n=50.0, xmu=0.5)
        atoms.calc = ase_bpm.Granular("hooke/history", **law, kernels="compiled",
                                      fixes=[ase_bpm.Gravity(9.81),
                                             ase_bpm.GranularWall("hooke/history", **law)])
        first_forces.append(atoms.get_forces())
        if count == 2:
            SphereVelocityVerlet(atoms, 1e-3).run(40)
            runs.append(atoms)
    assert calls.count(2) > 80 and set(calls) == {1, 2}  # two runs of 41 calls, on threads
    a, b = runs
    for name in ("positions", "omega", "gran_shear", "ncontacts"):
        assert np.array_equal(a.arrays[name], b.arrays[name]), name
    # (partners by ID: each atoms object draws its own IDs)
    assert np.array_equal(a.arrays["gran_partner"] != 0, b.arrays["gran_partner"] != 0)
    assert a.arrays["ncontacts"].sum() > 50
    close(first_forces[0], first_forces[2], "forces")
