"""Hooke against Hertz on a binary collision: timestep against accuracy.

Two spheres meet head on at relative speed ``v0`` (no rotation, no tangential
motion, so friction plays no part).  The scene runs in ase_bpm (``Granular``
under ``SphereVelocityVerlet``) at timesteps from a fiftieth of
``calc.stable_timestep(atoms)`` up to that estimate, and two numbers are read
off each run and compared with a reference: the contact time ``t_c`` and the
coefficient of restitution ``e`` (separation over approach speed).

The force law (LAMMPS ``pair_style gran/hooke`` and ``gran/hertz/history``;
checked in ``src/GRANULAR/pair_gran_hooke.cpp`` and
``pair_gran_hertz_history.cpp``): with the overlap ``delta = R_i + R_j - r``,
the normal force pushing the spheres apart is

    Hooke:  F = kn delta + meff gamma_n delta'
    Hertz:  F = sqrt(R_eff delta) (kn delta + meff gamma_n delta')

with ``meff = m_i m_j / (m_i + m_j)`` and ``R_eff = R_i R_j / (R_i + R_j)``.
It acts whenever ``r < R_i + R_j`` and is not clipped (unless the keyword
``limit_damping`` is given, not used here): at the end of a damped Hookean
contact it pulls.  So the contact ends when the overlap, not the force,
returns to zero, and the overlap obeys ``meff delta'' = -F`` from
``delta(0) = 0``, ``delta'(0) = v0``.  Note that ``gamma_n`` multiplies the
effective mass: it is a rate (1/time), in both laws.

References:

* Hooke, a damped harmonic oscillator: ``w0^2 = kn / meff``,
  ``beta = gamma_n / 2``, ``wd = sqrt(w0^2 - beta^2)``;
  ``delta = (v0 / wd) exp(-beta t) sin(wd t)``, so ``t_c = pi / wd`` and
  ``e = exp(-beta t_c) = exp(-pi beta / wd)``, for any speed.  These are the
  widely used expressions; Schwager T. and Poeschel T., Granular Matter 9, 465
  (2007), arXiv:cond-mat/0701278, point out that they hold when the contact
  ends at zero overlap, pulling at the end, which is what LAMMPS does; with
  ``limit_damping`` it would end earlier, where the force reaches zero.
* Hertz without damping (the classical Hertz impact; Johnson K. L., Contact
  Mechanics, CUP 1985, chapter 11): energy
  ``meff v0^2 / 2 = (2/5) kn sqrt(R_eff) delta_max^(5/2)`` gives
  ``delta_max = (5 meff v0^2 / (4 kn sqrt(R_eff)))^(2/5)``, and integrating
  ``dt = d(delta) / delta'`` over the way in and out,
  ``t_c = (2 delta_max / v0) * (2/5) B(2/5, 1/2) = 2.94327 delta_max / v0``
  (B: Euler's beta function).  With the contact modulus ``E*`` of Hertz'
  theory, ``kn = 4/3 E*``, this is the familiar
  ``t_c = 2.868 (meff^2 / (R_eff E*^2 v0))^(1/5)``.  ``e = 1``.
* Hertz with LAMMPS' damping ``sqrt(R_eff delta) meff gamma_n delta'`` has no
  closed form (``e`` depends on ``v0``): the reference is the ODE above solved
  by SciPy's ``solve_ivp`` (DOP853, relative tolerance ``ODE_RTOL``), the
  contact end an event at ``delta = 0``.  The same solver is checked against
  the closed forms, and against itself at a looser tolerance (the section's
  first table).

Measuring.  The spheres start a whole step plus a fraction ``phase`` of a
step apart in time, so the first touch falls at a known instant between two
steps (free flight is exact under velocity Verlet); the end of the contact is
found by linear interpolation of the overlap between the last step in contact
and the next.  That interpolation is exact for the integrator's own path:
in the step that separates the spheres, velocity Verlet drifts the positions
along a straight line with the half-step velocity, which is the final one.
Which phase a run gets is luck, so every timestep runs ``PHASES`` of them and
the table gives the largest error.  ``e`` is read from the velocities once
the spheres have separated (they no longer change).

The timestep estimate is ``calc.stable_timestep(atoms)`` with the spheres at
the deepest overlap of the reference collision (at first touch it is
infinite, and Hertzian contacts stiffen as they are pressed).  The cost per
step is the wall time of ``dyn.run`` over its steps (the setup evaluation
not counted; the observer that records the overlap adds about 1 us), the
least of ``TIMING_REPEATS`` runs at the finest timestep.  On two spheres it
is almost all fixed overhead (ASE's integrator, the calculator's
bookkeeping), the same for both laws; the cost of a collision is that times
the number of steps it takes, which grows as ``1 / dt``.

Array names: ``_n`` per sphere, ``_c`` Cartesian component, ``_s`` per
recorded step.
"""

from __future__ import annotations

from tradeoff_common import order, pyplot, relative_error, save_figure, table, timed

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from ase import Atoms
from scipy.integrate import solve_ivp
from scipy.special import beta as beta_function

from ase_bpm import Granular
from ase_bpm import SphereVelocityVerlet

#: timesteps tried, as fractions of ``calc.stable_timestep(atoms)``
RATIOS = (0.02, 0.05, 0.1, 0.2, 0.5, 1.0)
QUICK_RATIOS = (0.1, 0.5, 1.0)
#: where, as a fraction of a step, the first touch falls in the runs of one timestep
PHASES = (0.125, 0.375, 0.625, 0.875)
QUICK_PHASES = (0.375,)
#: the accuracy asked for: every error within 1 %
TOLERANCE = 0.01
#: relative tolerance of the ODE reference (its absolute tolerances scale with it)
ODE_RTOL = 1e-12
#: Hertz: t_c = HERTZ_TIME * delta_max / v0 (module doc)
HERTZ_TIME = 2.0 * 0.4 * beta_function(0.4, 0.5)
#: a run lasts this many reference contact times past first touch (longer while
#: the spheres still touch)
MARGIN = 1.5
#: the runs whose errors set the observed order: the smallest ratios
ORDER_POINTS = 3
#: the cost per step is the least over this many runs of the finest timestep
TIMING_REPEATS = 7


@dataclass(frozen=True)
class Collision:
    """Two spheres meeting head on at relative speed ``speed`` (along x)."""

    label: str
    model: str  # "hooke" or "hertz/history"
    kn: float
    gamma_n: float
    radius_n: tuple = (0.5, 0.5)
    mass_n: tuple = (1.0, 1.0)
    speed: float = 1.0

    @property
    def hertz(self) -> bool:
        return self.model == "hertz/history"

    @property
    def meff(self) -> float:
        m_i, m_j = self.mass_n
        return m_i * m_j / (m_i + m_j)

    @property
    def reff(self) -> float:
        r_i, r_j = self.radius_n
        return r_i * r_j / (r_i + r_j)

    def calculator(self) -> Granular:
        return Granular(self.model, kn=self.kn, gamma_n=self.gamma_n, xmu=0.0)

    def atoms(self, gap: float) -> Atoms:
        """The two spheres ``gap`` apart (negative: overlapping), centre of
        mass at rest, approaching."""
        r_i, r_j = self.radius_n
        m_i, m_j = self.mass_n
        atoms = Atoms("H2", positions=[[0.0, 0.0, 0.0], [r_i + r_j + gap, 0.0, 0.0]])
        atoms.set_masses(self.mass_n)
        atoms.arrays["radius"] = np.array(self.radius_n, dtype=float)
        share = self.speed / (m_i + m_j)
        atoms.set_velocities([[m_j * share, 0.0, 0.0], [-m_i * share, 0.0, 0.0]])
        atoms.calc = self.calculator()
        return atoms


#: the scenes: equal spheres of mass 1 and radius 0.5 (meff 0.5, R_eff 0.25)
#: pressed to about 3 % of their radius at v0 = 1, and unequal ones
#: (radius 0.25, density as the first); damping gives e of 0.78 to 0.95
CASES = (
    Collision("Hooke, elastic", "hooke", kn=2000.0, gamma_n=0.0),
    Collision("Hooke, damped", "hooke", kn=2000.0, gamma_n=10.0),
    Collision("Hertz, elastic", "hertz/history", kn=40000.0, gamma_n=0.0),
    Collision("Hertz, damped", "hertz/history", kn=40000.0, gamma_n=150.0),
    Collision("Hertz, damped, unequal", "hertz/history", kn=40000.0, gamma_n=150.0,
              radius_n=(0.5, 0.25), mass_n=(1.0, 0.125)),
)


@dataclass(frozen=True)
class Outcome:
    """A collision's contact time, restitution and deepest overlap."""

    contact_time: float
    restitution: float
    overlap_max: float


# -- references ------------------------------------------------------------------------

def hooke_outcome(case: Collision) -> Outcome:
    """The damped harmonic oscillator in closed form (module doc)."""
    beta = 0.5 * case.gamma_n
    w0_sq = case.kn / case.meff
    if beta * beta >= w0_sq:
        raise ValueError(f"{case.label}: overdamped (gamma_n / 2 >= sqrt(kn / meff))")
    wd = math.sqrt(w0_sq - beta * beta)
    t_max = math.atan2(wd, beta) / wd  # delta' = 0
    return Outcome(math.pi / wd, math.exp(-math.pi * beta / wd),
                   case.speed / wd * math.exp(-beta * t_max) * math.sin(wd * t_max))


def hertz_elastic_outcome(case: Collision) -> Outcome:
    """Hertz without damping in closed form (module doc)."""
    overlap_max = (5.0 * case.meff * case.speed ** 2
                   / (4.0 * case.kn * math.sqrt(case.reff))) ** 0.4
    return Outcome(HERTZ_TIME * overlap_max / case.speed, 1.0, overlap_max)


def closed_form(case: Collision) -> Outcome | None:
    """The closed-form outcome where one exists (Hooke; Hertz undamped)."""
    if not case.hertz:
        return hooke_outcome(case)
    return hertz_elastic_outcome(case) if case.gamma_n == 0 else None


def ode_outcome(case: Collision, rtol: float = ODE_RTOL) -> Outcome:
    """The overlap's equation of motion, ``meff delta'' = -F``, integrated
    from first touch to ``delta = 0`` at relative tolerance ``rtol``."""
    scale = closed_form(replace(case, gamma_n=0.0)).overlap_max  # a length of the contact

    def rhs(_, y):
        overlap, rate = y
        law = math.sqrt(case.reff * max(overlap, 0.0)) if case.hertz else 1.0
        return [rate, -law * (case.kn / case.meff * overlap + case.gamma_n * rate)]

    def parted(_, y):
        return y[0]

    def deepest(_, y):
        return y[1]

    parted.terminal, parted.direction = True, -1.0
    deepest.direction = -1.0
    sol = solve_ivp(rhs, (0.0, 1e3 * scale / case.speed), [0.0, case.speed],
                    method="DOP853", rtol=rtol, atol=[rtol * scale, rtol * case.speed],
                    events=(parted, deepest))
    if sol.status != 1:
        raise RuntimeError(f"{case.label}: the ODE reference never parted: {sol.message}")
    t_end, (_, rate_end) = sol.t_events[0][0], sol.y_events[0][0]
    return Outcome(float(t_end), float(-rate_end / case.speed), float(sol.y_events[1][0][0]))


def reference(case: Collision) -> Outcome:
    """The closed form where there is one, else the ODE."""
    return closed_form(case) or ode_outcome(case)


# -- measurements ----------------------------------------------------------------------

def timestep_estimate(case: Collision, outcome: Outcome) -> float:
    """``calc.stable_timestep(atoms)`` at the collision's deepest overlap."""
    atoms = case.atoms(gap=-outcome.overlap_max)
    return atoms.calc.stable_timestep(atoms)


@dataclass(frozen=True)
class Run:
    """One simulated collision."""

    contact_time: float
    restitution: float
    steps: int  # steps run
    contact_steps: int  # steps that ended in contact
    seconds: float  # wall time of the run


def collide(case: Collision, dt: float, phase: float, contact_time: float) -> Run:
    """Simulate ``case`` at timestep ``dt``, first touch ``phase`` of a step
    after step 1; run until ``MARGIN`` reference contact times
    (``contact_time``) past it, longer while the spheres still touch."""
    touch = (1.0 + phase) * dt
    atoms = case.atoms(gap=touch * case.speed)
    radsum = sum(case.radius_n)
    dyn = SphereVelocityVerlet(atoms, dt)
    overlap_s = []
    dyn.attach(lambda: overlap_s.append(radsum - (atoms.positions[1, 0]
                                                  - atoms.positions[0, 0])))
    atoms.get_forces()  # the setup evaluation, untimed (as LAMMPS' setup)
    steps = math.ceil((touch + MARGIN * contact_time) / dt)
    _, seconds = timed(dyn.run, steps)
    while overlap_s[-1] > 0.0:  # still touching: go on
        _, more = timed(dyn.run, steps)
        seconds += more
        steps += steps
    overlap_s = np.array(overlap_s)  # observer: before step 1, then after every step
    (inside_s,) = np.nonzero(overlap_s > 0.0)
    last = inside_s[-1]  # the last step in contact; the next is out
    end = (last + overlap_s[last] / (overlap_s[last] - overlap_s[last + 1])) * dt
    v_nc = atoms.get_velocities()
    return Run(end - touch, (v_nc[1, 0] - v_nc[0, 0]) / case.speed, steps, len(inside_s),
               seconds)


@dataclass(frozen=True)
class Point:
    """The runs of one timestep: the largest errors over the phases."""

    ratio: float
    dt: float
    time_error: float
    restitution_error: float
    contact_steps: float  # mean steps in contact

    @property
    def error(self) -> float:
        return max(self.time_error, self.restitution_error)


def measure(case: Collision, outcome: Outcome, estimate: float, ratios, phases) -> list:
    points = []
    for ratio in ratios:
        dt = ratio * estimate
        runs = [collide(case, dt, phase, outcome.contact_time) for phase in phases]
        points.append(Point(
            ratio, dt,
            max(relative_error(run.contact_time, outcome.contact_time) for run in runs),
            max(relative_error(run.restitution, outcome.restitution) for run in runs),
            float(np.mean([run.contact_steps for run in runs]))))
    return points


def step_cost(case: Collision, dt: float, contact_time: float) -> float:
    """Seconds per step of ``dyn.run`` on the collision at timestep ``dt``:
    the least of ``TIMING_REPEATS`` runs (the least disturbed)."""
    runs = [collide(case, dt, PHASES[0], contact_time) for _ in range(TIMING_REPEATS)]
    return min(run.seconds / run.steps for run in runs)


def observed_order(points, attr: str) -> float:
    """The slope of log(error) against log(dt) over the ``ORDER_POINTS``
    smallest timesteps (NaN where an error is zero)."""
    chosen = sorted(points, key=lambda p: p.ratio)[:ORDER_POINTS]
    errors = [getattr(p, attr) for p in chosen]
    if not all(e > 0 for e in errors):
        return float("nan")
    return order([p.ratio for p in chosen], errors)


def advised(points) -> Point | None:
    """The largest timestep tried that keeps every error within ``TOLERANCE``."""
    within = [p for p in points if p.error <= TOLERANCE]
    return max(within, key=lambda p: p.ratio) if within else None


# -- the section -----------------------------------------------------------------------

def reference_checks() -> list:
    """The ODE solver against the closed forms, and against itself at a
    hundred times the tolerance where there is none: rows of a table."""
    rows = []
    for case in CASES:
        ode = ode_outcome(case)
        exact = closed_form(case)
        against = "closed form"
        if exact is None:
            exact, against = ode_outcome(case, 100 * ODE_RTOL), f"ODE at {100 * ODE_RTOL:.0e}"
        rows.append((case.label, f"{ode.contact_time:.8g}", f"{ode.restitution:.8g}", against,
                     f"{relative_error(ode.contact_time, exact.contact_time):.1e}",
                     f"{relative_error(ode.restitution, exact.restitution):.1e}"))
    return rows


@dataclass(frozen=True)
class Scene:
    """A scene's reference, timestep estimate, measurements and cost per step."""

    case: Collision
    outcome: Outcome
    estimate: float
    points: list
    step_cost: float


def run_scene(case: Collision, ratios, phases) -> Scene:
    outcome = reference(case)
    estimate = timestep_estimate(case, outcome)
    return Scene(case, outcome, estimate, measure(case, outcome, estimate, ratios, phases),
                 step_cost(case, min(ratios) * estimate, outcome.contact_time))


def plot(scenes, phases, figures: Path) -> str:
    """Errors against dt / estimate, log-log: contact time left, restitution right."""
    plt = pyplot()
    fig, (ax_t, ax_e) = plt.subplots(1, 2, figsize=(10, 4.2), sharey=True)
    for scene in scenes:
        ratio_s = np.array([p.ratio for p in scene.points])
        for ax, attr in ((ax_t, "time_error"), (ax_e, "restitution_error")):
            error_s = np.array([getattr(p, attr) for p in scene.points])
            ax.loglog(ratio_s, np.where(error_s > 0, error_s, np.nan), "o-",
                      label=scene.case.label)
    guide_s = np.array([min(ratio_s), max(ratio_s)])
    for ax, title in ((ax_t, "contact time"), (ax_e, "restitution coefficient")):
        ax.axhline(TOLERANCE, color="k", lw=0.8, ls=":")
        ax.loglog(guide_s, 0.05 * guide_s, color="0.5", lw=0.8, ls="--", label="~ dt")
        ax.loglog(guide_s, 0.02 * guide_s ** 2, color="0.5", lw=0.8, ls="-.", label="~ dt²")
        ax.set_title(f"{title}: largest error over {len(phases)} phases")
        ax.set_xlabel("dt / calc.stable_timestep(atoms)")
        ax.grid(True, which="both", alpha=0.3)
    ax_t.set_ylabel("relative error")
    ax_t.set_ylim(bottom=3e-6)
    ax_t.legend(fontsize=8, loc="lower right")
    ax_t.text(guide_s[0], TOLERANCE, f" {TOLERANCE:.0%}", va="bottom")
    return save_figure(fig, figures, "collision_timestep")


def scene_table(scene: Scene) -> list:
    """A scene's parameters, reference and estimate, and its errors per timestep."""
    case, outcome = scene.case, scene.outcome
    m_i, m_j = case.mass_n
    return [f"**{case.label}**: `pair_style gran/{case.calculator().law.lammps_args()}`, "
            f"radii {case.radius_n[0]:g} and {case.radius_n[1]:g}, masses {m_i:g} and "
            f"{m_j:g}; reference t_c = {outcome.contact_time:.5g}, "
            f"e = {outcome.restitution:.5g}, deepest overlap {outcome.overlap_max:.3g}; "
            f"estimate {scene.estimate:.4g} (t_c / estimate = "
            f"{outcome.contact_time / scene.estimate:.2f}).", "",
            table(("dt / estimate", "dt", "steps in contact", "t_c error", "e error",
                   "ms / contact"),
                  [(f"{p.ratio:g}", f"{p.dt:.3g}", f"{p.contact_steps:.1f}",
                    f"{p.time_error:.2e}", f"{p.restitution_error:.2e}",
                    f"{1e3 * scene.step_cost * p.contact_steps:.2f}")
                   for p in scene.points]), ""]


def summary_row(scene: Scene) -> tuple:
    """Cost per step, observed orders and the advised timestep of a scene."""
    best = advised(scene.points)
    if best is None:
        advice = (f"none tried (errors {min(p.error for p in scene.points):.2g} at the "
                  "smallest)")
    else:
        advice = f"{best.ratio:g} ({best.contact_steps:.0f} steps in contact)"
    return (scene.case.label, f"{1e6 * scene.step_cost:.0f}",
            f"{observed_order(scene.points, 'time_error'):.2f}",
            f"{observed_order(scene.points, 'restitution_error'):.2f}", advice)


def verdict(scenes, ratios) -> str:
    """The largest timestep tried within the tolerance in every scene."""
    shared = [ratio for ratio in ratios
              if all(p.error <= TOLERANCE for scene in scenes for p in scene.points
                     if p.ratio == ratio)]
    if not shared:
        return f"No timestep tried keeps every scene within {TOLERANCE:.0%}."
    return (f"The largest timestep tried that keeps every scene within {TOLERANCE:.0%} is "
            f"{max(shared):g} times the estimate.")


def section(quick: bool, figures: Path) -> str:
    ratios, phases = (QUICK_RATIOS, QUICK_PHASES) if quick else (RATIOS, PHASES)
    scenes = [run_scene(case, ratios, phases) for case in CASES]
    # the first (Hooke) scene again with the shear history hertz/history keeps:
    # what that bookkeeping costs, apart from the law
    first = scenes[0]
    history_cost = step_cost(replace(first.case, model="hooke/history"),
                             min(ratios) * first.estimate, first.outcome.contact_time)
    coarsest = [max(scene.points, key=lambda p: p.ratio) for scene in scenes]

    out = [
        "## Hooke against Hertz: a binary collision", "",
        "Two spheres meet head on at relative speed 1 (`Granular` under "
        "`SphereVelocityVerlet`, no friction needed); the contact time and the "
        "coefficient of restitution of each run are compared with a closed form "
        "(Hooke; Hertz without damping) or, for Hertz with LAMMPS' damping "
        "`sqrt(R_eff delta) meff gamma_n delta'`, which has none, with the overlap's "
        "equation of motion solved by SciPy at a relative tolerance of "
        f"{ODE_RTOL:.0e}. Formulas and sources: the docstring of "
        "`benchmarks/tradeoff_collision.py`. The timestep runs from "
        f"{min(ratios):g} to {max(ratios):g} times `calc.stable_timestep(atoms)` "
        "taken at the deepest overlap of the collision. Each timestep runs "
        f"{len(phases)} times, the first touch falling at "
        f"{', '.join(f'{p:g}' for p in phases)} of a step; the tables give the largest "
        "error. The end of the contact is interpolated linearly between steps "
        "(exact for velocity Verlet's straight drift in the step that parts the "
        "spheres), so the contact time is not rounded to a step.", "",
        "The references, from the ODE solver, and how far they are from the closed "
        "forms (relative differences), or where there is none from the solver at a "
        "looser tolerance:", "",
        table(("scene", "t_c", "e", "checked against", "t_c diff.", "e diff."),
              reference_checks()), ""]
    for scene in scenes:
        out += scene_table(scene)
    out += [
        f"Observed order (slope of log error against log dt over the {ORDER_POINTS} "
        "smallest timesteps) and the advised timestep, the largest tried with every "
        f"error within {TOLERANCE:.0%}:", "",
        table(("scene", "us / step", "order, t_c", "order, e", "advised dt / estimate"),
              [summary_row(scene) for scene in scenes]), "",
        f"The cost per step is the least of {TIMING_REPEATS} runs at the finest timestep. "
        "On two spheres it is the fixed cost of a step (ASE's integrator, the "
        "calculator's checks and record), not the force law. What Hertz adds is the "
        "shear history its model (`hertz/history`) keeps: the first scene run as "
        f"`hooke/history` costs {1e6 * history_cost:.0f} us / step against "
        f"{1e6 * first.step_cost:.0f} as `hooke`. A collision costs the cost per step "
        "times its steps, in proportion to 1 / dt.", "",
        "Where the force is smooth (no damping) the errors fall as dt^2, as velocity "
        "Verlet's should. With damping they fall more slowly, the contact time's about "
        "as dt, for two reasons. The damping force uses the half-step velocity (as "
        "LAMMPS' `fix nve` does), which acts as a slightly stiffer spring: for Hooke it "
        "shortens the contact by a fraction of about gamma_n dt / 4. And Hooke's "
        "damping force jumps at touch and at parting (to `meff gamma_n delta'` at zero "
        "overlap, attractive at parting), so the impulse a step books depends on where "
        "in the step the jump falls: errors in e of order gamma_n dt with either sign, "
        "whence the spread between phases. Hertz's damping, scaled by "
        "`sqrt(R_eff delta)`, vanishes at zero overlap, and its errors in e stay "
        "smaller. At the estimate itself a contact lasts "
        f"{min(p.contact_steps for p in coarsest):.1f} to "
        f"{max(p.contact_steps for p in coarsest):.1f} steps and the errors reach "
        f"{max(p.error for p in coarsest):.0%}: `stable_timestep` is a stability limit, "
        f"not an accuracy target. {verdict(scenes, ratios)}", "",
        plot(scenes, phases, figures), ""]
    return "\n".join(out)
