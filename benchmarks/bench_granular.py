"""Granular gas and settling pile, side by side with LAMMPS, with the parts of a step.

    python benchmarks/bench_granular.py [--scene gas|pile|both] [--steps N]
                                        [--repeats 3] [--quick] [--skin S]

Two scenes, each built in ase_bpm and exported with
``ase_bpm.scene.lammps.write_lammps`` to the reference LAMMPS build, each
engine in its own process on one thread (``engines.py``), every repeat a
fresh process that runs the same steps from the same start; the setup
(building the scene, the first force evaluation; LAMMPS's deck up to its
``run 0``) is not timed.  The calculator is the one a user gets (the guard
and the energy ledger on, ``skin=None``), under ``SphereVelocityVerlet``
against LAMMPS's ``fix nve/sphere``.

* ``gas``: 8,000 equal spheres (radius 0.5, density 1) in a periodic cube at
  packing fraction :data:`GAS_PACKING` (0.25: after the first few hundred
  steps about one sphere in ten touches another), started on a jittered
  grid with Gaussian velocities (one per component, the total momentum
  removed) and no spin;
  ``pair_style gran/hooke/history 2000 NULL 10 NULL 0.5 0`` (a normal
  restitution of about 0.84, so it stays a gas over the run), 2,000 steps of
  0.001.
* ``pile``: 800 spheres on the jittered release grid of ``ase-bpm demo pour``
  in its ``--quick`` box (radii 0.4 to 0.6, density 1; 10 wide, here
  periodic in x and y; 13 layers, the top one at a height of 15.6), falling
  under gravity 1 onto a granular floor (``fix wall/gran ... zplane 0.0
  NULL``) and settling;
  the law of LAMMPS's ``examples/pour`` (``gran/hooke/history 2000 NULL 50
  NULL 0.5 0``) for the contacts and the floor, 10,000 steps of 0.001.

Prints per scene the engines' wall time, ms/step (median, min-max), peak
memory and the ratio to LAMMPS (median, min-max of the rounds), the same
ratio in CPU time (on a machine others use too, a process waiting for a
core loses wall time but no CPU time); LAMMPS's own
timing breakdown from its log (Pair, Neigh, Comm, Modify, Other, in ms/step,
and its neighbour-list builds); and ase_bpm's parts of a step, timed by
perf_counter probes put in place of the callables in :data:`PROBES` (a probe
costs about 0.3 us a call, three calls a step at most; ``engines.py``): the
neighbour list (the rebuild check of every step and the rebuilds), the
rebuilds alone (matscipy's search and ours around it, per step and per
rebuild), matscipy's search alone, the contact
kernel, the wall kernel, and the rest (the integrator, the calculator's
plumbing, the ledger, the guard).  ``--skin S``: ase_bpm and the exported
deck both with that skin.  ``--quick``: 500 steps of the gas, 3,000 of the
pile.
"""

from __future__ import annotations

import argparse
import os
import tempfile

import numpy as np
from ase import Atoms

import engines
from ase_bpm import SphereVelocityVerlet, rotational_energy, write_lammps
from ase_bpm.core import neighbours
from ase_bpm.core.neighbours import SphereVerletList, minimum_image
from ase_bpm.laws import granular_kernels
from ase_bpm.models.granular import Granular
from ase_bpm.scene.demos.pour import LAW as POUR_LAW
from ase_bpm.scene.demos.pour import pour_scene
from ase_bpm.scene.fixes import GranularWall, Gravity

TIMESTEP = 0.001
#: packing fraction of the gas (sphere volume over box volume)
GAS_PACKING = 0.25
GAS_SIDE = 20  # spheres along each edge of the start grid: 8,000
GAS_RADIUS = 0.5
#: the gas's law: examples/pour's but with less normal damping (restitution ~0.84)
GAS_LAW = dict(POUR_LAW, gamma_n=10.0)
PILE_COUNT = 800
PILE_WIDTH = 10.0
GRAVITY = 1.0
STEPS = {"gas": 2000, "pile": 10000}
QUICK_STEPS = {"gas": 500, "pile": 3000}
SEED = 20261128

#: the parts of an ase_bpm step: name -> (owner, attribute) timed by a probe.
#: After a refactor moves one of these, point it at its new home.
PROBES = {
    "neighbour list": (SphereVerletList, "update"),  # the check of every step + rebuilds
    "rebuilds": (SphereVerletList, "_pairs"),  # matscipy's search and ours around it
    "matscipy": (neighbours, "neighbour_list"),  # matscipy's search alone
    "contact kernel": (granular_kernels("auto"), "pair_contacts"),
    "wall kernel": (granular_kernels("auto"), "walls_contacts"),
}

#: the parts timed inside another (left out of "the rest")
WITHIN = {"rebuilds": "neighbour list", "matscipy": "rebuilds"}


# -- the scenes ---------------------------------------------------------------------

def gas_scene() -> Atoms:
    """8,000 spheres of radius 0.5 at packing fraction GAS_PACKING in a
    periodic cube, on a grid jittered within its gaps, with Gaussian
    velocities (no net momentum) and no spin."""
    rng = np.random.default_rng(SEED)
    count = GAS_SIDE ** 3
    volume = 4.0 / 3.0 * np.pi * GAS_RADIUS ** 3
    side = (count * volume / GAS_PACKING) ** (1.0 / 3.0)
    spacing = side / GAS_SIDE
    grid = np.indices((GAS_SIDE,) * 3).reshape(3, -1).T + 0.5
    gap = spacing - 2.0 * GAS_RADIUS  # jitter within the gap: nothing touches at the start
    positions = grid * spacing + rng.uniform(-0.45, 0.45, grid.shape) * gap
    atoms = Atoms(["Ar"] * count, positions=positions, cell=[side] * 3, pbc=True)
    atoms.arrays["radius"] = np.full(count, GAS_RADIUS)
    atoms.set_masses(np.full(count, volume))  # density 1
    v_nc = rng.normal(0.0, 1.0, (count, 3))
    atoms.set_velocities(v_nc - v_nc.mean(axis=0))
    atoms.arrays["omega"] = np.zeros((count, 3))
    return atoms


def pile_scene() -> Atoms:
    """The pour demo's jittered grid of PILE_COUNT spheres in a box PILE_WIDTH
    wide, periodic in x and y, open above the floor."""
    atoms = pour_scene(count=PILE_COUNT, width=PILE_WIDTH)
    atoms.pbc = (True, True, False)
    return atoms


def calculator(scene: str, skin: float | None = None) -> Granular:
    """The scene's Granular, as a user gets it (``skin`` None: the default)."""
    if scene == "gas":
        return Granular(**GAS_LAW, skin=skin)
    return Granular(**POUR_LAW, skin=skin,
                    fixes=[Gravity(GRAVITY), GranularWall(**POUR_LAW, axis="z", lo=0.0)])


SCENES = {"gas": gas_scene, "pile": pile_scene}


# -- the children -------------------------------------------------------------------

def child_ase(args) -> dict:
    """ase_bpm on the scene; its parts from the probes; final positions to
    ``--state``."""
    atoms = SCENES[args.scene]()
    atoms.calc = calculator(args.scene, args.skin)
    dyn = SphereVelocityVerlet(atoms, TIMESTEP)
    atoms.get_forces()  # setup, as LAMMPS' (untimed) run 0
    seconds, cpu, probes = engines.probed_run(dyn.run, args.steps, PROBES)
    np.savez(args.state, x=atoms.positions)
    return dict(seconds=seconds, cpu=cpu, peak_mb=engines.peak_memory_mb(),
                parts=probes.seconds, calls=probes.calls,
                contacts=int(atoms.arrays["ncontacts"].sum() // 2),
                ke=atoms.get_kinetic_energy(), rotational=rotational_energy(atoms))


def child_lammps(args) -> dict:
    """LAMMPS on the exported deck (``--deck``, ending with ``run 0``, its data
    file in its own folder), the timed run logged to read its timing
    breakdown; final positions to ``--state``."""
    lmp = engines.new_lammps()
    cwd = os.getcwd()
    log = os.path.join(os.path.dirname(args.state), "lammps.log")
    try:
        os.chdir(os.path.dirname(args.deck))
        lmp.file(os.path.basename(args.deck))
    finally:
        os.chdir(cwd)
    seconds, cpu, breakdown = engines.timed_lammps_run(lmp, args.steps, log)
    count = lmp.get_natoms()
    np.savez(args.state, x=engines.lammps_per_atom(lmp, "x", count))
    lmp.close()
    return dict(seconds=seconds, cpu=cpu, peak_mb=engines.peak_memory_mb(),
                breakdown=breakdown)


CHILDREN = {"ase_bpm": child_ase, "lammps": child_lammps}


# -- the parent ---------------------------------------------------------------------

def report(scene: str, atoms: Atoms, steps: int, results: dict, states: dict) -> str:
    """The scene's table, LAMMPS's breakdown and ase_bpm's parts."""
    labels = {"ase_bpm": "ase_bpm (SphereVelocityVerlet + Granular)",
              "lammps": "LAMMPS, same scene (exported)"}
    lines = [engines.engine_table({labels[role]: results[role] for role in results}, steps,
                                  labels["lammps"])]
    ratios = engines.per_round_ratios(results["ase_bpm"], results["lammps"])
    lines.append(f"ase_bpm / LAMMPS: {engines.spread(ratios, 2)}x")
    cpu = [a["cpu"] / b["cpu"] for a, b in zip(results["ase_bpm"], results["lammps"])]
    lines.append(f"the same in CPU time (less swayed by a busy machine): "
                 f"{engines.spread(cpu, 2)}x; ms/step ase_bpm "
                 f"{engines.ms_per_step([r['cpu'] for r in results['ase_bpm']], steps)}, LAMMPS "
                 f"{engines.ms_per_step([r['cpu'] for r in results['lammps']], steps)}")

    lines += ["", *engines.breakdown_lines(results["lammps"], steps), "",
              *engines.parts_lines(results["ase_bpm"], steps, PROBES, WITHIN, "rebuilds")]

    last = results["ase_bpm"][-1]
    # (LAMMPS wraps its positions into the periodic box, ASE does not)
    apart_nc = minimum_image(states["ase_bpm"]["x"] - states["lammps"]["x"], atoms.cell,
                             atoms.pbc)
    lines.append(f"\nafter {steps} steps: contacts {last['contacts']}, kinetic energy "
                 f"{last['ke']:.8g}, rotational {last['rotational']:.4g}; largest difference "
                 f"of positions from LAMMPS's {np.abs(apart_nc).max():.2e} (the scenes are "
                 "chaotic: it grows with the steps)")
    return "\n".join(lines)


def run_scene(scene: str, args) -> str:
    atoms = SCENES[scene]()
    steps = args.steps or (QUICK_STEPS if args.quick else STEPS)[scene]
    calc = calculator(scene, args.skin)
    skin = calc.contact_skin(atoms.arrays["radius"])
    print(f"\n== {scene}: {len(atoms)} spheres, {steps} steps of {TIMESTEP}, skin {skin:.4g}",
          flush=True)
    common = ["--scene", scene, "--steps", str(steps)] + (
        [] if args.skin is None else ["--skin", repr(args.skin)])
    with tempfile.TemporaryDirectory() as tmp:
        _, deck = write_lammps(os.path.join(tmp, scene), atoms, calc, timestep=TIMESTEP,
                               steps=0, thermo=engines.NO_THERMO)
        runs = {"ase_bpm": common, "lammps": [*common, "--deck", deck]}
        results, states = engines.fresh_runs(__file__, runs, args.repeats, tmp)
    return report(scene, atoms, steps, results, states)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="both", choices=("gas", "pile", "both"))
    ap.add_argument("--steps", type=int, default=None,
                    help="steps per run (gas 2000, pile 10000)")
    ap.add_argument("--repeats", type=int, default=3, help="fresh runs per engine (3)")
    ap.add_argument("--quick", action="store_true",
                    help="500 steps of the gas, 3000 of the pile")
    ap.add_argument("--skin", type=float, default=None,
                    help="neighbour skin of both engines (default: Granular's)")
    ap.add_argument("--deck", help=argparse.SUPPRESS)
    engines.add_child_options(ap, CHILDREN)
    args = ap.parse_args()
    if args.steps is not None and args.steps < 1:
        ap.error(f"--steps {args.steps}: give at least one step")
    if args.skin is not None and not args.skin >= 0:
        ap.error(f"--skin {args.skin}: give a non-negative skin")
    if args.child:
        engines.answer(CHILDREN, args)
        return
    print(f"load average at the start: {os.getloadavg()[0]:.2f} (1 min)")
    for scene in ("gas", "pile") if args.scene == "both" else (args.scene,):
        print(run_scene(scene, args), flush=True)
    print(f"\nload average at the end: {os.getloadavg()[0]:.2f} (1 min)")


if __name__ == "__main__":
    main()
