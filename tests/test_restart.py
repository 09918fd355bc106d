"""Restart files: lossless state, bit-identical continuation."""

import numpy as np
import pytest
from ase.constraints import FixAtoms
from ase.md.verlet import VelocityVerlet

import ase_bpm
from scenes import fcc_cluster

# (length, mass, time) scales: reduced LJ units and an SI-scale scene
UNITS = {"reduced": (1.0, 1.0, 1.0), "SI": (5e-4, 2.75e-7, 1e-7)}


def scene(length, mass, time):
    atoms, rng = fcc_cluster(4, seed=3, masses=(mass,))
    atoms.positions *= length
    atoms.cell *= length
    ase_bpm.create_bonds(atoms, 1.5 * length)
    atoms.set_velocities(rng.normal(0, 0.08, atoms.positions.shape) * length / time)
    stiffness, damping = mass / time ** 2, mass / time
    coeffs = dict(bond_coeffs={1: (1.0 * stiffness, 0.06, 0.2 * damping)},
                  pair_coeffs={(1, 1): (1.0 * stiffness, 1.0 * length, 0.5 * damping)})
    return atoms, coeffs


@pytest.mark.parametrize("units", UNITS)
def test_restart_mid_run_continues_bit_identically(tmp_path, units):
    length, mass, time = UNITS[units]
    dt = 0.1 * time
    straight, coeffs = scene(length, mass, time)
    interrupted = straight.copy()
    straight.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(straight, dt).run(200)

    interrupted.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(interrupted, dt).run(100)
    ase_bpm.write_restart(tmp_path / "run.bpm", interrupted)
    resumed = ase_bpm.read_restart(tmp_path / "run.bpm")
    resumed.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(resumed, dt).run(100)

    assert np.array_equal(resumed.positions, straight.positions)
    assert np.array_equal(resumed.get_momenta(), straight.get_momenta())
    for name in ("bpm_id", "bond_partner", "bond_type", "bond_r0"):
        assert np.array_equal(resumed.arrays[name], straight.arrays[name], equal_nan=True)
    for a, b in zip(ase_bpm.get_bonds(resumed, True), ase_bpm.get_bonds(straight, True)):
        assert np.array_equal(a, b)
    assert (straight.arrays["damage"] > 0).sum() > 50  # bonds broke on the way
    for key in ("bpm_step", "bpm_dissipated_energy", "bpm_broken_bond_energy"):
        assert resumed.info[key] == straight.info[key]


def test_copy_carries_the_whole_state():
    atoms, coeffs = scene(1.0, 1.0, 1.0)
    atoms.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(atoms, 0.1).run(50)
    twin = atoms.copy()
    twin.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(atoms, 0.1).run(50)
    VelocityVerlet(twin, 0.1).run(50)
    assert np.array_equal(twin.positions, atoms.positions)


def test_restart_file_keeps_everything_bit_for_bit(tmp_path):
    atoms, coeffs = scene(*UNITS["SI"])
    atoms.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(atoms, 1e-8).run(20)
    atoms.info["note"] = "hello"
    atoms.info["scalar"] = np.float64(1.25)
    atoms.set_constraint(FixAtoms(indices=[0, 3]))
    ase_bpm.write_restart(tmp_path / "state.npz", atoms)
    back = ase_bpm.read_restart(tmp_path / "state.npz")
    assert set(back.arrays) == set(atoms.arrays)
    for name, array in atoms.arrays.items():
        assert back.arrays[name].dtype == array.dtype
        assert np.array_equal(back.arrays[name], array, equal_nan=array.dtype.kind == "f")
    assert np.array_equal(back.cell, atoms.cell) and np.array_equal(back.pbc, atoms.pbc)
    assert set(back.info) == set(atoms.info)
    for key, value in atoms.info.items():
        assert np.array_equal(back.info[key], value)
    assert back.constraints[0].todict() == atoms.constraints[0].todict()
    # SI-scale momenta (extxyz would keep only a few digits of them)
    assert 0 < np.abs(back.get_momenta()).max() < 1e-3


def test_unstorable_state_is_refused_by_name(tmp_path):
    atoms, _ = scene(1.0, 1.0, 1.0)
    atoms.arrays["labels"] = np.array([object()] * len(atoms))
    with pytest.raises(TypeError, match="labels"):
        ase_bpm.write_restart(tmp_path / "x.npz", atoms)
