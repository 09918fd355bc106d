"""BPMPeri bad input: clear exceptions that name the culprit."""

import numpy as np
import pytest

import ase_bpm
from scenes import HORIZON, SPACING, peri_model, sc_block


@pytest.mark.parametrize("coeffs,message", [
    ({1: ("xyz", 1.0)}, r"bond type 1: unknown model 'xyz' \(one of pmb, lps, ves, eps\)"),
    ({1: ("lps", 1e10, 1e10, HORIZON, 0.5)},
     r"model lps: expected 5 coefficients \(K, G, horizon, s00, alpha\), got 4"),
    ({1: ("pmb", -1.0, HORIZON, 0.5, 0.25)}, r"model pmb: c = -1.0 must be positive"),
    ({1: ("ves", 1e10, 1e10, 1.5, 1e-6, HORIZON, 0.5, 0.25)}, r"lambda = 1.5 must lie"),
])
def test_bad_models(coeffs, message):
    with pytest.raises(ValueError, match=message):
        ase_bpm.BPMPeri(bond_coeffs=coeffs)


def evaluate(atoms, **kwargs):
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb")}, **kwargs)
    return atoms.get_forces()


def test_missing_volumes():
    atoms = sc_block(3)
    del atoms.arrays["vfrac"]
    with pytest.raises(ValueError, match=r'nodal volume of every node in atoms.arrays\["vfrac"\]'):
        evaluate(atoms)


def test_horizon_smaller_than_the_lattice_spacing():
    atoms = sc_block(3)
    with pytest.raises(ValueError, match=r"horizon 0.0015001 is smaller than the lattice "
                                         r"spacing 0.002"):
        evaluate(atoms, lattice_spacing=0.002)


def test_non_cubic_lattice():
    atoms = sc_block(4)
    atoms.positions[:, 2] *= 1.1  # stretched along z: not simple cubic with equal spacing
    with pytest.raises(ValueError, match="not a simple cubic lattice with equal spacing"):
        evaluate(atoms)
    atoms = sc_block(4)
    atoms.positions += np.random.default_rng(0).uniform(-0.1, 0.1, atoms.positions.shape) \
        * SPACING
    with pytest.raises(ValueError, match="pass lattice_spacing="):
        evaluate(atoms)
    assert np.isfinite(evaluate(atoms, lattice_spacing=SPACING)).all()


def test_non_positive_volume_and_unknown_pair_types():
    atoms = sc_block(3)
    atoms.arrays["vfrac"][4] = 0.0
    with pytest.raises(ValueError, match=r'vfrac"\] of node 4 is 0.0'):
        evaluate(atoms)
    atoms = sc_block(3)
    atoms.arrays["type"] = np.ones(len(atoms), dtype=int)
    atoms.arrays["type"][0] = 2
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb")},
                                 pair_coeffs={(1, 1): (1e22, HORIZON)})
    with pytest.raises(ValueError, match=r"unknown particle type pair \(1, 2\)"):
        atoms.get_forces()


def test_ves_without_a_timestep():
    """The first evaluation needs none; a step with ASE's own integrator and no
    timestep given raises, naming the fix; ase_bpm's integrator supplies it."""
    from ase.md.verlet import VelocityVerlet

    atoms = sc_block(4)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("ves")})
    atoms.set_velocities(np.random.default_rng(1).normal(0, 1.0, (len(atoms), 3)))
    atoms.get_forces()
    with pytest.raises(ValueError, match=r"the model of BPMPeri needs the MD timestep: pass "
                                         r"timestep=.*\(ase_bpm.VelocityVerlet\)"):
        VelocityVerlet(atoms, timestep=1e-7).run(1)
    atoms = sc_block(4)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("ves")})
    atoms.set_velocities(np.random.default_rng(1).normal(0, 1.0, (len(atoms), 3)))
    ase_bpm.VelocityVerlet(atoms, timestep=1e-7).run(3)
    assert atoms.info["bpm_step"] == 3
