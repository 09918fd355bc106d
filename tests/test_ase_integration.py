"""BPMSpring inside ASE's own machinery: trajectories, thermostats, todict."""

import json

import numpy as np
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
    assert again._pair_coeffs == {(1, 1): (1.0, 1.0, 0.5)}


def test_langevin_thermostat_drives_the_calculator():
    """ASE's Langevin integrator runs on BPMSpring; one evaluation per step."""
    atoms = bonded_block()
    calc = ase_bpm.BPMSpring(**COEFFS)
    atoms.calc = calc
    dyn = Langevin(atoms, timestep=0.05, temperature_K=0, friction=0.5, fixcm=False,
                   rng=np.random.default_rng(0))
    ke0 = atoms.get_kinetic_energy()
    dyn.run(200)
    assert atoms.info["bpm_step"] == 200
    assert atoms.get_kinetic_energy() < 0.1 * ke0  # friction, at zero temperature
