"""Granular against the reference LAMMPS build: gran/hooke, gran/hooke/history,
gran/hertz/history, fix nve/sphere, fix wall/gran, fix gravity, fix freeze."""

import numpy as np
import pytest
from ase.constraints import FixAtoms

import ase_bpm
from ase_bpm import SphereVelocityVerlet
from ase_bpm.core.neighbours import minimum_image, neighbour_pairs
from scenes import fcc_cluster, sphere_pile

pytestmark = pytest.mark.oracle
MODELS = ["hooke", "hooke/history", "hertz/history"]
DT = 1e-3
STEPS = 400
#: both kernels against LAMMPS where it matters most ("auto", compiled where
#: built, everywhere else)
KERNELS = ["numpy", "auto"]


@pytest.fixture(scope="module")
def GranularOracle(Oracle):  # the Oracle fixture fails in CI without LAMMPS
    from granular_oracle import GranularOracle

    return GranularOracle


def calculator(model, fixes=(), **kwargs):
    # Hertz stiffness is per unit sqrt(overlap * R_eff) (~0.15 here)
    kn = 6000.0 if model == "hertz/history" else 1000.0
    kwargs = {"kn": kn, "gamma_n": 20.0, "xmu": 0.3, **kwargs}
    return ase_bpm.Granular(model, fixes=list(fixes), **kwargs)


def box_walls(model, kernels="auto", friction=True):
    """A floor and four side walls, each with its own coefficients (and
    ``xmu = 0`` for all without ``friction``)."""
    kn = 8000.0 if model == "hertz/history" else 1500.0
    xmu = [0.5, 0.2, 0.4] if friction else [0.0] * 3
    return [ase_bpm.GranularWall(model, kn=kn, gamma_n=30.0, xmu=xmu[0], axis="z", lo=0.0,
                                 kernels=kernels),
            ase_bpm.GranularWall(model, kn=0.8 * kn, gamma_n=10.0, xmu=xmu[1], axis="x",
                                 lo=-0.3, hi=3.3, dampflag=0, kernels=kernels),
            ase_bpm.GranularWall(model, kn=kn, gamma_n=15.0, xmu=xmu[2], kt=0.5 * kn,
                                 gamma_t=4.0, axis="y", lo=-0.3, hi=3.3, kernels=kernels)]


def relative(a, b):
    """Largest difference relative to the largest reference value (absolute
    where the reference is all zero)."""
    return np.abs(a - b).max() / (np.abs(b).max() or 1.0)


def run_both(atoms, lmp, steps, pbc_positions=False):
    """The same run in ase_bpm (SphereVelocityVerlet) and LAMMPS; largest
    differences of positions, velocities and angular velocities."""
    SphereVelocityVerlet(atoms, DT).run(steps)
    lmp.run(steps)
    dx = atoms.positions - lmp.get("x")
    if pbc_positions:
        dx = minimum_image(dx, atoms.cell, atoms.pbc)
    return (np.abs(dx).max(), np.abs(atoms.get_velocities() - lmp.get("v")).max(),
            np.abs(atoms.arrays["omega"] - lmp.get("omega")).max())


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("kernels", KERNELS)
def test_forces_and_torques_of_overlapping_spheres(GranularOracle, model, kernels):
    atoms = sphere_pile(seed=1)
    atoms.calc = calculator(model, kernels=kernels)
    lmp = GranularOracle(atoms, atoms.calc, DT)
    try:
        lmp.run(0)
        forces = atoms.get_forces()
        torques = atoms.calc.get_property("torques", atoms)
        assert atoms.arrays["ncontacts"].sum() > 150  # a dense scene
        assert np.abs(torques).max() > 1.0  # tangential damping turns them
        assert relative(forces, lmp.get("f")) <= 1e-9
        assert relative(torques, lmp.get("torque")) <= 1e-9
    finally:
        lmp.close()


@pytest.mark.parametrize("model", MODELS)
def test_stress_of_a_periodic_packing(GranularOracle, model):
    atoms = sphere_pile(seed=6)
    atoms.cell = [4.0, 4.0, 4.0]
    atoms.pbc = True
    atoms.calc = calculator(model)
    lmp = GranularOracle(atoms, atoms.calc, DT, virial=True)
    try:
        lmp.run(0)
        pxx, pyy, pzz, pxy, pxz, pyz = lmp.virial_pressure()
        expected = -np.array([pxx, pyy, pzz, pyz, pxz, pxy])
        assert relative(atoms.get_stress(), expected) <= 1e-9
        assert np.abs(expected[3:]).max() > 1e-3 * np.abs(expected[:3]).max()
    finally:
        lmp.close()


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("options", [{}, {"dampflag": 0, "limit_damping": True},
                                     {"kt": 300.0, "gamma_t": 3.0, "xmu": 0.05}])
def test_trajectory_of_a_granular_gas(GranularOracle, model, options):
    """Dense spheres in a periodic box: every sphere collides many times."""
    atoms = sphere_pile(seed=2, speed=1.0, spin=3.0)
    atoms.cell = [4.0, 4.0, 4.0]
    atoms.pbc = True
    atoms.calc = calculator(model, **options)
    lmp = GranularOracle(atoms, atoms.calc, DT)
    try:
        errors = run_both(atoms, lmp, STEPS, pbc_positions=True)
        assert max(errors) <= 1e-9, errors
        # forces and torques with a full shear history still agree
        assert atoms.arrays["ncontacts"].sum() > 20
        assert relative(atoms.get_forces(), lmp.get("f")) <= 1e-9
        assert relative(atoms.calc.get_property("torques", atoms), lmp.get("torque")) <= 1e-9
        if model != "hooke":
            shear = atoms.arrays["gran_shear"]
            assert np.abs(shear).max() > 1e-4  # the history matters
    finally:
        lmp.close()


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("kernels", KERNELS)
def test_pile_in_a_box_with_walls_and_gravity(GranularOracle, model, kernels):
    atoms = sphere_pile(seed=3, speed=0.5, spin=1.0, lift=0.5)
    atoms.calc = calculator(model, kernels=kernels,
                            fixes=[ase_bpm.Gravity(9.81)] + box_walls(model, kernels))
    lmp = GranularOracle(atoms, atoms.calc, DT)
    try:
        errors = run_both(atoms, lmp, STEPS)
        assert max(errors) <= 1e-9, errors
        touching = [np.count_nonzero(np.abs(atoms.arrays.get(f"gran_wall_{a}", 0.0)) > 0)
                    for a in "xyz"]
        if model != "hooke":
            assert min(touching) > 0, touching  # every wall holds shear history
        assert relative(atoms.calc.get_property("torques", atoms), lmp.get("torque")) <= 1e-9
    finally:
        lmp.close()


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("kernels", KERNELS)
def test_frictionless_pile_in_a_box(GranularOracle, model, kernels):
    """``xmu = 0`` in the contacts and the walls: the frictionless kernels
    (no tangential force, torque or shear) follow LAMMPS, whose spheres keep
    their spin as ours do, untouched."""
    atoms = sphere_pile(seed=3, speed=0.5, spin=1.0, lift=0.5)
    walls = box_walls(model, kernels, friction=False)
    atoms.calc = calculator(model, kernels=kernels, xmu=0.0,
                            fixes=[ase_bpm.Gravity(9.81)] + walls)
    assert not atoms.calc.produces_torques
    assert "frictionless" in atoms.calc.kernel_variant
    spins = atoms.arrays["omega"].copy()
    lmp = GranularOracle(atoms, atoms.calc, DT)
    try:
        errors = run_both(atoms, lmp, STEPS)
        assert max(errors) <= 1e-9, errors
        assert np.array_equal(atoms.arrays["omega"], spins)
        assert np.abs(lmp.get("omega") - spins).max() == 0.0
        assert atoms.arrays["ncontacts"].sum() > 20
    finally:
        lmp.close()


@pytest.mark.parametrize("model", MODELS)
def test_frozen_spheres_count_as_fix_freeze(GranularOracle, model):
    atoms = sphere_pile(seed=4, speed=1.0, spin=2.0)
    held = [0, 5, 21, 22, 42, 63]
    atoms.set_constraint(FixAtoms(indices=held))
    atoms.calc = calculator(model)
    start = atoms.positions[held].copy()
    lmp = GranularOracle(atoms, atoms.calc, DT)
    try:
        errors = run_both(atoms, lmp, STEPS)
        assert max(errors) <= 1e-9, errors
        assert np.array_equal(atoms.positions[held], start)
    finally:
        lmp.close()


@pytest.mark.parametrize("model", MODELS)
def test_periodic_bed_on_a_floor(GranularOracle, model):
    atoms = sphere_pile(seed=5, speed=1.0, spin=2.0, lift=0.5)
    atoms.cell = [4.0, 4.0, 8.0]
    atoms.pbc = [True, True, False]
    wall = ase_bpm.GranularWall(model, kn=3000.0, gamma_n=30.0, xmu=0.5, axis="z", lo=0.0)
    atoms.calc = calculator(model, fixes=[ase_bpm.Gravity(9.81), wall])
    lmp = GranularOracle(atoms, atoms.calc, DT)
    try:
        errors = run_both(atoms, lmp, STEPS, pbc_positions=True)
        assert max(errors) <= 1e-9, errors
        i, j, shift = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc,
                                      atoms.arrays["radius"])
        assert (np.abs(shift) > 0).any()  # some contacts across the boundary
    finally:
        lmp.close()


@pytest.mark.parametrize("model", MODELS)
def test_bonded_body_falls_on_a_granular_floor(Oracle, model):
    """BPMSpring + Gravity + GranularWall under SphereVelocityVerlet against
    LAMMPS bpm/spring with atom_style bpm/sphere, fix nve/sphere, fix gravity
    and fix wall/gran (the LAMMPS examples/bpm/pour idea)."""
    atoms, rng = fcc_cluster(3, seed=1, jitter=0.05)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.positions[:, 2] += 0.6 - atoms.positions[:, 2].min()
    atoms.arrays["radius"] = np.full(len(atoms), 0.5)
    atoms.set_velocities(rng.normal(0, 0.05, (len(atoms), 3)) + [0.3, 0.0, -1.0])
    floor = ase_bpm.GranularWall(model, kn=200.0, gamma_n=5.0, xmu=0.5, axis="z", lo=0.0)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.5)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)},
                                   fixes=[ase_bpm.Gravity(0.5), floor])
    lmp = Oracle(atoms, atoms.calc, timestep=0.01)
    try:
        assert np.array_equal(lmp.get("rmass"), atoms.get_masses())  # exact export
        SphereVelocityVerlet(atoms, 0.01).run(500)
        lmp.run(500)
        assert lmp.position_error(atoms.positions).max() <= 1e-9
        assert np.abs(atoms.arrays["omega"] - lmp.get("omega")).max() <= 1e-9
        assert np.abs(atoms.arrays["omega"]).max() > 0.1  # the floor turned them
        assert atoms.arrays["damage"].max() > 0  # bonds broke on impact
    finally:
        lmp.close()


def test_exported_deck_runs_in_lammps(tmp_path, GranularOracle):
    """``write_lammps`` writes a Granular scene (walls, gravity, frozen
    spheres) as a deck that LAMMPS runs as it is, to the same trajectory."""
    from ase_bpm import write_lammps
    from oracle import gather, run_deck

    model = "hertz/history"
    atoms = sphere_pile(seed=7, speed=0.5, spin=1.0, lift=0.5)
    atoms.set_constraint(FixAtoms(indices=[1, 30]))
    atoms.calc = calculator(model, fixes=[ase_bpm.Gravity(9.81)] + box_walls(model),
                            timestep=DT)
    _, deck = write_lammps(str(tmp_path / "pile"), atoms, steps=STEPS, thermo=100)
    text = open(deck).read()
    assert "pair_style gran/hertz/history" in text and "fix integrate all nve/sphere" in text
    lmp = run_deck(deck)
    SphereVelocityVerlet(atoms, DT).run(STEPS)
    x, omega = gather(lmp, "x"), gather(lmp, "omega")
    lmp.close()
    assert np.abs(x - atoms.positions).max() <= 1e-9
    assert np.abs(omega - atoms.arrays["omega"]).max() <= 1e-9
    # exporting again, mid-run, stops at what a LAMMPS data file cannot carry
    with pytest.raises(ValueError, match=r"the shear history in gran_shear, gran_wall_z"):
        write_lammps(str(tmp_path / "later"), atoms, steps=10)
