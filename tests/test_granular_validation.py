"""Granular bad input: a clear exception naming the culprit, and no state lost."""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm import SphereVelocityVerlet
from scenes import sphere_pile
from state import assert_unchanged, snapshot

GOOD = dict(kn=1000.0, gamma_n=10.0, xmu=0.3)


def running_pile(model="hooke/history", steps=5, **kwargs):
    """A pile that has run a few steps: contacts with shear history on it."""
    atoms = sphere_pile(n=3, seed=11)
    atoms.calc = ase_bpm.Granular(model, **{**GOOD, **kwargs})
    SphereVelocityVerlet(atoms, 1e-3).run(steps)
    assert atoms.arrays["ncontacts"].sum() > 0
    return atoms


def step_raises(atoms, message, edit):
    """``edit`` the atoms of a running pile, then a step must raise ``message``
    and leave every array and info entry as the edit left it."""
    edit(atoms)
    before = snapshot(atoms)
    atoms.positions[0, 0] += 1e-6  # a new configuration: a step
    moved = atoms.positions.copy()
    with pytest.raises(ValueError, match=message):
        atoms.get_forces()
    assert np.array_equal(atoms.positions, moved)
    atoms.positions = before[0]["positions"]
    assert_unchanged(atoms, before)


@pytest.mark.parametrize("args,message", [
    (dict(model="hooky"), r"Granular: unknown model 'hooky' \(did you mean 'hooke'\?\); "
                          r"choose one of 'hooke'"),
    (dict(xmu=-0.1), r"Granular: xmu = -0.1 must be finite and non-negative"),
    (dict(xmu=np.nan), r"Granular: xmu = nan must be finite"),
    (dict(kn=0.0), r"Granular: kn = 0.0 must be finite and positive"),
    (dict(kn=None), r"Granular needs kn"),
    (dict(gamma_n=-1.0), r"Granular: gamma_n = -1.0 must be finite and non-negative"),
    (dict(kt=-5.0), r"Granular: kt = -5.0 must be finite and positive"),
    (dict(gamma_t="soft"), r"Granular: gamma_t must be a number, got 'soft'"),
    (dict(dampflag=2), r"Granular: dampflag must be 0 or 1, got 2"),
    (dict(skin=-0.1), r"Granular: skin = -0.1 must be non-negative"),
])
def test_bad_coefficients(args, message):
    with pytest.raises(ValueError, match=message):
        ase_bpm.Granular(**{"model": "hooke/history", **GOOD, **args})


MODELS = ("'hooke', 'no_history', 'hooke/history', 'history', 'hertz/history', "
          "'hertzian'")


@pytest.mark.parametrize("make", [ase_bpm.Granular, ase_bpm.GranularWall])
@pytest.mark.parametrize("model,near", [("hook/history", "hooke/history"),
                                        ("gran/hok", "hooke"), ("HOOKE", "hooke"),
                                        ("flat", None), (None, None)])
@pytest.mark.parametrize("given", [(), (2000.0,)], ids=["keywords", "by position"])
@pytest.mark.parametrize("coefficients", [{}, dict(kn=2000.0), dict(kn=2000.0, gama_t=1.0),
                                          GOOD], ids=["none", "kn", "a misspelt one", "all"])
def test_an_unknown_model_is_named_first(make, model, near, given, coefficients):
    """Whatever else is wrong or missing (coefficients, a keyword, some given by
    position), the model is named first, with the nearest valid name and all."""
    with pytest.raises(ValueError) as info:
        make(model, *given, **coefficients)
    message = str(info.value)
    assert message.startswith(f"{make.__name__}: unknown model {model!r}")
    assert message.endswith(f"; choose one of {MODELS}")
    assert (f"(did you mean {near!r}?)" in message) is (near is not None)


def test_a_model_set_later_is_checked_and_changes_nothing():
    atoms = sphere_pile(n=3, seed=11)
    atoms.calc = calc = ase_bpm.Granular("hooke/history", **GOOD)
    forces = atoms.get_forces().copy()
    with pytest.raises(ValueError, match=r"Granular: unknown model 'hertz/histroy' \(did you "
                                         r"mean 'hertz/history'\?\); choose one of"):
        calc.set(model="hertz/histroy")
    assert calc.parameters["model"] == calc.law.model == "hooke/history"
    assert np.array_equal(atoms.get_forces(), forces)


@pytest.mark.parametrize("given,missing", [(dict(kn=2000.0), "gamma_n= and xmu="),
                                           (dict(xmu=0.5), "kn= and gamma_n="),
                                           ({}, "kn=, gamma_n= and xmu="),
                                           (dict(kn=1.0, xmu=0.0), "gamma_n=")])
@pytest.mark.parametrize("make,error", [(ase_bpm.Granular, ValueError),
                                        (ase_bpm.GranularWall, TypeError)])
def test_every_missing_coefficient_is_named_at_once(make, error, given, missing):
    with pytest.raises(error, match=rf"^{make.__name__} needs {missing}$"):
        make("hooke/history", **given)


def test_model_names_of_the_old_page_are_aliases():
    for old, new in [("no_history", "hooke"), ("history", "hooke/history"),
                     ("hertzian", "hertz/history"), ("gran/hooke", "hooke")]:
        assert ase_bpm.Granular(old, **GOOD).law.model == new


def test_missing_radius():
    atoms = running_pile()
    step_raises(atoms, r'Granular: atoms.arrays\["radius"\] \(the sphere radius of each '
                       r'atom\) is missing', lambda a: a.arrays.pop("radius"))


@pytest.mark.parametrize("value", [0.0, -0.3, np.nan, np.inf])
def test_non_positive_radius(value):
    atoms = running_pile()

    def edit(a):
        a.arrays["radius"][4] = value

    step_raises(atoms, rf'atoms.arrays\["radius"\] of atom 4 is {value}: radii must be '
                       'positive and finite', edit)


@pytest.mark.parametrize("shape", [(27,), (27, 2), (27, 4), (27, 3, 1)])
def test_omega_of_the_wrong_shape(shape):
    atoms = running_pile()

    def edit(a):
        del a.arrays["omega"]
        a.arrays["omega"] = np.zeros(shape)

    step_raises(atoms, r'atoms.arrays\["omega"\] must be an N x 3 array of angular '
                       r'velocities \(N = 27\), got shape', edit)


def test_omega_not_finite():
    atoms = running_pile()

    def edit(a):
        a.arrays["omega"][7, 2] = np.nan

    step_raises(atoms, r'atoms.arrays\["omega"\] of atom 7 is not finite', edit)


def test_coinciding_spheres_have_no_contact_normal():
    atoms = running_pile()

    def edit(a):
        a.positions[5] = a.positions[6]

    step_raises(atoms, r"spheres 5 and 6 are at the same position", edit)


def test_integrator_checks_omega_and_radius_up_front():
    atoms = sphere_pile(n=2)
    atoms.arrays["omega"] = np.zeros((len(atoms), 2))
    with pytest.raises(ValueError, match=r'atoms.arrays\["omega"\] must be an N x 3'):
        SphereVelocityVerlet(atoms, 1e-3)
    atoms = sphere_pile(n=2)
    atoms.arrays["radius"][1] = -1.0
    with pytest.raises(ValueError, match=r'atoms.arrays\["radius"\] of atom 1 is -1.0'):
        SphereVelocityVerlet(atoms, 1e-3)


def test_history_needs_the_true_timestep():
    """Shear history advances by one timestep per step: never a guessed dt."""
    atoms = sphere_pile(n=3, seed=11)
    atoms.calc = ase_bpm.Granular("hooke/history", **GOOD)
    with pytest.raises(ValueError, match=r"the model of Granular needs the MD timestep.* "
                                         r"\(ase_bpm.SphereVelocityVerlet, which turns"):
        VelocityVerlet(atoms, 1e-3).run(2)
    atoms = sphere_pile(n=3, seed=11)
    atoms.calc = ase_bpm.Granular("hooke/history", **GOOD, timestep=2e-3)
    with pytest.raises(ValueError, match=r"timestep mismatch: the calculator was given "
                                         r"timestep=0.002, but the atoms moved as a "
                                         r"velocity Verlet step of 0.001"):
        VelocityVerlet(atoms, 1e-3).run(2)
    atoms = sphere_pile(n=3, seed=11)
    atoms.calc = ase_bpm.Granular("hooke/history", **GOOD, timestep=2e-3)
    with pytest.raises(ValueError, match=r"timestep mismatch: the calculator was given "
                                         r"timestep=0.002, the integrator steps 0.001"):
        SphereVelocityVerlet(atoms, 1e-3).run(2)


@pytest.mark.filterwarnings("ignore::ase_bpm.SpinNotIntegratedWarning")  # translation only
def test_no_history_model_needs_no_timestep():
    atoms = sphere_pile(n=3, seed=11)
    atoms.calc = ase_bpm.Granular("hooke", **GOOD)
    VelocityVerlet(atoms, 1e-3).run(3)
    assert atoms.info["bpm_step"] == 3


@pytest.mark.parametrize("args,message", [
    (dict(axis="w"), r"GranularWall: axis must be 'x', 'y' or 'z', got 'w'"),
    (dict(lo=None, hi=None), r"GranularWall: give lo, hi or both"),
    (dict(lo=1.0, hi=0.5), r"GranularWall: lo = 1.0 must be below hi = 0.5"),
    (dict(lo=np.inf), r"GranularWall: lo = inf must be finite"),
    (dict(model="flat"), r"GranularWall: unknown model 'flat'"),
    (dict(xmu=-1.0), r"GranularWall: xmu = -1.0 must be finite and non-negative"),
])
def test_bad_walls(args, message):
    wall = {"model": "hooke/history", **GOOD, **args}
    with pytest.raises(ValueError, match=message):
        ase_bpm.GranularWall(wall.pop("model"), **wall)


def test_wall_across_a_periodic_direction():
    atoms = sphere_pile(n=3, seed=11, lift=0.5)
    atoms.cell = [3.0, 3.0, 3.0]
    atoms.pbc = True
    atoms.calc = ase_bpm.Granular("hooke", **GOOD,
                                  fixes=[ase_bpm.GranularWall("hooke", **GOOD)])
    before = snapshot(atoms)
    with pytest.raises(ValueError, match=r"GranularWall 'z': a wall across the periodic "
                                         r"direction z"):
        atoms.get_forces()
    assert_unchanged(atoms, before)


def test_two_history_walls_need_different_names():
    walls = [ase_bpm.GranularWall("hooke/history", **GOOD, axis="z", lo=0.0),
             ase_bpm.GranularWall("hooke/history", **GOOD, axis="z", hi=5.0)]
    atoms = sphere_pile(n=3, seed=11, lift=0.3)
    atoms.positions[:, 2] -= 0.05
    atoms.calc = ase_bpm.Granular("hooke/history", **GOOD, fixes=walls, timestep=1e-3)
    with pytest.raises(ValueError, match=r"two fixes keep their state in "
                                         r"atoms.arrays\['gran_wall_z'\]"):
        atoms.get_forces()


def test_a_sphere_centred_on_a_wall_of_a_box_names_that_wall():
    """Walls of one law run in one kernel call; the error still names the
    wall the sphere sits on, and nothing is written."""
    walls = [ase_bpm.GranularWall("hooke", **GOOD, axis=axis, lo=-1.0, hi=4.0)
             for axis in "xyz"]
    atoms = sphere_pile(n=3, seed=11, lift=0.3)
    atoms.positions[4, 1] = 4.0
    atoms.calc = ase_bpm.Granular("hooke", **GOOD, fixes=walls)
    before = snapshot(atoms)
    with pytest.raises(ValueError, match=r"GranularWall 'y': sphere 4 has its centre on "
                                         r"the wall"):
        atoms.get_forces()
    assert_unchanged(atoms, before)


def test_bad_gravity():
    with pytest.raises(ValueError, match=r"Gravity: g = -9.81 must be finite"):
        ase_bpm.Gravity(-9.81)
    with pytest.raises(ValueError, match=r"Gravity: direction \[0.0, 0.0, 0.0\] must be"):
        ase_bpm.Gravity(9.81, (0, 0, 0))


def test_sphere_deleted_while_in_contact():
    """Contact partners are IDs: deleting a sphere drops its contacts, and every
    other contact keeps its shear."""
    from ase_bpm.models.contacts import read_contacts

    atoms = running_pile()
    keys, shear = read_contacts(atoms)
    n = len(atoms)
    i, j = keys // n, keys % n
    assert np.any((i == 2) | (j == 2)) and np.abs(shear).max() > 0
    kept = (i != 2) & (j != 2)
    renumber = lambda k: k - (k > 2)  # noqa: E731
    expected = dict(zip(zip(renumber(i[kept]), renumber(j[kept])), shear[kept]))
    del atoms[2]
    keys, shear = read_contacts(atoms)
    found = dict(zip(zip(keys // (n - 1), keys % (n - 1)), shear))
    assert found.keys() == expected.keys()
    for pair, s in expected.items():
        assert np.array_equal(found[pair], s)
    atoms.calc = ase_bpm.Granular("hooke/history", **GOOD)
    SphereVelocityVerlet(atoms, 1e-3).run(2)
    assert atoms.arrays["ncontacts"].sum() > 0


def test_reordered_spheres_keep_their_contacts():
    """Any permutation of the atoms (ase.build.sort too) gives the permuted forces
    and torques, shear history included."""
    atoms = running_pile()
    atoms.calc = ase_bpm.Granular("hooke/history", **GOOD, timestep=1e-3)
    atoms.calc.refresh()  # recompute with the velocities now (not the run's record)
    f, t = atoms.get_forces(), atoms.calc.get_property("torques", atoms)
    perm = np.random.default_rng(4).permutation(len(atoms))
    shuffled = atoms[perm]
    shuffled.calc = ase_bpm.Granular("hooke/history", **GOOD, timestep=1e-3)
    assert np.allclose(shuffled.get_forces(), f[perm], rtol=0, atol=1e-12 * np.abs(f).max())
    assert np.allclose(shuffled.calc.get_property("torques", shuffled), t[perm], rtol=0,
                       atol=1e-12 * np.abs(t).max())
    assert np.abs(t).max() > 0  # the shear history acts


def test_history_wall_needs_the_true_timestep_but_a_setup_does_not():
    atoms = sphere_pile(n=3, seed=11, lift=0.2)
    atoms.positions[:, 2] -= 0.1  # the lowest layer presses into the floor
    floor = ase_bpm.GranularWall("hooke/history", **GOOD)
    atoms.calc = ase_bpm.Granular("hooke", **GOOD, fixes=[floor])
    atoms.info["bpm_step"] = 7  # a run that has been going on: a setup needs no dt
    assert np.abs(atoms.get_forces()).max() > 0
    with pytest.raises(ValueError, match=r"GranularWall needs the MD timestep"):
        VelocityVerlet(atoms, 1e-3).run(1)
