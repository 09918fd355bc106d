"""The calculator holds a model (issue 31): ``calc.model`` computes the
forces from the atoms and the :class:`~ase_bpm.models.evaluation.Context` it
is handed, never from the calculator, and the calculator adds what ASE needs
around it (parameters, the record, the ledger, the guard)."""

import numpy as np
import pytest
from ase.calculators.calculator import Calculator

import ase_bpm
from ase_bpm.core.arrays import Inputs
from ase_bpm.core.bond_set import BondSet as CoreBondSet
from ase_bpm.models import bonded
from ase_bpm.models.evaluation import Context
from ase_bpm.models.granular import GranularModel
from ase_bpm.models.model import Model
from ase_bpm.models.peri import PeriModel
from ase_bpm.models.spring import SpringModel
from scenes import MULTI_TYPE_COEFFS, multi_type_cluster, peri_model, sc_block, sphere_pile


def spring_scene():
    atoms, _ = multi_type_cluster(seed=3)
    atoms.calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
    return atoms


def peri_scene():
    atoms = sc_block(4)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("lps")},
                                 pair_coeffs={(1, 1): (1e20, 1e-3)})
    return atoms


def granular_scene():
    atoms = sphere_pile(n=3)
    atoms.calc = ase_bpm.Granular("hertz/history", kn=2000.0, gamma_n=5.0, xmu=0.5,
                                  timestep=1e-3)
    return atoms


SCENES = {SpringModel: spring_scene, PeriModel: peri_scene, GranularModel: granular_scene}


def context(atoms, parameters, advancing=False, pure=False, timestep=None, step=0):
    return Context(advancing=advancing, pure=pure, step=step, timestep=timestep,
                   inputs=Inputs(atoms), parameters=parameters)


def state_of(atoms) -> dict:
    """Copies of everything on the atoms."""
    return {**{f"arrays[{k}]": np.array(v) for k, v in atoms.arrays.items()},
            **{f"info[{k}]": np.array(v) for k, v in atoms.info.items()}}


def same_state(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("model_class", list(SCENES), ids=lambda c: c.__name__)
def test_a_model_alone_gives_its_calculators_forces_touching_nothing(model_class):
    """A model is no ASE calculator; one of its own, set up with a
    calculator's parameters, has the same digest and, told the calculator's
    first evaluation as a Context, gives its forces and energy bit for bit,
    with nothing on the atoms changed."""
    atoms = SCENES[model_class]()
    calc = atoms.calc
    assert type(calc.model) is model_class and isinstance(calc.model, Model)
    assert not isinstance(calc.model, Calculator)
    fresh = atoms.copy()  # (as the calculator finds them: a first evaluation)
    forces, energy = atoms.get_forces(), atoms.get_potential_energy()

    model = model_class()
    assert model.setup(calc.parameters) == calc._param_digest
    before = state_of(fresh)
    ev = model.evaluate(fresh, context(fresh, calc.parameters,
                                       timestep=calc.parameters.get("timestep")))
    assert np.array_equal(ev.forces, forces) and ev.energy == energy
    assert same_state(state_of(fresh), before)


def test_a_step_is_what_the_context_says():
    """The same stretched bond breaks in the commit of an advancing context
    and not in that of a setup one: the model takes ``advancing`` from the
    context it is handed, with no calculator at all."""
    atoms, _ = multi_type_cluster(seed=3)
    model = SpringModel()
    model.setup(ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS).parameters)
    model.commit(atoms, model.evaluate(atoms, context(atoms, model.parameters)),
                 context(atoms, model.parameters))  # reference lengths taken
    i, j = ase_bpm.get_bonds(atoms)[0][0], ase_bpm.get_bonds(atoms)[1][0]
    atoms.positions[j] += 0.3 * (atoms.positions[j] - atoms.positions[i])  # past eps_c
    bonds_before = len(ase_bpm.get_bonds(atoms)[0])
    for advancing in (False, True):
        stretched = atoms.copy()
        ctx = context(stretched, model.parameters, advancing=advancing, step=1)
        ev = model.evaluate(stretched, ctx)
        assert ev.bonds.broken_b.any() == advancing
        model.commit(stretched, ev, ctx)
        assert (len(ase_bpm.get_bonds(stretched)[0]) < bonds_before) == advancing


def test_bad_parameters_fail_in_the_model_with_the_calculators_words():
    """The model checks the parameters: a bad one raises there with the words
    the calculator's constructor gives, and a calculator whose ``set`` fails
    keeps its model as it was."""
    calc = ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS)
    with pytest.raises(ValueError, match='mix must be "geometric" or "arithmetic", got '
                                         "'harmonic'"):
        SpringModel().setup({**calc.parameters, "mix": "harmonic"})
    digest = calc._param_digest
    with pytest.raises(ValueError, match="mix must be"):
        calc.set(mix="harmonic")
    assert calc.model.parameters["mix"] == "geometric" and calc._param_digest == digest
    with pytest.raises(ValueError, match="Granular: skin = -1.0 must be non-negative"):
        GranularModel().setup({**ase_bpm.Granular(kn=1.0, gamma_n=0.0, xmu=0.0).parameters,
                               "skin": -1.0})


def test_the_old_names_are_the_models_and_the_bond_set():
    """``ase_bpm.models.bonded.BondedModel`` is the model class of the bonded
    calculators now, and ``BondSet`` lives in the core, re-exported."""
    assert issubclass(SpringModel, bonded.BondedModel) and issubclass(PeriModel,
                                                                       bonded.BondedModel)
    assert not issubclass(bonded.BondedModel, Calculator)
    assert bonded.BondSet is CoreBondSet
    for calc in (ase_bpm.BPMSpring(**MULTI_TYPE_COEFFS), ase_bpm.BPMPeri(
            bond_coeffs={1: peri_model("pmb")}), ase_bpm.Granular(kn=1.0, gamma_n=0.0,
                                                                   xmu=0.0)):
        again = type(calc)(**calc.todict())
        assert again.todict() == calc.todict()
        assert again._param_digest == calc._param_digest
