"""Handing a large scene to LAMMPS and back: ase_bpm's write_lammps and
read_lammps beside LAMMPS's own write_data and read_data of the same block.

    python benchmarks/bench_lammps_io.py [--particles 1e6] [--quick]

The scene is that of ``scaling.py``: the README's usage example grown to an FCC
cube (1e6 -> 1,000,188 particles, about 5.8 million bonds), ``BPMSpring``.
Each measurement runs in a fresh process on one thread (``engines.py``):

1. ase_bpm, writing: builds the block (untimed), then ``write_lammps`` (timed);
   its memory is what the writing adds: the peak resident memory during the
   call (the peak is reset just before it, ``/proc/self/clear_refs``) less the
   resident memory before it.
2. ase_bpm, reading: ``read_lammps`` of those files (timed); memory: the peak
   of the process (imports included) and what the reading added to the
   resident memory before it.
3. LAMMPS (the reference build, as a Python module): the written deck's
   commands up to its ``read_data`` (untimed), ``read_data`` (timed, its peak
   and added memory as in 2.), the rest of the set-up (untimed), then
   ``write_data`` (timed, the memory it adds as in 1.).

Prints seconds, memory in MB and the ratio ase_bpm/LAMMPS of each direction.
``--quick``: 1e5 particles (97,556).  The PYTHONPATH of the run picks the
ase_bpm measured (e.g. another worktree, for a before-and-after).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import engines
from scaling import TIMESTEP, cells, readme_block, readme_calculator

PARTICLES, QUICK_PARTICLES = 1e6, 1e5
SCENE = "block"  # the written files: block.data and in.block


def resident_mb(field: str = "VmRSS") -> float:
    """This process's resident memory (``VmRSS``) or its peak (``VmHWM``), MB."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    return float("nan")


def measured(call) -> dict:
    """Wall seconds of ``call()``, the memory it added to the resident memory
    before it (its own peak: the peak is reset first) and the process's peak."""
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")  # (Linux: VmHWM := VmRSS)
    before = resident_mb()
    start = time.perf_counter()
    call()
    seconds = time.perf_counter() - start
    peak = resident_mb("VmHWM")
    return dict(seconds=seconds, added_mb=peak - before, peak_mb=peak)


# -- the children ----------------------------------------------------------------------

def child_ase_write(args) -> dict:
    from ase_bpm import get_bonds, write_lammps

    atoms = readme_block(args.cells)
    atoms.calc = readme_calculator()
    path = os.path.join(args.dir, SCENE)
    result = measured(lambda: write_lammps(path, atoms, timestep=TIMESTEP))
    return dict(result, particles=len(atoms), bonds=len(get_bonds(atoms)[0]))


def child_ase_read(args) -> dict:
    from ase_bpm import get_bonds, read_lammps

    back = {}
    data, deck = (os.path.join(args.dir, name) for name in (f"{SCENE}.data", f"in.{SCENE}"))
    result = measured(lambda: back.update(atoms=read_lammps(data, deck)))
    result["peak_mb"] = resident_mb("VmHWM")
    return dict(result, particles=len(back["atoms"]), bonds=len(get_bonds(back["atoms"])[0]))


def child_lammps(args) -> dict:
    with open(os.path.join(args.dir, f"in.{SCENE}")) as fh:
        lines = [line.split("#")[0].strip() for line in fh]
    commands = [line for line in lines if line and not line.startswith("run ")]
    at = next(k for k, line in enumerate(commands) if line.startswith("read_data "))
    os.chdir(args.dir)  # (the deck names its data file relative to itself)
    lmp = engines.new_lammps()
    lmp.commands_list(commands[:at])
    read = measured(lambda: lmp.command(commands[at]))
    lmp.commands_list(commands[at + 1:])
    write = measured(lambda: lmp.command("write_data lammps.data"))
    result = dict(read=read, write=write, particles=lmp.get_natoms(),
                  bonds=int(lmp.extract_global("nbonds")))
    lmp.close()
    return result


CHILDREN = {"ase_write": child_ase_write, "ase_read": child_ase_read,
            "lammps": child_lammps}


# -- the parent ------------------------------------------------------------------------

def row(direction: str, engine: str, r: dict, reference: dict | None) -> str:
    ratio = "" if reference is None else f"{r['seconds'] / reference['seconds']:8.2f}"
    return (f"{direction:6s} {engine:8s} {r['seconds']:8.2f} {r['added_mb']:9.0f} "
            f"{r['peak_mb']:8.0f} {ratio}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=float, help=f"block size ({PARTICLES:g})")
    ap.add_argument("--quick", action="store_true", help=f"{QUICK_PARTICLES:g} particles")
    engines.add_child_options(ap, CHILDREN)
    ap.add_argument("--cells", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--dir", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        engines.answer(CHILDREN, args)
        return
    n = cells(args.particles or (QUICK_PARTICLES if args.quick else PARTICLES))
    with tempfile.TemporaryDirectory() as tmp:
        options = ["--cells", str(n), "--dir", tmp]
        print(f"FCC {n}^3 cells: ase_bpm writing ...", file=sys.stderr, flush=True)
        wrote = engines.spawn(__file__, "ase_write", options)
        print("  ase_bpm reading ...", file=sys.stderr, flush=True)
        read = engines.spawn(__file__, "ase_read", options)
        print("  LAMMPS reading and writing ...", file=sys.stderr, flush=True)
        lammps = engines.spawn(__file__, "lammps", options)
        size = os.path.getsize(os.path.join(tmp, f"{SCENE}.data")) / 2 ** 20
    scenes = {(r["particles"], r["bonds"]) for r in (wrote, read, lammps)}
    if len(scenes) != 1:
        raise RuntimeError(f"the engines hold different scenes (particles, bonds): {scenes}")
    print(f"{wrote['particles']:,} particles, {wrote['bonds']:,} bonds; data file "
          f"{size:.0f} MB; one process per measurement, one thread\n"
          "added: peak resident memory during the call less that before it; peak: the "
          "process's\nratio: seconds / LAMMPS's in the same direction")
    print(f"{'':6s} {'engine':8s} {'seconds':>8s} {'added MB':>9s} {'peak MB':>8s} "
          f"{'ratio':>8s}")
    print(row("write", "LAMMPS", lammps["write"], None))
    print(row("write", "ase_bpm", wrote, lammps["write"]))
    print(row("read", "LAMMPS", lammps["read"], None))
    print(row("read", "ase_bpm", read, lammps["read"]))


if __name__ == "__main__":
    main()
