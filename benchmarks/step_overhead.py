"""Per-step cost outside the force kernels, on the scenes of the --quick demos.

    python benchmarks/step_overhead.py [--scene impact|pour|all] [--repeats 3]
                                       [--steps N] [--json FILE]

Runs the scenes of ``ase-bpm demo impact --quick`` (BPMSpring, ASE's
VelocityVerlet, 1500 steps) and ``ase-bpm demo pour --quick`` (Granular,
SphereVelocityVerlet, 8000 steps), built by the demo modules, with no
trajectory, plot or progress bar, on one thread.  The setup evaluation is not
timed; each repeat builds a fresh scene.  Per step: the wall time (total), the
time inside the kernels, and the difference, the overhead:

* kernel: the time inside the callables listed in PROBES below: the force laws
  (bonds: spring_bonds in 0.1, SpringBond.forces in 0.2 and, on the compiled
  route, the C kernel as made ready per bond set, compiled.SpringBonds (before
  it, SpringBond.add_sums), which gathers and scatters too; contacts:
  compiled.SpringPairs (compiled.spring_pairs) on the compiled route, else
  spring_pairs in 0.1, the contact kernel contact_forces in 0.2, which also
  looks up per-pair coefficients, selects the touching pairs and sums the
  forces; granular pair_contacts and walls_contacts), the neighbour list builds
  (VerletList._pairs, SphereVerletList._pairs, only when a list is rebuilt)
  and the gathers and scatters of bond and pair forces (BondSet.vectors,
  VerletList.pair_vectors; 0.1: ``bonds.incidence @ f`` in
  BPMSpring._evaluate, BondSet.forces, scatter_pairs; 0.2: BondSet.geometry,
  vectors with their lengths, and BondSet.sum_forces, force vectors from
  magnitudes and their per-atom sums).  A probe called inside another is
  counted once, in the outer one.  0.2's kernels also compute the bond
  lengths, the breaking test and the selection of touching contacts, which
  0.1 did inline in BPMSpring._evaluate; to draw the same boundary in 0.1,
  measure it with ``benchmarks/v01_kernel_probes.patch`` applied (it moves
  those lines, unchanged, into three functions that PROBES then times):
  ``git worktree add ../v01 d1d6ebb && cd ../v01 && git apply
  <this repo>/benchmarks/v01_kernel_probes.patch``, install it in its own
  environment and run this script there.
* overhead: everything else in the step: the integrator's own arithmetic,
  ASE's property requests and the calculator's state checks (signatures,
  digests, velocities), bookkeeping on the atoms (bond sets, contact history,
  the record of the last evaluation, the ledger), the Verlet list's rebuild
  check and result assembly.

Each probe is a perf_counter accumulator put in place of ``owner.attribute``
(monkeypatched, restored afterwards); ``BondSet.incidence`` (a property) is
wrapped so that only ``incidence @ f`` is timed.  After a refactor that moves
these callables, point the PROBES table at their new homes: the roles (one
entry per force law, list build, gather and scatter) are what must be kept.
The probes cost a little themselves, so one run without them is reported too.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one thread: set before numpy is imported

import argparse
import functools
import json
import operator
import time

import numpy as np
from ase.md.verlet import VelocityVerlet

try:  # the modules of the layer folders (ase_bpm 0.2 on)
    import ase_bpm.models.spring as spring_model
    from ase_bpm.core.neighbours import SphereVerletList, VerletList
    from ase_bpm.laws import granular_kernels
    from ase_bpm.models.bonded import BondSet
    from ase_bpm.scene.demos import impact, pour
    from ase_bpm.scene.md import SphereVelocityVerlet
except ImportError:  # ase_bpm 0.1 (commit d1d6ebb), a flat package
    import ase_bpm.spring as spring_model
    from ase_bpm.bondstate import BondSet
    from ase_bpm.demos import impact, pour
    from ase_bpm.kernels import granular_kernels
    from ase_bpm.md import SphereVelocityVerlet
    from ase_bpm.neighbours import SphereVerletList, VerletList

GRANULAR = granular_kernels("auto")  # the module held by Granular and GranularWall
try:  # ase_bpm 0.2: laws as classes of the bond- and contact-law protocols
    from ase_bpm.laws.spring import SpringBond
    SPRING_BONDS = (SpringBond, "forces")
    # the compiled route (issue 16): one pass that gathers, computes and scatters
    from ase_bpm.laws import compiled as _compiled
    if hasattr(_compiled, "SpringBonds"):  # the kernels made ready per bond set and list
        COMPILED = {"compiled_spring_bonds": (_compiled.SpringBonds, "__call__"),
                    "compiled_spring_pairs": (_compiled.SpringPairs, "__call__")}
    else:
        COMPILED = ({"compiled_spring_bonds": (SpringBond, "add_sums"),
                     "compiled_spring_pairs": (_compiled, "spring_pairs")}
                    if hasattr(SpringBond, "add_sums") else {})
    # the contact kernel: coefficients, touching pairs, law and per-atom sums
    SPRING_PAIRS = (spring_model, "contact_forces")
except ImportError:  # ase_bpm 0.1: kernel functions looked up in its ase_bpm.spring
    SPRING_BONDS = (spring_model, "spring_bonds")
    SPRING_PAIRS = (spring_model, "spring_pairs")
    COMPILED = {}
#: name -> (owner, attribute): each kernel where it is looked up at run time
PROBES = {
    "spring_bonds": SPRING_BONDS,  # force law, bonds
    "spring_pairs": SPRING_PAIRS,  # force law, contacts
    **COMPILED,  # the same two on the compiled route, with their gathers and scatters
    "pair_contacts": (GRANULAR, "pair_contacts"),  # force law (+ its scatter), spheres
    "walls_contacts": (GRANULAR, "walls_contacts"),  # force law (+ its scatter), walls
    "verlet_build": (VerletList, "_pairs"),  # neighbour search (rebuilds only)
    "sphere_verlet_build": (SphereVerletList, "_pairs"),  # the same for spheres
    "bond_vectors": (BondSet, "vectors"),  # gather: x[j] - x[i] per bond
    # 0.2: bond vectors with the minimum image and lengths (0.1: inline in the model)
    **({"bond_geometry": (BondSet, "geometry")} if hasattr(BondSet, "geometry") else {}),
    "pair_vectors": (VerletList, "pair_vectors"),  # gather: x[j] - x[i] + shift per pair
    "bond_incidence_matmul": (BondSet, "incidence"),  # scatter: incidence @ f_bc
    "bond_forces": (BondSet, "forces"),  # scatter: per-atom sums of bond forces
    # ase_bpm 0.2: force vectors from magnitudes and their per-atom sums
    **({"bond_sum_forces": (BondSet, "sum_forces")} if hasattr(BondSet, "sum_forces")
       else {}),
    # scatter: pair forces (0.1; inside the contact kernel in 0.2)
    **({"scatter_pairs": (spring_model, "scatter_pairs")}
       if hasattr(spring_model, "scatter_pairs") else {}),
    # 0.1 with benchmarks/v01_kernel_probes.patch applied: the force-law work
    # 0.1 did inline in BPMSpring._evaluate (0.2's kernels do it), as functions
    **{name: (spring_model, name) for name in ("_m_lengths", "_m_criterion", "_m_select")
       if hasattr(spring_model, name)},
}
spent = dict.fromkeys(PROBES, 0.0)  # seconds inside each probe
_depth = [0]  # a probe inside another counts in the outer one only


def _timed(name, call):
    @functools.wraps(call)
    def probe(*args, **kwargs):
        if _depth[0]:
            return call(*args, **kwargs)
        _depth[0] += 1
        start = time.perf_counter()
        try:
            return call(*args, **kwargs)
        finally:
            spent[name] += time.perf_counter() - start
            _depth[0] -= 1
    return probe


class _TimedMatmul:
    """A sparse matrix whose ``@`` is timed; everything else goes to the matrix."""

    def __init__(self, matmul, matrix):
        self._matmul, self._matrix = matmul, matrix

    def __matmul__(self, other):
        return self._matmul(self._matrix, other)

    def __getattr__(self, attr):
        return getattr(self._matrix, attr)


def install():
    """Put the probes in place; return the originals, for restore()."""
    saved = {name: vars(owner)[attr] for name, (owner, attr) in PROBES.items()}
    for name, raw in saved.items():  # (a KeyError above: PROBES names a stale attribute)
        owner, attr = PROBES[name]
        if isinstance(raw, property):  # BondSet.incidence: its `@` only is timed
            matmul = _timed(name, operator.matmul)
            wrapped = property(lambda self, _m=matmul, _g=raw.fget: _TimedMatmul(_m, _g(self)))
        else:
            wrapped = _timed(name, raw)
        setattr(owner, attr, wrapped)
    return saved


def restore(saved):
    for name, raw in saved.items():
        setattr(*PROBES[name], raw)


def make_dyn(scene):
    """A fresh scene of ``ase-bpm demo <scene> --quick`` and its integrator."""
    if scene == "impact":
        atoms = impact.impact_scene(**impact.QUICK)
        atoms.calc = spring_model.BPMSpring(bond_coeffs=impact.BOND_COEFFS,
                                        pair_coeffs=impact.PAIR_COEFFS)
        return atoms, VelocityVerlet(atoms, timestep=impact.TIMESTEP)
    atoms = pour.pour_scene(**pour.QUICK)
    atoms.calc = pour.pour_calculator(pour.QUICK["width"])
    return atoms, SphereVelocityVerlet(atoms, pour.TIMESTEP)


def run(scene, steps, probes=True):
    """ms/step: total, in the kernels, and per probe."""
    atoms, dyn = make_dyn(scene)
    saved = install() if probes else {}
    try:
        atoms.get_forces()  # setup, untimed (as in bench_impact.py, bench_pour.py)
        spent.update(dict.fromkeys(spent, 0.0))
        start = time.perf_counter()
        dyn.run(steps)
        wall = time.perf_counter() - start
    finally:
        restore(saved)
    per_probe = {name: 1e3 * t / steps for name, t in spent.items() if t}
    return 1e3 * wall / steps, sum(per_probe.values()), per_probe


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="all", choices=("impact", "pour", "all"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, help="default: the demo's --quick step count")
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args()
    quick_steps = {"impact": impact.QUICK_STEPS, "pour": pour.QUICK_STEPS}
    print(f"granular kernels: {GRANULAR.__name__}; threads: {os.environ['OMP_NUM_THREADS']}")

    out = {}
    for scene in (("impact", "pour") if args.scene == "all" else (args.scene,)):
        steps = args.steps or quick_steps[scene]
        runs = [run(scene, steps) for _ in range(args.repeats)]
        bare = run(scene, steps, probes=False)[0]
        total, kernel = np.array([r[0] for r in runs]), np.array([r[1] for r in runs])
        figures = {"total": total, "kernel": kernel, "overhead": total - kernel}
        probes = {n: float(np.median([r[2].get(n, 0.0) for r in runs]))
                  for n in PROBES if any(n in r[2] for r in runs)}
        print(f"\n{scene}: {steps} steps, {args.repeats} repeats (ms/step)")
        print(f"{'':10s} {'median':>9s} {'min':>9s} {'max':>9s}")
        for k, v in figures.items():
            print(f"{k:10s} {np.median(v):9.4f} {v.min():9.4f} {v.max():9.4f}")
        print(f"kernel share {np.median(kernel / total):.1%}; without probes: total "
              f"{bare:.4f} ms/step (one run)")
        print("per probe (median): " + ", ".join(f"{n} {t:.4f}" for n, t in probes.items()))
        out[scene] = {"steps": steps, "repeats": args.repeats, "uninstrumented_total": bare,
                      "probes": probes, "unit": "ms/step",
                      **{k: {"median": float(np.median(v)), "min": float(v.min()),
                             "max": float(v.max()), "runs": v.tolist()}
                         for k, v in figures.items()}}
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()
