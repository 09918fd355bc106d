"""The public API: what ``ase_bpm`` exports, plus ``ase_bpm.laws.bond``.

The import paths of ase_bpm 0.1 (``ase_bpm.md``...) resolve to the same
module objects as their homes, each with a DeprecationWarning naming the
public path, and only when used; nothing outside the package (README, docs,
examples, tests, benchmarks) uses them.
"""

import ast
import copy
import importlib
import importlib.util
import pickle
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import ase_bpm
from ase_bpm.core.old_paths import OLD_PATHS

ROOT = Path(__file__).resolve().parent.parent
#: what the README and examples need from ase_bpm besides the models (issue 29)
NEEDED = ("VelocityVerlet", "SphereVelocityVerlet", "calculator_from_dict", "register_fix",
          "with_bond_strings", "set_threads")
#: the one public module besides the package
PUBLIC_MODULES = ("ase_bpm.laws.bond",)


def forget(old: str) -> None:
    """Undo an old path's resolution in this process (the import machinery
    keeps it in sys.modules and on its parent), so that it resolves anew."""
    for name in list(sys.modules):
        if name == f"ase_bpm.{old}" or name.startswith(f"ase_bpm.{old}."):
            del sys.modules[name]
    vars(ase_bpm).pop(old.split(".")[0], None)


@pytest.fixture
def old_paths_forgotten():
    for old in OLD_PATHS:
        forget(old)
    yield
    for old in OLD_PATHS:
        forget(old)


def public_names_in(message: str):
    return re.findall(r"\b(ase_bpm(?:\.\w+)+)", message)


def test_the_public_names():
    assert sorted(ase_bpm.__all__, key=str.lower) == ase_bpm.__all__
    assert set(NEEDED) <= set(ase_bpm.__all__)
    for name in ase_bpm.__all__:
        assert getattr(ase_bpm, name).__module__.startswith("ase_bpm."), name
    from ase_bpm.laws.bond import BondForces, BondLaw, register  # noqa: F401


@pytest.mark.parametrize("old", list(OLD_PATHS))
def test_an_old_path_warns_naming_the_public_path_and_is_its_home(old, old_paths_forgotten):
    home = importlib.import_module(f"ase_bpm.{OLD_PATHS[old][0]}")
    spec = home.__spec__
    with pytest.warns(DeprecationWarning) as record:
        module = importlib.import_module(f"ase_bpm.{old}")
    assert module is home and module.__spec__ is spec and module.__name__ == spec.name
    message = next(str(w.message) for w in record
                   if str(w.message).startswith(f"ase_bpm.{old} is deprecated: "))
    named = public_names_in(message.split(": ", 1)[1])
    assert named or "the ase-bpm" in message, message  # names, or the command line
    for name in named:  # a public name, or the home of an internal module
        public = (name.startswith("ase_bpm.") and name.split(".", 1)[1] in ase_bpm.__all__
                  or name in PUBLIC_MODULES)
        assert public or (name == home.__name__ and "internal" in message), message
    if "." not in old:  # as an attribute of the package, too
        forget(old)
        with pytest.warns(DeprecationWarning, match=re.escape(f"ase_bpm.{old} is deprecated")):
            assert getattr(ase_bpm, old) is home


def test_old_imports_warn_at_the_importing_line(old_paths_forgotten):
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        from ase_bpm.md import VelocityVerlet  # noqa: F401
        line = sys._getframe().f_lineno - 1
    assert [(w.category, w.filename, w.lineno) for w in record] == \
        [(DeprecationWarning, __file__, line)]
    assert str(record[0].message) == ("ase_bpm.md is deprecated: use ase_bpm.VelocityVerlet "
                                      "and ase_bpm.SphereVelocityVerlet")
    assert VelocityVerlet is ase_bpm.VelocityVerlet
    forget("fixes")
    with pytest.warns(DeprecationWarning, match="ase_bpm.fixes is deprecated: use "
                                                "ase_bpm.SphericalIndenter"):
        from ase_bpm import fixes
    assert fixes.Gravity is ase_bpm.Gravity


def test_a_module_below_an_old_package_path_is_its_home(old_paths_forgotten):
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        from ase_bpm.kernels.bond import BondLaw
    assert [str(w.message).split(": ", 1) for w in record] == [
        ["ase_bpm.kernels is deprecated", "use ase_bpm.laws.bond (a bond law of your own) and "
         "ase_bpm.set_threads; the rest of it is internal"],
        ["ase_bpm.kernels.bond is deprecated", "use ase_bpm.laws.bond"]]
    from ase_bpm.laws.bond import BondLaw as home

    assert BondLaw is home


def test_a_name_that_is_no_old_path_is_no_attribute():
    with pytest.raises(AttributeError, match="module 'ase_bpm' has no attribute 'mdx'"):
        ase_bpm.mdx
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("ase_bpm.mdx")


def test_a_fresh_import_registers_no_old_path_and_warns_of_nothing():
    script = ("import sys, ase_bpm\n"
              "print([m for m in sys.modules if m.startswith('ase_bpm.')"
              " and m.split('.')[1] not in ('core', 'laws', 'models', 'scene')])\n"
              "print([name for name in ('md', 'fixes', 'kernels') if name in vars(ase_bpm)])\n")
    run = subprocess.run([sys.executable, "-W", "error::DeprecationWarning", "-c", script],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split("\n")[:2] == ["[]", "[]"]


def test_set_threads_without_the_compiled_kernels():
    """``ase_bpm.set_threads`` imports and works where the kernels are not built."""
    script = ("import sys, warnings\n"
              "sys.modules['ase_bpm.laws._kernels'] = None  # as if never built\n"
              "import ase_bpm\n"
              "from ase_bpm.laws import compiled\n"
              "assert not compiled.available\n"
              "assert ase_bpm.set_threads(2) is None and compiled.threads() == 1\n"
              "assert ase_bpm.set_threads(None) == 2\n")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 0, run.stderr


def test_objects_pickle_and_copy_by_their_homes(old_paths_forgotten):
    with pytest.warns(DeprecationWarning):
        import ase_bpm.fixes  # noqa: F401  (an old path in use changes nothing)
    for name in ase_bpm.__all__:
        value = getattr(ase_bpm, name)
        if isinstance(value, type):
            assert "ase_bpm.fixes" not in value.__module__
            assert pickle.loads(pickle.dumps(value)) is value
    gravity = ase_bpm.Gravity(2.0, (1.0, 0.0, 0.0))
    for again in (pickle.loads(pickle.dumps(gravity)), copy.deepcopy(gravity)):
        assert type(again) is ase_bpm.Gravity and again.todict() == gravity.todict()
    assert b"ase_bpm.scene.fixes" in pickle.dumps(gravity)


# -- no old path outside the package ------------------------------------------------

OLD = re.compile(r"\base_bpm\.(" + "|".join(sorted(map(re.escape, OLD_PATHS), key=len,
                                                    reverse=True)) + r")\b")
#: this file uses the old paths on purpose
ON_PURPOSE = {Path(__file__).resolve()}


def dotted(node):
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        return ".".join([node.id, *reversed(parts)])
    return None


def old_uses(path: Path):
    """(line, name) of each old path the Python file imports or reads as an
    attribute, except in the handlers of ``except ImportError`` (a fallback
    for measuring ase_bpm 0.1)."""
    tree = ast.parse(path.read_text())
    fallback = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ExceptHandler) and dotted(node.type or ast.Name("")) == \
                "ImportError":
            fallback.update(id(inner) for inner in ast.walk(node))
    for node in ast.walk(tree):
        if id(node) in fallback:
            continue
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            names = [node.module or ""] + [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Attribute):
            names = [dotted(node) or ""]
        for name in names:
            if OLD.match(name) and not name.startswith(("ase_bpm.core", "ase_bpm.laws",
                                                        "ase_bpm.models", "ase_bpm.scene")):
                yield node.lineno, name


def test_the_check_sees_old_uses(tmp_path):
    script = tmp_path / "x.py"
    script.write_text("import ase_bpm.md\nfrom ase_bpm.fixes import Gravity\n"
                      "ase_bpm.lammps.write_lammps\nimport ase_bpm.scene.md\n"
                      "try:\n    import ase_bpm.scene.md\nexcept ImportError:\n"
                      "    import ase_bpm.md\n")
    assert sorted({line for line, _ in old_uses(script)}) == [1, 2, 3]


@pytest.mark.parametrize("folder", ["examples", "tests", "benchmarks"])
def test_no_old_path_in_python_files(folder):
    found = [f"{path.name}:{line}: {name}"
             for path in sorted((ROOT / folder).glob("*.py")) if path.resolve() not in ON_PURPOSE
             for line, name in old_uses(path)]
    assert not found, found


def test_no_old_path_in_the_readme_and_docs():
    found = [f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
             for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
             for number, line in enumerate(path.read_text().splitlines(), 1)
             if OLD.search(line)]
    assert not found, found


def test_an_old_path_without_a_home_is_not_found(old_paths_forgotten):
    """find_spec of a module below an old package path that has no home gives
    None (the parent's warning only), and importing it fails by its own name."""
    with pytest.warns(DeprecationWarning, match="ase_bpm.kernels is deprecated"):
        assert importlib.util.find_spec("ase_bpm.kernels.nonexistent") is None
    with pytest.raises(ModuleNotFoundError, match="No module named 'ase_bpm.kernels.nonexistent'"):
        importlib.import_module("ase_bpm.kernels.nonexistent")


def test_an_old_paths_loader_answers_for_its_home(old_paths_forgotten):
    """What tools ask a loader (runpy, inspect) is answered for the home."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # finding is no import: no warning
        spec = importlib.util.find_spec("ase_bpm.demos")
    home = importlib.util.find_spec("ase_bpm.scene.demos")
    assert spec.origin == home.origin
    assert spec.loader.is_package("ase_bpm.demos") and not spec.loader.is_package("ase_bpm.md")
    assert spec.loader.get_source("ase_bpm.md") == Path(ROOT, "ase_bpm/scene/md.py").read_text()


def test_python_m_of_an_old_path_runs_its_home_with_the_warning(tmp_path):
    run = subprocess.run([sys.executable, "-m", "ase_bpm.cli", "--version"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().endswith(ase_bpm.__version__)
    assert "DeprecationWarning: ase_bpm.cli is deprecated: use the ase-bpm command" in run.stderr
