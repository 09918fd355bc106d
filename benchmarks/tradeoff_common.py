"""What the sections of ``tradeoff.py`` share: one thread, timing, tables, figures.

Each section is a module ``tradeoff_<name>.py`` beside this one with a
function ``section(quick: bool, figures: Path) -> str`` that runs its
measurements, writes its PNGs into ``figures`` (via :func:`save_figure`) and
returns its Markdown, starting with a ``## `` heading.  ``tradeoff.py``
assembles the sections into ``docs/accuracy.md``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one thread: set before numpy is imported

import time
from pathlib import Path

import numpy as np

#: where the figures are linked from: docs/accuracy.md links "accuracy/<name>.png"
FIGURE_DIR = "accuracy"


def timed(run, *args, **kwargs):
    """``run(*args, **kwargs)`` and the wall seconds it took."""
    start = time.perf_counter()
    result = run(*args, **kwargs)
    return result, time.perf_counter() - start


def table(headers, rows) -> str:
    """A Markdown table; floats are printed with 4 significant digits
    unless the row gives strings."""
    def cell(value):
        if isinstance(value, float):
            return f"{value:.4g}"
        return str(value)

    lines = ["| " + " | ".join(headers) + " |",
             "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def relative_error(value, reference) -> float:
    """|value - reference| / |reference| (absolute error where the reference is 0)."""
    value, reference = float(value), float(reference)
    return abs(value - reference) / (abs(reference) if reference else 1.0)


def order(dt_r, err_r) -> float:
    """The convergence order: least-squares slope of log error against log
    dt over the nonzero errors (nan with fewer than two)."""
    dt_r, err_r = np.asarray(dt_r), np.asarray(err_r)
    ok = err_r > 0
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(dt_r[ok]), np.log(err_r[ok]), 1)[0])


def save_figure(fig, figures: Path, name: str) -> str:
    """Write ``fig`` as ``figures/<name>.png``; return the Markdown that shows it."""
    figures.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(figures / f"{name}.png", dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return f"![{name}]({FIGURE_DIR}/{name}.png)"


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
