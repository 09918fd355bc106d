"""Read a LAMMPS scene back into ase_bpm: the inverse of :func:`write_lammps`.

:func:`read_lammps` takes a data file and an input deck of the kind
:func:`ase_bpm.lammps.write_lammps` writes (or written by hand in the same
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
from dataclasses import dataclass, field

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms
from ase.data import atomic_numbers

from ..core.bonds import BondTable, atom_ids, write_table
from ..core.lammps_text import CONSISTENT_UNITS
from ..core.spheres import OMEGA, RADIUS
from ..laws.bond import LAWS
from ..models.granular import Granular
from ..models.peri import UNREACHABLE_STRETCH, BPMPeri
from ..models.spring import BPMSpring
from .fixes import Gravity, GranularWall, SphericalIndenter

#: commands that organise a LAMMPS run without changing its physics here
PASSED_OVER = {"dimension", "comm_modify", "neigh_modify", "thermo", "thermo_style",
               "thermo_modify", "compute", "dump", "dump_modify", "run", "atom_modify",
               "newton", "log", "print", "echo", "write_data", "write_restart"}
#: columns of the Atoms section of each atom style ase_bpm writes
ATOM_COLUMNS = {"bond": ("id", "mol", "type", "x", "y", "z"),
                "bpm/sphere": ("id", "mol", "type", "diameter", "density", "x", "y", "z"),
                "sphere": ("id", "type", "diameter", "density", "x", "y", "z"),
                "peri": ("id", "type", "volume", "density", "x", "y", "z")}
SPHERE_STYLES = ("bpm/sphere", "sphere")


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


def read_data(path: str | os.PathLike, atom_style: str | None = None) -> DataFile:
    """A data file of one of :data:`ATOM_COLUMNS`' styles (``atom_style``, or
    the style named in the ``Atoms # <style>`` header)."""
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
            name = words[0]
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
    """An input deck's commands (``(line number, words)``, comments and
    continuation lines resolved), consumed as they are understood."""

    path: str
    commands: list
    used: set = field(default_factory=set)

    def all(self, name: str, style: str | None = None) -> list:
        """The commands ``name`` (with ``style`` as the third word, for
        fixes), marked as understood."""
        found = []
        for k, (_, words) in enumerate(self.commands):
            if words[0] == name and (style is None or words[3:4] == [style]):
                self.used.add(k)
                found.append(words[1:])
        return found

    def last(self, name: str, default=None):
        found = self.all(name)
        return found[-1] if found else default

    def refuse_the_rest(self) -> None:
        for k, (number, words) in enumerate(self.commands):
            if k not in self.used and words[0] not in PASSED_OVER:
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r} has no "
                                 "ase_bpm counterpart: read_lammps reads the commands "
                                 "write_lammps writes")


def read_deck(path: str | os.PathLike) -> Deck:
    commands, pending, start = [], "", 0
    with open(path) as fh:
        for number, raw in enumerate(fh, start=1):
            text = raw.split("#", 1)[0].rstrip() if '"' not in raw else _strip_comment(raw)
            if not pending:
                start = number
            if text.endswith("&"):
                pending += text[:-1] + " "
                continue
            text, pending = pending + text, ""
            words = shlex.split(text)
            if words:
                commands.append((start, words))
    return Deck(str(path), commands)


def _strip_comment(raw: str) -> str:
    """The line without a comment outside quotes."""
    quoted = False
    for k, char in enumerate(raw):
        if char == '"':
            quoted = not quoted
        elif char == "#" and not quoted:
            return raw[:k].rstrip()
    return raw.rstrip()


# -- the scene ------------------------------------------------------------------------

def read_lammps(data: str | os.PathLike, deck: str | os.PathLike) -> Atoms:
    """The scene of a LAMMPS ``data`` file and input ``deck`` (as
    :func:`ase_bpm.lammps.write_lammps` writes them), with its calculator
    (BPMSpring, BPMPeri or Granular, with its fixes and timestep) attached;
    ``atoms.info["lammps_units"]`` keeps the deck's unit system."""
    commands = read_deck(deck)
    units = (commands.last("units") or ["lj"])[0]
    if units not in CONSISTENT_UNITS:
        raise ValueError(f"{deck}: units {units}: ase_bpm converts no units and reads "
                         f"{', '.join(CONSISTENT_UNITS)}")
    style = (commands.last("atom_style") or [None])[0]
    table = read_data(data, style)
    atoms = _atoms(table, commands)
    atoms.info["lammps_units"] = units
    pair = commands.last("pair_style")
    if pair is None:
        raise ValueError(f"{deck}: no pair_style: nothing for ase_bpm to compute")
    if pair[0].startswith("gran/"):
        calc = _granular(commands, pair)
    elif pair[0].startswith("peri/"):
        calc = _peri(commands, pair, atoms)
    elif pair[0] in ("bpm/spring", "zero"):
        calc = _spring(commands, pair, atoms)
    else:
        raise ValueError(f"{deck}: pair_style {pair[0]} has no ase_bpm counterpart")
    volume = float(atoms.arrays["vfrac"][0]) if "vfrac" in atoms.arrays else 1.0
    calc.fixes = _fixes(commands, atoms, volume if isinstance(calc, BPMPeri) else 1.0)
    commands.refuse_the_rest()
    atoms.calc = calc
    return atoms


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
        for words in deck.all("set"):  # set atom <id> mass <m> (write_lammps's exact masses)
            if words[0] != "atom" or words[2] != "mass":
                raise ValueError(f"{deck.path}: set {' '.join(words)}: read_lammps reads "
                                 "only 'set atom <id> mass <m>'")
            masses[int(words[1]) - 1] = float(words[3])
    elif table.style == "peri":
        atoms.arrays["vfrac"] = c["volume"].copy()
        masses = c["density"] * c["volume"]
    else:
        masses = np.array([table.masses_t[t] for t in types_n])
    atoms.set_masses(masses)
    if table.v_nc is not None:
        atoms.set_velocities(table.v_nc)
    if table.omega_nc is not None:
        atoms.arrays[OMEGA] = table.omega_nc.copy()
    if table.bonds is not None and len(table.bonds):
        put_bonds(atoms, table.bonds[:, 1], table.bonds[:, 2], table.bonds[:, 0])
    _read_only_data_commands(deck)
    return atoms


def _read_only_data_commands(deck: Deck) -> None:
    """Commands the data file and atoms already account for."""
    for name in ("units", "atom_style", "boundary", "read_data"):
        deck.all(name)


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
    found = deck.all("fix", style)
    if len(found) != 1 or found[0][1] != "all":
        raise ValueError(f"{deck.path}: ase_bpm reads one 'fix <id> all {style}' for this "
                         f"scene, found {len(found)}")


def _granular(deck: Deck, pair: list) -> Granular:
    model = pair[0].removeprefix("gran/")
    words = pair[1:]
    values = [None if w == "NULL" else float(w) for w in words[:5]]
    kn, kt, gamma_n, gamma_t, xmu = values
    limit_damping = "limit_damping" in words[6:]
    if deck.all("pair_coeff") != [["*", "*"]]:
        raise ValueError(f"{deck.path}: gran styles take one 'pair_coeff * *'")
    _integrator(deck, "nve/sphere")
    return Granular(model, kn=kn, kt=kt, gamma_n=gamma_n, gamma_t=gamma_t, xmu=xmu,
                    dampflag=int(words[5]), limit_damping=limit_damping,
                    skin=_skin(deck), timestep=_timestep(deck))


def _spring(deck: Deck, pair: list, atoms: Atoms) -> BPMSpring:
    style = deck.last("bond_style")
    if style is None or style[0] != "bpm/spring":
        raise ValueError(f"{deck.path}: pair_style {pair[0]} needs bond_style bpm/spring")
    flags = dict(zip(style[1::2], style[2::2]))
    on = {"smooth": True, "normalize": False, "break": True, "overlay/pair": False}
    on.update({k: v == "yes" for k, v in flags.items() if k in on})
    nbonds = len(atoms.arrays.get("bond_partner", ()))
    bond_coeffs = {int(w[0]): (float(w[1]), float(w[2]), float(w[3]))
                   for w in deck.all("bond_coeff")}
    used = set(np.unique(atoms.arrays["bond_type"])) - {0} if nbonds else set()
    bond_coeffs = {t: v for t, v in bond_coeffs.items() if t in used}
    pair_coeffs = {}
    if pair[0] == "bpm/spring":
        pair_coeffs = {(int(w[0]), int(w[1])): (float(w[2]), float(w[3]), float(w[4]))
                       for w in deck.all("pair_coeff")}
    else:
        deck.all("pair_coeff")  # pair_style zero: the bonds' communication only
    mix = (deck.last("pair_modify") or ["mix", "geometric"])[1]
    special = deck.last("special_bonds")
    overlay = special is not None and special[:1] == ["lj/coul"]
    if overlay != on["overlay/pair"]:
        raise ValueError(f"{deck.path}: special_bonds {' '.join(special or [])} disagrees "
                         f"with overlay/pair {'yes' if on['overlay/pair'] else 'no'}")
    _integrator(deck, "nve/sphere" if atoms.has(RADIUS) else "nve")
    store = "store/local" in style
    skin = _skin(deck)  # (without contacts, the bonds' communication only)
    return BPMSpring(bond_coeffs=bond_coeffs, pair_coeffs=pair_coeffs, mix=mix,
                     smooth=on["smooth"], normalize=on["normalize"],
                     break_bonds=on["break"], overlay_pair=on["overlay/pair"],
                     store_local=store, skin=skin if pair_coeffs else None,
                     timestep=_timestep(deck))


def _peri(deck: Deck, pair: list, atoms: Atoms) -> BPMPeri:
    """Legacy peri/<model>: one model for every pair within the horizon,
    bonded afresh here, with the legacy contact as ``pair_style bpm/peri``."""
    from ..core.bonds import create_bonds

    name = pair[0].removeprefix("peri/")
    law = LAWS.get(name)
    coeffs = deck.all("pair_coeff")
    if law is None or getattr(law, "family", "") != "peri" or len(coeffs) != 1:
        raise ValueError(f"{deck.path}: pair_style {pair[0]} with one 'pair_coeff * *' is "
                         "what read_lammps reads of legacy PERI")
    legacy = dict(zip(law.legacy_order, (float(w) for w in coeffs[0][2:])))
    lattice = deck.last("lattice")
    spacing = float(lattice[1]) if lattice else None
    create_bonds(atoms, legacy["horizon"])
    k = legacy["c"] if name == "pmb" else 18.0 * legacy["K"] / (math.pi
                                                                   * legacy["horizon"] ** 4)
    _integrator(deck, "nve")
    breaks = legacy["s00"] != UNREACHABLE_STRETCH  # (how write_lammps says break_bonds=False)
    return BPMPeri(bond_coeffs={1: (name, *(legacy[n] for n in law.coefficients))},
                   pair_coeffs={(1, 1): (k, legacy["horizon"])}, lattice_spacing=spacing,
                   break_bonds=breaks, skin=_skin(deck), timestep=_timestep(deck))


# -- fixes ----------------------------------------------------------------------------

def _fixes(deck: Deck, atoms: Atoms, force_per_lammps_force: float) -> list:
    """The deck's fixes (each ``fix`` command as ``[id, group, style, ...]``),
    in the order of the deck; ``FixAtoms`` set on the atoms.
    ``force_per_lammps_force``: what LAMMPS' ``f`` is of a true force (the
    node volume for legacy PERI)."""
    fixes = []
    variables = {w[0]: w[2] for w in deck.all("variable") if w[1] == "equal"}
    groups = {w[0]: w for w in deck.all("group")}
    for number, words in deck.commands:
        if words[0] != "fix" or len(words) < 4:
            continue
        fix = words[1:]
        if fix[2] == "gravity" and fix[1] == "all" and fix[4:5] == ["vector"]:
            fixes.append(Gravity(float(fix[3]), [float(w) for w in fix[5:8]]))
        elif fix[2] == "wall/gran" and fix[1] == "all":
            fixes.append(_wall(deck, fix))
        elif fix[2] == "indent" and fix[1] == "all":
            fixes.append(_indenter(deck, fix, variables, force_per_lammps_force))
        elif fix[2] in ("freeze", "setforce"):
            group = groups.get(fix[1])
            if group is None or group[1] != "id" or fix[3:] not in ([], ["0.0"] * 3):
                raise ValueError(f"{deck.path} line {number}: {' '.join(words)!r}: read_lammps "
                                 "reads 'fix <id> <group> freeze' (or setforce 0.0 0.0 0.0) "
                                 "of a 'group <group> id <ids>'")
            atoms.set_constraint(FixAtoms(indices=[int(i) - 1 for i in group[2:]]))
        else:
            continue
        deck.used.add(deck.commands.index((number, words)))
    return fixes


def _wall(deck: Deck, words: list) -> GranularWall:
    """``fix <id> all wall/gran <model> Kn Kt gamma_n gamma_t xmu dampflag
    [limit_damping] <axis>plane lo hi``."""
    model, numbers = words[3], words[4:9]
    kn, kt, gamma_n, gamma_t, xmu = (None if w == "NULL" else float(w) for w in numbers)
    limit_damping = words[10] == "limit_damping"
    axis, lo, hi = words[10 + limit_damping:13 + limit_damping]
    if len(words) != 13 + limit_damping or not axis.endswith("plane"):
        raise ValueError(f"{deck.path}: fix {' '.join(words)}: read_lammps reads 'fix <id> all "
                         "wall/gran <model> Kn Kt gamma_n gamma_t xmu dampflag "
                         "[limit_damping] xplane|yplane|zplane lo hi'")
    name = words[0].removeprefix("ase_bpm_wall_") if words[0].startswith("ase_bpm_wall_") \
        else None
    return GranularWall(model, kn=kn, kt=kt, gamma_n=gamma_n, gamma_t=gamma_t, xmu=xmu,
                        dampflag=int(words[9]), axis=axis[0],
                        lo=None if lo == "NULL" else float(lo),
                        hi=None if hi == "NULL" else float(hi),
                        limit_damping=limit_damping, name=name)


MOVING = re.compile(r"^\s*(\S+)\s*\+\s*step\s*\*\s*dt\s*\*\s*(\S+)\s*$")


def _indenter(deck: Deck, words: list, variables: dict,
              force_per_lammps_force: float) -> SphericalIndenter:
    """``fix <id> all indent K sphere x y z R units box``, each coordinate a
    number or ``v_<name>`` of an equal variable ``"x0 + step*dt*v"``."""
    if words[4] != "sphere" or words[-2:] != ["units", "box"]:
        raise ValueError(f"{deck.path}: fix {' '.join(words)}: read_lammps reads 'fix <id> "
                         "all indent K sphere x y z R units box'")
    centre, velocity = [], []
    for word in words[5:8]:
        if word.startswith("v_"):
            moving = MOVING.match(variables.get(word[2:], ""))
            if moving is None:
                raise ValueError(f"{deck.path}: variable {word[2:]} must be \"x0 + "
                                 "step*dt*v\" for an indenter ase_bpm can move")
            centre.append(float(moving.group(1)))
            velocity.append(float(moving.group(2)))
        else:
            centre.append(float(word))
            velocity.append(0.0)
    return SphericalIndenter(float(words[3]) * force_per_lammps_force, float(words[8]), centre,
                             velocity)
