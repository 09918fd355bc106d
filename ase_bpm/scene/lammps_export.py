"""Each model's scene in LAMMPS: the inverse of :mod:`.lammps_read`.

:func:`lammps_scene` gives a calculator's scene as a
:class:`ase_bpm.core.lammps_text.LammpsScene` (data file, commands, output
lines), by the function :data:`SCENES` lists for the calculator's class:

* :func:`spring_scene`: BPMSpring, ``bond_style`` and ``pair_style
  bpm/spring`` on ``atom_style bond`` (``bpm/sphere`` with ``fix
  nve/sphere`` when a fix needs spheres);
* :func:`peri_scene`: BPMPeri, in the styles it follows on the atoms,
  ``bond_style``/``pair_style bpm/peri`` (:func:`bpm_peri_scene`) or the
  legacy ``peri/<law>`` pair style (:func:`legacy_peri_scene`);
* :func:`granular_scene`: Granular, ``pair_style gran/<model>`` on
  ``atom_style sphere`` with ``fix nve/sphere``.

The style names and coefficient orders are the laws' own
(``BondLaw.lammps_style`` and ``coefficients``, ``PairLaw.name`` and
``coefficients``, ``PeriBond.legacy_style()`` and ``legacy_order``,
``ContactLaw.STYLE_PREFIX`` and ``LAMMPS_ORDER``), which :mod:`.lammps_read`
reads back by; the facts only a deck carries are defined here once, for the
reader too (:data:`SPRING_KEYWORDS`, :data:`STORE_LOCAL`,
:data:`UNREACHABLE_STRETCH`, :func:`legacy_contact_stiffness`).  What the
LAMMPS files cannot express is refused with a ValueError naming it, never
written as a deck that runs other physics.  :func:`ase_bpm.write_lammps`
puts the fixes, ``FixAtoms``, the output and the run around the scene; it
knows no model.  A model of its own brings its function and its line in
:data:`SCENES`.
"""

from __future__ import annotations

import os

import numpy as np
from ase import Atoms

from ..core.arrays import particle_types
from ..core.bonds import bond_table, get_bonds
from ..core.lammps_text import (DEFAULT_SKIN, LammpsScene, bond_data, bond_lengths,
                                check_reference_lengths, exact, integrator,
                                neighbour_lists, orientation_lines, peri_data, preamble,
                                sphere_data, sphere_densities)
from ..core.neighbours import neighbour_pairs
from ..core.spheres import radii
from ..laws.peri import BPM_PERI, PeriBond, PeriContact
from ..laws.rotational import RotationalBond
from ..laws.spring import VOLUME_FACTOR, SpringBond, SpringPair
from ..models.contacts import SHEAR
from ..models.granular import Granular
from ..models.peri import BPMPeri
from ..models.spring import BPMSpring

#: the keywords of ``bond_style bpm/spring`` ase_bpm has, in the order
#: written: each one's BPMSpring parameter and its LAMMPS default
SPRING_KEYWORDS = {"smooth": ("smooth", True), "normalize": ("normalize", False),
                   "break": ("break_bonds", True), "overlay/pair": ("overlay_pair", False)}
#: the attributes ``store/local`` records of a broken bond, in the order of
#: the columns of ``atoms.info["broken_bonds"]`` (a ``store/local`` fix ID
#: and N come before them)
STORE_LOCAL = ("id1", "id2", "time", "x", "y", "z", "x/ref", "y/ref", "z/ref")
#: ``bond_style bpm/spring``'s keyword for BPMSpring's ``volume_factor`` (its
#: a_v then closes every ``bond_coeff`` line), and ``pair_style bpm/spring``'s
#: for ``anharmonic`` (its k_a then closes every ``pair_coeff`` line)
VOLUME_KEYWORD, ANHARMONIC_KEYWORD = "volume/factor", "anharmonic"
#: ``bond_coeff`` values of a bond type no bond has (LAMMPS needs some), by
#: coefficient name (of the bpm/spring laws and bpm/rotational)
UNUSED_SPRING_TYPE = {"k": 1.0, "eps_c": 1.0, "gamma": 0.0, "eps_p": 1.0, VOLUME_FACTOR: 0.0,
                      **dict.fromkeys(RotationalBond.coefficients, 0.0),
                      **dict.fromkeys(RotationalBond.positive, 1.0)}
#: the s00 exported for break_bonds=False: legacy PERI has no switch, and no
#: bond stretches this far (s0 = s00 - alpha * smallest stretch stays near it)
UNREACHABLE_STRETCH = 1e300
#: a bond_style bpm/peri deck's node volumes: the fix property/atom that holds
#: them, and the data-file section read_data fills it from
VFRAC_FIX, VFRAC_SECTION = "ase_bpm_vfrac", "Vfrac"
#: a deck's neighbour skin for PERI without one given, in lattice spacings
PERI_SKIN = 0.3


def lammps_scene(atoms: Atoms, calc, data_file: str, **options) -> LammpsScene:
    """The calculator's scene in LAMMPS, by the function :data:`SCENES`
    lists for its class (or the nearest base class listed); ``options`` are
    that function's keywords (``units``, ``timestep``, ``thermo``, ...)."""
    for cls in type(calc).__mro__:
        if cls in SCENES:
            return SCENES[cls](calc, atoms, data_file, **options)
    raise TypeError(f"no LAMMPS export for {type(calc).__name__}: write_lammps exports "
                    f"{', '.join(cls.__name__ for cls in SCENES)} (and their subclasses)")


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def _bond_laws(calc, style: str) -> dict:
    """``{type: (law, coefficients by name)}`` of the calculator's bond
    types; a type whose law ``bond_style <style>`` cannot run (its
    ``lammps_style`` is another or None) is refused, naming law and type."""
    laws = {}
    for t, values in calc.model._bond_values.items():
        law = calc.model._laws[calc.model._law_of_type[t]]
        if law.lammps_style != style:
            raise ValueError(f"bond type {t} follows the law {law.name!r}, which "
                             f"bond_style {style} cannot run: no LAMMPS export")
        laws[t] = law, values
    return laws


# -- BPMSpring ------------------------------------------------------------------------

def _spring_bond_style(calc) -> str:
    """The one ``bond_style`` a BPMSpring scene's bond types run under (their
    laws' ``lammps_style``; ``bpm/spring`` without bond types).  A LAMMPS
    scene has one bond style: laws of different styles are refused, naming
    the bond types of each."""
    model = calc.model
    types_of = {}
    for t in sorted(model._bond_values):
        law = model._laws[model._law_of_type[t]]
        # (a law without a LAMMPS style: refused by _bond_laws, under bpm/spring)
        types_of.setdefault(law.lammps_style or SpringBond.lammps_style, []).append(t)
    if len(types_of) > 1:
        listed = "; ".join(f"{style}: bond types {', '.join(map(str, types))}"
                           for style, types in types_of.items())
        raise ValueError(f"a LAMMPS scene has one bond_style, and these bond types need "
                         f"several ({listed}): no LAMMPS export")
    return next(iter(types_of), SpringBond.lammps_style)


def spring_scene(calc, atoms: Atoms, data_file: str, *, units: str | None = None,
                 timestep: float | None = None, thermo: int = 100,
                 broken_bonds_fix: str | bool | None = True) -> LammpsScene:
    """A BPMSpring scene: ``bond_style bpm/spring`` (``volume/factor yes``
    with ``volume_factor``, ``a_v`` closing each ``bond_coeff`` line),
    ``bpm/spring/plastic`` or ``bpm/rotational``, as the bond types' laws have
    it, and ``pair_style bpm/spring`` (``anharmonic yes`` with
    ``anharmonic``) or ``gran/*`` (``granular``) on ``atom_style bond``, or on
    ``bpm/sphere`` where particles turn (``fix nve/bpm/sphere`` for
    bpm/rotational, ``fix nve/sphere`` for granular contacts and walls; the
    orientations as ``set atom <id> quat`` lines, :func:`orientation_lines`).
    ``units`` default ``"lj"``,
    ``timestep`` the calculator's.  ``broken_bonds_fix`` names a
    ``store/local`` fix that records broken bonds every ``thermo`` steps,
    dumped next to the data file (``<stem>.broken``, columns as
    ``atoms.info["broken_bonds"]``, 1-based atom IDs); ``True`` (default):
    ``"broken"`` with ``store_local``, else none; ``False`` or ``None``:
    none; none either for atoms without bonds, whose deck has no
    ``bond_style`` (LAMMPS takes none without bonds to store).  Bond types
    of laws of two styles, or a law without a LAMMPS style, are refused.
    """
    p = calc.parameters
    style = _spring_bond_style(calc)
    laws = _bond_laws(calc, style)
    turning = any(law.turns for law, _ in laws.values())  # (bpm/rotational: orientations)
    bond_coeffs = {t: tuple(values[c] for c in law.coefficients)  # (the law's order)
                   for t, (law, values) in laws.items()}
    volume_t = calc.model._volume_t
    if volume_t is not None:  # (volume/factor: a_v closes each bond_coeff line)
        bond_coeffs = {t: (*values, volume_t[t]) for t, values in bond_coeffs.items()}
    strains = [values[law.breaking_strain] for law, values in laws.values()
               if law.breaking_strain is not None]
    pair_coeffs = calc.model._pair_coeffs  # (i, j) -> the pair_coeff values, checked
    bonds = get_bonds(atoms)
    if broken_bonds_fix is True or not len(bonds[0]):  # (no bonds, none to break)
        broken_bonds_fix = "broken" if p["store_local"] and len(bonds[0]) else None
    granular = calc.model._granular  # (pair_style gran/* beside the bonds, or None)
    spheres = turning or granular is not None or any(
        getattr(fix, "needs_spheres", False) for fix in calc.fixes)
    types_n = particle_types(atoms)
    ntypes = max([int(types_n.max(initial=1))] + [max(k) for k in pair_coeffs])
    nbondtypes = max([1] + list(bond_coeffs))
    at_rc = SpringPair.coefficients.index("r_c")
    rc_p = [values[at_rc] for values in pair_coeffs.values()]
    data = bond_data(atoms, ntypes, nbondtypes, margin=max(rc_p, default=1.0),
                     spheres=spheres, bonds=bonds)
    r_b = bond_lengths(atoms, *bonds[:2])
    check_reference_lengths(atoms)  # LAMMPS takes the lengths now as the reference
    stretch = 1.0 + max(strains, default=0.0)
    skin = calc.contact_skin()
    skin = DEFAULT_SKIN if skin is None else skin
    if granular is not None:
        _refuse_shear_history(calc, atoms)
        r_n = radii(atoms, "LAMMPS export")
        skin = calc.contact_skin(r_n)
        rc_p = [2.0 * float(r_n.max())]
    comm_cut = max(max(rc_p, default=0.0), stretch * r_b.max(initial=0.0)) + skin

    bond_style = f"bond_style {style} " + " ".join(
        f"{keyword} {_yes(p[name])}" for keyword, (name, _) in SPRING_KEYWORDS.items())
    if volume_t is not None:
        bond_style += f" {VOLUME_KEYWORD} yes"
    if broken_bonds_fix:
        bond_style += f" store/local {broken_bonds_fix} {thermo} {' '.join(STORE_LOCAL)}"
    cmds = [*preamble(atoms, units or "lj", "bpm/sphere" if spheres else "bond"),
            "newton on off",
            "special_bonds lj/coul 1 1 1" if p["overlay_pair"]
            else "special_bonds lj 0 1 1 coul 1 1 1",
            f"read_data {data_file}",
            *(sphere_densities(atoms)[1] + orientation_lines(atoms) if spheres else ()),
            f"comm_modify vel yes cutoff {exact(comm_cut)}"]
    if len(bonds[0]):  # (without bonds LAMMPS refuses a BPM bond style: no bond to store)
        cmds.append(bond_style)
        style_law = next((law for law, _ in laws.values()), SpringBond)
        unused = tuple(UNUSED_SPRING_TYPE[c] for c in style_law.coefficients) + (
            () if volume_t is None else (UNUSED_SPRING_TYPE[VOLUME_FACTOR],))
        for t in range(1, nbondtypes + 1):  # (a type no bond has needs values too)
            cmds.append(f"bond_coeff {t} "
                        + " ".join(exact(v) for v in bond_coeffs.get(t, unused)))
    if granular is not None:
        law = granular.law
        cmds += [f"pair_style {law.STYLE_PREFIX}{law.lammps_args()}", "pair_coeff * *"]
    elif pair_coeffs:
        anharmonic = f" {ANHARMONIC_KEYWORD} yes" if p["anharmonic"] else ""
        cmds += [f"pair_style {SpringPair.name}{anharmonic}", f"pair_modify mix {p['mix']}"]
        for (ti, tj), values in sorted(pair_coeffs.items()):
            cmds.append(f"pair_coeff {ti} {tj} " + " ".join(exact(v) for v in values))
    else:
        cmds += [f"pair_style zero {exact(max(stretch * r_b.max(initial=1.0), 1e-300))}",
                 "pair_coeff * *"]
    cmds += neighbour_lists(skin)
    cmds += integrator("nve/bpm/sphere" if turning else "nve/sphere" if spheres else "nve",
                       p["timestep"] if timestep is None else timestep)

    dumps = ()
    if broken_bonds_fix:
        stem = os.path.splitext(data_file)[0]
        dumps = (f"dump {broken_bonds_fix} all local {thermo} {stem}.broken "
                 + " ".join(f"f_{broken_bonds_fix}[{k + 1}]" for k in range(len(STORE_LOCAL))),
                 f"dump_modify {broken_bonds_fix} format float %.17g")
    return LammpsScene(data, tuple(cmds), spheres=spheres, dumps=dumps,
                       thermo=("compute nbond all nbond/atom",
                               "compute tbond all reduce sum c_nbond",
                               "thermo_style custom step ke pe c_tbond"))


# -- BPMPeri --------------------------------------------------------------------------

def peri_scene(calc, atoms: Atoms, data_file: str, *, units: str | None = None,
               timestep: float | None = None, thermo: int = 100,
               spacing: float | None = None, driver_repairs_s0: bool = False) -> LammpsScene:
    """A BPMPeri scene in the styles the calculator follows on the atoms
    (``calc.followed(atoms)``): ``bond_style bpm/peri``
    (:func:`bpm_peri_scene`) or the legacy ``peri/<law>`` pair style
    (:func:`legacy_peri_scene`, which takes ``driver_repairs_s0``)."""
    if units == "lj":  # (there `lattice sc` reads its number as a reduced density)
        raise ValueError("no LAMMPS export of BPMPeri in lj units: PERI takes the "
                         "lattice spacing from 'lattice sc', which lj units read as a "
                         "reduced density; use si (the default), cgs, micro or nano")
    if calc.followed(atoms) != BPM_PERI:
        return legacy_peri_scene(calc, atoms, data_file, units=units, timestep=timestep,
                                 spacing=spacing, driver_repairs_s0=driver_repairs_s0)
    if driver_repairs_s0:
        raise ValueError("driver_repairs_s0 repairs the legacy peri/* styles of the "
                         "reference build: this calculator follows bond_style bpm/peri "
                         "(give follows='legacy' to export legacy PERI)")
    return bpm_peri_scene(calc, atoms, data_file, units=units, timestep=timestep,
                          spacing=spacing)


def _spacing(calc, atoms: Atoms, spacing: float | None, bonds=None) -> float:
    """``spacing``, or the calculator's lattice spacing on the atoms."""
    if spacing is not None:
        return spacing
    bonds = get_bonds(atoms) if bonds is None else bonds
    return calc.model.lattice_spacing(atoms, None, bond_lengths(atoms, *bonds[:2]))


def bpm_peri_scene(calc, atoms: Atoms, data_file: str, *, units: str | None,
                   timestep: float | None, spacing: float | None) -> LammpsScene:
    """``bond_style bpm/peri`` + ``pair_style bpm/peri`` (LAMMPS 2026, not
    in the reference build) on ``atom_style bond``: the intact bonds with
    their types, one mass per particle type, the node volumes in a
    ``Vfrac`` section read into ``fix property/atom d_vfrac``, ``lattice
    sc <spacing>``; the thermo output reports the mean damage.  LAMMPS
    takes the reference lengths at its first run: export a body at its
    reference state.  Its forces are force densities (one volume) on true
    masses, where ase_bpm's are true forces, so the deck runs other
    accelerations in LAMMPS unless the volumes are 1; ``read_lammps`` of it
    gives back this scene.  Fixes act on true masses in both."""
    p = calc.parameters
    laws = _bond_laws(calc, PeriBond.lammps_style)
    if not laws:
        raise ValueError("no LAMMPS export of a BPMPeri without bond_coeffs")
    check_reference_lengths(atoms)  # LAMMPS takes the lengths now as the reference
    bonds = get_bonds(atoms)  # (looked up once: the spacing and the data file)
    spacing = _spacing(calc, atoms, spacing, bonds)
    types_n = particle_types(atoms)
    ntypes = max([int(types_n.max(initial=1))] + [max(k) for k in calc.model._pairs])
    values = {t: named for t, (_, named) in laws.items()}  # type -> coefficients by name
    nbondtypes = max(values)
    at_horizon = PeriContact.coefficients.index("horizon")
    reach = max([v["horizon"] * (1.0 + v["s00"]) for v in values.values()]
                + [pair[at_horizon] for pair in calc.model._pairs.values()])
    skin = p["skin"] or PERI_SKIN * spacing
    data = bond_data(atoms, ntypes, nbondtypes, margin=reach, bonds=bonds,
                     properties={VFRAC_SECTION: calc.model._volumes(atoms)})
    cmds = [*preamble(atoms, units or "si", "bond"), "atom_modify map array",
            "newton on off", "special_bonds lj 0 1 1 coul 1 1 1",
            f"lattice sc {exact(spacing)}",
            f"fix {VFRAC_FIX} all property/atom d_vfrac ghost yes",
            f"read_data {data_file} fix {VFRAC_FIX} NULL {VFRAC_SECTION}",
            f"comm_modify cutoff {exact(reach + skin)}",
            f"bond_style {PeriBond.lammps_style}" + ("" if p["break_bonds"] else " break no")]
    for t in range(1, nbondtypes + 1):  # (a type no bond has needs values too)
        law, named = laws[t if t in laws else min(laws)]
        cmds.append(f"bond_coeff {t} {law.name} "
                    + " ".join(exact(named[c]) for c in law.coefficients))
    if calc.model._pairs:
        cmds.append(f"pair_style {PeriContact.name}")
        cmds += [f"pair_coeff {ti} {tj} " + " ".join(exact(v) for v in pair)
                 for (ti, tj), pair in sorted(calc.model._pairs.items())]
    else:  # (bond_style bpm/peri takes pair_style zero for no contact)
        cmds += [f"pair_style zero {exact(reach)}", "pair_coeff * *"]
    cmds += [*neighbour_lists(skin),
             *integrator("nve", p["timestep"] if timestep is None else timestep)]
    return LammpsScene(data, tuple(cmds), force_per_lammps_force=1.0,
                       thermo=("compute damage all bpm/peri/damage/atom",
                               "compute mean_damage all reduce ave c_damage",
                               "thermo_style custom step ke pe c_mean_damage"))


def legacy_peri_scene(calc, atoms: Atoms, data_file: str, *, units: str | None,
                      timestep: float | None, spacing: float | None,
                      driver_repairs_s0: bool) -> LammpsScene:
    """The legacy ``peri/<law>`` pair style on ``atom_style peri``, the
    peridynamics of the reference build.  Legacy PERI bonds every pair of
    nodes within the horizon by itself and takes the reference at its first
    run: export an unbroken scene.  With ``break_bonds=False`` the deck's
    ``s00`` is :data:`UNREACHABLE_STRETCH` (legacy PERI has no switch).
    ``units`` default ``"si"``, ``timestep`` the calculator's, ``spacing``
    the lattice spacing (default: the calculator's, the one recorded on the
    atoms, or that of the simple cubic positions).  The thermo output reports
    the mean damage.  LAMMPS' ``f`` holds force densities here, so fixes
    need one node volume.

    The reference build's ``peri/lps``, ``peri/ves`` and ``peri/eps`` leave
    the breaking stretch ``s0`` uninitialised at the first setup (their
    forces come before ``fix PERI_NEIGH`` has found the bonds), so bonds may
    break at zero stretch, and no stock command sets ``s0``: those laws are
    refused unless ``driver_repairs_s0`` says that the caller runs the deck
    from Python and repairs it (``run 0``, ``s0`` set to the largest double
    through ``extract_atom``, ``run 0`` again at the reference state, as
    ``tests/peri_oracle.py`` does).
    """
    p = calc.parameters
    head = preamble(atoms, units or "si", "peri")
    law, coeffs = legacy_pair_coeffs(calc, atoms)
    if law.state_based and not driver_repairs_s0:
        raise ValueError(
            f"no LAMMPS export of {law.legacy_style()} as a deck: the reference LAMMPS (22 "
            "Jul 2025) leaves its breaking stretch s0 uninitialised at the first setup, so "
            "bonds may break at zero stretch, and no LAMMPS command sets s0. Run it from "
            "Python instead (write_lammps(..., driver_repairs_s0=True), then run 0, s0 "
            "set to the largest double with extract_atom, run 0), or export pmb")
    check_reference_lengths(atoms)  # legacy PERI takes the lengths now as the reference
    spacing = _spacing(calc, atoms, spacing)
    vol_n = atoms.arrays["vfrac"]
    if calc.fixes and np.any(vol_n != vol_n[0]):
        raise ValueError("legacy PERI fixes act on force densities: exporting them "
                         "needs one node volume")
    cmds = [*head, "atom_modify map array", f"lattice sc {exact(spacing)}",
            f"read_data {data_file}", f"pair_style {law.legacy_style()}",
            "pair_coeff * * " + " ".join(exact(c) for c in coeffs),
            *neighbour_lists(p["skin"] or PERI_SKIN * spacing),
            *integrator("nve", p["timestep"] if timestep is None else timestep)]
    return LammpsScene(peri_data(atoms), tuple(cmds),
                       force_per_lammps_force=float(vol_n[0]),
                       thermo=("compute damage all damage/atom",
                               "compute mean_damage all reduce ave c_damage",
                               "thermo_style custom step ke pe c_mean_damage"))


def legacy_contact_stiffness(law, values: dict) -> float:
    """The stiffness ``k`` of the contact a legacy ``peri/<law>`` style ties
    to its bond law (``values`` by name): the micromodulus ``c`` of pmb,
    ``18 K / (pi horizon^4)`` of the others."""
    if not law.state_based:
        return values["c"]
    return 18.0 * values["K"] / (np.pi * values["horizon"] ** 4)


def legacy_pair_coeffs(calc, atoms: Atoms) -> tuple:
    """``(law, coefficients)``: the scene's single law and its coefficients
    in its legacy ``pair_coeff`` order, checked to be expressible in legacy
    PERI."""
    models = calc.parameters["bond_coeffs"]
    if len(models) != 1:
        raise ValueError("legacy PERI has one model per scene: the calculator has bond "
                         f"types {sorted(models)}")
    btype, = models
    law, values = calc.model._laws[calc.model._law_of_type[btype]], calc.model._bond_values[btype]
    if not getattr(law, "legacy_order", ()):
        raise ValueError(f"bond type {btype} follows the law {law.name!r}, which no legacy "
                         "PERI pair style runs: no LAMMPS export")
    types_n = particle_types(atoms)
    if np.any(types_n != types_n[0]):
        raise ValueError("legacy PERI export supports one particle type")
    table = bond_table(atoms)
    if np.any(table.type_b != btype):
        raise ValueError("legacy PERI bonds every pair within the horizon and breaks them "
                         "itself: the scene has broken bonds or bonds of other types")
    i_p, j_p, _ = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc, values["horizon"])
    want = {(min(a, b), max(a, b)) for a, b in zip(i_p, j_p)}
    have = {(min(a, b), max(a, b)) for a, b in zip(table.owner_b, table.partner_b)}
    if want != have:
        raise ValueError(f"legacy PERI bonds every pair within the horizon: the scene lacks "
                         f"{len(want - have)} of them and has {len(have - want)} beyond it")
    pairs = calc.model._pairs  # (i, j) -> (k, horizon), checked
    legacy_k = legacy_contact_stiffness(law, values)
    if not pairs:  # legacy PERI always has its contact
        raise ValueError(f"legacy PERI always pushes nodes apart at short range: export "
                         f"needs that contact here too, pair_coeffs={{(1, 1): "
                         f"({legacy_k!r}, {values['horizon']!r})}}")
    (_, (k, horizon)), = pairs.items()
    if not (np.isclose(k, legacy_k, rtol=1e-12) and horizon == values["horizon"]):
        raise ValueError(f"legacy PERI ties the contact stiffness to the bond law: "
                         f"pair_coeffs must be (k={legacy_k!r}, horizon="
                         f"{values['horizon']!r})")
    if not calc.parameters["break_bonds"]:  # legacy PERI has no switch
        values = dict(values, s00=UNREACHABLE_STRETCH)
    return law, [values[key] for key in law.legacy_order]


# -- Granular -------------------------------------------------------------------------

def granular_scene(calc, atoms: Atoms, data_file: str, *, units: str | None = None,
                   timestep: float | None = None, thermo: int = 100) -> LammpsScene:
    """A Granular scene: ``pair_style gran/<model>`` on ``atom_style
    sphere`` with ``fix nve/sphere``; ``units`` default ``"lj"``,
    ``timestep`` the calculator's.  The shear history of contacts already
    touching has no place in a data file: a scene that holds some is refused
    (the exported run would start those contacts unsheared)."""
    law = calc.law
    cmds = [*preamble(atoms, units or "lj", "sphere"), f"read_data {data_file}",
            *sphere_densities(atoms)[1], "comm_modify vel yes",
            f"pair_style {law.STYLE_PREFIX}{law.lammps_args()}", "pair_coeff * *",
            *neighbour_lists(calc.contact_skin(radii(atoms))),
            *integrator("nve/sphere",
                        calc.parameters["timestep"] if timestep is None else timestep)]
    _refuse_shear_history(calc, atoms)
    return LammpsScene(sphere_data(atoms), tuple(cmds), spheres=True,
                       thermo=("compute erot all erotate/sphere",
                               "thermo_style custom step ke c_erot pe"))


def _refuse_shear_history(calc, atoms: Atoms) -> None:
    """The shear history of contacts already touching has no place in a data
    file: refuse a scene that holds some (the exported run would start those
    contacts unsheared)."""
    histories = [SHEAR] + [fix.history_array for fix in calc.fixes
                           if hasattr(fix, "history_array")]
    sheared = [name for name in histories
               if name in atoms.arrays and np.any(atoms.arrays[name] != 0.0)]
    if sheared:
        raise ValueError(f"no LAMMPS export of this scene: the shear history in "
                         f"{', '.join(sheared)} has no place in a LAMMPS data file, and "
                         "the exported run would start these contacts unsheared; export "
                         "before contacts form (or delete the arrays to start them "
                         "afresh in ase_bpm too)")


#: the scene of each calculator class: a function ``(calc, atoms, data_file,
#: **options) -> LammpsScene``
SCENES = {BPMSpring: spring_scene, BPMPeri: peri_scene, Granular: granular_scene}
