"""The step's machinery (issue 31, a lean step): what ASE's repeated
requests find and what the calculator works out once.  (How many calls a
step makes is measured by benchmarks/calls_per_step.py, not asserted here.)"""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.core.arrays import Inputs, same_array
from ase_bpm.core.bonds import TYPE as BOND_TYPE
from ase_bpm.models.record import SIGNATURE
from scenes import MULTI_TYPE_COEFFS, multi_type_cluster

def bonded_scene():
    atoms, _ = multi_type_cluster()
    atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
    atoms.get_forces()
    return atoms


def test_same_array_compares_every_pair_given():
    a = np.arange(6.0).reshape(2, 3)
    assert same_array(a, a.copy(), (None, None), (np.ones(2), np.ones(2)))
    assert not same_array(a, a.copy(), (np.ones(2), np.zeros(2)))
    assert not same_array(a, a.copy(), (np.ones(2), None))
    assert not same_array(a, a.astype(np.float32), (None, None))
    nan = np.array([np.nan])
    assert same_array(nan, nan.copy(), (nan, nan.copy()))  # NaN is NaN, bytewise


def test_check_state_names_what_changed():
    atoms = bonded_scene()
    calc = atoms.calc
    assert calc.check_state(atoms) == []
    atoms.arrays["type"][0] += 1  # in place: compared by value
    assert calc.check_state(atoms) == ["type"]
    atoms.arrays["type"][0] -= 1
    atoms.numbers[1] = 2
    assert calc.check_state(atoms) == ["numbers"]
    atoms.numbers[1] = 29
    atoms.cell[0, 0] += 1.0
    assert calc.check_state(atoms) == ["cell", "pbc"]
    atoms.cell[0, 0] -= 1.0
    atoms.arrays[BOND_TYPE] = atoms.arrays[BOND_TYPE].copy()  # bonds replaced: by identity
    assert calc.check_state(atoms) == ["bonds"]
    atoms.get_forces()
    assert calc.check_state(atoms) == []
    atoms.positions[2, 1] += 1e-3  # moved: named with all it may have changed
    assert calc.check_state(atoms)[0] == "positions"
    assert len(atoms.calc.check_state(atoms[:-1])) > 0  # another number of atoms


def test_inputs_are_read_once_and_read_only():
    atoms, _ = multi_type_cluster()
    inputs = Inputs(atoms)
    v_nc = inputs.velocities
    assert inputs.velocities is v_nc and inputs.masses is inputs.masses
    assert not v_nc.flags.writeable and not inputs.types.flags.writeable
    np.testing.assert_array_equal(v_nc, atoms.get_velocities())
    assert atoms.arrays["type"].flags.writeable  # the atoms' own stays writable
    assert inputs.frozen is None
    atoms.arrays["momenta"][4, 2] = np.nan
    with pytest.raises(ValueError, match="velocity of atom 4 is not finite"):
        Inputs(atoms).velocities


def test_a_fix_changed_in_place_is_described_anew_at_refresh():
    """The fixes' parameters enter the signature on the atoms; they are read
    when the fixes are replaced, at ``set`` and at ``refresh``: after a
    refresh the record is that of a calculator built with the changed fix
    (which restores it without evaluating)."""
    atoms = bonded_scene()
    gravity = ase_bpm.Gravity(0.5)
    atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, fixes=[gravity])
    dyn = VelocityVerlet(atoms, timestep=0.01)
    dyn.run(3)
    gravity.g = 0.25
    atoms.calc.refresh()
    dyn.run(2)
    restored = atoms.copy()
    restored.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, fixes=[ase_bpm.Gravity(0.25)])
    assert restored.calc._signature(restored, None) == atoms.info[SIGNATURE]
    evaluations = []
    evaluate = restored.calc.model.evaluate
    restored.calc.model.evaluate = lambda *args: evaluations.append(1) or evaluate(*args)
    np.testing.assert_array_equal(restored.get_forces(), atoms.get_forces())
    assert evaluations == []  # the record held
    other = atoms.copy()
    other.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, fixes=[ase_bpm.Gravity(0.5)])
    assert other.calc._signature(other, None) != atoms.info[SIGNATURE]


def test_produces_torques_follows_the_fixes_list():
    atoms = bonded_scene()
    calc = atoms.calc
    assert not calc.produces_torques
    calc.fixes.append(ase_bpm.GranularWall("hooke", kn=1.0, gamma_n=0.5, xmu=0.5, lo=-5.0))
    assert calc.produces_torques  # (a frictional wall: noticed in the list, in place)
    calc.fixes.pop()
    assert not calc.produces_torques


def test_pair_table_rows_follow_the_types_changed_in_place():
    """The compiled kernels' rows of a pair table are kept while the types
    are the same, and follow them when they change, in place too."""
    from ase_bpm.laws.contact import PairTable

    table = PairTable({(1, 1): (1.0,), (1, 2): (2.0,), (2, 2): (4.0,)}, ("k",))
    types_n = np.array([1, 1, 1])
    first = table.rows(types_n)
    assert table.rows(types_n.copy()) is first
    assert first.shape == (2, 2, 1) and first[1, 1, 0] == 1.0  # type 2 not present
    types_n[2] = 2  # in place
    rows = table.rows(types_n)
    assert rows[1, 2, 0] == 2.0 and rows[2, 2, 0] == 4.0
    assert np.array_equal(rows, np.moveaxis(table(types_n), 0, -1), equal_nan=True)
    assert rows.flags.c_contiguous


def _retype(atoms):
    atoms.arrays["type"][:] = 1  # in place: the pairs' coefficients change


def _reweigh(atoms):
    atoms.set_masses(atoms.get_masses() * 1.5)  # the velocities change with them


def _rebond(atoms):
    bond_type = atoms.arrays[BOND_TYPE].copy()
    bond_type[bond_type == 1] = 2  # replaced: other coefficients
    atoms.arrays[BOND_TYPE] = bond_type


def _hold(atoms):
    from ase.constraints import FixAtoms
    atoms.set_constraint(FixAtoms(indices=[0]))  # the frozen mask enters the signature


def _resize(atoms):
    atoms.arrays["radius"] *= 1.01  # in place: the spheres overlap more


def _recell(atoms):
    atoms.cell[0, 0] *= 0.98  # in place: the images come closer


def periodic_scene():
    atoms, _ = multi_type_cluster(pbc=True)
    atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
    atoms.get_forces()
    return atoms


def by_numbers_scene():
    """The bonded scene with the masses of the elements (no masses array)."""
    atoms, _ = multi_type_cluster()
    del atoms.arrays["masses"]
    atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
    atoms.get_forces()
    return atoms


def _renumber(atoms):
    atoms.numbers[::2] = 13  # in place: other masses


def _kick(atoms):
    atoms.set_velocities(atoms.get_velocities() + 0.05)


def granular_scene():
    from scenes import sphere_pile
    atoms = sphere_pile(n=3, seed=2, speed=0.5, spin=1.0)
    atoms.calc = ase_bpm.Granular(model="hooke/history", kn=2000.0, gamma_n=50.0, xmu=0.5,
                                  dampflag=0, timestep=1e-3)
    atoms.get_forces()
    return atoms


def _steps(base, edit=None, fresh_look=False):
    """Four evaluations of a copy of ``base`` (its calculator made anew: the
    record holds), each at positions moved a little, ``edit`` applied with
    the third move (the first evaluation reads every input: the second and
    the third may take them as they were); ``fresh_look``: the calculator forgets what the last
    evaluation saw before each (the general path, as after a refresh, but
    a step).  Returns the copy."""
    atoms = base.copy()
    atoms.calc = type(base.calc)(**base.calc.todict())
    rng = np.random.default_rng(1)
    for k in range(4):
        atoms.positions = atoms.positions + rng.normal(0.0, 1e-3, atoms.positions.shape)
        if k == 2 and edit is not None:
            edit(atoms)
        if fresh_look:
            atoms.calc._seen = None
        atoms.get_forces()
    return atoms


def _pull(atoms):
    atoms.positions[0] += 1.0  # (in place) far past its bonds' breaking strain


@pytest.mark.filterwarnings("ignore::ase_bpm.OptimiserStepWarning")  # (momenta kept)
def test_bonds_broken_in_an_ordinary_step_give_the_signature_of_a_fresh_look():
    """The ordinary step keeps the last signature only where no bond broke:
    after a step that broke bonds (and the ordinary step after it) the
    record's signature is that of a fresh look, and no longer the first."""
    base = bonded_scene()
    ordinary, fresh = _steps(base, _pull), _steps(base, _pull, fresh_look=True)
    assert ordinary.arrays["nbonds"].sum() < base.arrays["nbonds"].sum()
    assert ordinary.info[SIGNATURE] == fresh.info[SIGNATURE] != base.info[SIGNATURE]


@pytest.mark.filterwarnings("ignore::ase_bpm.OptimiserStepWarning")  # (momenta kept)
@pytest.mark.filterwarnings("ignore::ase_bpm.SpinNotIntegratedWarning")  # (spins kept)
@pytest.mark.parametrize("scene, edit", [
    (bonded_scene, None), (bonded_scene, _retype), (bonded_scene, _reweigh),
    (bonded_scene, _rebond), (bonded_scene, _kick), (periodic_scene, _recell),
    (by_numbers_scene, _renumber),
    (granular_scene, None),
    (granular_scene, _resize), (granular_scene, _reweigh), (granular_scene, _hold)])
def test_a_step_after_an_input_changed_is_the_step_of_a_fresh_look(scene, edit):
    """Steps that move the atoms, one of them after ``edit`` changed an input
    along with the move, give what the same steps give when the calculator
    forgets what the last evaluation saw before each (lifecycle.Seen, whose
    ordinary step takes the last evaluation's checked inputs and signature):
    forces, energies, the ledger, the record's signature, bit for bit."""
    base = scene()
    ordinary, fresh = _steps(base, edit), _steps(base, edit, fresh_look=True)
    assert ordinary.info["bpm_step"] == fresh.info["bpm_step"] == base.info["bpm_step"] + 4
    assert np.array_equal(ordinary.get_forces(), fresh.get_forces())
    for name in ("bpm_energy", "bpm_dissipated_energy", SIGNATURE):
        assert ordinary.info[name] == fresh.info[name], name
    if edit is not None:  # (and the edit mattered)
        assert not np.array_equal(_steps(base).get_forces(), ordinary.get_forces())


class _FailingFix:
    """A fix that raises while ``failing`` (an evaluation that does not finish)."""

    failing = False

    def forces(self, atoms, time):
        if self.failing:
            raise RuntimeError("the fix failed")
        return np.zeros((len(atoms), 3)), 0.0

    def todict(self):
        return {"name": "failing fix"}


def _moves_after_a_failed_step(fail: bool):
    """Two steps; then bond types replaced and a step that fails in a fix
    (``fail``), after which the user puts the old bond types back; then a
    step. Its forces."""
    atoms, _ = multi_type_cluster()
    fix = _FailingFix()
    atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS, fixes=[fix])
    rng = np.random.default_rng(1)
    for _ in range(2):
        atoms.positions = atoms.positions + rng.normal(0.0, 1e-3, atoms.positions.shape)
        atoms.get_forces()
    kept = atoms.arrays[BOND_TYPE]
    if fail:
        other = kept.copy()
        other[other == 1] = 2
        atoms.arrays[BOND_TYPE] = other
        fix.failing = True
        with pytest.raises(RuntimeError, match="the fix failed"):
            atoms.get_forces()
        fix.failing = False
        atoms.arrays[BOND_TYPE] = kept
    atoms.positions = atoms.positions + rng.normal(0.0, 1e-3, atoms.positions.shape)
    return atoms.get_forces()


def test_a_step_after_one_that_failed_reads_the_bonds_afresh():
    """An evaluation that raises (here in a fix) after reading replaced bond
    arrays leaves nothing the next step takes as the last evaluation's: with
    the old arrays put back, the next step is the one that never failed."""
    assert np.array_equal(_moves_after_a_failed_step(True), _moves_after_a_failed_step(False))


def test_an_ordinary_step_takes_no_view_of_a_detached_array():
    """The types a step hands on to the next are its own copy: an array
    detached from the atoms (an equal copy put in its place) and then
    changed does not reach the next step."""
    def steps(detach: bool):
        atoms, _ = multi_type_cluster()
        atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
        rng = np.random.default_rng(1)
        for k in range(3):
            atoms.positions = atoms.positions + rng.normal(0.0, 1e-3, atoms.positions.shape)
            if k == 2 and detach:
                old = atoms.arrays["type"]
                atoms.arrays["type"] = old.copy()
                old[:] = 1
            atoms.get_forces()
        return atoms.get_forces()

    assert np.array_equal(steps(True), steps(False))
