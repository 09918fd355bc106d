"""A granular MD step does each piece of work once: the contact kernel and
the walls' kernel (the walls of one law together) run once a step, and
Gravity keeps its weights while nothing they depend on changes."""

import numpy as np
import pytest

import ase_bpm
from ase_bpm.laws import compiled
from ase_bpm.scene.demos import pour
from ase_bpm.scene.md import SphereVelocityVerlet

STEPS = 40


def test_a_pour_step_runs_each_kernel_once(monkeypatch):
    atoms = pour.demo_scene(quick=True)  # 500 spheres, gravity, five frictional walls
    if atoms.calc.kernel_route != "compiled":
        pytest.skip("counts the compiled kernels' calls")
    dyn = SphereVelocityVerlet(atoms, pour.TIMESTEP)
    dyn.run(5)
    calls = {"pair_contacts": 0, "walls_contacts": 0}
    for name in calls:
        kernel = getattr(compiled, name)

        def counted(*args, _kernel=kernel, _name=name, **kwargs):
            calls[_name] += 1
            return _kernel(*args, **kwargs)
        monkeypatch.setattr(compiled, name, counted)
    dyn.run(STEPS)
    assert calls == {"pair_contacts": STEPS, "walls_contacts": STEPS}


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
