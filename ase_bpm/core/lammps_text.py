"""LAMMPS text that every model's export shares.

Numbers written so that they read back bit for bit (:func:`exact`), the box
of a data file (:func:`box`), the commands every deck starts with
(:func:`preamble`, for the unit systems ase_bpm can hand over,
:data:`CONSISTENT_UNITS`), the neighbour lists and the integrator, the data
files of the atom styles ase_bpm exports to (:func:`bond_data`,
:func:`peri_data`, :func:`sphere_data`) and the orientations that bpm/sphere
data files lack (:func:`orientation_lines`), and :class:`LammpsScene`, what a
model's export (:mod:`ase_bpm.scene.lammps_export`) returns.  The deck around
it (fixes, ``FixAtoms``, output, run) is assembled by :mod:`ase_bpm.scene.lammps`.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
from ase import Atoms
from ase.data import chemical_symbols

from .arrays import particle_types, velocities
from .bonds import R0, bond_table, get_bonds
from .neighbours import minimum_image
from .quaternions import IDENTITY, normalised
from .spheres import QUAT, angular_velocities, orientations, radii
from .text_columns import write_rows

#: LAMMPS unit systems in which ase_bpm's numbers (it converts none) carry over
CONSISTENT_UNITS = ("lj", "si", "cgs", "micro", "nano")
#: neighbour skin of a deck without contacts (LAMMPS' default in lj units)
DEFAULT_SKIN = 0.3
DATA_TITLE = "LAMMPS data file written by ase_bpm"
BONDS_PER_CHUNK = 1 << 18  # bond vectors computed at a time (bond_lengths)


@dataclass(frozen=True)
class LammpsScene:
    """A calculator's scene in LAMMPS, as ``scene.lammps_export.lammps_scene`` gives it.

    ``data``: the data file, as text or as a :class:`DataText` (written in
    bulk: :func:`write_data` writes either).  ``commands``: units to the
    integrator and timestep, reading the data file.  The exporter follows
    them with the commands of the calculator's fixes (each fix's own
    ``lammps_commands``, given ``force_per_lammps_force``: what a true force
    is in LAMMPS' ``f``, the node volume for legacy PERI whose ``f`` holds
    force densities) and with ``FixAtoms`` as ``fix freeze`` (``spheres``:
    finite-size particles) or ``fix setforce``; then ``thermo`` (computes and
    ``thermo_style``), ``thermo N``, ``dumps`` and the run.  What the LAMMPS
    files cannot carry is refused (ValueError naming it) by the export,
    never written as a deck that runs other physics.
    """

    data: str | DataText
    commands: tuple[str, ...]
    thermo: tuple[str, ...] = ()
    dumps: tuple[str, ...] = ()
    spheres: bool = False
    force_per_lammps_force: float = 1.0


def exact(x: float) -> str:
    """A float written so that it reads back bit for bit."""
    return repr(float(x))


def preamble(atoms: Atoms, units: str, atom_style: str) -> list[str]:
    """``units``, ``dimension``, ``boundary`` (from the atoms' pbc) and
    ``atom_style``: the first commands of every deck."""
    if units not in CONSISTENT_UNITS:
        raise ValueError(f"units must be one of {CONSISTENT_UNITS} (ase_bpm converts "
                         f"no units), got {units!r}")
    _, boundary = box(atoms, margin=1.0)
    return [f"units {units}", "dimension 3", f"boundary {boundary}", f"atom_style {atom_style}"]


def neighbour_lists(skin: float) -> list[str]:
    """A Verlet skin, the lists checked at every step (as ase_bpm's)."""
    return [f"neighbor {exact(skin)} bin", "neigh_modify every 1 delay 0 check yes"]


def integrator(style: str, timestep: float | None) -> list[str]:
    """``fix integrate all <style>`` and the timestep (when known)."""
    return [f"fix integrate all {style}"] + ([] if timestep is None
                                              else [f"timestep {exact(timestep)}"])


def check_reference_lengths(atoms: Atoms, rtol: float = 1e-12) -> None:
    """Refuse a body whose intact bonds are not at their reference length
    (``bond_r0``, where known): a LAMMPS data file has no place for it, and
    LAMMPS takes the lengths at its first run as the reference."""
    r0 = atoms.arrays.get(R0)
    if r0 is None:
        return
    table = bond_table(atoms)
    live = np.flatnonzero(table.type_b > 0)
    owner_b, partner_b = table.owner_b[live], table.partner_b[live]
    r0_b = r0[owner_b, table.slot_b[live]]
    r_b = bond_lengths(atoms, owner_b, partner_b)
    off = np.flatnonzero((r0_b > 0) & (np.abs(r_b - r0_b) > rtol * r0_b))
    if len(off):
        b = off[np.argmax(np.abs(r_b - r0_b)[off] / r0_b[off])]
        raise ValueError(
            f"no LAMMPS export of this body: {len(off)} bonds are not at their reference "
            f"length (bond {owner_b[b]}-{partner_b[b]}: {float(r_b[b])!r} against r0 "
            f"{float(r0_b[b])!r}); "
            "a LAMMPS data file has no place for reference lengths, and LAMMPS would take "
            "the lengths at its first run instead. Export the body at its reference state")


def bond_lengths(atoms: Atoms, i_b, j_b) -> np.ndarray:
    """The lengths of bonds ``i_b``-``j_b`` (minimum image), computed a chunk
    of bonds at a time: the vectors of millions of bonds are not held at once."""
    r_b = np.empty(len(i_b))
    for start in range(0, len(i_b), BONDS_PER_CHUNK):
        part = slice(start, start + BONDS_PER_CHUNK)
        r_bc = minimum_image(atoms.positions[j_b[part]] - atoms.positions[i_b[part]],
                             atoms.cell, atoms.pbc)
        r_b[part] = np.sqrt(np.einsum("bc,bc->b", r_bc, r_bc))
    return r_b


def box(atoms: Atoms, margin: float):
    """LAMMPS box lines and boundary string for the atoms' cell and pbc;
    non-periodic directions span the positions plus ``margin``."""
    pbc, cell = atoms.pbc, np.asarray(atoms.cell)
    if pbc.any():
        off_diagonal = cell[np.triu_indices(3, 1)]
        if np.any(off_diagonal != 0):
            raise ValueError(
                "LAMMPS needs a cell with a along x and b in the xy plane "
                "(lower-triangular cell matrix); rotate the atoms first")
        if not pbc.all() and np.any(cell[np.tril_indices(3, -1)] != 0):
            raise ValueError("a triclinic cell must be periodic in all directions")
    lo, hi = np.zeros(3), np.diag(cell).astype(float).copy()
    pos = atoms.positions
    for k in range(3):
        if not pbc[k]:
            lo[k], hi[k] = pos[:, k].min() - margin, pos[:, k].max() + margin
    lines = [f"{exact(lo[k])} {exact(hi[k])} {a}lo {a}hi" for k, a in enumerate("xyz")]
    if pbc.all() and np.any(cell[np.tril_indices(3, -1)] != 0):
        lines.append(f"{exact(cell[1, 0])} {exact(cell[2, 0])} {exact(cell[2, 1])} xy xz yz")
    boundary = " ".join("p" if p else "m" for p in pbc)
    return lines, boundary


def sphere_densities(atoms: Atoms, who: str = "LAMMPS export"):
    """Densities for LAMMPS' sphere styles that give back ase_bpm's masses.

    LAMMPS reads a diameter and a density and computes the mass as
    ``density * (4 pi / 3 * r * r * r)``.  The density written is the double
    for which that product is the mass bit for bit, where one exists (about
    nine particles in ten); for the others ``set atom <id> mass <m>`` lines
    (returned as the second value) restore the exact mass after reading.
    """
    r_n = radii(atoms, who)
    m_n = atoms.get_masses()
    volume_n = 4.0 * np.pi / 3.0 * r_n * r_n * r_n  # in LAMMPS' order of operations
    density_n = exact_ratios(m_n, volume_n)
    fix_mass = [f"set atom {n + 1} mass {exact(m_n[n])}"
                for n in np.flatnonzero(density_n * volume_n != m_n)]
    return density_n, fix_mass


# -- orientations: LAMMPS's set ... quat -----------------------------------------------
#
# A data file of atom_style bpm/sphere holds no orientation: LAMMPS's read_data
# sets every quaternion to the identity, and its write_data writes none (checked
# in the reference build).  Orientations reach LAMMPS through ``set atom <id>
# quat a b c theta`` (a turn by theta degrees about the axis (a, b, c)), whose
# arithmetic in degrees gives them back within a few units in the last place.

def set_quat_quaternions(axis_nc, theta_n) -> np.ndarray:
    """The unit quaternions ``(w, i, j, k)`` (N x 4) that LAMMPS's ``set ...
    quat a b c theta`` gives: a turn by ``theta_n`` degrees about the axes
    ``axis_nc`` (N x 3), in the reference build's order of operations
    (half angle ``(pi/2 theta)/180``; ``(cos, a sin, b sin, c sin)`` times
    the inverse of its norm), which gives its quaternions bit for bit."""
    axis_nc = np.asarray(axis_nc, dtype=float).reshape(-1, 3)
    half_n = np.pi / 2 * np.asarray(theta_n, dtype=float).reshape(-1) / 180.0
    sin_n = np.sin(half_n)
    return normalised(np.column_stack([np.cos(half_n), axis_nc * sin_n[:, None]]))


def orientation_lines(atoms: Atoms) -> list[str]:
    """``set atom <id> quat a b c theta`` for each particle whose orientation
    (``atoms.arrays["quat"]``, checked) is not the identity, which a
    bpm/sphere data file leaves it: the unit axis and the angle in degrees
    (LAMMPS gets each quaternion back within a few units in the last place,
    :func:`set_quat_quaternions`)."""
    if QUAT not in atoms.arrays:
        return []
    q_nq = orientations(atoms)
    turned = np.flatnonzero(np.any(q_nq != IDENTITY, axis=1))
    v_nc = q_nq[turned, 1:]
    sin_n = np.sqrt(np.einsum("nc,nc->n", v_nc, v_nc))
    axis_nc = v_nc / np.where(sin_n > 0, sin_n, 1.0)[:, None]
    axis_nc[sin_n == 0] = (0.0, 0.0, 1.0)  # ((-1, 0, 0, 0): 360 degrees about any axis)
    theta_n = np.degrees(2.0 * np.arctan2(sin_n, q_nq[turned, 0]))
    return [f"set atom {n + 1} quat {exact(a)} {exact(b)} {exact(c)} {exact(theta)}"
            for n, (a, b, c), theta in zip(turned, axis_nc, theta_n)]


def exact_ratios(m_n: np.ndarray, volume_n: np.ndarray) -> np.ndarray:
    """``m / volume``, moved to a neighbouring double where that one times
    ``volume`` gives back ``m`` bit for bit (about nine in ten have one)."""
    density_n = m_n / volume_n
    exact_n = density_n * volume_n == m_n
    for direction in (np.inf, -np.inf):  # the neighbouring doubles
        for _ in range(2):
            trial_n = np.nextafter(density_n, direction)
            hit = ~exact_n & (trial_n * volume_n == m_n)
            density_n = np.where(hit, trial_n, density_n)
            exact_n |= hit
    return density_n


# -- data files ----------------------------------------------------------------------

@dataclass(frozen=True)
class Rows:
    """Rows of a data-file section given as columns, written in bulk
    (:func:`ase_bpm.core.text_columns.write_rows`): each column a string (the
    same in every row), a ``range`` (atom IDs), or an array of ``count``
    floats, integers or strings."""

    columns: tuple
    count: int


@dataclass(frozen=True)
class DataText:
    """A LAMMPS data file, written in bulk and never held whole as text:
    ``header`` lines (title, counts, box), then ``sections``, each a title and
    its rows (a list of lines, or :class:`Rows`).  ``str()`` gives the text."""

    header: tuple
    sections: tuple = ()

    def write(self, fh) -> None:
        """Write the file to ``fh``, opened in binary mode."""
        fh.write(_text(self.header).encode())
        for title, rows in self.sections:
            fh.write(f"\n{title}\n\n".encode())
            if isinstance(rows, Rows):
                write_rows(fh, rows.columns, rows.count)
            elif rows:
                fh.write(_text(rows).encode())

    def __str__(self) -> str:
        text = io.BytesIO()
        self.write(text)
        return text.getvalue().decode()


def write_data(fh, data) -> None:
    """Write a scene's data file (``LammpsScene.data``: text or a
    :class:`DataText`) to ``fh``, opened in binary mode."""
    if isinstance(data, str):
        fh.write(data.encode())
    else:
        data.write(fh)


def _text(lines) -> str:
    return "\n".join(lines) + "\n"


def _ids(atoms: Atoms) -> range:
    return range(1, len(atoms) + 1)


def _symbols(atoms: Atoms) -> tuple:
    """The columns ``# <symbol>`` that end an atom's line."""
    return "#", np.array(chemical_symbols, dtype=np.bytes_)[atoms.numbers]


def _velocities(atoms: Atoms, extra_nc=None) -> Rows:
    """``id vx vy vz`` (held atoms at rest), then the columns of ``extra_nc``."""
    v_nc = velocities(atoms)
    if extra_nc is not None:
        v_nc = np.hstack([v_nc, extra_nc])
    return Rows((_ids(atoms), *v_nc.T), len(atoms))


def _sphere_sections(atoms: Atoms, types_n, molecule: bool, who: str) -> tuple:
    """``Atoms`` (``[mol-ID] type diameter density x y z``) and ``Velocities``
    (with angular velocities) of a sphere style."""
    r_n = radii(atoms, who)
    density_n, _ = sphere_densities(atoms, who)
    mol = ("0",) if molecule else ()
    rows = Rows((_ids(atoms), *mol, types_n, 2.0 * r_n, density_n, *atoms.positions.T,
                 *_symbols(atoms)), len(atoms))
    return ((f"Atoms # {'bpm/sphere' if molecule else 'sphere'}", rows),
            ("Velocities", _velocities(atoms, angular_velocities(atoms))))


def _masses_per_type(atoms: Atoms, types_n, ntypes: int) -> dict:
    masses = atoms.get_masses()
    per_type = {}
    for t in range(1, ntypes + 1):
        m = masses[types_n == t]
        if len(m) and np.any(m != m[0]):
            raise ValueError(f"LAMMPS atom_style bond has one mass per type: particle "
                             f"type {t} has masses from {m.min()} to {m.max()}")
        per_type[t] = m[0] if len(m) else 1.0
    return per_type


def bond_data(atoms: Atoms, ntypes: int, nbondtypes: int, margin: float,
              spheres: bool = False, bonds=None,
              properties: dict | None = None) -> DataText:
    """A data file with the intact bonds: ``atom_style bond`` (one mass per
    type), or ``bpm/sphere`` (diameter and density per particle, angular
    velocities) with ``spheres``.  ``bonds``: the intact bonds ``(i_b, j_b,
    type_b)`` when the caller has them (:func:`get_bonds`).  ``properties``:
    ``{section: values_n}``, per-atom values of a ``fix property/atom`` in a
    section of their own (``id value``), which ``read_data <file> fix <id>
    NULL <section>`` reads."""
    types_n = particle_types(atoms)
    i_b, j_b, t_b = get_bonds(atoms) if bonds is None else bonds
    box_lines, _ = box(atoms, margin)
    header = (DATA_TITLE, "", f"{len(atoms)} atoms", f"{ntypes} atom types",
              f"{len(i_b)} bonds", f"{nbondtypes} bond types", "", *box_lines)
    if spheres:
        sections = _sphere_sections(atoms, types_n, molecule=True,
                                    who="LAMMPS export of granular walls")
    else:
        masses = _masses_per_type(atoms, types_n, ntypes)
        sections = (("Masses", [f"{t} {exact(m)}" for t, m in masses.items()]),
                    ("Atoms # bond", Rows((_ids(atoms), "0", types_n, *atoms.positions.T,
                                           *_symbols(atoms)), len(atoms))),
                    ("Velocities", _velocities(atoms)))
    if len(i_b):
        sections += (("Bonds", Rows((range(1, len(i_b) + 1), t_b, i_b + 1, j_b + 1),
                                    len(i_b))),)
    for title, values_n in (properties or {}).items():
        sections += ((title, Rows((_ids(atoms), np.asarray(values_n, float)), len(atoms))),)
    return DataText(header, sections)


def peri_data(atoms: Atoms) -> DataText:
    """A LAMMPS data file (``atom_style peri``: volume and density per node;
    the density is the double that gives back the mass bit for bit where one
    exists, as in :func:`sphere_densities`)."""
    types_n = particle_types(atoms)
    vol_n = atoms.arrays["vfrac"]
    density_n = exact_ratios(atoms.get_masses(), vol_n)
    box_lines, _ = box(atoms, margin=10 * float(np.max(vol_n)) ** (1 / 3))
    header = (f"{DATA_TITLE} (peridynamics)", "", f"{len(atoms)} atoms",
              f"{int(types_n.max())} atom types", "", *box_lines)
    return DataText(header, (
        ("Atoms # peri", Rows((_ids(atoms), types_n, vol_n, density_n, *atoms.positions.T,
                               *_symbols(atoms)), len(atoms))),
        ("Velocities", _velocities(atoms))))


def sphere_data(atoms: Atoms) -> DataText:
    """A LAMMPS data file (``atom_style sphere``: diameter and density per
    particle, velocities with angular velocities)."""
    types_n = particle_types(atoms)
    box_lines, _ = box(atoms, margin=2.0 * float(radii(atoms, "LAMMPS export").max(initial=1.0)))
    header = (f"{DATA_TITLE} (granular)", "", f"{len(atoms)} atoms",
              f"{int(types_n.max(initial=1))} atom types", "", *box_lines)
    return DataText(header, _sphere_sections(atoms, types_n, molecule=False,
                                             who="LAMMPS export"))
