"""The LAMMPS exporter knows no model and no fix: each model's scene comes
from ``scene/lammps_export.py`` (``SCENES``, one table, beside the reader),
each fix writes its commands (``lammps_commands``), so a fix defined outside
ase_bpm exports as well as the package's own; the style names are the laws',
which the writer and the reader take from one place."""

import ast
from pathlib import Path

import numpy as np
import pytest
from ase.calculators.emt import EMT
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.core.lammps_text import exact
from ase_bpm.laws.granular import ContactLaw
from ase_bpm.laws.peri import PeriBond, PeriContact
from ase_bpm.laws.spring import SpringBond, SpringPair, SpringPlasticBond
from ase_bpm.models.base import BPMCalculator
from ase_bpm.scene.lammps_export import SCENES
from ase_bpm import write_lammps
from scenes import (HORIZON, MICROMODULUS, NODE_VOLUME, SPACING, fcc_cluster, peri_model,
                    sc_block, sphere_pile)

EXPORTER = Path(ase_bpm.scene.lammps.__file__)
CLASSES = {"BPMSpring", "BPMPeri", "Granular", "BPMCalculator", "SphericalIndenter",
           "Gravity", "GranularWall"}
PUSH = np.array([0.01, 0.0, -0.02])  # force on every particle
DT, STEPS = 0.05, 200


def type_dispatch(source: str) -> list[str]:
    """``isinstance``/``issubclass`` calls, ``type(x) is/== ...`` comparisons
    and names of ase_bpm's models and fixes in ``source``, with line numbers."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id in ("isinstance", "issubclass")):
            found.append(f"{node.func.id} at line {node.lineno}")
        elif isinstance(node, ast.Compare):
            for side in [node.left, *node.comparators]:
                if (isinstance(side, ast.Call) and isinstance(side.func, ast.Name)
                        and side.func.id == "type"):
                    found.append(f"type(...) comparison at line {node.lineno}")
        elif isinstance(node, (ast.Name, ast.alias)):
            name = node.id if isinstance(node, ast.Name) else node.asname or node.name
            if name in CLASSES:
                found.append(f"{name} at line {node.lineno}")
    return found


def test_the_exporter_has_no_type_dispatch():
    assert type_dispatch(EXPORTER.read_text()) == []


def test_the_check_sees_type_dispatch():
    """The checker itself finds each kind of dispatch (a test that cannot fail
    is no test)."""
    source = ("from ..models.granular import Granular\n"
              "if isinstance(calc, Granular): pass\n"
              "if type(fix) is Gravity: pass\n")
    found = type_dispatch(source)
    assert "isinstance at line 2" in found and "type(...) comparison at line 3" in found
    assert "Granular at line 1" in found and "Gravity at line 3" in found


class Push:
    """A constant force on every particle, defined outside ase_bpm, with its
    own LAMMPS export (``fix addforce``)."""

    needs_time = False

    def __init__(self, force):
        self.force = np.asarray(force, dtype=float)

    def forces(self, atoms, time):
        return (np.tile(self.force, (len(atoms), 1)),
                float(-np.sum(atoms.positions @ self.force)))

    def todict(self):
        return {"type": "Push", "force": self.force.tolist()}

    def lammps_commands(self, index, force_per_lammps_force=1.0):
        f = " ".join(exact(f) for f in self.force / force_per_lammps_force)
        return [f"fix push{index} all addforce {f}"]


class Plain:
    """A fix without a LAMMPS export."""

    needs_time = False

    def forces(self, atoms, time):
        return np.zeros((len(atoms), 3)), 0.0

    def todict(self):
        return {"type": "Plain"}


def pushed_cluster(*fixes):
    atoms, rng = fcc_cluster(3, seed=1)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.5)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)},
                                   fixes=[ase_bpm.Gravity(0.1), *fixes])
    return atoms


@pytest.mark.oracle
def test_a_fix_from_outside_the_package_runs_in_lammps(tmp_path, Oracle):
    """write_lammps puts the foreign fix's own command into the deck, and
    LAMMPS runs that deck to ase_bpm's trajectory."""
    from oracle import gather, run_deck

    atoms = pushed_cluster(Push(PUSH))
    _, deck = write_lammps(str(tmp_path / "pushed"), atoms, timestep=DT, steps=STEPS)
    assert "fix push1 all addforce 0.01 0.0 -0.02" in Path(deck).read_text().splitlines()
    lmp = run_deck(deck)
    x = gather(lmp, "x")
    lmp.close()
    start = atoms.positions.copy()
    VelocityVerlet(atoms, timestep=DT).run(STEPS)
    assert np.abs(x - atoms.positions).max() <= 1e-9
    assert np.abs(atoms.positions - start).max() > 0.1  # the push moved them


def test_a_foreign_fix_gets_the_force_units_of_the_scene(tmp_path):
    """Under legacy PERI, LAMMPS' forces are force densities: the fix is told
    so and writes its force per node volume."""
    atoms = sc_block(5)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb")},
                                 pair_coeffs={(1, 1): (MICROMODULUS, HORIZON)},
                                 timestep=1e-7, fixes=[Push(PUSH)], follows="legacy")
    _, deck = write_lammps(str(tmp_path / "block"), atoms)
    f = " ".join(exact(f) for f in PUSH / NODE_VOLUME)
    assert f"fix push0 all addforce {f}" in Path(deck).read_text().splitlines()


def test_a_foreign_fix_that_needs_spheres_turns_bonded_particles_into_spheres(tmp_path):
    class RoundPush(Push):
        needs_spheres = True

    atoms = pushed_cluster(RoundPush(PUSH))
    atoms.arrays["radius"] = np.full(len(atoms), 0.5)
    _, deck = write_lammps(str(tmp_path / "round"), atoms, timestep=DT)
    lines = Path(deck).read_text().splitlines()
    assert "atom_style bpm/sphere" in lines and "fix integrate all nve/sphere" in lines


def test_a_fix_without_an_export_is_refused_by_name(tmp_path):
    atoms = pushed_cluster(Plain())
    with pytest.raises(ValueError, match="no LAMMPS export for Plain in this scene"):
        write_lammps(str(tmp_path / "plain"), atoms, timestep=DT)
    assert list(tmp_path.iterdir()) == []  # nothing half written


def test_a_calculator_without_an_export_is_refused_by_name(tmp_path):
    atoms, _ = fcc_cluster(2)
    atoms.calc = EMT()
    with pytest.raises(TypeError, match="no LAMMPS export for EMT"):
        write_lammps(str(tmp_path / "emt"), atoms)


def test_every_calculator_of_the_package_has_a_scene():
    """Each public calculator is in the exporter's table (a new one without
    an export fails here, not in a user's write_lammps)."""
    public = {getattr(ase_bpm, name) for name in ase_bpm.__all__}
    calculators = {c for c in public if isinstance(c, type) and issubclass(c, BPMCalculator)
                   and c is not BPMCalculator}
    assert {c.__name__ for c in calculators} == {"BPMSpring", "BPMPeri", "Granular"}
    assert set(SCENES) == calculators


def test_a_subclass_exports_as_the_calculator_it_extends(tmp_path):
    """A calculator derived from BPMSpring writes the same files as BPMSpring."""
    class Tuned(ase_bpm.BPMSpring):
        pass

    written = []
    for cls in (ase_bpm.BPMSpring, Tuned):
        atoms, _ = fcc_cluster(3, seed=1)
        ase_bpm.create_bonds(atoms, 1.25)
        atoms.calc = cls(bond_coeffs={1: (1.0, 0.1, 0.5)},
                         pair_coeffs={(1, 1): (1.0, 1.0, 0.5)}, timestep=DT)
        (tmp_path / cls.__name__).mkdir()
        paths = write_lammps(str(tmp_path / cls.__name__ / "scene"), atoms, steps=10)
        written.append([Path(path).read_bytes() for path in paths])
    assert written[0] == written[1]


def spring_scene():
    atoms, rng = fcc_cluster(3, seed=2)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.5)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)}, timestep=DT)
    return atoms, 0.01


def plastic_scene():
    atoms, _ = spring_scene()
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: ("bpm/spring/plastic", 1.0, 0.1, 0.5, 0.01)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)}, timestep=DT)
    return atoms, 0.01


def peri_scene(follows):
    def scene():
        atoms = sc_block(4)
        atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb")},
                                     pair_coeffs={(1, 1): (MICROMODULUS, HORIZON)},
                                     timestep=1e-7, follows=follows)
        return atoms, 0.01 * SPACING
    return scene


def granular_scene():
    atoms = sphere_pile(seed=3)
    atoms.calc = ase_bpm.Granular("hooke/history", kn=1000.0, gamma_n=20.0, xmu=0.4,
                                  timestep=1e-3)
    return atoms, None  # (compared as they are: the spheres overlap)


#: each fact that names a style, the law that holds it, and a scene that uses it
STYLE_NAMES = {"bond_style bpm/spring": (SpringBond, "lammps_style", spring_scene),
               "bond_style bpm/spring/plastic": (SpringPlasticBond, "lammps_style",
                                                 plastic_scene),
               "pair_style bpm/spring": (SpringPair, "name", spring_scene),
               "bond_style bpm/peri": (PeriBond, "lammps_style", peri_scene("bpm/peri")),
               "pair_style bpm/peri": (PeriContact, "name", peri_scene("bpm/peri")),
               "pair_style peri/<law>": (PeriBond, "legacy_prefix", peri_scene("legacy")),
               "pair_style gran/<model>": (ContactLaw, "STYLE_PREFIX", granular_scene)}


@pytest.mark.parametrize("style", list(STYLE_NAMES))
def test_a_style_name_is_the_laws_for_writer_and_reader(tmp_path, monkeypatch, style):
    """Renamed in the law, a style is written under its new name and read
    back by it into the same calculator, with the same forces at a deformed
    state: write_lammps and read_lammps take the name from one place."""
    law, fact, scene = STYLE_NAMES[style]
    old = getattr(law, fact)
    new = old[:-1] + "-renamed/" if old.endswith("/") else old + "-renamed"
    monkeypatch.setattr(law, fact, new)
    command = style.split()[0]
    atoms, jitter = scene()
    data, deck = write_lammps(str(tmp_path / "scene"), atoms, steps=10)
    named = [line.split()[1] for line in Path(deck).read_text().splitlines()
             if line.startswith(command + " ")]
    assert named and all(word.startswith(new) for word in named
                         if word != "zero"), named
    back = ase_bpm.read_lammps(data, deck)
    assert type(back.calc) is type(atoms.calc)
    if jitter is not None:
        atoms.get_forces(), back.get_forces()  # (the reference states)
        x = atoms.positions + np.random.default_rng(4).uniform(-jitter, jitter,
                                                                  atoms.positions.shape)
        atoms.positions, back.positions = x, x.copy()
    forces = atoms.get_forces()
    assert np.abs(forces).max() > 0
    assert np.abs(back.get_forces() - forces).max() <= 1e-12 * np.abs(forces).max()


@pytest.mark.parametrize("follows, refusal", [("bpm/peri", "bond_style bpm/peri cannot run"),
                                              ("legacy", "no legacy PERI pair style runs")])
def test_a_peri_law_lammps_cannot_run_is_refused_naming_law_and_type(tmp_path, monkeypatch,
                                                                      follows, refusal):
    """A PERI law that sets no LAMMPS style (nor a legacy order: pmb made
    so for this test) is not exported, in either style BPMPeri follows: the
    error names the law and the bond type, and nothing is written."""
    from ase_bpm.laws.peri import Pmb

    monkeypatch.setattr(Pmb, "lammps_style", None)
    monkeypatch.setattr(Pmb, "legacy_order", ())
    atoms = sc_block(3)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("pmb")},
                                 pair_coeffs={(1, 1): (MICROMODULUS, HORIZON)},
                                 timestep=1e-7, follows=follows)
    with pytest.raises(ValueError, match=rf"bond type 1 follows the law 'pmb', which "
                                         rf"{refusal}: no LAMMPS export"):
        write_lammps(str(tmp_path / "block"), atoms)
    assert list(tmp_path.iterdir()) == []


def test_a_peri_scene_without_bond_coefficients_is_refused_by_name(tmp_path):
    atoms = sc_block(2)
    atoms.calc = ase_bpm.BPMPeri(timestep=1e-7)
    with pytest.raises(ValueError, match="no LAMMPS export of a BPMPeri without bond_coeffs"):
        write_lammps(str(tmp_path / "block"), atoms)
    assert list(tmp_path.iterdir()) == []
