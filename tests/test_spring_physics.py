"""BPMSpring physics: analytic results, conservation laws, invariances."""

import contextlib

import numpy as np
import pytest
from ase import Atoms
from ase.md.verlet import VelocityVerlet
from hypothesis import given, settings
from hypothesis import strategies as st

import ase_bpm
from ase_bpm.laws.spring import spring_bonds, spring_pairs
from scenes import MULTI_TYPE_COEFFS, deform_below_breaking, fcc_cluster, multi_type_cluster


def undamped(coeffs):
    return dict(bond_coeffs={t: (k, e, 0.0) for t, (k, e, _) in coeffs["bond_coeffs"].items()},
                pair_coeffs={p: (k, rc, 0.0) for p, (k, rc, _) in coeffs["pair_coeffs"].items()})


def deformed_scene(seed=1, smooth=True, normalize=False, damped=False, overlay=False):
    atoms, rng = multi_type_cluster(seed=seed)
    coeffs = MULTI_TYPE_COEFFS if damped else undamped(MULTI_TYPE_COEFFS)
    atoms.calc = ase_bpm.BPMSpring(**coeffs, smooth=smooth, normalize=normalize,
                                   overlay_pair=overlay)
    atoms.get_forces()  # reference lengths
    atoms.positions = deform_below_breaking(atoms, rng)
    atoms.set_velocities(rng.normal(0, 0.1, atoms.positions.shape))
    return atoms, rng


@pytest.mark.parametrize("smooth,normalize,overlay",
                         [(True, False, False), (False, False, True), (True, True, False),
                          (False, True, True)])
def test_forces_are_minus_energy_gradient(smooth, normalize, overlay):
    atoms, _ = deformed_scene(smooth=smooth, normalize=normalize, overlay=overlay)
    forces = atoms.get_forces()
    h = 1e-6
    for n in range(0, len(atoms), 7):
        for c in range(3):
            energies = []
            for sign in (1, -1):
                probe = atoms.copy()
                probe.calc = ase_bpm.BPMSpring(**undamped(MULTI_TYPE_COEFFS), smooth=smooth,
                                               normalize=normalize, overlay_pair=overlay)
                probe.positions[n, c] += sign * h
                energies.append(probe.get_potential_energy())
            assert forces[n, c] == pytest.approx(-(energies[0] - energies[1]) / (2 * h),
                                                 abs=1e-7)


def test_bond_energy_is_integral_of_smoothed_force():
    """Analytic check of the kernel: dU/dr = F along the bond, and U(r0) = 0."""
    r = np.linspace(0.93, 1.07, 29)

    def bond(r, normalize):
        r_bc = np.column_stack([r, 0 * r, 0 * r])
        return spring_bonds(r_bc, None, 1.0, 2.0, 0.08, None, True, normalize)

    h = 1e-6
    for normalize in (False, True):
        res = bond(r, normalize)
        assert res.energy_x[14] == 0.0
        dU = (bond(r + h, normalize).energy_x - bond(r - h, normalize).energy_x) / (2 * h)
        # force on the first atom along +x is +dU/dr (a stretched bond pulls it)
        assert np.allclose(dU, res.f_xc[:, 0], rtol=1e-7, atol=1e-10)
        # closed form: k r0^2 (e^2/2 - e^10/(10 ec^8)), one r0 less with normalize
        e = r - 1.0
        assert np.allclose(res.energy_x, 2.0 * (e ** 2 / 2 - e ** 10 / (10 * 0.08 ** 8)),
                           rtol=1e-12, atol=1e-16)


def test_pair_law_matches_its_formula():
    r = np.array([0.2, 0.5, 0.9])
    r_pc = np.column_stack([0 * r, r, 0 * r])
    v_pc = np.column_stack([0 * r, 0.3 + 0 * r, 0 * r])  # separating
    res = spring_pairs(r_pc, v_pc, 2.0, 1.0, 0.5, )
    w = 1 - r ** 8
    expected = -2.0 * (1.0 - r) + 0.5 * w * 0.3  # along +y, on the first atom
    assert np.allclose(res.f_xc[:, 1], expected, rtol=1e-14)
    assert np.allclose(res.energy_x, (1.0 - r) ** 2, rtol=1e-14)


def test_newtons_third_law():
    atoms, _ = deformed_scene(damped=True)
    forces = atoms.get_forces()
    assert np.abs(forces.sum(axis=0)).max() < 1e-13 * np.abs(forces).max() * len(atoms)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_damping_only_removes_energy(seed):
    """Instantaneous power of the damping forces is never positive."""
    atoms, rng = multi_type_cluster(seed=seed)
    atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
    atoms.get_forces()
    atoms.positions = deform_below_breaking(atoms, rng)
    atoms.set_velocities(rng.normal(0, 0.3, atoms.positions.shape))
    atoms.get_forces()
    power = np.sum(atoms.arrays["bpm_fd_last"] * atoms.get_velocities())
    assert power <= 1e-15
    assert power < 0  # the scene has damping at work


def test_rotation_and_translation_invariance():
    atoms, _ = deformed_scene(damped=True)
    energy, forces = atoms.get_potential_energy(), atoms.get_forces()
    rot = atoms.copy()
    angle = 0.7
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    rot.positions = atoms.positions @ R.T + [10.0, -3.0, 2.5]
    rot.set_velocities(atoms.get_velocities() @ R.T + [0.2, 0.1, -0.3])  # Galilean too
    rot.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
    for name in ("bpm_x_last", "bpm_f_last", "bpm_fd_last"):
        del rot.arrays[name]
    assert rot.get_potential_energy() == pytest.approx(energy, rel=1e-12)
    assert np.allclose(rot.get_forces(), forces @ R.T, atol=1e-12)


def nve_energy_drift(dt, steps_time=20.0):
    atoms, rng = fcc_cluster(3, seed=2)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0)},
                                   pair_coeffs={(1, 1): (1.0, 1.7, 0.0)}, smooth=False)
    e0 = atoms.get_total_energy()
    drift = 0.0
    dyn = VelocityVerlet(atoms, timestep=dt)
    for _ in dyn.irun(int(round(steps_time / dt))):
        drift = max(drift, abs(atoms.get_total_energy() - e0))
    return drift, e0


def test_energy_conserved_without_damping_drift_scales_as_dt_squared():
    drift_1, e0 = nve_energy_drift(0.1)
    drift_2, _ = nve_energy_drift(0.05)
    assert drift_1 < 5e-3 * abs(e0)
    assert 3.0 < drift_1 / drift_2 < 5.0


def energy_balance(dt, time=40.0):
    """Final error of kinetic + elastic + dissipated + broken-bond energy."""
    atoms, rng = fcc_cluster(4, seed=3)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.08, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.06, 0.2)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)})

    def ledger():
        potential = atoms.get_potential_energy()
        r = atoms.calc.results
        return (atoms.get_kinetic_energy() + potential
                + r["dissipated_energy"] + r["broken_bond_energy"])

    e0 = ledger()
    VelocityVerlet(atoms, timestep=dt).run(int(round(time / dt)))
    r = atoms.calc.results
    return abs(ledger() - e0), r["dissipated_energy"], r["broken_bond_energy"], e0


def test_energy_balance_with_damping_and_breaking():
    """Hundreds of bonds break (some in compression, handing overlapping pairs
    to the contact law); the ledger closes, and better with a smaller step."""
    err_1, dissipated, released, e0 = energy_balance(0.1)
    err_2, _, _, _ = energy_balance(0.05)
    assert dissipated > 0.5 * e0 and released > 0.1 * e0  # both ledgers are at work
    assert err_1 < 0.03 * dissipated
    assert err_2 < 0.3 * err_1


def test_stress_is_strain_derivative_of_energy():
    atoms, rng = fcc_cluster(3, seed=5, pbc=True)
    ase_bpm.create_bonds(atoms, 1.25)
    coeffs = dict(bond_coeffs={1: (1.0, 0.3, 0.0)}, pair_coeffs={(1, 1): (1.0, 1.7, 0.0)})
    atoms.calc = ase_bpm.BPMSpring(**coeffs)
    atoms.get_forces()
    atoms.positions += rng.uniform(-0.05, 0.05, atoms.positions.shape)
    stress = atoms.get_stress(voigt=False)
    volume = atoms.get_volume()
    h = 1e-6
    for a, b in [(0, 0), (1, 2), (0, 1), (2, 2)]:
        energies = []
        for sign in (1, -1):
            eps = np.eye(3)
            eps[a, b] += sign * h / 2
            eps[b, a] += sign * h / 2
            probe = atoms.copy()
            probe.set_cell(atoms.cell @ eps, scale_atoms=True)
            probe.calc = ase_bpm.BPMSpring(**coeffs)
            for name in ("bpm_x_last", "bpm_f_last"):
                del probe.arrays[name]
            energies.append(probe.get_potential_energy())
        assert stress[a, b] == pytest.approx((energies[0] - energies[1]) / (2 * h * volume),
                                             rel=1e-6, abs=1e-10)


def test_coincident_particles_get_finite_forces():
    atoms = Atoms("H3", positions=[[0, 0, 0], [0, 0, 0], [0.5, 0, 0]], masses=[1, 1, 1])
    atoms.set_velocities([[0.1, 0, 0], [-0.1, 0, 0], [0, 0, 0]])
    atoms.calc = ase_bpm.BPMSpring(pair_coeffs={(1, 1): (1.0, 1.0, 1.0)})
    forces = atoms.get_forces()
    assert np.isfinite(forces).all()
    assert np.isfinite(atoms.get_potential_energy())
    assert forces[2, 0] > 0  # the third particle is still pushed away


def test_one_evaluation_per_md_step_and_refresh():
    atoms, rng = fcc_cluster(3, seed=6)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 1.0)})
    atoms.calc = calc
    calls = []
    evaluate = calc.model.evaluate
    calc.model.evaluate = lambda a, ctx: calls.append(1) or evaluate(a, ctx)
    VelocityVerlet(atoms, timestep=0.1).run(25)
    assert len(calls) == 26 and atoms.info["bpm_step"] == 25

    # only velocities change: forces are reused until refresh()
    before = atoms.get_forces()
    atoms.set_velocities(np.zeros_like(before))
    assert np.array_equal(atoms.get_forces(), before)
    calc.refresh()
    undamped_forces = atoms.get_forces()
    assert len(calls) == 27 and atoms.info["bpm_step"] == 25
    assert np.abs(undamped_forces - before).max() > 1e-6
    probe = atoms.copy()
    probe.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0)})  # no damping at all
    probe.calc.refresh()
    assert np.allclose(probe.get_forces(), undamped_forces, atol=1e-14)


def test_changes_to_types_bonds_and_atom_count_are_seen():
    atoms, rng = fcc_cluster(3, seed=7, ntypes=2)
    ase_bpm.create_bonds(atoms, 1.25)
    calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.0), 2: (5.0, 0.5, 0.0)},
                             pair_coeffs={(1, 1): (1.0, 1.7, 0.0), (2, 2): (3.0, 1.7, 0.0)})
    atoms.calc = calc
    atoms.get_forces()
    atoms.positions += rng.uniform(-0.05, 0.05, atoms.positions.shape)
    f1 = atoms.get_forces()

    atoms.arrays["type"] = 3 - atoms.arrays["type"]  # swap particle types
    f2 = atoms.get_forces()
    assert np.abs(f2 - f1).max() > 1e-3

    retyped = atoms.arrays["bond_type"].copy()  # read-only: edits replace the array
    retyped[retyped == 1] = 2
    atoms.arrays["bond_type"] = retyped
    f3 = atoms.get_forces()
    assert np.abs(f3 - f2).max() > 1e-3
    assert atoms.info["bpm_step"] == 1  # same positions: same step

    atoms += Atoms("H", positions=[atoms.positions[0] + [0.3, 0, 0]], masses=[1.0])
    atoms.arrays["type"][-1] = 1
    f4 = atoms.get_forces()
    assert len(f4) == len(f3) + 1 and np.abs(f4[-1]).max() > 0.1


def test_broken_bond_log_and_outputs():
    """A single bond pulled apart at constant speed breaks at the first step
    beyond eps_c; the log records the step and the centres."""
    atoms = Atoms("H3", positions=[[0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]], masses=[1, 1, 1])
    atoms.arrays["bonds"] = np.array(["1(1)", "2(1)", "_"])  # as lammps-data gives them
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.0)})
    atoms.get_forces()
    assert list(atoms.arrays["nbonds"]) == [1, 2, 1]
    with pytest.warns(ase_bpm.OptimiserStepWarning):  # steps by hand, the momenta kept
        for _ in range(1, 20):
            atoms.positions[2, 0] += 0.01  # the 1-2 bond stretches 1% per step
            atoms.get_forces()
    log = atoms.info["broken_bonds"]
    assert log.shape == (1, 9)
    i, j, step, x, y, z, xr, yr, zr = log[0]
    assert (i, j, step) == (1, 2, 11)  # strain 0.11 > 0.1 at step 11
    assert (x, y, z) == pytest.approx((1.555, 0, 0)) and (xr, yr, zr) == (1.5, 0, 0)
    assert list(ase_bpm.core.bonds.bond_strings(atoms)) == ["1(1)", "2(0)", "_"]
    i, j, t = ase_bpm.get_bonds(atoms, include_broken=True)
    assert (list(i), list(j), list(t)) == ([0, 1], [1, 2], [1, 0])
    assert list(atoms.arrays["nbonds"]) == [1, 1, 0]
    assert np.allclose(atoms.arrays["damage"], [0, 0.5, 1])


def test_wrapping_atoms_into_the_cell_changes_nothing():
    """Atoms that leave a periodic cell, or get wrapped back into it, feel the
    same forces and give the same stress."""
    atoms, rng = fcc_cluster(3, seed=8, pbc=True)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.3, 0.5)},
                                   pair_coeffs={(1, 1): (1.0, 1.7, 0.5)})
    atoms.positions += [2.0, -1.5, 0.7]  # many atoms now outside the cell
    before = atoms.get_forces()
    stress = atoms.get_stress()
    wrapped = atoms.copy()
    wrapped.wrap()
    assert not np.allclose(wrapped.positions, atoms.positions)
    wrapped.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.3, 0.5)},
                                     pair_coeffs={(1, 1): (1.0, 1.7, 0.5)})
    wrapped.calc.refresh()
    assert np.allclose(wrapped.get_forces(), before, atol=1e-12)
    assert np.allclose(wrapped.get_stress(), stress, atol=1e-12)


def test_stress_asked_for_late_or_every_step_is_the_same_and_changes_nothing():
    """Stress is computed only when asked for; asking (at once, later, or from a
    fresh calculator at a restored state) neither changes the trajectory nor
    the value."""
    def run(ask_every_step):
        atoms, rng = fcc_cluster(3, seed=9, pbc=True)
        ase_bpm.create_bonds(atoms, 1.25)
        atoms.set_velocities(rng.normal(0, 0.1, atoms.positions.shape))
        atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.3, 0.5)},
                                       pair_coeffs={(1, 1): (1.0, 1.7, 0.5)})
        stresses = []
        dyn = VelocityVerlet(atoms, timestep=0.1)
        if ask_every_step:
            dyn.attach(lambda: stresses.append(atoms.get_stress()), interval=1)
        dyn.run(20)
        return atoms, atoms.get_stress(), stresses

    quiet, late_stress, _ = run(False)
    watched, stress, every = run(True)
    assert np.array_equal(quiet.positions, watched.positions)
    assert np.array_equal(late_stress, stress) and np.array_equal(every[-1], stress)
    fresh = quiet.copy()
    fresh.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.3, 0.5)},
                                   pair_coeffs={(1, 1): (1.0, 1.7, 0.5)})
    del fresh.info["bpm_stress"]
    assert np.array_equal(fresh.get_forces(), quiet.get_forces())  # the record
    recomputed = fresh.get_stress()  # from a fresh evaluation, velocities of now: close
    assert np.allclose(recomputed, stress, rtol=0.05, atol=1e-6)


@pytest.mark.parametrize("normalize", [False, True])
def test_over_stretched_bond_without_breaking_keeps_acting(normalize):
    """``break_bonds=False`` is LAMMPS ``break no``: a bond at twice its
    critical strain, in a step, still pulls with ``k (r - r0)`` (``k e`` with
    normalize) and stays; in a pure evaluation too."""
    atoms = Atoms("H2", positions=[[0, 0, 0], [1, 0, 0]], masses=[1, 1])
    ase_bpm.create_bonds(atoms, 1.1)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (2.0, 0.1, 0.0)}, smooth=False,
                                   normalize=normalize, break_bonds=False)
    atoms.get_forces()  # r0 = 1
    atoms.positions[1, 0] = 1.2  # strain 0.2, eps_c 0.1
    expected = 2.0 * 0.2
    for pure in (False, True):
        with ase_bpm.pure(atoms) if pure else contextlib.nullcontext():
            forces = atoms.get_forces()
            assert forces[0] == pytest.approx([expected, 0, 0], rel=1e-14)
            assert forces[1] == pytest.approx([-expected, 0, 0], rel=1e-14)
            assert atoms.get_potential_energy() == pytest.approx(
                0.5 * 2.0 * 0.2 ** 2, rel=1e-14)
    assert atoms.info["bpm_step"] == 1
    assert len(ase_bpm.get_bonds(atoms)[0]) == 1 and atoms.arrays["nbonds"].tolist() == [1, 1]
    assert len(atoms.info.get("broken_bonds", [])) == 0
    assert atoms.info.get("bpm_broken_bond_energy", 0.0) == 0.0
