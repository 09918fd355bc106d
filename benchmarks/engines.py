"""What the side-by-side benchmarks share: each engine in its own process, one thread.

``bench_impact.py``, ``bench_peri.py``, ``bench_pour.py`` and ``scaling.py``
run every engine (ase_bpm, LAMMPS) in a child process: the script runs itself
again with ``--child ROLE`` (:func:`spawn`) under :data:`ONE_THREAD`, and the
child prints its result as JSON on the last line of its output.  The peak
resident memory of a child (:func:`peak_memory_mb`) is then that engine's
alone.  Arrays the parent compares (final positions, velocities) go through an
``.npz`` file named by the child's ``--state`` option.

The parts of a step: :class:`Probes` times what ase_bpm spends in a few
callables (perf_counter probes put in their place), and
:func:`timed_lammps_run` reads LAMMPS's own timing breakdown (Pair, Bond,
Neigh, Comm, Output, Modify, Other and its neighbour-list builds) from the
log of the timed run; :func:`breakdown_lines` and :func:`parts_lines` print
both, side by side in ``bench_impact.py``, ``bench_granular.py`` and
``scaling.py``; :func:`spring_probes` is the table of a BPMSpring step,
:func:`rotational_probes` that of rotational bonds beside granular contacts.

Repeats come two ways: :func:`successive_runs`, timed runs one after the other
in one child on the same trajectory (``scaling.py``, which calibrates the
length of its runs), and :func:`fresh_runs`, a fresh child per repeat, so that
every repeat runs the same steps from the same start (the ``bench_*`` scenes,
whose cost per step changes as they evolve: fracture, landing spheres).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from typing import Callable

import numpy as np

#: environment of a child: one thread for OpenMP, BLAS and numexpr (LAMMPS runs
#: without MPI ranks: one process, one thread)
ONE_THREAD = {var: "1" for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                   "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")}
#: LAMMPS command-line arguments: no log file, no screen output, no citation note
QUIET_LAMMPS = ["-log", "none", "-screen", "none", "-nocite"]
#: the LAMMPS thermo interval of the timed runs: no thermo output in between
NO_THERMO = 100000


# -- in a child ----------------------------------------------------------------------

def peak_memory_mb() -> float:
    """This process's peak resident memory (VmHWM), MB."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def new_lammps():
    """An instance of the reference LAMMPS build, without log or screen output."""
    from ase_bpm.scene.lammps import load_lammps

    return load_lammps()(cmdargs=QUIET_LAMMPS)


def lammps_per_atom(lmp, name: str, count: int) -> np.ndarray:
    """The per-atom vector ``name`` (``x``, ``v``, ``omega``) of the ``count``
    atoms in atom-ID order (LAMMPS re-sorts atoms during a run); rows of atoms
    LAMMPS no longer has are NaN."""
    nlocal = lmp.extract_global("nlocal")
    ids = np.array(lmp.numpy.extract_atom("id")[:nlocal]) - 1
    values = np.full((count, 3), np.nan)
    values[ids] = lmp.numpy.extract_atom(name)[:nlocal]
    return values


def timed(advance: Callable[[int], object], steps: int) -> float:
    """Wall seconds of ``advance(steps)``."""
    start = time.perf_counter()
    advance(steps)
    return time.perf_counter() - start


def successive_runs(advance: Callable[[int], object], steps: int,
                    repeats: int) -> list[float]:
    """``repeats`` timed runs of ``advance(steps)``, one after the other on the
    same trajectory: the milliseconds per step of each."""
    return [1e3 * timed(advance, steps) / steps for _ in range(repeats)]


def add_child_options(parser: argparse.ArgumentParser, roles) -> None:
    """The hidden options of a child: ``--child ROLE`` (one of ``roles``) and
    ``--state FILE`` (the ``.npz`` the child writes its final arrays to)."""
    parser.add_argument("--child", choices=roles, help=argparse.SUPPRESS)
    parser.add_argument("--state", help=argparse.SUPPRESS)


def answer(children: dict, args: argparse.Namespace) -> None:
    """Run the child ``args.child`` (``children[role](args)``, a dict) and
    print its result as JSON, the last line of its output (:func:`spawn`)."""
    print(json.dumps(children[args.child](args)))


#: the sections of LAMMPS's "MPI task timing breakdown"; Bond only where the
#: atom style has bonds (LAMMPS leaves the line out otherwise)
SECTIONS = ("Pair", "Bond", "Neigh", "Comm", "Output", "Modify", "Other")
OPTIONAL_SECTIONS = ("Bond",)


def lammps_breakdown(log_text: str) -> dict:
    """Seconds per section of the last timing breakdown in a LAMMPS log (the
    average column) and its ``Neighbor list builds``; a section LAMMPS
    leaves out (:data:`OPTIONAL_SECTIONS`) is 0."""
    found = dict.fromkeys(OPTIONAL_SECTIONS, 0.0)
    for line in log_text.splitlines():
        fields = [f.strip() for f in line.split("|")]
        if len(fields) >= 3 and fields[0] in SECTIONS:
            found[fields[0]] = float(fields[2])
        elif line.startswith("Neighbor list builds"):
            found["builds"] = int(line.split("=")[1])
    missing = [name for name in (*SECTIONS, "builds") if name not in found]
    if missing:
        raise ValueError(f"no {', '.join(missing)} in the LAMMPS log's timing breakdown")
    return found


def timed_lammps_run(lmp, steps: int, log: str, options: str = "") -> tuple[float, float, dict]:
    """``run steps options`` on ``lmp`` (``options``: e.g. ``pre no`` after an
    earlier run; not ``post no``, which leaves the breakdown out), logged to
    the file ``log``: its wall seconds, CPU seconds and LAMMPS's timing
    breakdown (:func:`lammps_breakdown`)."""
    lmp.command(f"log {log}")
    cpu = time.process_time()
    seconds = timed(lambda n: lmp.command(f"run {n} {options}"), steps)
    cpu = time.process_time() - cpu
    lmp.command("log none")
    with open(log) as fh:
        return seconds, cpu, lammps_breakdown(fh.read())


class Probes:
    """perf_counter accumulators put in place of the callables of ``table``
    (part name -> ``(owner, attribute)``; restored by :meth:`remove`):
    seconds and calls of each.  A probe costs about 0.3 us a call."""

    def __init__(self, table: dict):
        self.seconds = {name: 0.0 for name in table}
        self.calls = {name: 0 for name in table}
        self._saved = []
        for name, (owner, attribute) in table.items():
            if not hasattr(owner, attribute):
                raise AttributeError(f"probe {name!r}: {owner!r} has no {attribute!r} any "
                                     "more; point the benchmark's PROBES at its new home")
            original = getattr(owner, attribute)
            self._saved.append((owner, attribute, original))
            setattr(owner, attribute, self._timed(name, original))

    def _timed(self, name: str, original):
        seconds, calls, clock = self.seconds, self.calls, time.perf_counter

        def probe(*args, **kwargs):
            start = clock()
            try:
                return original(*args, **kwargs)
            finally:
                seconds[name] += clock() - start
                calls[name] += 1

        return probe

    def remove(self) -> None:
        for owner, attribute, original in reversed(self._saved):
            setattr(owner, attribute, original)


def spring_probes() -> tuple[dict, dict]:
    """The parts of a BPMSpring step under ASE's ``VelocityVerlet``
    (``bench_impact.py``, ``scaling.py``): the probe table (part name ->
    ``(owner, attribute)``, :class:`Probes`) and the parts timed inside
    another (part -> the one it is in, left out of "the rest").  The
    calculator holds the kernels and the contact list, so "the rest" is the
    integrator's own work.  After a
    refactor moves one of these callables, point the table at its new home."""
    from ase_bpm import BPMCalculator
    from ase_bpm.core import neighbours
    from ase_bpm.laws.compiled import SpringBonds, SpringPairs
    from ase_bpm.models.bonded import ContactList

    probes = {
        # all the calculator does when the integrator asks it (ASE's
        # get_property): the parts below and its plumbing, the ledger, the guard
        "calculator": (BPMCalculator, "get_property"),
        "bond kernel": (SpringBonds, "__call__"),
        "contact kernel": (SpringPairs, "__call__"),
        # the check of every step, the rebuilds, the bonded pairs taken out
        "contact list": (ContactList, "listed"),
        "rebuilds": (neighbours.VerletList, "rebuild"),  # matscipy's search and ours around it
        "matscipy": (neighbours, "neighbour_list"),  # matscipy's search alone
        "bonded pairs": (ContactList, "_select"),  # the pairs of intact bonds taken out
    }
    within = {"bond kernel": "calculator", "contact kernel": "calculator",
              "contact list": "calculator", "rebuilds": "contact list",
              "matscipy": "rebuilds", "bonded pairs": "contact list"}
    return probes, within


def rotational_probes() -> tuple[dict, dict]:
    """The parts of a step of ``bond_style bpm/rotational`` bonds with
    ``pair_style gran/*`` contacts (a BPMSpring with ``granular``) under
    ``SphereVelocityVerlet`` (``bench_impact.py``), as :func:`spring_probes`
    gives them for springs.  The bonds run on one of two routes, the NumPy
    laws (``bond_forces``, the rotational law inside it) or the compiled
    kernels (``_compiled_bond_forces``): the other's part stays at zero."""
    from ase_bpm import BPMCalculator
    from ase_bpm.core import neighbours
    from ase_bpm.laws import granular_kernels
    from ase_bpm.laws.rotational import RotationalBond
    from ase_bpm.models.bonded import BondedModel, ContactList
    from ase_bpm.models.granular import GranularModel

    probes = {
        "calculator": (BPMCalculator, "get_property"),
        "bonds, NumPy route": (BondedModel, "bond_forces"),
        "rotational law": (RotationalBond, "forces"),  # its forces and torques, per bond
        "bonds, compiled route": (BondedModel, "_compiled_bond_forces"),
        # the granular contacts: their list, the bonded pairs taken out, the kernel
        "granular contacts": (GranularModel, "evaluate"),
        "contact list": (neighbours.SphereVerletList, "update"),  # the check of every step
        # matscipy's search and ours (matscipy alone is not timed: the guard's
        # timestep check searches the touching pairs with it outside the list)
        "rebuilds": (neighbours.SphereVerletList, "_pairs"),
        "bonded pairs": (ContactList, "_select"),  # the pairs of intact bonds taken out
        "contact kernel": (granular_kernels("auto"), "pair_contacts"),
    }
    within = {"bonds, NumPy route": "calculator", "rotational law": "bonds, NumPy route",
              "bonds, compiled route": "calculator", "granular contacts": "calculator",
              "contact list": "granular contacts", "rebuilds": "contact list",
              "bonded pairs": "granular contacts",
              "contact kernel": "granular contacts"}
    return probes, within


def probed_run(advance: Callable[[int], object], steps: int,
               table: dict) -> tuple[float, float, Probes]:
    """``advance(steps)`` with the probes of ``table`` in place: its wall
    seconds, CPU seconds and the :class:`Probes` (removed again)."""
    probes = Probes(table)
    cpu = time.process_time()
    try:
        seconds = timed(advance, steps)
    finally:
        probes.remove()
    return seconds, time.process_time() - cpu, probes


# -- in the parent -------------------------------------------------------------------

def spawn(script: str, role: str, options=()) -> dict:
    """Run ``script --child role *options`` on one thread in a new process and
    return its result, the JSON on the last line of its output."""
    cmd = [sys.executable, os.path.abspath(script), "--child", role, *options]
    done = subprocess.run(cmd, env={**os.environ, **ONE_THREAD}, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{role} child of {os.path.basename(script)} failed "
                           f"({' '.join(options)}):\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def fresh_runs(script: str, engines: dict, repeats: int,
               directory: str) -> tuple[dict, dict]:
    """Each engine (role -> options of its child) ``repeats`` times, each time in
    a fresh child; the engines take turns (round 1 of each, then round 2...),
    so the runs of one round see about the same load on the machine.  Each
    child gets ``--state <directory>/<role>.npz`` for its final arrays.

    Returns role -> the results of its rounds, in order, and role -> the
    arrays its last child saved (for the roles that save any)."""
    paths = {role: os.path.join(directory, f"{role}.npz") for role in engines}
    results = {role: [] for role in engines}
    for round_ in range(repeats):
        for role, options in engines.items():
            print(f"  {role}, run {round_ + 1} of {repeats} ...", file=sys.stderr,
                  flush=True)
            results[role].append(spawn(script, role, [*options, "--state", paths[role]]))
    states = {role: load_state(path) for role, path in paths.items()
              if os.path.exists(path)}
    return results, states


def load_state(path: str) -> dict:
    """The arrays a child saved to its ``--state`` file."""
    with np.load(path) as saved:
        return dict(saved)


def spread(values, digits: int = 3) -> str:
    """``median (min-max)`` of ``values``."""
    return (f"{np.median(values):.{digits}f} "
            f"({min(values):.{digits}f}-{max(values):.{digits}f})")


def ms_per_step(values, steps: int) -> str:
    """``median (min-max)`` of seconds over ``steps`` steps, as ms/step."""
    return spread([1e3 * v / steps for v in values], 3)


def breakdown_lines(results: list[dict], steps: int) -> list[str]:
    """LAMMPS's timing breakdown of its runs (each result's ``breakdown``), in
    ms/step, and its time per neighbour-list build."""
    runs = [r["breakdown"] for r in results]
    builds = int(np.median([b["builds"] for b in runs]))
    lines = [f"LAMMPS's timing breakdown, ms/step, median (min-max); {builds} "
             "neighbour-list builds:"]
    for name in SECTIONS:
        if name not in OPTIONAL_SECTIONS or any(b[name] for b in runs):
            lines.append(f"  {name:8s} {ms_per_step([b[name] for b in runs], steps)}")
    per_build = [1e3 * b["Neigh"] / max(b["builds"], 1) for b in runs]
    lines.append(f"  Neigh per build: {spread(per_build, 2)} ms")
    return lines


def parts_lines(results: list[dict], steps: int, names, within: dict,
                rebuilds: str) -> list[str]:
    """ase_bpm's parts of its runs (each result's probed ``parts``, seconds,
    and ``calls``), in ms/step: each part of ``names`` (in order; one timed
    inside another, ``within[part]``, is indented and left out of "the
    rest"; a part with others inside is followed by its own time, itself
    without them), then the rest of the step; the number of calls of the
    part ``rebuilds`` and its time per call."""
    builds = int(np.median([r["calls"][rebuilds] for r in results]))
    lines = [f"ase_bpm's parts, ms/step, median (min-max); {builds} neighbour-list builds:"]
    def depth(name):
        return 0 if name not in within else 1 + depth(within[name])

    def own(name):
        return [r["parts"][name] - sum(r["parts"][inner] for inner in names
                                       if within.get(inner) == name) for r in results]

    holders = set(within.values())
    width = max(2 * depth(name) + len(name) + (9 if name in holders else 0) for name in names)
    for name in names:
        label = "  " * depth(name) + name
        lines.append(f"  {label:{width}s} "
                     f"{ms_per_step([r['parts'][name] for r in results], steps)}")
    for name in names:
        if name in holders:
            label = "  " * depth(name) + f"{name}, its own"
            lines.append(f"  {label:{width}s} {ms_per_step(own(name), steps)}")
    rest = [r["seconds"] - sum(r["parts"][name] for name in names if name not in within)
            for r in results]
    lines.append(f"  {'the rest':{width}s} {ms_per_step(rest, steps)}")
    per_build = [1e3 * r["parts"][rebuilds] / max(r["calls"][rebuilds], 1) for r in results]
    lines.append(f"  {rebuilds} per build: {spread(per_build, 2)} ms")
    return lines


def per_round_ratios(ours: list[dict], theirs: list[dict]) -> list[float]:
    """Timed seconds of ``ours`` over those of ``theirs``, round by round."""
    return [a["seconds"] / b["seconds"] for a, b in zip(ours, theirs)]


def engine_table(rows: dict[str, list[dict]], steps: int, reference: str) -> str:
    """What the timed runs of ``steps`` steps give: a note, then a line per
    engine (label -> results of its rounds; each result has the timed
    ``seconds`` and ``peak_mb``): median wall seconds, ms/step median
    (min-max), the largest peak memory of its children, and its ratio to the
    engine labelled ``reference``, taken round by round (median (min-max) of
    the per-round ratios)."""
    width = max(len(label) for label in rows)
    lines = [f"{len(rows[reference])} run(s) per engine, each a fresh process on one "
             f"thread, setup untimed;\nratio: wall time / that of {reference} in the "
             "same round",
             f"{'engine':{width}s} {'wall s':>8s} {'ms/step median (min-max)':>27s} "
             f"{'peak MB':>8s} {'ratio median (min-max)':>23s}"]
    for label, results in rows.items():
        seconds = [r["seconds"] for r in results]
        ms = [1e3 * s / steps for s in seconds]
        lines.append(f"{label:{width}s} {np.median(seconds):8.2f} {spread(ms):>27s} "
                     f"{max(r['peak_mb'] for r in results):8.0f} "
                     f"{spread(per_round_ratios(results, rows[reference]), 2):>23s}")
    return "\n".join(lines)
