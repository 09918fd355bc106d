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


def test_readme_usage_block_runs(tmp_path, monkeypatch):
    readme = (EXAMPLES.parent / "README.md").read_text()
    block = readme.split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(block, "README.md", "exec"), namespace)
    frames = read(tmp_path / "run.extxyz", ":")
    assert len(frames) == 21 and "damage" in frames[-1].arrays
    assert namespace["atoms"].info["bpm_step"] == 1000
