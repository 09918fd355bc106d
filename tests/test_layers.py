"""The package's layers import one way: core -> laws -> models -> scene.

Every module of ``ase_bpm`` sits in the folder of its layer; a module may
import from its own layer and those before it, never from one after it.  The
package's ``__init__`` (the public names, and the table of old import paths)
stands above all four.
"""

import ast
from pathlib import Path

import pytest

import ase_bpm

PACKAGE = Path(ase_bpm.__file__).parent
LAYERS = ("core", "laws", "models", "scene")


def layer_of(module: str):
    """``ase_bpm.models.spring`` -> ``models``; None for the package itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS else None


def modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        yield name, path


def imported(name: str, path: Path):
    """Every ase_bpm module that the file imports (at any depth of the code)."""
    is_package = path.name == "__init__.py"
    here = name.split(".") if is_package else name.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[:len(here) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.startswith("ase_bpm"):
                yield target, node.lineno
                for alias in node.names:  # "from . import compiled" names modules too
                    yield f"{target}.{alias.name}", node.lineno
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("ase_bpm"):
                    yield alias.name, node.lineno


def test_every_module_sits_in_a_layer():
    loose = [name for name, _ in modules() if name != "ase_bpm" and layer_of(name) is None]
    assert not loose, f"modules outside the layer folders {LAYERS}: {loose}"


@pytest.mark.parametrize("name,path", list(modules()), ids=lambda x: str(x))
def test_no_import_from_a_layer_above(name, path):
    mine = layer_of(name)
    if mine is None:
        return  # the package's __init__ stands above every layer
    for target, line in imported(name, path):
        theirs = layer_of(target)
        assert theirs is not None, (f"{name} imports {target} at line {line}: modules "
                                    "import from the layer folders, not from the package "
                                    "facade or its old paths")
        assert LAYERS.index(theirs) <= LAYERS.index(mine), \
            f"{name} ({mine}) imports {target} ({theirs}) at line {line}"


def test_the_check_sees_an_upward_import(tmp_path):
    """The checker itself finds a violation (a test that cannot fail is no test)."""
    bad = tmp_path / "bad.py"
    bad.write_text("from ..scene.fixes import Gravity\n")
    found = list(imported("ase_bpm.core.bad", bad))
    assert ("ase_bpm.scene.fixes", 1) in found
    assert LAYERS.index(layer_of(found[0][0])) > LAYERS.index("core")
