"""A granular MD step's own calls (issue 31, the lean step): the model, its
contact history, the fixes, the integrator and the wrappers of the compiled
granular kernels make few Python calls a step, whatever the scene's size."""

import cProfile
import pstats
from pathlib import Path

import numpy as np
import pytest

import ase_bpm
from ase_bpm.scene.demos import pour
from ase_bpm.scene.md import SphereVelocityVerlet

PACKAGE = Path(ase_bpm.__file__).parent
#: the modules of the granular step, and the granular functions of compiled.py
STEP_MODULES = ("models/granular.py", "models/contacts.py", "scene/fixes.py",
                "scene/md.py", "laws/granular.py")
COMPILED_GRANULAR = ("pair_contacts", "walls_contacts", "_spheres", "_sums_into")
#: asked each step by the calculator's digest of its fixes (models/base.py),
#: not by the step's own work
DIGEST = "todict"
#: calls a step at the most (48 before the lean step, counted so; 21 with it)
MOST_CALLS = 26


def step_calls(atoms, steps: int) -> dict:
    """Calls a step to each function of the granular step (name: count)."""
    dyn = SphereVelocityVerlet(atoms, pour.TIMESTEP)
    dyn.run(5)
    profile = cProfile.Profile()
    profile.enable()
    dyn.run(steps)
    profile.disable()
    calls = {}
    for (file, line, name), (_, count, *_) in pstats.Stats(profile).stats.items():
        path = Path(file)
        if not path.is_relative_to(PACKAGE) or name == DIGEST:
            continue
        where = path.relative_to(PACKAGE).as_posix()
        if where in STEP_MODULES or (where == "laws/compiled.py"
                                     and name in COMPILED_GRANULAR):
            calls[f"{where}:{line}:{name}"] = count / steps
    return calls


def test_a_pour_step_makes_few_calls_in_the_model_fixes_and_integrator():
    atoms = pour.demo_scene(quick=True)  # 500 spheres, gravity, five frictional walls
    if atoms.calc.kernel_route != "compiled":
        pytest.skip("the NumPy kernels are Python functions: counted on the compiled route")
    calls = step_calls(atoms, 40)
    assert sum(calls.values()) <= MOST_CALLS, sorted(calls.items(), key=lambda kv: -kv[1])
    # the kernels once a step each: the pairs, and the walls of one law together
    for name in ("pair_contacts", "walls_contacts"):
        assert [n for where, n in calls.items() if where.endswith(f":{name}")
                and "compiled" in where] == [1.0]


def test_gravity_direction_is_replaced_not_edited():
    """Gravity keeps its weights while the masses and its direction are the
    same read-only arrays: an edit of its direction in place is refused (it
    would go unseen), a new direction is followed, and one given as a
    writable array is followed through edits."""
    from ase import Atoms

    atoms = Atoms("H2", positions=[[0, 0, 0], [3, 0, 0]], masses=[1.0, 3.0])
    gravity = ase_bpm.Gravity(2.0)
    atoms.calc = ase_bpm.BPMSpring(fixes=[gravity])
    with pytest.raises(ValueError, match="read-only"):
        gravity.direction[2] = 1.0
    assert np.array_equal(atoms.get_forces()[:, 2], [-2.0, -6.0])
    gravity.direction = np.array([0.0, 1.0, 0.0])  # a writable array: compared by value
    atoms.calc.refresh()
    assert np.array_equal(atoms.get_forces()[:, 1], [2.0, 6.0])
    gravity.direction[1] = -1.0  # an edit of that array
    atoms.calc.refresh()
    assert np.array_equal(atoms.get_forces()[:, 1], [-2.0, -6.0])
    assert np.array_equal(gravity.forces(atoms, 0.0)[0][:, 1], [-2.0, -6.0])
