"""The compiled PERI kernels against the NumPy ones, the reference.

Every model (pmb, lps, ves, eps), in open and periodic blocks, in steps with
and without bonds breaking, in pure evaluations, and the bpm/peri contact:
from the same state, the two routes give forces, energy, stress and the
energy of broken bonds within ``TOL`` of the largest magnitude of each, the
same history (ves, eps, the smallest stretches, the plastic multiplier) and
the same broken bonds; and a trajectory with fracture stays together.
"""

import numpy as np
import pytest

import ase_bpm
from ase_bpm import VelocityVerlet
from scenes import BULK, HORIZON, MICROMODULUS, SPACING, sc_block

pytestmark = pytest.mark.compiled

TOL = 1e-12  # relative to the largest magnitude of each quantity (issue 16)
ROUTES = ("numpy", "compiled")
MODELS = ("pmb", "lps", "ves", "eps")


def material(model: str, s00: float, alpha: float = 0.25) -> tuple:
    """The PERI example's material; ves relaxes within a few steps and eps
    yields under the deformations below."""
    return {"pmb": ("pmb", MICROMODULUS, HORIZON, s00, alpha),
            "lps": ("lps", BULK, 0.6 * BULK, HORIZON, s00, alpha),
            "ves": ("ves", BULK, 0.6 * BULK, 0.5, 3e-7, HORIZON, s00, alpha),
            "eps": ("eps", BULK, 0.6 * BULK, 2e6, HORIZON, s00, alpha)}[model]


def calculators(model, s00=0.2, contacts=False, **parameters) -> dict:
    pairs = {(1, 1): (MICROMODULUS, HORIZON)} if contacts else {}
    return {route: ase_bpm.BPMPeri(bond_coeffs={1: material(model, s00)}, pair_coeffs=pairs,
                                   timestep=1e-7, lattice_spacing=SPACING, kernels=route,
                                   **parameters)
            for route in ROUTES}


def block(pbc: bool):
    """An open 5^3 block, or a periodic 8^3 one (bonds reach at most 3.6 of
    its 8 spacings at s00 = 0.2)."""
    return sc_block(8, pbc=True) if pbc else sc_block(5)


def relative(a, b) -> float:
    """The largest difference over the largest magnitude (0 for two zeros)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape
    assert np.array_equal(np.isnan(a), np.isnan(b))
    a, b = np.nan_to_num(a), np.nan_to_num(b)
    scale = max(np.abs(a).max(initial=0.0), np.abs(b).max(initial=0.0))
    return float(np.abs(a - b).max(initial=0.0) / scale) if scale > 0 else 0.0


STATE = ("bond_r0", "bond_ves", "bond_eps", "peri_smin", "peri_lambda", "peri_wvolume",
         "peri_vinter", "dilatation", "damage")


def assert_same(reference, other) -> None:
    """Results, bonds and history of two atoms objects evaluated alike."""
    for name in ("forces", "energy", "broken_bond_energy"):
        assert relative(reference.calc.results[name], other.calc.results[name]) <= TOL, name
    if reference.pbc.all():
        assert relative(reference.get_stress(), other.get_stress()) <= TOL
    assert np.array_equal(reference.arrays["bond_type"], other.arrays["bond_type"])
    for name in STATE:
        assert (name in reference.arrays) == (name in other.arrays), name
        if name in reference.arrays:
            assert relative(reference.arrays[name], other.arrays[name]) <= TOL, name
    log = [atoms.info.get("broken_bonds", np.zeros((0, 3)))[:, :3] for atoms in (reference,
                                                                                    other)]
    assert np.array_equal(*log)


def on_both(atoms, calcs: dict, move=None, pure=False) -> dict:
    """Copies of ``atoms`` on each route's calculator, moved by ``move`` and
    evaluated: a step (or a pure evaluation, whose results are kept in
    ``info["pure_results"]``)."""
    out = {}
    for route, calc in calcs.items():
        copy = atoms.copy()
        copy.calc = calc
        if move is not None:
            copy.positions = move(copy.positions)
        if pure:
            with ase_bpm.pure(copy):
                copy.get_forces()
                copy.info["pure_results"] = dict(calc.results)
        else:
            copy.get_forces()
        out[route] = copy
    return out


def stretch(by: float, seed: int, jitter: float = 0.001):
    """Positions stretched from their centre by ``by`` and jittered (in
    spacings), the same each time."""
    def move(x):
        rng = np.random.default_rng(seed)
        centre = x.mean(axis=0)
        return x + by * (x - centre) + rng.uniform(-jitter, jitter, x.shape) * SPACING
    return move


def setup_state(model, pbc, s00=0.2, **parameters):
    """A block evaluated once (reference lengths, weighted volumes, the
    smallest stretches) and stepped once, so that history is set, on the
    NumPy route; and the two routes' calculators."""
    atoms = block(pbc)
    calcs = calculators(model, s00, **parameters)
    atoms.calc = calcs["numpy"]
    atoms.get_forces()
    atoms.positions = stretch(0.0005, seed=1)(atoms.positions)
    atoms.get_forces()  # a step: history advances
    return atoms, calcs


@pytest.mark.parametrize("pbc", [False, True])
@pytest.mark.parametrize("model", MODELS)
def test_the_first_evaluation_agrees(model, pbc):
    """The setup: reference lengths taken, node state summed, nothing breaks."""
    atoms = block(pbc)
    atoms.positions = stretch(0.0, seed=3, jitter=0.01)(atoms.positions)
    both = on_both(atoms, calculators(model))
    assert_same(both["numpy"], both["compiled"])
    assert "bond_r0" in both["compiled"].arrays


@pytest.mark.parametrize("pbc", [False, True])
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("breaking", [False, True])
@pytest.mark.parametrize("follows", ["bpm/peri", "legacy"])
def test_a_step_agrees(model, pbc, breaking, follows):
    """A step from the same state, with bonds breaking in it (a stretch past
    s00 with Parks' history from the step before) or not, following either
    LAMMPS."""
    atoms, calcs = setup_state(model, pbc, s00=0.004, follows=follows)
    both = on_both(atoms, calcs, stretch(0.0045 if breaking else -0.0005, seed=2))
    assert_same(both["numpy"], both["compiled"])
    broken = len(both["compiled"].info.get("broken_bonds", []))
    assert (broken > 0) == breaking
    if breaking:  # some bonds break, not all, and take energy with them
        assert broken < len(ase_bpm.get_bonds(atoms, include_broken=True)[0])
        assert both["compiled"].calc.results["broken_bond_energy"] != 0


@pytest.mark.parametrize("follows", ["bpm/peri", "legacy"])
@pytest.mark.parametrize("model", ["ves", "eps"])
def test_history_advances_alike(model, follows):
    """ves relaxes and eps yields over a few steps: their history differs
    from its start, and the routes keep it together step after step, in the
    forms of bond_style bpm/peri and of the legacy styles (whose eps update
    adds a force times the plastic multiplier to an extension: at this yield
    stress its plastic extensions grow fast and the stable-timestep guard
    would stop the run, so it is off there)."""
    guard = not (model == "eps" and follows == "legacy")
    atoms, calcs = setup_state(model, pbc=False, s00=0.2, follows=follows, guard=guard)
    start = atoms.arrays["bond_" + model].copy()
    for k in range(4):
        both = on_both(atoms, calcs, stretch(0.002, seed=10 + k))
        assert_same(both["numpy"], both["compiled"])
        atoms = both["numpy"]
    assert relative(start, atoms.arrays["bond_" + model]) > 1e-3
    if model == "eps":
        assert atoms.arrays["peri_lambda"].max() > 0  # some nodes yielded


@pytest.mark.parametrize("pbc", [False, True])
@pytest.mark.parametrize("model", MODELS)
def test_a_pure_evaluation_agrees(model, pbc):
    """Inside pure(): bonds past their criterion act broken but stay, nothing
    is written; the two routes agree on forces and energy."""
    atoms, calcs = setup_state(model, pbc, s00=0.004)
    both = on_both(atoms, calcs, stretch(0.0045, seed=2), pure=True)
    results = {route: copy.info["pure_results"] for route, copy in both.items()}
    for name in ("forces", "energy"):
        assert relative(results["numpy"][name], results["compiled"][name]) <= TOL, name
    for copy in both.values():  # nothing broke on the atoms
        assert np.array_equal(copy.arrays["bond_type"], atoms.arrays["bond_type"])
    # and the bonds past their criterion did act broken: less energy than intact
    intact = on_both(atoms, calculators(model, s00=0.2), stretch(0.0045, seed=2), pure=True)
    for route in ROUTES:
        assert results[route]["energy"] < intact[route].info["pure_results"]["energy"]


def broken_and_squeezed(pbc: bool, model: str = "pmb"):
    """A block whose bonds partly broke in a stretch, then pushed together
    with jitter: non-bonded nodes touch, some of them the two nodes of a
    broken bond (contact from 0.9 r0)."""
    atoms, calcs = setup_state(model, pbc, s00=0.004, contacts=True)
    both = on_both(atoms, calcs, stretch(0.0045, seed=2))
    atoms = both["numpy"]
    assert len(atoms.info["broken_bonds"]) > 0
    return atoms, calcs


@pytest.mark.parametrize("pbc", [False, True])
def test_the_contact_agrees(pbc):
    atoms, calcs = broken_and_squeezed(pbc)
    squeeze = stretch(-0.02, seed=5, jitter=0.15)
    both = on_both(atoms, calcs, squeeze)
    assert_same(both["numpy"], both["compiled"])
    # the contacts act: without them the energy differs
    apart = on_both(atoms, calculators("pmb", s00=0.004), squeeze)
    for route in ROUTES:
        assert both[route].calc.results["energy"] != apart[route].calc.results["energy"]


def test_two_bodies_in_contact_agree():
    """Two blocks pressed together: only the contact acts between them."""
    a, b = sc_block(4), sc_block(4, offset=(4.2, 0.3, 0.1))
    atoms = a + ase_bpm.renew_ids(b)
    both = on_both(atoms, calculators("lps", contacts=True))
    assert_same(both["numpy"], both["compiled"])
    on_a = both["compiled"].calc.results["forces"][:len(a)]
    assert np.abs(on_a.sum(axis=0)).max() > 0  # the contact pushes a as a whole


@pytest.mark.parametrize("pbc", [False, True])
@pytest.mark.parametrize("pair", [("pmb", "lps"), ("ves", "eps")])
def test_mixed_models_agree(pair, pbc):
    """Two bond types with different models in one block: each law's kernel
    runs on its own bonds; the dilatation sums the state-based ones; when
    bonds break, the energy left is summed anew over both."""
    atoms = block(pbc)
    types = atoms.arrays["bond_type"].copy()
    left = atoms.positions[:, 0] < atoms.positions[:, 0].mean()
    types[left] = np.where(types[left] > 0, 2, 0)  # the bonds owned by the left half
    atoms.arrays["bond_type"] = types
    calcs = {route: ase_bpm.BPMPeri(bond_coeffs={1: material(pair[0], 0.004),
                                                 2: material(pair[1], 0.004)},
                                    timestep=1e-7, lattice_spacing=SPACING, kernels=route)
             for route in ROUTES}
    atoms.calc = calcs["numpy"]
    atoms.get_forces()
    atoms.positions = stretch(0.0005, seed=1)(atoms.positions)
    atoms.get_forces()
    for by in (-0.0005, 0.0045):  # a step without breaking, one with
        both = on_both(atoms, calcs, stretch(by, seed=2))
        assert_same(both["numpy"], both["compiled"])
    assert len(both["compiled"].info["broken_bonds"]) > 0


@pytest.mark.parametrize("model,speed", [("pmb", 4.0), ("lps", 5.0), ("ves", 7.0),
                                         ("eps", 4.0)])
def test_a_fracturing_trajectory_stays_together(model, speed):
    """80 steps of a block pulled apart from its centre (neighbours part at
    ``speed``): bonds break in several of them; positions stay within 1e-10
    spacings, the same bonds break in the same steps, energies agree to
    1e-10."""
    runs = {}
    for route in ROUTES:
        atoms = sc_block(5)
        atoms.calc = calculators(model, s00=0.003, contacts=True)[route]
        atoms.get_forces()
        atoms.set_velocities(speed * (atoms.positions - atoms.positions.mean(axis=0))
                             / SPACING)
        energies = []
        dyn = VelocityVerlet(atoms, timestep=1e-7)
        dyn.attach(lambda: energies.append(atoms.get_potential_energy()))
        dyn.run(80)
        runs[route] = atoms, np.array(energies)
    (reference, e_ref), (other, e_other) = runs["numpy"], runs["compiled"]
    log = reference.info["broken_bonds"]
    assert len(np.unique(log[:, 2])) > 5  # bonds broke in several steps
    assert np.array_equal(log[:, :3], other.info["broken_bonds"][:, :3])
    assert np.abs(reference.positions - other.positions).max() < 1e-10 * SPACING
    assert relative(e_ref, e_other) < 1e-10


@pytest.mark.parametrize("model", ["pmb", "lps"])
def test_an_output_array_of_another_type_is_refused_not_written_past(model, monkeypatch):
    """The PERI kernels write into the arrays they are given (forces, totals,
    breaking marks): one of another type raises, naming it, instead of being
    written out of bounds or into a copy that is then lost."""
    from ase_bpm.laws.bond import BondSums

    zeros = BondSums.zeros

    def single_precision_forces(natoms, nbonds, damped, breaking):
        sums = zeros(natoms, nbonds, damped, breaking)
        sums.f_nc = sums.f_nc.astype(np.float32)
        return sums

    atoms = block(False)
    atoms.calc = calculators(model)["compiled"]
    monkeypatch.setattr(BondSums, "zeros", staticmethod(single_precision_forces))
    with pytest.raises(ValueError, match="write into the f_nc.*float64, not float32"):
        atoms.get_forces()
    monkeypatch.setattr(BondSums, "zeros", zeros)
    assert np.isfinite(atoms.get_forces()).all()
