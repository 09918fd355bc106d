"""How big the step's machinery is, class by class (issue 31's measure).

    python benchmarks/class_sizes.py

For each public calculator: the methods (functions, properties, static and
class methods) defined in each of its ase_bpm classes, the calculator's own
bases up to ASE's ``Calculator`` and, apart, those of the model it holds
(``calc.model``, of its class ``model_class``) and the model's bases; and the lines of each module of
``ase_bpm/models``.  A count of definitions, not of calls: calls per step are
``benchmarks/calls_per_step.py``'s.
"""

from __future__ import annotations

import inspect
from pathlib import Path

import ase_bpm

CALCULATORS = (ase_bpm.BPMSpring, ase_bpm.BPMPeri, ase_bpm.Granular)


def own_methods(cls) -> list:
    """The names of the methods ``cls`` itself defines."""
    return [name for name, value in vars(cls).items()
            if inspect.isfunction(value) or isinstance(value, (property, staticmethod,
                                                                classmethod))]


def chain(cls) -> list:
    """``cls`` and its bases that belong to ase_bpm, most derived first."""
    return [c for c in cls.__mro__ if c.__module__.startswith("ase_bpm")]


def describe(classes) -> str:
    counts = [(c.__name__, len(own_methods(c))) for c in classes]
    total = sum(n for _, n in counts)
    return f"{total:4d} ({', '.join(f'{name} {n}' for name, n in counts)})"


def main() -> None:
    for cls in CALCULATORS:
        model = cls.model_class
        print(f"{cls.__name__}: calculator {describe(chain(cls))}; "
              f"model {describe(chain(model))}")
    print()
    for path in sorted((Path(ase_bpm.__file__).parent / "models").glob("*.py")):
        print(f"{len(path.read_text().splitlines()):6d}  models/{path.name}")


if __name__ == "__main__":
    main()
