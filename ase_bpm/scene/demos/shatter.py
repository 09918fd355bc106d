"""The LAMMPS ``examples/bpm/peri`` scene: a brittle cylinder shattered by a
spherical indenter, built with ASE and run with ase_bpm's velocity Verlet.

LAMMPS deck, in short (SI units)::

    lattice sc 0.0005
    region target cylinder y 0.0 0.0 0.0050 -0.0050 0.0 units box
    mass * 2.75e-7                                   # density 2200 x volume
    set group all d_vfrac 1.25e-10
    pair_coeff * * 1.6863e22 0.0015001               # bpm/peri contact
    create_bonds many all all 1 0.0 0.0015001
    bond_coeff 1 pmb 1.6863e22 0.0015001 0.0005 0.25
    variable y equal "0.00155 + step*dt*(-100)"
    fix 2 all indent 1e17 sphere 0.0 v_y 0.0 0.0015 units box
    timestep 1.0e-7
    run 2000

``fix indent`` acts on PERI force densities: the true-force stiffness of the
ase_bpm indenter is ``1e17 * 1.25e-10``, the legacy ``examples/peri``
reading of the deck; the demo follows the legacy styles (``follows="legacy"``,
which that indenter belongs to, and which the reference build runs when
exported).  LAMMPS' ``bpm/peri`` deck puts the same ``1e17`` on true
masses, eight billion times stiffer.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms

from ...core.bonds import create_bonds

SPACING = 0.0005
HORIZON = 0.0015001
VOLUME = 1.25e-10
DENSITY = 2200.0
MICROMODULUS = 1.6863e22
BOND_COEFFS = {1: ("pmb", MICROMODULUS, HORIZON, 0.0005, 0.25)}
PAIR_COEFFS = {(1, 1): (MICROMODULUS, HORIZON)}
INDENTER = dict(k=1e17 * VOLUME, radius=0.0015, centre=(0.0, 0.00155, 0.0),
                velocity=(0.0, -100.0, 0.0))
TIMESTEP = 1e-7
STEPS = 2000
QUICK_STEPS = 400


def cylinder(radius: float = 0.0050, height: float = 0.0050) -> Atoms:
    """Simple cubic nodes in a cylinder along y, from y = -height to 0,
    bonded within the horizon (LAMMPS ``region cylinder y``)."""
    n = int(np.ceil(max(radius, height) / SPACING))
    k = np.arange(-n, n + 1)
    grid = np.array(np.meshgrid(k, k, k, indexing="ij")).reshape(3, -1).T * SPACING
    inside = (np.hypot(grid[:, 0], grid[:, 2]) <= radius + 1e-12) & \
        (grid[:, 1] >= -height - 1e-12) & (grid[:, 1] <= 1e-12)
    atoms = Atoms(f"Si{inside.sum()}", positions=grid[inside], pbc=False)
    atoms.arrays["vfrac"] = np.full(len(atoms), VOLUME)
    atoms.set_masses(np.full(len(atoms), DENSITY * VOLUME))
    create_bonds(atoms, HORIZON)
    return atoms


def demo_scene(quick: bool = False) -> Atoms:
    """The scene with its calculator (``quick`` changes only the steps)."""
    from ..fixes import SphericalIndenter
    from ...models.peri import BPMPeri

    atoms = cylinder()
    atoms.calc = BPMPeri(bond_coeffs=BOND_COEFFS, pair_coeffs=PAIR_COEFFS,
                         fixes=[SphericalIndenter(**INDENTER)], follows="legacy")
    return atoms


def run_shatter(steps: int = STEPS,
                trajectory: str | None = "shatter.extxyz", plot: str | None = "shatter.png",
                picture: str | None = "shatter-final.png", every: int = 100,
                sample: int = 10, progress: bool = True) -> dict:
    """Shatter the cylinder for ``steps`` steps (the example's 2,000, or 400
    for a quick look): ase_bpm's velocity Verlet (the indenter's clock),
    an extxyz trajectory for ase gui, a PNG of mean damage against time and a
    picture of the fractured cylinder coloured by damage."""
    from ..md import VelocityVerlet
    from ..viewing import ViewerTrajectory
    from . import drive

    atoms = demo_scene()
    dyn = VelocityVerlet(atoms, timestep=TIMESTEP)
    series = {"time": [], "mean_damage": []}

    def record(n):
        series["time"].append(n * TIMESTEP)
        series["mean_damage"].append(float(atoms.arrays["damage"].mean()))

    writer = ViewerTrajectory(trajectory, atoms) if trajectory else None
    wall = drive(dyn, steps, label="shatter", record=record, sample=sample, writer=writer,
                 every=every, timestep=TIMESTEP, progress=progress)
    if plot:
        plot_damage(series, plot)
    if picture:
        draw(atoms, picture, f"after {steps:,} steps (t = {1e6 * steps * TIMESTEP:g} "
                             "\N{MICRO SIGN}s)")
    return {"nodes": len(atoms), "broken": len(atoms.info.get("broken_bonds", [])),
            "mean_damage": series["mean_damage"][-1], "steps": steps,
            "wall_seconds": wall, "ms_per_step": 1e3 * wall / max(steps, 1),
            "trajectory": trajectory, "plot": plot, "picture": picture}


def plot_damage(series: dict, filename: str):
    """Mean damage against time, as a PNG; returns the matplotlib figure."""
    from matplotlib.figure import Figure

    from . import save_figure

    fig = Figure(figsize=(6, 3.5), layout="tight")
    ax = fig.add_subplot()
    ax.plot(1e6 * np.asarray(series["time"]), series["mean_damage"], color="tab:red")
    ax.set_xlabel("time (\N{MICRO SIGN}s)")
    ax.set_ylabel("mean damage")
    ax.set_title("ase-bpm: brittle cylinder struck by an indenter")
    return save_figure(fig, filename)


#: the damage at which a node's colour is the reddest (beyond it: the same)
DAMAGE_TOP = 0.5


def draw(atoms: Atoms, filename: str, when: str = ""):
    """A picture of the nodes coloured by damage (blue intact, red broken
    off; ``DAMAGE_TOP`` and beyond the reddest), seen obliquely from above,
    onto the struck face, with a title (ending in ``when``) and a colour
    bar; returns the matplotlib figure."""
    from . import DAMAGE_COLOURS, picture

    view = Atoms(atoms.numbers, positions=atoms.positions / SPACING)
    return picture(view, atoms.arrays["damage"], filename,
                   title=f"ase-bpm shatter: the cylinder {when}".strip(),
                   label="damage (share of the node's bond volume lost)",
                   limits=(0.0, DAMAGE_TOP), extend="max", cmap=DAMAGE_COLOURS,
                   rotation="60x,20y", radii=np.full(len(view), 0.45))
