"""Section "terms" of ``docs/accuracy.md``: the terms each demo needs, and
what each term costs per step.

A term switched off costs nothing (``tests/test_only_what_is_needed.py``
counts it): no contact search without pair coefficients, no velocities or
damping work with ``gamma = 0``, no breaking test with breaking off, no
rotation without friction.  For each demo scene (:mod:`tradeoff_scenes`)
this runs the scene part-way (``warm`` steps at the demo's timestep), then
from that same state times ``steps`` steps with the scene as it is and with
each term switched off in turn, everything else unchanged; ``REPEATS`` runs
of each, taken in turn, the median kept.  Run alone:

    python benchmarks/tradeoff.py --only terms --out /tmp/terms.md [--quick]
"""

from __future__ import annotations

import tradeoff_common  # noqa: F401  (one thread, before numpy is imported)

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ase_bpm import Gravity, GranularWall, SphericalIndenter
from tradeoff_common import table, timed
from tradeoff_scenes import Impact, Pour, Shatter

#: runs of each variant (the median is kept), full and --quick
REPEATS = {False: 3, True: 1}
#: (warm-up steps, timed steps) per scene, full and --quick: the impact's ball
#: reaches the disk after about 300 steps, the indenter touches the cylinder
#: within 5, the pour's lower layers have landed by step 2,000
STEPS = {("impact", False): (600, 200), ("impact", True): (400, 100),
         ("shatter", False): (150, 100), ("shatter", True): (40, 20),
         ("pour", False): (3000, 500), ("pour", True): (2000, 300)}


@dataclass(frozen=True)
class Term:
    """A term of a scene and how to switch it off."""

    name: str  # what is switched off, and how
    needed: str  # why the scene needs it ("" when it does not)
    without: Callable  # the demo's calculator -> a calculator without the term


def like(calc, fixes=None, **changes):
    """A new calculator as ``calc`` with ``changes`` to its parameters (and
    ``fixes`` instead of its fixes)."""
    return type(calc)(**{**calc.parameters, **changes},
                      fixes=calc.fixes if fixes is None else fixes)


def but(calc, kind) -> list:
    """``calc``'s fixes without those of class ``kind``."""
    return [fix for fix in calc.fixes if not isinstance(fix, kind)]


GUARD = Term("blow-up guard (`guard=False`)", "", lambda calc: like(calc, guard=False))
LOG = Term("broken-bond log (`store_local=False`)", "",
           lambda calc: like(calc, store_local=False))


def no_contacts(reason: str) -> Term:
    return Term("contacts (`pair_coeffs={}`: no neighbour search)", reason,
                lambda calc: like(calc, pair_coeffs={}))


def no_breaking(reason: str, **also) -> Term:
    return Term("breaking (`break_bonds=False`" + "".join(f", `{k}={v}`" for k, v in also.items())
                + ": no breaking test)", reason,
                lambda calc: like(calc, break_bonds=False, **also))


def undamped(coeffs: dict) -> dict:
    """bpm/spring coefficients ``(k, x, gamma)`` with ``gamma = 0``."""
    return {key: (k, x, 0.0) for key, (k, x, _) in coeffs.items()}


IMPACT = (
    "bonds with damping, breaking and smoothing (the LAMMPS deck's `bond_style bpm/spring` "
    "with its defaults), and contact pairs with damping",
    no_contacts("the ball strikes the disk through them; fragments touch"),
    Term("bond damping (`gamma = 0` in `bond_coeffs`)", "the deck's `gamma = 1`",
         lambda calc: like(calc, bond_coeffs=undamped(calc.parameters["bond_coeffs"]))),
    Term("contact damping (`gamma = 0` in `pair_coeffs`)", "the deck's `gamma = 1`",
         lambda calc: like(calc, pair_coeffs=undamped(calc.parameters["pair_coeffs"]))),
    Term("all damping (both: no velocities read)", "as above",
         lambda calc: like(calc, bond_coeffs=undamped(calc.parameters["bond_coeffs"]),
                           pair_coeffs=undamped(calc.parameters["pair_coeffs"]))),
    no_breaking("the disk shatters", smooth=False),  # breaking off needs smoothing off
    Term("smoothing (`smooth=False`)", "the deck's default, `smooth yes`",
         lambda calc: like(calc, smooth=False)),
    LOG, GUARD)

SHATTER = (
    "pmb bonds that break (Parks' criterion), contacts and the indenter; no dilatation "
    "(pmb is bond-based)",
    no_contacts("fragments and crack faces touch (the deck's `pair_style bpm/peri`)"),
    no_breaking("the cylinder cracks"),
    Term("the indenter (`fix indent`)", "it strikes the cylinder",
         lambda calc: like(calc, fixes=but(calc, SphericalIndenter))),
    LOG, GUARD)


def walls_with(calc, **law) -> list:
    """``calc``'s fixes, each granular wall with ``law`` changed (e.g.
    ``xmu=0.0``)."""
    def rebuilt(wall):
        kwargs = {**wall.todict(), **law}
        del kwargs["type"]
        return GranularWall(**kwargs, kernels=calc.parameters["kernels"])

    return [rebuilt(fix) if isinstance(fix, GranularWall) else fix for fix in calc.fixes]


POUR = (
    "contacts with friction (tangential springs with shear history, so rotation) and "
    "normal damping, the walls (with friction too) and gravity; no tangential damping "
    "(the deck's `dampflag 0`)",
    Term("friction, contacts and walls (`xmu = 0`: frictionless kernels, no shear "
         "history, no rotation)", "the deck's `xmu = 0.5`: the pile's slope",
         lambda calc: like(calc, xmu=0.0, fixes=walls_with(calc, xmu=0.0))),
    Term("friction of the walls only (the spheres still turn)", "the deck's walls",
         lambda calc: like(calc, fixes=walls_with(calc, xmu=0.0))),
    Term("normal damping (`gamma_n = 0`, contacts and walls)", "the pile settles by it",
         lambda calc: like(calc, gamma_n=0.0, fixes=walls_with(calc, gamma_n=0.0))),
    Term("the walls (`fix wall/gran`)", "the box holds the pile",
         lambda calc: like(calc, fixes=but(calc, GranularWall))),
    Term("gravity (`fix gravity`)", "the spheres fall",
         lambda calc: like(calc, fixes=but(calc, Gravity))),
    GUARD)

TERMS = {"impact": IMPACT, "shatter": SHATTER, "pour": POUR}


def ms_per_step(start, calc, scene, steps: int) -> float:
    """Milliseconds per step of ``steps`` steps from a copy of ``start``
    under ``calc`` (after one untimed step: the new calculator reads the
    scene, its bonds, its neighbours)."""
    atoms = start.copy()
    atoms.calc = calc
    dyn = scene.integrator(atoms, scene.demo_dt)
    dyn.run(1)
    _, seconds = timed(dyn.run, steps)
    return 1e3 * seconds / steps


def measure(scene, terms, warm: int, steps: int, repeats: int) -> tuple:
    """``(start, ms_base, {term name: ms})``: the median ms/step of the scene
    as it is and without each term, all from its state after ``warm`` steps."""
    start = scene.build()
    demo = start.calc
    # a calculator given the timestep: a new calculator's first look, part-way,
    # comes before any step its integrator announces (the indenter's clock)
    demo.set(timestep=scene.demo_dt)
    scene.integrator(start, scene.demo_dt).run(warm)
    variants = {"": lambda: like(demo), **{t.name: (lambda t=t: t.without(demo))
                                            for t in terms}}
    runs = {name: [] for name in variants}
    for _ in range(repeats):  # in turn, so that a busy moment hits all alike
        for name, make in variants.items():
            runs[name].append(ms_per_step(start, make(), scene, steps))
    ms = {name: float(np.median(values)) for name, values in runs.items()}
    return start, ms.pop(""), ms


def describe(scene, needs: str, terms, start, base: float, ms: dict, warm: int, steps: int,
             repeats: int) -> str:
    note = ""
    if isinstance(scene, Pour):
        note = (f"  Contact kernels: `{start.calc.kernel_variant}`, without friction "
                f"`{terms[0].without(start.calc).kernel_variant}`; "
                f"{int(start.arrays['ncontacts'].sum()) // 2} contacts when the timing "
                "starts.")
    rows = [("the scene as it is", "", f"{base:.3f}", "")]
    rows += [(t.name, t.needed or "not needed", f"{ms[t.name]:.3f}",
              f"{100.0 * (base - ms[t.name]) / base:+.1f} %") for t in terms]
    return "\n".join([
        f"### {scene.name} ({type(start.calc).__name__})",
        "",
        f"{len(start)} particles; timed over {steps} steps after step {warm} (median of "
        f"{repeats} run{'s' if repeats > 1 else ''}).  The scene needs {needs}.{note}",
        "",
        table(["switched off", "the scene needs it because", "ms/step", "saving"], rows),
    ])


INTRO = """## Terms each demo needs

A term that is switched off costs nothing: without pair coefficients there
is no contact search, with `gamma = 0` no velocity is read and no damping
computed, with breaking off no breaking test, without friction no
tangential force, shear history or rotation (the frictionless granular
kernels, and `SphereVelocityVerlet` leaves `omega` alone).
`tests/test_only_what_is_needed.py` checks each by counting calls, never
by timing.  Below, for each demo{size}, the terms its physics needs, and
what each term costs: the scene's milliseconds per step as it is and with
that one term switched off, everything else unchanged, timed from the same
state part-way through the run.  The saving is the share of a step the term
takes.

Where the scene needs a term, switching it off changes the physics (a disk
that cannot break, a pile without friction, spheres that never land): the
figure is the cost of the term, not advice to drop it.  Only the terms
marked *not needed* (bookkeeping and checks) can go without changing the
trajectory.  Over the timed steps a scene without a term also evolves
differently, which is part of what is measured (without walls the pile
loses its contacts, without breaking the disk keeps its bonds)."""

OUTRO = ("A negative saving is a term whose removal made the step dearer (a scene "
         "without it evolves differently) or noise: differences of a few per cent are "
         "within what a machine varies between runs.")


def section(quick: bool, figures: Path) -> str:
    repeats = REPEATS[quick]
    parts = [INTRO.format(size=" (the `--quick` sizes)" if quick else "")]
    for scene in (Impact(quick), Shatter(quick), Pour(quick)):
        needs, *terms = TERMS[scene.name]
        warm, steps = STEPS[scene.name, quick]
        start, base, ms = measure(scene, terms, warm, steps, repeats)
        parts.append(describe(scene, needs, terms, start, base, ms, warm, steps, repeats))
    parts.append(OUTRO)
    return "\n\n".join(parts)
