"""BPMSpring inside ASE's own machinery: trajectories, thermostats, todict."""

import json

import numpy as np
import pytest
from ase import Atoms
from ase.io import Trajectory, read
from ase.md.langevin import Langevin
from ase.md.verlet import VelocityVerlet

import ase_bpm
from scenes import fcc_cluster

COEFFS = dict(bond_coeffs={1: (1.0, 0.1, 0.5)}, pair_coeffs={(1, 1): (1.0, 1.0, 0.5)})


def bonded_block():
    atoms, rng = fcc_cluster(3, seed=21)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    return atoms


def test_ase_trajectory_records_an_md_run(tmp_path):
    atoms = bonded_block()
    atoms.calc = ase_bpm.BPMSpring(**COEFFS)
    dyn = VelocityVerlet(atoms, timestep=0.1)
    with Trajectory(tmp_path / "md.traj", "w", atoms) as traj:
        dyn.attach(traj.write, interval=5)
        dyn.run(20)
    frames = read(tmp_path / "md.traj", ":")
    assert len(frames) == 5
    assert np.allclose(frames[-1].get_forces(), atoms.get_forces())


def test_parameters_survive_json():
    calc = ase_bpm.BPMSpring(**COEFFS, mix="arithmetic", smooth=False)
    again = ase_bpm.BPMSpring(**json.loads(json.dumps(calc.todict())))
    assert again.todict() == calc.todict()
    assert again.model._pair_coeffs == {(1, 1): (1.0, 1.0, 0.5)}


def test_langevin_thermostat_drives_the_calculator():
    """ASE's Langevin integrator runs on BPMSpring; one evaluation per step."""
    atoms = bonded_block()
    calc = ase_bpm.BPMSpring(**COEFFS)
    atoms.calc = calc
    dyn = Langevin(atoms, timestep=0.05, temperature_K=0, friction=0.5, fixcm=False,
                   rng=np.random.default_rng(0))
    ke0 = atoms.get_kinetic_energy()
    with pytest.warns(ase_bpm.TimestepUncheckedWarning, match="pass timestep="):
        dyn.run(200)  # (without timestep=, the thermostat's cannot be told)
    assert atoms.info["bpm_step"] == 200
    assert atoms.get_kinetic_energy() < 0.1 * ke0  # friction, at zero temperature


@pytest.mark.parametrize("model", ["spring", "granular"])
def test_changed_parameters_apply_at_the_same_positions(model):
    """``calc.set(...)`` takes effect at the next request even if the atoms
    have not moved (ASE keeps results until they do): the forces are those
    of a fresh calculator with the new parameters."""
    if model == "spring":
        atoms, rng = fcc_cluster(2, seed=5)
        ase_bpm.create_bonds(atoms, 1.25)
        atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0)})
        atoms.get_forces()  # the bonds' rest lengths are taken here
        atoms.positions += rng.normal(0, 0.05, atoms.positions.shape)
        old, new = dict(bond_coeffs={1: (1.0, 0.5, 0.0)}), dict(bond_coeffs={1: (3.0, 0.5, 0.0)})
        make = ase_bpm.BPMSpring  # (attached afresh below, the rest lengths on the atoms)
    else:  # two spheres pressed together and sliding: friction on, then off
        atoms = Atoms("H2", positions=[[0, 0, 0], [0.95, 0, 0]])
        atoms.arrays["radius"] = np.full(2, 0.5)
        atoms.set_velocities([[0, 0.5, 0], [0, -0.5, 0]])
        old = dict(model="hooke", kn=2000.0, gamma_n=50.0, xmu=0.5)
        new = dict(old, xmu=0.0)
        make = ase_bpm.Granular
    atoms.calc = make(**old)
    before = atoms.get_forces().copy()
    atoms.calc.set(**new)
    fresh = atoms.copy()
    fresh.calc = make(**new)
    assert np.abs(before - fresh.get_forces()).max() > 1e-3  # the change matters
    np.testing.assert_allclose(atoms.get_forces(), fresh.get_forces(), rtol=0, atol=1e-14)
