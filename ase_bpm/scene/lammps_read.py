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

A command with no ase_bpm counterpart stops the reading with a ValueError
naming the line: a deck is never read as other physics.  Commands that only
organise a LAMMPS run (output, communication, neighbour-list checks, the run
itself) are passed over (:data:`PASSED_OVER`).

The data file's own reader here knows the atom styles ase_bpm writes: ``bond``
(``id mol type x y z``), ``bpm/sphere`` (``id mol type diameter density x y
z``), ``sphere`` (``id type diameter density x y z``) and ``peri`` (``id type
volume density x y z``), with ``Masses``, ``Velocities`` (with the angular
velocities of sphere styles) and ``Bonds``; a ``# Symbol`` comment on an atom's
line gives its chemical symbol (ase_bpm writes one), else ``X``.
"""

from __future__ import annotations

import math
import os
import re
import shlex
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
from ..models.peri import UNREACHABLE_STRETCH, BPMPeri
from ..models.spring import BPMSpring
from .fixes import Gravity, GranularWall, SphericalIndenter

#: commands that organise a LAMMPS run without changing its physics here
PASSED_OVER = {"comm_modify", "thermo", "thermo_style", "thermo_modify", "compute", "dump",
               "dump_modify", "run", "newton", "log", "print", "echo", "write_data",
               "write_restart"}
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
    masses_t: dict = field(default_factory=dict)
    v_nc: np.ndarray | None = None
    omega_nc: np.ndarray | None = None
    bonds: np.ndarray | None = None  # rows (type, i, j), 0-based atoms
    #: per-atom values of fix property/atom sections, by property (``d_vfrac``)
    properties_n: dict = field(default_factory=dict)


def read_data(path: str | os.PathLike, atom_style: str | None = None,
              properties: dict | None = None) -> DataFile:
    """A data file of one of :data:`ATOM_COLUMNS`' styles (``atom_style``, or
    the style named in the ``Atoms # <style>`` header).  ``properties``:
    ``{section: property names}`` of ``read_data <file> fix <id> NULL
    <section>`` (the fix's ``property/atom`` names, e.g. ``("d_vfrac",)``):
    each such section holds ``id value...`` per atom."""
    properties = properties or {}
    with open(path) as fh:
        lines = fh.read().splitlines()
    counts, bounds, tilt = {}, {}, (0.0, 0.0, 0.0)
    sections, name = {}, None
    for number, raw in enumerate(lines[1:], start=2):  # (the first line is a title)
        text, _, comment = raw.partition("#")
        words = text.split()
        if not words:
            continue
        if words[0][0].isalpha() and not _is_number(words[0]):  # a section starts
            name = " ".join(words)
            if name not in SECTIONS and name not in properties:
                raise ValueError(f"{path} line {number}: section {name!r}: read_lammps "
                                 f"reads {', '.join(SECTIONS)} (coefficients belong in the "
                                 "deck)")
            sections[name] = []
            if name == "Atoms" and comment.strip():
                atom_style = atom_style or comment.split()[0]
            continue
        if name is None:  # the header
            if words[-1] in ("atoms", "bonds") or words[-2:-1] in (["atom"], ["bond"]):
                counts[" ".join(words[1:])] = int(words[0])
            elif words[-1] in ("xhi", "yhi", "zhi"):
                bounds[words[-1][0]] = (float(words[0]), float(words[1]))
            elif words[-3:] == ["xy", "xz", "yz"]:
                tilt = tuple(float(w) for w in words[:3])
            continue
        sections[name].append((number, words, comment.strip()))
    if atom_style not in ATOM_COLUMNS:
        raise ValueError(f"{path}: atom_style {atom_style!r} is not one ase_bpm reads "
                         f"({', '.join(ATOM_COLUMNS)})")
    natoms = counts.get("atoms", 0)
    rows = _by_id(path, "Atoms", sections.get("Atoms", []), natoms,
                  len(ATOM_COLUMNS[atom_style]))
    columns_n = {c: np.array([float(r[1][k]) for r in rows])
                 for k, c in enumerate(ATOM_COLUMNS[atom_style])}
    symbols_n = [r[2].split()[0] if r[2] and r[2].split()[0] in atomic_numbers else "X"
                 for r in rows]
    lo = np.array([bounds[a][0] for a in "xyz"])
    hi = np.array([bounds[a][1] for a in "xyz"])
    cell = np.diag(hi - lo)
    cell[1, 0], cell[2, 0], cell[2, 1] = tilt
    data = DataFile(atom_style, columns_n, symbols_n, cell)
    for _, words, _ in sections.get("Masses", []):
        data.masses_t[int(words[0])] = float(words[1])
    if "Velocities" in sections:
        width = 7 if atom_style in SPHERE_STYLES else 4
        v = np.array([[float(w) for w in r[1][1:width]]
                      for r in _by_id(path, "Velocities", sections["Velocities"], natoms,
                                      width)])
        data.v_nc, data.omega_nc = v[:, :3], (v[:, 3:6] if width == 7 else None)
    if "Bonds" in sections:
        data.bonds = np.array([[int(w) for w in words[1:4]]
                               for _, words, _ in sections["Bonds"]], dtype=np.int64)
        data.bonds[:, 1:] -= 1
    for section, names in properties.items():
        if section not in sections:
            raise ValueError(f"{path}: no section {section!r}, which read_data names for "
                             f"the properties {', '.join(names)}")
        rows = _by_id(path, section, sections[section], natoms, 1 + len(names))
        for k, name in enumerate(names, start=1):
            data.properties_n[name] = np.array([float(r[1][k]) for r in rows])
    return data


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def _by_id(path, section: str, rows, natoms: int, width: int) -> list:
    """The rows of a section in atom-ID order (IDs 1..natoms, each once)."""
    out = [None] * natoms
    for number, words, comment in rows:
        if len(words) < width:
            raise ValueError(f"{path} line {number}: {section} needs {width} columns, got "
                             f"{' '.join(words)!r}")
        n = int(words[0]) - 1
        if not 0 <= n < natoms or out[n] is not None:
            raise ValueError(f"{path} line {number}: atom ID {n + 1} out of 1..{natoms} "
                             "or given twice")
        out[n] = (number, words, comment)
    if None in out:
        raise ValueError(f"{path}: {section} lacks atom ID {out.index(None) + 1}")
    return out


# -- the deck -------------------------------------------------------------------------

@dataclass
class Deck:
    """An input deck's commands (``(line number, words)``, continuation lines
    joined and comments removed as LAMMPS does), each marked as understood
    when a reader takes it."""

    path: str
    commands: list
    used: set = field(default_factory=set)

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

    def refuse_the_rest(self) -> None:
        """Every command not taken must only organise the run (PASSED_OVER),
        and nothing that changes the physics may follow the first run."""
        first_run = next((k for k, (_, w) in enumerate(self.commands)
                          if w[0] == "run" and w[1:2] != ["0"]), len(self.commands))
        for k, (number, words) in enumerate(self.commands):
            if k in self.used and k > first_run:
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r} after the "
                                 "first run: read_lammps reads one scene, set up before its "
                                 "run")
            if k not in self.used and words[0] not in PASSED_OVER:
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r} has no "
                                 "ase_bpm counterpart: read_lammps reads the commands "
                                 "write_lammps writes")


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
    return Deck(str(path), commands)


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

def read_lammps(data: str | os.PathLike, deck: str | os.PathLike) -> Atoms:
    """The scene of a LAMMPS ``data`` file and input ``deck`` (as
    :func:`ase_bpm.write_lammps` writes them), with its calculator
    (BPMSpring, BPMPeri or Granular, with its fixes and timestep) attached;
    ``atoms.info["lammps_units"]`` keeps the deck's unit system."""
    commands = read_deck(deck)
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
    reads = commands.take("read_data")
    if len(reads) != 1:
        raise ValueError(f"{deck}: read_lammps reads one 'read_data <file>', found "
                         f"{[' '.join(w) for _, w in reads]}")
    style = (commands.last("atom_style") or [None])[0]
    table = read_data(data, style, _property_sections(commands, *reads[0]))
    atoms = _atoms(table, commands)
    atoms.info["lammps_units"] = units
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
    _refuse_lost_atoms(commands)
    # (legacy PERI's f holds force densities, for one node volume; others true forces)
    legacy = isinstance(calc, BPMPeri) and calc.parameters["follows"] == LEGACY
    volume = float(atoms.arrays["vfrac"][0]) if legacy else 1.0
    calc.fixes = _fixes(commands, atoms, volume)
    commands.refuse_the_rest()
    atoms.calc = calc
    return atoms


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


def _refuse_lost_atoms(deck: Deck) -> None:
    """``thermo_modify lost ignore`` in a box with a fixed face: LAMMPS removes
    the atoms that leave it, and ase_bpm keeps every atom, so the scenes would
    differ once one leaves: refused by line (with ``m`` or ``s`` faces LAMMPS
    loses no atom)."""
    boundary = deck.last("boundary", ["p", "p", "p"])
    for number, (name, *words) in deck.commands:  # (not taken: it stays passed over)
        if name != "thermo_modify":
            continue
        lost = words.index("lost") if "lost" in words else None
        if lost is not None and words[lost + 1:lost + 2] == ["ignore"] and any(
                "f" in face for face in boundary):
            raise ValueError(
                f"{deck.path} line {number}: {' '.join(['thermo_modify', *words])!r} with "
                f"the fixed faces of 'boundary {' '.join(boundary)}': LAMMPS removes the "
                "atoms that leave the box, ase_bpm keeps every atom; make those faces m "
                "or s (then LAMMPS keeps them too), or remove the line")


#: the neigh_modify keywords that change no physics (each takes one value)
NEIGH_MODIFY = ("every", "delay", "check", "once", "page", "one", "binsize")


def _atoms(table: DataFile, deck: Deck) -> Atoms:
    """Positions, cell, pbc, types, masses, velocities and the style's own
    per-atom columns."""
    c = table.columns_n
    boundary = deck.last("boundary", ["p", "p", "p"])
    pbc = np.array([b == "p" for b in boundary])
    x_nc = np.column_stack([c["x"], c["y"], c["z"]])
    atoms = Atoms(symbols=table.symbols_n, positions=x_nc, cell=table.cell, pbc=pbc)
    types_n = c["type"].astype(np.int64)
    if np.any(types_n != 1) or table.style != "peri":
        atoms.arrays["type"] = types_n
    if table.style in SPHERE_STYLES:
        r_n = 0.5 * c["diameter"]
        atoms.arrays[RADIUS] = r_n
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
    elif "d_vfrac" in table.properties_n:  # bond_style bpm/peri: true masses per type
        atoms.arrays["vfrac"] = table.properties_n["d_vfrac"]
        masses = np.array([table.masses_t[t] for t in types_n])
    else:
        masses = np.array([table.masses_t[t] for t in types_n])
    atoms.set_masses(masses)
    if table.v_nc is not None:
        atoms.set_velocities(table.v_nc)
    if table.omega_nc is not None:
        atoms.arrays[OMEGA] = table.omega_nc.copy()
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

def _fixes(deck: Deck, atoms: Atoms, force_per_lammps_force: float) -> list:
    """The deck's fixes, in its order; the held atoms of ``fix freeze`` (or
    ``setforce 0.0 0.0 0.0`` on point particles) as one ``FixAtoms`` on the
    atoms.  ``force_per_lammps_force``: what LAMMPS' ``f`` is of a true force
    (the node volume for legacy PERI).

    Fix IDs as LAMMPS keeps them: a fix defined again with the same ID and
    style replaces the first, in its place; with another style it is refused
    (LAMMPS refuses it too); ``unfix <id>`` removes one."""
    defined = {}  # fix ID -> (style, a fix of ase_bpm's or the atoms it holds)
    variables = {w[0]: w[2] for _, w in deck.take("variable") if w[1:2] == ["equal"]}
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
        if style in readers and fix[1] == "all":
            wanted = READS[style]
            with deck.reading(number, words, wanted):
                made = readers[style](deck, number, fix, variables, force_per_lammps_force)
        elif style in ("freeze", "setforce"):
            wanted = ("'fix <id> <group> freeze' (setforce 0.0 0.0 0.0 for point "
                      "particles) of a 'group <group> id <ids>'")
            line, group = groups.get(fix[1], (number, []))
            spheres = atoms.has(RADIUS)
            if (group[1:2] != ["id"] or (style == "freeze") != (fix[3:] == [])
                    or (style == "setforce" and (spheres or fix[3:] != ["0.0"] * 3))):
                raise deck.refuse(number, words, wanted)
            with deck.reading(line, ["group", *group], "'group <name> id <ids>'"):
                made = _ids(group[2:])
        else:
            continue
        if fix[0] in defined and defined[fix[0]][0] != style:
            raise ValueError(f"{deck.path} line {number}: {' '.join(words)!r}: fix ID "
                             f"{fix[0]} is a fix {defined[fix[0]][0]} already (LAMMPS: "
                             "replacing a fix, but new style != old style)")
        defined[fix[0]] = (style, made)  # (a fix defined again keeps its place)
        deck.used.add(k)
    fixes = [made for style, made in defined.values() if style in readers]
    held = [i for style, made in defined.values() if style not in readers for i in made]
    if held:
        atoms.set_constraint(FixAtoms(indices=sorted(set(held))))
    return fixes


READS = {"gravity": ("'fix <id> all gravity g vector x y z' (or 'spherical phi theta', "
                     "'chute angle')"),
         "wall/gran": ("'fix <id> all wall/gran <model> Kn Kt gamma_n gamma_t xmu dampflag "
                       "[limit_damping] xplane|yplane|zplane lo hi'"),
         "indent": "'fix <id> all indent K sphere x y z R units box'"}


def _ids(words) -> list:
    """0-based indices of LAMMPS atom IDs and ``a:b`` ranges."""
    out = []
    for word in words:
        lo, _, hi = word.partition(":")
        out += range(int(lo) - 1, int(hi or lo))
    return out


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
    name = words[0].removeprefix("ase_bpm_wall_") if words[0].startswith("ase_bpm_wall_") \
        else None
    return GranularWall(words[3], kn=kn, kt=kt, gamma_n=gamma_n, gamma_t=gamma_t, xmu=xmu,
                        dampflag=int(words[9]), axis=axis[0], lo=_number_or_null(lo),
                        hi=_number_or_null(hi), limit_damping=limit_damping, name=name)


MOVING = re.compile(r"^\s*(\S+)\s*\+\s*step\s*\*\s*dt\s*\*\s*(\S+)\s*$")


def _indenter(deck, number, words, variables, force_per_lammps_force) -> SphericalIndenter:
    """``fix <id> all indent K sphere x y z R units box``, each coordinate a
    number or ``v_<name>`` of an equal variable ``"x0 + step*dt*v"``."""
    if len(words) != 11 or words[4] != "sphere" or words[9:] != ["units", "box"]:
        raise deck.refuse(number, ["fix", *words], READS["indent"])
    centre, velocity = [], []
    for word in words[5:8]:
        if word.startswith("v_"):
            moving = MOVING.match(variables.get(word[2:], ""))
            if moving is None:
                raise ValueError(f"{deck.path} line {number}: variable {word[2:]} must be "
                                 "\"x0 + step*dt*v\" for an indenter ase_bpm can move")
            centre.append(float(moving.group(1)))
            velocity.append(float(moving.group(2)))
        else:
            centre.append(float(word))
            velocity.append(0.0)
    return SphericalIndenter(float(words[3]) * force_per_lammps_force, float(words[8]), centre,
                             velocity)
