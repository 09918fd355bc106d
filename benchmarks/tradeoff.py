"""Speed against accuracy, measured: writes ``docs/accuracy.md`` and its figures.

    python benchmarks/tradeoff.py [--quick] [--only NAME ...] [--out docs/accuracy.md]

For each knob a user turns to go faster (timestep, neighbour skin, smoothing,
peridynamic horizon and model, Hooke or Hertz, NumPy or compiled kernels,
terms switched off) it measures the cost per step against the error relative
to a converged reference of the same scene, and ends with advice per demo.
The sections live in ``tradeoff_<name>.py`` beside this script (see
``tradeoff_common.py``); ``--only`` runs some of them and writes their part
alone to ``--out``.  Run it on a quiet machine: the costs are wall times on
one thread.  ``--quick`` runs smaller scenes and fewer points (a smoke test
of the script, not the published figures).
"""

from __future__ import annotations

import tradeoff_common  # noqa: F401  (one thread, before numpy is imported)

import argparse
import importlib
import platform
import time
from pathlib import Path

import numpy as np

import ase_bpm

#: the sections, in the order they appear in docs/accuracy.md
SECTIONS = ("timestep", "skin", "smoothing", "horizon", "collision", "kernels", "terms",
            "advice")

HEADER = """# Speed against accuracy

What each knob costs and buys, measured on this package's own scenes by
`benchmarks/tradeoff.py`, which writes this page and its figures
(`python benchmarks/tradeoff.py`; about {minutes:.0f} minutes on the machine below).
Errors are relative to a reference run of the same scene at a tenth of the
stable timestep (`calc.stable_timestep(atoms)`), unless a section says
otherwise; the neighbour skin changes no result, only the cost (its section
shows both).  Fracture and granular flow are chaotic, so
errors are measured on what a user reads off a run (broken bonds, damage,
kinetic energy, fragments, packing), and trajectories only over a stated short
horizon.

Machine: {machine}; one thread; ase_bpm {version}, NumPy {numpy}.
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small scenes, few points")
    ap.add_argument("--only", nargs="+", choices=SECTIONS, help="run these sections alone")
    ap.add_argument("--out", type=Path,
                    default=Path(__file__).resolve().parent.parent / "docs" / "accuracy.md")
    args = ap.parse_args()
    figures = args.out.parent / tradeoff_common.FIGURE_DIR
    start = time.perf_counter()
    parts = []
    for name in args.only or SECTIONS:
        module = importlib.import_module(f"tradeoff_{name}")
        began = time.perf_counter()
        parts.append(module.section(args.quick, figures).strip())
        print(f"{name}: {time.perf_counter() - began:.0f} s", flush=True)
        write(args.out, parts, time.perf_counter() - start)  # what is done so far, kept
    print(f"wrote {args.out}")


def write(out: Path, parts: list, seconds: float) -> None:
    header = HEADER.format(minutes=seconds / 60,
                           machine=f"{platform.processor() or platform.machine()}, "
                                   f"Python {platform.python_version()}",
                           version=ase_bpm.__version__, numpy=np.__version__)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(header + "\n" + "\n\n".join(parts) + "\n")


if __name__ == "__main__":
    main()
