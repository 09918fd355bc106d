"""Constructors that cannot be misread: keywords only where the LAMMPS line
orders coefficients otherwise, coefficient tuples in the order of their
LAMMPS line (checked against that line written by hand), mappings with
names beside them, a legacy PERI order refused, unknown keywords refused."""

import json

import numpy as np
import pytest

import ase_bpm
from scenes import (BULK, HORIZON, MICROMODULUS, MULTI_TYPE_COEFFS, SPACING,
                    deform_below_breaking, multi_type_cluster, sc_block, sphere_pile)

DT = 1e-3
#: a distinct value in every slot of the granular line, so that any two
#: slots swapped give other forces
GRANULAR = dict(kn=1500.0, kt=700.0, gamma_n=20.0, gamma_t=9.0, xmu=0.35, dampflag=1)
WALL = dict(kn=1900.0, kt=500.0, gamma_n=30.0, gamma_t=4.0, xmu=0.45, dampflag=1)


def relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


# -- Granular and GranularWall: keywords after the model ------------------------------

@pytest.mark.parametrize("make", [ase_bpm.Granular, ase_bpm.GranularWall])
def test_coefficients_by_position_are_refused_naming_the_keywords(make):
    """The LAMMPS order (Kn Kt gamma_n gamma_t xmu dampflag) typed by position
    would have been read as (kn, gamma_n, xmu, kt, ...): refused instead."""
    with pytest.raises(TypeError) as info:
        make("hooke/history", 2000.0, 500.0, 50.0, 25.0, 0.5, 1)
    message = str(info.value)
    for keyword in ("kn=", "kt=", "gamma_n=", "gamma_t=", "xmu=", "dampflag="):
        assert keyword in message
    assert "Kn Kt gamma_n gamma_t xmu dampflag" in message


def test_a_wall_without_its_coefficients_is_refused():
    with pytest.raises(TypeError, match="GranularWall needs gamma_n="):
        ase_bpm.GranularWall("hooke", kn=1.0, xmu=0.0)


@pytest.mark.oracle
@pytest.mark.parametrize("model", ["hooke", "hooke/history", "hertz/history"])
def test_granular_keywords_are_the_lammps_line(Oracle, model):
    """Granular and GranularWall built from the keywords give the forces and
    torques of the pair_style and fix wall/gran lines written by hand, the
    numbers in the LAMMPS order."""
    from granular_oracle import GranularOracle

    atoms = sphere_pile(seed=3)
    wall = ase_bpm.GranularWall(model, **WALL, axis="z", lo=0.2)
    atoms.calc = ase_bpm.Granular(model, **GRANULAR, fixes=[wall])
    lmp = GranularOracle(atoms, atoms.calc, DT)
    try:
        line = " ".join(repr(GRANULAR[k]) for k in ("kn", "kt", "gamma_n", "gamma_t", "xmu"))
        wall_line = " ".join(repr(WALL[k]) for k in ("kn", "kt", "gamma_n", "gamma_t", "xmu"))
        lmp.lmp.commands_list([f"pair_style gran/{model} {line} 1", "pair_coeff * *",
                               "unfix ase_bpm_wall_z",
                               f"fix by_hand all wall/gran {model} {wall_line} 1 "
                               "zplane 0.2 NULL", "run 0"])
        forces = atoms.get_forces()
        torques = atoms.calc.get_property("torques", atoms)
        assert (atoms.positions[:, 2] - atoms.arrays["radius"] < 0.2).sum() >= 3  # on the wall
        assert relative(forces, lmp.get("f")) <= 1e-9
        assert relative(torques, lmp.get("torque")) <= 1e-9
    finally:
        lmp.close()


# -- BPMSpring and BPMPeri: tuples in the order of the line, or mappings -------------

def _named(coeffs, names):
    return {key: dict(zip(names, values)) for key, values in coeffs.items()}


def test_spring_mappings_are_their_tuples():
    """Each tuple as a mapping from its names gives the same forces, bit for
    bit, and a JSON round trip of todict() keeps the mappings."""
    atoms, rng = multi_type_cluster(seed=2)
    tuples = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
    named = ase_bpm.BPMSpring(
        bond_coeffs=_named(MULTI_TYPE_COEFFS["bond_coeffs"], ("k", "eps_c", "gamma")),
        pair_coeffs=_named(MULTI_TYPE_COEFFS["pair_coeffs"], ("k", "r_c", "gamma")))
    again = ase_bpm.BPMSpring(**json.loads(json.dumps(named.todict())))
    copies = [atoms.copy() for _ in range(3)]
    for copy, calc in zip(copies, (tuples, named, again)):
        copy.calc = calc
        copy.get_forces()
    x = deform_below_breaking(copies[0], rng)
    forces = []
    for copy in copies:
        copy.positions = x
        forces.append(copy.get_forces())
    assert np.abs(forces[0]).max() > 0.01
    assert np.array_equal(forces[0], forces[1]) and np.array_equal(forces[0], forces[2])


@pytest.mark.oracle
def test_spring_tuples_are_the_lammps_lines(Oracle):
    """bond_coeff t k eps_c gamma and pair_coeff i j k r_c gamma, written by
    hand from the tuples, give ase_bpm's forces at a deformed, moving state
    (the strains near eps_c, damping on)."""
    atoms, rng = multi_type_cluster(seed=4)
    atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, mix="arithmetic")
    atoms.get_forces()
    lmp = Oracle(atoms, atoms.calc)
    try:
        lines = [f"bond_coeff {t} {k!r} {eps_c!r} {gamma!r}"
                 for t, (k, eps_c, gamma) in MULTI_TYPE_COEFFS["bond_coeffs"].items()]
        lines += [f"pair_coeff {i} {j} {k!r} {rc!r} {gamma!r}"
                  for (i, j), (k, rc, gamma) in MULTI_TYPE_COEFFS["pair_coeffs"].items()]
        lmp.lmp.commands_list(lines)
        lmp.run(0)  # LAMMPS takes the reference lengths here
        x = deform_below_breaking(atoms, rng)
        atoms.positions = x
        lmp.set_state(x, atoms.get_velocities())
        lmp.run(0)
        assert relative(atoms.get_forces(), lmp.forces()) <= 1e-9
    finally:
        lmp.close()


#: the legacy pair_coeff lines of the LAMMPS manual (pair_peri.html), by hand
LEGACY_LINES = {"pmb": "c horizon s00 alpha", "lps": "K G horizon s00 alpha",
                "ves": "K G horizon s00 alpha lambda tau",
                "eps": "K G horizon s00 alpha yield_stress"}
#: the bond_coeff lines of bond_style bpm/peri (bond_bpm_peri.html), by hand
BPM_PERI_LINES = {"pmb": "c horizon s00 alpha", "lps": "K G horizon s00 alpha",
                  "ves": "K G lambda tau horizon s00 alpha",
                  "eps": "K G yield_stress horizon s00 alpha"}
PERI = {"pmb": ("pmb", MICROMODULUS, HORIZON, 0.5, 0.25),
        "lps": ("lps", BULK, 0.6 * BULK, HORIZON, 0.5, 0.25),
        "ves": ("ves", BULK, 0.6 * BULK, 0.4, 1e-6, HORIZON, 0.5, 0.25),
        "eps": ("eps", BULK, 0.6 * BULK, 1e15, HORIZON, 0.5, 0.25)}


@pytest.mark.parametrize("name", list(PERI))
def test_peri_tuples_follow_the_bpm_peri_line(name):
    """The tuple's order is that of the bond_style bpm/peri line; the mapping
    from those names is the same model; the LAMMPS export writes the legacy
    line in its own order."""
    model = PERI[name]
    values = dict(zip(BPM_PERI_LINES[name].split(), model[1:]))
    mapping = {"model": name, **values}
    atoms = sc_block(5)
    contact = {(1, 1): (MICROMODULUS, HORIZON)}  # (legacy PERI's, always on)
    tuples, named = (ase_bpm.BPMPeri(bond_coeffs={1: c}, pair_coeffs=contact, timestep=1e-7,
                                     follows="legacy")
                     for c in (model, mapping))
    assert tuples.model._bond_values == named.model._bond_values == {1: values}
    atoms.calc = tuples
    lines = "\n".join(ase_bpm.scene.lammps.peri_commands(atoms, tuples, "x.data", timestep=1e-7,
                                                   driver_repairs_s0=True))
    legacy = " ".join(repr(values[n]) for n in LEGACY_LINES[name].split())
    assert f"pair_coeff * * {legacy}" in lines


@pytest.mark.oracle
@pytest.mark.parametrize("name", ["ves", "eps"])
def test_peri_mapping_is_the_legacy_line(Oracle, name):
    """A mapping gives, over 30 steps from a deformed moving state, the
    trajectory of the legacy pair_coeff line written by hand (ves relaxes
    with tau; eps stays below its yield stress, where the legacy style's
    update and bpm/peri's radial return agree: any other slot of the
    yield stress, 1e15, would show)."""
    from ase.md.verlet import VelocityVerlet

    from peri_oracle import PeriOracle

    values = dict(zip(BPM_PERI_LINES[name].split(), PERI[name][1:]))
    atoms = sc_block(6)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: {"model": name, **values}},
                                 pair_coeffs={(1, 1): {"k": MICROMODULUS, "horizon": HORIZON}},
                                 timestep=1e-7, follows="legacy")
    atoms.get_forces()
    rng = np.random.default_rng(5)
    x = atoms.positions + rng.uniform(-0.02, 0.02, atoms.positions.shape) * SPACING
    v = rng.normal(0, 1.0, x.shape)
    lmp = PeriOracle(atoms, atoms.calc, timestep=1e-7)
    try:
        legacy = " ".join(repr(values[n]) for n in LEGACY_LINES[name].split())
        lmp.lmp.command(f"pair_coeff * * {legacy}")
        atoms.positions = x
        atoms.set_velocities(v)
        lmp.set_state(x, v)
        VelocityVerlet(atoms, timestep=1e-7).run(30)
        lmp.run(30)
        assert lmp.position_error(atoms.positions).max() <= 1e-9 * SPACING
        assert np.abs(atoms.positions - x).max() > 0.005 * SPACING
    finally:
        lmp.close()


# -- a legacy PERI line typed as a tuple ----------------------------------------------

def _legacy_tuple(name):
    values = dict(zip(BPM_PERI_LINES[name].split(), PERI[name][1:]))
    return (name, *(values[n] for n in LEGACY_LINES[name].split()))


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
@pytest.mark.parametrize("name", ["ves", "eps"])
def test_a_legacy_peri_line_as_a_tuple_is_refused_naming_both_orders(name, kernels):
    """(K G horizon s00 alpha ...) read in bpm/peri order puts alpha or s00 in
    the horizon: the bonds and the spacing show it, and nothing runs."""
    atoms = sc_block(5)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: _legacy_tuple(name)}, timestep=1e-7,
                                 kernels=kernels)
    before = {k: v.copy() for k, v in atoms.arrays.items()}
    with pytest.raises(ValueError) as info:
        atoms.get_forces()
    message = str(info.value)
    assert "bond type 1" in message and "legacy" in message
    assert BPM_PERI_LINES[name] in message and LEGACY_LINES[name] in message
    assert repr(HORIZON) in message  # the horizon it fits in the legacy order
    assert before.keys() == atoms.arrays.keys()
    assert all(np.array_equal(before[k], atoms.arrays[k]) for k in before)
    # the suggested tuple runs
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: PERI[name]}, timestep=1e-7, kernels=kernels)
    assert np.isfinite(atoms.get_forces()).all()


def test_a_legacy_ves_line_in_reduced_units_is_refused_at_once():
    """In units where the horizon exceeds 1 the legacy line puts it in lambda,
    which must lie in [0, 1]: the error says the other order fits."""
    with pytest.raises(ValueError, match=r"lambda = 3.015 must lie between 0 and 1 .*"
                                         r"K G horizon s00 alpha lambda tau"):
        ase_bpm.BPMPeri(bond_coeffs={1: ("ves", 10.0, 5.0, 3.015, 0.1, 0.25, 0.5, 1.0)})


# -- mappings and keywords that do not fit ----------------------------------------------

@pytest.mark.parametrize("coeffs,error,message", [
    ({1: {"k": 1.0, "eps": 0.1, "gamma": 0.0}}, TypeError,
     r"bond type 1: unknown keyword 'eps' \(did you mean 'eps_c'\?\); .* k, eps_c, gamma"),
    ({1: {"k": 1.0, "gamma": 0.0}}, ValueError, r"bond type 1: the mapping lacks eps_c"),
    ({1: {"model": "pmb", "c": 1.0}}, ValueError, r"unknown model 'pmb'"),
])
def test_bad_spring_mappings(coeffs, error, message):
    with pytest.raises(error, match=message):
        ase_bpm.BPMSpring(bond_coeffs=coeffs)


def test_a_peri_mapping_needs_its_model():
    with pytest.raises(ValueError, match=r"bond type 1: unknown model None \(one of pmb"):
        ase_bpm.BPMPeri(bond_coeffs={1: {"c": 1.0, "horizon": 1.0, "s00": 0.1,
                                         "alpha": 0.0}})


@pytest.mark.parametrize("make,word,near", [
    (lambda: ase_bpm.Granular("hooke", kn=1.0, gamma_n=0.0, xmu=0.0, gama_t=1.0),
     "gama_t", "gamma_t"),
    (lambda: ase_bpm.GranularWall("hooke", kn=1.0, gamma_n=0.0, xmu=0.0, gama_t=1.0),
     "gama_t", "gamma_t"),
    (lambda: ase_bpm.BPMSpring(bond_coefs={1: (1.0, 0.1, 0.0)}), "bond_coefs", "bond_coeffs"),
    (lambda: ase_bpm.BPMPeri(lattice_spaceing=1.0), "lattice_spaceing", "lattice_spacing"),
    (lambda: ase_bpm.Gravity(9.81, directon=(0, 0, -1)), "directon", "direction"),
    (lambda: ase_bpm.Gravity(9.81, Direction=(0, 0, -1)), "Direction", "direction"),
    (lambda: ase_bpm.SphericalIndenter(1.0, 1.0, (0, 0, 0), velocty=(0, 0, 1)),
     "velocty", "velocity"),
])
def test_unknown_keywords_are_refused_naming_the_valid_ones(make, word, near):
    with pytest.raises(TypeError, match=rf"unknown keyword '{word}' \(did you mean "
                                        rf"'{near}'\?\); the keywords are .*{near}"):
        make()


def test_set_refuses_unknown_keywords_and_a_failed_set_changes_nothing():
    atoms, rng = multi_type_cluster(seed=6)
    atoms.calc = calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
    forces = atoms.get_forces().copy()
    with pytest.raises(TypeError, match="unknown keyword 'smoth'"):
        calc.set(smoth=False)
    with pytest.raises(ValueError, match="eps_c = -0.1 must be positive"):
        calc.set(bond_coeffs={1: (1.0, -0.1, 0.0), 2: (2.0, 0.12, 0.2)})
    assert calc.parameters["bond_coeffs"] == MULTI_TYPE_COEFFS["bond_coeffs"]
    assert "smoth" not in calc.parameters
    calc.refresh()
    assert np.array_equal(atoms.get_forces(), forces)


@pytest.mark.parametrize("law,coeffs", [("eps", (1.0, 0.5, 2.0, 3.0, 0.1, 0.0)),
                                        ("ves", (1.0, 0.5, 1.0, 1.0, 3.0, 0.1, 0.0))])
@pytest.mark.parametrize("size", [2, 3, 4])
def test_a_bpm_peri_tuple_in_reduced_units_is_not_mistaken(law, coeffs, size):
    """Spacing 1, horizon 3, bodies smaller than the horizon and a yield stress
    or lambda that could pass for a horizon: the legacy reading is invalid
    (alpha = 0 there would be the yield stress), so nothing is refused."""
    from ase import Atoms

    grid = np.arange(size, dtype=float)
    atoms = Atoms(positions=np.array(np.meshgrid(grid, grid, grid)).reshape(3, -1).T)
    atoms.arrays["vfrac"] = np.ones(len(atoms))
    ase_bpm.create_bonds(atoms, 3.0001)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: (law, *coeffs)}, lattice_spacing=1.0,
                                 timestep=0.01)
    assert np.isfinite(atoms.get_forces()).all()


@pytest.mark.parametrize("name", ["ves", "eps"])
def test_a_mapping_is_never_taken_for_a_legacy_line(name):
    """The legacy line's numbers under their bpm/peri names pass at once; a
    mapping's failing check says nothing of another order."""
    atoms = sc_block(5)
    values = dict(zip(BPM_PERI_LINES[name].split(), _legacy_tuple(name)[1:]))
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: {"model": name, **values}}, timestep=1e-7)
    if name == "ves":  # lambda = the horizon (0.0015), tau = s00: valid, and named
        assert np.isfinite(atoms.get_forces()).all()
    bad = {"model": "ves", **dict(zip(BPM_PERI_LINES["ves"].split(), PERI["ves"][1:])),
           "lambda": 2.0}
    with pytest.raises(ValueError) as info:
        ase_bpm.BPMPeri(bond_coeffs={1: bad})
    assert "lambda = 2.0 must lie between 0 and 1" in str(info.value)
    assert "other order" not in str(info.value)


def test_a_coefficient_in_the_model_place_is_refused():
    with pytest.raises(TypeError, match=r"Granular takes every argument after the model by "
                                        r"keyword: .* got 1 coefficient\(s\) by position"):
        ase_bpm.Granular(1000.0)
