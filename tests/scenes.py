"""Small particle scenes for the tests, built with ASE's lattice tools."""

import numpy as np
from ase.lattice.cubic import FaceCenteredCubic

import ase_bpm
from ase_bpm.core.neighbours import minimum_image

FCC = 4 ** (1 / 3)  # LAMMPS "lattice fcc 1.0": reduced density 1


def fcc_cluster(size=3, seed=0, jitter=0.1, pbc=False, ntypes=1, masses=(1.0, 2.0, 1.5)):
    """A jittered FCC block with random particle types and masses per type."""
    atoms = FaceCenteredCubic("Cu", size=(size,) * 3, latticeconstant=FCC, pbc=pbc)
    rng = np.random.default_rng(seed)
    atoms.positions += rng.uniform(-jitter, jitter, atoms.positions.shape)
    types = rng.integers(1, ntypes + 1, len(atoms))
    atoms.arrays["type"] = types
    atoms.set_masses(np.asarray(masses)[types - 1])
    return atoms, rng


def multi_type_cluster(seed=0, size=3, pbc=False, shear=0.0):
    """Three particle types, two bond types (type-3 particles only in type-2
    bonds).  Nearest neighbours are bonded; second neighbours are not and
    touch through the pair law.  ``shear``: the third cell vector tilted
    along x by that fraction of its length (a triclinic cell)."""
    atoms, rng = fcc_cluster(size, seed=seed, pbc=pbc, ntypes=3)
    if shear:
        cell = atoms.cell.array.copy()
        cell[2, 0] += shear * cell[2, 2]
        atoms.set_cell(cell, scale_atoms=True)
    types = atoms.arrays["type"]
    ase_bpm.create_bonds(atoms, 1.25, bond_type=1, mask=types != 3)
    ase_bpm.create_bonds(atoms, 1.25, bond_type=2)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    return atoms, rng


MULTI_TYPE_COEFFS = dict(
    bond_coeffs={1: (1.0, 0.08, 0.5), 2: (2.0, 0.12, 0.2)},
    # (1,2) and (2,3) are mixed; r_c differ enough that the mixing rule matters
    pair_coeffs={(1, 1): (1.0, 1.5, 1.0), (2, 2): (1.5, 2.0, 0.5),
                 (1, 3): (0.7, 1.7, 0.3), (3, 3): (0.8, 1.6, 0.7)},
)


def deform_below_breaking(atoms, rng, fraction=0.97, scale=0.1):
    """Random displacements as large as possible with every bond strain below
    ``fraction * eps_c`` (positions relative to the bonds' reference lengths)."""
    i, j, t = ase_bpm.get_bonds(atoms)

    def lengths(x):
        return np.linalg.norm(minimum_image(x[j] - x[i], atoms.cell, atoms.pbc), axis=1)

    r0 = lengths(atoms.positions)
    ecrit = np.array([np.nan] + [c[1] for _, c in sorted(
        atoms.calc.parameters["bond_coeffs"].items())])[t]
    direction = rng.uniform(-1, 1, atoms.positions.shape)

    def worst(s):
        return np.max(np.abs(lengths(atoms.positions + s * direction) / r0 - 1) / ecrit)

    while worst(scale) > fraction:
        scale *= 0.95
    return atoms.positions + scale * direction


# -- peridynamics: the LAMMPS PERI example material, SI units -------------------------
SPACING = 0.0005  # lattice spacing (m)
HORIZON = 0.0015001  # 3 lattice spacings
NODE_VOLUME = SPACING ** 3  # 1.25e-10 m^3
DENSITY = 2200.0  # kg/m^3
BULK = 14.9e9  # Pa
MICROMODULUS = 18 * BULK / (np.pi * HORIZON ** 4)  # 1.6863e22
LPS_CONTACT = 18 * BULK / (np.pi * HORIZON ** 4)


def sc_block(nx, ny=None, nz=None, offset=(0, 0, 0), pbc=False):
    """Simple cubic block of peridynamic nodes, bonded within the horizon."""
    from ase import Atoms

    ny, nz = ny or nx, nz or nx
    grid = np.array(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz),
                                indexing="ij")).reshape(3, -1).T
    atoms = Atoms(f"Si{len(grid)}", positions=(grid + offset) * SPACING,
                  cell=np.diag([nx, ny, nz]) * SPACING, pbc=pbc)
    atoms.arrays["vfrac"] = np.full(len(atoms), NODE_VOLUME)
    atoms.set_masses(np.full(len(atoms), DENSITY * NODE_VOLUME))
    ase_bpm.create_bonds(atoms, HORIZON)
    return atoms


def peri_model(name, s00=0.5, alpha=0.25):
    """One model of each kind with the PERI example's material."""
    return {
        "pmb": ("pmb", MICROMODULUS, HORIZON, s00, alpha),
        "lps": ("lps", BULK, 0.6 * BULK, HORIZON, s00, alpha),
        "ves": ("ves", BULK, 0.6 * BULK, 0.5, 1e-6, HORIZON, s00, alpha),
        "eps": ("eps", BULK, 0.6 * BULK, 1e15, HORIZON, s00, alpha),  # far below yield
    }[name]


def sphere_pile(n=4, spacing=1.0, seed=0, radii=(0.45, 0.6), speed=0.5, spin=1.0,
                lift=0.0):
    """Polydisperse spheres on a jittered n x n x n grid, many of them
    overlapping their neighbours, with random velocities and spins; the
    lowest sphere centres ``lift`` above z = 0."""
    from ase import Atoms

    rng = np.random.default_rng(seed)
    grid = np.indices((n, n, n)).reshape(3, -1).T * spacing
    x = grid + rng.uniform(-0.08, 0.08, grid.shape) * spacing
    atoms = Atoms(numbers=np.ones(len(x), dtype=int), positions=x)
    atoms.positions[:, 2] += lift - atoms.positions[:, 2].min()
    atoms.arrays["radius"] = rng.uniform(*radii, len(atoms)) * spacing
    atoms.set_masses(rng.uniform(0.8, 1.6, len(atoms)))
    atoms.set_velocities(rng.normal(0, speed, x.shape))
    atoms.arrays["omega"] = rng.normal(0, spin, x.shape)
    return atoms
