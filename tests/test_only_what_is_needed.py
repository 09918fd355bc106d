"""A term that is switched off costs nothing: its code path is not entered.
Counted calls on the NumPy route, never timings."""

import pytest

import numpy as np

import ase_bpm
import ase_bpm.core.neighbours as neighbours
import ase_bpm.laws.peri as peri_laws
import ase_bpm.laws.spring as spring_laws
import ase_bpm.models.spring as spring_model
from ase_bpm.md import VelocityVerlet
from ase_bpm.models.bonded import BondSet
from scenes import fcc_cluster, peri_model, sc_block

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


def block(**coeffs):
    """A few steps of a small bonded block (the blow-up guard off: its
    stable-timestep check reads the bonds once more)."""
    atoms, rng = fcc_cluster(2, seed=4)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(**coeffs, guard=False)
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


@pytest.mark.parametrize("model", ["pmb", "lps"])
def test_no_dilatation_for_the_bond_based_model(model, monkeypatch):
    from test_properties import scene

    dilatations = Calls(monkeypatch, peri_laws, "dilatation")
    atoms = scene(model, seed=0)  # evaluated at the lattice, then jittered
    atoms.get_forces()
    assert (dilatations.count > 0) == (model == "lps")


def stretched_peri_block(break_bonds: bool, s00: float = 0.0005):
    """A pmb block pulled apart from its centre for a few steps: past the
    critical stretch ``s00`` within them (the guard off, as in :func:`block`)."""
    atoms = sc_block(4)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb", s00=s00)},
                                 break_bonds=break_bonds, guard=False)
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


def test_without_breaking_bonds_past_their_criterion_act_as_unbreakable_ones():
    """With breaking off, a bond past ``s00`` acts as one that could not
    reach its criterion: the run is bit for bit that with ``s00 = 10``."""
    off = stretched_peri_block(False)
    far = stretched_peri_block(True, s00=10.0)
    assert len(far.info.get("broken_bonds", [])) == 0
    assert np.array_equal(off.positions, far.positions)
    assert np.array_equal(off.get_velocities(), far.get_velocities())
