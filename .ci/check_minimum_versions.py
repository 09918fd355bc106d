"""Fail unless .ci/minimum-versions.txt pins every direct dependency of
pyproject.toml (the test extra's included) to the lower bound stated there,
and this environment has exactly those versions installed."""

import sys
import tomllib
from importlib.metadata import version
from pathlib import Path

from packaging.requirements import Requirement
from packaging.version import Version

ROOT = Path(__file__).resolve().parent.parent
project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
requirements = [Requirement(text) for text in
                project["dependencies"] + project["optional-dependencies"]["test"]]
pins = {}
for line in (ROOT / ".ci/minimum-versions.txt").read_text().splitlines():
    if line.strip() and not line.startswith("#"):
        name, pinned = line.split("==")
        pins[name.strip()] = Version(pinned)

problems = []
for requirement in requirements:
    bounds = [Version(s.version) for s in requirement.specifier if s.operator in (">=", "==")]
    pinned = pins.get(requirement.name)
    if not bounds or pinned != bounds[0]:
        problems.append(f"{requirement}: pinned to {pinned}, lower bound "
                        f"{bounds[0] if bounds else 'none'}")
    elif Version(version(requirement.name)) != pinned:
        problems.append(f"{requirement}: {version(requirement.name)} installed, not {pinned}")
    else:
        print(f"{requirement.name}=={version(requirement.name)}")
if problems:
    sys.exit("minimum versions:\n  " + "\n  ".join(problems))
