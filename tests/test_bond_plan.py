"""The bonded step runs a plan made once per bond set (``BondPlan``).

A bond set lasts until bonds break (a lazily marked set keeps its plan: its
bonds keep their places) or the bonds on the atoms are read anew.  What
stays while it lasts is worked out once: the law groups, routes, damping,
and each compiled law's kernel with its arguments converted for C
(``BondLaw.prepare``; ``compiled.SpringBonds``); the contact kernel is made
ready once per neighbour list and bond set (``compiled.SpringPairs``).  A
commit that changes no bond writes nothing.  Counted calls and identities,
never timings; and what a plan made once gives is what fresh ones give.
"""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.laws import compiled
from ase_bpm.laws.bond import BondSums
from ase_bpm.laws.spring import SpringBond
from ase_bpm.models.bonded import PLAN, BondState
from test_compiled_spring import coefficients
from test_lazy_breaking import flying_cluster

pytestmark = pytest.mark.compiled

STEPS = 40


class Counted:
    """Counts the calls of ``owner.name``, noting what ``note(*args)`` says of each."""

    def __init__(self, monkeypatch, owner, name, note=lambda *args: None):
        self.notes = []
        inner = getattr(owner, name)

        def counted(*args, **kwargs):
            self.notes.append(note(*args))
            return inner(*args, **kwargs)
        monkeypatch.setattr(owner, name, counted)

    @property
    def count(self) -> int:
        return len(self.notes)


def calculator(**kwargs):
    return ase_bpm.BPMSpring(**coefficients(), kernels="compiled", guard=False, **kwargs)


def sets_of(atoms, steps):
    """The bond sets of each evaluation of ``steps`` steps of ASE's
    VelocityVerlet (the set as evaluated, before its commit)."""
    seen = []
    model = atoms.calc.model
    evaluate = model.evaluate

    def noted(a, ctx):
        ev = evaluate(a, ctx)
        seen.append(ev.bonds.bonds)
        return ev
    model.evaluate = noted
    try:
        VelocityVerlet(atoms, timestep=0.02).run(steps)
    finally:
        del model.evaluate
    return seen


def test_a_kernel_is_made_ready_once_per_bond_set(monkeypatch):
    """Each bond set's kernel is made ready at its first evaluation and
    used at every one after; bonds that break lazily keep the set's plan
    (the same kernel), a set that sheds them, or bonds read anew, make a new
    one."""
    prepared = Counted(monkeypatch, SpringBond, "prepare")
    runs = Counted(monkeypatch, compiled.SpringBonds, "__call__",
                   note=lambda kernel, scene: id(kernel))
    atoms = flying_cluster()
    atoms.calc = calculator()
    sets = sets_of(atoms, STEPS)  # the setup evaluation, then the steps
    assert len(sets) == runs.count == STEPS + 1
    marked = shed = 0
    for before, after in zip(sets, sets[1:]):
        same_bonds = after is before or (after.parent == before.serial
                                         and after.i_b is before.i_b)  # marked lazily
        assert (after.cache[PLAN] is before.cache[PLAN]) == same_bonds
        marked += same_bonds and after is not before
        shed += not same_bonds
    assert marked and shed, "the scene no longer breaks bonds lazily and sheds them"
    plans = {id(s.cache[PLAN]) for s in sets}  # (all alive: sets holds them)
    assert prepared.count == len(plans) == len(set(runs.notes))

    # bonds read anew (an array replaced): a new set, a new plan, a new kernel,
    # and the forces of a first evaluation of these bonds
    atoms.arrays["bond_type"] = atoms.arrays["bond_type"].copy()
    forces = atoms.get_forces()
    assert prepared.count == len(plans) + 1
    reference = atoms.copy()
    del reference.arrays["bpm_x_last"]  # (no record: a first evaluation)
    reference.calc = calculator()
    assert np.array_equal(forces, reference.get_forces())


def test_the_contact_kernel_is_made_ready_per_list_and_bond_set(monkeypatch):
    """One SpringPairs per neighbour-list build and bond set (the rows of
    the list's candidate pairs), used until either changes."""
    made = Counted(monkeypatch, compiled.SpringPairs, "__init__")
    keys = []
    atoms = flying_cluster()
    atoms.calc = calculator()
    contacts = atoms.calc.model._contacts
    listed = contacts.listed

    def noted(a, bonds):
        out = listed(a, bonds)
        keys.append((contacts.neighbours.nbuilds, bonds.serial))
        return out
    monkeypatch.setattr(contacts, "listed", noted)
    VelocityVerlet(atoms, timestep=0.02).run(STEPS)
    assert len(keys) == STEPS + 1
    assert len(set(keys)) > 2  # rebuilt, or bonds broke, on the way
    assert made.count == len(set(keys))


def test_a_step_that_changes_no_bond_writes_none(monkeypatch):
    """Where no bond breaks and every reference length is taken, the commit
    leaves the bond arrays on the atoms as they are (the same read-only
    objects, not written); a step in which bonds break writes them."""
    writes = Counted(monkeypatch, BondState, "write")
    atoms = flying_cluster()
    atoms.calc = calculator()
    atoms.get_forces()  # the reference lengths taken: written
    assert writes.count == 1
    names = ("bond_partner", "bond_type", "bond_r0", "bpm_id")
    held = {name: atoms.arrays[name] for name in names}
    dyn = VelocityVerlet(atoms, timestep=0.02)
    steps = 0
    while "broken_bonds" not in atoms.info:
        dyn.run(1)
        steps += 1
        assert steps < STEPS, "no bond broke: the scene no longer tests breaking"
        if "broken_bonds" not in atoms.info:
            assert writes.count == 1
            for name in names:
                assert atoms.arrays[name] is held[name], name
                assert not atoms.arrays[name].flags.writeable, name
    assert writes.count == 2
    type_b = ase_bpm.get_bonds(atoms, include_broken=True)[2]
    assert (type_b == 0).sum() == len(atoms.info["broken_bonds"])


def test_a_bond_output_of_another_type_is_refused_not_written_past(monkeypatch):
    """The bond kernel made ready once still checks, at every call, the
    arrays it writes into: single-precision forces raise, naming them, and
    the atoms lose nothing (the step then runs as if it had not)."""
    zeros = BondSums.zeros

    def single_precision_forces(natoms, nbonds, damped, breaking):
        sums = zeros(natoms, nbonds, damped, breaking)
        sums.f_nc = sums.f_nc.astype(np.float32)
        return sums

    atoms = flying_cluster()
    atoms.calc = calculator()
    atoms.get_forces()
    atoms.positions[0] += 0.01
    twin = atoms.copy()
    twin.calc = calculator()
    bond_type, step = atoms.arrays["bond_type"], atoms.info["bpm_step"]
    monkeypatch.setattr(BondSums, "zeros", staticmethod(single_precision_forces))
    with pytest.raises(ValueError, match="write into the forces.*float64, not float32"):
        atoms.get_forces()
    assert atoms.arrays["bond_type"] is bond_type and atoms.info["bpm_step"] == step
    monkeypatch.setattr(BondSums, "zeros", zeros)
    assert np.array_equal(atoms.get_forces(), twin.get_forces())
    assert atoms.info["bpm_step"] == twin.info["bpm_step"] == step + 1
