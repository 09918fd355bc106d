"""Granular physics: analytic collisions, rolling and sliding, conservation laws."""

import numpy as np
import pytest
from ase import Atoms

import ase_bpm
from ase_bpm import Granular, Gravity, GranularWall
from ase_bpm import SphereVelocityVerlet
from scenes import sphere_pile


def head_on(model, kn, gamma_n, v, dt, radius=0.5, mass=1.0):
    """Two equal spheres meet head on with relative speed ``v``: the ratio of
    separation to approach speed and the contact duration (to one step)."""
    atoms = Atoms("H2", positions=[[0.0, 0, 0], [2 * radius + 0.5 * v * dt, 0, 0]])
    atoms.set_masses([mass, mass])
    atoms.arrays["radius"] = np.array([radius, radius])
    atoms.set_velocities([[0.5 * v, 0, 0], [-0.5 * v, 0, 0]])
    atoms.calc = Granular(model, kn=kn, gamma_n=gamma_n, xmu=0.5)
    dyn = SphereVelocityVerlet(atoms, dt)
    touching = 0
    while True:
        dyn.run(1)
        if atoms.arrays["ncontacts"][0]:
            touching += 1
        elif touching:
            break
    v_nc = atoms.get_velocities()
    assert np.abs(v_nc[:, 1:]).max() == 0.0 and np.abs(atoms.arrays["omega"]).max() == 0.0
    return (v_nc[1, 0] - v_nc[0, 0]) / v, touching * dt


@pytest.mark.parametrize("model", ["hooke", "hooke/history"])
def test_restitution_of_a_hookean_collision(model):
    """Linear spring-dashpot: e = exp(-beta pi / omega_d), beta = gamma_n / 2,
    omega_d = sqrt(kn / meff - beta^2), for any impact speed."""
    kn, meff, dt = 1000.0, 0.5, 2e-5
    for gamma_n, v in [(0.0, 1.0), (5.0, 0.3), (20.0, 1.0), (50.0, 2.0)]:
        beta = 0.5 * gamma_n
        omega_d = np.sqrt(kn / meff - beta ** 2)
        e, duration = head_on(model, kn, gamma_n, v, dt)
        assert e == pytest.approx(np.exp(-beta * np.pi / omega_d), rel=2e-3, abs=1e-9)
        assert duration == pytest.approx(np.pi / omega_d, abs=1.5 * dt)


def test_hertzian_contact_duration_scales_as_v_to_the_minus_one_fifth():
    """Elastic Hertz contact: t_c = 2.9432 delta_max / v with
    (2/5) kn sqrt(R_eff) delta_max^(5/2) = meff v^2 / 2, i.e. t_c ~ v^(-1/5)."""
    kn, meff, reff, dt = 1e4, 0.5, 0.25, 2e-5
    speeds = np.array([0.1, 0.3, 1.0, 3.0])
    durations = []
    for v in speeds:
        e, duration = head_on("hertz/history", kn, 0.0, v, dt)
        assert e == pytest.approx(1.0, abs=1e-6)  # elastic
        delta_max = (5 * meff * v ** 2 / (4 * kn * np.sqrt(reff))) ** 0.4
        assert duration == pytest.approx(2.9432 * delta_max / v, abs=1.5 * dt)
        durations.append(duration)
    slope = np.polyfit(np.log(speeds), np.log(durations), 1)[0]
    assert slope == pytest.approx(-0.2, abs=2e-3)


def roll_down(theta_deg, mu, model, seconds=0.6, dt=2e-4, g=10.0, radius=0.5):
    """A sphere released on a floor with gravity tilted by theta: its
    acceleration down the slope (second half of the run) and the slip
    velocity of its contact point."""
    theta = np.radians(theta_deg)
    atoms = Atoms("H", positions=[[0, 0, radius]])
    atoms.set_masses([1.0])
    atoms.arrays["radius"] = np.array([radius])
    kn = 1e5 if model != "hertz/history" else 1e6
    # the pair-style law: LAMMPS' own hertz/history wall loses its grip after
    # each slip (see GranularWall), which spoils rolling near the friction angle
    floor = GranularWall(model, kn=kn, gamma_n=100.0, xmu=mu, axis="z", lo=0.0, pair_law=True)
    slope = Gravity(g, (np.sin(theta), 0.0, -np.cos(theta)))
    atoms.calc = Granular(model, kn=kn, gamma_n=100.0, xmu=mu, fixes=[slope, floor])
    dyn = SphereVelocityVerlet(atoms, dt)
    t, v, slip = [], [], []
    for step in range(int(seconds / dt)):
        dyn.run(1)
        t.append(step * dt)
        v.append(atoms.get_velocities()[0, 0])
        slip.append(v[-1] - radius * atoms.arrays["omega"][0, 1])
    half = len(t) // 2
    return np.polyfit(t[half:], v[half:], 1)[0], np.array(slip[half:]), v[-1], g, theta


@pytest.mark.parametrize("model", ["hooke/history", "hertz/history"])
def test_sphere_on_an_incline_rolls_below_the_friction_angle_and_slides_above(model):
    """A solid sphere rolls without slipping, a = 5/7 g sin(theta), while
    tan(theta) < 7/2 mu; beyond, it slides with a = g (sin - mu cos)."""
    mu = 0.3
    critical = np.degrees(np.arctan(3.5 * mu))  # 46.4 degrees
    for angle in (20.0, critical - 6.0):
        acc, slip, v_end, g, theta = roll_down(angle, mu, model)
        assert acc == pytest.approx(5 / 7 * g * np.sin(theta), rel=2e-3)
        # rolling: the contact point only rocks on the tangential spring
        assert np.abs(slip).max() < 2e-2 * v_end and abs(slip.mean()) < 1e-2 * v_end
    for angle in (critical + 6.0, 70.0):
        acc, slip, v_end, g, theta = roll_down(angle, mu, model)
        assert acc == pytest.approx(g * (np.sin(theta) - mu * np.cos(theta)), rel=1e-3)
        # sliding: friction mu N spins the sphere up, slip grows at
        # g (sin - 7/2 mu cos)
        slip_rate = np.polyfit(np.arange(len(slip)) * 2e-4, slip, 1)[0]
        assert slip_rate == pytest.approx(g * (np.sin(theta) - 3.5 * mu * np.cos(theta)),
                                          rel=1e-2)
        assert slip.min() > 0.1 * v_end


@pytest.mark.parametrize("model", ["hooke", "hooke/history", "hertz/history"])
def test_isolated_cluster_conserves_linear_momentum(model):
    atoms = sphere_pile(seed=8, speed=1.0, spin=3.0)
    atoms.calc = Granular(model, kn=1000.0, gamma_n=20.0, xmu=0.3)
    p0 = atoms.get_momenta().sum(axis=0)
    scale = np.abs(atoms.get_momenta()).sum()
    dyn = SphereVelocityVerlet(atoms, 1e-3)
    for _ in range(6):
        dyn.run(50)
        assert np.abs(atoms.get_momenta().sum(axis=0) - p0).max() <= 1e-13 * scale
    assert np.abs(atoms.get_momenta().sum(axis=0) - p0).max() <= 1e-13 * scale
    assert np.abs(atoms.get_forces().sum(axis=0)).max() <= 1e-12 * np.abs(
        atoms.get_forces()).max()


def energy_drift(model, dt, steps_per_unit, units=0.3):
    """Largest change of kinetic + rotational + elastic + dissipated energy
    over a run of a damped, frictional granular gas in a box with walls."""
    atoms = sphere_pile(seed=9, speed=1.0, spin=3.0, lift=0.6)
    walls = [GranularWall(model, kn=2000.0, gamma_n=10.0, xmu=0.3, axis="z", lo=0.0),
             GranularWall(model, kn=2000.0, gamma_n=10.0, xmu=0.3, axis="x", lo=-0.6, hi=3.6)]
    atoms.calc = Granular(model, kn=1000.0, gamma_n=10.0, xmu=0.3,
                          fixes=[Gravity(5.0)] + walls)

    def total():
        return (atoms.get_kinetic_energy() + ase_bpm.rotational_energy(atoms)
                + atoms.get_potential_energy() + atoms.calc.results["dissipated_energy"])

    start = total()
    dyn = SphereVelocityVerlet(atoms, dt)
    drift = 0.0
    for _ in range(int(units / dt / steps_per_unit)):
        dyn.run(steps_per_unit)
        drift = max(drift, abs(total() - start))
    assert atoms.calc.results["dissipated_energy"] > 0.1 * start
    return drift / start


@pytest.mark.parametrize("model", ["hooke/history", "hertz/history"])
def test_energy_ledger_closes_to_order_dt_squared(model):
    """Damping, tangential springs and friction do work that the ledger books
    (translation and rotation): the total is conserved to O(dt^2)."""
    coarse = energy_drift(model, 2e-4, 25)
    fine = energy_drift(model, 1e-4, 50)
    assert coarse < 5e-3
    assert fine < coarse / 3.0


def test_rotation_follows_a_constant_torque_with_solid_sphere_inertia():
    """omega(t) = omega0 + tau t / (2/5 m r^2) exactly under velocity Verlet."""
    class Spinner:  # a test piece: a constant torque on every sphere
        needs_time = False

        def contribute(self, atoms, clock):
            from ase_bpm.scene.fixes import Contribution
            return Contribution(np.zeros((len(atoms), 3)), 0.0,
                                torques=np.tile([0.0, 0.3, -0.2], (len(atoms), 1)))

        def todict(self):
            return {"type": "Spinner"}

    atoms = Atoms("H2", positions=[[0, 0, 0], [5, 0, 0]])
    atoms.set_masses([2.0, 0.5])
    atoms.arrays["radius"] = np.array([0.5, 0.25])
    atoms.arrays["omega"] = np.array([[1.0, 0, 0], [0, 0, 2.0]])
    atoms.calc = Granular("hooke", kn=1.0, gamma_n=0.0, xmu=0.0, fixes=[Spinner()])
    SphereVelocityVerlet(atoms, 0.01).run(100)
    inertia = 0.4 * np.array([2.0, 0.5]) * np.array([0.5, 0.25]) ** 2
    expected = np.array([[1.0, 0, 0], [0, 0, 2.0]]) + np.outer(1.0 / inertia,
                                                                [0.0, 0.3, -0.2])
    assert np.abs(atoms.arrays["omega"] - expected).max() <= 1e-12 * np.abs(expected).max()
    assert np.abs(atoms.positions - [[0, 0, 0], [5, 0, 0]]).max() == 0.0
