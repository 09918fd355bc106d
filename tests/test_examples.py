"""The examples run as the README shows them."""

import runpy
from pathlib import Path

import numpy as np
import pytest
from ase.io import read

import ase_bpm

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def test_quickstart(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    runpy.run_path(str(EXAMPLES / "quickstart.py"), run_name="__main__")
    frames = read(tmp_path / "quickstart.extxyz", ":")
    assert len(frames) == 13  # steps 0, 50, ..., 600
    assert frames[-1].arrays["damage"].max() > frames[0].arrays["damage"].max()
    assert "broken" in capsys.readouterr().out


def readme_blocks():
    readme = (EXAMPLES.parent / "README.md").read_text()
    return [part.split("```", 1)[0] for part in readme.split("```python\n")[1:]]


def readme_block(containing: str) -> str:
    """The README's one Python block that contains ``containing``."""
    found = [block for block in readme_blocks() if containing in block]
    assert len(found) == 1, f"{len(found)} README blocks contain {containing!r}"
    return found[0]


def test_readme_usage_block_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(readme_blocks()[0], "README.md", "exec"), namespace)
    frames = read(tmp_path / "run.extxyz", ":")
    assert len(frames) == 21 and "damage" in frames[-1].arrays
    assert namespace["atoms"].info["bpm_step"] == 1000


def test_readme_peridynamics_block_runs(capsys):
    namespace = {}
    exec(compile(readme_blocks()[1], "README.md", "exec"), namespace)
    block = namespace["block"]
    assert block.info["bpm_step"] == 300 and block.arrays["damage"].max() > 0.1
    assert float(capsys.readouterr().out) == block.arrays["damage"].max()


def test_readme_granular_block_runs(capsys):
    block = readme_blocks()[2]
    run = "SphereVelocityVerlet(balls"
    assert run in block

    def total(balls):
        return (balls.get_kinetic_energy() + ase_bpm.rotational_energy(balls)
                + balls.get_potential_energy() + balls.calc.results["dissipated_energy"])

    block = block.replace(run, "start = total(balls)\n" + run)
    namespace = {"total": total}
    exec(compile(block, "README.md", "exec"), namespace)
    balls = namespace["balls"]
    assert balls.info["bpm_step"] == 4000
    contacts = int(capsys.readouterr().out.split()[0])
    assert contacts == balls.arrays["ncontacts"].sum() // 2 > len(balls) // 2
    # they fell into the box, turned by friction, and the energy ledger closes
    r, x = balls.arrays["radius"], balls.positions
    assert (x - r[:, None]).min() > -0.05 and (x[:, :2] + r[:, None]).max() < 7.05
    assert x[:, 2].mean() < 0.7 * (1.0 + 2.5 * 1.25)
    assert np.abs(balls.arrays["omega"]).max() > 0.1
    dissipated = balls.calc.results["dissipated_energy"]
    assert dissipated > 0.5 * (namespace["start"] - balls.get_potential_energy())
    assert abs(total(balls) - namespace["start"]) < 3e-3 * dissipated  # O(dt^2)


def test_readme_bond_law_block_runs():
    """The README's own bond law registers and runs through BPMSpring."""
    from ase import Atoms

    import ase_bpm
    from ase_bpm.laws.bond import LAWS

    namespace = {"ase_bpm": ase_bpm}
    try:
        exec(compile(readme_block("register("), "README.md", "exec"), namespace)
        atoms = Atoms("H2", positions=[[0, 0, 0], [1, 0, 0]], masses=[1, 1])
        atoms.arrays["bonds"] = np.array(["1(1)", "_"])
        atoms.calc = namespace["calc"]
        atoms.get_forces()
        atoms.positions[1, 0] = 1.02
        assert atoms.get_forces()[0, 0] == pytest.approx(0.02)
        atoms.positions[1, 0] = 1.1  # past eps_c: breaks in this step
        atoms.get_forces()
        assert list(ase_bpm.get_bonds(atoms, include_broken=True)[2]) == [0]
    finally:
        LAWS.pop("harmonic", None)


def test_readme_lammps_block_runs(tmp_path, monkeypatch):
    """The README's way to LAMMPS and back: the files, and the same scene."""
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(readme_block("ase_bpm.write_lammps("), "README.md", "exec"), namespace)
    atoms, again = namespace["atoms"], namespace["again"]
    assert (tmp_path / "pour.data").exists() and "run 15000" in (tmp_path / "in.pour").read_text()
    assert np.array_equal(again.positions, atoms.positions)
    assert [f.todict() for f in again.calc.fixes] == [f.todict() for f in atoms.calc.fixes]
