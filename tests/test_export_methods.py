"""The LAMMPS exporter knows no model and no fix: each calculator describes
its scene (``lammps_scene``) and each fix writes its commands
(``lammps_commands``), so a fix defined outside ase_bpm exports as well as
the package's own."""

import ast
from pathlib import Path

import numpy as np
import pytest
from ase.calculators.emt import EMT
from ase.md.verlet import VelocityVerlet

import ase_bpm
from ase_bpm.core.lammps_text import exact
from ase_bpm import write_lammps
from scenes import HORIZON, MICROMODULUS, NODE_VOLUME, fcc_cluster, peri_model, sc_block

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
