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


def peri(model=None):
    """A pmb block struck by an indenter hard enough to break bonds within
    the steps run, on nodes of two volumes (the legacy and bpm/peri forces
    differ there, and in the step a bond breaks); ``model``: another bond
    model's tuple for the block."""
    from ase import Atoms
    spacing = 1.0
    grid = np.indices((6, 6, 6)).reshape(3, -1).T * spacing
    atoms = Atoms(f"Si{len(grid)}", positions=grid, pbc=False)
    volume_n = np.where(np.arange(len(grid)) % 2, 1.0, 1.3)
    atoms.arrays["vfrac"] = volume_n
    atoms.set_masses(volume_n)
    atoms.set_velocities(np.random.default_rng(3).normal(0, 0.01, grid.shape))
    horizon = 3.0 * spacing
    ase_bpm.create_bonds(atoms, horizon)
    c = 18.0 / (np.pi * horizon ** 4)
    indenter = ase_bpm.SphericalIndenter(0.5, 1.5, (2.5, 2.5, 6.6), velocity=(0, 0, -0.05))
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: model or ("pmb", c, horizon, 0.01, 0.25)},
                                 pair_coeffs={(1, 1): (c, horizon)}, timestep=0.5,
                                 lattice_spacing=spacing, fixes=[indenter])
    return atoms, VelocityVerlet, 0.5


def peri_eps():
    """The block of :func:`peri` in eps, whose nodes yield under the indenter
    within the steps run."""
    return peri(("eps", 1.0, 0.6, EPS_YIELD, 3.0, 0.01, 0.25))


EPS_YIELD = 0.1  # of the eps block (reduced units): some nodes yield, more each step

#: the scenes, by the name of their files; a name given after the folder
#: makes only those (the peri files were made at commit 7ce3fea, before
#: BPMPeri's follows option, the others at 369485d)
SCENES = {"spring": spring, "granular": granular, "peri": peri, "peri_eps": peri_eps}


def main(folder, names=()):
    route = "numpy" if os.environ.get("ASE_BPM_KERNELS") == "numpy" else "compiled"
    for name, make in SCENES.items():
        if names and name not in names:
            continue
        atoms, integrator, dt = make()
        dyn = integrator(atoms, dt)
        dyn.run(STEPS)
        restart = io.BytesIO()
        ase_bpm.write_restart(restart, atoms)
        dyn.run(STEPS)
        prefix = "old_follows" if name.startswith("peri") else "old_ids"
        np.savez_compressed(os.path.join(folder, f"{prefix}_{name}_{route}.npz"),
                            restart=np.frombuffer(restart.getvalue(), dtype=np.uint8),
                            positions=atoms.positions, momenta=atoms.get_momenta())


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
