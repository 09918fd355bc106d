"""What runs where: ``calc.kernel_routes`` says it per law, and a law without a
compiled twin runs on NumPy beside laws that stay compiled.

Before, one such law sent every bond of the set to NumPy, the ``bpm/spring``
bonds beside it included, while ``calc.kernel_route`` still said "compiled".
"""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.laws.bond import LAWS, BondForces, BondLaw, register
from ase_bpm.laws.peri import Pmb
from ase_bpm.laws.spring import SpringBond
from ase_bpm.laws.timestep import LawStiffness
from scenes import MULTI_TYPE_COEFFS, multi_type_cluster, peri_model, sc_block


class DampedHarmonic(BondLaw):
    """``k (r - r0)`` plus ``gamma`` times the speed apart along the bond,
    broken beyond the strain ``eps_c``; NumPy only (no compiled twin)."""

    name = "test-routes-harmonic"
    coefficients = ("k", "eps_c", "gamma")
    positive = ("k", "eps_c")
    non_negative = ("gamma",)
    breaking_strain = "eps_c"

    @staticmethod
    def uses_velocities(coeff) -> bool:
        return bool(np.any(coeff["gamma"] > 0))

    def forces(self, bonds):
        k, eps_c, gamma = bonds.coeff["k"], bonds.coeff["eps_c"], bonds.coeff["gamma"]
        stretch_b = bonds.r_b - bonds.r0_b
        fd_b = None
        if bonds.v_bc is not None:
            fd_b = gamma * np.einsum("bc,bc->b", bonds.r_bc, bonds.v_bc) / bonds.r_b
        f_b = k * stretch_b + (0.0 if fd_b is None else fd_b)
        breaks_b = np.abs(stretch_b) > eps_c * bonds.r0_b if bonds.breaking else None
        return BondForces(f_b=f_b, energy_b=0.5 * k * stretch_b ** 2, breaks_b=breaks_b,
                          fd_b=fd_b)

    def stiffness(self, bonds):
        return LawStiffness(bonds.coeff["k"], bonds.coeff["gamma"])


@pytest.fixture(autouse=True)
def test_laws():
    register(DampedHarmonic)
    yield
    LAWS.pop(DampedHarmonic.name)


def spring_scene(kernels: str, **parameters):
    """Type-1 bonds bpm/spring, type-2 bonds the NumPy-only law, contacts."""
    atoms, _ = multi_type_cluster(seed=5, pbc=True)
    coeffs = dict(MULTI_TYPE_COEFFS, bond_coeffs={
        1: (1.0, 0.08, 0.5), 2: (DampedHarmonic.name, 2.0, 0.12, 0.2)})
    atoms.calc = ase_bpm.BPMSpring(**coeffs, kernels=kernels, **parameters)
    return atoms


@pytest.mark.compiled
def test_a_law_without_a_twin_runs_numpy_beside_compiled_springs(monkeypatch):
    """The bpm/spring bonds stay on their compiled kernel (their NumPy law
    is never asked), the other law runs on NumPy, and the two together give
    the all-NumPy trajectory to round-off: forces, energy, stress, breaking,
    the ledger."""
    mixed, numpy = spring_scene("compiled"), spring_scene("numpy")
    assert mixed.calc.kernel_route == "compiled"
    assert mixed.calc.kernel_routes == {"bpm/spring": "compiled",
                                        DampedHarmonic.name: "numpy", "contacts": "compiled"}
    assert numpy.calc.kernel_routes == {"bpm/spring": "numpy",
                                        DampedHarmonic.name: "numpy", "contacts": "numpy"}
    for atoms in (mixed, numpy):
        atoms.positions *= 1.04  # strained: some bonds of each law break on the way
    type_of = {(i, j): t for i, j, t in zip(*ase_bpm.get_bonds(numpy))}
    numpy_forces = SpringBond.forces
    VelocityVerlet(numpy, 0.05).run(40)

    def refused(self, bonds):
        raise AssertionError("bpm/spring ran on NumPy on the compiled route")

    monkeypatch.setattr(SpringBond, "forces", refused)
    VelocityVerlet(mixed, 0.05).run(40)
    monkeypatch.setattr(SpringBond, "forces", numpy_forces)

    i_b, j_b, t_b = ase_bpm.get_bonds(numpy, include_broken=True)
    broken_t = set(zip(*ase_bpm.get_bonds(mixed, include_broken=True)))
    assert broken_t == set(zip(i_b, j_b, t_b))
    broke_t = [type_of[int(i), int(j)] for i, j in numpy.info["broken_bonds"][:, :2]]
    assert set(broke_t) == {1, 2}  # bonds of both laws broke
    assert np.array_equal(mixed.info["broken_bonds"][:, :3], numpy.info["broken_bonds"][:, :3])
    scale = np.abs(numpy.get_forces()).max()
    assert np.abs(mixed.get_forces() - numpy.get_forces()).max() < 1e-10 * scale
    assert np.allclose(mixed.positions, numpy.positions, rtol=0, atol=1e-11)
    for key in ("energy", "dissipated_energy", "broken_bond_energy"):
        assert mixed.calc.results[key] == pytest.approx(numpy.calc.results[key], rel=1e-10)
    assert np.allclose(mixed.get_stress(), numpy.get_stress(), rtol=1e-10, atol=1e-14)


@pytest.mark.compiled
def test_a_mixed_first_evaluation_takes_each_laws_reference_lengths():
    """The first evaluation takes the reference lengths of both laws' bonds,
    each on its own route, and a pure evaluation then agrees with NumPy."""
    mixed, numpy = spring_scene("compiled"), spring_scene("numpy")
    for atoms in (mixed, numpy):
        atoms.get_forces()
        assert np.isfinite(atoms.arrays["bond_r0"][atoms.arrays["bond_type"] > 0]).all()
    assert np.allclose(mixed.arrays["bond_r0"], numpy.arrays["bond_r0"], rtol=1e-15,
                       equal_nan=True)
    pure_f = []
    for atoms in (mixed, numpy):
        atoms.positions[:5] += 0.01
        with ase_bpm.pure(atoms):
            pure_f.append(atoms.get_forces())
    assert np.allclose(*pure_f, rtol=0, atol=1e-12)


@pytest.mark.compiled
def test_peri_laws_share_their_route(monkeypatch):
    """BPMPeri runs its laws in one compiled pass over the bonds: a law
    without a twin (here pmb, its twin hidden) puts them all, the contacts
    included, on NumPy, and says so."""
    monkeypatch.setattr(Pmb, "compiled", False)
    together = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb"), 2: peri_model("lps")},
                               pair_coeffs={(1, 1): (1e10, 0.0015001)}, kernels="compiled")
    assert together.kernel_route == "compiled"
    assert together.kernel_routes == {"pmb": "numpy", "lps": "numpy", "contacts": "numpy"}
    alone = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("lps")}, kernels="compiled")
    assert alone.kernel_routes == {"lps": "compiled"}
    atoms = sc_block(4)
    atoms.calc = together
    atoms.get_forces()
    atoms.positions *= 1.001
    forces = atoms.get_forces()
    other = sc_block(4)
    other.calc = ase_bpm.BPMPeri(**{**together.parameters, "kernels": "numpy"})
    other.get_forces()
    other.positions *= 1.001
    assert np.array_equal(other.get_forces(), forces)  # the same (NumPy) kernels


def test_granular_reports_its_route():
    calc = ase_bpm.Granular("hooke", kn=1.0, gamma_n=0.0, xmu=0.0, kernels="numpy")
    assert (calc.kernel_route, calc.kernel_routes) == ("numpy", {"contacts": "numpy"})
