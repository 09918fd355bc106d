"""What the guard says short of stopping a run (issue 29): a timestep above
``stable_timestep(atoms)`` (TimestepWarning), a timestep it cannot tell
(TimestepUncheckedWarning, under thermostats) and evaluations that look like
an optimiser's outside ``ase_bpm.pure`` (OptimiserStepWarning); each where it
must be given and nowhere else."""

import warnings

import numpy as np
import pytest
from ase.constraints import FixAtoms
from ase.lattice.cubic import FaceCenteredCubic, SimpleCubic
from ase.md.langevin import Langevin
from ase.md.verlet import VelocityVerlet as AseVelocityVerlet
from ase.optimize import BFGS
from ase.vibrations import Vibrations

import ase_bpm
import ase_bpm.models.guard
from ase_bpm import VelocityVerlet
from scenes import fcc_cluster

NEW = (ase_bpm.TimestepWarning, ase_bpm.OptimiserStepWarning)


def readme_block():
    """The README's usage example: a jittered 8x8x2 FCC block, bonded."""
    atoms = FaceCenteredCubic("Ne", size=(8, 8, 2), latticeconstant=4 ** (1 / 3), pbc=False)
    atoms.positions += np.random.default_rng(0).uniform(-0.1, 0.1, atoms.positions.shape)
    atoms.set_masses(np.ones(len(atoms)))
    atoms.set_velocities(np.random.default_rng(1).normal(0, 0.05, (len(atoms), 3)))
    ase_bpm.create_bonds(atoms, 1.5, bond_type=1)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.04, 1.0)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 1.0)})
    return atoms


def block(seed=0, speed=0.01, **calc):
    """A small damped FCC block, bonded, moving a little."""
    atoms, rng = fcc_cluster(2, seed=seed)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, speed, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.05, 0.5)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)}, **calc)
    return atoms


def caught(run, kinds=NEW):
    """The warnings of ``kinds`` that ``run()`` gives, every one."""
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        run()
    return [w for w in seen if issubclass(w.category, kinds)]


def langevin(atoms, dt, seed=0):
    return Langevin(atoms, dt, temperature_K=1.0, friction=0.05, fixcm=False,
                    rng=np.random.default_rng(seed))


# -- item 1: timesteps between the estimate and three times it ----------------------------

def test_the_readme_block_at_one_and_a_half_times_the_estimate_is_warned_of():
    atoms = readme_block()
    estimate = atoms.calc.stable_timestep(atoms)
    assert estimate == pytest.approx(0.155, abs=5e-4)
    dt = 1.5 * estimate
    seen = caught(lambda: AseVelocityVerlet(atoms, timestep=dt).run(30))
    assert [w.category for w in seen] == [ase_bpm.TimestepWarning]
    message = str(seen[0].message)
    assert f"the timestep {dt:.6g} is 1.5 times stable_timestep(atoms)" in message
    assert f"{estimate:.6g} at step 0's positions, the run's first state" in message
    assert "the stiffest particle is " in message and "3 times" in message
    assert seen[0].filename == __file__  # the user's line


def test_the_warning_comes_once_per_calculator_and_timestep():
    atoms = block()
    estimate = atoms.calc.stable_timestep(atoms)
    dyn = VelocityVerlet(atoms, timestep=1.5 * estimate)
    assert len(caught(lambda: dyn.run(5))) == 1
    assert caught(lambda: dyn.run(5)) == []  # the same calculator, the same timestep
    dyn.dt = 2.0 * dyn.dt / 1.5
    seen = caught(lambda: dyn.run(5))  # another timestep: checked and named again
    assert len(seen) == 1 and "is 2 times" in str(seen[0].message)
    atoms.calc = ase_bpm.BPMSpring(**atoms.calc.todict())
    assert len(caught(lambda: VelocityVerlet(atoms, timestep=1.5 * estimate).run(3))) == 1


@pytest.mark.parametrize("factor", [0.5, 1.0])
@pytest.mark.parametrize("integrator", ["ase", "ase_bpm", "langevin"])
def test_no_warning_at_or_below_the_estimate(integrator, factor):
    atoms = block()
    dt = factor * atoms.calc.stable_timestep(atoms)
    if integrator == "ase":
        dyn = AseVelocityVerlet(atoms, timestep=dt)
    elif integrator == "ase_bpm":
        dyn = VelocityVerlet(atoms, timestep=dt)
    else:  # ASE's thermostat, told the timestep
        atoms.calc.set(timestep=dt)
        dyn = langevin(atoms, dt)
    assert caught(lambda: dyn.run(200)) == []
    assert atoms.info["bpm_step"] == 200


def test_the_readme_example_runs_without_a_warning():
    atoms = readme_block()
    assert caught(lambda: AseVelocityVerlet(atoms, timestep=0.1).run(300)) == []


def test_above_three_times_it_stops_naming_the_state_of_the_estimate():
    """Before the run stable_timestep gives 0.155; the error at 10 times it
    gives the same, at the state the run started from (step 1's positions
    would give another)."""
    atoms = readme_block()
    estimate = atoms.calc.stable_timestep(atoms)
    with pytest.raises(ase_bpm.UnstableSimulationError,
                       match=rf"step 1 \(timestep {10 * estimate:.6g}\): the timestep is 10 "
                             rf"times the stable timestep {estimate:.6g} at step 0's positions, "
                             r"the run's first state \(the stiffest particle is \d+\), more "
                             r"than 3 times"):
        AseVelocityVerlet(atoms, timestep=10 * estimate).run(5)
    assert atoms.info["bpm_step"] == 0


def test_a_later_error_gives_the_estimate_now_and_at_the_run_s_first_state(monkeypatch):
    """A blow-up caught by the run-time checks names both estimates."""
    monkeypatch.setattr(ase_bpm.models.guard, "BEYOND_LIMIT", np.inf)
    atoms = readme_block()
    first = atoms.calc.stable_timestep(atoms)
    with pytest.warns(ase_bpm.TimestepWarning), np.errstate(over="ignore", invalid="ignore"), \
            pytest.raises(ase_bpm.UnstableSimulationError,
                          match=r"step (\d+) .*stable_timestep\(atoms\) suggests at most "
                                rf"[\d.e+-]+ at step \d+'s positions \({first:.6g} at the "
                                r"run's first state, step 0\)"):
        AseVelocityVerlet(atoms, timestep=10 * first).run(300)


def test_a_later_check_at_a_stiffer_state_warns(monkeypatch):
    """Checked again every STABILITY_EVERY steps, at that step's positions."""
    monkeypatch.setattr(ase_bpm.models.guard, "STABILITY_EVERY", 5)
    atoms = block()
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.5)},  # contacts on bonds
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)}, overlay_pair=True)
    first = atoms.calc.stable_timestep(atoms)
    dyn = VelocityVerlet(atoms, timestep=0.9 * first)
    assert caught(lambda: dyn.run(3)) == []  # checked at step 1
    atoms.positions *= 0.9  # pressed by hand: contacts act, 1.35 times as stiff ...
    assert caught(lambda: dyn.run(1)) == []  # (steps 4, the hand's, and 5) ...
    assert atoms.info["bpm_step"] == 5  # ... judged when due again, at step 6
    seen = caught(lambda: dyn.run(1))
    assert [w.category for w in seen] == [ase_bpm.TimestepWarning]
    assert (f"at step 6's positions ({first:.6g} at the run's first state, step 0)"
            in str(seen[0].message))


def test_set_has_the_next_step_check_the_timestep():
    """Stiffer bonds through calc.set: judged at the very next step, at the
    state the step started from, not STABILITY_EVERY steps later."""
    atoms = block()
    calc = atoms.calc
    first = calc.stable_timestep(atoms)
    dyn = VelocityVerlet(atoms, timestep=0.9 * first)
    assert caught(lambda: dyn.run(3)) == []  # checked at step 1
    calc.set(bond_coeffs={1: (4.0, 0.05, 0.5)})  # four times as stiff from now on
    seen = caught(lambda: dyn.run(1))
    assert [w.category for w in seen] == [ase_bpm.TimestepWarning]
    assert (f"at step 3's positions ({first:.6g} at the run's first state, step 0)"
            in str(seen[0].message))
    calc.refresh()  # the same timestep, checked and named again after a refresh
    assert [w.category for w in caught(lambda: dyn.run(1))] == [ase_bpm.TimestepWarning]


def test_langevin_without_timestep_says_the_timestep_is_not_checked():
    atoms = readme_block()
    dt = 10 * atoms.calc.stable_timestep(atoms)  # far beyond: nothing can tell
    seen = caught(lambda: langevin(atoms, dt).run(10))
    assert [w.category for w in seen] == [ase_bpm.TimestepUncheckedWarning]
    message = str(seen[0].message)
    assert "not checked against stable_timestep(atoms)" in message
    assert "pass timestep=" in message and "Langevin" in message
    assert caught(lambda: langevin(atoms, dt).run(10)) == []  # once per calculator


@pytest.mark.parametrize("factor, expected", [(2.0, ase_bpm.TimestepWarning),
                                              (4.0, ase_bpm.UnstableSimulationError)])
def test_langevin_with_timestep_is_checked_as_any_integrator(factor, expected):
    atoms = block()
    dt = factor * atoms.calc.stable_timestep(atoms)
    atoms.calc.set(timestep=dt)
    dyn = langevin(atoms, dt)
    if expected is ase_bpm.UnstableSimulationError:
        with pytest.raises(expected, match="more than 3 times"):
            dyn.run(5)
    else:
        seen = caught(lambda: dyn.run(5))
        assert [w.category for w in seen] == [expected]
        assert "is 2 times" in str(seen[0].message)


def test_without_the_guard_no_timestep_is_checked_nor_warned_of():
    atoms = block(guard=False)
    dt = 2.0 * atoms.calc.stable_timestep(atoms)
    assert caught(lambda: VelocityVerlet(atoms, timestep=dt).run(5)) == []
    assert caught(lambda: langevin(atoms, dt).run(10)) == []


def test_a_hand_move_before_the_run_is_no_untold_timestep():
    atoms = block()
    dt = 0.5 * atoms.calc.stable_timestep(atoms)
    atoms.get_forces()
    atoms.positions[:, 0] += 0.3  # moved into place by hand
    assert caught(lambda: AseVelocityVerlet(atoms, timestep=dt).run(50)) == []


# -- item 2: evaluations that look like an optimiser's -------------------------------------

def test_bfgs_outside_pure_is_warned_of_once():
    atoms = block(speed=0.0)
    atoms.get_forces()  # reference lengths, then deformed
    atoms.positions += np.random.default_rng(3).normal(0, 0.03, atoms.positions.shape)
    seen = caught(lambda: BFGS(atoms, logfile=None).run(steps=5))
    assert [w.category for w in seen] == [ase_bpm.OptimiserStepWarning]
    message = str(seen[0].message)
    assert "momenta unchanged" in message and "ase_bpm.pure" in message
    assert "MD step" in message and seen[0].filename == __file__
    assert caught(lambda: BFGS(atoms, logfile=None).run(steps=5)) == []  # once


def test_bfgs_inside_pure_is_not():
    atoms = block(speed=0.0)
    atoms.get_forces()  # reference lengths, then deformed
    atoms.positions += np.random.default_rng(3).normal(0, 0.03, atoms.positions.shape)

    def relax():
        with ase_bpm.pure(atoms):
            BFGS(atoms, logfile=None).run(steps=5)
        atoms.calc.step(atoms)  # quasi-static: commit the breaking
        atoms.positions[:2, 0] -= 0.02  # the boundary moves, and again
        with ase_bpm.pure(atoms):
            BFGS(atoms, logfile=None).run(steps=5)
        atoms.calc.step(atoms)

    assert caught(relax) == []


def test_bfgs_is_warned_of_with_the_guard_off_too():
    atoms = block(speed=0.05, guard=False)  # moving atoms: their momenta stay as they are
    atoms.get_forces()
    atoms.positions += np.random.default_rng(3).normal(0, 0.03, atoms.positions.shape)
    seen = caught(lambda: BFGS(atoms, logfile=None).run(steps=3))
    assert [w.category for w in seen] == [ase_bpm.OptimiserStepWarning]


def test_vibrations_outside_pure_are_warned_of(tmp_path):
    atoms = block(speed=0.05)  # moving atoms: their momenta stay as they are
    vib = Vibrations(atoms, indices=[0, 1], name=str(tmp_path / "vib"))
    seen = caught(vib.run)
    assert [w.category for w in seen] == [ase_bpm.OptimiserStepWarning]


def test_vibrations_inside_pure_are_not(tmp_path):
    atoms = block(speed=0.05)
    vib = Vibrations(atoms, indices=[0, 1], name=str(tmp_path / "vib"))

    def run():
        with ase_bpm.pure(atoms):
            vib.run()

    assert caught(run) == []


@pytest.mark.parametrize("scene", ["ase-from-rest", "ase", "ase_bpm", "langevin",
                                   "fixatoms", "indenter", "translated", "free-flight"])
def test_no_optimiser_warning_under_dynamics(scene):
    """Each scene is evaluated, then deformed by hand (one evaluation at new
    positions with the momenta as they were), then run; ASE's Langevin
    evaluates before it sets the momenta, so from rest its first step is
    another such."""
    atoms = block(speed=0.01 if scene in ("ase", "ase_bpm", "translated") else 0.0)
    dt = 0.5 * atoms.calc.stable_timestep(atoms)
    atoms.get_forces()  # reference lengths
    if scene == "free-flight":  # undeformed, translating: forces of round-off size only
        atoms.set_velocities(np.tile([0.3, 0.1, 0.0], (len(atoms), 1)))
    else:
        atoms.positions += np.random.default_rng(3).normal(0, 0.02, atoms.positions.shape)
    if scene == "langevin":  # from rest
        atoms.calc.set(timestep=dt)
        dyn = langevin(atoms, dt)
    elif scene == "ase_bpm":
        dyn = VelocityVerlet(atoms, timestep=dt)
    else:
        if scene == "fixatoms":  # the held atoms feel forces and do not move
            atoms.set_constraint(FixAtoms(indices=[0, 1, 2]))
        if scene == "indenter":  # a moving fix, pressing on the body
            centre = atoms.positions.mean(axis=0) + [0.0, 0.0, 3.0]
            atoms.calc = ase_bpm.BPMSpring(**atoms.calc.todict(), timestep=dt, fixes=[
                ase_bpm.SphericalIndenter(10.0, 1.5, centre, (0.0, 0.0, -0.1))])
        if scene == "translated":  # and moved into place by hand
            atoms.get_forces()
            atoms.positions += [3.0, 0.0, 0.0]
        dyn = AseVelocityVerlet(atoms, timestep=dt)
    assert caught(lambda: dyn.run(100)) == []
    assert atoms.info["bpm_step"] >= 100


def test_a_restart_continues_without_a_warning(tmp_path):
    atoms = block()
    dt = 0.5 * atoms.calc.stable_timestep(atoms)
    AseVelocityVerlet(atoms, timestep=dt).run(20)
    ase_bpm.write_restart(tmp_path / "run.bpm", atoms)
    back = ase_bpm.read_restart(tmp_path / "run.bpm")
    back.calc = ase_bpm.BPMSpring(**atoms.calc.todict())
    assert caught(lambda: AseVelocityVerlet(back, timestep=dt).run(50)) == []
    assert back.info["bpm_step"] == 70


# -- the demos at their own timesteps ---------------------------------------------------

#: each demo's integrator (as the demo runs it) and the steps run here: the
#: pour's quick run whole (checked again at steps 2001, 4001, 6001, as it
#: packs), the others' first steps (their full runs, checked by hand, warn
#: of nothing either)
DEMO_RUNS = {"impact": (AseVelocityVerlet, 300), "shatter": (VelocityVerlet, 100),
             "pour": (ase_bpm.SphereVelocityVerlet, None),
             "beam": (ase_bpm.SphereVelocityVerlet, 500)}


@pytest.mark.parametrize("name", sorted(DEMO_RUNS))
def test_the_quick_demos_run_without_a_warning(name):
    from importlib import import_module

    demo = import_module(f"ase_bpm.scene.demos.{name}")
    integrator, steps = DEMO_RUNS[name]
    steps = steps or demo.QUICK_STEPS
    atoms = demo.demo_scene(quick=True)
    dyn = integrator(atoms, timestep=demo.TIMESTEP)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ase_bpm.TimestepWarning)
        warnings.simplefilter("error", ase_bpm.OptimiserStepWarning)
        dyn.run(steps)
    assert atoms.info["bpm_step"] == steps


# -- between the tested cases (a review and a new user's trial) -----------------------

def pressable_block():
    """``block`` whose contacts act on bonded pairs too (overlay/pair): pressed
    to 0.9 of its size it is 1.4 times as stiff (stable_timestep 0.263 -> 0.185)."""
    atoms = block()
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.5)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)}, overlay_pair=True)
    return atoms


def test_a_body_pressed_by_hand_before_the_run_is_judged_where_it_is():
    """Evaluated, then pressed by hand, then run: the first check takes the
    stiffer state the atoms are in, not the evaluated one (3.2 times the one,
    2.3 times the other)."""
    atoms = pressable_block()
    atoms.get_forces()
    atoms.positions *= 0.9
    pressed = atoms.calc.stable_timestep(atoms)
    assert 3.0 * pressed < 2.2 * 0.26
    with pytest.raises(ase_bpm.UnstableSimulationError, match="3.2 times the stable timestep"):
        AseVelocityVerlet(atoms, timestep=3.2 * pressed).run(3)


def test_a_quasi_static_step_has_no_timestep_to_check():
    """calc.step integrates nothing: a timestep= given (for the clock) is not
    judged against stable_timestep there."""
    atoms = block(timestep=None)
    atoms.calc.set(timestep=2.0 * atoms.calc.stable_timestep(atoms))
    atoms.get_forces()
    atoms.positions[0] += 0.01
    with pytest.warns() as seen:
        warnings.warn("marker")
        atoms.calc.step(atoms)
    assert [w.category for w in seen] == [UserWarning]
    assert atoms.info["bpm_step"] == 1


def test_a_new_integrator_at_another_timestep_is_checked_at_once():
    """Under ASE's VelocityVerlet the timestep is told by the drift: a second
    integrator on the same atoms at another timestep is judged at its first
    step, not 2,000 steps later (one particle's drift tells the change)."""
    atoms = readme_block()
    estimate = atoms.calc.stable_timestep(atoms)
    assert caught(lambda: AseVelocityVerlet(atoms, timestep=0.5 * estimate).run(20)) == []
    seen = caught(lambda: AseVelocityVerlet(atoms, timestep=1.5 * estimate).run(2))
    assert [w.category for w in seen] == [ase_bpm.TimestepWarning]
    assert atoms.info["bpm_step"] == 22
    with pytest.raises(ase_bpm.UnstableSimulationError, match="more than 3 times"):
        AseVelocityVerlet(atoms, timestep=3.5 * estimate).run(2)
    assert atoms.info["bpm_step"] == 22


def test_spheres_that_touch_later_are_judged_when_they_do():
    """stable_timestep is inf before the spheres touch: checked again as soon
    as a contact acts (here the floor), not 2,000 steps later: a timestep far
    beyond the landed spheres' limit is named (or stops the run) at their
    landing (before, at 0.04 they bounced off the floor to z = 180 unnamed)."""
    spheres = SimpleCubic("Ar", size=(3, 3, 3), latticeconstant=1.25, pbc=False)
    spheres.positions += 1.0
    spheres.arrays["radius"] = np.full(len(spheres), 0.5)
    spheres.set_masses(np.full(len(spheres), 0.5))
    law = dict(kn=2000.0, gamma_n=50.0, xmu=0.5, dampflag=0)
    spheres.calc = ase_bpm.Granular("hooke/history", **law, fixes=[
        ase_bpm.Gravity(1.0), ase_bpm.GranularWall("hooke/history", **law, axis="z", lo=0.0)])
    assert spheres.calc.stable_timestep(spheres) == np.inf
    landed = spheres.copy()
    landed.calc = ase_bpm.Granular(**spheres.calc.todict())
    seen = caught(lambda: ase_bpm.SphereVelocityVerlet(spheres, timestep=0.04).run(30))
    assert [w.category for w in seen] == [ase_bpm.TimestepWarning]  # 2.1 times, landing
    assert "at step 25's positions" in str(seen[0].message)
    with pytest.raises(ase_bpm.UnstableSimulationError, match="more than 3 times"):
        ase_bpm.SphereVelocityVerlet(landed, timestep=0.07).run(2000)
    assert landed.info["bpm_step"] < 20


def test_a_slow_body_far_from_the_origin_drifts_as_velocity_verlet():
    """Displacements of 1e-7 at coordinates of 10: round-off in the positions
    is not a thermostat (no TimestepUncheckedWarning)."""
    atoms = block(speed=1e-6)
    atoms.positions += 10.0
    seen = caught(lambda: AseVelocityVerlet(atoms, timestep=0.1).run(20),
                  kinds=(ase_bpm.TimestepUncheckedWarning, ase_bpm.OptimiserStepWarning))
    assert seen == []


def test_the_error_says_how_to_run_again():
    atoms = readme_block()
    estimate = atoms.calc.stable_timestep(atoms)
    kept = atoms.copy()
    with pytest.raises(ase_bpm.UnstableSimulationError,
                       match="start from a copy or restart file of them taken before"):
        AseVelocityVerlet(atoms, timestep=4 * estimate).run(3)
    kept.calc = ase_bpm.BPMSpring(**atoms.calc.todict())  # as the message says
    assert caught(lambda: AseVelocityVerlet(kept, timestep=estimate).run(3)) == []
