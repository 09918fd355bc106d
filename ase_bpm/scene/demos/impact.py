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

``bonds="rotational"``: the scene of LAMMPS's ``in.bpm.impact.rotational``,
the same disk and ball of ``atom_style bpm/sphere`` particles (diameter 1,
density 1) joined by ``bond_style bpm/rotational`` bonds, which also resist
shear, bending and twisting, with ``pair_style gran/hooke/history`` contacts
between particles not bonded, run with ``SphereVelocityVerlet`` (``fix
nve/bpm/sphere``)::

    atom_style bpm/sphere
    pair_style gran/hooke/history 1.0 NULL 0.5 NULL 0.1 1
    fix 1 all nve/bpm/sphere
    bond_style bpm/rotational
    bond_coeff 1 1.0 0.2 0.02 0.02 0.05 0.01 0.01 0.01 0.1 0.2 0.002 0.002
    bond_coeff 2 1.0 0.2 0.02 0.02 0.20 0.04 0.04 0.04 0.1 0.2 0.002 0.002
    timestep 0.05
    run 7500
"""

from __future__ import annotations

from typing import NamedTuple

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

#: in.bpm.impact.rotational's bond_coeff lines (k_r k_s k_t k_b f_rc f_sc
#: tau_tc tau_bc gamma_n gamma_s gamma_r gamma_t): the disk's bonds (1) break
#: at a quarter of the loads of the ball's (2)
ROTATIONAL_BOND_COEFFS = {
    1: ("bpm/rotational", 1.0, 0.2, 0.02, 0.02, 0.05, 0.01, 0.01, 0.01, 0.1, 0.2, 0.002, 0.002),
    2: ("bpm/rotational", 1.0, 0.2, 0.02, 0.02, 0.20, 0.04, 0.04, 0.04, 0.1, 0.2, 0.002, 0.002)}
#: pair_style gran/hooke/history 1.0 NULL 0.5 NULL 0.1 1 (kt = 2/7 kn,
#: gamma_t = gamma_n / 2), between particles not bonded
GRANULAR = dict(model="hooke/history", kn=1.0, gamma_n=0.5, xmu=0.1, dampflag=1)
#: atom_style bpm/sphere's particles by default: diameter 1, density 1
SPHERE_RADIUS = 0.5
SPHERE_DENSITY = 1.0


class Variant(NamedTuple):
    """What a choice of bonds (``--bonds``) runs: its timestep and numbers of
    steps (the full scene's and ``--quick``'s, the same time span)."""

    timestep: float
    steps: int
    quick_steps: int


#: the demo's bonds: LAMMPS's in.bpm.impact.spring and in.bpm.impact.rotational
VARIANTS = {"spring": Variant(TIMESTEP, STEPS, QUICK_STEPS),
            "rotational": Variant(0.05, 7500, 3000)}


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


def variant(bonds: str) -> Variant:
    """The timestep and steps of ``bonds`` (a key of :data:`VARIANTS`);
    ValueError naming the choices for anything else."""
    if bonds not in VARIANTS:
        raise ValueError(f"bonds={bonds!r}: the impact demo's bonds are "
                         f"{', '.join(map(repr, VARIANTS))}")
    return VARIANTS[bonds]


def make_spheres(atoms: Atoms) -> None:
    """Give every particle the size and mass of an ``atom_style bpm/sphere``
    particle by default (radius :data:`SPHERE_RADIUS`, mass from
    :data:`SPHERE_DENSITY`), keeping the velocities."""
    velocities = atoms.get_velocities()
    atoms.arrays["radius"] = np.full(len(atoms), SPHERE_RADIUS)
    atoms.set_masses(np.full(len(atoms), SPHERE_DENSITY * 4 / 3 * np.pi * SPHERE_RADIUS ** 3))
    atoms.set_velocities(velocities)


def demo_scene(quick: bool = False, bonds: str = "spring") -> Atoms:
    """The scene (``quick``: the small one) with its calculator: ``bonds``
    "spring" (in.bpm.impact.spring) or "rotational" (in.bpm.impact.rotational:
    spheres, rotational bonds, granular contacts)."""
    from ...models.spring import BPMSpring

    variant(bonds)
    atoms = impact_scene(**(QUICK if quick else FULL))
    if bonds == "rotational":
        make_spheres(atoms)
        atoms.calc = BPMSpring(bond_coeffs=ROTATIONAL_BOND_COEFFS, granular=GRANULAR)
    else:
        atoms.calc = BPMSpring(bond_coeffs=BOND_COEFFS, pair_coeffs=PAIR_COEFFS)
    return atoms


def run_impact(steps: int | None = None, quick: bool = False,
               trajectory: str | None = "impact.extxyz", plot: str | None = "impact.png",
               picture: str | None = "impact-final.png", every: int = 250, sample: int = 10,
               progress: bool = True, bonds: str = "spring") -> dict:
    """Run the impact (``bonds``: "spring" with ASE's VelocityVerlet,
    "rotational" with SphereVelocityVerlet) for ``steps`` steps (None: the
    variant's, :data:`VARIANTS`); write frames, a plot of the kinetic energy
    and intact bonds, and a picture of the broken disk.

    Returns a summary: atom and bond counts, bonds broken, final kinetic
    energy, wall time and milliseconds per step.
    """
    from ase.md.verlet import VelocityVerlet

    from ...core.bonds import get_bonds
    from ..md import SphereVelocityVerlet
    from ..viewing import ViewerTrajectory
    from . import drive

    timestep, full_steps, quick_steps = variant(bonds)
    if steps is None:
        steps = quick_steps if quick else full_steps
    atoms = demo_scene(quick, bonds)
    bonds_start = len(get_bonds(atoms)[0])
    integrator = SphereVelocityVerlet if bonds == "rotational" else VelocityVerlet
    dyn = integrator(atoms, timestep=timestep)

    series = {"time": [], "kinetic_energy": [], "intact_bonds": []}

    def record(n):
        series["time"].append(n * timestep)
        series["kinetic_energy"].append(atoms.get_kinetic_energy())
        series["intact_bonds"].append(int(atoms.arrays["nbonds"].sum()) // 2)

    writer = ViewerTrajectory(trajectory, atoms) if trajectory else None
    wall = drive(dyn, steps, label=f"impact ({bonds})", record=record, sample=sample,
                 writer=writer, every=every, timestep=timestep, progress=progress)
    if plot:
        plot_series(series, plot, bonds)
    if picture:
        draw_disk(atoms, picture, f"after {steps:,} steps (t = {steps * timestep:g} "
                                  "\N{GREEK SMALL LETTER TAU})", bonds)
    return {"bond_style": bonds,
        "atoms": len(atoms), "bonds": bonds_start,
        "broken": bonds_start - series["intact_bonds"][-1],
        "kinetic_energy": series["kinetic_energy"][-1],
        "steps": steps, "wall_seconds": wall,
        "ms_per_step": 1e3 * wall / max(steps, 1),
        "trajectory": trajectory, "plot": plot, "picture": picture,
    }


def _named(bonds: str) -> str:
    """What a title adds for ``bonds`` other than the springs."""
    return "" if bonds == "spring" else f" ({bonds} bonds)"


def plot_series(series: dict, filename: str, bonds: str = "spring"):
    """Kinetic energy and intact bonds against time, as a PNG (the title
    names the ``bonds`` where they are not springs); returns the matplotlib
    figure."""
    from matplotlib.figure import Figure

    from . import REDUCED_TIME, save_figure

    fig = Figure(figsize=(6, 5), layout="tight")
    top, bottom = fig.subplots(2, 1, sharex=True)
    top.plot(series["time"], series["kinetic_energy"], color="tab:red")
    top.set_ylabel("kinetic energy (reduced units)")
    bottom.plot(series["time"], series["intact_bonds"], color="tab:blue")
    bottom.set_ylabel("intact bonds")
    bottom.set_xlabel(REDUCED_TIME)
    top.set_title("ase-bpm: ball striking a bonded disk" + _named(bonds))
    return save_figure(fig, filename)


def draw_disk(atoms: Atoms, filename: str, when: str = "", bonds: str = "spring"):
    """The disk (``body`` 0) coloured by ``damage`` (the share of each
    particle's bonds broken), its particles at their display radius, with a
    title (ending in ``when``) and a colour bar; returns the matplotlib
    figure.  Springs: the disk alone, seen face-on along x.  Other ``bonds``
    (rotational): the ball too, in :data:`~ase_bpm.scene.demos.CONTEXT_COLOUR`,
    seen from its side, 30 degrees off the disk's axis: the ball stays whole
    and stuck in the disk it shattered."""
    from ..viewing import display_radius
    from . import DAMAGE_COLOURS, picture

    disk = atoms.arrays["body"] == 0
    shown = np.ones(len(atoms), bool) if bonds != "spring" else disk
    view = Atoms(atoms.numbers[shown], positions=atoms.positions[shown])
    radius = display_radius(atoms)
    title = (f"ase-bpm impact: the disk {when}" if bonds == "spring" else
             f"ase-bpm impact{_named(bonds)}:\nthe disk and the ball (grey) {when}")
    return picture(view, atoms.arrays["damage"][shown], filename, title=title.strip(),
                   label="damage (share of the particle's bonds broken)", limits=(0.0, 1.0),
                   cmap=DAMAGE_COLOURS, rotation="90y" if bonds == "spring" else "-120y",
                   radii=None if radius is None else radius[shown],
                   context=None if bonds == "spring" else ~disk)
