"""bond_style bpm/rotational on the compiled route (c/rotational.c) against
the NumPy law (ase_bpm/laws/rotational.py), the reference.

From the same state (positions, orientations, velocities, spins, reference
lengths and directions) the two give the same forces, torques, damping
parts, stress and ledger to 1e-12 of the largest magnitude of each, and break
the same bonds; trajectories under SphereVelocityVerlet agree to round-off.
The oracle tests (test_rotational_oracle.py) hold both routes to LAMMPS.

Why the same reference state: near its reference direction a bond's shear
angle is ``acos`` of a number within ~1e-8 of 1, where a difference of one
unit in the last place of a reference length (the NumPy machinery sums a
length in another order than C) moves the angle by ~1e-12.  Each route takes
its own reference state in :func:`test_each_route_takes_the_same_reference_state`.
"""

import numpy as np
import pytest

import ase_bpm
from ase_bpm import SphereVelocityVerlet
from ase_bpm.core.quaternions import multiply, normalised
from ase_bpm.laws.bond import LAWS, register
from ase_bpm.laws.rotational import REFERENCE_DIRECTION, RotationalBond
from scenes import fcc_cluster

#: (scenes turned a little before their bonds take the reference state)
pytestmark = [pytest.mark.compiled,
              pytest.mark.filterwarnings("ignore::ase_bpm.RotatedReferenceWarning")]

RELATIVE = 1e-12
#: k_r k_s k_t k_b f_rc f_sc tau_tc tau_bc gamma_n gamma_s gamma_r gamma_t
SOFT = (1.0, 0.6, 0.05, 0.08, 0.08, 0.05, 0.012, 0.02, 0.3, 0.2, 0.02, 0.01)
STIFF = (1.5, 1.0, 0.1, 0.12, 0.12, 0.07, 0.02, 0.03, 0.1, 0.05, 0.01, 0.03)
DAMPED = {1: ("bpm/rotational",) + SOFT, 2: ("bpm/rotational",) + STIFF}
UNDAMPED = {t: c[:9] + (0.0,) * 4 for t, c in DAMPED.items()}
PAIRS = {(1, 1): (1.0, 1.0, 0.5), (2, 2): (1.0, 1.1, 0.3)}
DIRECTION = "bond_" + REFERENCE_DIRECTION


def close(ours, reference, what):
    """``ours`` within RELATIVE of ``reference``, relative to its largest magnitude."""
    ours, reference = np.asarray(ours), np.asarray(reference)
    scale = max(np.abs(reference).max(initial=0.0), 1e-300)
    error = np.abs(ours - reference).max(initial=0.0) / scale
    assert error <= RELATIVE, f"{what}: relative difference {error:.3g}"


def turns(rng, n, angle):
    """Unit quaternions of random axes turned by up to ``angle`` radians."""
    axis_nc = rng.normal(size=(n, 3))
    axis_nc /= np.linalg.norm(axis_nc, axis=1)[:, None]
    half_n = 0.5 * rng.uniform(0, angle, n)
    return np.column_stack([np.cos(half_n), axis_nc * np.sin(half_n)[:, None]])


def cluster(cell="open", seed=3):
    """A jittered FCC block of spheres of two types, nearest neighbours
    bonded (two bond types), turned a little, moving and spinning: in an
    open box, or periodic (bonds across the cell) in an orthorhombic or a
    sheared cell."""
    atoms, rng = fcc_cluster(3, seed=seed, pbc=cell != "open", ntypes=2)
    if cell == "triclinic":
        cell_cc = atoms.cell.array.copy()
        cell_cc[2, 0] += 0.3 * cell_cc[2, 2]
        atoms.set_cell(cell_cc, scale_atoms=True)
    atoms.arrays["radius"] = np.where(atoms.arrays["type"] == 1, 0.5, 0.55)
    ase_bpm.create_bonds(atoms, 1.25, bond_type=2, mask=atoms.arrays["type"] == 2)
    ase_bpm.create_bonds(atoms, 1.25, bond_type=1)  # (the pairs not bonded yet)
    atoms.arrays["quat"] = turns(rng, len(atoms), 0.03)
    atoms.arrays["omega"] = rng.normal(0, 0.05, (len(atoms), 3))
    atoms.set_velocities(rng.normal(0, 0.05, (len(atoms), 3)))
    return atoms


def calculator(route, bond_coeffs=DAMPED, **options):
    return ase_bpm.BPMSpring(bond_coeffs=bond_coeffs, pair_coeffs=PAIRS, kernels=route,
                             guard=False, **options)


def referenced(atoms, bond_coeffs=DAMPED, **options):
    """``atoms`` with the reference state taken (lengths and directions, on
    the NumPy route), for both routes to start from."""
    atoms = atoms.copy()
    atoms.calc = calculator("numpy", bond_coeffs, **options)
    atoms.get_forces()
    types_nw = atoms.arrays["bond_type"]
    direction_nwc = atoms.arrays[DIRECTION].reshape(types_nw.shape + (4,))
    rotational_nw = np.isin(types_nw, [t for t, c in bond_coeffs.items()
                                       if c[0] != "bpm/spring"])
    assert rotational_nw.any() and not np.isnan(direction_nwc[rotational_nw]).any()
    return atoms


def moved(atoms, rng, shift, angle):
    """Positions moved, orientations turned further, new velocities and spins."""
    atoms.positions = atoms.positions + rng.normal(0, shift, atoms.positions.shape)
    atoms.arrays["quat"] = normalised(multiply(turns(rng, len(atoms), angle),
                                               atoms.arrays["quat"]))
    atoms.arrays["omega"] = rng.normal(0, 0.1, atoms.positions.shape)
    atoms.set_velocities(rng.normal(0, 0.1, atoms.positions.shape))


def both_routes(start, moves, bond_coeffs=DAMPED, **options):
    """Copies of ``start`` (its reference state taken) on each route, each
    taken through the ``moves`` (``(shift, angle)``, the same random ones on
    both), each a step; the atoms by route."""
    out = {}
    for route in ("numpy", "compiled"):
        atoms = start.copy()
        atoms.calc = calculator(route, bond_coeffs, **options)
        rng = np.random.default_rng(11)
        for shift, angle in moves:
            moved(atoms, rng, shift, angle)
            atoms.get_forces()
        out[route] = atoms
    return out


def compare(routes):
    """Every output of the two routes, alike: forces, torques and their
    damping parts, stress, the ledger, reference state, broken bonds."""
    ref, ours = routes["numpy"], routes["compiled"]
    close(ours.get_forces(), ref.get_forces(), "forces")
    close(ours.calc.results["torques"], ref.calc.results["torques"], "torques")
    close(ours.get_potential_energy(), ref.get_potential_energy(), "energy (of contacts)")
    if ref.pbc.any():
        close(ours.get_stress(), ref.get_stress(), "stress")
    for name in ("bpm_fd_last", "bpm_td_last"):  # the damping parts
        assert (name in ours.arrays) == (name in ref.arrays), name
        if name in ref.arrays:
            close(ours.arrays[name], ref.arrays[name], name)
    for name in ("bpm_dissipated_energy", "bpm_broken_bond_energy"):
        close(ours.info.get(name, 0.0), ref.info.get(name, 0.0), name)
    for name in ("bond_r0", DIRECTION):
        close(np.nan_to_num(ours.arrays[name]), np.nan_to_num(ref.arrays[name]), name)
    assert np.array_equal(ours.arrays["bond_type"], ref.arrays["bond_type"])  # same broken
    assert np.array_equal(ours.arrays["nbonds"], ref.arrays["nbonds"])
    log_ref = ref.info.get("broken_bonds", np.zeros((0, 9)))
    log_ours = ours.info.get("broken_bonds", np.zeros((0, 9)))
    assert np.array_equal(log_ours[:, :3], log_ref[:, :3])  # atoms and steps
    if len(log_ref):
        close(log_ours, log_ref, "broken-bond log")


OPTIONS = [dict(), dict(smooth=False), dict(normalize=True), dict(smooth=False, normalize=True),
           dict(smooth=False, break_bonds=False), dict(overlay_pair=True)]


@pytest.mark.parametrize("cell", ["open", "orthorhombic", "triclinic"])
@pytest.mark.parametrize("damped", [True, False], ids=["damped", "undamped"])
@pytest.mark.parametrize("options", OPTIONS, ids=lambda o: ",".join(o) or "default")
def test_same_outputs_from_the_same_state(cell, damped, options):
    """Three steps that stretch, shear, bend and twist the bonds, some of
    them (with breaking on) past their breaking measure."""
    coeffs = DAMPED if damped else UNDAMPED
    start = referenced(cluster(cell), coeffs, **options)
    routes = both_routes(start, [(0.005, 0.02), (0.01, 0.05), (0.01, 0.1)], coeffs, **options)
    assert routes["compiled"].calc.kernel_routes == {"bpm/rotational": "compiled",
                                                     "contacts": "compiled"}
    assert np.abs(routes["numpy"].calc.results["torques"]).max() > 1e-3
    if options.get("break_bonds", True):
        broken = len(routes["numpy"].info.get("broken_bonds", []))
        assert 0 < broken < len(ase_bpm.get_bonds(start)[0])
    compare(routes)


def test_each_route_takes_the_same_reference_state():
    """Without a reference state, each route takes its own at the first
    evaluation: the same lengths and directions (to the last bits of a
    length), and forces that agree as far as the shear angle's condition
    near the reference direction allows (see the module docstring)."""
    atoms = cluster()
    routes = {}
    for route in ("numpy", "compiled"):
        routes[route] = atoms.copy()
        routes[route].calc = calculator(route)
        routes[route].get_forces()
    ref, ours = routes["numpy"], routes["compiled"]
    assert np.array_equal(np.isnan(ours.arrays[DIRECTION]), np.isnan(ref.arrays[DIRECTION]))
    for name in ("bond_r0", DIRECTION):
        difference = np.nan_to_num(ours.arrays[name] - ref.arrays[name])
        assert np.abs(difference).max() <= 4e-16 * np.nanmax(np.abs(ref.arrays[name]))
    scale = np.abs(ref.get_forces()).max()
    assert np.abs(ours.get_forces() - ref.get_forces()).max() <= 1e-9 * scale


def test_pure_evaluations_alike():
    """Inside ase_bpm.pure, bonds past their breaking measure act broken on
    both routes and stay on the atoms."""
    start = referenced(cluster())
    out = {}
    for route in ("numpy", "compiled"):
        atoms = start.copy()
        atoms.calc = calculator(route)
        atoms.get_forces()
        with ase_bpm.pure(atoms):
            moved(atoms, np.random.default_rng(5), 0.02, 0.2)
            out[route] = (atoms.get_forces(), atoms.calc.results["torques"])
        assert np.array_equal(atoms.arrays["bond_type"], start.arrays["bond_type"])
    close(out["compiled"][0], out["numpy"][0], "forces")
    close(out["compiled"][1], out["numpy"][1], "torques")
    # (past the breaking measure: the forces differ from those of every bond acting)
    atoms = start.copy()
    atoms.calc = calculator("numpy", smooth=False, break_bonds=False)
    atoms.get_forces()
    with ase_bpm.pure(atoms):
        moved(atoms, np.random.default_rng(5), 0.02, 0.2)
        assert np.abs(atoms.get_forces() - out["numpy"][0]).max() > 1e-3


#: trajectories: how many times further the two routes may drift apart than
#: two runs of the NumPy route whose initial velocities differ in the last
#: place (the round-off floor: the shear angle's condition near the
#: reference direction amplifies round-off); measured, the routes drift
#: apart by 0.5 to 1.5 times the floor
FLOOR_FACTOR = 10.0


@pytest.mark.parametrize("coeffs", [DAMPED, UNDAMPED], ids=["damped", "undamped"])
def test_trajectories_agree(coeffs):
    """300 steps of SphereVelocityVerlet on each route, bonds breaking along
    the way: positions, velocities, spins and orientations agree as far as
    round-off lets two runs of one route agree (measured, relative to the
    largest: positions 5e-13 and 1.7e-12, velocities 4e-12 and 5e-12, spins
    1.9e-11 and 3.8e-11, orientations 1.2e-12 and 6.7e-11, damped and
    undamped; the NumPy route drifts from itself as far), and the same bonds
    break at the same steps."""
    start = referenced(cluster(seed=4), coeffs)
    runs = {}
    for route, nudge in (("numpy", 0.0), ("compiled", 0.0), ("numpy", 2.0 ** -52)):
        atoms = start.copy()
        atoms.calc = calculator(route, coeffs)
        atoms.set_velocities(start.get_velocities() * (1.0 + nudge))
        SphereVelocityVerlet(atoms, timestep=0.1).run(300)
        runs[route, nudge] = atoms
    ref, ours, nudged = runs["numpy", 0.0], runs["compiled", 0.0], runs["numpy", 2.0 ** -52]

    def outputs(atoms):
        return {"positions": atoms.positions, "velocities": atoms.get_velocities(),
                "spins": atoms.arrays["omega"], "orientations": atoms.arrays["quat"]}

    def drift(a, b):
        return np.abs(a - b).max() / np.abs(b).max()

    for name, reference in outputs(ref).items():
        floor = max(drift(outputs(nudged)[name], reference), 1e-15)
        assert drift(outputs(ours)[name], reference) <= FLOOR_FACTOR * floor, name
    assert np.abs(ref.arrays["quat"][:, 1:]).max() > 0.05  # they turned
    broken = ref.info["broken_bonds"]
    assert len(broken) > 5
    assert np.array_equal(ours.info["broken_bonds"][:, :3], broken[:, :3])


def test_beside_a_law_on_numpy():
    """A bond type whose law runs on NumPy (no compiled twin) beside
    bpm/rotational running compiled: the forces and torques of both parts
    add up as with every law on NumPy."""
    class OnNumpy(RotationalBond):
        name = "test-rotational-on-numpy"
        compiled = False

    register(OnNumpy)
    try:
        coeffs = {1: DAMPED[1], 2: (OnNumpy.name,) + STIFF}
        start = referenced(cluster(), coeffs)
        routes = both_routes(start, [(0.005, 0.02), (0.01, 0.1)], coeffs)
        assert routes["compiled"].calc.kernel_routes == {
            "bpm/rotational": "compiled", OnNumpy.name: "numpy", "contacts": "compiled"}
        compare(routes)
    finally:
        LAWS.pop(OnNumpy.name)


def test_beside_bpm_spring():
    """bpm/spring bonds (type 1) beside bpm/rotational (type 2), both
    compiled: one pass each into the same sums, bonds of both breaking."""
    coeffs = {1: ("bpm/spring", 1.0, 0.02, 0.5), 2: DAMPED[2]}
    start = referenced(cluster(), coeffs)
    routes = both_routes(start, [(0.005, 0.02), (0.01, 0.05), (0.01, 0.1)], coeffs)
    assert routes["compiled"].calc.kernel_routes == {
        "bpm/spring": "compiled", "bpm/rotational": "compiled", "contacts": "compiled"}
    log = routes["numpy"].info["broken_bonds"]
    types = {int(t) for t in ase_bpm.get_bonds(start)[2][
        [k for k, (i, j) in enumerate(zip(*ase_bpm.get_bonds(start)[:2]))
         if (min(i, j), max(i, j)) in {(int(a), int(b)) for a, b in log[:, :2]}]]}
    assert types == {1, 2}  # bonds of both laws broke
    compare(routes)
