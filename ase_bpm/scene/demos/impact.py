"""The LAMMPS ``examples/bpm/impact`` scene, built with ASE.

A thin FCC disk (reduced density 1) is struck edge-on by a bonded FCC ball
moving at 0.05 lattice spacings per unit time (LAMMPS ``velocity`` uses
lattice units by default).  Bonds within the disk (type 1) break at 4 % strain, bonds
within the ball (type 2) at 20 %, so the ball stays whole and the disk
shatters.  Reduced LJ units: mass 1, timestep 0.1.

LAMMPS deck, in short::

    lattice fcc 1.0
    region disk cylinder x 0.0 0.0 20.0 -0.5 0.5    # 7529 atoms
    region ball sphere 8.0 0.0 0.0 6.0              # 3589 atoms
    displace_atoms all random 0.1 0.1 0.1 134598738
    create_bonds many plate plate 1 0.0 1.5          # 38559 bonds
    create_bonds many projectile projectile 2 0.0 1.5  # 21869 bonds
    pair_coeff 1 1 1.0 1.0 1.0
    bond_coeff 1 1.0 0.04 1.0
    bond_coeff 2 1.0 0.20 1.0
    velocity projectile set -0.05 0.0 0.0
    timestep 0.1
    run 7500

The random displacements come from NumPy, not LAMMPS' generator, so the
particles sit slightly differently; counts and statistics are the same.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms
from ase.lattice.cubic import FaceCenteredCubic

from ...core.bonds import create_bonds

LATTICE = 4 ** (1 / 3)  # LAMMPS "lattice fcc 1.0"
BOND_COEFFS = {1: (1.0, 0.04, 1.0), 2: (1.0, 0.20, 1.0)}
PAIR_COEFFS = {(1, 1): (1.0, 1.0, 1.0)}
TIMESTEP = 0.1
STEPS = 7500
QUICK_STEPS = 1500
FULL = dict(disk_radius=20.0, ball_radius=6.0, ball_centre=8.0)
QUICK = dict(disk_radius=8.0, ball_radius=3.0, ball_centre=5.0)


def _lattice_points(lo, hi) -> np.ndarray:
    """FCC sites (lattice units) with integer cell corners from lo to hi."""
    size = [int(top - bottom) + 1 for bottom, top in zip(lo, hi)]
    block = FaceCenteredCubic("Ne", size=size, latticeconstant=1.0, pbc=False)
    return np.round(2 * (block.positions + lo)) / 2  # exact half-integers


def impact_scene(disk_radius: float = 20.0, ball_radius: float = 6.0,
                 ball_centre: float = 8.0, speed: float = 0.05,
                 seed: int = 134598738) -> Atoms:
    """Disk and ball, bonded, with the ball moving towards the disk.

    Lengths and the speed in lattice units as in the LAMMPS deck.  Returns the atoms with
    ``type`` (all 1), ``bonds`` (type 1 in the disk, 2 in the ball),
    ``body`` (0 disk, 1 ball), masses 1 and velocities.
    """
    r = int(np.ceil(max(disk_radius, ball_radius))) + 1
    x_hi = int(np.ceil(ball_centre + ball_radius)) + 1
    sites = _lattice_points((-1, -r, -r), (x_hi, r, r))
    in_disk = (np.hypot(sites[:, 1], sites[:, 2]) <= disk_radius) & (np.abs(sites[:, 0]) <= 0.5)
    in_ball = np.linalg.norm(sites - [ball_centre, 0, 0], axis=1) <= ball_radius
    sites = np.concatenate([sites[in_disk], sites[in_ball]])
    body = np.r_[np.zeros(in_disk.sum(), int), np.ones(in_ball.sum(), int)]

    rng = np.random.default_rng(seed)
    positions = LATTICE * (sites + rng.uniform(-0.1, 0.1, sites.shape))
    atoms = Atoms(["Ne"] * len(sites), positions=positions, pbc=False)
    atoms.set_masses(np.ones(len(atoms)))
    atoms.arrays["type"] = np.ones(len(atoms), dtype=int)
    atoms.arrays["body"] = body
    create_bonds(atoms, 1.5, bond_type=1, mask=body == 0)
    create_bonds(atoms, 1.5, bond_type=2, mask=body == 1)
    velocities = np.zeros((len(atoms), 3))
    velocities[body == 1, 0] = -speed * LATTICE
    atoms.set_velocities(velocities)
    extent = atoms.positions.max(axis=0) - atoms.positions.min(axis=0)
    atoms.set_cell(np.diag(extent + 2.0))
    atoms.set_celldisp(atoms.positions.min(axis=0) - 1.0)
    return atoms


def demo_scene(quick: bool = False) -> Atoms:
    """The scene (``quick``: the small one) with its calculator."""
    from ...models.spring import BPMSpring

    atoms = impact_scene(**(QUICK if quick else FULL))
    atoms.calc = BPMSpring(bond_coeffs=BOND_COEFFS, pair_coeffs=PAIR_COEFFS)
    return atoms


def run_impact(steps: int = STEPS, quick: bool = False,
               trajectory: str | None = "impact.extxyz", plot: str | None = "impact.png",
               picture: str | None = "impact-final.png", every: int = 250, sample: int = 10,
               progress: bool = True) -> dict:
    """Run the impact with ASE's VelocityVerlet; write frames, a plot of the
    kinetic energy and intact bonds, and a picture of the broken disk.

    Returns a summary: atom and bond counts, bonds broken, final kinetic
    energy, wall time and milliseconds per step.
    """
    from ase.md.verlet import VelocityVerlet

    from ...core.bonds import get_bonds
    from ..viewing import ViewerTrajectory
    from . import drive

    atoms = demo_scene(quick)
    bonds_start = len(get_bonds(atoms)[0])
    dyn = VelocityVerlet(atoms, timestep=TIMESTEP)

    series = {"time": [], "kinetic_energy": [], "intact_bonds": []}

    def record(n):
        series["time"].append(n * TIMESTEP)
        series["kinetic_energy"].append(atoms.get_kinetic_energy())
        series["intact_bonds"].append(int(atoms.arrays["nbonds"].sum()) // 2)

    writer = ViewerTrajectory(trajectory, atoms) if trajectory else None
    wall = drive(dyn, steps, label="impact", record=record, sample=sample, writer=writer,
                 every=every, timestep=TIMESTEP, progress=progress)
    if plot:
        plot_series(series, plot)
    if picture:
        draw_disk(atoms, picture, f"after {steps:,} steps (t = {steps * TIMESTEP:g} "
                                  "\N{GREEK SMALL LETTER TAU})")
    return {
        "atoms": len(atoms), "bonds": bonds_start,
        "broken": bonds_start - series["intact_bonds"][-1],
        "kinetic_energy": series["kinetic_energy"][-1],
        "steps": steps, "wall_seconds": wall,
        "ms_per_step": 1e3 * wall / max(steps, 1),
        "trajectory": trajectory, "plot": plot, "picture": picture,
    }


def plot_series(series: dict, filename: str):
    """Kinetic energy and intact bonds against time, as a PNG; returns the
    matplotlib figure."""
    from matplotlib.figure import Figure

    from . import REDUCED_TIME, save_figure

    fig = Figure(figsize=(6, 5), layout="tight")
    top, bottom = fig.subplots(2, 1, sharex=True)
    top.plot(series["time"], series["kinetic_energy"], color="tab:red")
    top.set_ylabel("kinetic energy (reduced units)")
    bottom.plot(series["time"], series["intact_bonds"], color="tab:blue")
    bottom.set_ylabel("intact bonds")
    bottom.set_xlabel(REDUCED_TIME)
    top.set_title("ase-bpm: ball striking a bonded disk")
    return save_figure(fig, filename)


def draw_disk(atoms: Atoms, filename: str, when: str = ""):
    """The disk (``body`` 0, without the ball) seen face-on, along x, its
    particles at their display radius and coloured by ``damage`` (the share
    of each particle's bonds broken), with a title (ending in ``when``) and a
    colour bar; returns the matplotlib figure."""
    from ..viewing import display_radius
    from . import DAMAGE_COLOURS, picture

    disk = atoms.arrays["body"] == 0
    view = Atoms(atoms.numbers[disk], positions=atoms.positions[disk])
    radius = display_radius(atoms)
    return picture(view, atoms.arrays["damage"][disk], filename,
                   title=f"ase-bpm impact: the disk {when}".strip(),
                   label="damage (share of the particle's bonds broken)", limits=(0.0, 1.0),
                   cmap=DAMAGE_COLOURS, rotation="90y", radii=None if radius is None else radius[disk])
