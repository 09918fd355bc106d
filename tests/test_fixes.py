"""External pieces (ase_bpm.scene.fixes) and the step-announcing integrator."""

import numpy as np
import pytest
from ase import Atoms

import ase_bpm
from ase_bpm import SphericalIndenter


def test_indenter_force_is_lammps_fix_indent_and_minus_energy_gradient():
    indenter = SphericalIndenter(k=3.0, radius=2.0, centre=(0, 0, 0), velocity=(0, -1, 0))
    atoms = Atoms("H3", positions=[[1.5, 0, 0], [0, -1.0, 0], [5, 5, 5]])
    forces, energy = indenter.forces(atoms, time=0.5)  # centre at (0, -0.5, 0)
    # particle 0: r = |(1.5, 0.5, 0)|, pushed out along that direction by K (R - r)^2
    d = np.array([1.5, 0.5, 0.0])
    r = np.linalg.norm(d)
    assert np.allclose(forces[0], 3.0 * (2.0 - r) ** 2 * d / r)
    assert np.allclose(forces[2], 0)
    h = 1e-7
    for n, c in [(0, 0), (0, 1), (1, 1)]:
        energies = []
        for sign in (1, -1):
            probe = atoms.copy()
            probe.positions[n, c] += sign * h
            energies.append(indenter.forces(probe, 0.5)[1])
        assert forces[n, c] == pytest.approx(-(energies[0] - energies[1]) / (2 * h), abs=1e-6)


def test_indenter_composes_with_bpm_spring_and_needs_a_clock():
    atoms = Atoms("H2", positions=[[0, 0, 0], [1.0, 0, 0]], masses=[1, 1])
    atoms.arrays["bonds"] = np.array(["1(1)", "_"])
    indenter = SphericalIndenter(k=10.0, radius=1.0, centre=(0.5, 3.0, 0),
                                 velocity=(0, -1.0, 0))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0)}, fixes=[indenter])
    atoms.get_forces()  # step 0: no time needed
    # the pair rests until the indenter arrives: ase_bpm's integrator keeps the clock
    dyn = ase_bpm.VelocityVerlet(atoms, timestep=0.1)
    dyn.run(30)
    assert atoms.info["bpm_step"] == 30
    assert atoms.get_velocities()[:, 1].min() < -0.05  # pushed down once reached
    # a calculator given a timestep refuses an integrator stepping another
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0)}, fixes=[indenter],
                                   timestep=0.1)
    with pytest.raises(ValueError, match=r"timestep mismatch: the calculator was given "
                                         r"timestep=0.1, the integrator steps 0.2"):
        ase_bpm.VelocityVerlet(atoms, timestep=0.2).run(1)


def test_a_fix_that_needs_time_without_a_timestep_is_refused():
    from ase.md.verlet import VelocityVerlet

    atoms = Atoms("H2", positions=[[0, 0, 0], [1.0, 0, 0]], masses=[1, 1])
    atoms.set_velocities([[0.1, 0, 0], [0, 0, 0]])
    atoms.calc = ase_bpm.BPMSpring(pair_coeffs={(1, 1): (1.0, 0.5, 0.0)},
                                   fixes=[SphericalIndenter(1.0, 1.0, (0, 5, 0))])
    atoms.get_forces()
    with pytest.raises(ValueError, match=r"SphericalIndenter needs the MD timestep"):
        VelocityVerlet(atoms, timestep=0.1).run(1)


def test_gravity_follows_a_changed_g():
    from ase import Atoms

    atoms = Atoms("H2", positions=[[0, 0, 0], [3, 0, 0]], masses=[1.0, 2.0])
    gravity = ase_bpm.Gravity(1.0)
    atoms.calc = ase_bpm.BPMSpring(fixes=[gravity])
    assert np.allclose(atoms.get_forces()[:, 2], [-1.0, -2.0])
    gravity.g = 5.0
    atoms.calc.refresh()
    assert np.allclose(atoms.get_forces()[:, 2], [-5.0, -10.0])
    gravity.direction = np.array([1.0, 0.0, 0.0])
    atoms.calc.refresh()
    assert np.allclose(atoms.get_forces()[:, 0], [5.0, 10.0])


@pytest.mark.parametrize("case", [str.lower, str.upper])
@pytest.mark.parametrize("axis", range(3))
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_gravity_along_a_signed_axis_is_that_unit_vector(axis, sign, case):
    """"-z" (or "-Z") is (0, 0, -1), the default, "+x" is (1, 0, 0) ...: the
    same forces, energy and LAMMPS line as the vector given as numbers."""
    name = case(("+" if sign > 0 else "-") + "xyz"[axis])
    vector = np.zeros(3)
    vector[axis] = sign
    atoms = Atoms("H2", positions=[[0, 0.5, 1.0], [3, -1.0, 2.0]], masses=[1.0, 2.0])
    by_name, by_vector = ase_bpm.Gravity(2.5, name), ase_bpm.Gravity(2.5, direction=vector)
    assert np.array_equal(by_name.direction, vector)
    f_nc, energy = by_name.forces(atoms, 0.0)
    assert np.array_equal(f_nc, 2.5 * np.outer([1.0, 2.0], vector))
    assert energy == -2.5 * sign * (atoms.positions[:, axis] @ [1.0, 2.0])
    assert by_name.lammps_commands(0) == by_vector.lammps_commands(0)
    assert by_name.todict() == by_vector.todict()
    if name.lower() == "-z":
        assert by_name.todict() == ase_bpm.Gravity(2.5).todict()


@pytest.mark.parametrize("direction,words", [
    ("z", r"direction 'z' has no sign: give '-z' or '\+z'"),
    ("x", r"direction 'x' has no sign: give '-x' or '\+x'"),
    ("down", r"direction 'down' is not a direction"),
    ("Z", r"direction 'Z' has no sign: give '-Z' or '\+Z'"),
    ("zz", r"direction 'zz' is not a direction"),
    ((0.0, -1.0), r"direction \(0.0, -1.0\) is not a direction"),
    ((0.0, 0.0, "down"), r"direction \(0.0, 0.0, 'down'\) is not a direction"),
    (None, r"direction None is not a direction"),
])
def test_gravity_refuses_a_direction_naming_the_forms_it_takes(direction, words):
    with pytest.raises(ValueError, match=rf"^Gravity: {words}; a direction is a 3-vector "
                                         r"such as \(0, 0, -1\), or a signed axis: '\+x', "
                                         r"'-x', '\+y', '-y', '\+z', '-z'$"):
        ase_bpm.Gravity(9.81, direction)


def test_gravity_refuses_a_g_that_is_not_a_number():
    with pytest.raises(ValueError, match=r"^Gravity: g must be a number, got 'heavy'$"):
        ase_bpm.Gravity("heavy")


def test_another_integrator_after_an_ase_bpm_one_does_not_run_on_its_clock():
    """The clock of a moving indenter runs on the timestep ase_bpm's
    integrator announced; ASE's own integrator stepping another timestep
    afterwards is refused (it placed the indenter at the old one's time),
    and at the same timestep it goes on."""
    from ase.md.verlet import VelocityVerlet as AseVelocityVerlet

    atoms = Atoms("H2", positions=[[0, 0, 0], [1.0, 0, 0]], masses=[1, 1])
    atoms.arrays["bonds"] = np.array(["1(1)", "_"])
    atoms.set_velocities([[0.01, 0.0, 0.0], [-0.01, 0.0, 0.0]])
    indenter = SphericalIndenter(k=10.0, radius=1.0, centre=(0.5, 3.0, 0),
                                 velocity=(0, -1.0, 0))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0)}, fixes=[indenter])
    ase_bpm.VelocityVerlet(atoms, timestep=0.1).run(5)
    AseVelocityVerlet(atoms, timestep=0.1).run(5)  # the same timestep: on it goes
    assert atoms.info["bpm_step"] == 10
    with pytest.raises(ValueError, match=r"timestep mismatch: the clock runs on the timestep "
                                         r"an ase_bpm integrator announced, 0.1, but the atoms "
                                         r"moved as a velocity Verlet step of 0.05"):
        AseVelocityVerlet(atoms, timestep=0.05).run(5)
    assert atoms.info["bpm_step"] == 10
