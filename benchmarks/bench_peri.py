"""BPMPeri on the LAMMPS PERI benchmark, side by side with the legacy peri/* styles.

    python benchmarks/bench_peri.py [--law pmb|lps|ves|eps|all] [--steps 200]
                                    [--repeats 3] [--shatter] [--quick]

The benchmark block (LAMMPS examples/bpm/peri/benchmark): periodic 16^3
simple cubic nodes, spacing 0.0005 m, horizon 0.0015001 m (122 bonds per
node, 249,856 bonds), 200 steps of 1e-7 s from the reference configuration,
its nodes moving (:data:`BLOCK_SPEED`: LAMMPS's block starts at rest), with the law ``--law`` (pmb unless told; ``all``: the four in turn) and the
coefficients of that benchmark's README (:data:`BLOCK_COEFFS`), against the
legacy ``peri/<law>`` pair style; BPMPeri follows the legacy styles
(``follows="legacy"``).  With ``--shatter`` also the shatter demo scene
(3,487 nodes, 167,983 bonds, indenter, fracture; pmb, ``follows="legacy"``)
against legacy peri/pmb, for the same number of steps.

Each engine runs in its own process on one thread (``engines.py``).  The
shatter scene's cost per step changes as it fractures, so every repeat is a
fresh process that runs the same steps from the reference configuration (the
block is run the same way): ``--repeats`` rounds, each running the engines in
turn.  Setup (building and bonding the scene, the first force evaluation;
LAMMPS' data file, its two ``run 0``) is not timed.  Prints per scene and
engine the wall time (median), ms/step (median, min-max), peak memory (the
largest of its processes) and the ratio to LAMMPS (median, min-max of the
ratios of the rounds), and how far apart the two trajectories end.
``--quick``: 50 steps (unless ``--steps`` says otherwise).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile

import numpy as np
from ase import Atoms

import ase_bpm
import engines
from ase_bpm import SphericalIndenter
from ase_bpm.laws.bond import LAWS as LAWS_BY_NAME
from ase_bpm.scene.lammps import peri_commands, peri_data
from ase_bpm.scene.lammps_export import legacy_contact_stiffness
from ase_bpm import VelocityVerlet

SPACING, HORIZON, VOLUME, DENSITY = 0.0005, 0.0015001, 1.25e-10, 2200.0
#: bulk and shear modulus of the state-based laws (Pa), the eps yield stress (Pa)
MODULUS, YIELD_STRESS = 14.9e9, 10.0e8
#: breaking: s00, alpha (never reached at the reference configuration)
S00, ALPHA = 0.5, 0.25
#: ves: lambda, tau (s)
VES_LAMBDA, VES_TAU = 0.5, 0.001
#: each law's bond_coeffs row (bond_style bpm/peri order), as the LAMMPS
#: benchmark's README gives them
BLOCK_COEFFS = {
    "pmb": ("pmb", 1.6863e22, HORIZON, S00, ALPHA),
    "lps": ("lps", MODULUS, MODULUS, HORIZON, S00, ALPHA),
    "ves": ("ves", MODULUS, MODULUS, VES_LAMBDA, VES_TAU, HORIZON, S00, ALPHA),
    "eps": ("eps", MODULUS, MODULUS, YIELD_STRESS, HORIZON, S00, ALPHA),
}
LAWS = tuple(BLOCK_COEFFS)
TIMESTEP = 1e-7
#: the block's nodes start moving (m/s, each component uniform in +-BLOCK_SPEED,
#: seeded, no net momentum): LAMMPS's benchmark block starts at rest with no
#: force, so its nodes never move; these move them about a hundredth of a
#: spacing in 200 steps, so forces act and the two trajectories can be compared
BLOCK_SPEED, BLOCK_SEED = 0.5, 7
STEPS, QUICK_STEPS = 200, 50
ASE_LABEL = "ase_bpm BPMPeri"


def lammps_label(law: str) -> str:
    return f"LAMMPS legacy peri/{law}"


def block(n=16) -> Atoms:
    grid = np.array(np.meshgrid(*[np.arange(n)] * 3, indexing="ij")).reshape(3, -1).T
    atoms = Atoms(f"Si{len(grid)}", positions=grid * SPACING, cell=np.eye(3) * n * SPACING,
                  pbc=True)
    atoms.arrays["vfrac"] = np.full(len(atoms), VOLUME)
    atoms.set_masses(np.full(len(atoms), DENSITY * VOLUME))
    v_nc = np.random.default_rng(BLOCK_SEED).uniform(-BLOCK_SPEED, BLOCK_SPEED, (len(atoms), 3))
    atoms.set_velocities(v_nc - v_nc.mean(axis=0))
    ase_bpm.create_bonds(atoms, HORIZON)
    return atoms


def benchmark_block(law: str = "pmb") -> Atoms:
    """The benchmark block with its BPMPeri of ``law`` (following legacy
    peri/<law>, which it is timed against), with the short-range contact
    the legacy style ties to the law (as LAMMPS's bond_style bpm/peri
    benchmark runs pair_style bpm/peri beside its bonds)."""
    atoms = block()
    row = BLOCK_COEFFS[law]
    values = dict(zip(LAWS_BY_NAME[law].coefficients, row[1:]))
    contact = (legacy_contact_stiffness(LAWS_BY_NAME[law], values), HORIZON)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: row}, pair_coeffs={(1, 1): contact},
                                 lattice_spacing=SPACING, timestep=TIMESTEP, follows="legacy")
    return atoms


def shatter_scene(law: str = "pmb") -> Atoms:
    """The shatter demo's cylinder with its BPMPeri and indenter (following
    legacy peri/pmb, as the demo does and LAMMPS runs here)."""
    from ase_bpm.scene.demos import shatter

    if law != "pmb":
        raise ValueError(f"the shatter scene's bonds are pmb, not {law}")
    atoms = shatter.cylinder()
    atoms.calc = ase_bpm.BPMPeri(
        bond_coeffs=shatter.BOND_COEFFS, pair_coeffs=shatter.PAIR_COEFFS,
        fixes=[SphericalIndenter(**shatter.INDENTER)], timestep=TIMESTEP, follows="legacy")
    return atoms


#: scene name -> (title, builder of the atoms with their calculator, given the law)
SCENES = {"block": ("PERI benchmark block", benchmark_block),
          "shatter": ("shatter demo (cylinder, indenter, fracture)", shatter_scene)}


# -- the children -------------------------------------------------------------------

def child_ase(args) -> dict:
    """ase_bpm on the scene ``--scene`` (law ``--law``) it builds; final
    positions to ``--state``."""
    atoms = SCENES[args.scene][1](args.law)
    dyn = VelocityVerlet(atoms, timestep=TIMESTEP)
    atoms.get_forces()  # setup (LAMMPS' setup is not timed either)
    seconds = engines.timed(dyn.run, args.steps)
    np.savez(args.state, x=atoms.positions)
    return dict(seconds=seconds, peak_mb=engines.peak_memory_mb())


def child_lammps(args) -> dict:
    """Legacy peri/<law> on the exported scene (``--commands``: a JSON list of
    commands); final positions to ``--state``."""
    with open(args.commands) as fh:
        commands = json.load(fh)
    lmp = engines.new_lammps()
    lmp.commands_list([*commands, f"thermo {engines.NO_THERMO}", "run 0"])
    # legacy PERI leaves s0 unset after its first setup (see tests/peri_oracle.py)
    nlocal = lmp.extract_global("nlocal")
    lmp.numpy.extract_atom("s0")[:nlocal] = np.finfo(float).max
    lmp.command("run 0")
    seconds = engines.timed(lambda n: lmp.command(f"run {n}"), args.steps)
    np.savez(args.state, x=engines.lammps_per_atom(lmp, "x", lmp.get_natoms()))
    lmp.close()
    return dict(seconds=seconds, peak_mb=engines.peak_memory_mb())


CHILDREN = {"ase_bpm": child_ase, "lammps": child_lammps}


# -- the parent ---------------------------------------------------------------------

def export(atoms: Atoms, directory: str) -> str:
    """Write the scene's LAMMPS data file and commands into ``directory``;
    returns the path of the commands (a JSON list)."""
    data = os.path.join(directory, "scene.data")
    with open(data, "w") as fh:
        fh.write(peri_data(atoms))
    commands = os.path.join(directory, "scene.json")
    with open(commands, "w") as fh:
        # (child_lammps repairs s0, as the state-based legacy styles need)
        json.dump(peri_commands(atoms, atoms.calc, data, timestep=TIMESTEP,
                                spacing=SPACING, driver_repairs_s0=True), fh)
    return commands


def compare(scene: str, law: str, steps: int, repeats: int):
    """Run ``scene`` with ``law`` in both engines and print the table and the
    trajectories' gap."""
    name, make = SCENES[scene]
    reference = make(law)
    reference.get_forces()
    print(f"\n{name}, {law}: {len(reference)} nodes, "
          f"{len(ase_bpm.get_bonds(reference)[0])} bonds, {steps} steps", flush=True)
    common = ["--scene", scene, "--law", law, "--steps", str(steps)]
    with tempfile.TemporaryDirectory() as tmp:
        runs = {"ase_bpm": common,
                "lammps": [*common, "--commands", export(reference, tmp)]}
        results, states = engines.fresh_runs(__file__, runs, repeats, tmp)
    labels = {"ase_bpm": ASE_LABEL, "lammps": lammps_label(law)}
    print(engines.engine_table({labels[role]: results[role] for role in results}, steps,
                               labels["lammps"]))
    d = ase_bpm.core.neighbours.minimum_image(states["ase_bpm"]["x"] - states["lammps"]["x"],
                                         reference.cell, reference.pbc)
    print(f"largest position difference: {np.nanmax(np.abs(d)) / SPACING:.2e} spacings")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, help=f"steps per run ({STEPS}; --quick "
                    f"{QUICK_STEPS})")
    ap.add_argument("--repeats", type=int, default=3, help="fresh runs per engine (3)")
    ap.add_argument("--law", choices=(*LAWS, "all"), default="pmb",
                    help="the block's law (pmb; all: each in turn)")
    ap.add_argument("--shatter", action="store_true", help="also the shatter scene (pmb)")
    ap.add_argument("--quick", action="store_true", help=f"{QUICK_STEPS} steps")
    ap.add_argument("--scene", choices=SCENES, help=argparse.SUPPRESS)
    ap.add_argument("--commands", help=argparse.SUPPRESS)
    engines.add_child_options(ap, CHILDREN)
    args = ap.parse_args()
    if args.steps is None:
        args.steps = QUICK_STEPS if args.quick else STEPS
    if args.child:
        engines.answer(CHILDREN, args)
        return

    for law in LAWS if args.law == "all" else (args.law,):
        compare("block", law, args.steps, args.repeats)
    if args.shatter:
        compare("shatter", "pmb", args.steps, args.repeats)


if __name__ == "__main__":
    main()
