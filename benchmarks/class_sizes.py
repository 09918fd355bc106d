"""Method definitions per calculator class, over its ase_bpm bases and its model's
(issue 31's measure of the step's machinery): python benchmarks/class_sizes.py"""
import inspect, ase_bpm
from ase.calculators.calculator import Calculator
for cls in (ase_bpm.BPMSpring, ase_bpm.BPMPeri, ase_bpm.Granular):
    total = 0; names=set(); per=[]
    classes = [c for c in cls.__mro__ if c.__module__.startswith("ase_bpm")]
    model = getattr(cls, "model_class", None)
    if model: classes += [c for c in model.__mro__ if c.__module__.startswith("ase_bpm")]
    for c in classes:
        defs = [k for k, v in vars(c).items() if inspect.isfunction(v) or isinstance(v, (property, staticmethod, classmethod))]
        per.append(f"{c.__name__} {len(defs)}"); total += len(defs); names |= set(defs)
    print(cls.__name__, "method definitions", total, "names", len(names), "|", ", ".join(per))
