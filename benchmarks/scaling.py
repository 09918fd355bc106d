"""How ase_bpm and LAMMPS scale with the particle count, one core each.

    python benchmarks/scaling.py [--sizes 1e3,1.1e4,1e5,1e6] [--repeats 3]
                                 [--seconds 3] [--quick] [--threads 1]

The scene is the README's usage example grown to a cube: a jittered FCC
block at reduced density 1 (FCC n x n x n, n = round((N/4)^(1/3)), so
1e3 -> 864, 1.1e4 -> 10,976, 1e5 -> 97,556, 1e6 -> 1,000,188 particles),
uniform jitter of 0.1, masses 1, velocities normal(0, 0.05), bonds between
every pair closer than 1.5 (``create_bonds``), ``BPMSpring`` with the
README's coefficients (bond 1.0 0.04 1.0, pair 1 1 1.0 1.0 1.0), the guard on
as a user gets it, ASE's ``VelocityVerlet`` at timestep 0.1.  LAMMPS runs the
very same scene, exported with ``ase_bpm.scene.lammps`` (``bond_style`` and
``pair_style bpm/spring``, ``fix nve``, the same skin and timestep).

Each engine at each size runs in its own subprocess with one thread
(``OMP_NUM_THREADS=1`` and friends; LAMMPS without MPI ranks; the machinery
is ``engines.py``), so the peak memory (VmHWM of the child) is that engine's
alone; the LAMMPS data file is written by a third subprocess. Setup (building
and bonding the scene or reading the data file, the first force evaluation or
``run 0``) is not timed; a first step and a short calibration run (also
untimed; ase_bpm's guard makes its first ``stable_timestep`` check there) pick
the steps so that each timed run takes about ``--seconds``. ``--repeats``
timed runs follow one another on the same trajectory in the same child; the
table gives ms/step as median (min-max), the median ns per particle-step, the
ratio ase_bpm/LAMMPS (of the medians), peak memory, and the growth of ns per
particle-step relative to the smallest size run.  Under it, for each size,
the parts of a step (``engines.py``, as ``bench_impact.py`` prints them):
LAMMPS's own timing breakdown from the log of each timed run (Pair, Bond,
Neigh, Comm, Output, Modify, Other, its neighbour-list builds) and
ase_bpm's parts, timed by perf_counter probes (``engines.spring_probes``:
the bond kernel, the contact kernel, the contact list with its rebuilds,
matscipy's search and the removal of the bonded pairs, and the rest). ``--quick``: sizes up to
1e5, one repeat. Timings are indicative when another process shares the
machine. At 1e6 particles ase_bpm takes about 0.2 s a step and 1.5 GB: a
timed run of a few dozen steps may or may not hold a neighbour-list rebuild
(or a shedding of broken bonds), so its runs spread; give it ``--seconds 30``
or more there for a steadier median.

``--threads n``: ase_bpm's compiled bond and pair kernels on n threads
(``ase_bpm.laws.compiled.set_threads``; the rest of ase_bpm, NumPy's BLAS and
LAMMPS stay on one).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

import engines

SIZES = (1e3, 1.1e4, 1e5, 1e6)
QUICK_SIZES = (1e3, 1.1e4, 1e5)
FCC = 4 ** (1 / 3)  # LAMMPS "lattice fcc 1.0": reduced density 1
BOND_COEFFS = {1: (1.0, 0.04, 1.0)}  # k, eps_c, gamma (the README's usage example)
PAIR_COEFFS = {(1, 1): (1.0, 1.0, 1.0)}  # k, r_c, gamma
TIMESTEP = 0.1
#: the parts of an ase_bpm step timed by probes, and those timed inside another
PROBES, WITHIN = engines.spring_probes()


def cells(particles: float) -> int:
    """FCC cells per side of the cube closest to ``particles`` (4 per cell)."""
    return max(1, round((particles / 4) ** (1 / 3)))


def readme_block(n: int):
    """The README's usage example on an n x n x n FCC cube, bonded."""
    from ase.lattice.cubic import FaceCenteredCubic

    import ase_bpm

    atoms = FaceCenteredCubic("Ne", size=(n, n, n), latticeconstant=FCC, pbc=False)
    atoms.positions += np.random.default_rng(0).uniform(-0.1, 0.1, atoms.positions.shape)
    atoms.set_masses(np.ones(len(atoms)))
    atoms.set_velocities(np.random.default_rng(1).normal(0, 0.05, (len(atoms), 3)))
    ase_bpm.create_bonds(atoms, 1.5, bond_type=1)
    return atoms


def readme_calculator():
    from ase_bpm import BPMSpring

    return BPMSpring(bond_coeffs=BOND_COEFFS, pair_coeffs=PAIR_COEFFS)


def calibrated_steps(advance, seconds: float) -> int:
    """Calibrate (untimed) with ``advance(steps)``: the steps that take about
    ``seconds``.  A first step, apart, takes the one-off costs (ase_bpm's
    guard estimates ``stable_timestep`` there: several steps' worth at 1e6
    particles)."""
    advance(1)
    steps, spent = 2, 0.0
    while spent < 0.3 * seconds and steps < 100000:
        spent = engines.timed(advance, steps)
        per_step = spent / steps
        steps *= 4
    return max(5, round(seconds / per_step))


# -- the children -------------------------------------------------------------------

def child_ase(args) -> dict:
    from ase.md.verlet import VelocityVerlet

    from ase_bpm import get_bonds
    from ase_bpm.laws import compiled

    compiled.set_threads(args.threads)
    start = time.perf_counter()
    atoms = readme_block(args.cells)
    bonded = time.perf_counter() - start
    atoms.calc = readme_calculator()
    dyn = VelocityVerlet(atoms, timestep=TIMESTEP)
    atoms.get_forces()  # the first evaluation: setup, as LAMMPS' run 0
    setup = time.perf_counter() - start
    bonds = len(get_bonds(atoms)[0])
    steps = calibrated_steps(dyn.run, args.seconds)
    runs = []
    for _ in range(args.repeats):
        seconds, cpu, probes = engines.probed_run(dyn.run, steps, PROBES)
        runs.append(dict(seconds=seconds, cpu=cpu, parts=probes.seconds, calls=probes.calls))
    return dict(particles=len(atoms), bonds=bonds, steps=steps, runs=runs,
                ms=[1e3 * r["seconds"] / steps for r in runs],
                build_s=bonded, setup_s=setup, peak_mb=engines.peak_memory_mb())


def child_write(args) -> dict:
    """The LAMMPS data file and commands of the scene (not measured)."""
    from ase_bpm.scene.lammps import lammps_commands, lammps_data

    atoms = readme_block(args.cells)
    calc = readme_calculator()
    with open(args.data, "w") as fh:
        fh.write(lammps_data(atoms, calc))
    return dict(commands=lammps_commands(atoms, calc, args.data, timestep=TIMESTEP))


def child_lammps(args) -> dict:
    with open(args.commands) as fh:
        commands = json.load(fh)
    start = time.perf_counter()
    lmp = engines.new_lammps()
    lmp.commands_list([*commands, "thermo 0", "run 0"])
    setup = time.perf_counter() - start
    particles, bonds = lmp.get_natoms(), int(lmp.extract_global("nbonds"))
    steps = calibrated_steps(lambda n: lmp.command(f"run {n} pre no post no"), args.seconds)
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeats):
            seconds, cpu, breakdown = engines.timed_lammps_run(
                lmp, steps, os.path.join(tmp, "lammps.log"), "pre no")
            runs.append(dict(seconds=seconds, cpu=cpu, breakdown=breakdown))
    lmp.close()
    return dict(particles=particles, bonds=bonds, steps=steps, runs=runs,
                ms=[1e3 * r["seconds"] / steps for r in runs], setup_s=setup,
                peak_mb=engines.peak_memory_mb())


CHILDREN = {"ase_bpm": child_ase, "write": child_write, "lammps": child_lammps}


# -- the parent ---------------------------------------------------------------------

def spawn(role: str, n: int, args, **extra) -> dict:
    """Run one child (this script with ``--child role``, :func:`engines.spawn`)
    on ``n``^3 cells; ``extra`` options go to it as ``--key value``."""
    options = ["--cells", str(n), "--seconds", str(args.seconds),
               "--repeats", str(args.repeats)]
    for key, value in extra.items():
        options += [f"--{key}", value]
    return engines.spawn(__file__, role, options)


def measure(n: int, args) -> dict:
    print(f"FCC {n}^3 cells ...", file=sys.stderr, flush=True)
    ours = spawn("ase_bpm", n, args, threads=str(args.threads))
    with tempfile.TemporaryDirectory() as tmp:
        data, commands = os.path.join(tmp, "scene.data"), os.path.join(tmp, "scene.json")
        start = time.perf_counter()
        written = spawn("write", n, args, data=data)
        export_s = time.perf_counter() - start
        with open(commands, "w") as fh:
            json.dump(written["commands"], fh)
        theirs = spawn("lammps", n, args, commands=commands)
    if (ours["particles"], ours["bonds"]) != (theirs["particles"], theirs["bonds"]):
        raise RuntimeError(f"scenes differ: ase_bpm {ours}, LAMMPS {theirs}")
    return dict(ase=ours, lmp=theirs, export_s=export_s)


def report(rows: list[dict], repeats: int):
    def ns(r, e):
        return 1e6 * np.median(r[e]["ms"]) / r[e]["particles"]

    print(f"\nms/step, median (min-max) of {repeats} run(s); ns per particle-step from "
          "the median; ratio: of the medians; growth: ns per particle-step / that of "
          "the smallest size")
    head = (f"{'particles':>9s} {'bonds':>9s} {'steps a/L':>11s} "
            f"{'ase_bpm ms/step':>27s} {'LAMMPS ms/step':>27s} "
            f"{'ns/p-step a':>11s} {'ns/p-step L':>11s} "
            f"{'ratio':>6s} {'peak MB a':>9s} {'peak MB L':>9s} {'growth a':>8s} "
            f"{'growth L':>8s}")
    print(head)
    base = rows[0]
    for r in rows:
        a, lm = r["ase"], r["lmp"]
        print(f"{a['particles']:9d} {a['bonds']:9d} {a['steps']:>5d}/{lm['steps']:<5d} "
              f"{engines.spread(a['ms']):>27s} {engines.spread(lm['ms']):>27s} "
              f"{ns(r, 'ase'):11.1f} {ns(r, 'lmp'):11.1f} "
              f"{ns(r, 'ase') / ns(r, 'lmp'):6.2f} "
              f"{a['peak_mb']:9.0f} {lm['peak_mb']:9.0f} "
              f"{ns(r, 'ase') / ns(base, 'ase'):8.2f} {ns(r, 'lmp') / ns(base, 'lmp'):8.2f}")
    for r in rows:
        a, lm = r["ase"], r["lmp"]
        print(f"\n{a['particles']:,} particles, {a['bonds']:,} bonds: the parts of a step "
              f"(timed runs of {a['steps']} steps in ase_bpm, {lm['steps']} in LAMMPS)")
        print("\n".join(engines.breakdown_lines(lm["runs"], lm["steps"])))
        print("\n".join(engines.parts_lines(a["runs"], a["steps"], PROBES, WITHIN,
                                             "rebuilds")))
    print("\nsetup, seconds (untimed above): ase_bpm scene + create_bonds, + first "
          "evaluation; LAMMPS data file written by ase_bpm; LAMMPS read_data + run 0")
    for r in rows:
        print(f"{r['ase']['particles']:9d}  ase_bpm {r['ase']['build_s']:7.2f} "
              f"{r['ase']['setup_s']:7.2f}   export {r['export_s']:7.2f}   "
              f"LAMMPS {r['lmp']['setup_s']:7.2f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", help="particle counts, comma-separated (e.g. 1e3,1e5)")
    ap.add_argument("--repeats", type=int, help="timed runs per engine and size (3)")
    ap.add_argument("--seconds", type=float, default=3.0, help="length of a timed run")
    ap.add_argument("--quick", action="store_true", help="sizes to 1e5, one repeat")
    ap.add_argument("--threads", type=int, default=1,
                    help="threads of ase_bpm's compiled bond and pair kernels (1)")
    engines.add_child_options(ap, CHILDREN)
    ap.add_argument("--cells", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--data", help=argparse.SUPPRESS)
    ap.add_argument("--commands", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.repeats is None:
        args.repeats = 1 if args.quick else 3
    if args.child:
        engines.answer(CHILDREN, args)
        return
    threads = (f" (ase_bpm's bond and pair kernels: {args.threads})" if args.threads > 1
               else "")
    sizes = ([float(s) for s in args.sizes.split(",")] if args.sizes
             else QUICK_SIZES if args.quick else SIZES)
    print(f"README usage example (BPMSpring, ASE VelocityVerlet, dt {TIMESTEP}) on FCC "
          f"cubes; one thread per engine{threads}; ~{args.seconds:g} s per timed run",
          flush=True)
    rows = [measure(cells(s), args) for s in sizes]
    report(rows, args.repeats)


if __name__ == "__main__":
    main()
