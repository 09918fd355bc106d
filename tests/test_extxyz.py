"""Bonded atoms through ASE's extxyz files, atom IDs in their two-word form,
restart files of the one-number form, and what create_bonds and get_bonds say.

ASE's extxyz reader reads integer columns as int32: the IDs are stored as two
int32 words each (low and high 31 bits), so ``ase.io.write``/``ase.io.read``
of any bonded scene gives the same bonds back; extxyz writes floats with 8
decimals, so forces agree to 1e-6 where the scene's numbers are of order one
(reduced units).
"""

import importlib.util
import io
import os
import warnings

import ase.io
import numpy as np
import pytest
from ase import Atoms
from ase.gui.images import Images
from ase.lattice.cubic import FaceCenteredCubic
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.core.bonds import id_keys, id_numbers, read_ids, state_slots
from ase_bpm.laws import kernel_route
from ase_bpm import SphereVelocityVerlet
from ase_bpm.models.contacts import read_contacts
from scenes import sphere_pile
from test_examples import readme_block

#: extxyz writes floats as %16.8f: half the last decimal
EXTXYZ_ROUNDING = 5e-9
#: forces after a round trip, for scenes of numbers of order one
FORCE_TOLERANCE = 1e-6
WORD_LIMIT = 2 ** 31
ID_LIMIT = 2 ** 62
DATA = os.path.join(os.path.dirname(__file__), "data")


def round_trip(atoms, tmp_path, name="scene.extxyz"):
    path = tmp_path / name
    ase.io.write(path, atoms)
    return ase.io.read(path)


def same_bonds(a, b):
    for x, y in zip(ase_bpm.get_bonds(a, include_broken=True),
                    ase_bpm.get_bonds(b, include_broken=True)):
        assert np.array_equal(x, y)


# -- the README's example (reduced units) ----------------------------------------------

USE = "ase_bpm.create_bonds(atoms, 1.5, bond_type=1)"  # in the README's "Use" block
RUN = "dyn.run(1000)"


def readme_use(tmp_path, monkeypatch, run: bool):
    """The atoms of the README's "Use" block (a jittered 8 x 8 x 2 FCC block
    bonded within 1.5, BPMSpring), run as it says or stopped before the run;
    the calculator logs broken bonds (store_local)."""
    code = readme_block(USE)
    assert RUN in code and "ase_bpm.BPMSpring(" in code
    code = code.replace("ase_bpm.BPMSpring(", "ase_bpm.BPMSpring(store_local=True, ")
    if not run:
        code = code.replace(RUN, "pass")
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(code, "README.md", "exec"), namespace)
    return namespace["atoms"]


def same_calculator(atoms):
    return type(atoms.calc)(**atoms.calc.todict())


def test_freshly_bonded_atoms_come_back_from_extxyz(tmp_path, monkeypatch):
    atoms = readme_use(tmp_path, monkeypatch, run=False)
    assert "bpm_step" not in atoms.info  # straight after create_bonds
    back = round_trip(atoms, tmp_path)
    assert back.arrays["bpm_id"].dtype == np.int32  # as ASE's reader gives them
    same_bonds(atoms, back)
    gui = Images()  # what ase gui opens the file with
    gui.read([str(tmp_path / "scene.extxyz")])
    same_bonds(atoms, gui[0])
    assert len(ase_bpm.get_bonds(back)[0]) > 4 * len(atoms)
    back.calc = same_calculator(atoms)
    assert np.abs(back.get_forces() - atoms.get_forces()).max() < FORCE_TOLERANCE


def test_the_readme_run_comes_back_from_extxyz(tmp_path, monkeypatch):
    """After the README's 1000 steps (some bonds broken): the same bonds and
    broken-bond log, and a new calculator gives the forces of the run."""
    atoms = readme_use(tmp_path, monkeypatch, run=True)
    assert atoms.info["bpm_step"] == 1000
    assert (ase_bpm.get_bonds(atoms, include_broken=True)[2] == 0).any()
    forces = atoms.get_forces()
    back = round_trip(atoms, tmp_path)
    same_bonds(atoms, back)
    assert np.array_equal(back.info["broken_bonds"], atoms.info["broken_bonds"])
    back.calc = same_calculator(atoms)
    assert np.abs(back.get_forces() - forces).max() < FORCE_TOLERANCE
    assert back.info["bpm_step"] == atoms.info["bpm_step"]  # the record held
    # evaluated afresh, both at once (the damping at full-step velocities)
    atoms.calc.refresh()
    back.calc.refresh()
    assert np.abs(back.get_forces() - atoms.get_forces()).max() < FORCE_TOLERANCE


# -- BPMPeri and Granular ----------------------------------------------------------------

SPACING, HORIZON, BULK = 1.0, 3.0001, 1.0
PERI_MODELS = {
    "pmb": ("pmb", 18 * BULK / (np.pi * HORIZON ** 4), HORIZON, 0.5, 0.25),
    "lps": ("lps", BULK, 0.6 * BULK, HORIZON, 0.5, 0.25),
    "ves": ("ves", BULK, 0.6 * BULK, 0.5, 1.0, HORIZON, 0.5, 0.25),
    "eps": ("eps", BULK, 0.6 * BULK, 1e-2, HORIZON, 0.5, 0.25),  # yields in the run
}
PERI_DT = 0.02


def peri_calculator(name):
    return ase_bpm.BPMPeri(bond_coeffs={1: PERI_MODELS[name]}, timestep=PERI_DT)


def peri_run(name):
    """A simple cubic block of the model ``name`` in reduced units after 30
    steps (eps yields in them)."""
    grid = np.indices((5, 5, 5)).reshape(3, -1).T * SPACING
    atoms = Atoms(f"Si{len(grid)}", positions=grid, pbc=False)
    atoms.arrays["vfrac"] = np.ones(len(atoms))
    atoms.set_masses(np.ones(len(atoms)))
    atoms.set_velocities(np.random.default_rng(2).normal(0, 0.02, grid.shape))
    ase_bpm.create_bonds(atoms, HORIZON)
    atoms.calc = peri_calculator(name)
    VelocityVerlet(atoms, timestep=PERI_DT).run(30)
    return atoms


@pytest.mark.parametrize("name", sorted(PERI_MODELS))
def test_a_peri_run_comes_back_from_extxyz(tmp_path, name):
    """A simple cubic block in reduced units after a run: the same bonds, the
    per-bond history (ves, eps) to extxyz's decimals, the forces."""
    atoms = peri_run(name)
    forces = atoms.get_forces()
    back = round_trip(atoms, tmp_path)
    same_bonds(atoms, back)
    for state in [key for key in atoms.arrays if key.startswith("bond_") and
                  atoms.arrays[key].dtype.kind == "f"]:
        kept, got = atoms.arrays[state], back.arrays[state]
        assert got.shape == kept.shape
        assert np.array_equal(np.isnan(got), np.isnan(kept))
        assert np.nanmax(np.abs(got - kept)) <= EXTXYZ_ROUNDING, state
    if name in ("ves", "eps"):
        history = state_slots(atoms.arrays[f"bond_{name}"], atoms.arrays["bond_type"].shape[1])
        assert history.ndim == 3 and np.nanmax(np.abs(history)) > 1e-4  # a history to keep
    back.calc = peri_calculator(name)
    assert np.abs(back.get_forces() - forces).max() < FORCE_TOLERANCE


GRANULAR = dict(kn=1000.0, gamma_n=20.0, xmu=0.3)
MOST_CONTACTS = 12  # of one sphere


def test_a_granular_history_comes_back_from_extxyz(tmp_path):
    """The same contacts (by ID) and their shear to extxyz's decimals.  Radii
    and masses of more decimals than the file keeps change the signature, so
    the new calculator evaluates afresh: as the first scene does when asked
    afresh, within what the rounding of positions, velocities and shear allows
    (per contact: kn, kt and gamma_n / m times their rounding)."""
    atoms = sphere_pile(seed=1)
    atoms.calc = ase_bpm.Granular("hooke/history", **GRANULAR)
    SphereVelocityVerlet(atoms, 1e-3).run(20)
    back = round_trip(atoms, tmp_path)
    assert back.arrays["gran_partner"].dtype == np.int32
    keys, shear = read_contacts(atoms)
    back_keys, back_shear = read_contacts(back)
    assert len(keys) > 20 and np.array_equal(back_keys, keys)
    assert np.abs(back_shear - shear).max() <= EXTXYZ_ROUNDING
    back.calc = ase_bpm.Granular("hooke/history", **GRANULAR)
    atoms.calc.refresh()
    law = back.calc.law
    per_unit = (2 * law.kn + law.kt + 2 * law.gamma_n / atoms.get_masses().min()) * np.sqrt(3)
    bound = MOST_CONTACTS * per_unit * EXTXYZ_ROUNDING
    assert np.abs(back.get_forces() - atoms.get_forces()).max() < bound


# -- the stored form of IDs ----------------------------------------------------------------

def test_ids_are_two_words_of_31_bits_over_the_62_bit_space():
    atoms = Atoms(f"H{100_000}", positions=np.zeros((100_000, 3)))
    words = ase_bpm.core.bonds.id_words(atoms)
    assert words.dtype == np.int32 and words.shape == (len(atoms), 2)
    assert words.min() >= 0 and words.max() < WORD_LIMIT
    numbers = id_numbers(ase_bpm.core.bonds.keys_of(words)[:, 0])
    assert numbers.min() > 0 and numbers.max() < ID_LIMIT
    assert numbers.max() > ID_LIMIT // 2  # the high words are used: 62 bits as before
    assert len(np.unique(numbers)) == len(numbers)
    assert np.array_equal(id_keys(numbers), ase_bpm.core.bonds.keys_of(words)[:, 0])


@pytest.mark.parametrize("value,message", [
    (lambda a: -a.arrays["bpm_id"], r'atoms.arrays\["bpm_id"\] holds words outside '
                                    r'\[0, 2147483647\]'),
    (lambda a: np.zeros((len(a), 3), np.int32),
     r'atoms.arrays\["bpm_id"\] must be an integer array of shape \(\d+, 2\) int32 \(two '
     r'words\) or \(\d+,\) of another integer type \(numbers, e.g. int64\), got shape '
     r'\(\d+, 3\) and dtype int32$'),
    # numbers as int32: taken for words, and told so
    (lambda a: np.arange(1, len(a) + 1, dtype=np.int32),
     r'^atoms.arrays\["bpm_id"\] must be an integer array of shape \((\d+), 2\) int32 '
     r'\(two words\) or \(\1,\) of another integer type \(numbers, e.g. int64\), got '
     r'shape \(\1,\) and dtype int32: int32 is read as two words per ID, not as numbers; '
     r'give numbers as int64 \(atoms.arrays\["bpm_id"\] = ids.astype\(np.int64\)\)$'),
    (lambda a: np.full(len(a), ID_LIMIT),
     r'atoms.arrays\["bpm_id"\] holds IDs outside \[0, 4611686018427387903\]'),
])
def test_ids_that_are_no_ids_are_named(value, message):
    atoms = fcc(False)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.arrays["bpm_id"] = value(atoms)
    with pytest.raises(ValueError, match=message):
        ase_bpm.get_bonds(atoms)


# -- IDs as numbers (before the two-word form) ------------------------------------------

def old_scenes():
    """The scenes of tests/data/make_old_restarts.py (run with the package of
    before: restart files with int64 IDs)."""
    spec = importlib.util.spec_from_file_location(
        "make_old_restarts", os.path.join(DATA, "make_old_restarts.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("form", ["read_restart", "numbers"])
@pytest.mark.parametrize("scene", ["spring", "granular"])
def test_a_restart_file_with_ids_as_numbers_continues_bit_for_bit(scene, form):
    """A restart file written before IDs were two words (int64 IDs and a
    64-bit record checksum) runs on exactly as the package of then ran on;
    atoms that hold int64 IDs (a pickle) too."""
    made = old_scenes()
    data = np.load(os.path.join(DATA, f"old_ids_{scene}_{kernel_route()}.npz"))
    restart = data["restart"].tobytes()
    atoms = ase_bpm.read_restart(io.BytesIO(restart))
    with np.load(io.BytesIO(restart)) as raw:
        plain = {key[len("arrays/"):]: raw[key] for key in raw.files
                 if key in ("arrays/bpm_id", "arrays/bond_partner", "arrays/gran_partner")}
    assert plain and all(array.dtype == np.int64 for array in plain.values())
    assert all(atoms.arrays[name].dtype == np.int32 for name in plain)  # converted
    for name, array in plain.items():
        assert np.array_equal(id_numbers(read_ids(atoms, name)), array)
    if form == "numbers":
        as_read = ase_bpm.get_bonds(atoms, include_broken=True)
        atoms.arrays.update(plain)
        for x, y in zip(as_read, ase_bpm.get_bonds(atoms, include_broken=True)):
            assert np.array_equal(x, y)
    fresh, integrator, dt = getattr(made, scene)()
    atoms.calc = fresh.calc
    integrator(atoms, dt).run(made.STEPS)
    assert np.array_equal(atoms.positions, data["positions"])
    assert np.array_equal(atoms.get_momenta(), data["momenta"])


@pytest.mark.parametrize("name", ["ves", "eps"])
def test_a_restart_file_with_three_axis_states_is_read_in_the_stored_form(tmp_path, name):
    """Restart files written before per-bond states of several numbers were
    two-dimensional hold bond_ves and bond_eps as (N, W, k) (those of
    tests/data have no such state: one is written here).  read_restart gives
    them as (N, W k), which extxyz and ``a + b`` with a body of today take,
    and the run goes on exactly as from a file of today."""
    atoms = peri_run(name)
    key = f"bond_{name}"
    stored = atoms.arrays[key]
    old = atoms.copy()
    old.arrays[key] = state_slots(stored, atoms.arrays["bond_type"].shape[1]).copy()
    assert old.arrays[key].ndim == 3 and stored.ndim == 2
    ase_bpm.write_restart(tmp_path / "old.bpm", old)
    ase_bpm.write_restart(tmp_path / "new.bpm", atoms)
    back, ref = (ase_bpm.read_restart(tmp_path / f"{form}.bpm") for form in ("old", "new"))
    assert back.arrays[key].shape == stored.shape
    assert np.array_equal(back.arrays[key], stored, equal_nan=True)
    ase.io.write(tmp_path / "back.extxyz", back)
    same_bonds(back, ase.io.read(tmp_path / "back.extxyz"))
    body = ase_bpm.renew_ids(atoms.copy())
    body.positions += 10 * HORIZON
    both = back + body
    assert both.arrays[key].shape == (2 * len(atoms), stored.shape[1])
    for one in (back, ref):
        one.calc = peri_calculator(name)
        VelocityVerlet(one, timestep=PERI_DT).run(5)
    assert np.array_equal(back.positions, ref.positions)
    assert np.array_equal(back.arrays[key], ref.arrays[key], equal_nan=True)


# -- create_bonds and get_bonds ----------------------------------------------------------

def fcc(pbc):
    return FaceCenteredCubic("Ne", size=(3, 3, 3), latticeconstant=4 ** (1 / 3), pbc=pbc)


@pytest.mark.parametrize("pbc", [False, True])
def test_a_cutoff_below_the_spacing_is_warned_of(pbc):
    atoms = fcc(pbc)
    shortest = min(d for d in atoms.get_all_distances(mic=pbc).ravel() if d > 0)
    with pytest.warns(ase_bpm.NoBondsCreatedWarning) as seen:
        assert ase_bpm.create_bonds(atoms, 0.5) == 0
    message = str(seen[0].message)
    assert len(seen) == 1 and seen[0].filename == __file__
    assert "cutoff 0.5" in message and f"{shortest:.6g}" in message
    assert "bpm_id" not in atoms.arrays and "bond_partner" not in atoms.arrays


def test_a_selection_of_one_atom_is_warned_of():
    atoms = fcc(False)
    mask = np.zeros(len(atoms), dtype=bool)
    mask[0] = True
    with pytest.warns(ase_bpm.NoBondsCreatedWarning, match=r"cutoff 1.5 \(1 atom selected\)"):
        ase_bpm.create_bonds(atoms, 1.5, mask=mask)


def test_no_warning_when_bonds_are_made_or_already_there():
    atoms = fcc(False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert ase_bpm.create_bonds(atoms, 1.5) > 0
        assert ase_bpm.create_bonds(atoms, 1.5) == 0  # every pair within is bonded


def test_bonds_are_changed_by_replacing_their_arrays(tmp_path, monkeypatch):
    """What get_bonds' docstring says: in place, NumPy refuses; a replaced
    array is read at the next evaluation; without bond_r0 the reference
    lengths are taken anew."""
    atoms = readme_use(tmp_path, monkeypatch, run=False)
    atoms.get_forces()
    with pytest.raises(ValueError, match="assignment destination is read-only"):
        atoms.arrays["bond_type"][0, 0] = 0
    types = atoms.arrays["bond_type"].copy()
    types[:, 0] = 0  # every atom's first bond
    atoms.arrays["bond_type"] = types
    atoms.get_forces()
    i_b, j_b, type_b = ase_bpm.get_bonds(atoms, include_broken=True)
    assert (type_b == 0).sum() == len(np.unique(i_b))
    atoms.positions *= 1.01
    del atoms.arrays["bond_r0"]
    atoms.get_forces()
    table = ase_bpm.core.bonds.bond_table(atoms)
    r_b = np.linalg.norm(atoms.positions[table.partner_b] - atoms.positions[table.owner_b], axis=1)
    r0_b = atoms.arrays["bond_r0"][table.owner_b, table.slot_b]
    live = table.type_b > 0
    assert np.allclose(r0_b[live], r_b[live], rtol=1e-15, atol=0)
