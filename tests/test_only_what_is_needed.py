"""A term that is switched off costs nothing: its code path is not entered.
Counted calls on the NumPy route, never timings."""

import pytest

import ase_bpm
import ase_bpm.core.neighbours as neighbours
import ase_bpm.laws.peri as peri_laws
import ase_bpm.models.spring as spring_model
from ase_bpm.md import VelocityVerlet
from ase_bpm.models.bonded import BondSet
from scenes import fcc_cluster

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
