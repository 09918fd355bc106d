"""What the integrators cost by themselves: ASE's VelocityVerlet against
ase_bpm's SphereVelocityVerlet, driving a calculator that costs nothing.

    python benchmarks/integrator_cost.py [--sizes 500 3000] [--steps 3000] [--repeats 5]

The calculator returns fixed, non-zero forces and torques (so the spheres'
rotation is integrated too) and checks its state with one array comparison,
so what is timed is the integrator: ASE's ``VelocityVerlet`` moving points,
``SphereVelocityVerlet`` (LAMMPS ``fix nve/sphere``) moving and turning
spheres.  Issue 16's budget: the sphere integrator within 2 times ASE's at the
same size.  Prints the median ms/step of each (runs alternate) and the ratio.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one thread: set before numpy is imported

import argparse
import time

import numpy as np
from ase import Atoms
from ase.calculators.calculator import Calculator
from ase.md.verlet import VelocityVerlet

from ase_bpm import SphereVelocityVerlet


class FixedForces(Calculator):
    """Fixed non-zero forces and torques, at no cost."""

    implemented_properties = ["energy", "forces", "torques"]

    def __init__(self, n: int, seed: int = 0):
        super().__init__()
        rng = np.random.default_rng(seed)
        self.f_nc, self.t_nc = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
        self._x_nc = None

    def check_state(self, atoms, tol=0.0):
        return [] if np.array_equal(self._x_nc, atoms.positions) else ["positions"]

    def calculate(self, atoms=None, properties=("energy",), system_changes=()):
        self._x_nc = atoms.positions.copy()
        self.results = {"energy": 0.0, "forces": self.f_nc, "torques": self.t_nc}


def spheres(n: int) -> Atoms:
    atoms = Atoms(f"Ar{n}", positions=np.random.default_rng(1).uniform(0.0, 10.0, (n, 3)))
    atoms.arrays["radius"] = np.full(n, 0.5)
    atoms.arrays["omega"] = np.zeros((n, 3))
    atoms.calc = FixedForces(n)
    return atoms


def ms_per_step(integrator, n: int, steps: int) -> float:
    atoms = spheres(n)
    dyn = integrator(atoms, 1e-5)
    dyn.run(10)  # warm-up, untimed
    start = time.perf_counter()
    dyn.run(steps)
    return 1e3 * (time.perf_counter() - start) / steps


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[500, 3000])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(f"{'atoms':>6} {'ASE VelocityVerlet':>19} {'SphereVelocityVerlet':>21} {'ratio':>6}"
          "   (ms/step, median)")
    for n in args.sizes:
        times = {VelocityVerlet: [], SphereVelocityVerlet: []}
        for _ in range(args.repeats):
            for integrator in times:
                times[integrator].append(ms_per_step(integrator, n, args.steps))
        ase_ms, sphere_ms = (float(np.median(t)) for t in times.values())
        print(f"{n:>6} {ase_ms:>19.4f} {sphere_ms:>21.4f} {sphere_ms / ase_ms:>6.2f}")


if __name__ == "__main__":
    main()
