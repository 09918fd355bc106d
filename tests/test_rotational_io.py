"""bpm/rotational scenes out to LAMMPS and back: write_lammps, read_lammps."""

import warnings

import numpy as np
import pytest

import ase_bpm
from ase_bpm.scene.lammps import write_lammps
from test_rotational_oracle import GRANULAR, rotational_cluster

#: (scenes turned a little before their bonds take the reference state)
pytestmark = pytest.mark.filterwarnings("ignore::ase_bpm.RotatedReferenceWarning")


def read_quietly(deck):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ase_bpm.IgnoredCommandsWarning)
        return ase_bpm.read_lammps(deck)


@pytest.mark.parametrize("granular", [None, GRANULAR[0]], ids=["pair-bpm-spring", "gran"])
def test_a_rotational_scene_reads_back_as_it_went_out(tmp_path, granular):
    """Coefficients in the bond_coeff order, the keywords, the contacts and
    the orientations come back (to the last digits: LAMMPS's 'set quat'
    takes an angle in degrees), and so do the forces and torques."""
    atoms, calc, _ = rotational_cluster(pair=granular is None, normalize=True,
                                        overlay_pair=False)
    if granular is not None:
        calc = ase_bpm.BPMSpring(bond_coeffs=calc.parameters["bond_coeffs"],
                                 normalize=True, granular=granular)
        atoms.calc = calc
    _, deck = write_lammps(str(tmp_path / "scene"), atoms, calc, timestep=0.1, steps=10)
    text = open(deck).read()
    assert "bond_style bpm/rotational" in text and "fix integrate all nve/bpm/sphere" in text
    back = read_quietly(deck)
    p, q = calc.parameters, back.calc.parameters
    assert q["bond_coeffs"] == p["bond_coeffs"]
    assert q["normalize"] and q["smooth"]
    if granular is not None:
        assert {k: q["granular"][k] for k in granular} == granular
    assert np.abs(back.arrays["quat"] - atoms.arrays["quat"]).max() <= 1e-15
    # (1e-10: the orientations differ in the last digits, and the law's arccos
    # near rest makes that 1e-11 of the forces)
    forces = atoms.get_forces()
    assert np.abs(back.get_forces() - forces).max() <= 1e-10 * np.abs(forces).max()
    torques = calc.results["torques"]
    assert np.abs(back.calc.results["torques"] - torques).max() <= 1e-10 * np.abs(torques).max()


def test_rotational_bonds_need_the_integrator_that_turns_them(tmp_path):
    atoms, calc, _ = rotational_cluster()
    _, deck = write_lammps(str(tmp_path / "scene"), atoms, calc, timestep=0.1, steps=10)
    text = open(deck).read().replace("nve/bpm/sphere", "nve/sphere")
    open(deck, "w").write(text)
    with pytest.raises(ValueError, match=r"reads one 'fix <id> all nve/bpm/sphere'"):
        read_quietly(deck)


def test_a_rotational_bond_coeff_line_of_another_length_is_refused_by_line(tmp_path):
    atoms, calc, _ = rotational_cluster()
    _, deck = write_lammps(str(tmp_path / "scene"), atoms, calc, timestep=0.1, steps=10)
    lines = open(deck).read().splitlines()
    number = next(k for k, line in enumerate(lines) if line.startswith("bond_coeff 1 "))
    lines[number] = "bond_coeff 1 1.0 0.2 0.05"
    open(deck, "w").write("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=rf"line {number + 1}: 'bond_coeff 1 1.0 0.2 0.05': "
                                         r"read_lammps reads 'bond_coeff <type> k_r k_s k_t"):
        read_quietly(deck)


def test_mixing_bond_styles_is_refused_naming_the_types(tmp_path):
    atoms, calc, _ = rotational_cluster()
    calc = ase_bpm.BPMSpring(bond_coeffs={1: calc.parameters["bond_coeffs"][1],
                                          2: (1.0, 0.1, 0.0)})
    atoms.calc = calc
    with pytest.raises(ValueError, match=r"one bond_style, and these bond types need several "
                                         r"\(bpm/rotational: bond types 1; bpm/spring: bond "
                                         r"types 2\)"):
        write_lammps(str(tmp_path / "scene"), atoms, calc)


def test_the_contact_skin_of_granular_contacts_beside_bonds():
    atoms, calc, _ = rotational_cluster(pair=False)
    given = ase_bpm.BPMSpring(bond_coeffs=calc.parameters["bond_coeffs"],
                              granular={**GRANULAR[0], "skin": 0.25})
    assert given.contact_skin() == 0.25
    default = ase_bpm.BPMSpring(bond_coeffs=calc.parameters["bond_coeffs"],
                                granular=GRANULAR[0])
    assert default.contact_skin() is None  # (it follows the radii)
    r_n = atoms.arrays["radius"]
    assert default.contact_skin(r_n) == ase_bpm.Granular(**GRANULAR[0]).contact_skin(r_n)


def test_wildcard_coefficient_lines_are_read_as_lammps_reads_them(tmp_path):
    """'pair_coeff * *' and 'bond_coeff *' (and 'm*n' ranges), as LAMMPS's
    examples write them, give every type or pair of types of the range."""
    from test_rotational_oracle import SOFT

    atoms, calc, _ = rotational_cluster()
    _, deck = write_lammps(str(tmp_path / "scene"), atoms, calc, timestep=0.1, steps=10)
    lines = [line for line in open(deck).read().splitlines()
             if not line.startswith(("pair_coeff", "bond_coeff "))]
    at = next(k for k, line in enumerate(lines) if line.startswith("pair_modify"))
    lines[at + 1:at + 1] = ["pair_coeff * * 1.0 1.0 0.5", "pair_coeff 2*2 2* 1.5 1.1 0.3"]
    at = next(k for k, line in enumerate(lines) if line.startswith("bond_style"))
    lines[at + 1:at + 1] = ["bond_coeff * " + " ".join(map(str, SOFT))]
    open(deck, "w").write("\n".join(lines) + "\n")
    back = read_quietly(deck)
    assert back.calc.parameters["pair_coeffs"] == {
        (1, 1): (1.0, 1.0, 0.5), (1, 2): (1.0, 1.0, 0.5), (2, 2): (1.5, 1.1, 0.3)}
    assert back.calc.parameters["bond_coeffs"] == {t: ("bpm/rotational", *SOFT) for t in (1, 2)}
