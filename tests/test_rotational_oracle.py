"""bond_style bpm/rotational against the reference LAMMPS build: forces and
torques at states that stretch, shear, bend and twist the bonds, and
trajectories under ``fix nve/bpm/sphere`` (SphereVelocityVerlet) in which
bonds break."""

import itertools

import numpy as np
import pytest

import ase_bpm
from ase_bpm import SphereVelocityVerlet
from ase_bpm.core.quaternions import multiply, normalised
from ase_bpm.scene.lammps import write_lammps
from oracle import Oracle as LammpsOracle, broken_log, gather, read_dump_local, run_deck
from scenes import fcc_cluster

#: (scenes turned a little before their bonds take the reference state: the
#: harder case, as LAMMPS computes it)
pytestmark = [pytest.mark.oracle,
              pytest.mark.filterwarnings("ignore::ase_bpm.RotatedReferenceWarning")]

#: k_r k_s k_t k_b f_rc f_sc tau_tc tau_bc gamma_n gamma_s gamma_r gamma_t
SOFT = (1.0, 0.6, 0.05, 0.08, 0.08, 0.05, 0.012, 0.02, 0.3, 0.2, 0.02, 0.01)
STIFF = (1.5, 1.0, 0.1, 0.12, 0.12, 0.07, 0.02, 0.03, 0.1, 0.05, 0.01, 0.03)
UNDAMPED = SOFT[:8] + (0.0,) * 4


def small_turns(rng, n, angle):
    """Unit quaternions of random axes turned by up to ``angle`` radians."""
    axis_nc = rng.normal(size=(n, 3))
    axis_nc /= np.linalg.norm(axis_nc, axis=1)[:, None]
    half_n = 0.5 * rng.uniform(0, angle, n)
    return np.column_stack([np.cos(half_n), axis_nc * np.sin(half_n)[:, None]])


def rotational_cluster(seed=3, coeffs=(SOFT, STIFF), size=3, angle=0.03, spin=0.05,
                       speed=0.05, pair=True, **options):
    """A jittered FCC block of spheres, nearest neighbours bonded (two bond
    types), turned a little and spinning; contacts by pair bpm/spring."""
    atoms, rng = fcc_cluster(size, seed=seed, ntypes=2)
    atoms.arrays["radius"] = np.where(atoms.arrays["type"] == 1, 0.5, 0.55)
    # (type 2 first: create_bonds leaves pairs already bonded as they are)
    ase_bpm.create_bonds(atoms, 1.25, bond_type=2, mask=atoms.arrays["type"] == 2)
    ase_bpm.create_bonds(atoms, 1.25, bond_type=1)
    assert set(ase_bpm.get_bonds(atoms)[2]) == {1, 2}
    atoms.arrays["quat"] = small_turns(rng, len(atoms), angle)
    atoms.arrays["omega"] = rng.normal(0, spin, (len(atoms), 3))
    atoms.set_velocities(rng.normal(0, speed, (len(atoms), 3)))
    pair_coeffs = {(1, 1): (1.0, 1.0, 0.5), (2, 2): (1.0, 1.1, 0.3)} if pair else {}
    calc = ase_bpm.BPMSpring(bond_coeffs={t: ("bpm/rotational",) + c
                                          for t, c in enumerate(coeffs, start=1)},
                             pair_coeffs=pair_coeffs, **options)
    atoms.calc = calc
    return atoms, calc, rng


def oracle(atoms, calc, timestep=0.1):
    return LammpsOracle(atoms, calc, timestep=timestep)


def intact(atoms):
    i, j, _ = ase_bpm.get_bonds(atoms)
    return {(min(a, b), max(a, b)) for a, b in zip(i, j)}


def turned_state(atoms, rng, shift=0.005, angle=0.02):
    """Positions moved, orientations turned further, new velocities and spins."""
    positions = atoms.positions + rng.normal(0, shift, atoms.positions.shape)
    quat = normalised(multiply(small_turns(rng, len(atoms), angle), atoms.arrays["quat"]))
    return positions, quat, rng.normal(0, 0.1, positions.shape), rng.normal(0, 0.1,
                                                                          positions.shape)


def assert_close(ours, theirs, scale=None):
    scale = np.abs(theirs).max() if scale is None else scale
    assert np.abs(ours - theirs).max() <= 1e-9 * scale


OPTIONS = [dict(smooth=s, normalize=n, overlay_pair=o)
           for s, n, o in itertools.product([True, False], [False, True], [False, True])] + [
    dict(smooth=False, break_bonds=False)]  # (break no: LAMMPS needs smooth no with it)


@pytest.mark.parametrize("options", OPTIONS, ids=lambda o: "-".join(
    f"{k}={int(v)}" for k, v in o.items()))
def test_forces_and_torques_at_turned_states(options):
    """After the reference state is taken, the particles move, turn and spin
    (every bond bent, twisted and sheared, up to about 0.7 of its breaking
    measure: LAMMPS breaks no bond in the setup of a run): forces and torques
    agree with LAMMPS within 1e-9 of the largest."""
    atoms, calc, rng = rotational_cluster(**options)
    lmp = oracle(atoms, calc)
    try:
        forces = atoms.get_forces()
        lmp.run(0)
        assert_close(forces, lmp.forces())
        assert_close(calc.results["torques"], lmp.get("torque"))
        before = intact(atoms)
        positions, quat, velocities, omega = turned_state(atoms, rng)
        atoms.positions = positions
        atoms.arrays["quat"] = quat
        atoms.arrays["omega"] = omega
        atoms.set_velocities(velocities)
        forces = atoms.get_forces()
        lmp.set_state(positions, velocities)
        lmp.set("quat", quat)
        lmp.set("omega", omega)
        lmp.run(0)
        assert np.abs(calc.results["torques"]).max() > 1e-3 * np.abs(forces).max()
        assert_close(forces, lmp.forces())
        assert_close(calc.results["torques"], lmp.get("torque"))
        assert intact(atoms) == lmp.intact_bonds() == before  # (LAMMPS breaks none in a setup)
    finally:
        lmp.close()


def runs_as_in_lammps(tmp_path, atoms, calc, steps=300):
    """Run the scene ``steps`` steps of 0.1 here (SphereVelocityVerlet) and
    in LAMMPS from the deck write_lammps exports (fix nve/bpm/sphere):
    positions, velocities, spins and orientations within 1e-9, the same
    bonds broken at the same steps (some do)."""
    _, deck = write_lammps(str(tmp_path / "scene"), atoms, calc, timestep=0.1, steps=steps,
                           thermo=50)
    lmp = run_deck(deck)
    try:
        SphereVelocityVerlet(atoms, timestep=0.1).run(steps)
        for name, ours in (("x", atoms.positions), ("v", atoms.get_velocities()),
                           ("omega", atoms.arrays["omega"]), ("quat", atoms.arrays["quat"])):
            assert np.abs(gather(lmp, name) - ours).max() <= 1e-9, name
    finally:
        lmp.close()
    ours = broken_log(atoms.info["broken_bonds"])
    theirs = {(i - 1, j - 1, step)
              for i, j, step in broken_log(read_dump_local(tmp_path / "scene.broken"))}
    assert len(ours) > 5
    assert ours == theirs


@pytest.mark.parametrize("coeffs", [(SOFT, STIFF), (UNDAMPED, UNDAMPED)],
                         ids=["damped", "undamped"])
def test_trajectory_with_orientations_and_breaking(tmp_path, coeffs):
    """SphereVelocityVerlet against LAMMPS fix nve/bpm/sphere, from the deck
    write_lammps exports (orientations set in it): 300 steps, positions,
    velocities, orientations and spins within 1e-9, the same bonds broken
    at the same steps (the store/local log)."""
    atoms, calc, _ = rotational_cluster(coeffs=coeffs, speed=0.05, spin=0.02)
    runs_as_in_lammps(tmp_path, atoms, calc)
    assert np.abs(atoms.arrays["quat"][:, 1:]).max() > 0.05  # they turned


GRANULAR = [dict(model="hooke/history", kn=1.0, gamma_n=0.5, xmu=0.1),
            dict(model="hooke", kn=1.5, gamma_n=0.3, gamma_t=0.2, xmu=0.2),
            dict(model="hertz/history", kn=2.0, gamma_n=0.4, xmu=0.3, dampflag=0)]


@pytest.mark.parametrize("granular", GRANULAR, ids=lambda g: g["model"])
def test_rotational_bonds_beside_granular_contacts(tmp_path, granular):
    """Rotational bonds with pair_style gran/* (as LAMMPS's rotational impact
    combines them): bonded pairs do not touch, broken ones do; 300 steps of
    two bonded blocks colliding agree with LAMMPS within 1e-9, with the same
    bonds broken at the same steps."""
    a, calc, rng = rotational_cluster(seed=4, pair=False, speed=0.02, spin=0.01)
    b, _, _ = rotational_cluster(seed=5, pair=False, speed=0.02, spin=0.01)
    b.positions += [a.positions[:, 0].max() - b.positions[:, 0].min() + 0.95, 0.2, 0.1]
    v_a, v_b = a.get_velocities(), b.get_velocities()
    atoms = a + ase_bpm.renew_ids(b)
    atoms.set_velocities(np.vstack([v_a + [0.15, 0, 0], v_b - [0.15, 0, 0]]))
    calc = ase_bpm.BPMSpring(bond_coeffs=calc.parameters["bond_coeffs"], granular=granular)
    atoms.calc = calc
    runs_as_in_lammps(tmp_path, atoms, calc)
    assert atoms.arrays["ncontacts"].sum() > 0  # the blocks touch


def test_ase_integrators_that_do_not_turn_the_spheres_are_named():
    """ASE's VelocityVerlet leaves omega and the orientations as they are:
    the calculator says so once (SpinNotIntegratedWarning)."""
    from ase.md.verlet import VelocityVerlet as AseVelocityVerlet

    atoms, _, _ = rotational_cluster()
    with pytest.warns(ase_bpm.SpinNotIntegratedWarning):
        AseVelocityVerlet(atoms, timestep=0.05).run(3)
