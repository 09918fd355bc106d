"""The calculator as an ASE adapter: its machinery in modules of its own
(models/lifecycle.py, guard.py, ledger.py, record.py, pure.py), each usable
without a calculator, and every name models/base.py defined before the split
still importable from there."""

import importlib

import numpy as np
import pytest
from ase.lattice.cubic import FaceCenteredCubic

import ase_bpm
from ase_bpm.core.arrays import Inputs
from ase_bpm.models import base
from ase_bpm.models.evaluation import Context, Evaluation
from ase_bpm.models.guard import RUNAWAY_FACTOR, RUNAWAY_STEPS, Guard, UnstableSimulationError
from ase_bpm.models.record import STEP, STRESS
from scenes import FCC
from state import assert_unchanged, snapshot

#: the names models/base.py defined before the split, with their new homes
#: (None: still defined there)
MOVED = {
    "record": ["X_LAST", "F_LAST", "FD_LAST", "T_LAST", "STEP", "ENERGY", "STRESS",
               "RECORD_IDS", "DISSIPATED", "BROKEN_ENERGY", "SIGNATURE", "digest",
               "InputDigests"],
    "guard": ["RUNAWAY_FACTOR", "RUNAWAY_STEPS", "BEYOND_LIMIT", "STABILITY_EVERY",
              "DRIFT_PRECISION", "DRIFT_RESIDUAL", "POSITION_ROUNDOFF", "UNTOLD_STEPS",
              "STILL_STEPS", "LEDGER_FACTOR", "TimestepWarning", "TimestepUncheckedWarning",
              "OptimiserStepWarning", "RUN_AGAIN", "UnstableSimulationError", "GuardWatch"],
    "lifecycle": ["SpinNotIntegratedWarning", "state_taken", "_together", "_add"],
    "ledger": ["_work"],
    "pure": ["pure"],
    None: ["virial", "FIX_TYPES", "register_fix", "fix_from_dict", "BPMCalculator"],
}


@pytest.mark.parametrize("home,name", [(home, name) for home, names in MOVED.items()
                                       for name in names])
def test_every_name_base_defined_stays_importable_from_base(home, name):
    assert hasattr(base, name), f"ase_bpm.models.base.{name} is gone"
    if home is not None:
        moved_to = importlib.import_module(f"ase_bpm.models.{home}")
        assert getattr(base, name) is getattr(moved_to, name)


def test_public_names_are_the_moved_ones():
    assert ase_bpm.pure is base.pure
    assert ase_bpm.UnstableSimulationError is UnstableSimulationError
    assert ase_bpm.SpinNotIntegratedWarning is base.SpinNotIntegratedWarning


def test_guard_works_from_what_it_is_told_without_a_calculator():
    """The runaway check on its own: kinetic energy growing more than
    RUNAWAY_FACTOR-fold in each of RUNAWAY_STEPS steps stops the run, and
    the message takes its advice from the estimate the guard is handed."""
    atoms = FaceCenteredCubic("Cu", size=(2, 2, 2), latticeconstant=FCC)
    atoms.set_masses(np.ones(len(atoms)))
    guard, dt = Guard("Stand-in"), 0.01
    asked = []

    def stiffest(at):
        asked.append(len(at))
        return 0.004, 5

    growth = np.sqrt(2 * RUNAWAY_FACTOR)  # the kinetic energy 2 RUNAWAY_FACTOR-fold
    atoms.set_velocities(np.full((len(atoms), 3), 1e-3))
    check = dict(on=True, announced=True, quasi_static=True, given=dt, stiffest=stiffest)

    def step_to(step):
        atoms.set_velocities(atoms.get_velocities() * growth)
        ctx = Context(advancing=True, pure=False, step=step, timestep=dt,
                      inputs=Inputs(atoms), parameters={}, fixes=())
        guard.check(atoms, Evaluation(forces=np.zeros((len(atoms), 3)), energy=0.0), ctx,
                    **check)

    for step in range(1, RUNAWAY_STEPS + 1):  # the first sets the scale, then a streak
        step_to(step)
    with pytest.raises(UnstableSimulationError) as raised:
        step_to(RUNAWAY_STEPS + 1)
    message = str(raised.value)
    assert message.startswith(f"step {RUNAWAY_STEPS + 1} (timestep 0.01): the kinetic "
                              f"energy grew more than {RUNAWAY_FACTOR:g}-fold in each of "
                              f"the last {RUNAWAY_STEPS} steps")
    assert f"suggests at most 0.004 at step {RUNAWAY_STEPS + 1}'s positions" in message
    assert asked == [len(atoms)]  # asked once, for the message


def test_guard_off_looks_at_nothing_and_non_finite_positions_without_record_are_bad_input():
    atoms = FaceCenteredCubic("Cu", size=(2, 2, 2), latticeconstant=FCC)
    atoms.set_masses(np.ones(len(atoms)))
    ctx = Context(advancing=True, pure=False, step=1, timestep=0.01, inputs=Inputs(atoms),
                  parameters={}, fixes=())
    forces = np.zeros((len(atoms), 3))
    forces[3, 1] = np.nan
    ev = Evaluation(forces=forces, energy=0.0)
    guard = Guard("Stand-in")
    guard.check(atoms, ev, ctx, on=False, announced=True, quasi_static=True, given=0.01,
                stiffest=None)  # off: not looked at
    with pytest.raises(UnstableSimulationError, match=r"the force on particle 3 is \[ *0\. +nan"):
        guard.check(atoms, ev, ctx, on=True, announced=True, quasi_static=True, given=0.01,
                    stiffest=lambda at: (None, None))
    atoms.positions[2, 0] = np.inf  # no record on the atoms: bad input, not a blow-up
    with pytest.raises(ValueError, match="position") as raised:
        guard.non_finite_positions(atoms, 0.01, stiffest=None)
    assert not isinstance(raised.value, UnstableSimulationError)


def periodic_block():
    atoms = FaceCenteredCubic("Cu", size=(3, 3, 3), latticeconstant=FCC, pbc=True)
    atoms.set_masses(np.ones(len(atoms)))
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0)})
    atoms.get_forces()  # reference lengths
    atoms.positions += np.random.default_rng(4).uniform(-0.02, 0.02, atoms.positions.shape)
    return atoms


def test_pure_stress_leaves_the_recorded_stress_as_it_was():
    atoms = periodic_block()
    stress = atoms.get_stress()  # a step, its stress recorded
    assert np.array_equal(atoms.info[STRESS], stress)
    before, step = snapshot(atoms), atoms.info[STEP]
    at = atoms.positions.copy()
    with ase_bpm.pure(atoms):
        atoms.positions *= 1.01
        assert not np.allclose(atoms.get_stress(), stress)
        atoms.positions = at
        assert np.array_equal(atoms.get_stress(), stress)  # pure: the same function
        assert_unchanged(atoms, before)
    assert np.array_equal(atoms.get_stress(), stress)
    assert atoms.info[STEP] == step  # the record's: no evaluation, no step
