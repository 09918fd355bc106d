"""BPMSpring on the LAMMPS examples/bpm/impact scenes, side by side with LAMMPS.

    python benchmarks/bench_impact.py [--steps 7500] [--repeats 3] [--quick] [--skin S]
                                      [--bonds {spring,rotational,both}]

Runs the spring impact (``in.bpm.impact.spring``, built by
ase_bpm.scene.demos.impact) three ways, each engine in its own process on one
thread (``engines.py``):

1. ase_bpm: BPMSpring under ASE's VelocityVerlet;
2. LAMMPS (the reference build) on the very same scene, exported with
   ase_bpm.scene.lammps; the two trajectories are compared;
3. the original LAMMPS deck (its own lattice and random displacements), whose
   published log ends at kinetic energy 0.00036136735 per atom after 7,500
   steps (not with ``--quick``: the deck is the full scene).

and, in the same rounds, the rotational impact (``in.bpm.impact.rotational``,
``ase-bpm demo impact --bonds rotational``: bpm/sphere particles, ``bond_style
bpm/rotational``, ``pair_style gran/hooke/history``, timestep 0.05) two ways:
ase_bpm under SphereVelocityVerlet and LAMMPS on the exported scene (``fix
nve/bpm/sphere``).  Each scene gets its table, its ratio to LAMMPS, its
comparison of the two trajectories and its parts, and the run ends with the
rotational ratio over the spring one, round by round.  ``--bonds`` runs one
scene only.

The cost of a step grows as the disk breaks up (more contacts, neighbour-list
rebuilds, bond bookkeeping), so every repeat is a fresh process that builds
the scene and runs the same ``--steps`` from the start: ``--repeats`` rounds,
each running the engines in turn.  Setup (building the scene or reading the
data file, the first force evaluation or ``run 0``) is not timed.  Prints per
engine the wall time (median), ms/step (median, min-max), peak memory (the
largest of its processes) and the ratio to LAMMPS on the same scene (median,
min-max of the ratios of the rounds); then how far apart ase_bpm and LAMMPS
end (intact bonds, kinetic energy, positions); then the parts of a step
(``engines.py``): LAMMPS's own timing breakdown from the log of its timed run
(Pair, Bond, Neigh, Comm, Output, Modify, Other, in ms/step, and its
neighbour-list builds) and ase_bpm's, timed by perf_counter probes put in
place of the callables in :data:`PROBES` (about 0.3 us a call, a few calls a
step): the bond kernel, the contact kernel, the contact list (the rebuild
check of every step, the rebuilds and the removal of the bonded pairs), the
rebuilds alone (per step and per rebuild), matscipy's search alone, the
removal of the bonded pairs alone, and the rest (the integrator, the
calculator's plumbing, the ledger, the guard).  Both engines use the skin
and rebuild rule printed with the scene (the exported deck's ``neighbor``
and ``neigh_modify``).  ``--quick``: the small scene of
``ase-bpm demo impact --quick`` (1,648 particles), without the original deck.
``--skin S``: ase_bpm and the exported deck both with that skin (the original
deck keeps its 0.3); the trajectories do not depend on it, as the pair
kernels add only the touching pairs, in order of (i, j).  For the
rotational scene the skin is the granular contacts' (``Granular``'s
default, 0.4 of the largest radius, and ``neighbor`` in the exported deck).
The rotational bonds run on the compiled kernels where ase_bpm has them,
else on NumPy: the table's label and the parts say which.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from functools import partial

import numpy as np
from ase.md.verlet import VelocityVerlet

import engines
from ase_bpm import BPMSpring, Granular, SphereVelocityVerlet, get_bonds
from ase_bpm.scene.demos.impact import (BOND_COEFFS, FULL, GRANULAR, PAIR_COEFFS, QUICK,
                                        ROTATIONAL_BOND_COEFFS, TIMESTEP, VARIANTS,
                                        impact_scene, make_spheres)
from ase_bpm.scene.lammps import lammps_commands, lammps_data

ORIGINAL_DECK = """
units lj
dimension 3
boundary f f f
atom_style bond
special_bonds lj 0.0 1.0 1.0 coul 0.0 1.0 1.0
newton on off
comm_modify vel yes cutoff 2.6
lattice fcc 1.0
region box block -25 15 -22 22 -22 22
create_box 1 box bond/types 2 extra/bond/per/atom 20
region disk cylinder x 0.0 0.0 20.0 -0.5 0.5
create_atoms 1 region disk
group plate region disk
region ball sphere 8.0 0.0 0.0 6.0
create_atoms 1 region ball
group projectile region ball
displace_atoms all random 0.1 0.1 0.1 134598738
mass 1 1.0
neighbor 1.0 bin
pair_style bpm/spring
pair_coeff 1 1 1.0 1.0 1.0
fix 1 all nve
create_bonds many plate plate 1 0.0 1.5
create_bonds many projectile projectile 2 0.0 1.5
neighbor 0.3 bin
special_bonds lj 0.0 1.0 1.0 coul 1.0 1.0 1.0
bond_style bpm/spring
bond_coeff 1 1.0 0.04 1.0
bond_coeff 2 1.0 0.20 1.0
velocity projectile set -0.05 0.0 0.0
timestep 0.1
thermo_modify lost ignore lost/bond ignore
"""

#: the scenes, by their bonds: the engines' roles (children), in the order of the table
ROLES = {"spring": ("ase_bpm", "lammps", "deck"),
         "rotational": ("ase_bpm_rotational", "lammps_rotational")}
LABELS = {"ase_bpm": "ase_bpm (VelocityVerlet + BPMSpring)",
          "lammps": "LAMMPS, same scene (exported)",
          "deck": "LAMMPS, original deck",
          "ase_bpm_rotational": "ase_bpm (SphereVelocityVerlet + bpm/rotational{route})",
          "lammps_rotational": "LAMMPS, same scene (exported)"}
PUBLISHED_KE = "0.00036136735"  # per atom, the deck's log after 7,500 steps

#: the parts of an ase_bpm step: name -> (owner, attribute) timed by a probe,
#: and the parts timed inside another (left out of "the rest"), of each scene
PROBES = {"spring": engines.spring_probes(), "rotational": engines.rotational_probes()}


def calculator(skin: float | None = None, bonds: str = "spring") -> BPMSpring:
    """The scene's BPMSpring (``skin`` None: the default, 0.3 r_c for the
    springs' contacts, Granular's for the rotational scene's)."""
    if bonds == "rotational":
        return BPMSpring(bond_coeffs=ROTATIONAL_BOND_COEFFS,
                         granular=GRANULAR if skin is None else {**GRANULAR, "skin": skin})
    return BPMSpring(bond_coeffs=BOND_COEFFS, pair_coeffs=PAIR_COEFFS, skin=skin)


def scene(quick: bool, bonds: str = "spring"):
    """The atoms of the scene (without a calculator)."""
    atoms = impact_scene(**(QUICK if quick else FULL))
    if bonds == "rotational":
        make_spheres(atoms)
    return atoms


# -- the children -------------------------------------------------------------------

def child_ase(args, bonds: str = "spring") -> dict:
    """ase_bpm on the scene of ``bonds`` it builds (as the parent does); final
    positions to ``--state``.  The springs must run on the compiled kernels;
    the rotational bonds run on the route ase_bpm has (``routes``)."""
    atoms = scene(args.quick, bonds)
    atoms.calc = calculator(args.skin, bonds)
    if bonds == "rotational":
        dyn = SphereVelocityVerlet(atoms, timestep=VARIANTS[bonds].timestep)
    else:
        dyn = VelocityVerlet(atoms, timestep=TIMESTEP)
    atoms.get_forces()  # setup, as LAMMPS' (untimed) run 0
    if bonds == "spring" and atoms.calc.kernel_route != "compiled":
        raise RuntimeError(f"ase_bpm runs the {atoms.calc.kernel_route} kernels, not the "
                           "compiled ones: build them (pip install -e .)")
    seconds, cpu, probes = engines.probed_run(dyn.run, args.steps, PROBES[bonds][0])
    np.savez(args.state, x=atoms.positions)
    return dict(seconds=seconds, cpu=cpu, parts=probes.seconds, calls=probes.calls,
                peak_mb=engines.peak_memory_mb(), routes=atoms.calc.kernel_routes,
                bonds=len(get_bonds(atoms)[0]),
                ke=atoms.get_kinetic_energy() / len(atoms))


def child_lammps(args) -> dict:
    """LAMMPS on the exported scene (``--commands``: a JSON list of commands);
    final positions and velocities to ``--state``."""
    with open(args.commands) as fh:
        commands = json.load(fh)
    lmp = engines.new_lammps()
    lmp.commands_list([*commands, f"thermo {engines.NO_THERMO}", "run 0"])
    log = os.path.join(os.path.dirname(args.state), "lammps.log")
    seconds, cpu, breakdown = engines.timed_lammps_run(lmp, args.steps, log)
    count = lmp.get_natoms()
    np.savez(args.state, x=engines.lammps_per_atom(lmp, "x", count),
             v=engines.lammps_per_atom(lmp, "v", count))
    bonds = len(np.array(lmp.numpy.gather_bonds()).reshape(-1, 3))
    lmp.close()
    return dict(seconds=seconds, cpu=cpu, breakdown=breakdown,
                peak_mb=engines.peak_memory_mb(), bonds=bonds)


def child_deck(args) -> dict:
    """The original LAMMPS deck: its particle count and final kinetic energy."""
    lmp = engines.new_lammps()
    lmp.commands_string(ORIGINAL_DECK)
    lmp.commands_list([f"thermo {engines.NO_THERMO}", "run 0"])
    seconds = engines.timed(lambda n: lmp.command(f"run {n}"), args.steps)
    result = dict(seconds=seconds, peak_mb=engines.peak_memory_mb(),
                  ke=lmp.get_thermo("ke"), particles=lmp.get_natoms())
    lmp.close()
    return result


CHILDREN = {"ase_bpm": child_ase, "lammps": child_lammps, "deck": child_deck,
            "ase_bpm_rotational": partial(child_ase, bonds="rotational"),
            "lammps_rotational": child_lammps}


# -- the parent ---------------------------------------------------------------------

def export(atoms, directory: str, skin: float | None = None, bonds: str = "spring") -> str:
    """Write the scene's LAMMPS data file and commands (with ``skin``) into
    ``directory``; returns the path of the commands (a JSON list)."""
    data = os.path.join(directory, f"impact_{bonds}.data")
    with open(data, "w") as fh:
        fh.write(lammps_data(atoms, calculator(skin, bonds)))
    commands = os.path.join(directory, f"impact_{bonds}.json")
    with open(commands, "w") as fh:
        json.dump(lammps_commands(atoms, calculator(skin, bonds), data,
                                  timestep=VARIANTS[bonds].timestep), fh)
    return commands


def neighbour_rule(skin: float | None, atoms, bonds: str = "spring") -> str:
    """ase_bpm's contact list: its reach, skin and rebuild rule."""
    if bonds == "rotational":
        given = GRANULAR if skin is None else {**GRANULAR, "skin": skin}
        skin = Granular(**given).contact_skin(atoms.arrays["radius"])
        return (f"granular pairs within r_i + r_j + skin {skin:g}, rebuilt when an atom "
                "moved more than half the skin")
    reach = max(rc for _, rc, _ in PAIR_COEFFS.values())
    return (f"pairs within r_c {reach:g} + skin {calculator(skin).contact_skin():g}, "
            "rebuilt when an atom moved more than half the skin")


def lammps_neighbour_rule(commands: str) -> str:
    """The exported deck's ``neighbor`` and ``neigh_modify`` commands."""
    with open(commands) as fh:
        return "; ".join(c for c in json.load(fh) if c.startswith(("neighbor", "neigh_modify")))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=7500, help="steps per run (7500)")
    ap.add_argument("--repeats", type=int, default=3, help="fresh runs per engine (3)")
    ap.add_argument("--quick", action="store_true", help="the small scene of --quick demos")
    ap.add_argument("--skin", type=float, default=None,
                    help="neighbour skin of ase_bpm and of the exported deck (default: "
                         "BPMSpring's, 0.3 r_c, and Granular's for the rotational scene; "
                         "the original deck keeps its own 0.3)")
    ap.add_argument("--bonds", choices=("spring", "rotational", "both"), default="both",
                    help="the scenes to run (default both, in the same rounds)")
    ap.add_argument("--commands", help=argparse.SUPPRESS)
    engines.add_child_options(ap, CHILDREN)
    args = ap.parse_args()
    if args.skin is not None and not args.skin >= 0:
        ap.error(f"--skin {args.skin}: give a non-negative skin")
    if args.child:
        engines.answer(CHILDREN, args)
        return

    chosen = list(ROLES) if args.bonds == "both" else [args.bonds]
    common = ["--steps", str(args.steps)] + (["--quick"] if args.quick else [])
    skin = [] if args.skin is None else ["--skin", repr(args.skin)]
    scenes, runs = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for bonds in chosen:
            atoms = scenes[bonds] = scene(args.quick, bonds)
            print(f"{bonds} scene: {len(atoms)} particles, {len(get_bonds(atoms)[0])} bonds, "
                  f"{args.steps} steps of {VARIANTS[bonds].timestep:g}", flush=True)
            commands = export(atoms, tmp, args.skin, bonds)
            print(f"  neighbour lists: ase_bpm {neighbour_rule(args.skin, atoms, bonds)}; "
                  f"LAMMPS {lammps_neighbour_rule(commands)}", flush=True)
            ours, theirs, *deck = ROLES[bonds]
            runs[ours] = [*common, *skin]
            runs[theirs] = [*common, "--commands", commands]
            if deck and not args.quick:
                runs[deck[0]] = common
        results, states = engines.fresh_runs(__file__, runs, args.repeats, tmp)

    ratios = {}
    for bonds in chosen:
        ratios[bonds] = report(bonds, scenes[bonds], results, states, args.steps)
    if "deck" in results:
        deck = results["deck"][-1]
        print(f"\noriginal spring deck: {deck['particles']} particles, kinetic energy/atom "
              f"{deck['ke']:.11g} (published log, 7500 steps: {PUBLISHED_KE})")
    if len(ratios) == 2:
        over = [r / s for r, s in zip(ratios["rotational"], ratios["spring"])]
        print(f"\nrotational ratio / spring ratio, round by round: {engines.spread(over, 2)}")


def report(bonds: str, atoms, results: dict, states: dict, steps: int) -> list[float]:
    """Print a scene's table, ratio to LAMMPS, the comparison of the two
    trajectories and the parts of a step of both engines; returns the
    per-round ratios."""
    ours, theirs, *_ = ROLES[bonds]
    roles = [role for role in ROLES[bonds] if role in results]
    routes = results[ours][-1]["routes"]
    labels = {role: LABELS[role].format(
        route="" if bonds == "spring" else f", {routes['bpm/rotational']} kernels")
        for role in roles}
    print(f"\n== the {bonds} impact ==")
    print(engines.engine_table({labels[role]: results[role] for role in roles}, steps,
                               labels[theirs]))
    ratios = engines.per_round_ratios(results[ours], results[theirs])
    print(f"\nase_bpm / LAMMPS (same scene, {bonds}): {engines.spread(ratios, 2)}x")
    ase, lmp = results[ours][-1], results[theirs][-1]
    x_ours, lammps_state = states[ours]["x"], states[theirs]
    ke_lmp = (0.5 * np.sum(atoms.get_masses()[:, None] * lammps_state["v"] ** 2)
              / len(atoms))
    print(f"same scene, ase_bpm vs LAMMPS after {steps} steps: intact bonds "
          f"{ase['bonds']} vs {lmp['bonds']}; kinetic energy/atom {ase['ke']:.10g} vs "
          f"{ke_lmp:.10g}; largest position difference "
          f"{np.abs(x_ours - lammps_state['x']).max():.2e}")
    probes, within = PROBES[bonds]
    print("\n" + "\n".join(engines.breakdown_lines(results[theirs], steps)))
    print("\n" + "\n".join(engines.parts_lines(results[ours], steps, probes, within,
                                               "rebuilds")))
    return ratios


if __name__ == "__main__":
    main()
