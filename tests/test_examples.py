"""The examples run as the README shows them.

Every Python block of README.md runs as pasted, in a fresh interpreter whose
working folder is an empty temporary one, within ``BLOCK_SECONDS``; checks
appended to its code (or put before a line of it) look at what it made.
"""

import runpy
import subprocess
import sys
from pathlib import Path

import pytest
from ase.io import read

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
#: what a README block may take, in CI on one core
BLOCK_SECONDS = 60


def test_quickstart(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    runpy.run_path(str(EXAMPLES / "quickstart.py"), run_name="__main__")
    frames = read(tmp_path / "quickstart.extxyz", ":")
    assert len(frames) == 13  # steps 0, 50, ..., 600
    assert frames[-1].arrays["damage"].max() > frames[0].arrays["damage"].max()
    assert "broken" in capsys.readouterr().out


def readme_blocks():
    readme = (ROOT / "README.md").read_text()
    return [part.split("```", 1)[0] for part in readme.split("```python\n")[1:]]


def readme_block(containing: str) -> str:
    """The README's one Python block that contains ``containing``."""
    found = [block for block in readme_blocks() if containing in block]
    assert len(found) == 1, f"{len(found)} README blocks contain {containing!r}"
    return found[0]


# what the block prints, for the checks (``printed``)
CAPTURE = """import contextlib as _contextlib, io as _io
_printed = _io.StringIO()
_capture = _contextlib.redirect_stdout(_printed)
_capture.__enter__()
"""
RELEASE = """
_capture.__exit__(None, None, None)
printed = _printed.getvalue().splitlines()
"""

#: each README block, found by a line of its code: (code put before that
#: line, checks run after the block)
CHECKS = {
    'with ase_bpm.ViewerTrajectory("run.extxyz", atoms) as trajectory:': ("", """
from ase.io import read
frames = read("run.extxyz", ":")
assert len(frames) == 21 and "damage" in frames[-1].arrays
assert atoms.info["bpm_step"] == 1000
"""),
    "block.calc = ase_bpm.BPMPeri(": ("", """
assert block.info["bpm_step"] == 300 and block.arrays["damage"].max() > 0.1
assert float(printed[0]) == block.arrays["damage"].max()
"""),
    "ase_bpm.SphereVelocityVerlet(balls, timestep=0.001).run(4000)": ("""
def total(balls):
    return (balls.get_kinetic_energy() + ase_bpm.rotational_energy(balls)
            + balls.get_potential_energy() + balls.calc.results["dissipated_energy"])
start = total(balls)
""", """
import numpy as np
assert balls.info["bpm_step"] == 4000
contacts = int(printed[0].split()[0])
assert contacts == balls.arrays["ncontacts"].sum() // 2 > len(balls) // 2
# they fell into the box, turned by friction, and the energy ledger closes
r, x = balls.arrays["radius"], balls.positions
assert (x - r[:, None]).min() > -0.05 and (x[:, :2] + r[:, None]).max() < 7.05
assert x[:, 2].mean() < 0.7 * (1.0 + 2.5 * 1.25)
assert np.abs(balls.arrays["omega"]).max() > 0.1
dissipated = balls.calc.results["dissipated_energy"]
assert dissipated > 0.5 * (start - balls.get_potential_energy())
assert abs(total(balls) - start) < 3e-3 * dissipated  # O(dt^2)
"""),
    "stored = ase_bpm.calculator_from_dict(": ("", """
described = json.dumps(calc.todict())
assert [f["type"] for f in calc.todict()["fixes"]] == ["Gravity"]
for other in (again, stored):
    assert type(other) is ase_bpm.BPMSpring and json.dumps(other.todict()) == described
# the same forces bit for bit, a step on from the same state
moved = atoms.positions + 0.01 * np.sin(np.arange(atoms.positions.size)).reshape(-1, 3)
forces = []
for other in (calc, again, stored):
    copy = atoms.copy()
    copy.calc = other
    copy.positions = moved
    forces.append(copy.get_forces())
assert forces[0].any() and all(np.array_equal(f, forces[0]) for f in forces)
"""),
    "with ase_bpm.pure(atoms):": ("", """
assert printed[0] == "broken while relaxing: 0"
broken = int(printed[1].split(":")[1])
assert broken == len(atoms.info["broken_bonds"]) > 0
assert atoms.info["bpm_step"] == 1  # the relaxation was no step; calc.step was one
"""),
    "register(Harmonic)": ("", """
from ase import Atoms
atoms = Atoms("H2", positions=[[0, 0, 0], [1, 0, 0]], masses=[1, 1])
atoms.arrays["bonds"] = np.array(["1(1)", "_"])
atoms.calc = calc
atoms.get_forces()
atoms.positions[1, 0] = 1.02
assert abs(atoms.get_forces()[0, 0] - 0.02) < 1e-12
atoms.positions[1, 0] = 1.1  # past eps_c: breaks in this step
atoms.get_forces()
assert list(ase_bpm.get_bonds(atoms, include_broken=True)[2]) == [0]
"""),
    "ase_bpm.SphereVelocityVerlet(block, timestep=0.02)": ("", """
assert 0.02 <= float(printed[0])  # (within the estimate: no TimestepWarning either)
assert abs(block.arrays["quat"][0, 3]) > 0.01  # the spinning sphere turned about z
assert abs(np.linalg.norm(block.arrays["quat"], axis=1) - 1).max() < 1e-14
assert np.abs(block.calc.results["torques"]).max() > 0  # the bonds resist its turn
assert block.get_potential_energy() == 0.0 and not block.calc.ledger_balances
"""),
    'ase_bpm.write_lammps("pour", balls': ("", """
from pathlib import Path
assert Path("pour.data").exists() and "run 15000" in Path("in.pour").read_text()
assert np.array_equal(again.positions, balls.positions)
assert [f.todict() for f in again.calc.fixes] == [f.todict() for f in balls.calc.fixes]
assert type(again.calc) is ase_bpm.Granular
assert all(again.calc.todict()[key] == value for key, value in law.items())
"""),
}


#: the README's blocks run within the estimate, outside optimisers and on the
#: public paths: every warning of ase_bpm is an error there (put before the
#: block: -W options cannot name ase_bpm's classes, imported too late)
STRICT = """import warnings as _warnings
import ase_bpm as _ase_bpm
for _category in (_ase_bpm.TimestepWarning, _ase_bpm.OptimiserStepWarning,
                  _ase_bpm.NoBondsWarning, _ase_bpm.NoBondsCreatedWarning,
                  _ase_bpm.SpinNotIntegratedWarning, DeprecationWarning):
    _warnings.simplefilter("error", _category)
"""


def marker_of(block: str) -> str:
    found = [marker for marker in CHECKS if marker in block]
    assert len(found) == 1, f"{len(found)} markers of CHECKS in the README block:\n{block}"
    return found[0]


def test_every_readme_block_is_checked():
    """Each README block is run by exactly one entry of CHECKS, and each
    entry runs a block."""
    markers = [marker_of(block) for block in readme_blocks()]
    assert sorted(markers) == sorted(CHECKS)


@pytest.mark.parametrize("marker", list(CHECKS))
def test_readme_block_runs_as_pasted(marker, tmp_path):
    """The block, in a fresh interpreter, in an empty folder, in time."""
    block = next(block for block in readme_blocks() if marker in block)
    before, after = CHECKS[marker]
    head, tail = block.split(marker, 1)
    line_start = head.rfind("\n") + 1  # the checks' code goes before the whole line
    code = (CAPTURE + head[:line_start] + before.lstrip("\n") + head[line_start:] + marker
            + tail + RELEASE + after)
    run = subprocess.run([sys.executable, "-c", STRICT + code], cwd=tmp_path,
                         capture_output=True, text=True, timeout=BLOCK_SECONDS)
    assert run.returncode == 0, f"the README block failed:\n{block}\n{run.stderr}"
