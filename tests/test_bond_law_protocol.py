"""A bond law is one small class plus one line of registration.

The law below lives in this test, outside the package: a harmonic spring that
breaks at a strain.  Registered, it runs through the shared machinery of
:class:`ase_bpm.models.bonded.BondedModel`: reference lengths, breaking in
steps, the broken-bond record, the energy ledger, restart files, and bond
types of different laws side by side.
"""

import numpy as np
import pytest
from ase import Atoms
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.laws.bond import LAWS, BondForces, BondLaw, register
from scenes import fcc_cluster, peri_model


class Harmonic(BondLaw):
    """``k (r - r0)``, energy ``k (r - r0)^2 / 2``, broken beyond strain ``eps_c``."""

    name = "harmonic"
    coefficients = ("k", "eps_c")
    positive = ("k", "eps_c")
    breaking_strain = "eps_c"

    def forces(self, bonds):
        k, eps_c = bonds.coeff["k"], bonds.coeff["eps_c"]
        stretch_b = bonds.r_b - bonds.r0_b
        return BondForces(f_b=k * stretch_b, energy_b=0.5 * k * stretch_b ** 2,
                          breaks_b=np.abs(stretch_b) > eps_c * bonds.r0_b)


@pytest.fixture(autouse=True)
def harmonic_law():
    register(Harmonic)  # the one line of registration
    yield
    LAWS.pop("harmonic")


def chain():
    """Three atoms in a row, bonded 0-1 and 1-2 (lammps-data strings)."""
    atoms = Atoms("H3", positions=[[0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]], masses=[1, 1, 1])
    atoms.arrays["bonds"] = np.array(["1(1)", "2(1)", "_"])
    return atoms


def test_forces_and_energy_are_the_law():
    atoms = chain()
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: ("harmonic", 3.0, 0.5)})
    assert np.abs(atoms.get_forces()).max() == 0  # reference lengths taken now
    atoms.positions[2] = [2.2, 0.1, 0.0]
    r12 = atoms.positions[2] - atoms.positions[1]
    length = np.linalg.norm(r12)
    f = atoms.get_forces()
    expected = 3.0 * (length - 1.0) * r12 / length  # on atom 1, towards atom 2
    assert np.allclose(f[1], expected, rtol=1e-14) and np.allclose(f[2], -expected)
    assert np.all(f[0] == 0)
    assert atoms.get_potential_energy() == pytest.approx(1.5 * (length - 1.0) ** 2, rel=1e-14)


def test_breaking_record_and_ledger_come_from_the_machinery():
    atoms = chain()
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: ("harmonic", 2.0, 0.1)})
    atoms.get_forces()
    atoms.positions[2, 0] = 2.05  # strain 0.05: holds
    held = atoms.get_potential_energy()
    assert held == pytest.approx(0.5 * 2.0 * 0.05 ** 2)
    atoms.positions[2, 0] = 2.15  # strain 0.15: breaks in this step
    assert np.all(atoms.get_forces() == 0)
    i, j, t = ase_bpm.get_bonds(atoms, include_broken=True)
    assert list(zip(i, j, t)) == [(0, 1, 1), (1, 2, 0)]
    log = atoms.info["broken_bonds"]
    assert log.shape == (1, 9) and tuple(log[0, :3]) == (1, 2, 2)
    released = atoms.calc.results["broken_bond_energy"]
    assert released == pytest.approx(0.5 * 2.0 * 0.15 ** 2)
    assert list(atoms.arrays["nbonds"]) == [1, 1, 0]


def test_restart_continues_bit_for_bit(tmp_path):
    atoms, rng = fcc_cluster(3, seed=21)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.1, atoms.positions.shape))
    coeffs = dict(bond_coeffs={1: ("harmonic", 1.0, 0.06)},
                  pair_coeffs={(1, 1): (1.0, 1.0, 0.0)})
    straight = atoms.copy()
    straight.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(straight, 0.1).run(200)
    assert straight.arrays["damage"].max() > 0  # the law broke bonds on the way

    atoms.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(atoms, 0.1).run(100)
    ase_bpm.write_restart(tmp_path / "run.bpm", atoms)
    resumed = ase_bpm.read_restart(tmp_path / "run.bpm")
    resumed.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(resumed, 0.1).run(100)
    assert np.array_equal(resumed.positions, straight.positions)
    assert np.array_equal(resumed.arrays["bond_type"], straight.arrays["bond_type"])
    assert resumed.info["bpm_broken_bond_energy"] == straight.info["bpm_broken_bond_energy"]


def test_laws_side_by_side_and_bad_names():
    atoms = chain()
    atoms.arrays["bonds"] = np.array(["1(1)", "2(2)", "_"])
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: ("harmonic", 2.0, 0.5),
                                                2: (5.0, 0.5, 0.0)})  # bpm/spring
    atoms.get_forces()
    atoms.positions[:, 0] *= 1.1
    f = atoms.get_forces()
    assert f[0, 0] == pytest.approx(2.0 * 0.1)  # harmonic pulls atom 0 along +x
    spring = 5.0 * 0.1 * (1 - (0.1 / 0.5) ** 8)  # bpm/spring, smoothed
    assert f[2, 0] == pytest.approx(-spring)
    with pytest.raises(ValueError, match=r"bond type 1: unknown model 'cubic'"):
        ase_bpm.BPMSpring(bond_coeffs={1: ("cubic", 1.0)})
    with pytest.raises(ValueError, match=r"bond type 1: unknown model 'pmb'"):
        ase_bpm.BPMSpring(bond_coeffs={1: ("pmb", 1.0, 1.0, 0.5, 0.25)})  # a BPMPeri law
    with pytest.raises(ValueError, match=r"model harmonic: expected 2 coefficients"):
        ase_bpm.BPMSpring(bond_coeffs={1: ("harmonic", 1.0)})
    with pytest.raises(TypeError, match="not a named BondLaw"):
        register(object)


def test_a_law_without_a_lammps_style_is_not_exported(tmp_path):
    from ase_bpm import write_lammps

    atoms = chain()
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: ("harmonic", 2.0, 0.5)})
    with pytest.raises(ValueError, match=r"bond type 1 follows the law 'harmonic', which "
                                         r"bond_style bpm/spring cannot run"):
        write_lammps(str(tmp_path / "chain"), atoms)


class Unbreakable(BondLaw):
    """``k (r - r0)`` that never breaks: ``breaks_b=None`` in every evaluation."""

    name = "test-unbreakable"
    coefficients = ("k",)
    positive = ("k",)

    def forces(self, bonds):
        k = bonds.coeff["k"]
        stretch_b = bonds.r_b - bonds.r0_b
        return BondForces(f_b=k * stretch_b, energy_b=0.5 * k * stretch_b ** 2, breaks_b=None)


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_a_law_that_never_breaks_says_none_beside_one_that_breaks(kernels):
    """breaks_b=None means "this law never breaks": with breaking on, its
    bond holds at any strain, in steps and in pure evaluations, while a
    bpm/spring bond beside it breaks as its own criterion says (before,
    the evaluation stopped with AttributeError)."""
    register(Unbreakable)
    try:
        atoms = chain()
        atoms.arrays["bonds"] = np.array(["1(1)", "2(2)", "_"])
        atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: ("test-unbreakable", 2.0),
                                                    2: (5.0, 0.05, 0.0)}, kernels=kernels)
        atoms.get_forces()
        atoms.positions[:, 0] *= 1.5  # both bonds at strain 0.5
        with ase_bpm.pure(atoms):
            pure_f = atoms.get_forces()
        assert pure_f[0, 0] == pytest.approx(2.0 * 0.5)  # held, pulling atom 0 along +x
        assert pure_f[2, 0] == 0.0  # the spring acts broken in a pure evaluation
        assert len(ase_bpm.get_bonds(atoms)[0]) == 2  # and nothing is recorded
        atoms.calc.step(atoms)
        i_b, j_b, _ = ase_bpm.get_bonds(atoms)
        assert (list(i_b), list(j_b)) == ([0], [1])  # the spring broke in the step
        atoms.positions[1, 0] += 10.0  # strain 20
        atoms.calc.step(atoms)
        assert len(ase_bpm.get_bonds(atoms)[0]) == 1  # never
    finally:
        LAWS.pop("test-unbreakable")


def test_a_name_taken_by_another_law_is_refused():
    """register would silently replace a law of the same name (a test that
    then popped "harmonic" would have deleted a packaged law of that name)."""
    class Impostor(BondLaw):
        name = "bpm/spring"
        coefficients = ("k",)

        def forces(self, bonds):
            raise AssertionError("never evaluated")

    with pytest.raises(ValueError, match=r"register: the bond law name 'bpm/spring' is taken "
                                         r"by ase_bpm\.laws\.spring\.\w+; give "
                                         r"test_bond_law_protocol\..*Impostor a name of its "
                                         r"own"):
        register(Impostor)
    assert LAWS["bpm/spring"].__module__ == "ase_bpm.laws.spring"


def test_a_law_defined_again_as_a_notebook_cell_run_twice_takes_its_place():
    source = ("from ase_bpm.laws.bond import BondLaw, register\n"
              "@register\n"
              "class Cell(BondLaw):\n"
              "    name = 'test-cell'\n"
              "    coefficients = ('k',)\n")
    first, second = {"__name__": "__main__"}, {"__name__": "__main__"}
    try:
        exec(source, first)
        exec(source, second)  # (the cell run again: a new class of the same name)
        assert LAWS["test-cell"] is second["Cell"] is not first["Cell"]
    finally:
        LAWS.pop("test-cell")


def test_bpmperi_refuses_a_registered_law_it_has_no_node_state_for():
    """BPMPeri's node pass (weighted volume, dilatation) knows its own four
    laws: a law registered as one of them, under a name of its own, is
    refused by name and bond type rather than failing inside."""
    class OwnPMB(LAWS["pmb"]):
        name = "test-own-pmb"

    register(OwnPMB)
    try:
        with pytest.raises(ValueError, match=r"bond_coeffs for bond type 1: BPMPeri has no "
                                             r"node state for the registered law "
                                             r"'test-own-pmb': its bond laws are pmb, lps"):
            ase_bpm.BPMPeri(bond_coeffs={1: (OwnPMB.name,) + peri_model("pmb")[1:]})
    finally:
        LAWS.pop(OwnPMB.name)
