"""A LAMMPS data file, read: the atoms, box, masses, velocities and bonds
that the ``read_data`` of a deck names (:func:`read_data`, for
:mod:`.lammps_setup`).

The data file's own reader here knows the atom styles ase_bpm writes: ``bond``
(``id mol type x y z``), ``bpm/sphere`` (``id mol type diameter density x y
z``), ``sphere`` (``id type diameter density x y z``) and ``peri`` (``id type
volume density x y z``), with ``Masses``, ``Velocities`` (with the angular
velocities of sphere styles) and ``Bonds``; a ``# Symbol`` comment on an atom's
line gives its chemical symbol (ase_bpm writes one), else ``X``.  A data file of
``bpm/sphere`` holds no orientation (LAMMPS's read_data makes each the
identity and its write_data writes none): a deck sets them (``set ... quat``).
"""

from __future__ import annotations

import io
import os
import re
import warnings
from dataclasses import dataclass, field

import numpy as np
from ase.data import atomic_numbers

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
    quat_nq: np.ndarray | None = None  # orientations (bpm/sphere), where known
    properties_n: dict = field(default_factory=dict)  # fix property/atom: d_<name> -> values
    quat_nq: np.ndarray | None = None  # orientations (w, i, j, k), where not all the identity


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
            # (NumPy 2.0 reads "1.0" as the integer 1, with this warning; later ones refuse it)
            warnings.simplefilter("error", DeprecationWarning)
            return np.loadtxt(io.BytesIO(section.body), dtype=dtype, comments="#",
                              usecols=range(first, width), ndmin=2)
    except (ValueError, DeprecationWarning) as error:
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
