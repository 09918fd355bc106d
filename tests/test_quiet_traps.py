"""What used to run without a word: bond coefficients on atoms that lost their
bonds, spheres whose spin nothing integrates, per-atom arrays of the wrong
shape or type (after ASE operations, file round trips or by hand)."""

import warnings

import numpy as np
import pytest
from ase.constraints import FixAtoms
from ase.io import read, write
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm import SphereVelocityVerlet
from scenes import SPACING, fcc_cluster, peri_model, sc_block, sphere_pile

SPRING = dict(bond_coeffs={1: (1.0, 0.1, 0.1)}, pair_coeffs={(1, 1): (1.0, 1.0, 0.1)})


def bonded_cluster():
    atoms, _ = fcc_cluster(seed=2)
    ase_bpm.create_bonds(atoms, 1.25)
    return atoms


def caught(run):
    """The warnings ``run()`` gives, every one."""
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        run()
    return [w for w in seen if issubclass(w.category, (ase_bpm.NoBondsWarning,
                                                        ase_bpm.SpinNotIntegratedWarning))]


# -- bond coefficients on atoms without bonds ---------------------------------------------

def test_bonds_lost_in_an_ase_trajectory_are_warned_of_once(tmp_path):
    """An ASE .traj keeps no bond arrays: the body read back has none, and
    the calculator says so (once, whatever the steps) instead of running a
    body without bonds in silence."""
    atoms = bonded_cluster()
    write(tmp_path / "body.traj", atoms)
    back = read(tmp_path / "body.traj")
    assert "bond_partner" not in back.arrays
    back.calc = ase_bpm.BPMSpring(**SPRING)
    seen = caught(lambda: VelocityVerlet(back, 0.01).run(5))
    assert len(seen) == 1 and seen[0].category is ase_bpm.NoBondsWarning
    message = str(seen[0].message)
    assert "bond types [1]" in message and "no bonds" in message and "read_restart" in message


def test_bonds_kept_by_a_restart_give_no_warning(tmp_path):
    atoms = bonded_cluster()
    atoms.calc = ase_bpm.BPMSpring(**SPRING)
    atoms.get_forces()
    ase_bpm.write_restart(tmp_path / "body.bpm", atoms)
    back = ase_bpm.read_restart(tmp_path / "body.bpm")
    back.calc = ase_bpm.BPMSpring(**SPRING)
    assert caught(lambda: VelocityVerlet(back, 0.01).run(5)) == []


@pytest.mark.parametrize("model", ["spring", "peri"])
def test_a_fully_broken_body_and_a_scene_without_bond_coeffs_are_quiet(model):
    """Legitimate: every bond broken (listed with type 0), or contacts only."""
    if model == "spring":
        atoms, calc, none = bonded_cluster(), ase_bpm.BPMSpring(**SPRING), ase_bpm.BPMSpring(
            pair_coeffs=SPRING["pair_coeffs"])
    else:
        atoms = sc_block(4)
        # (with every bond broken the spacing cannot be inferred: given)
        calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb")}, timestep=1e-7,
                               lattice_spacing=SPACING)
        none = ase_bpm.BPMPeri(timestep=1e-7, lattice_spacing=SPACING)
    broken = atoms.copy()
    broken.arrays["bond_type"] = np.zeros_like(atoms.arrays["bond_type"])
    broken.calc = calc
    assert caught(broken.get_forces) == []
    bare = atoms.copy()
    for name in [n for n in bare.arrays if n.startswith("bond_")]:
        del bare.arrays[name]
    bare.calc = none
    assert caught(bare.get_forces) == []


# -- spheres whose spin nothing integrates ---------------------------------------------------

def spinning_pile(model="hooke/history", xmu=0.3):
    atoms = sphere_pile(seed=1)
    atoms.calc = ase_bpm.Granular(model, kn=1000.0, gamma_n=20.0, xmu=xmu, timestep=1e-3)
    return atoms


@pytest.mark.parametrize("model", ["hooke", "hooke/history", "hertz/history"])
def test_ase_velocity_verlet_under_torques_is_warned_of_once(model):
    atoms = spinning_pile(model)
    omega = atoms.arrays["omega"].copy()
    seen = caught(lambda: VelocityVerlet(atoms, 1e-3).run(5))
    assert np.array_equal(atoms.arrays["omega"], omega)  # the trap: they never turn
    assert len(seen) == 1 and seen[0].category is ase_bpm.SpinNotIntegratedWarning
    assert "SphereVelocityVerlet" in str(seen[0].message)


def test_a_wall_that_turns_the_spheres_is_watched_too():
    """A frictional wall under a frictionless pair law still turns spheres."""
    atoms = sphere_pile(seed=1, lift=0.3)
    wall = ase_bpm.GranularWall("hooke", kn=1000.0, gamma_n=20.0, xmu=0.5, axis="z", lo=0.0)
    atoms.calc = ase_bpm.Granular("hooke", kn=1000.0, gamma_n=20.0, xmu=0.0, fixes=[wall])
    assert [w.category for w in caught(lambda: VelocityVerlet(atoms, 1e-3).run(4))] == [
        ase_bpm.SpinNotIntegratedWarning]


def test_what_turns_the_spheres_or_needs_no_turning_is_quiet():
    atoms = spinning_pile()  # SphereVelocityVerlet turns them
    assert caught(lambda: SphereVelocityVerlet(atoms, 1e-3).run(5)) == []
    atoms = spinning_pile(xmu=0.0)  # frictionless: no torque can act
    assert caught(lambda: VelocityVerlet(atoms, 1e-3).run(5)) == []
    atoms = spinning_pile()  # every sphere held: none may turn
    atoms.set_constraint(FixAtoms(indices=range(len(atoms))))
    assert caught(lambda: VelocityVerlet(atoms, 1e-3).run(5)) == []


def test_an_integrator_of_ones_own_that_turns_the_spheres_is_quiet():
    atoms = spinning_pile()

    def turn():
        torques = atoms.calc.get_property("torques", atoms)
        atoms.arrays["omega"] = atoms.arrays["omega"] + 1e-3 * torques

    dyn = VelocityVerlet(atoms, 1e-3)
    dyn.attach(turn, interval=1)
    assert caught(lambda: dyn.run(5)) == []


# -- per-atom arrays of the wrong shape or type ----------------------------------------------

def evaluated(make):
    atoms = make()
    atoms.get_forces()
    atoms.positions = atoms.positions + 1e-3
    return atoms


def spring_body():
    atoms = bonded_cluster()
    atoms.calc = ase_bpm.BPMSpring(**SPRING)
    return atoms


def granular_pile():
    atoms = spinning_pile()
    SphereVelocityVerlet(atoms, 1e-3).run(2)  # a contact history on the atoms
    return atoms


@pytest.mark.parametrize("make,name,value,message", [
    (spring_body, "type", lambda a: np.array(["1"] * len(a)),
     r'atoms.arrays\["type"\] must hold one integer per atom, got shape \(\d+,\) and dtype <U1'),
    (spring_body, "type", lambda a: np.ones((len(a), 1), int),
     r'atoms.arrays\["type"\] must hold one integer per atom, got shape \(\d+, 1\)'),
    (spring_body, "bond_r0", lambda a: np.ones((len(a), 2)),
     r'atoms.arrays\["bond_r0"\] must be numbers of shape \(\d+, 16\), one per slot of '
     r'atoms.arrays\["bond_type"\], got shape \(\d+, 2\)'),
    (spring_body, "bond_r0", lambda a: np.full(a.arrays["bond_type"].shape, "x"),
     r'atoms.arrays\["bond_r0"\] must be numbers .* dtype <U1'),
    (spring_body, "bond_type", lambda a: a.arrays["bond_type"].astype(float),
     r'atoms.arrays\["bond_type"\] must be an integer array .* dtype float64'),
    (spring_body, "bpm_id", lambda a: a.arrays["bpm_id"].astype(float),
     r'atoms.arrays\["bpm_id"\] must be an integer array .* dtype float64'),
    (granular_pile, "radius", lambda a: a.arrays["radius"][:, None],
     r'atoms.arrays\["radius"\] must hold one number per atom, got shape \(\d+, 1\)'),
    (granular_pile, "omega", lambda a: np.ones(len(a)),
     r'atoms.arrays\["omega"\] must be an N x 3 array'),
    (granular_pile, "gran_partner", lambda a: a.arrays["gran_partner"].astype(float),
     r'atoms.arrays\["gran_partner"\] must be an integer array .* dtype float64'),
    (granular_pile, "gran_shear", lambda a: a.arrays["gran_shear"][:, :3].copy(),
     r'atoms.arrays\["gran_partner"\] and atoms.arrays\["gran_shear"\] do not fit'),
])
def test_a_per_atom_array_of_the_wrong_shape_or_type_is_named(make, name, value, message):
    """A clear error naming the array, its shape and type, and nothing on the
    atoms changed by the failed evaluation."""
    atoms = evaluated(make)
    atoms.arrays[name] = value(atoms)
    before = {k: v.copy() for k, v in atoms.arrays.items()}
    info = dict(atoms.info)
    with pytest.raises(ValueError, match=message):
        atoms.get_forces()
    assert before.keys() == atoms.arrays.keys()
    for k, kept in before.items():  # (NaN marks unset per-bond state)
        assert np.array_equal(kept, atoms.arrays[k], equal_nan=kept.dtype.kind == "f"), k
    assert atoms.info.keys() == info.keys()


def test_ase_combining_bodies_with_and_without_an_array_is_named():
    """``a + b`` fills what ``b`` lacks with zeros: a radius or type of 0 is named."""
    from ase import Atoms

    pile = granular_pile()
    pile += Atoms("H", positions=[[20.0, 20.0, 20.0]])
    with pytest.raises(ValueError, match=r'atoms.arrays\["radius"\] of atom 64 is 0.0'):
        pile.get_forces()
    body = evaluated(spring_body)
    body += Atoms("H", positions=[[20.0, 20.0, 20.0]])
    with pytest.raises(ValueError, match=rf"particle type 0 of atom {len(body) - 1} is invalid"):
        body.get_forces()


def test_quasi_static_steps_are_not_watched_for_spin():
    """``calc.step(atoms)`` after a relaxation: no integrator, nothing to turn."""
    atoms = spinning_pile()
    atoms.get_forces()

    def steps():
        for _ in range(3):
            atoms.positions[:, 2] -= 1e-3
            atoms.calc.step(atoms)

    assert caught(steps) == []


def test_the_warnings_name_the_callers_line():
    atoms = spinning_pile()
    seen = caught(lambda: VelocityVerlet(atoms, 1e-3).run(3))
    assert seen and seen[0].filename == __file__
    body = bonded_cluster()
    for name in [n for n in body.arrays if n.startswith("bond_")]:
        del body.arrays[name]
    body.calc = ase_bpm.BPMSpring(**SPRING)
    seen = caught(body.get_forces)
    assert seen and seen[0].filename == __file__
