"""A term that is switched off costs nothing: its code path is not entered.
Counted calls, on the NumPy route and on the compiled one, never timings."""

import pytest

import numpy as np

import ase_bpm
import ase_bpm.core.neighbours as neighbours
import ase_bpm.core.spheres as spheres
import ase_bpm.laws.granular as granular_laws
import ase_bpm.laws.peri as peri_laws
import ase_bpm.laws.spring as spring_laws
import ase_bpm.models.spring as spring_model
from ase_bpm.core.arrays import Inputs
from ase_bpm.laws import compiled
from ase_bpm import SphereVelocityVerlet, VelocityVerlet
from ase_bpm.models.bonded import BondSet
from scenes import fcc_cluster, peri_model, sc_block, sphere_pile

STEPS = 5


class Calls:
    """Counts the calls of ``owner.name`` (and what each was given)."""

    def __init__(self, monkeypatch, owner, name):
        self.count, self.args = 0, []
        inner = getattr(owner, name)

        def counted(*args, **kwargs):
            self.count += 1
            self.args.append((args, kwargs))
            return inner(*args, **kwargs)
        monkeypatch.setattr(owner, name, counted)


def block(kernels="numpy", **coeffs):
    """A few steps of a small bonded block (the blow-up guard off: its
    stable-timestep check reads the bonds once more)."""
    atoms, rng = fcc_cluster(2, seed=4)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(**coeffs, guard=False, kernels=kernels)
    VelocityVerlet(atoms, timestep=0.05).run(STEPS)
    return atoms


@pytest.mark.parametrize("pairs", [False, True])
def test_no_contact_search_without_pair_coefficients(pairs, monkeypatch):
    search = Calls(monkeypatch, neighbours, "neighbour_pairs")
    block(bond_coeffs={1: (1.0, 0.5, 0.0)},
          **({"pair_coeffs": {(1, 1): (1.0, 1.0, 0.0)}} if pairs else {}))
    assert (search.count > 0) == pairs


@pytest.mark.parametrize("gamma", [0.0, 1.0])
def test_no_damping_work_when_gamma_is_zero(gamma, monkeypatch):
    gathers = Calls(monkeypatch, BondSet, "vectors")  # x or v at j minus at i, per bond
    contacts = Calls(monkeypatch, spring_model, "contact_forces")
    block(bond_coeffs={1: (1.0, 0.5, gamma)}, pair_coeffs={(1, 1): (1.0, 1.0, gamma)})
    evaluations = contacts.count
    assert evaluations == STEPS + 1
    # positions only, or positions and velocities, in each evaluation
    assert gathers.count == evaluations * (2 if gamma else 1)
    velocities_given = [args[7] is not None for args, _ in contacts.args]
    assert all(velocities_given) if gamma else not any(velocities_given)


@pytest.mark.compiled
@pytest.mark.parametrize("gamma", [0.0, 1.0])
def test_no_damping_work_when_gamma_is_zero_compiled(gamma, monkeypatch):
    """On the compiled route the kernels get the velocities only with damping
    (and then compute the damping part), and no NumPy gather runs at all."""
    gathers = Calls(monkeypatch, BondSet, "vectors")
    # the kernels as made ready per bond set and list: each call's arguments
    # follow the kernel itself
    bonds = Calls(monkeypatch, compiled.SpringBonds, "__call__")
    pairs = Calls(monkeypatch, compiled.SpringPairs, "__call__")
    block("compiled", bond_coeffs={1: (1.0, 0.5, gamma)},
          pair_coeffs={(1, 1): (1.0, 1.0, gamma)})
    assert bonds.count == pairs.count == STEPS + 1
    assert gathers.count == 0
    bond_velocities = [args[1].v_nc is not None for args, _ in bonds.args]
    pair_velocities = [args[4] is not None for args, _ in pairs.args]
    for given in (bond_velocities, pair_velocities):
        assert all(given) if gamma else not any(given)


@pytest.mark.parametrize("model", ["pmb", "lps"])
def test_no_dilatation_for_the_bond_based_model(model, monkeypatch):
    from test_properties import scene

    monkeypatch.setenv("ASE_BPM_KERNELS", "numpy")  # kernels="auto" of the scene
    dilatations = Calls(monkeypatch, peri_laws, "dilatation")
    atoms = scene(model, seed=0)  # evaluated at the lattice, then jittered
    atoms.get_forces()
    assert (dilatations.count > 0) == (model == "lps")


@pytest.mark.compiled
@pytest.mark.parametrize("model", ["pmb", "lps"])
def test_no_dilatation_for_the_bond_based_model_compiled(model, monkeypatch):
    """On the compiled route the node pass sums dilatations only for the
    state-based model (it runs for pmb only at the setup, to take the
    reference lengths and weighted volumes)."""
    from test_properties import scene

    monkeypatch.setenv("ASE_BPM_KERNELS", "compiled")
    passes = Calls(monkeypatch, compiled, "peri_nodes")
    atoms = scene(model, seed=0)
    atoms.get_forces()
    dilatations = [kwargs.get("dilatation", False) for _, kwargs in passes.args]
    assert dilatations.count(True) == (2 if model == "lps" else 0)  # setup, then the step
    assert len(dilatations) == dilatations.count(True) + 2  # lengths, weighted volumes


def stretched_peri_block(break_bonds: bool, s00: float = 0.0005, kernels: str = "numpy"):
    """A pmb block pulled apart from its centre for a few steps: past the
    critical stretch ``s00`` within them (the guard off, as in :func:`block`)."""
    atoms = sc_block(4)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb", s00=s00)},
                                 break_bonds=break_bonds, guard=False, kernels=kernels)
    atoms.get_forces()  # reference lengths
    atoms.set_velocities(2e3 * (atoms.positions - atoms.positions.mean(axis=0)))
    VelocityVerlet(atoms, timestep=1e-7).run(STEPS)
    return atoms


@pytest.mark.parametrize("breaking", [False, True])
def test_no_breaking_test_when_breaking_is_off(breaking, monkeypatch):
    """BPMSpring: eps_c is tested in each step with breaking on (not in the
    setup evaluation, where nothing breaks), never with it off."""
    tests = Calls(monkeypatch, spring_laws, "past_eps_c")
    block(bond_coeffs={1: (1.0, 0.5, 0.0)}, smooth=breaking, break_bonds=breaking)
    assert tests.count == (STEPS if breaking else 0)


@pytest.mark.compiled
@pytest.mark.parametrize("breaking", [False, True])
def test_no_breaking_test_when_breaking_is_off_compiled(breaking, monkeypatch):
    """The same on the compiled route: the kernel is asked for the test in
    each step with breaking on, never with it off."""
    calls = Calls(monkeypatch, compiled.SpringBonds, "__call__")
    block("compiled", bond_coeffs={1: (1.0, 0.5, 0.0)}, smooth=breaking,
          break_bonds=breaking)
    assert calls.count == STEPS + 1
    assert sum(args[1].breaking for args, _ in calls.args) == (STEPS if breaking else 0)


@pytest.mark.parametrize("breaking", [False, True])
def test_no_parks_test_nor_its_history_when_breaking_is_off(breaking, monkeypatch):
    """BPMPeri: neither Parks' test nor the smallest stretch it needs from
    the step before; with breaking on, both, and bonds past it break."""
    tests = Calls(monkeypatch, peri_laws, "past_critical_stretch")
    minima = Calls(monkeypatch, BondSet, "node_min")  # s_min per node
    atoms = stretched_peri_block(breaking)
    assert tests.count == (STEPS if breaking else 0)
    assert minima.count == (STEPS + 1 if breaking else 0)  # + the setup's
    broken = len(atoms.info.get("broken_bonds", []))
    assert (broken > 0) == breaking
    assert ("peri_smin" in atoms.arrays) == breaking


@pytest.mark.compiled
@pytest.mark.parametrize("breaking", [False, True])
def test_no_parks_test_nor_its_history_when_breaking_is_off_compiled(breaking, monkeypatch):
    """The same on the compiled route: the kernel is asked for Parks' test
    in each step with breaking on, and keeps the smallest stretches only
    then; no NumPy stretch, test or minimum runs."""
    kernels = Calls(monkeypatch, compiled, "peri_bonds")
    numpy_parts = [Calls(monkeypatch, peri_laws, "past_critical_stretch"),
                   Calls(monkeypatch, peri_laws, "extension"),
                   Calls(monkeypatch, BondSet, "node_min"), Calls(monkeypatch, BondSet, "vectors")]
    atoms = stretched_peri_block(breaking, kernels="compiled")
    assert kernels.count == STEPS + 1  # + the setup's
    scenes = [args[1] for args, _ in kernels.args]
    assert sum(scene.breaking for scene in scenes) == (STEPS if breaking else 0)
    kept = [scene.nodes.smin_new_n is not None for scene in scenes]
    assert kept == [breaking] * (STEPS + 1)
    assert all(calls.count == 0 for calls in numpy_parts)
    assert (len(atoms.info.get("broken_bonds", [])) > 0) == breaking
    assert ("peri_smin" in atoms.arrays) == breaking


@pytest.mark.compiled
def test_no_virial_unless_stress_is_asked_for_compiled(monkeypatch):
    """On the compiled route the bond kernels leave the virial out of the
    steps of a periodic run; asked for the stress, they run once more with
    it, and the stress is that of the NumPy route (to 1e-9: the two runs
    part by round-off over the steps; from the same state they agree to
    1e-12, tests/test_peri_kernels.py)."""
    calls = Calls(monkeypatch, compiled, "peri_bonds")
    runs = {}
    for kernels in ("numpy", "compiled"):
        atoms = sc_block(8, pbc=True)
        atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb", s00=0.2)},
                                     guard=False, kernels=kernels)
        atoms.get_forces()
        atoms.set_velocities(2e3 * (atoms.positions - atoms.positions.mean(axis=0)))
        VelocityVerlet(atoms, timestep=1e-7).run(STEPS)
        runs[kernels] = atoms
    assert calls.count == STEPS + 1
    assert not any(args[1].virial for args, _ in calls.args)
    stress = {kernels: atoms.get_stress() for kernels, atoms in runs.items()}
    assert calls.count == STEPS + 2 and calls.args[-1][0][1].virial
    assert np.abs(stress["compiled"] - stress["numpy"]).max() <= 1e-9 * np.abs(
        stress["numpy"]).max()


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_without_breaking_bonds_past_their_criterion_act_as_unbreakable_ones(kernels):
    """With breaking off, a bond past ``s00`` acts as one that could not
    reach its criterion: the run is bit for bit that with ``s00 = 10``."""
    off = stretched_peri_block(False, kernels=kernels)
    far = stretched_peri_block(True, s00=10.0, kernels=kernels)
    assert len(far.info.get("broken_bonds", [])) == 0
    assert np.array_equal(off.positions, far.positions)
    assert np.array_equal(off.get_velocities(), far.get_velocities())


# -- granular: no rotation work without friction ----------------------------------------

#: the pour demo's law, and the same without friction
FRICTION = dict(model="hooke/history", kn=2000.0, gamma_n=50.0, xmu=0.5, dampflag=0)
NO_FRICTION = dict(FRICTION, xmu=0.0)


def pile(pairs: dict, walls: dict, kernels: str = "numpy"):
    """A spinning pile of spheres on a floor between side walls, under
    gravity, a few steps of SphereVelocityVerlet (the guard off, as in
    :func:`block`)."""
    atoms = sphere_pile(n=3, seed=2, speed=0.5, spin=1.0, lift=0.45)
    box = [ase_bpm.GranularWall(**walls, axis="z", lo=0.0, kernels=kernels),
           ase_bpm.GranularWall(**walls, axis="x", lo=-0.5, hi=2.5, kernels=kernels)]
    atoms.calc = ase_bpm.Granular(**pairs, kernels=kernels, guard=False,
                                  fixes=[ase_bpm.Gravity(9.81)] + box)
    spins = atoms.arrays["omega"].copy()
    SphereVelocityVerlet(atoms, 1e-3).run(STEPS)
    return atoms, spins


@pytest.mark.parametrize("friction", [False, True])
def test_no_rotation_work_without_friction(friction, monkeypatch):
    """Without friction in the contacts or the walls, the NumPy route forms
    no tangential velocity or torque (no cross product), reads no spins and
    the integrator turns nothing: omega stays as it was."""
    crosses = Calls(monkeypatch, granular_laws, "_cross")
    spins_read = Calls(monkeypatch, spheres, "angular_velocities")  # (Inputs.omega reads them)
    turns = Calls(monkeypatch, SphereVelocityVerlet, "_turn")
    law = FRICTION if friction else NO_FRICTION
    atoms, spins = pile(law, law)
    assert atoms.calc.produces_torques == friction
    assert atoms.arrays["ncontacts"].sum() > 10  # the spheres touch
    assert (crosses.count > 0) == friction
    assert (spins_read.count > 0) == friction
    assert turns.count == (2 * STEPS if friction else 0)
    assert np.array_equal(atoms.arrays["omega"], spins) != friction
    assert ("gran_shear" in atoms.arrays) == friction  # no shear history either


def test_frictional_walls_turn_spheres_between_frictionless_contacts(monkeypatch):
    """Rotation is the whole calculator's business: frictionless contacts
    between the spheres, but walls with friction, still turn them."""
    kernels = Calls(monkeypatch, granular_laws, "contact_forces")
    turns = Calls(monkeypatch, SphereVelocityVerlet, "_turn")
    atoms, spins = pile(NO_FRICTION, FRICTION)
    assert atoms.calc.produces_torques and not atoms.calc.law.frictional
    assert turns.count == 2 * STEPS
    assert not np.array_equal(atoms.arrays["omega"], spins)
    frictional = [kwargs["frictional"] for _, kwargs in kernels.args]
    assert frictional.count(False) == STEPS + 1  # the pairs, once per evaluation
    assert frictional.count(True) > 0  # the walls, where spheres touch them


@pytest.mark.parametrize("kernels", ["numpy", "auto"])
def test_friction_switched_off_drops_its_history(kernels):
    """A frictionless run keeps no shear history: what a frictional run
    stored is dropped from the atoms (pairs and walls), so friction switched
    back on starts from none, as a fresh calculator would, instead of
    bringing back stale shear on contacts that have since opened."""
    atoms, _ = pile(FRICTION, FRICTION, kernels)
    walls = [fix.history_array for fix in atoms.calc.fixes if hasattr(fix, "history_array")]
    assert "gran_shear" in atoms.arrays and all(name in atoms.arrays for name in walls)
    atoms.calc.set(xmu=0.0)  # the pairs lose friction, the walls keep it
    SphereVelocityVerlet(atoms, 1e-3).run(STEPS)
    assert "gran_shear" not in atoms.arrays and "gran_partner" not in atoms.arrays
    assert all(name in atoms.arrays for name in walls)
    box = [ase_bpm.GranularWall(**NO_FRICTION, axis="z", lo=0.0, kernels=kernels),
           ase_bpm.GranularWall(**NO_FRICTION, axis="x", lo=-0.5, hi=2.5, kernels=kernels)]
    atoms.calc = ase_bpm.Granular(**NO_FRICTION, kernels=kernels, guard=False,
                                  fixes=[ase_bpm.Gravity(9.81)] + box)
    SphereVelocityVerlet(atoms, 1e-3).run(STEPS)
    assert not any(name in atoms.arrays for name in walls)


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_neighbouring_walls_of_one_law_are_one_kernel_call(kernels, monkeypatch):
    """A box of walls is one kernel call per evaluation (their per-call cost
    is most of a small scene's walls), and gives the forces of the walls
    called one by one to round-off; a wall of another law, or one with
    another piece between, is called on its own."""
    route = ase_bpm.laws.granular_kernels(kernels)
    calls = Calls(monkeypatch, route, "walls_contacts")
    floor = dict(FRICTION, kn=3000.0)  # another law: a call of its own
    atoms = sphere_pile(n=3, seed=2, speed=0.5, spin=1.0, lift=0.45)
    atoms.positions[:, 1] += 0.3
    box = [ase_bpm.GranularWall(**FRICTION, axis=axis, lo=-0.5, hi=2.5, kernels=kernels)
           for axis in "xy"]
    walls = [*box, ase_bpm.GranularWall(**floor, axis="z", lo=0.0, kernels=kernels)]
    atoms.calc = ase_bpm.Granular(**FRICTION, kernels=kernels, fixes=walls, timestep=1e-3)
    SphereVelocityVerlet(atoms, 1e-3).run(STEPS)
    assert calls.count == 2 * (STEPS + 1)
    assert [len(args[0]) for args, _ in calls.args[:2]] == [2, 1]
    # the same state afresh, with the walls together and apart (Gravity(0) between them)
    together, apart = atoms.copy(), atoms.copy()
    together.calc = ase_bpm.Granular(**FRICTION, kernels=kernels, timestep=1e-3, fixes=walls)
    apart.calc = ase_bpm.Granular(**FRICTION, kernels=kernels, timestep=1e-3,
                                  fixes=[box[0], ase_bpm.Gravity(0.0), *walls[1:]])
    calls.count = 0
    with ase_bpm.pure(together, apart):  # evaluated, not restored from the record
        ours, theirs = together.get_forces(), apart.get_forces()
    assert calls.count == 2 + 3
    assert np.abs(ours - theirs).max() <= 1e-12 * np.abs(theirs).max()
    assert np.abs(theirs).max() > 0.0


@pytest.mark.parametrize("torques", [False, True])
def test_a_fix_that_does_not_say_is_taken_to_turn_the_spheres(torques):
    """A fix of one's own that contributes (and could return torques) keeps
    rotation on unless it says ``produces_torques = False``."""
    class Piece:
        def contribute(self, atoms, clock):
            return ase_bpm.scene.fixes.Contribution(np.zeros((len(atoms), 3)))

        def todict(self):
            return {"type": "Piece"}

    piece = Piece()
    if not torques:
        piece.produces_torques = False
    calc = ase_bpm.Granular(**NO_FRICTION, fixes=[piece])
    assert calc.produces_torques == torques


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
@pytest.mark.parametrize("law,frictional", [
    (FRICTION, True), (NO_FRICTION, False),
    (dict(model="hooke", kn=2000.0, gamma_n=50.0, xmu=0.5), True),  # tangential damper
    (dict(model="hooke", kn=2000.0, gamma_n=50.0, xmu=0.5, dampflag=0), False),
    (dict(model="hertz/history", kn=2000.0, gamma_n=0.0, xmu=0.0), False)])
def test_the_kernel_variant_is_chosen_from_the_coefficients(kernels, law, frictional,
                                                            monkeypatch):
    """Granular and GranularWall name the variant they chose at setup; on the
    compiled route it is the C function a run calls, and nothing else but
    the one that writes a shear history (history laws only)."""
    names = {"numpy": ("numpy pair_contacts", "numpy walls_contacts"),
             "compiled": ("granular_pairs", "granular_walls")}[kernels]
    suffix = {"numpy": " (frictionless)", "compiled": "_frictionless"}[kernels]
    expected = [name + ("" if frictional else suffix) for name in names]
    called = []
    if kernels == "compiled":
        class Spy:  # the library, noting each C function looked up
            def __init__(self, lib):
                self.lib = lib

            def __getattr__(self, name):
                called.append(name)
                return getattr(self.lib, name)

        monkeypatch.setattr(compiled, "_lib", Spy(compiled._lib))
    atoms, _ = pile(law, law, kernels)
    assert atoms.calc.law.frictional == frictional
    assert atoms.calc.kernel_variant == expected[0]
    assert {wall.kernel_variant for wall in atoms.calc.fixes[1:]} == {expected[1]}
    if kernels == "compiled":
        history = {"granular_place_contacts"} if atoms.calc.law.keeps_history else set()
        assert set(called) == set(expected) | history


def test_the_inputs_of_an_evaluation_are_views_not_copies():
    """An evaluation reads the atoms' spins and particle types through
    read-only views of their own arrays (no per-step copies), which leave
    the atoms' arrays writable: the integrator turns the spheres in place,
    a user may edit the types."""
    atoms = sphere_pile(n=3, seed=2, speed=0.5, spin=1.0)
    atoms.arrays["type"] = np.ones(len(atoms), dtype=np.int64)
    inputs = Inputs(atoms)
    for name, value in (("omega", inputs.omega), ("type", inputs.types)):
        assert np.shares_memory(value, atoms.arrays[name]), name
        assert not value.flags.writeable and atoms.arrays[name].flags.writeable, name
        with pytest.raises(ValueError, match="read-only"):
            value[0] = 2
    assert inputs.omega is inputs.omega  # read once per evaluation
    atoms.calc = ase_bpm.Granular("hooke/history", kn=2000.0, gamma_n=50.0, xmu=0.5,
                                  kernels="compiled" if compiled.available else "numpy")
    SphereVelocityVerlet(atoms, 1e-3).run(3)
    assert atoms.arrays["omega"].flags.writeable and atoms.arrays["type"].flags.writeable
