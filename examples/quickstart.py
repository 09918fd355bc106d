"""Quick start: bond an FCC block, shoot a particle cluster at it, watch it crack.

    python examples/quickstart.py        # writes quickstart.extxyz
    ase gui quickstart.extxyz            # View > Colors > By user-defined damage

Reduced (LJ) units throughout: masses 1, timestep 0.1.
"""

import numpy as np
from ase.lattice.cubic import FaceCenteredCubic
from ase.md.verlet import VelocityVerlet

import ase_bpm

# 1. build: a jittered FCC block (reduced density 1) ...
block = FaceCenteredCubic("Ne", size=(8, 8, 2), latticeconstant=4 ** (1 / 3), pbc=False)
rng = np.random.default_rng(0)
block.positions += rng.uniform(-0.1, 0.1, block.positions.shape)
# ... and a small projectile above it
bullet = FaceCenteredCubic("Ne", size=(2, 2, 2), latticeconstant=4 ** (1 / 3), pbc=False)
bullet.positions += block.positions.mean(axis=0) - bullet.positions.mean(axis=0) + [0, 0, 6]
atoms = block + bullet
atoms.set_masses(np.ones(len(atoms)))
projectile = np.arange(len(atoms)) >= len(block)

# 2. bond: neighbours closer than 1.5, type 1 in the block, type 2 in the projectile
ase_bpm.create_bonds(atoms, 1.5, bond_type=1, mask=~projectile)
ase_bpm.create_bonds(atoms, 1.5, bond_type=2, mask=projectile)
velocities = np.zeros((len(atoms), 3))
velocities[projectile] = [0.0, 0.0, -0.4]
atoms.set_velocities(velocities)

# 3. attach: LAMMPS bond_coeff / pair_coeff numbers, in LAMMPS order
atoms.calc = ase_bpm.BPMSpring(
    bond_coeffs={1: (1.0, 0.04, 1.0),    # k, eps_c, gamma
                 2: (1.0, 0.20, 1.0)},
    pair_coeffs={(1, 1): (1.0, 1.0, 1.0)},  # k, r_c, gamma
)

# 4. run ASE's VelocityVerlet, 5. write frames for ase gui
dyn = VelocityVerlet(atoms, timestep=0.1)
with ase_bpm.ViewerTrajectory("quickstart.extxyz", atoms) as trajectory:
    dyn.attach(trajectory, interval=50)
    dyn.run(600)

i, j, _ = ase_bpm.get_bonds(atoms)
print(f"{len(atoms)} particles, {len(i)} intact bonds, "
      f"{len(atoms.info.get('broken_bonds', []))} broken; "
      f"most damaged particle: {atoms.arrays['damage'].max():.2f}")
