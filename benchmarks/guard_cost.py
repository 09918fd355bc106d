"""What the blow-up guard costs: the impact scene with the guard on and off.

    python benchmarks/guard_cost.py [--steps 1500] [--repeats 5] [--quick]

Runs the scene of ``ase-bpm demo impact`` (BPMSpring, ASE's VelocityVerlet,
11,118 particles; ``--quick``: 1,648) with ``guard=True`` (the default) and
``guard=False``, alternately, ``--repeats`` times each on one thread, after an
untimed setup evaluation, and prints the median ms/step of each and the
guard's share of a step.  The issue's budget: at most 2 %.  The guard checks
every step for non-finite forces, torques and energies, the kinetic energy's
growth and the step's energy ledger, and compares the timestep with
``stable_timestep`` at the first step and every ``STABILITY_EVERY`` steps.
The first step, where the first estimate is made, is timed apart: the share
is given of the steps after it (the per-step cost) and of the whole run.
The guard's own time, ``Guard.check`` timed by a probe (``engines.Probes``)
with the guard on and off (off, it still watches for optimiser steps), is
given beside: on a machine whose step times spread by more than the
guard's share, that difference is the steadier measure of its cost.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one thread: set before numpy is imported

import argparse
import time

import numpy as np
from ase.md.verlet import VelocityVerlet

import engines
from ase_bpm import BPMSpring
from ase_bpm.models.guard import Guard
from ase_bpm.scene.demos import impact


def run(steps: int, guard: bool, quick: bool) -> tuple:
    """One fresh run: (ms of its first step, ms/step of the ``steps`` after
    it, ms/step of ``Guard.check`` in those steps)."""
    atoms = impact.impact_scene(**(impact.QUICK if quick else impact.FULL))
    atoms.calc = BPMSpring(bond_coeffs=impact.BOND_COEFFS, pair_coeffs=impact.PAIR_COEFFS,
                           guard=guard)
    atoms.get_forces()  # setup, untimed
    dyn = VelocityVerlet(atoms, timestep=impact.TIMESTEP)
    start = time.perf_counter()
    dyn.run(1)
    first = time.perf_counter()
    dyn.run(steps)
    per_step = 1e3 * (time.perf_counter() - first) / steps
    probes = engines.Probes({"guard": (Guard, "check")})  # (a second, probed run on)
    try:
        dyn.run(steps)
    finally:
        probes.remove()
    return 1e3 * (first - start), per_step, 1e3 * probes.seconds["guard"] / steps


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="the --quick scene, 1,648 particles")
    args = ap.parse_args()
    times = {True: [], False: []}
    firsts = {True: [], False: []}
    checks = {True: [], False: []}
    for _ in range(args.repeats):
        for guard in (True, False):
            first, per_step, check = run(args.steps, guard, args.quick)
            firsts[guard].append(first)
            times[guard].append(per_step)
            checks[guard].append(check)
    on, off = np.median(times[True]), np.median(times[False])
    first_on, first_off = np.median(firsts[True]), np.median(firsts[False])
    print(f"impact{' --quick' if args.quick else ''}, a first step and {args.steps} "
          f"steps after it, {args.repeats} runs each (median)")
    print(f"guard on  {on:8.4f} ms/step   runs {np.round(times[True], 4).tolist()}; "
          f"first step {first_on:.2f} ms")
    print(f"guard off {off:8.4f} ms/step   runs {np.round(times[False], 4).tolist()}; "
          f"first step {first_off:.2f} ms")
    print(f"guard's share of a step after the first: {(on - off) / off:+.2%} (budget 2 %)")
    whole_on, whole_off = first_on + on * args.steps, first_off + off * args.steps
    print(f"guard's share of the whole run, its first estimate included: "
          f"{(whole_on - whole_off) / whole_off:+.2%}")
    check_on, check_off = np.median(checks[True]), np.median(checks[False])
    print(f"Guard.check, ms/step in {args.steps} further steps (probed): on {check_on:.4f}, "
          f"off {check_off:.4f}; the difference is {(check_on - check_off) / off:.2%} "
          f"of a step with the guard off")


if __name__ == "__main__":
    main()
