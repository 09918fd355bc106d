"""BPMPeri against the reference LAMMPS build's legacy peri/* pair styles."""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from scenes import (BULK, HORIZON, MICROMODULUS, NODE_VOLUME, SPACING, peri_model,
                    sc_block)

pytestmark = pytest.mark.oracle
MODELS = ["pmb", "lps", "ves", "eps"]
DT = 1e-7


@pytest.fixture(scope="module")
def PeriOracle(Oracle):  # the Oracle fixture fails in CI without LAMMPS
    from peri_oracle import PeriOracle

    return PeriOracle


def calculator(model, follows="legacy", **kwargs):
    """BPMPeri following the legacy styles the reference build has."""
    contact = MICROMODULUS  # 18 K / (pi horizon^4) for the state-based models too
    return ase_bpm.BPMPeri(bond_coeffs={1: model}, pair_coeffs={(1, 1): (contact, HORIZON)},
                           timestep=DT, follows=follows, **kwargs)


def deformed_moving_state(name, seed=7, block=None, jitter=0.02):
    atoms = sc_block(6) if block is None else block
    atoms.calc = calculator(peri_model(name))
    atoms.get_forces()  # reference state
    rng = np.random.default_rng(seed)
    x = atoms.positions + rng.uniform(-jitter, jitter, atoms.positions.shape) * SPACING
    v = rng.normal(0, 1.0, x.shape)
    return atoms, x, v


def forces_of_both(PeriOracle, atoms, x, v):
    """ase_bpm's and LAMMPS's forces at the state ``(x, v)``, both from the
    reference state the atoms are in."""
    lmp = PeriOracle(atoms, atoms.calc, timestep=DT)
    try:
        atoms.positions = x
        atoms.set_velocities(v)
        lmp.set_state(x, v)
        lmp.run(0)
        return atoms.get_forces(), lmp.forces()
    finally:
        lmp.close()


@pytest.mark.parametrize("name", MODELS)
def test_forces_at_a_deformed_state(PeriOracle, name):
    atoms, x, v = deformed_moving_state(name)
    forces, expected = forces_of_both(PeriOracle, atoms, x, v)
    assert np.abs(forces - expected).max() <= 1e-12 * np.abs(expected).max()
    if name != "pmb":
        assert np.abs(atoms.arrays["dilatation"]).max() > 1e-3


@pytest.mark.parametrize("name", MODELS)
def test_trajectory_from_a_deformed_moving_state(PeriOracle, name):
    """150 steps of velocity Verlet from a deformed, moving state, bonded pairs
    kept above 0.9 r0 (below, the legacy styles add contact between bonded
    nodes).  LAMMPS advances ves history at every force evaluation, setup
    included, so its run starts right from the deformed state as ours does."""
    atoms, x, v = deformed_moving_state(name)
    lmp = PeriOracle(atoms, atoms.calc, timestep=DT)
    try:
        atoms.positions = x
        atoms.set_velocities(v)
        lmp.set_state(x, v)
        VelocityVerlet(atoms, timestep=DT).run(150)
        lmp.run(150)
        assert lmp.position_error(atoms.positions).max() <= 1e-9 * SPACING
        assert np.abs(atoms.positions - x).max() > 0.02 * SPACING  # they did move
    finally:
        lmp.close()


def test_fracture_breaks_the_same_bonds(PeriOracle):
    """A brittle pmb block torn in two: thousands of bonds break over 400 steps,
    with the same damage on every node as the legacy style."""
    atoms = sc_block(12, 6, 6)
    atoms.calc = calculator(peri_model("pmb", s00=0.0005))
    atoms.get_forces()
    lmp = PeriOracle(atoms, atoms.calc, timestep=DT)
    try:
        v = np.zeros((len(atoms), 3))
        v[:, 0] = np.where(atoms.positions[:, 0] > 5.5 * SPACING, 3.0, -3.0)
        atoms.set_velocities(v)
        lmp.set_state(atoms.positions, v)
        VelocityVerlet(atoms, timestep=DT).run(400)
        lmp.run(400)
        assert len(atoms.info["broken_bonds"]) > 1000
        assert atoms.arrays["damage"].max() > 0.5
        assert np.abs(atoms.arrays["damage"] - lmp.damage()).max() <= 1e-12
        assert lmp.position_error(atoms.positions).max() <= 1e-9 * SPACING
    finally:
        lmp.close()


def test_colliding_blocks_meet_through_contact(PeriOracle):
    """Two separate blocks collide: only the contact law acts between them."""
    left, right = sc_block(5), sc_block(5, offset=(8.5, 0.3, 0.2))
    atoms = left + right  # bonds refer to atom IDs: each body keeps its own
    i, j, t = ase_bpm.get_bonds(atoms)
    il, jl, tl = ase_bpm.get_bonds(left)
    ir, jr, tr = ase_bpm.get_bonds(right)
    assert np.array_equal(i, np.r_[il, ir + len(left)])
    assert np.array_equal(j, np.r_[jl, jr + len(left)]) and np.array_equal(t, np.r_[tl, tr])
    atoms.calc = calculator(peri_model("pmb"), lattice_spacing=SPACING)
    atoms.get_forces()
    lmp = PeriOracle(atoms, atoms.calc, timestep=DT, spacing=SPACING)
    try:
        v = np.zeros((len(atoms), 3))
        v[: len(left), 0], v[len(left):, 0] = 20.0, -20.0
        atoms.set_velocities(v)
        lmp.set_state(atoms.positions, v)
        VelocityVerlet(atoms, timestep=DT).run(600)
        lmp.run(600)
        assert atoms.get_velocities()[: len(left), 0].mean() < 0  # bounced back
        assert lmp.position_error(atoms.positions).max() <= 1e-9 * SPACING
    finally:
        lmp.close()


def test_moving_indenter_is_lammps_fix_indent(PeriOracle):
    """A spherical indenter driven into a pmb block at rest, at 50 m/s:
    ase_bpm's SphericalIndenter (true forces, k = K V) against LAMMPS ``fix
    indent K`` on legacy PERI (force densities), 300 steps with fracture.
    The block stands still until the indenter arrives: ase_bpm's integrator
    keeps the clock running."""
    atoms = sc_block(8, 4, 8)
    indenter = ase_bpm.SphericalIndenter(
        k=1e17 * NODE_VOLUME, radius=0.0015, centre=(0.00175, 0.0032, 0.00175),
        velocity=(0.0, -50.0, 0.0))
    atoms.calc = calculator(peri_model("pmb", s00=0.0005), fixes=[indenter])
    atoms.get_forces()
    lmp = PeriOracle(atoms, atoms.calc, timestep=DT)
    try:
        ase_bpm.VelocityVerlet(atoms, timestep=DT).run(300)
        lmp.run(300)
        assert atoms.arrays["damage"].max() > 0.15
        assert np.abs(atoms.arrays["damage"] - lmp.damage()).max() <= 1e-12
        assert lmp.position_error(atoms.positions).max() <= 1e-9 * SPACING
    finally:
        lmp.close()


@pytest.mark.parametrize("model", ["pmb", "lps"])
def test_unbreakable_bonds_export_as_a_stretch_none_reaches(model, PeriOracle):
    """``break_bonds=False`` (no test at all) has no legacy PERI switch: the
    export gives s00 a stretch no bond reaches.  The indenter of the test
    above, which fractures the block with breaking on, then damages nothing
    in either code, and the trajectories agree."""
    atoms = sc_block(8, 4, 8)
    indenter = ase_bpm.SphericalIndenter(
        k=1e17 * NODE_VOLUME, radius=0.0015, centre=(0.00175, 0.0032, 0.00175),
        velocity=(0.0, -50.0, 0.0))
    atoms.calc = calculator(peri_model(model, s00=0.0005), fixes=[indenter],
                            break_bonds=False)
    atoms.get_forces()
    lmp = PeriOracle(atoms, atoms.calc, timestep=DT)
    try:
        ase_bpm.VelocityVerlet(atoms, timestep=DT).run(300)
        lmp.run(300)
        assert atoms.arrays["damage"].max() == 0 and lmp.damage().max() == 0
        assert lmp.position_error(atoms.positions).max() <= 1e-9 * SPACING
    finally:
        lmp.close()


def test_exported_peri_deck_runs_in_lammps(tmp_path, PeriOracle):
    """``write_lammps`` turns a BPMPeri scene into a legacy-PERI deck that the
    reference build runs as it is; export refuses what legacy PERI cannot
    express: the state-based models (whose s0 the reference build leaves
    uninitialised), a scene without all the bonds within the horizon."""
    from ase_bpm import write_lammps
    from oracle import run_deck

    atoms = sc_block(5)
    for name in ("lps", "ves", "eps"):
        atoms.calc = calculator(peri_model(name))
        with pytest.raises(ValueError, match=rf"no LAMMPS export of peri/{name} as a deck: "
                                             r".* breaking stretch s0 uninitialised"):
            write_lammps(str(tmp_path / "block"), atoms, steps=10)
    atoms.calc = calculator(peri_model("pmb"))
    _, deck = write_lammps(str(tmp_path / "block"), atoms, steps=10)
    lmp = run_deck(deck)
    try:
        assert lmp.extract_global("ntimestep") == 10 and lmp.get_natoms() == len(atoms)
    finally:
        lmp.close()
    # legacy PERI would bond every pair in the horizon: a scene without bonds
    atoms.arrays["bond_partner"] = np.zeros_like(atoms.arrays["bond_partner"])
    with pytest.raises(ValueError, match="legacy PERI bonds every pair within the horizon"):
        write_lammps(str(tmp_path / "broken"), atoms, steps=10)


def test_gravity_on_a_peridynamic_block_is_lammps_fix_gravity(PeriOracle):
    """Gravity composes with BPMPeri: true forces m g here, force densities
    rho g in legacy PERI (fix gravity pulls with its mass, the density)."""
    atoms = sc_block(5)
    atoms.set_velocities(np.random.default_rng(3).normal(0, 2.0, (len(atoms), 3)))
    atoms.calc = calculator(peri_model("pmb"), fixes=[ase_bpm.Gravity(2e5, (0.3, 0, -1))])
    atoms.get_forces()
    lmp = PeriOracle(atoms, atoms.calc, timestep=DT)
    try:
        start = atoms.positions.copy()
        ase_bpm.VelocityVerlet(atoms, timestep=DT).run(200)
        lmp.run(200)
        fall = (atoms.positions - start).mean(axis=0)
        assert fall[2] < -0.5 * 2e5 * (200 * DT) ** 2 * 0.9  # it fell
        assert lmp.position_error(atoms.positions).max() <= 1e-9 * SPACING
    finally:
        lmp.close()


#: examples/peri/in.peri.<model>: the pair_coeff line of each deck, in bond_style
#: bpm/peri order (K = G = 14.9e9 Pa, horizon 0.0015001, s00 0.0005, alpha 0.25;
#: ves lambda 0.5, tau 0.001; eps yield stress 1e9)
EXAMPLE_MODELS = {
    "pmb": ("pmb", 1.6863e22, 0.0015001, 0.0005, 0.25),
    "lps": ("lps", 14.9e9, 14.9e9, 0.0015001, 0.0005, 0.25),
    "ves": ("ves", 14.9e9, 14.9e9, 0.5, 0.001, 0.0015001, 0.0005, 0.25),
    "eps": ("eps", 14.9e9, 14.9e9, 10.0e8, 0.0015001, 0.0005, 0.25),
}
EXAMPLE_STEPS = 500


@pytest.mark.parametrize("name", MODELS)
def test_the_peri_example_follows_the_reference_build_through_fracture(PeriOracle, name):
    """LAMMPS examples/peri/in.peri.<model> (a cylinder of 3,487 nodes struck
    by a spherical indenter at 100 m/s, K = 1e17 on force densities: 1e17 V
    as a true force) with follows="legacy", against the reference build's
    peri/<model> (its s0 repaired, as PeriOracle does): positions within 1e-9
    of the spacing at step 500, after bonds broke.  (No node yields in the
    reference build's eps here, whose norm carries the dilatation factor:
    test_legacy_eps_yields_as_the_reference_build makes one yield.)"""
    from ase_bpm.scene.demos.shatter import HORIZON as EXAMPLE_HORIZON, cylinder

    atoms = cylinder()
    model = EXAMPLE_MODELS[name]
    # legacy contact: c, or 18 K / (pi horizon^4) (K the model's first coefficient)
    contact = model[1] if name == "pmb" else 18.0 * model[1] / (np.pi * EXAMPLE_HORIZON ** 4)
    indenter = ase_bpm.SphericalIndenter(1e17 * NODE_VOLUME, 0.0015, (0.0, 0.00155, 0.0),
                                         velocity=(0.0, -100.0, 0.0))
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: model},
                                 pair_coeffs={(1, 1): (contact, EXAMPLE_HORIZON)},
                                 timestep=DT, fixes=[indenter], follows="legacy")
    atoms.get_forces()
    lmp = PeriOracle(atoms, atoms.calc, timestep=DT)
    try:
        ase_bpm.VelocityVerlet(atoms, timestep=DT).run(EXAMPLE_STEPS)
        lmp.run(EXAMPLE_STEPS)
        assert len(atoms.info["broken_bonds"]) > 1000  # fracture
        assert np.abs(atoms.arrays["damage"] - lmp.damage()).max() <= 1e-9
        assert lmp.position_error(atoms.positions).max() <= 1e-9 * SPACING
    finally:
        lmp.close()


def test_legacy_eps_yields_as_the_reference_build(PeriOracle):
    """eps following legacy against the reference build's peri/eps, at a
    yield stress (4e7 Pa) where its defective norm (the dilatation factor)
    lets nodes of an expanded, jittered, moving block yield within 5 steps:
    then its plastic update (a force times the multiplier added to an
    extension) runs away, the multiplier growing some 1e4 times a step, and
    ase_bpm follows it to round-off through 8 steps (after that both blow
    up, round-off amplified as fast)."""
    atoms = sc_block(6)
    atoms.calc = calculator(("eps", BULK, 0.6 * BULK, 4e7, HORIZON, 0.5, 0.25), guard=False)
    atoms.get_forces()
    rng = np.random.default_rng(7)
    centre = atoms.positions.mean(axis=0)
    x = (atoms.positions + 0.003 * (atoms.positions - centre)
         + rng.uniform(-0.02, 0.02, atoms.positions.shape) * SPACING)
    v = rng.normal(0, 1.0, x.shape)
    lmp = PeriOracle(atoms, atoms.calc, timestep=DT)
    try:
        atoms.positions = x
        atoms.set_velocities(v)
        lmp.set_state(x, v)
        ase_bpm.VelocityVerlet(atoms, timestep=DT).run(8)
        lmp.run(8)
        assert (atoms.arrays["peri_lambda"] > 0).sum() > 10
        assert atoms.arrays["peri_lambda"].max() > 1.0  # (running away)
        assert lmp.position_error(atoms.positions).max() <= 1e-9 * SPACING
    finally:
        lmp.close()


@pytest.mark.parametrize("name", MODELS)
def test_periodic_block_follows_the_legacy_weighted_volume(PeriOracle, name):
    """In a periodic cell the legacy styles sum each node's weighted volume
    over its partners' wrapped positions without the minimum image; following
    legacy, BPMPeri does the same, and the forces at a deformed state agree
    (before, lps/ves/eps differed by 60 % of the largest force)."""
    atoms, x, v = deformed_moving_state(name, seed=3, block=sc_block(10, pbc=True), jitter=0.01)
    forces, expected = forces_of_both(PeriOracle, atoms, x, v)
    assert np.abs(forces - expected).max() <= 1e-12 * np.abs(expected).max()
    m_n = atoms.arrays["peri_wvolume"]
    assert m_n.max() > 1.5 * m_n.min()  # the nodes near a face have their own
