"""Granular pour: polydisperse spheres fall into a box and settle.

The physics of the LAMMPS ``examples/pour`` deck (reduced units, density 1,
diameters from 0.8 to 1.2), with the spheres released at once from a loose
grid instead of poured in over time, and a box of frictional walls::

    atom_style sphere
    pair_style gran/hooke/history 2000.0 NULL 50.0 NULL 0.5 0
    pair_coeff * *
    timestep 0.001
    fix 1 all nve/sphere
    fix 2 all gravity 1.0 vector 0 0 -1
    fix floor all wall/gran hooke/history 2000.0 NULL 50.0 NULL 0.5 0 zplane 0.0 NULL
    fix sides_x all wall/gran hooke/history ... xplane 0.0 15.0
    fix sides_y all wall/gran hooke/history ... yplane 0.0 15.0

``ase_bpm.write_lammps`` writes this deck for the scene (with the
``NULL`` defaults spelled out).
"""

from __future__ import annotations

import numpy as np
from ase import Atoms

#: gran/hooke/history 2000.0 NULL 50.0 NULL 0.5 0 (kt = 2/7 kn; no tangential damping)
LAW = dict(model="hooke/history", kn=2000.0, gamma_n=50.0, xmu=0.5, dampflag=0)
GRAVITY = 1.0
TIMESTEP = 0.001
SPACING = 1.25  # of the release grid: no two spheres touch at the start
FULL = dict(count=3000, width=15.0)
QUICK = dict(count=500, width=10.0)
STEPS = 15000
QUICK_STEPS = 8000


def pour_scene(count: int = 3000, width: float = 15.0, radii=(0.4, 0.6),
               seed: int = 300719) -> Atoms:
    """``count`` spheres on a jittered grid above the floor of a square box
    of side ``width``, with random radii (uniform in ``radii``), density 1,
    small random velocities and no spin."""
    rng = np.random.default_rng(seed)
    per_side = int(width // SPACING)
    layers = -(-count // per_side ** 2)
    grid = np.indices((per_side, per_side, layers)).reshape(3, -1).T[:count]
    jitter = rng.uniform(-0.015, 0.015, grid.shape)  # keeps every gap open
    positions = (grid + 0.5 + jitter) * SPACING
    positions[:, :2] += 0.5 * (width - per_side * SPACING)  # centred in the box
    atoms = Atoms(["Ar"] * count, positions=positions, pbc=False)
    radius = rng.uniform(*radii, count)
    atoms.arrays["radius"] = radius
    atoms.set_masses(4.0 / 3.0 * np.pi * radius ** 3)  # density 1
    atoms.set_velocities(rng.normal(0.0, 0.1, (count, 3)))
    atoms.arrays["omega"] = np.zeros((count, 3))
    atoms.set_cell([width, width, positions[:, 2].max() + 1.0])
    return atoms


def pour_calculator(width: float = 15.0, kernels: str = "auto"):
    """Granular with gravity, a floor and four side walls, all with LAW."""
    from ..fixes import GranularWall, Gravity
    from ...models.granular import Granular

    walls = [GranularWall(**LAW, axis="z", lo=0.0, kernels=kernels),
             GranularWall(**LAW, axis="x", lo=0.0, hi=width, kernels=kernels),
             GranularWall(**LAW, axis="y", lo=0.0, hi=width, kernels=kernels)]
    return Granular(**LAW, fixes=[Gravity(GRAVITY)] + walls, kernels=kernels)


def demo_scene(quick: bool = False) -> Atoms:
    """The scene (``quick``: the 500 spheres) with its calculator."""
    size = QUICK if quick else FULL
    atoms = pour_scene(**size)
    atoms.calc = pour_calculator(size["width"])
    return atoms


def run_pour(steps: int = STEPS, quick: bool = False,
             trajectory: str | None = "pour.extxyz", plot: str | None = "pour.png",
             picture: str | None = "pour-final.png", every: int = 500, sample: int = 50,
             progress: bool = True) -> dict:
    """Pour the spheres for ``steps`` steps with ``SphereVelocityVerlet``:
    an extxyz trajectory for ase gui (radius, ncontacts), a PNG of the
    kinetic energy decay and a picture of the settled pile."""
    from ..md import SphereVelocityVerlet
    from ...core.spheres import rotational_energy
    from ..viewing import ViewerTrajectory
    from . import drive

    atoms = demo_scene(quick)
    dyn = SphereVelocityVerlet(atoms, TIMESTEP)
    series = {"time": [], "kinetic_energy": [], "rotational_energy": [], "contacts": []}

    def record(n):
        series["time"].append(n * TIMESTEP)
        series["kinetic_energy"].append(atoms.get_kinetic_energy())
        series["rotational_energy"].append(rotational_energy(atoms))
        series["contacts"].append(int(atoms.arrays["ncontacts"].sum()) // 2)

    writer = ViewerTrajectory(trajectory, atoms) if trajectory else None
    wall = drive(dyn, steps, label="pour", record=record, sample=sample, writer=writer,
                 every=every, timestep=TIMESTEP, progress=progress)
    if plot:
        plot_energy(series, plot)
    if picture:
        draw(atoms, picture, f"after {steps:,} steps (t = {steps * TIMESTEP:g} "
                             "\N{GREEK SMALL LETTER TAU})")
    return {"spheres": len(atoms), "steps": steps, "contacts": series["contacts"][-1],
            "kinetic_energy": series["kinetic_energy"][-1],
            "peak_kinetic_energy": max(series["kinetic_energy"]),
            "height": float((atoms.positions[:, 2] + atoms.arrays["radius"]).max()),
            "wall_seconds": wall, "ms_per_step": 1e3 * wall / max(steps, 1),
            "trajectory": trajectory, "plot": plot, "picture": picture}


def plot_energy(series: dict, filename: str):
    """Translational and rotational kinetic energy against time (log scale)
    and the number of contacts, as a PNG; returns the matplotlib figure."""
    from matplotlib.figure import Figure

    from . import REDUCED_TIME, save_figure

    t = np.asarray(series["time"])

    def positive(values):  # a log scale shows no zeros (the spheres start unspun)
        values = np.asarray(values, dtype=float)
        return np.where(values > 0, values, np.nan)

    fig = Figure(figsize=(6, 5), layout="tight")
    top, bottom = fig.subplots(2, 1, sharex=True)
    top.semilogy(t, positive(series["kinetic_energy"]), color="tab:red", label="translation")
    top.semilogy(t, positive(series["rotational_energy"]), color="tab:purple",
                 label="rotation")
    top.set_ylabel("kinetic energy (reduced units)")
    top.legend()
    top.set_title("ase-bpm: spheres poured into a box")
    bottom.plot(t, series["contacts"], color="tab:blue")
    bottom.set_ylabel("contacts (touching pairs)")
    bottom.set_xlabel(REDUCED_TIME)
    return save_figure(fig, filename)


def draw(atoms: Atoms, filename: str, when: str = "", width: float | None = None):
    """The pile in its box (``width``: the cell's by default), seen obliquely
    from the side, spheres at their true size, coloured by the height of
    their centres, with a title (ending in ``when``) and a colour bar;
    returns the matplotlib figure."""
    from . import picture

    z = atoms.positions[:, 2]
    width = atoms.cell[0, 0] if width is None else width
    top = float((z + atoms.arrays["radius"]).max())
    view = Atoms(atoms.numbers, positions=atoms.positions, cell=[width, width, 1.1 * top])
    return picture(view, z, filename, title=f"ase-bpm pour: the pile {when}".strip(),
                   label="height of the centre above the floor (reduced units)",
                   limits=(0.0, float(z.max())), rotation="-90x,30y,20x",
                   radii=atoms.arrays["radius"])
