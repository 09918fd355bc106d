"""What a LAMMPS deck does after its first run, carried out in ase_bpm.

:func:`ase_bpm.read_lammps` gives the scene of a deck's first ``run``.  Many
decks go on: ``examples/pour`` removes a fix (``unfix ins``), tilts gravity
(a fix defined again with its ID) and runs again.  Each run after the first
is a :class:`Stage`: the commands before it that change the scene, carried
out as LAMMPS carries them out, then its steps.

Between runs ase_bpm carries out the commands of
:data:`.lammps_commands.BETWEEN_RUNS`: ``unfix`` and ``fix`` of the styles
read_lammps reads (a fix defined again with its ID replaces the first in
its place); ``variable <name> equal`` (a moving indenter follows it:
``step`` runs on from run to run, ``elapsed`` starts again at each run,
``dt`` is the timestep of the run under way); ``velocity <group> set``;
``timestep``; ``group <name> id|type``; ``neighbor``, ``neigh_modify`` and
``thermo_modify lost|lost/bond`` (they decide when lost atoms go); and
``run N`` (or ``run N upto``).  The commands the table ignores change
nothing and are listed as ignored.  Any other command after the first run
is refused by line, at reading.

Each stage is read from the deck up to its run, as LAMMPS holds it then:
the fixes are those defined and not removed by then, the timestep the last
one given.  As at LAMMPS' set-up of a run, the forces are evaluated afresh
at its start (after ``velocity set``, damping sees the new velocities), and
atoms outside a fixed face of the box go then (:class:`ase_bpm.LostAtoms`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from ase import Atoms

from ..core.spheres import frozen
from .lammps_commands import BETWEEN_RUNS, IGNORED, STAGE_FIXES, kind
from .lammps_deck import Deck
from .lammps_read import DEFAULT_TIMESTEP, _timestep, deck_fixes
from .lammps_setup import NEIGH_MODIFY, Reading
from .lammps_variables import RunClock, Variables
from .lost_atoms import LostAtoms

#: the commands ase_bpm carries out between runs, for the refusals
CARRIED_OUT = f"{', '.join(list(BETWEEN_RUNS.values())[:-1])} and {BETWEEN_RUNS['run']}"
#: the atoms' LAMMPS IDs, kept on the atoms while a deck runs (groups by ID
#: after atoms were lost)
LAMMPS_ID = "lammps_id"
#: atoms in a unit cell of the lattices whose spacing ``velocity ... units
#: lattice`` can scale by (LAMMPS: the cell's volume is 1 in lattice units)
BASIS_ATOMS = {"sc": 1, "bcc": 2, "fcc": 4, "diamond": 8}


class LaterRunsWarning(UserWarning):
    """read_lammps gave the scene of a deck's first run; the deck goes on
    after it (:func:`ase_bpm.run_lammps` carries the rest out)."""


@dataclass
class Stage:
    """A run after the first: ``number``, the line of its ``run``; ``end``,
    the run's index in the deck (the stage is the deck up to it);
    ``steps`` (or ``upto``, the step it runs to); the ``velocity ... set``
    commands before it (``(line, words)``)."""

    number: int
    end: int
    steps: int = 0
    upto: int | None = None
    velocities: list = field(default_factory=list)


def later_stages(atoms: Atoms, reading: Reading, warn: bool = False) -> list:
    """The :class:`Stage` s after the deck's first run, each checked: a line
    ase_bpm cannot carry out raises ValueError naming it.  ``warn``: a
    :class:`LaterRunsWarning` names them (read_lammps gives the first
    run's scene only)."""
    deck = reading.deck
    defined = _fix_styles(deck.commands[:reading.first_run])
    groups = _groups(deck.commands[:reading.first_run])
    stages, velocities = [], []
    run_line = deck.commands[reading.first_run][0] if reading.first_run < len(
        deck.commands) else None
    for k in range(reading.first_run + 1, len(deck.commands)):
        number, words = deck.commands[k]
        name = words[0]

        def refuse(why: str = ""):
            return ValueError(f"{deck.path} line {number}: {' '.join(words)!r} after the run "
                              f"of line {run_line}: {why or 'no counterpart there'}; ase_bpm "
                              f"carries out {CARRIED_OUT} between runs")

        if name not in BETWEEN_RUNS:
            if kind(words)[0] == IGNORED:
                continue
            raise refuse()
        if name == "run":
            stages.append(_stage(k, number, words, velocities, refuse))
            velocities, run_line = [], number
        elif name == "thermo_modify":
            continue  # (lost and lost/bond: read with each stage's fixes)
        elif name == "unfix":
            if len(words) != 2 or words[1] not in defined:
                raise refuse(f"no fix {' '.join(words[1:])} to remove (LAMMPS: could not "
                             "find fix ID to delete)")
            if defined[words[1]] not in STAGE_FIXES:
                raise refuse(f"fix {words[1]} is a fix {defined[words[1]]}, which ase_bpm "
                             "does not remove between runs")
            del defined[words[1]]
        elif name == "fix":
            if len(words) < 4 or words[3] not in STAGE_FIXES:
                raise refuse(f"fix {' '.join(words[3:4]) or 'without a style'} is not one "
                             "ase_bpm defines anew between runs")
            defined[words[1]] = words[3]
        elif name == "velocity":
            _velocity_set(words, groups, refuse)
            velocities.append((number, words))
        elif name == "timestep":
            if len(words) != 2 or not _number(words[1]) > 0:
                raise refuse("a timestep is one positive number")
        elif name == "variable":
            if words[2:3] != ["equal"]:
                raise refuse("ase_bpm evaluates equal-style variables")
            Variables(deck.path).define(number, words[1:])  # (the form; values at the run)
        elif name == "group":
            if len(words) < 4 or words[2] not in ("id", "type"):
                raise refuse("a group of atoms by id or type")
            groups[words[1]] = (number, words)
        elif name == "neighbor":
            if len(words) != 3 or not _number(words[1]) >= 0:
                raise refuse("'neighbor <skin> <style>'")
        elif name == "neigh_modify":
            pairs = words[1:]
            if len(pairs) % 2 or any(w not in NEIGH_MODIFY for w in pairs[::2]):
                raise refuse(f"neigh_modify with {', '.join(NEIGH_MODIFY)} only")
    _check_stages(atoms, reading, stages)
    if warn and stages:
        lines = ", ".join(str(s.number) for s in stages)
        warnings.warn(f"{deck.path}: read_lammps gives the scene of the first run (line "
                      f"{deck.commands[reading.first_run][0]}); the deck runs again after "
                      f"it (runs at lines {lines}): ase_bpm.run_lammps (ase-bpm run "
                      "DECK) carries them out", LaterRunsWarning, stacklevel=3)
    return stages


def _stage(k: int, number: int, words, velocities: list, refuse) -> Stage:
    """The stage of ``run N`` or ``run N upto`` (command ``k``, line
    ``number``); ``refuse(why)`` makes the error for another form."""
    stage = Stage(number, k, velocities=velocities)
    if len(words) == 2 and words[1].isdigit():
        stage.steps = int(words[1])
    elif len(words) == 3 and words[1].isdigit() and words[2] == "upto":
        stage.upto = int(words[1])
    else:
        raise refuse("a run is 'run N' or 'run N upto'")
    return stage


def _check_stages(atoms: Atoms, reading: Reading, stages: list) -> None:
    """Read each stage's fixes once on a stand-in of the atoms (so that a fix
    or variable ase_bpm cannot read is refused now, by line, not mid-run)."""
    stand_in = Atoms(positions=atoms.positions, cell=atoms.cell, pbc=atoms.pbc)
    for name in ("radius", "type"):
        if name in atoms.arrays:
            stand_in.arrays[name] = atoms.arrays[name]
    stand_in.arrays[LAMMPS_ID] = reading.ids_n
    for stage in stages:
        prefix = reading.deck.up_to(stage.end)
        deck_fixes(prefix, stand_in, reading, RunClock(0, stage_timestep(prefix, reading)),
                   reading.ids_n)
        groups = _groups(prefix.commands)
        for number, words in stage.velocities:  # (on held atoms: refused)
            set_velocities(stand_in, prefix, reading, number, words, groups)


def stage_timestep(prefix: Deck, reading: Reading) -> float:
    """The timestep of the run that ends ``prefix`` (LAMMPS' default for the
    units where the deck gives none)."""
    return _timestep(prefix) or DEFAULT_TIMESTEP[reading.units]


def _number(word: str) -> float:
    """The number a word gives (NaN, which no comparison passes, for another)."""
    try:
        return float(word)
    except ValueError:
        return float("nan")


def _fix_styles(commands) -> dict:
    """Fix ID -> style after ``commands`` (``unfix`` removes one)."""
    defined = {}
    for _, words in commands:
        if words[0] == "fix" and len(words) >= 4:
            defined[words[1]] = words[3]
        elif words[0] == "unfix" and len(words) == 2:
            defined.pop(words[1], None)
    return defined


def _groups(commands) -> dict:
    """Group name -> ``(line, words)`` of its last ``group`` command."""
    return {words[1]: (number, words) for number, words in commands
            if words[0] == "group" and len(words) > 1}


# -- velocity set ---------------------------------------------------------------------

VELOCITY_SET = ("'velocity <group> set vx vy vz [sum yes|no] [units box|lattice]' (each "
                "a number or NULL; the group all or one by id or type)")


def _velocity_set(words, groups: dict, refuse) -> dict:
    """The options of ``velocity <group> set vx vy vz ...``: ``group``,
    ``values`` (None for NULL), ``sum`` and ``units``."""
    if len(words) < 6 or words[2] != "set" or len(words) % 2:
        raise refuse(f"ase_bpm sets velocities between runs with {VELOCITY_SET}")
    options = {"sum": "no", "units": "lattice"}
    for key, value in zip(words[6::2], words[7::2]):
        if key not in options or value not in (("yes", "no") if key == "sum"
                                               else ("box", "lattice")):
            raise refuse(f"ase_bpm sets velocities between runs with {VELOCITY_SET}")
        options[key] = value
    try:
        values = [None if w == "NULL" else float(w) for w in words[3:6]]
    except ValueError:
        raise refuse(f"ase_bpm sets velocities between runs with {VELOCITY_SET}") from None
    group = words[1]
    if group != "all" and (group not in groups or groups[group][1][2] not in ("id", "type")):
        raise refuse(f"group {group} is not all nor one by id or type")
    return {"group": group, "values": values, "sum": options["sum"] == "yes",
            "units": options["units"]}


def lattice_scale(prefix: Deck, units: str, number: int) -> float:
    """What ``velocity ... units lattice`` multiplies by: the spacing of the
    deck's last ``lattice`` (1 without one), as LAMMPS sets it: ``none s``
    gives s; ``sc``, ``bcc``, ``fcc``, ``diamond`` give the lattice constant,
    in lj units ``(atoms per cell / reduced density)^(1/3)``."""
    found = [w for _, w in prefix.commands if w[0] == "lattice"]
    if not found:
        return 1.0
    words = found[-1][1:]
    if len(words) == 2 and words[0] == "none":
        return float(words[1])
    if len(words) == 2 and words[0] in BASIS_ATOMS:
        value = float(words[1])
        return (BASIS_ATOMS[words[0]] / value) ** (1.0 / 3.0) if units == "lj" else value
    raise ValueError(f"{prefix.path} line {number}: velocity in lattice units with "
                     f"'lattice {' '.join(words)}': ase_bpm scales by the lattices "
                     f"{', '.join(BASIS_ATOMS)} and none without keywords; give 'units box'")


def set_velocities(atoms: Atoms, prefix: Deck, reading: Reading, number: int, words,
                   groups: dict) -> None:
    """Carry out ``velocity <group> set ...`` (line ``number``) on the atoms,
    whose LAMMPS IDs are ``atoms.arrays[LAMMPS_ID]``."""
    def refuse(why):
        return ValueError(f"{prefix.path} line {number}: {' '.join(words)!r}: {why}")

    options = _velocity_set(words, groups, refuse)
    members = _members(atoms, options["group"], groups)
    scale = 1.0 if options["units"] == "box" else lattice_scale(prefix, reading.units, number)
    v_nc = atoms.get_velocities()
    for axis, value in enumerate(options["values"]):
        if value is None:
            continue
        if options["sum"]:
            v_nc[members, axis] += value * scale
        else:
            v_nc[members, axis] = value * scale
    held = frozen(atoms)
    if held is not None and np.any(v_nc[held & members] != 0.0):
        raise refuse("it gives held atoms (fix freeze or setforce 0 0 0) a velocity, at which "
                     "LAMMPS moves them on; ase_bpm holds them still (FixAtoms)")
    atoms.set_velocities(v_nc)


def _members(atoms: Atoms, group: str, groups: dict) -> np.ndarray:
    """A mask of the atoms of ``group`` (``all``, or by LAMMPS id or type)."""
    if group == "all":
        return np.ones(len(atoms), dtype=bool)
    _, words = groups[group]
    wanted = []
    for word in words[3:]:
        lo, _, hi = word.partition(":")
        wanted += range(int(lo), int(hi or lo) + 1)
    if words[2] == "id":
        return np.isin(atoms.arrays[LAMMPS_ID], wanted)
    types_n = atoms.arrays.get("type", np.ones(len(atoms), dtype=np.int64))
    return np.isin(types_n, wanted)


# -- carrying a stage out -------------------------------------------------------------

@dataclass
class Progress:
    """Where a deck's run stands: the ``step`` and ``time`` (LAMMPS' clock)."""

    step: int = 0
    time: float = 0.0


def begin_stage(atoms: Atoms, reading: Reading, stage: Stage, now: Progress) -> int:
    """Set the scene up for ``stage`` (its fixes, timestep and velocities,
    as the deck holds them at its run) and return its number of steps."""
    deck = reading.deck
    prefix = deck.up_to(stage.end)
    calc = atoms.calc
    timestep = stage_timestep(prefix, reading)
    clock = RunClock(now.step, timestep, now.time)
    calc.fixes = deck_fixes(prefix, atoms, reading, clock, atoms.arrays[LAMMPS_ID])
    groups = _groups(prefix.commands)
    for number, words in stage.velocities:
        set_velocities(atoms, prefix, reading, number, words, groups)
    if calc.parameters.get("timestep") != timestep:
        calc.set(timestep=timestep)
    calc.refresh()  # (LAMMPS' set-up: forces anew, at these velocities)
    for fix in calc.fixes:
        if isinstance(fix, LostAtoms):
            fix.start_run()
    if stage.upto is not None:
        if stage.upto < now.step:
            raise ValueError(f"{deck.path} line {stage.number}: 'run {stage.upto} upto' at "
                             f"step {now.step}: LAMMPS refuses a run to a step passed")
        return stage.upto - now.step
    return stage.steps


def first_stage(reading: Reading) -> Stage:
    """The deck's first run as a stage (its scene is read_lammps')."""
    deck = reading.deck
    if reading.first_run >= len(deck.commands):
        raise ValueError(f"{deck.path}: no 'run N' with N > 0: nothing to run")
    number, words = deck.commands[reading.first_run]
    return _stage(reading.first_run, number, words, [], lambda why: ValueError(
        f"{deck.path} line {number}: {' '.join(words)!r}: {why}"))

