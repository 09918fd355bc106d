"""LAMMPS's own example decks in LAMMPS and in ase_bpm, side by side (issue 30).

    python benchmarks/bench_decks.py [EXAMPLES] [--steps N] [--quick]

``EXAMPLES`` is a folder holding LAMMPS's ``examples/`` tree (default: the
environment variable ``ASE_BPM_LAMMPS_EXAMPLES``).  Each deck the reference
build runs (``examples/bpm/impact/in.bpm.impact.spring``,
``examples/peri/in.peri.pmb|lps|ves|eps``,
``examples/bpm/peri/benchmark/in.bench.legacy.pmb`` and the pile LAMMPS pours
with ``examples/pour/in.pour``, run down its chute by ``tests/decks/in.twin.pile``,
as ``tests/test_lammps_examples.py`` makes it) runs to the end of its first
run (or ``--steps N``) in two child processes on one thread each
(``engines.py``): LAMMPS (the Python module: the deck's set-up, then the run,
wall time around the ``run`` command; legacy ``peri/lps|ves|eps`` with the
``s0`` repair the oracle tests use, ``tests/deck_oracle.py``) and ase_bpm
(``ase_bpm.run_lammps`` of the deck, its wall time, the first evaluation
included).  The ``bpm/peri`` decks, which the reference build lacks, run in
ase_bpm against the rows and loop time of LAMMPS's published logs
(``log.23Aug2026.*.g++.1`` beside the decks in ``EXAMPLES``, another machine).

Printed per deck: ms/step of both and their ratio, and the late observables
at the end: atoms, broken bonds (ase_bpm: since the first run, or gone with
atoms lost; LAMMPS: the bond styles' intact bonds at the start less those at
the end), mean damage (peridynamics), contacts (spheres), kinetic energy
(as each deck's thermo prints it: per atom in lj units, over the node
volume for legacy PERI).  ``--quick``: 100 steps of each.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import time
from pathlib import Path

import engines

TESTS = Path(__file__).resolve().parent.parent / "tests"
#: decks both engines run: (name, path under examples/)
BOTH = [("impact.spring", "bpm/impact/in.bpm.impact.spring"),
        *[(f"peri.{m}", f"peri/in.peri.{m}") for m in ("pmb", "lps", "ves", "eps")],
        ("bench.legacy.pmb", "bpm/peri/benchmark/in.bench.legacy.pmb"),
        ("pour pile", "pour/in.pour")]
#: decks only ase_bpm runs, against LAMMPS's published log beside them
PUBLISHED = [*[(f"bpm.peri.{m}", f"bpm/peri/in.bpm.peri.{m}")
               for m in ("pmb", "lps", "ves", "eps")],
             ("bench.bpm.pmb", "bpm/peri/benchmark/in.bench.bpm.pmb")]
QUICK_STEPS = 100
#: the columns of a row, their headings and formats
COLUMNS = {"ms_step": ("ms/step", "{:.3f}"), "atoms": ("atoms", "{:d}"),
           "broken": ("broken", "{:d}"), "damage": ("damage", "{:.9g}"),
           "contacts": ("contacts", "{:d}"), "ke": ("KinEng", "{:.9g}")}


# -- the children --------------------------------------------------------------------

def child_lammps(args) -> dict:
    """LAMMPS: the deck's set-up (``deck_oracle.run_setup``: its lines up to
    the first run, legacy s0 repaired), then ``--steps`` steps timed."""
    from deck_oracle import run_setup
    from oracle import intact_bonds

    lmp = run_setup(args.deck)
    peri = lmp.extract_atom("s0") is not None  # (atom_style peri)
    spheres = lmp.extract_atom("radius") is not None
    bonded = lmp.extract_global("nbonds") > 0
    if peri:
        lmp.commands_list(["compute bench_damage all damage/atom",
                           "compute bench_mean all reduce ave c_bench_damage"])
    if spheres:
        lmp.commands_list(["compute bench_contacts all contact/atom",
                           "compute bench_sum all reduce sum c_bench_contacts"])
    start = len(intact_bonds(lmp)) if bonded else 0
    seconds = engines.timed(lambda n: lmp.command(f"run {n}"), args.steps)
    out = dict(seconds=seconds, steps=args.steps, atoms=int(lmp.get_natoms()),
               ke=float(lmp.get_thermo("ke")))
    if bonded:
        out["broken"] = start - len(intact_bonds(lmp))
    if peri:
        out["damage"] = float(lmp.extract_compute("bench_mean", 0, 0))
    if spheres:
        out["contacts"] = int(round(lmp.extract_compute("bench_sum", 0, 0))) // 2
    lmp.close()
    return out


def child_ase(args) -> dict:
    """ase_bpm: ``run_lammps`` of the deck for ``--steps`` steps (its own
    wall time: the run, its first evaluation included)."""
    import warnings

    import ase_bpm

    ase_bpm.set_threads(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the ignored lines: no effect on the physics)
        result = ase_bpm.run_lammps(args.deck, steps=args.steps)
    last = result.rows[-1]
    out = dict(seconds=result.wall_seconds, steps=result.steps, atoms=last["atoms"],
               ke=last["ke"])
    for key in ("broken", "damage"):
        if key in last:
            out[key] = last[key]
    if "ncontacts" in result.atoms.arrays:
        out["contacts"] = int(result.atoms.arrays["ncontacts"].sum()) // 2
    return out


# -- in the parent -------------------------------------------------------------------

def published(deck: Path, steps: int) -> dict | None:
    """The thermo row (atoms, mean damage) of LAMMPS's published one-process
    log beside ``deck`` at the last of its steps up to ``steps``, and its
    ms/step; None without the log."""
    name = deck.name.removeprefix("in.")
    log = deck.parent / f"log.23Aug2026.{name}.g++.1"
    if not log.exists():
        return None
    text = log.read_text()
    loop = re.search(r"Loop time of (\S+) on 1 procs for (\d+) steps", text)
    out = {"ms_step": 1e3 * float(loop[1]) / int(loop[2]), "steps": int(loop[2])}
    rows = [r for r in re.findall(r"^\s+(\d+)\s+(\d+)\s+([0-9.eE+-]+)\s*$", text, re.M)
            if int(r[0]) <= steps]
    if rows:
        step, atoms, damage = rows[-1]
        out.update(atoms=int(atoms), damage=float(damage), last_step=int(step))
    return out


def deck_steps(deck: Path) -> int:
    """The length of the deck's first run."""
    from ase_bpm.scene.lammps_deck import read_deck

    commands = read_deck(deck)
    _, words = commands.commands[commands.first_run()]
    return int(words[1])


def row(label: str, values: dict) -> str:
    cells = [f"{label:<26}"]
    for key, (_, form) in COLUMNS.items():
        value = values.get(key)
        cells.append(f"{'-' if value is None else form.format(value):>16}")
    return "".join(cells)


def heading() -> str:
    return f"{'deck / engine':<26}" + "".join(f"{h:>16}" for h, _ in COLUMNS.values())


def with_rate(result: dict) -> dict:
    return {**result, "ms_step": 1e3 * result["seconds"] / max(result["steps"], 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("examples", nargs="?", default=os.environ.get("ASE_BPM_LAMMPS_EXAMPLES"),
                        help="a folder holding LAMMPS's examples/ tree")
    parser.add_argument("--steps", type=int, help="steps of each deck (default: its first run)")
    parser.add_argument("--quick", action="store_true", help=f"{QUICK_STEPS} steps of each")
    parser.add_argument("--deck", help=argparse.SUPPRESS)
    engines.add_child_options(parser, ["lammps", "ase_bpm"])
    args = parser.parse_args()
    sys.path.insert(0, str(TESTS))
    if args.child:
        engines.answer({"lammps": child_lammps, "ase_bpm": child_ase}, args)
        return
    if not args.examples:
        parser.error("name the folder holding LAMMPS's examples/ tree (or set "
                     "ASE_BPM_LAMMPS_EXAMPLES)")
    examples = Path(args.examples) / "examples"
    steps = QUICK_STEPS if args.quick else args.steps
    print(heading())
    with tempfile.TemporaryDirectory() as scratch:
        for name, path in BOTH:
            deck = examples / path
            if not deck.exists():
                print(f"{name}: {deck} missing")
                continue
            if name == "pour pile":
                from test_lammps_decks import POUR_STEPS, pour_in_lammps

                print(f"  (LAMMPS pours {POUR_STEPS} steps with {path}, write_data, "
                      "tests/decks/in.twin.pile runs the pile)", file=sys.stderr)
                deck = pour_in_lammps(deck, Path(scratch))
            count = steps or deck_steps(deck)
            options = ["--deck", str(deck), "--steps", str(count)]
            clock = time.perf_counter()
            theirs = with_rate(engines.spawn(__file__, "lammps", options))
            ours = with_rate(engines.spawn(__file__, "ase_bpm", options))
            print(f"{name}: {count} steps (both engines {time.perf_counter() - clock:.0f} s "
                  f"in all); ase_bpm / LAMMPS {ours['ms_step'] / theirs['ms_step']:.2f}")
            print(row("  LAMMPS", theirs))
            print(row("  ase_bpm", ours), flush=True)
        for name, path in PUBLISHED:
            deck = examples / path
            if not deck.exists():
                print(f"{name}: {deck} missing")
                continue
            count = steps or deck_steps(deck)
            log = published(deck, count)
            ours = with_rate(engines.spawn(__file__, "ase_bpm",
                                           ["--deck", str(deck), "--steps", str(count)]))
            ratio = (f"; ase_bpm / published {ours['ms_step'] / log['ms_step']:.2f}"
                     if log else "")
            print(f"{name}: {count} steps{ratio}")
            if log:
                at = f" (step {log['last_step']})" if "last_step" in log else ""
                print(row(f"  LAMMPS log{at}", log))
            print(row("  ase_bpm", ours), flush=True)


if __name__ == "__main__":
    main()
