"""ase_bpm inside ASE's files: the ``ase-bpm`` format through ASE's
``ase.ioformats`` entry point, calculators (fixes and all) from their
``todict()``, and what ASE's trajectories keep of them."""

import json
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np
import pytest
from ase.io import Trajectory, read, write

import ase_bpm
from ase_bpm import SphereVelocityVerlet, VelocityVerlet
from ase_bpm.models.base import FIX_TYPES, fix_from_dict
from ase_bpm.scene.aseio import CALCULATORS, calculator_from_dict
from scenes import NODE_VOLUME, SPACING, fcc_cluster, peri_model, sc_block, sphere_pile

ROOT = Path(__file__).resolve().parent.parent
NAME = "ase-bpm"  # the format's name, the entry point's


# -- the format, found by ASE -----------------------------------------------------------
def declared_format():
    """The ``ase.ioformats`` entry ``ase-bpm`` of pyproject.toml, and the
    project's top-level modules."""
    tomllib = pytest.importorskip("tomllib")
    with open(ROOT / "pyproject.toml", "rb") as fh:
        project = tomllib.load(fh)
    entry = project["project"].get("entry-points", {}).get("ase.ioformats", {}).get(NAME)
    modules = project.get("tool", {}).get("setuptools", {}).get("py-modules", [])
    return entry, modules


@pytest.fixture
def registered():
    """The format as ASE registered it from the installed entry point."""
    from ase.io.formats import ioformats

    installed = [ep for ep in entry_points(group="ase.ioformats") if ep.name == NAME]
    assert installed, (f"no '{NAME}' entry point in group 'ase.ioformats' is installed: "
                       "declare it in pyproject.toml and run pip install -e .")
    assert NAME in ioformats, f"ASE did not register the installed '{NAME}' format"
    return ioformats[NAME]


def test_pyproject_declares_the_format_outside_the_package():
    """ASE imports the entry point's module while importing ``ase.io``:
    inside ase_bpm, whose import needs ``ase.io`` and ``ase.md`` complete,
    it would fail when ``ase.md`` is imported first."""
    entry, modules = declared_format()
    assert entry is not None, f'pyproject.toml: [project.entry-points."ase.ioformats"] {NAME}'
    module = entry.split(":")[0].strip()
    assert module.split(".")[0] != "ase_bpm" and module in modules


def test_registered_format_names_the_reader_and_writer(registered):
    assert registered.module_name == "ase_bpm.scene.aseio"
    assert registered.single and registered.isbinary
    assert registered.can_read and registered.can_write
    assert registered.match_name("run.bpm") and "bpm" in registered.extensions


@pytest.mark.parametrize("first", ["ase.io", "ase.md.verlet", "ase_bpm"])
def test_ase_finds_the_format_whatever_is_imported_first(registered, first, tmp_path):
    """In a fresh interpreter, ASE registers the format without a warning,
    whichever of ASE and ase_bpm comes first; ASE alone does not import
    ase_bpm."""
    script = "\n".join([
        "import sys, warnings",
        "warnings.filterwarnings('error', message='.*external IO format')",
        f"import {first}",
        "import ase.io",
        "from ase.io.formats import ioformats",
        f"print(ioformats[{NAME!r}].module_name, 'ase_bpm' in sys.modules)"])
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    module, imported = run.stdout.split()
    assert module == "ase_bpm.scene.aseio"
    assert imported == str(first == "ase_bpm")


def spring_run():
    """A bonded block whose bonds break within the run (as in test_restart)."""
    atoms, rng = fcc_cluster(4, seed=3)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.08, atoms.positions.shape))
    return atoms, dict(bond_coeffs={1: (1.0, 0.06, 0.2)}, pair_coeffs={(1, 1): (1.0, 1.0, 0.5)})


def test_ase_io_restarts_a_run_bit_for_bit(registered, tmp_path):
    """``ase.io.write("x.bpm")`` and ``ase.io.read("x.bpm")``: the whole
    state, and the run goes on as if it had never stopped."""
    straight, coeffs = spring_run()
    interrupted = straight.copy()
    straight.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(straight, 0.1).run(120)

    interrupted.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(interrupted, 0.1).run(60)
    write(tmp_path / "run.bpm", interrupted)
    resumed = read(tmp_path / "run.bpm")
    assert set(resumed.arrays) == set(interrupted.arrays)
    for name, array in interrupted.arrays.items():
        assert np.array_equal(resumed.arrays[name], array, equal_nan=array.dtype.kind == "f")
    resumed.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(resumed, 0.1).run(60)

    assert (straight.arrays["damage"] > 0).sum() > 20  # bonds broke on the way
    assert np.array_equal(resumed.positions, straight.positions)
    assert np.array_equal(resumed.get_momenta(), straight.get_momenta())
    assert resumed.info["bpm_step"] == straight.info["bpm_step"] == 120


def test_format_by_name_and_on_open_files(registered, tmp_path):
    atoms, coeffs = spring_run()
    atoms.calc = ase_bpm.BPMSpring(**coeffs)
    VelocityVerlet(atoms, 0.1).run(5)
    with open(tmp_path / "state.npz", "wb") as fd:
        write(fd, atoms, format=NAME)
    with open(tmp_path / "state.npz", "rb") as fd:
        back = read(fd, format=NAME)
    assert np.array_equal(back.arrays["bond_r0"], atoms.arrays["bond_r0"], equal_nan=True)
    assert set(back.info) == set(atoms.info) and back.info["bpm_step"] == 5

    with open(tmp_path / "other.bpm", "wb") as fd:
        np.savez(fd, x=np.zeros(3))  # an .npz, not a restart
    with pytest.raises(ValueError, match="other.bpm: not an ase_bpm restart file"):
        read(tmp_path / "other.bpm")


# -- calculators from their todict() ------------------------------------------------------
def spring_scene():
    atoms, rng = fcc_cluster(3, seed=21)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    centre = atoms.positions.mean(axis=0) + (2.5, 0.0, 0.0)
    box = atoms.positions.min(axis=0) - 0.2, atoms.positions.max(axis=0) + 0.2
    fixes = [ase_bpm.Gravity(0.05, direction=(1.0, 2.0, -3.0)),
             ase_bpm.SphericalIndenter(1.0, 1.5, centre, velocity=(-0.2, 0.0, 0.0)),
             ase_bpm.LostAtoms(box[0], (None, *box[1][1:]), skin=0.05)]  # (none lost here)
    calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.1, 0.5)},
                             pair_coeffs={(1, 1): (1.0, 1.0, 0.5)}, fixes=fixes)
    return atoms, calc, VelocityVerlet, 0.05


def peri_scene():
    atoms = sc_block(5)
    centre = atoms.positions.mean(axis=0) + (0.0, 3.2 * SPACING, 0.0)
    fixes = [ase_bpm.SphericalIndenter(1e17 * NODE_VOLUME, 3 * SPACING, centre,
                                       velocity=(0.0, -100.0, 0.0)),
             ase_bpm.Gravity(9.81, direction=(0.3, -1.0, 0.2))]
    calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model("lps")}, fixes=fixes, guard=False)
    return atoms, calc, VelocityVerlet, 1e-7


def granular_scene():
    atoms = sphere_pile(n=3, seed=4, lift=0.3)
    law = dict(kn=2000.0, gamma_n=50.0, xmu=0.5)
    fixes = [ase_bpm.GranularWall("hertz/history", **law, axis="z", lo=0.0, kernels="numpy"),
             ase_bpm.GranularWall("hooke", kn=1500.0, gamma_n=20.0, xmu=0.0, axis="x",
                                  lo=-0.3, hi=2.3),
             ase_bpm.Gravity(9.81, direction=(0.1, 0.2, -1.0))]
    calc = ase_bpm.Granular("hooke/history", **law, kt=600.0, timestep=1e-3, fixes=fixes)
    return atoms, calc, SphereVelocityVerlet, 1e-3


SCENES = {"BPMSpring": spring_scene, "BPMPeri": peri_scene, "Granular": granular_scene}


def test_every_calculator_and_fix_is_covered():
    assert {type(scene()[1]).__name__ for scene in SCENES.values()} == {
        cls.__name__ for cls in CALCULATORS.values()}
    assert {type(fix).__name__ for scene in SCENES.values() for fix in scene()[1].fixes} \
        == set(FIX_TYPES) == {"Gravity", "GranularWall", "LostAtoms", "SphericalIndenter"}


@pytest.mark.parametrize("model", SCENES)
def test_json_round_trip_gives_the_same_run_bit_for_bit(model):
    """A calculator built again from ``json(calc.todict())`` (by its name, or
    its class) has the same fixes and gives the same forces, bit for bit,
    over a run."""
    atoms, calc, integrator, dt = SCENES[model]()
    described = json.loads(json.dumps(calc.todict()))
    assert [fix["type"] for fix in described["fixes"]] == [type(f).__name__ for f in calc.fixes]
    by_name = calculator_from_dict(calc.name, described)
    by_class = type(calc)(**described)
    bare = type(calc)(**{k: v for k, v in described.items() if k != "fixes"})
    for again in (by_name, by_class):
        assert type(again) is type(calc) and again.todict() == calc.todict()
        assert again.guard == calc.guard
        assert [f.todict() for f in again.fixes] == [f.todict() for f in calc.fixes]

    runs = []
    for c in (calc, by_name, by_class, bare):
        twin = atoms.copy()
        twin.calc = c
        forces = [twin.get_forces().copy()]
        dyn = integrator(twin, timestep=dt)
        for _ in range(15):
            dyn.run(1)
            forces.append(twin.get_forces().copy())
        runs.append((np.array(forces), twin.positions.copy()))
    for forces, positions in runs[1:3]:
        assert np.array_equal(forces, runs[0][0]) and np.array_equal(positions, runs[0][1])
    assert not np.array_equal(runs[3][0][0], runs[0][0][0])  # the fixes act


@pytest.mark.parametrize("fix", [
    ase_bpm.Gravity(3.5, direction=(0.3, -0.7, 0.11)),
    ase_bpm.SphericalIndenter(2.0, 0.7, (0.1, 0.2, 0.3), velocity=(1e-3, 0.0, -2.0)),
    ase_bpm.GranularWall("hertz/history", kn=1e4, gamma_n=5.0, xmu=0.4, kt=3e3, dampflag=0,
                         axis="y", lo=None, hi=2.0, limit_damping=True, name="roof",
                         kernels="numpy"),
    ase_bpm.GranularWall("hooke", kn=1e3, gamma_n=2.0, xmu=0.0, pair_law=True)],
    ids=["gravity", "indenter", "wall", "pair-law-wall"])
def test_each_fix_comes_back_from_json(fix):
    described = json.loads(json.dumps(fix.todict()))
    again = fix_from_dict(described)
    assert type(again) is type(fix) and again.todict() == fix.todict()
    for name, value in vars(fix).items():
        if isinstance(value, np.ndarray):
            assert np.array_equal(vars(again)[name], value), name


def test_unknown_names_are_named():
    with pytest.raises(ValueError, match="unknown type 'Wall'.*GranularWall"):
        fix_from_dict({"type": "Wall", "lo": 0.0})
    with pytest.raises(ValueError, match="no ase_bpm calculator is named 'emt'.*bpm_spring"):
        calculator_from_dict("emt", {})
    with pytest.raises(TypeError, match="radius"):  # the fix's own keyword check
        fix_from_dict({"type": "Gravity", "g": 1.0, "radius": 2.0})


def test_ase_trajectory_keeps_the_fixes(tmp_path):
    """ASE's trajectory stores ``calc.name`` and ``calc.todict()``: the
    calculator, fixes included, can be built again from a frame (the frame
    itself keeps no bonds nor radii: restart files keep those)."""
    atoms, calc, integrator, dt = granular_scene()
    atoms.calc = calc
    dyn = integrator(atoms, timestep=dt)
    with Trajectory(tmp_path / "run.traj", "w", atoms) as traj:
        dyn.attach(traj.write, interval=5)
        dyn.run(10)
    frames = read(tmp_path / "run.traj", ":")
    assert len(frames) == 3
    frame = frames[-1]
    assert np.array_equal(frame.get_forces(), atoms.get_forces())
    assert frame.calc.name == "granular"
    assert frame.calc.parameters["fixes"] == calc.todict()["fixes"]
    again = calculator_from_dict(frame.calc.name, frame.calc.parameters)
    assert again.todict() == calc.todict()
