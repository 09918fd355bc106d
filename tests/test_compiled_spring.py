"""BPMSpring on the compiled route against the NumPy route, the reference.

On the same configuration the two give the same forces, damping forces,
energy, stress and ledger to 1e-12 relative to the largest magnitude of
each, the same reference lengths and the same broken bonds; trajectories
agree over a short horizon (round-off grows later in chaotic scenes).  Both
routes are checked against LAMMPS by the oracle tests, which CI runs on each.
"""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.laws import compiled
from scenes import MULTI_TYPE_COEFFS, fcc_cluster, multi_type_cluster

pytestmark = pytest.mark.compiled

RELATIVE = 1e-12


def close(ours, reference, what):
    """``ours`` within RELATIVE of ``reference``, relative to its largest magnitude."""
    ours, reference = np.asarray(ours), np.asarray(reference)
    scale = max(np.abs(reference).max(initial=0.0), 1e-300)
    error = np.abs(ours - reference).max(initial=0.0) / scale
    assert error <= RELATIVE, f"{what}: relative difference {error:.3g}"


def bonded_scene(cell: str, seed: int = 0):
    """The multi-type cluster in an open box, or a jittered bonded FCC block in
    an orthorhombic or a sheared (triclinic) periodic cell, bonds across it."""
    if cell == "open":
        atoms, _ = multi_type_cluster(seed)
        return atoms
    atoms, rng = fcc_cluster(4, seed=seed, pbc=True, ntypes=3)
    if cell == "triclinic":
        cell_cc = atoms.cell.array.copy()
        cell_cc[2, 0] += 0.3 * cell_cc[2, 2]
        atoms.set_cell(cell_cc, scale_atoms=True)
    ase_bpm.create_bonds(atoms, 1.25, bond_type=1, mask=atoms.arrays["type"] != 3)
    ase_bpm.create_bonds(atoms, 1.25, bond_type=2)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    return atoms


def two_routes(atoms, steps=(), compiled_twins=True, **params):
    """Copies of ``atoms`` evaluated on each route: the first evaluation (which
    takes the reference lengths), then each displacement of ``steps`` as a
    step.  Returns the atoms by route.  ``compiled_twins``: whether the
    bonds' laws all have compiled kernels (else NumPy runs on both routes)."""
    out = {}
    for route in ("numpy", "compiled"):
        a = atoms.copy()
        a.calc = ase_bpm.BPMSpring(**params, kernels=route, guard=False)
        a.get_forces()
        for dx in steps:
            a.positions = a.positions + dx
            a.get_forces()
        assert a.calc.runs_compiled(a.calc.model._bond_state.current) == (
            route == "compiled" and compiled_twins)
        out[route] = a
    return out


def compare(atoms_by_route):
    """Every output the two routes give, alike."""
    ref, ours = atoms_by_route["numpy"], atoms_by_route["compiled"]
    close(ours.get_forces(), ref.get_forces(), "forces")
    close(ours.get_potential_energy(), ref.get_potential_energy(), "energy")
    if ref.pbc.any():
        close(ours.get_stress(), ref.get_stress(), "stress")
    for name in ("bpm_fd_last",):  # the damping part of the forces
        if name in ref.arrays:
            close(ours.arrays[name], ref.arrays[name], name)
    for name in ("bpm_dissipated_energy", "bpm_broken_bond_energy"):
        close(ours.info.get(name, 0.0), ref.info.get(name, 0.0), name)
    close(np.nan_to_num(ours.arrays["bond_r0"]), np.nan_to_num(ref.arrays["bond_r0"]),
          "reference lengths")
    assert np.array_equal(ours.arrays["bond_type"], ref.arrays["bond_type"])  # same broken
    assert np.array_equal(ours.arrays["nbonds"], ref.arrays["nbonds"])
    log_ref = ref.info.get("broken_bonds", np.zeros((0, 9)))
    log_ours = ours.info.get("broken_bonds", np.zeros((0, 9)))
    assert log_ours.shape == log_ref.shape
    if len(log_ref):
        close(log_ours, log_ref, "broken-bond log")


OPTIONS = [dict(), dict(smooth=False), dict(normalize=True), dict(overlay_pair=True),
           dict(smooth=False, break_bonds=False), dict(undamped=True)]


def coefficients(undamped=False, **options):
    coeffs = {key: dict(value) for key, value in MULTI_TYPE_COEFFS.items()}
    if undamped:
        coeffs = {key: {t: c[:2] + (0.0,) for t, c in value.items()}
                  for key, value in coeffs.items()}
    return {**coeffs, **options}


@pytest.mark.parametrize("cell", ["open", "orthorhombic", "triclinic"])
@pytest.mark.parametrize("options", OPTIONS, ids=lambda o: ",".join(o) or "default")
def test_same_outputs_on_the_same_configurations(cell, options):
    atoms = bonded_scene(cell)
    rng = np.random.default_rng(1)
    steps = [rng.normal(0, 0.01, atoms.positions.shape) for _ in range(3)]
    with pytest.warns(ase_bpm.OptimiserStepWarning):  # steps by hand, the momenta kept
        routes = two_routes(atoms, steps, **coefficients(**options))
    compare(routes)


@pytest.mark.parametrize("cell", ["open", "orthorhombic"])
def test_the_same_bonds_break_with_the_same_record(cell):
    """A pull large enough that a share of the bonds break in one step."""
    atoms = bonded_scene(cell, seed=2)
    rng = np.random.default_rng(3)
    routes = two_routes(atoms, [rng.normal(0, 0.06, atoms.positions.shape)],
                        **coefficients())
    broken = len(routes["numpy"].info.get("broken_bonds", []))
    assert 0 < broken < len(ase_bpm.get_bonds(atoms)[0])
    compare(routes)


def test_pure_evaluations_alike():
    """Inside ase_bpm.pure, bonds past eps_c act broken on both routes and
    stay on the atoms."""
    atoms = bonded_scene("open", seed=2)
    forces = {}
    for route in ("numpy", "compiled"):
        a = atoms.copy()
        a.calc = ase_bpm.BPMSpring(**coefficients(), kernels=route, guard=False)
        a.get_forces()
        with ase_bpm.pure(a):
            a.positions = a.positions + np.random.default_rng(3).normal(0, 0.06,
                                                                        a.positions.shape)
            forces[route] = (a.get_forces(), a.get_potential_energy())
        assert "broken_bonds" not in a.info or len(a.info["broken_bonds"]) == 0
    close(forces["compiled"][0], forces["numpy"][0], "forces")
    close(forces["compiled"][1], forces["numpy"][1], "energy")


def test_trajectories_agree_over_a_short_horizon():
    """200 steps of the damped multi-type cluster with contacts and breaking:
    positions within 1e-10 of the lattice spacing."""
    atoms = bonded_scene("open", seed=4)
    atoms.set_velocities(np.random.default_rng(5).normal(0, 0.3, atoms.positions.shape))
    finals = {}
    for route in ("numpy", "compiled"):
        a = atoms.copy()
        a.calc = ase_bpm.BPMSpring(**coefficients(), kernels=route, guard=False)
        VelocityVerlet(a, timestep=0.02).run(200)
        finals[route] = a
    assert len(finals["numpy"].info.get("broken_bonds", [])) > 0
    assert np.abs(finals["compiled"].positions - finals["numpy"].positions).max() < 1e-10
    assert np.array_equal(finals["compiled"].arrays["bond_type"],
                          finals["numpy"].arrays["bond_type"])


def test_a_law_without_a_compiled_twin_runs_numpy_on_either_route():
    """A bond type of a law with no compiled kernel keeps every bond of the
    model on the NumPy route, with the same results."""
    from ase_bpm.laws.bond import LAWS, BondForces, BondLaw, register

    class Linear(BondLaw):  # a harmonic bond that never breaks
        name = "test-linear"
        coefficients = ("k",)
        positive = ("k",)

        def forces(self, bonds):
            return BondForces(bonds.coeff["k"] * (bonds.r_b - bonds.r0_b),
                              0.5 * bonds.coeff["k"] * (bonds.r_b - bonds.r0_b) ** 2,
                              np.zeros(len(bonds.r_b), dtype=bool))

    register(Linear)
    try:
        atoms = bonded_scene("open")
        coeffs = coefficients()
        coeffs["bond_coeffs"][2] = ("test-linear", 2.0)
        rng = np.random.default_rng(1)
        routes = two_routes(atoms, [rng.normal(0, 0.01, atoms.positions.shape)],
                            compiled_twins=False, **coeffs)
    finally:
        del LAWS["test-linear"]
    compare(routes)


def test_the_kernels_parameter_is_checked():
    with pytest.raises(ValueError, match="kernels must be 'auto', 'compiled' or 'numpy'"):
        ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.0)}, kernels="fast")


def test_an_output_array_of_another_type_is_refused_not_written_past():
    """The kernels write into the arrays they are given: a float32 force
    array (or a read-only one) raises instead of being written out of bounds
    or into a copy that is then lost."""
    x_nc = np.array([[0.0, 0.0, 0.0], [1.1, 0.0, 0.0]])
    args = (np.array([0]), np.array([1]), np.zeros((1, 3)), None, np.array([1, 1]),
            np.ones((2, 2, 3)), x_nc, None, False)
    with pytest.raises(ValueError, match="write into the forces.*float64, not float32"):
        compiled.spring_pairs(*args, np.zeros((2, 3), dtype=np.float32), None, np.zeros(11))
    frozen = np.zeros(11)
    frozen.flags.writeable = False
    with pytest.raises(ValueError, match="the totals.*writable False"):
        compiled.spring_pairs(*args, np.zeros((2, 3)), None, frozen)
    f_nc, totals_t = np.zeros((2, 3)), np.zeros(11)
    assert compiled.spring_pairs(*args, f_nc, None, totals_t) == 0  # 1.1 > r_c = 1: apart


def test_pairs_without_shifts_give_what_zero_shifts_give():
    """A neighbour list built in an open box keeps no shifts (None): the
    pair kernel gives bit for bit what it gives with zero shifts."""
    rng = np.random.default_rng(4)
    x_nc = rng.uniform(0.0, 4.0, (200, 3))
    v_nc = rng.normal(0.0, 0.1, x_nc.shape)
    i_p, j_p, shift_pc = ase_bpm.core.neighbours.neighbour_pairs(x_nc, np.eye(3) * 4,
                                                            [False] * 3, 1.3)
    types_n = np.ones(len(x_nc), dtype=np.int64)
    coeff_ttc = np.ones((2, 2, 3))
    outputs = []
    for shifts in (shift_pc, None):
        f_nc, fd_nc, totals_t = np.zeros_like(x_nc), np.zeros_like(x_nc), np.zeros(11)
        touching = compiled.spring_pairs(i_p, j_p, shifts, None, types_n, coeff_ttc, x_nc,
                                         v_nc, True, f_nc, fd_nc, totals_t)
        outputs.append((touching, f_nc, fd_nc, totals_t))
    assert outputs[0][0] > 50
    assert outputs[1][0] == outputs[0][0]
    for ours, reference in zip(outputs[1][1:], outputs[0][1:]):
        assert np.array_equal(ours, reference)
