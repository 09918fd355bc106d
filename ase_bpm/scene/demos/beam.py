"""A cantilever bending under its own weight: what rotational bonds are for.

Two wires of touching spheres (``atom_style bpm/sphere`` defaults: diameter
1, density 1) stick out along x from a clamp, side by side, under gravity
along -z.  The first sphere of each is the clamp: held by ``FixAtoms``, it
neither moves nor turns (LAMMPS ``fix freeze``).

* The first wire's bonds are ``bond_style bpm/rotational``: besides
  stretching they resist shear, bending and twisting, so the wire is a beam
  and sags a little.
* The second wire's bonds are ``bond_style bpm/spring``: they act along the
  bond only, so the wire is a chain of beads with no bending stiffness; it
  swings down and hangs.

Both feel the same gravity (``ase_bpm.Gravity``), the same ``pair_style
bpm/spring`` contacts and a drag that takes a share of every sphere's
velocity and spin each step (as LAMMPS ``fix viscous`` and
``viscous/sphere``), chosen to damp the beam's slowest bending mode at half
its critical damping, so that the beam settles in a few of its periods.

**The beam in theory.**  A rotational bond between spheres a distance ``a``
apart bends by the relative rotation ``theta`` of its spheres with the
moment ``k_b theta`` (curvature ``theta / a``) and shears by the angle
between the bond and the mean orientation of its spheres with the force
``k_s a`` times that angle.  The wire is thus a Timoshenko beam of bending
stiffness ``EI = k_b a`` and shear stiffness ``kGA = k_s a``.  Each sphere
but the clamp carries its weight ``m g``: a load ``q = m g / a`` per length,
over ``L = (N + 1/2) a`` for ``N`` free spheres (the outermost one carries
half a spacing beyond its centre).  The deflection at distance ``x`` from
the clamp, for small deflections::

    w(x) = q x^2 (6 L^2 - 4 L x + x^2) / (24 EI) + q (L x - x^2 / 2) / kGA

The demo's gravity makes the tip deflection a tenth of the wire's length in
this theory, small enough for it: the settled beam follows it within a few
per cent.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms

#: the spheres: atom_style bpm/sphere's defaults (diameter 1, density 1),
#: touching along the wire
RADIUS = 0.5
DENSITY = 1.0
SPACING = 2 * RADIUS
#: k_r k_s k_t k_b f_rc f_sc tau_tc tau_bc gamma_n gamma_s gamma_r gamma_t;
#: the bonds do not break here (break_bonds=False), so the four critical
#: values only need to be positive
ROTATIONAL = ("bpm/rotational", 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0)
#: bpm/spring's k, eps_c (unused: no breaking) and gamma
SPRING = (1.0, 1.0, 0.0)
#: pair_style bpm/spring k r_c gamma: spheres not bonded repel on touching
PAIR = (1.0, 2 * RADIUS, 0.0)
#: the bond types of the two wires
ROTATIONAL_TYPE, SPRING_TYPE = 1, 2
#: the gap between the two wires (along y), so that they never touch
GAP = 4 * RADIUS
#: the rotational wire's tip deflection in the theory above, a share of its
#: length (the demo's gravity follows from it)
SAG = 0.1
#: the drag's share of the beam's critical damping, for its slowest mode
DAMPING_RATIO = 0.5
#: the first eigenvalue of a cantilever, (beta_1 L)^2: omega_1 = 3.516
#: sqrt(EI / (m' L^4)), m' its mass per length
FIRST_MODE = 1.8751040687 ** 2
TIMESTEP = 0.1
#: free spheres of each wire: the full demo's and --quick's
FULL, QUICK = 20, 10
#: about 20 / omega_1 of each: the beam settles (its swing is e^-10 of its
#: first); the hanging chain has come down
STEPS = 17500
QUICK_STEPS = 4500


def sphere_mass() -> float:
    """The mass of a sphere (density times volume)."""
    return DENSITY * 4 / 3 * np.pi * RADIUS ** 3


def loaded_length(spheres: int) -> float:
    """``L``: the length of wire whose weight the beam carries, ``(N + 1/2) a``."""
    return (spheres + 0.5) * SPACING


def beam_stiffness() -> tuple[float, float]:
    """``EI = k_b a`` and ``kGA = k_s a`` of the rotational wire."""
    k_s, k_b = ROTATIONAL[2], ROTATIONAL[4]
    return k_b * SPACING, k_s * SPACING


def deflection(x, spheres: int, g: float) -> np.ndarray:
    """The Timoshenko cantilever's deflection (downwards, distance units) at
    distances ``x`` from the clamp, under the weight of ``spheres`` free
    spheres in gravity ``g`` (distance/time^2)."""
    x = np.asarray(x, dtype=float)
    bending, shear = beam_stiffness()
    q, length = sphere_mass() * g / SPACING, loaded_length(spheres)
    return (q * x ** 2 * (6 * length ** 2 - 4 * length * x + x ** 2) / (24 * bending)
            + q * (length * x - x ** 2 / 2) / shear)


def gravity(spheres: int) -> float:
    """The gravity under which the beam's tip sags by :data:`SAG` of its
    length in theory."""
    return SAG * spheres * SPACING / deflection(spheres * SPACING, spheres, 1.0)


def first_frequency(spheres: int) -> float:
    """omega_1 of the beam (Euler-Bernoulli), 1/time."""
    bending, _ = beam_stiffness()
    per_length = sphere_mass() / SPACING
    return FIRST_MODE * np.sqrt(bending / (per_length * loaded_length(spheres) ** 4))


def drag_rate(spheres: int) -> float:
    """The drag (1/time): :data:`DAMPING_RATIO` of the critical damping of
    the beam's first mode, ``2 zeta omega_1``."""
    return 2 * DAMPING_RATIO * first_frequency(spheres)


def beam_scene(spheres: int = FULL) -> Atoms:
    """The two wires of ``spheres`` free spheres and a clamp each, straight
    along x: ``wire`` 0 (rotational bonds, type 1) at y = 0, ``wire`` 1
    (spring bonds, type 2) at y = :data:`GAP` + 2 radii; the clamps (the
    spheres at x = 0) held by ``FixAtoms``; at rest."""
    from ase.constraints import FixAtoms

    from ...core.bonds import create_bonds

    count = spheres + 1
    x_n = np.arange(count) * SPACING
    offset = GAP + 2 * RADIUS
    positions = np.concatenate([np.column_stack([x_n, np.full(count, y), np.zeros(count)])
                                for y in (0.0, offset)])
    atoms = Atoms(["Ar"] * 2 * count, positions=positions, pbc=False)
    wire = np.repeat([0, 1], count)
    atoms.arrays["wire"] = wire
    atoms.arrays["type"] = np.ones(len(atoms), dtype=int)
    atoms.arrays["radius"] = np.full(len(atoms), RADIUS)
    atoms.set_masses(np.full(len(atoms), sphere_mass()))
    reach = 1.5 * SPACING  # (next neighbours along the wire only)
    create_bonds(atoms, reach, bond_type=ROTATIONAL_TYPE, mask=wire == 0)
    create_bonds(atoms, reach, bond_type=SPRING_TYPE, mask=wire == 1)
    atoms.set_constraint(FixAtoms(indices=np.flatnonzero(positions[:, 0] == 0.0)))
    length = spheres * SPACING
    atoms.set_cell([length + 4 * SPACING, offset + 4 * SPACING, 2 * length + 4 * SPACING])
    atoms.set_celldisp([-2 * SPACING, -2 * SPACING, -length - 2 * SPACING])
    return atoms


def demo_scene(quick: bool = False) -> Atoms:
    """The scene (``quick``: the shorter wires) with its calculator: both
    bond styles in one BPMSpring, gravity along -z."""
    from ..fixes import Gravity
    from ...models.spring import BPMSpring

    spheres = QUICK if quick else FULL
    atoms = beam_scene(spheres)
    atoms.calc = BPMSpring(bond_coeffs={ROTATIONAL_TYPE: ROTATIONAL, SPRING_TYPE: SPRING},
                           pair_coeffs={(1, 1): PAIR}, break_bonds=False, smooth=False,
                           fixes=[Gravity(gravity(spheres))])
    return atoms


def run_beam(steps: int | None = None, quick: bool = False,
             trajectory: str | None = "beam.extxyz", plot: str | None = "beam.png",
             picture: str | None = "beam-final.png", every: int = 250, sample: int = 25,
             progress: bool = True) -> dict:
    """Let both wires bend for ``steps`` steps (None: :data:`STEPS`, with
    ``quick`` :data:`QUICK_STEPS`) with ``SphereVelocityVerlet`` and the
    drag; write frames (``wire`` 0 rotational, 1 spring), a plot of the tip
    deflections against time and a picture of the two wires from the side
    with the beam theory's curve.

    Returns a summary: spheres per wire, the gravity, the tip deflections of
    both wires and the theory's, the largest speed in the rotational wire at
    the end, wall time and milliseconds per step."""
    from ..md import SphereVelocityVerlet
    from ..viewing import ViewerTrajectory
    from . import drive

    if steps is None:
        steps = QUICK_STEPS if quick else STEPS
    spheres = QUICK if quick else FULL
    atoms = demo_scene(quick)
    tips = [spheres, 2 * spheres + 1]  # the last sphere of each wire
    z0 = atoms.positions[tips, 2].copy()
    dyn = SphereVelocityVerlet(atoms, TIMESTEP)
    keep = np.exp(-drag_rate(spheres) * TIMESTEP)

    def drag():
        atoms.set_momenta(keep * atoms.get_momenta(), apply_constraint=False)
        atoms.arrays["omega"] = keep * atoms.arrays["omega"]

    dyn.attach(drag, interval=1)
    series = {"time": [], "rotational": [], "spring": []}

    def record(n):
        sag = z0 - atoms.positions[tips, 2]
        series["time"].append(n * TIMESTEP)
        series["rotational"].append(float(sag[0]))
        series["spring"].append(float(sag[1]))

    writer = ViewerTrajectory(trajectory, atoms, arrays=["wire"]) if trajectory else None
    wall = drive(dyn, steps, label="beam", record=record, sample=sample, writer=writer,
                 every=every, timestep=TIMESTEP, progress=progress)
    g = gravity(spheres)
    theory = float(deflection(spheres * SPACING, spheres, g))
    if plot:
        plot_tips(series, plot, theory)
    if picture:
        draw(atoms, picture, g, f"after {steps:,} steps (t = {steps * TIMESTEP:g} "
                                "\N{GREEK SMALL LETTER TAU})")
    return {"spheres": spheres, "steps": steps, "gravity": g,
            "rotational_tip": series["rotational"][-1], "spring_tip": series["spring"][-1],
            "theory_tip": theory, "length": spheres * SPACING,
            "rotational_speed": float(np.linalg.norm(
                atoms.get_velocities()[atoms.arrays["wire"] == 0], axis=1).max()),
            "wall_seconds": wall, "ms_per_step": 1e3 * wall / max(steps, 1),
            "trajectory": trajectory, "plot": plot, "picture": picture}


#: the colours of the two wires in the plots
COLOURS = {"rotational": "tab:blue", "spring": "tab:orange"}
LABELS = {"rotational": "bpm/rotational bonds", "spring": "bpm/spring bonds"}


def plot_tips(series: dict, filename: str, theory: float):
    """The tip deflection of both wires against time, with the beam theory's
    for the rotational wire, as a PNG; returns the matplotlib figure."""
    from matplotlib.figure import Figure

    from . import REDUCED_TIME, save_figure

    fig = Figure(figsize=(6, 4.5), layout="tight")
    ax = fig.add_subplot()
    for wire in ("rotational", "spring"):
        ax.plot(series["time"], series[wire], color=COLOURS[wire], label=LABELS[wire])
    ax.axhline(theory, color="black", linestyle="--", linewidth=1,
               label="beam theory, EI = k_b a (rotational)")
    ax.set_ylabel("tip deflection (distance units)")
    ax.set_xlabel(REDUCED_TIME)
    ax.set_title("ase-bpm: two cantilevers under their own weight")
    ax.legend()
    return save_figure(fig, filename)


def draw(atoms: Atoms, filename: str, g: float, when: str = ""):
    """Both wires seen from the side (along y), their spheres at their true
    size, coloured by wire, the clamp hatched, and the beam theory's
    deflection curve through the rotational wire's place; returns the
    matplotlib figure."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Rectangle

    from . import save_figure

    wire = atoms.arrays["wire"]
    spheres = int((wire == 0).sum()) - 1
    fig = Figure(figsize=(7, 5.5), layout="tight")
    ax = fig.add_subplot()
    for index, name in enumerate(("rotational", "spring")):
        for x, _, z in atoms.positions[wire == index]:
            ax.add_patch(Circle((x, z), RADIUS, facecolor=COLOURS[name], edgecolor="black",
                                linewidth=0.3, alpha=0.85))
        ax.plot([], [], "o", color=COLOURS[name], label=LABELS[name])
    x = np.linspace(0.0, spheres * SPACING, 200)
    ax.plot(x, -deflection(x, spheres, g), color="black", linestyle="--", linewidth=1.2,
            label="beam theory: EI = k_b a, kGA = k_s a")
    length = spheres * SPACING
    ax.add_patch(Rectangle((-2 * SPACING, -length - SPACING), 1.5 * SPACING,
                           length + 2 * SPACING, facecolor="lightgrey", hatch="//",
                           edgecolor="grey"))
    ax.set_xlim(-2 * SPACING, length + 2 * SPACING)
    ax.set_ylim(-length - SPACING, 2 * SPACING)
    ax.set_aspect("equal")
    ax.set_xlabel("x, along the wire (distance units)")
    ax.set_ylabel("z (distance units; gravity along -z)")
    ax.set_title(f"ase-bpm beam: clamped wires {when}".strip())
    ax.legend(loc="center right")
    return save_figure(fig, filename)
