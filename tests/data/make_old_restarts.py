"""Makes the restart files of ``old_ids_*.npz`` with ase_bpm as it was before
IDs were stored as two int32 words (commit 369485d: ``bpm_id``,
``bond_partner`` and ``gran_partner`` hold int64 IDs), for
``tests/test_extxyz.py``.  Run it with that commit's package first on the
path (``git archive 369485d | tar -x -C old``, the compiled library copied
in), once as it is and once with ``ASE_BPM_KERNELS=numpy``::

    PYTHONPATH=old python tests/data/make_old_restarts.py tests/data

Each file holds a restart written after ``STEPS`` steps (``restart``, the
bytes of a ``.bpm`` file) and the positions and momenta after ``STEPS``
more, run on without stopping (``positions``, ``momenta``).
"""

import io
import os
import sys

import numpy as np
from ase.lattice.cubic import FaceCenteredCubic

import ase_bpm
from ase_bpm import SphereVelocityVerlet, VelocityVerlet

STEPS = 40


def spring():
    atoms = FaceCenteredCubic("Ne", size=(4, 4, 2), latticeconstant=4 ** (1 / 3), pbc=False)
    atoms.positions += np.random.default_rng(0).uniform(-0.1, 0.1, atoms.positions.shape)
    atoms.set_masses(np.ones(len(atoms)))
    atoms.set_velocities(np.random.default_rng(1).normal(0, 0.3, (len(atoms), 3)))
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.04, 1.0)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 1.0)}, store_local=True)
    return atoms, VelocityVerlet, 0.1


def granular():
    rng = np.random.default_rng(1)
    grid = np.indices((4, 4, 4)).reshape(3, -1).T * 1.0
    from ase import Atoms
    atoms = Atoms(numbers=np.ones(len(grid), dtype=int),
                  positions=grid + rng.uniform(-0.08, 0.08, grid.shape))
    atoms.arrays["radius"] = rng.uniform(0.45, 0.6, len(atoms))
    atoms.set_masses(rng.uniform(0.8, 1.6, len(atoms)))
    atoms.set_velocities(rng.normal(0, 0.5, grid.shape))
    atoms.arrays["omega"] = rng.normal(0, 1.0, grid.shape)
    atoms.calc = ase_bpm.Granular("hooke/history", kn=1000.0, gamma_n=20.0, xmu=0.3)
    return atoms, SphereVelocityVerlet, 1e-3


def main(folder):
    route = "numpy" if os.environ.get("ASE_BPM_KERNELS") == "numpy" else "compiled"
    for name, make in (("spring", spring), ("granular", granular)):
        atoms, integrator, dt = make()
        dyn = integrator(atoms, dt)
        dyn.run(STEPS)
        restart = io.BytesIO()
        ase_bpm.write_restart(restart, atoms)
        dyn.run(STEPS)
        np.savez_compressed(os.path.join(folder, f"old_ids_{name}_{route}.npz"),
                            restart=np.frombuffer(restart.getvalue(), dtype=np.uint8),
                            positions=atoms.positions, momenta=atoms.get_momenta())


if __name__ == "__main__":
    main(sys.argv[1])
