"""One harness over every registered bond and contact law.

As LAMMPS's force-style unit tests (one harness, a data file per style), each
law registered in ``ase_bpm.laws.bond.LAWS`` or
``ase_bpm.laws.contact.CONTACT_LAWS`` passes through the same checks, driven
through the public calculators with the law's entry in
``tests/every_law_data.py``:

* the third law: without fixes the forces sum to zero;
* the energy is the potential of the forces (central finite differences);
* ``stiffness`` is at least the tangent of the force along the bond or
  contact (what ``stable_timestep`` is built on);
* the NumPy and compiled kernels agree to 1e-12 (laws with a compiled twin);
* a restart file continues bit for bit;
* a pure evaluation gives the next step's forces and changes nothing;
* the LAMMPS export gives LAMMPS's forces (the reference build's oracle).

A law registered without an entry fails here, asking for one.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import ase_bpm
from ase_bpm.laws import timestep as stability
from ase_bpm.laws.bond import LAWS, BondLaw, register
from ase_bpm.laws.contact import CONTACT_LAWS
import every_law_data
from every_law_data import GRANULAR, PERI, SPRING

BOND, CONTACT = "bond", "contact"
#: the registry and the data of each kind of law
KINDS = {BOND: (LAWS, every_law_data.BOND_LAWS),
         CONTACT: (CONTACT_LAWS, every_law_data.CONTACT_LAWS)}
EVERY_LAW = [(kind, name) for kind, (registry, _) in KINDS.items() for name in sorted(registry)]
IDS = [f"{kind}:{name}" for kind, name in EVERY_LAW]
every_law = pytest.mark.parametrize("kind, name", EVERY_LAW, ids=IDS)
#: steps taken by hand (forces at displaced positions) do not turn spheres
#: (bpm/rotational's scene is turned a little before its bonds take their
#: reference state, the harder case: RotatedReferenceWarning says so)
pytestmark = [pytest.mark.filterwarnings("ignore::ase_bpm.SpinNotIntegratedWarning"),
              pytest.mark.filterwarnings("ignore::ase_bpm.RotatedReferenceWarning")]

FINITE_STEP = 1e-3  # of the jitter: the step of the energy's finite differences
SEED = 11


def case_of(kind: str, name: str) -> every_law_data.LawCase:
    """The law's entry in tests/every_law_data.py; a registered law without
    one fails, saying what to add."""
    registry, data = KINDS[kind]
    case = data.get(name)
    if case is None:
        pytest.fail(f"the {kind} law {name!r} is registered but has no entry in "
                    f"tests/every_law_data.py: add one to its {kind.upper()}_LAWS (a "
                    "calculator with the law's coefficients, a scene that exercises it, "
                    "two particles for its stiffness) so that this harness runs it",
                    pytrace=False)
    return case


def route_key(kind: str, name: str) -> str:
    """The law's key in ``calc.kernel_routes``."""
    return name if kind == BOND else "contacts"


def integrator(case, atoms):
    md = ase_bpm.SphereVelocityVerlet if case.spheres else ase_bpm.VelocityVerlet
    return md(atoms, case.dt)


def displacement(case, atoms, seed=SEED) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-case.jitter, case.jitter, atoms.positions.shape)


def prepared(case, kernels: str = "auto", still: bool = False):
    """The law's scene with its calculator: the first evaluation (the
    reference state), then displaced; ``still``: at rest (no velocities,
    no spins) and not evaluated since."""
    atoms = case.scene()
    if still:
        atoms.set_velocities(np.zeros((len(atoms), 3)))
        if "omega" in atoms.arrays:
            atoms.arrays["omega"] = np.zeros((len(atoms), 3))
    atoms.calc = case.calc(kernels)
    atoms.get_forces()
    atoms.positions = atoms.positions + displacement(case, atoms)
    return atoms


def relative(a, b) -> float:
    """The largest difference over the largest magnitude of ``b``."""
    return float(np.abs(np.asarray(a) - b).max() / (np.abs(b).max() or 1.0))


def state_of(atoms) -> tuple:
    """Everything on the atoms, copied."""
    return ({k: np.array(v) for k, v in atoms.arrays.items()}, copy.deepcopy(atoms.info))


def assert_same_state(before: tuple, after: tuple) -> None:
    assert before[0].keys() == after[0].keys()
    for key, value in before[0].items():
        assert np.array_equal(value, after[0][key], equal_nan=value.dtype.kind == "f"), key
    assert before[1].keys() == after[1].keys()
    for key, value in before[1].items():
        same = (np.array_equal(value, after[1][key], equal_nan=True)
                if isinstance(value, np.ndarray) else value == after[1][key])
        assert same, key


# -- every registered law has its data ---------------------------------------------------
@every_law
def test_the_law_has_an_entry_that_exercises_it(kind, name):
    case = case_of(kind, name)
    atoms = prepared(case)
    forces = atoms.get_forces()
    assert np.abs(forces).max() > 0  # the scene is not at rest
    route = atoms.calc.kernel_routes.get(route_key(kind, name))
    assert route in ("compiled", "numpy")  # the calculator runs the law


def test_a_law_registered_without_an_entry_fails_asking_for_one():
    class Unlisted(BondLaw):
        name = "test-every-law-unlisted"
        coefficients = ("k",)

    register(Unlisted)
    try:
        with pytest.raises(pytest.fail.Exception,
                           match=r"the bond law 'test-every-law-unlisted' is registered but "
                                 r"has no entry in tests/every_law_data.py: add one"):
            case_of(BOND, Unlisted.name)
    finally:
        LAWS.pop(Unlisted.name)


def test_every_entry_is_a_registered_law():
    for kind, (registry, data) in KINDS.items():
        assert set(data) <= set(registry), f"entries of {kind} laws no longer registered"


# -- the checks --------------------------------------------------------------------------
@every_law
def test_the_forces_sum_to_zero(kind, name):
    atoms = prepared(case_of(kind, name))
    forces = atoms.get_forces()
    assert np.abs(forces.sum(axis=0)).max() <= 1e-12 * np.abs(forces).max() * len(atoms)


@every_law
def test_the_energy_is_the_potential_of_the_forces(kind, name):
    """Central differences of the energy, in pure evaluations at rest,
    against the forces, for each coordinate of a few particles."""
    case = case_of(kind, name)
    if case.not_potential:
        pytest.skip(case.not_potential)
    atoms = prepared(case, still=True)
    with ase_bpm.pure(atoms):
        forces = atoms.get_forces()
    h = FINITE_STEP * case.jitter
    x = atoms.positions.copy()
    worst = 0.0
    for n in np.argsort(-np.abs(forces).max(axis=1))[:4]:  # the most loaded particles
        for c in range(3):
            energies = []
            for sign in (1, -1):
                atoms.positions = x
                atoms.positions[n, c] += sign * h
                with ase_bpm.pure(atoms):
                    energies.append(atoms.get_potential_energy())
            worst = max(worst, abs(-(energies[0] - energies[1]) / (2 * h) - forces[n, c]))
    assert worst <= 1e-6 * np.abs(forces).max()


@every_law
def test_the_stiffness_is_at_least_the_tangent(kind, name, monkeypatch):
    """Two particles joined by one bond or contact: the stiffness along it
    that ``stable_timestep`` takes (the law's ``stiffness``) against the
    tangent of the force along it, by central differences."""
    case = case_of(kind, name)
    atoms = case.pair()
    atoms.calc = case.calc("auto", **case.pair_parameters)
    atoms.get_forces()
    atoms.positions[1, 0] += case.stretch
    springs = []
    estimate = stability.stiffest

    def caught(found, *args, **kwargs):
        springs.extend(found)
        return estimate(found, *args, **kwargs)

    monkeypatch.setattr(stability, "stiffest", caught)
    atoms.calc.stable_timestep(atoms)
    k = 0.0
    for group in springs:
        for piece in (group.pieces() if hasattr(group, "pieces") else [group]):
            if piece is not None and len(piece):
                k += float(np.sum(np.broadcast_to(piece.k_x, (len(piece),))))
    h = 1e-4 * abs(case.stretch)
    x = atoms.positions.copy()
    along = []
    for sign in (1, -1):
        atoms.positions = x
        atoms.positions[1, 0] += sign * h
        with ase_bpm.pure(atoms):
            along.append(atoms.get_forces()[1, 0])
    tangent = -(along[0] - along[1]) / (2 * h)
    assert tangent > 0  # the pair is joined: its force stiffens along it
    assert k >= tangent * (1 - 1e-6)


@every_law
@pytest.mark.compiled
def test_numpy_and_compiled_kernels_agree(kind, name):
    case = case_of(kind, name)
    runs = {kernels: prepared(case, kernels) for kernels in ("numpy", "compiled")}
    if runs["compiled"].calc.kernel_routes[route_key(kind, name)] != "compiled":
        pytest.skip(f"the {kind} law {name!r} has no compiled twin: NumPy on both routes")
    for atoms in runs.values():
        atoms.get_forces()
        integrator(case, atoms).run(5)
    numpy, compiled = runs["numpy"], runs["compiled"]
    assert relative(compiled.get_forces(), numpy.get_forces()) <= 1e-12
    assert compiled.get_potential_energy() == pytest.approx(numpy.get_potential_energy(),
                                                            rel=1e-12, abs=1e-300)
    assert relative(compiled.positions, numpy.positions) <= 1e-12


@every_law
def test_a_restart_continues_bit_for_bit(kind, name, tmp_path):
    case = case_of(kind, name)
    atoms = prepared(case)
    straight = atoms.copy()
    straight.calc = case.calc("auto")
    integrator(case, straight).run(10)

    integrator(case, atoms).run(5)
    ase_bpm.write_restart(tmp_path / "law.bpm", atoms)
    resumed = ase_bpm.read_restart(tmp_path / "law.bpm")
    resumed.calc = case.calc("auto")
    integrator(case, resumed).run(5)
    assert np.array_equal(resumed.positions, straight.positions)
    assert np.array_equal(resumed.get_forces(), straight.get_forces())
    assert np.array_equal(resumed.get_velocities(), straight.get_velocities())


@every_law
def test_a_pure_evaluation_is_a_step_that_changes_nothing(kind, name):
    """A pure evaluation at the next step's positions writes nothing on the
    atoms, gives that step's forces and energy (on a twin of the atoms,
    which takes the step) unless the step advances history, and the run
    goes on bit for bit after it."""
    case = case_of(kind, name)
    atoms = prepared(case)
    integrator(case, atoms).run(3)
    twin, untouched = atoms.copy(), atoms.copy()  # (untouched: runs on without the block)
    twin.calc, untouched.calc = case.calc("auto"), case.calc("auto")
    x = atoms.positions.copy()  # where the last step was
    twin.positions = x + case.dt * atoms.get_velocities()
    with ase_bpm.pure(atoms):
        atoms.positions = twin.positions
        before = state_of(atoms)
        pure_forces = atoms.get_forces()
        pure_energy = atoms.get_potential_energy()
        assert_same_state(before, state_of(atoms))
        atoms.positions = x  # back where the block was entered
    twin_forces = twin.get_forces()
    assert twin.info["bpm_step"] == atoms.info["bpm_step"] + 1  # the twin took a step
    if case.history is None:
        assert np.array_equal(twin_forces, pure_forces)
        assert twin.get_potential_energy() == pure_energy
    else:  # the step advanced the history, which the pure evaluation read
        assert not np.array_equal(twin_forces, pure_forces), case.history

    for each in (atoms, untouched):  # on as if the block had never been
        integrator(case, each).run(3)
    assert np.array_equal(atoms.positions, untouched.positions)
    assert np.array_equal(atoms.get_forces(), untouched.get_forces())


@every_law
def test_the_lammps_export_gives_lammps_forces(kind, name, Oracle):
    case = case_of(kind, name)
    if case.oracle is None:
        pytest.skip(case.no_oracle)
    atoms = case.scene()
    atoms.calc = case.calc("auto", **case.oracle_parameters)
    if not case.spheres:  # the reference state, then a deformed one
        atoms.get_forces()
    lmp = oracle(case, atoms)
    try:
        if not case.spheres:
            lmp.run(0)
            x = atoms.positions + displacement(case, atoms)
            atoms.positions = x
            lmp.set("x", x)
            lmp.set("v", atoms.get_velocities())
        # (spheres: no reference state; LAMMPS's run 0 is a first evaluation)
        forces = atoms.get_forces()
        lmp.run(0)
        expected = lmp.forces() if hasattr(lmp, "forces") else lmp.get("f")
        assert relative(forces, expected) <= 1e-9
        if case.spheres:
            torques = atoms.calc.get_property("torques", atoms)
            assert relative(torques, lmp.get("torque")) <= 1e-9
    finally:
        lmp.close()


def oracle(case, atoms):
    """The reference build holding the exported scene (tests/oracle.py and
    its kin; the ``Oracle`` fixture made sure LAMMPS loads)."""
    if case.oracle == SPRING:
        from oracle import Oracle

        return Oracle(atoms, atoms.calc, timestep=case.dt)
    if case.oracle == PERI:
        from peri_oracle import PeriOracle

        return PeriOracle(atoms, atoms.calc, timestep=case.dt)
    assert case.oracle == GRANULAR, case.oracle
    from granular_oracle import GranularOracle

    return GranularOracle(atoms, atoms.calc, case.dt)
