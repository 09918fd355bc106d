"""The blow-up guard: non-finite forces, torques or energy stop a step with
UnstableSimulationError, naming step, particle and quantity, with nothing of
that step written to the atoms."""

import numpy as np
import pytest
from ase import Atoms

import ase_bpm
import ase_bpm.models.guard
from ase_bpm import VelocityVerlet
from scenes import fcc_cluster
from state import assert_unchanged, snapshot

SPRING = dict(bond_coeffs={1: (1.0, 0.1, 0.0)})


class Kick:
    """A fix that pushes one particle with ``value`` from time ``at`` on."""

    needs_time = True  # follows the clock: time = step * timestep

    def __init__(self, atom: int, value: float, at: int):
        self.atom, self.value, self.at = atom, value, at

    def forces(self, atoms, time):
        f_nc = np.zeros((len(atoms), 3))
        if time >= self.at:
            f_nc[self.atom, 1] = self.value
        return f_nc, 0.0

    def todict(self):
        return {"type": "Kick", "atom": self.atom, "value": self.value, "at": self.at}


def block(seed=0):
    atoms, rng = fcc_cluster(2, seed=seed)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.01, atoms.positions.shape))
    return atoms


def test_unstable_error_is_a_runtime_error():
    assert issubclass(ase_bpm.UnstableSimulationError, RuntimeError)


@pytest.mark.parametrize("value", [np.inf, np.nan])
def test_non_finite_force_stops_the_step_and_keeps_the_state(value):
    atoms = block()
    atoms.calc = ase_bpm.BPMSpring(**SPRING, timestep=0.01, fixes=[Kick(3, value, 0.05)])
    dyn = VelocityVerlet(atoms, timestep=0.01)
    with pytest.raises(ase_bpm.UnstableSimulationError) as caught:
        for _ in range(20):
            before = snapshot(atoms)
            dyn.run(1)
    message = str(caught.value)
    assert "particle 3" in message and "force" in message and "step 5" in message
    assert "timestep 0.01" in message
    # the failed evaluation wrote nothing: all is as after the last good step,
    # but for the drift the integrator made before asking for forces
    arrays, info = before
    for name in set(arrays) - {"positions", "momenta"}:
        assert np.array_equal(atoms.arrays[name], arrays[name],
                              equal_nan=arrays[name].dtype.kind == "f"), name
    assert set(atoms.arrays) == set(arrays)
    assert {k: str(v) for k, v in atoms.info.items()} == {k: str(v) for k, v in info.items()}
    assert atoms.info["bpm_step"] == 4


def test_non_finite_energy_stops_a_pure_evaluation_too():
    class NanEnergy(Kick):
        def forces(self, atoms, time):
            return np.zeros((len(atoms), 3)), float("nan")

    atoms = block()
    atoms.calc = ase_bpm.BPMSpring(**SPRING, fixes=[NanEnergy(0, 0.0, 0.0)])
    before = snapshot(atoms)
    with ase_bpm.pure(atoms):
        with pytest.raises(ase_bpm.UnstableSimulationError, match="step 0: the energy is nan"):
            atoms.get_potential_energy()
    assert_unchanged(atoms, before)


def spring_pair(k=2.0):
    """Two unit masses on one spring (w = sqrt(2 k / m)), stretched by 0.1;
    velocity Verlet is stable below dt = 2 / w."""
    atoms = Atoms("H2", positions=[[0, 0, 0], [1.0, 0, 0]], masses=[1, 1])
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (k, 1e300, 0.0)})
    atoms.get_forces()  # reference length 1
    atoms.positions[1, 0] = 1.1
    return atoms


def test_runaway_kinetic_energy_stops_the_run_within_a_few_steps(monkeypatch):
    monkeypatch.setattr(ase_bpm.models.guard, "BEYOND_LIMIT", np.inf)  # (it would stop first)
    atoms = spring_pair()  # w = 2: limit dt = 1; at dt = 3 the energy grows ~50-fold a step
    dyn = VelocityVerlet(atoms, timestep=3.0)
    with pytest.warns(ase_bpm.TimestepWarning, match="the timestep 3 is 3.33 times"), \
            pytest.raises(ase_bpm.UnstableSimulationError,
                          match=r"step \d+ \(timestep 3\): the kinetic energy grew more than "
                                r"10-fold in each of the last 4 steps.*fastest particle is [01]"
                                r".*suggests at most 0.9 at step \d+'s positions \(0.9 at the "
                                r"run's first state, step 1\)"):  # (step 1: the stretch by hand)
        dyn.run(1000)
    assert atoms.info["bpm_step"] <= 10


def test_overflow_is_caught_without_the_runaway_check(monkeypatch):
    monkeypatch.setattr(ase_bpm.models.guard, "RUNAWAY_STEPS", 10 ** 9)
    monkeypatch.setattr(ase_bpm.models.guard, "BEYOND_LIMIT", np.inf)
    atoms = spring_pair()
    dyn = VelocityVerlet(atoms, timestep=3.0)
    with pytest.warns(ase_bpm.TimestepWarning), \
            pytest.raises(ase_bpm.UnstableSimulationError,
                          match=r"step \d+ \(timestep 3\): the (force|energy|position)"), \
            np.errstate(over="ignore", invalid="ignore"):
        dyn.run(1000)
    assert atoms.info["bpm_step"] < 1000
    assert np.isfinite(atoms.arrays["bpm_x_last"]).all()  # the record: the last good step


def test_the_guard_can_be_switched_off():
    atoms = spring_pair()
    atoms.calc.guard = False
    with np.errstate(over="ignore", invalid="ignore"):
        VelocityVerlet(atoms, timestep=3.0).run(20)  # blows up, unguarded
    assert atoms.info["bpm_step"] == 21
    assert ase_bpm.BPMSpring(guard=False).guard is False


def test_stable_oscillation_near_the_limit_is_not_stopped():
    atoms = spring_pair()
    with pytest.warns(ase_bpm.TimestepWarning, match="the timestep 0.95 is 1.06 times"):
        VelocityVerlet(atoms, timestep=0.95).run(2000)  # w dt = 1.9 < 2, above the estimate
    assert atoms.info["bpm_step"] == 2001


# -- the guard on the scenes of the stable-timestep tests -------------------------------

from ase.md.langevin import Langevin  # noqa: E402

from ase_bpm import SphereVelocityVerlet  # noqa: E402
from test_stable_timestep import CASES  # noqa: E402

MODELS = ["spring", "spring-damped", "peri-pmb", "peri-lps", "hooke", "hertz/history-damped"]


def integrate(atoms, dt):
    return (SphereVelocityVerlet if "radius" in atoms.arrays else VelocityVerlet)(atoms, dt)


def total_energy(atoms):
    return (atoms.get_kinetic_energy() + ase_bpm.rotational_energy(atoms)
            + atoms.get_potential_energy())


@pytest.mark.parametrize("case", MODELS)
def test_half_the_estimate_runs_2000_steps_untouched(case):
    atoms = CASES[case]()
    dyn = integrate(atoms, 0.5 * atoms.calc.stable_timestep(atoms))
    e0 = total_energy(atoms)
    for _ in range(20):
        dyn.run(100)
        kinetic = atoms.get_kinetic_energy() + ase_bpm.rotational_energy(atoms)
        assert np.isfinite(atoms.get_forces()).all() and kinetic <= 1.2 * e0
    assert atoms.info["bpm_step"] == 2000


@pytest.mark.parametrize("case", MODELS)
def test_four_times_the_estimate_stops_at_the_first_step(case):
    atoms = CASES[case]()
    estimate = atoms.calc.stable_timestep(atoms)
    dyn = integrate(atoms, 4.0 * estimate)
    with pytest.raises(ase_bpm.UnstableSimulationError,
                       match=r"step 1 \(timestep [\d.e+-]+\): the timestep is 4 times the "
                             r"stable timestep [\d.e+-]+ at step 0's positions, the run's "
                             r"first state \(the stiffest particle is \d+\), more than 3 times"):
        dyn.run(300)


@pytest.mark.parametrize("case", ["spring", "spring-damped", "peri-pmb", "peri-lps"])
def test_the_run_time_checks_alone_stop_a_bonded_blow_up(case, monkeypatch):
    """Without the check of the timestep against the estimate, the ledger or
    the kinetic energy stops the run within a few steps."""
    monkeypatch.setattr(ase_bpm.models.guard, "BEYOND_LIMIT", np.inf)
    atoms = CASES[case]()
    dyn = integrate(atoms, 4.0 * atoms.calc.stable_timestep(atoms))
    with pytest.warns(ase_bpm.TimestepWarning, match="is 4 times"), \
            pytest.raises(ase_bpm.UnstableSimulationError,
                          match="energy ledger is off|kinetic energy grew"), \
            np.errstate(over="ignore", invalid="ignore"):
        dyn.run(300)
    assert atoms.info["bpm_step"] <= 20


def breaking_block(fixes=()):
    """The spring block of the stable-timestep tests, breaking at 3 % strain."""
    atoms = CASES["spring-damped"]()
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.03, 1.0)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 1.0)}, fixes=fixes)
    return atoms


@pytest.mark.parametrize("scene", ["breaking", "gravity", "indenter", "langevin"])
def test_energy_brought_in_or_released_is_no_blow_up(scene):
    centre = CASES["spring"]().positions.mean(axis=0) + [0.0, 0.0, 4.0]
    fixes = {"gravity": [ase_bpm.Gravity(0.05)],
             "indenter": [ase_bpm.SphericalIndenter(10.0, 1.5, centre, (0.0, 0.0, -0.05))],
             }.get(scene, [])
    atoms = breaking_block(fixes)
    dt = 0.5 * atoms.calc.stable_timestep(atoms)
    if scene == "indenter" or scene == "gravity":
        atoms.calc.parameters["timestep"] = dt  # the clock of the fixes
    if scene == "langevin":  # from rest, heated by ASE's thermostat
        atoms.set_velocities(np.zeros((len(atoms), 3)))
        dyn = Langevin(atoms, dt, temperature_K=300.0, friction=0.05, fixcm=False)
    else:
        dyn = VelocityVerlet(atoms, dt)
    bonds = len(ase_bpm.get_bonds(atoms)[0])
    if scene == "langevin":  # (no timestep=: the thermostat's cannot be told)
        with pytest.warns(ase_bpm.TimestepUncheckedWarning):
            dyn.run(2000)
    else:
        dyn.run(2000)
    assert np.isfinite(atoms.get_forces()).all()
    if scene == "breaking":
        assert len(ase_bpm.get_bonds(atoms)[0]) < bonds  # bonds did break


def test_a_hand_move_before_the_run_does_not_use_up_the_limit_check():
    atoms = spring_pair()  # evaluated, then stretched by hand: no timestep to judge
    atoms.get_forces()
    dyn = VelocityVerlet(atoms, timestep=4.0)
    with pytest.raises(ase_bpm.UnstableSimulationError, match="more than 3 times"):
        dyn.run(10)
    assert atoms.info["bpm_step"] == 1  # the first real step was checked


def test_raising_the_timestep_mid_run_is_checked_again():
    atoms = spring_pair()
    dyn = VelocityVerlet(atoms, timestep=0.5)
    dyn.run(10)
    dyn.dt = 4.0
    with pytest.raises(ase_bpm.UnstableSimulationError, match="more than 3 times"):
        dyn.run(10)
    assert atoms.info["bpm_step"] == 11


def test_an_earlier_integrators_timestep_is_not_held_against_another_run():
    from ase.md.verlet import VelocityVerlet as AseVelocityVerlet

    first, second = spring_pair(), spring_pair(k=0.5)
    calc = first.calc
    VelocityVerlet(first, timestep=0.8).run(3)  # announces dt = 0.8 to calc
    second.calc = calc
    dt = 0.5 * calc.stable_timestep(second)
    AseVelocityVerlet(second, timestep=dt).run(20)  # judged by its own dt, not 0.8


def test_two_atoms_objects_keep_their_own_watch(monkeypatch):
    monkeypatch.setattr(ase_bpm.models.guard, "BEYOND_LIMIT", np.inf)
    a, b = spring_pair(), spring_pair()
    b.calc = a.calc
    runs = [VelocityVerlet(a, timestep=3.0), VelocityVerlet(b, timestep=3.0)]
    with pytest.warns(ase_bpm.TimestepWarning), \
            pytest.raises(ase_bpm.UnstableSimulationError, match="kinetic energy grew"), \
            np.errstate(over="ignore", invalid="ignore"):
        for _ in range(50):
            for dyn in runs:
                dyn.run(1)
    assert max(a.info["bpm_step"], b.info["bpm_step"]) <= 10


@pytest.mark.parametrize("scene", ["granular", "rotational"])
def test_damping_that_slows_a_spinning_sphere_is_no_blow_up(scene):
    """A sphere spinning fast against its neighbours while nothing else
    moves: the damping takes rotational energy, which the ledger check
    counts as energy in play (it once counted only the translational and
    stopped such runs as blown up)."""
    atoms = Atoms("Ar2", positions=[[0, 0, 0], [0.98, 0, 0]], masses=[1.0, 1.0])
    atoms.arrays["radius"] = np.full(2, 0.5)
    atoms.arrays["omega"] = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 0.0]])
    if scene == "granular":
        atoms.calc = ase_bpm.Granular("hooke/history", kn=100.0, gamma_n=10.0, xmu=0.5)
    else:
        ase_bpm.create_bonds(atoms, 1.0)
        atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (
            "bpm/rotational", 100.0, 20.0, 2.0, 2.0, 1e3, 1e3, 1e3, 1e3, 1.0, 1.0, 1.0, 1.0)})
    spin = ase_bpm.rotational_energy(atoms)
    ase_bpm.SphereVelocityVerlet(atoms, timestep=0.2 * atoms.calc.stable_timestep(atoms)).run(50)
    assert ase_bpm.rotational_energy(atoms) < 0.9 * spin  # the damping took some
    assert atoms.calc.results["dissipated_energy"] > 0.0
