"""The examples run as the README shows them."""

import runpy
from pathlib import Path

from ase.io import read

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
