"""Granular and SphereVelocityVerlet inside ASE's machinery: restarts,
copies, trajectories, loggers, observers, other integrators."""

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.lj import LennardJones
from ase.constraints import FixAtoms
from ase.io import Trajectory, read
from ase.md.langevin import Langevin
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm import Granular, GranularWall, Gravity
from ase_bpm import SphereVelocityVerlet
from scenes import sphere_pile

DT = 1e-3


def pile_in_a_box(model):
    atoms = sphere_pile(n=4, seed=12, speed=1.0, spin=2.0, lift=0.5)
    atoms.set_constraint(FixAtoms(indices=[3, 17]))
    walls = [GranularWall(model, kn=2000.0, gamma_n=20.0, xmu=0.4, axis="z", lo=0.0),
             GranularWall(model, kn=2000.0, gamma_n=20.0, xmu=0.4, axis="x", lo=-0.4, hi=3.4)]
    atoms.calc = Granular(model, kn=1000.0, gamma_n=20.0, xmu=0.3,
                          fixes=[Gravity(9.81)] + walls)
    return atoms


@pytest.mark.parametrize("model", ["hooke", "hooke/history", "hertz/history"])
def test_restart_mid_run_continues_bit_identically(tmp_path, model):
    straight = pile_in_a_box(model)
    interrupted = pile_in_a_box(model)
    SphereVelocityVerlet(straight, DT).run(300)

    SphereVelocityVerlet(interrupted, DT).run(150)
    assert np.abs(interrupted.arrays.get("gran_shear", 0.0)).max() > 0 or model == "hooke"
    ase_bpm.write_restart(tmp_path / "pile.bpm", interrupted)
    resumed = ase_bpm.read_restart(tmp_path / "pile.bpm")
    resumed.calc = pile_in_a_box(model).calc  # a new calculator, same parameters
    SphereVelocityVerlet(resumed, DT).run(150)

    assert np.array_equal(resumed.positions, straight.positions)
    assert np.array_equal(resumed.get_momenta(), straight.get_momenta())
    assert np.array_equal(resumed.arrays["omega"], straight.arrays["omega"])
    for key in ("bpm_step", "bpm_dissipated_energy"):
        assert resumed.info[key] == straight.info[key]


def test_copy_carries_the_contact_history():
    atoms = pile_in_a_box("hooke/history")
    SphereVelocityVerlet(atoms, DT).run(100)
    twin = atoms.copy()
    twin.calc = pile_in_a_box("hooke/history").calc
    SphereVelocityVerlet(atoms, DT).run(100)
    SphereVelocityVerlet(twin, DT).run(100)
    assert np.array_equal(twin.positions, atoms.positions)
    assert np.array_equal(twin.arrays["omega"], atoms.arrays["omega"])


def test_history_matters_for_the_continuation():
    """A copy without its shear history continues differently: the restart
    test above is not passing by accident."""
    atoms = pile_in_a_box("hooke/history")
    SphereVelocityVerlet(atoms, DT).run(100)
    twin = atoms.copy()
    twin.arrays["gran_shear"][:] = 0.0
    twin.calc = pile_in_a_box("hooke/history").calc
    SphereVelocityVerlet(atoms, DT).run(50)
    SphereVelocityVerlet(twin, DT).run(50)
    assert np.abs(twin.positions - atoms.positions).max() > 1e-9


def test_trajectory_logger_and_observers(tmp_path):
    atoms = pile_in_a_box("hertz/history")
    seen = []
    dyn = SphereVelocityVerlet(atoms, DT, logfile=str(tmp_path / "md.log"), loginterval=50)
    with Trajectory(tmp_path / "md.traj", "w", atoms) as traj:
        dyn.attach(traj.write, interval=50)
        dyn.attach(lambda: seen.append(ase_bpm.rotational_energy(atoms)), interval=25)
        dyn.run(200)
    frames = read(tmp_path / "md.traj", ":")
    assert len(frames) == 5
    assert np.array_equal(frames[-1].positions, atoms.positions)
    assert np.allclose(frames[-1].get_forces(), atoms.get_forces(), rtol=0, atol=1e-12)
    log = (tmp_path / "md.log").read_text().splitlines()
    assert len(log) == 1 + 5 and "Epot" in log[0]
    assert len(seen) == 9 and max(seen) > 0
    assert atoms.info["bpm_step"] == 200


def test_translational_calculators_run_unchanged():
    """Under SphereVelocityVerlet an ASE calculator without torques runs as
    under ASE's VelocityVerlet, and the spheres keep their spin."""
    def cluster():
        atoms = sphere_pile(n=2, seed=4, speed=0.1)
        atoms.positions *= 1.2
        atoms.calc = LennardJones(sigma=1.0, epsilon=1.0, rc=3.0)
        return atoms

    spheres, points = cluster(), cluster()
    omega = spheres.arrays["omega"].copy()
    SphereVelocityVerlet(spheres, 0.002).run(100)
    VelocityVerlet(points, 0.002).run(100)
    assert np.array_equal(spheres.positions, points.positions)
    assert np.array_equal(spheres.arrays["omega"], omega)


@pytest.mark.filterwarnings("ignore::ase_bpm.SpinNotIntegratedWarning")  # translation only
def test_langevin_with_the_no_history_model():
    """ASE's own thermostat drives Granular (translation only)."""
    atoms = sphere_pile(n=3, seed=5, speed=1.0)
    atoms.calc = Granular("hooke", kn=1000.0, gamma_n=20.0, xmu=0.3)
    dyn = Langevin(atoms, timestep=DT, temperature_K=0, friction=5.0, fixcm=False,
                   rng=np.random.default_rng(0))
    ke0 = atoms.get_kinetic_energy()
    with pytest.warns(ase_bpm.TimestepUncheckedWarning, match="pass timestep="):
        dyn.run(300)  # (without timestep=, the thermostat's cannot be told)
    assert atoms.info["bpm_step"] == 300
    assert atoms.get_kinetic_energy() < 0.5 * ke0


def test_one_evaluation_per_step():
    atoms = pile_in_a_box("hooke/history")
    calls = []
    evaluate = atoms.calc.model.evaluate
    atoms.calc.model.evaluate = lambda a, ctx: calls.append(1) or evaluate(a, ctx)
    SphereVelocityVerlet(atoms, DT).run(40)
    assert len(calls) == 41  # the setup evaluation and one per step


def test_cached_history_equals_the_history_on_the_atoms():
    """Reading the shear history back from the atoms at every step (as after
    a copy) gives the same run as the calculator's cached copy of it."""
    cached, reread = pile_in_a_box("hertz/history"), pile_in_a_box("hertz/history")

    def replace_arrays():  # new array objects: the calculator must read them
        for name in ("gran_partner", "gran_shear"):
            if name in reread.arrays:
                reread.arrays[name] = reread.arrays[name].copy()

    dyn = SphereVelocityVerlet(reread, DT)
    dyn.attach(replace_arrays, interval=1)
    dyn.run(300)
    SphereVelocityVerlet(cached, DT).run(300)
    assert cached.calc.model._search.nbuilds > 3  # across neighbour-list rebuilds
    assert np.array_equal(cached.positions, reread.positions)
    assert np.array_equal(cached.arrays["gran_shear"], reread.arrays["gran_shear"])
    assert np.array_equal(partner_indices(cached), partner_indices(reread))
    # ncontacts: each sphere's touching partners, as the stored contacts list them
    partners = partner_indices(cached)
    owner = np.repeat(np.arange(len(cached)), partners.shape[1]).reshape(partners.shape)
    listed = partners >= 0
    counts = np.bincount(np.concatenate([owner[listed], partners[listed]]),
                         minlength=len(cached))
    assert listed.sum() > 20 and np.array_equal(cached.arrays["ncontacts"], counts)


def partner_indices(atoms):
    """``gran_partner`` with each partner's index instead of its ID (-1: empty)."""
    ids = ase_bpm.core.bonds.read_ids(atoms, "bpm_id")
    order = np.argsort(ids)
    partner = ase_bpm.core.bonds.read_ids(atoms, "gran_partner")
    at = np.searchsorted(ids[order], partner).clip(0, len(ids) - 1)
    return np.where(partner != 0, order[at], -1)


def test_parameters_survive_json():
    import json

    calc = Granular("hertzian", kn=1e4, gamma_n=2.0, xmu=0.4, kt=3e3, dampflag=0)
    again = Granular(**json.loads(json.dumps(calc.todict())))
    assert again.law == calc.law and again.law.model == "hertz/history"
    assert again.law.gamma_t == 0.0  # dampflag 0


def test_integrator_sees_bonds_replaced_between_runs():
    """The integrators take step-start forces from the calculator's results only
    when nothing changed since: retyped bonds between two runs are seen."""
    from ase import Atoms
    from ase_bpm import VelocityVerlet as BPMVelocityVerlet
    from ase_bpm.scene.md import forces_of

    atoms = Atoms("H3", positions=[[0, 0, 0], [1, 0, 0], [2, 0, 0]], masses=[1, 1, 1])
    atoms.arrays["bonds"] = np.array(["1(1)", "2(1)", "_"])
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0), 2: (9.0, 0.5, 0.0)})
    atoms.get_forces()
    atoms.positions[2, 0] = 2.1
    BPMVelocityVerlet(atoms, 0.01).run(1)
    retyped = atoms.arrays["bond_type"].copy()
    retyped[retyped == 1] = 2
    atoms.arrays["bond_type"] = retyped
    assert np.array_equal(forces_of(atoms), atoms.get_forces(md=True))


@pytest.mark.parametrize("width, touching", [(1.8, True), (0.9, True), (2.4, False)])
def test_a_contact_through_two_periodic_images_is_refused(width, touching):
    """A periodic cell so narrow that two spheres touch through two images
    (width 1.8: 0.9 apart both ways), or a sphere its own image (0.9, the
    first sphere alone), is refused, naming the spheres; one narrower than
    twice the list's reach where every pair touches once (2.4) is not."""
    count = 1 if width < 1.0 else 2
    atoms = Atoms("Ar" * count, positions=[[0.2, 1, 1], [1.1, 1, 1]][:count],
                  cell=[width, 5.0, 5.0], pbc=[True, False, False])
    atoms.arrays["radius"] = np.full(count, 0.5)
    atoms.calc = Granular("hooke", kn=100.0, gamma_n=0.0, xmu=0.0, skin=0.2)
    if touching:
        culprit = "sphere 0 touches sphere 0" if count == 1 else "sphere 0 touches sphere 1"
        with pytest.raises(ValueError, match=f"periodic cell too small: {culprit} through "
                                             "more than one periodic image"):
            atoms.get_forces()
    else:
        f_nc = atoms.get_forces()
        assert f_nc[0, 0] < 0 < f_nc[1, 0]  # pushed apart along the short way


@pytest.mark.parametrize("kernels", ["compiled", "numpy"])
def test_a_deep_copy_of_the_atoms_runs_on_as_the_original(kernels):
    """``copy.deepcopy(atoms)`` copies the calculator too (its kernels go by
    the module, not copied): the copy, walls and contact history with it,
    runs on bit for bit as the original."""
    import copy

    atoms = sphere_pile(n=3, lift=0.3)
    law = dict(kn=2000.0, gamma_n=50.0, xmu=0.5, dampflag=0)
    wall = GranularWall("hooke/history", **law, axis="z", lo=0.0, kernels=kernels)
    atoms.calc = Granular(model="hooke/history", **law, timestep=1e-3, fixes=[wall],
                          kernels=kernels)
    SphereVelocityVerlet(atoms, 1e-3).run(5)
    twin = copy.deepcopy(atoms)
    assert twin.calc is not atoms.calc and twin.calc.kernels is atoms.calc.kernels
    for each in (atoms, twin):
        SphereVelocityVerlet(each, 1e-3).run(20)
    assert np.array_equal(twin.positions, atoms.positions)
    assert np.array_equal(twin.arrays["omega"], atoms.arrays["omega"])
    assert np.array_equal(twin.get_forces(), atoms.get_forces())
