"""Trajectories for looking at: extxyz frames for ``ase gui`` and OVITO.

:class:`ViewerTrajectory` writes, per frame, what a viewer shows: the
positions, elements and cell, the particles' radius and orientation, and
the chosen per-atom outputs (by default the calculator's), with the step
and kinetic energy in the comment line.  It never writes the calculator's state (names
starting ``bpm_``, ``bond_``, ``gran_``, ``peri_``: bonds, contact history,
the record of the last evaluation), so the file stays small and the colour
menus short.  For restarts use :func:`ase_bpm.write_restart`: extxyz keeps 8
decimals only.

The per-atom outputs are by default the calculator's own
(``calc.per_atom_outputs``: ``damage`` and ``nbonds`` for the bonded models,
with ``dilatation`` for state-based PERI, ``ncontacts`` for
:class:`~ase_bpm.Granular`); for atoms without such a calculator (read from a
restart file, in post-processing) those of any model that the atoms carry.  A
name asked for that is neither one of them nor an array on the atoms is
refused, naming it and the valid ones; ``radius`` (always written where there
is one) and, for spheres (atoms with a radius), ``omega`` (zero when absent)
may always be asked for.

A :class:`ViewerTrajectory` is also an ASE dynamics' ``trajectory=``: the
integrator writes a frame every ``loginterval`` steps.

The cell of a frame encloses the particles.  Periodic cells stay as they are.
A non-periodic scene is drawn in its own cell where that encloses every
particle (with the cell's origin, ``atoms.get_celldisp()``), else in a box
around them (their bounding box plus the largest radius), which a trajectory
keeps while it encloses them and grows by a quarter of its length where they
leave it.  The extxyz format has no origin that ``ase gui`` reads (OVITO
reads an ``Origin`` key, ASE's reader drops it), so such a frame's positions
are translated to put the box's corner at zero: the frame's
``info["translation"]`` (distance units) is what was added to every position.

What each viewer makes of the columns:

* ``ase gui`` offers "By user-defined <key>" colouring (View > Colors ...) for
  every per-atom array, e.g. ``damage``; it draws every particle at the size
  of its element and ignores ``radius``.
* Particles with an orientation (``atoms.arrays["quat"]``, LAMMPS's order
  ``(w, i, j, k)``) carry it in every frame as the column ``orientation``
  in OVITO's order ``(X, Y, Z, W)`` = ``(i, j, k, w)``, which OVITO maps to
  its standard property ``Orientation`` (shown by particles of an aspherical
  shape, and read by its modifiers); asked for as ``quat``, it adds nothing.
* OVITO maps a column named ``radius`` to its standard property ``Radius``
  (the particles are drawn at their size), ``velo`` to ``Velocity`` and
  ``omega`` to ``Angular Velocity``, ``stress`` to ``Stress Tensor`` (ASE's
  own extxyz reader hands that column to the frame's calculator, as
  ``frame.calc.results["stress"]``); ``damage``, ``nbonds`` and ``ncontacts``
  stay properties of their own name (Color coding modifier).  A column named
  ``type`` would become its ``Particle Type``, which the element column (ASE's
  ``species``) already gives: OVITO keeps the element, not the type.
"""

from __future__ import annotations

from typing import Sequence

import ase.io  # (ase.io.write looked up when called: works while ase.io is mid-import)
import numpy as np
from ase import Atoms

from ..core.params import did_you_mean
from ..core.spheres import OMEGA, QUAT, RADIUS, angular_velocities, orientations
from ..models.outputs import PER_ATOM_OUTPUTS

#: the calculator's state on the atoms starts with these (bonds, contact
#: history, the record of the last evaluation, PERI's reference state)
STATE_PREFIXES = ("bpm_", "bond_", "gran_", "peri_")
#: state under other names: lammps-data bond strings, the broken-bond log
STATE_NAMES = ("bonds", "broken_bonds")
#: ASE's own per-atom arrays, which every frame carries
ASE_COLUMNS = ("numbers", "positions")
#: per-atom arrays every frame carries anyway (asked for, they add nothing):
#: the radius is :func:`display_radius`, where there is one; the orientation,
#: where there is one, is written as :data:`ORIENTATION`
ALWAYS = (*ASE_COLUMNS, RADIUS, QUAT)
#: OVITO's column name of the particles' orientation in an extxyz file (its
#: standard property Orientation, components X, Y, Z, W: the vector part,
#: then the scalar)
ORIENTATION = "orientation"
#: where each of OVITO's X, Y, Z, W is in a quaternion in LAMMPS's order (w, i, j, k)
OVITO_QUATERNION_ORDER = [1, 2, 3, 0]
#: columns a frame carries on request, not by name in ``arrays``
COLUMNS_ON_REQUEST = {"velo": "velocities=True", "velocities": "velocities=True",
                      "stress": "stress=True"}
#: the key of a frame's info holding what was added to its positions
TRANSLATION = "translation"
#: where particles leave a viewer box, it grows by this share of its length
#: beyond them (a body flying apart moves the frame's origin seldom)
GROWTH = 0.25
#: the margin of a box around point particles without a radius, as a share
#: of their largest extent
POINT_MARGIN = 0.05


def is_state(name: str) -> bool:
    """Is ``name`` (of ``atoms.arrays`` or ``atoms.info``) calculator state,
    which viewing files leave out?"""
    return name.startswith(STATE_PREFIXES) or name in STATE_NAMES


def _refuse_state(names, where: str) -> None:
    for name in names:
        if is_state(name):
            raise ValueError(f"{where}[{name!r}] is calculator state, which viewing files "
                             "leave out; ase_bpm.write_restart keeps the whole state")


def calculator_outputs(atoms: Atoms) -> tuple:
    """The per-atom outputs the atoms' calculator writes
    (``calc.per_atom_outputs``; none without such a calculator)."""
    return tuple(getattr(atoms.calc, "per_atom_outputs", ()))


def default_outputs(atoms: Atoms) -> tuple:
    """The per-atom outputs a frame carries by default: the calculator's
    (:func:`calculator_outputs`); without a calculator that declares some
    (atoms read from a restart file, in post-processing), the outputs of any
    ase_bpm model (``PER_ATOM_OUTPUTS``) that the atoms carry."""
    return calculator_outputs(atoms) or tuple(name for name in PER_ATOM_OUTPUTS
                                              if name in atoms.arrays)


def is_sphere_scene(atoms: Atoms) -> bool:
    """Are the atoms spheres (they carry a radius), whose angular velocity
    ``omega`` is zero when absent?"""
    return RADIUS in atoms.arrays


def written_without_array(atoms: Atoms) -> tuple:
    """Names a frame of ``atoms`` writes without an array of that name on
    them: the ``radius`` (:func:`display_radius`), for spheres ``omega``,
    and :data:`ORIENTATION` where they carry ``quat``."""
    return ((RADIUS, OMEGA) if is_sphere_scene(atoms) else (RADIUS,)) + \
        ((ORIENTATION,) if QUAT in atoms.arrays else ())


def checked_arrays(atoms: Atoms, arrays: Sequence[str] | str | None) -> tuple:
    """The per-atom arrays a frame of ``atoms`` carries: ``arrays`` (one name
    or several), by default :func:`default_outputs`.  A name that is
    calculator state, or is neither one of the calculator's outputs nor an
    array on the atoms nor one of :func:`written_without_array`, is refused
    (ValueError naming it, the nearest valid name and all valid ones)."""
    if arrays is None:
        return default_outputs(atoms)
    outputs = calculator_outputs(atoms)
    arrays = (arrays,) if isinstance(arrays, str) else tuple(arrays)
    _refuse_state(arrays, "atoms.arrays")
    for name in arrays:
        if name not in outputs and name not in atoms.arrays and \
                name not in written_without_array(atoms):
            carried = [key for key in atoms.arrays
                       if key not in outputs and key not in ASE_COLUMNS and not is_state(key)]
            calc = type(atoms.calc).__name__
            made = (f"{calc} writes {', '.join(outputs)}" if outputs
                    else "the atoms have no calculator" if atoms.calc is None
                    else f"{calc} declares no per-atom outputs")
            flag = COLUMNS_ON_REQUEST.get(name)
            hint = (f" (ask with {flag})" if flag
                    else did_you_mean(name, [*outputs, *carried]))
            raise ValueError(f"arrays: no per-atom array {name!r}{hint}; {made}, and the "
                             f"atoms carry {', '.join(carried) or 'no other'}")
    return arrays


def display_radius(atoms: Atoms) -> np.ndarray | None:
    """The radius to draw each particle at (distance units): the spheres'
    ``radius``; for point particles with bonds, half their shortest reference
    bond length (half the lattice spacing of a lattice), the same for all;
    None without either (a viewer then draws the element's size)."""
    if "radius" in atoms.arrays:
        return atoms.arrays["radius"]
    r0 = atoms.arrays.get("bond_r0")
    if r0 is None:
        return None
    r0 = r0[np.isfinite(r0) & (r0 > 0)]  # (NaN or ASE's 0: no reference length yet)
    if not r0.size:
        return None
    return np.full(len(atoms), 0.5 * float(r0.min()))


def encloses(box: tuple, x_nc: np.ndarray) -> bool:
    """Does ``box``, ``(origin_c, cell_cc)``, hold every position of
    ``x_nc`` (on its faces counts)?  A singular cell holds none."""
    origin_c, cell_cc = box
    if np.linalg.det(cell_cc) == 0:
        return False
    s_cn = np.linalg.solve(np.transpose(cell_cc), np.transpose(x_nc - origin_c))
    return bool(np.all((s_cn >= 0) & (s_cn <= 1)))


def viewer_box(atoms: Atoms, last: tuple | None = None) -> tuple:
    """The box ``(origin_c, cell_cc)`` (distance units) a frame of ``atoms``
    is drawn in, the origin in the atoms' coordinates.  A periodic cell as it
    is (origin zero).  Otherwise ``last`` (the box of the trajectory's last
    frame) or the atoms' own cell from ``atoms.get_celldisp()``, the first of
    them that holds every particle's centre; else an axis-aligned box around
    them: without ``last`` their bounding box plus a margin (the largest
    :func:`display_radius`; without radii ``POINT_MARGIN`` of their largest
    extent, or 1 if they all sit at one point), else ``last`` grown where
    they left it, to the margin and ``GROWTH`` of its length beyond them."""
    cell_cc = atoms.cell.array.copy()
    if atoms.pbc.any() or not len(atoms):
        return np.zeros(3), cell_cc
    x_nc = atoms.positions
    own = (atoms.get_celldisp().reshape(3).copy(), cell_cc)
    for box in (last, own):
        if box is not None and encloses(box, x_nc):
            return box
    radius = display_radius(atoms)
    extent = float(np.ptp(x_nc, axis=0).max())
    margin = (float(np.max(radius)) if radius is not None
              else POINT_MARGIN * extent or 1.0)
    lo_c, hi_c = x_nc.min(axis=0), x_nc.max(axis=0)
    if last is None or np.count_nonzero(last[1] - np.diag(np.diag(last[1]))):
        return lo_c - margin, np.diag(hi_c - lo_c + 2 * margin)
    low_c, high_c = last[0], last[0] + np.diag(last[1])
    room_c = margin + GROWTH * (high_c - low_c)
    lo_c = np.where(lo_c < low_c, lo_c - room_c, low_c)
    hi_c = np.where(hi_c > high_c, hi_c + room_c, high_c)
    return lo_c, np.diag(hi_c - lo_c)


def viewing_copy(atoms: Atoms, arrays: Sequence[str] | str | None = None,
                 info: dict | None = None, velocities: bool = False, stress: bool = False,
                 box: tuple | None = None) -> Atoms:
    """What a viewer shows of ``atoms``: positions, elements, the
    :func:`display_radius` as ``radius``, the orientation (where the atoms
    carry ``quat``) as :data:`ORIENTATION`, the per-atom ``arrays`` (by default
    :func:`default_outputs`; see :func:`checked_arrays`: those present, and
    a sphere's ``omega``, zero when absent), with
    ``velocities`` their velocities as ``velo`` (distance/time), with
    ``stress`` the per-atom stress of the calculator's analysis
    (``calc.analyse``: LAMMPS ``compute stress/atom``, six columns ``xx yy zz
    xy xz yz`` in pressure times volume), and ``info``.  The cell is ``box``
    (``(origin_c, cell_cc)``, :func:`viewer_box` by default), the positions
    translated by ``-origin_c`` (recorded as ``info["translation"]`` where not
    zero).  Calculator state is refused (ValueError naming it)."""
    arrays = checked_arrays(atoms, arrays)
    _refuse_state(info or {}, "info")
    origin_c, cell_cc = viewer_box(atoms) if box is None else box
    translated = bool(np.any(origin_c != 0))
    view = Atoms(numbers=atoms.numbers, positions=atoms.positions - origin_c, cell=cell_cc,
                 pbc=atoms.pbc, celldisp=None if translated else atoms.get_celldisp())
    radius = display_radius(atoms)
    if radius is not None:
        view.arrays["radius"] = np.array(radius, dtype=float)
    if QUAT in atoms.arrays:
        view.arrays[ORIENTATION] = orientations(atoms)[:, OVITO_QUATERNION_ORDER]
    for name in arrays:
        if name == OMEGA and is_sphere_scene(atoms):
            view.arrays[OMEGA] = np.array(angular_velocities(atoms))  # zero when absent
        elif name in atoms.arrays and name not in ALWAYS:
            view.arrays[name] = atoms.arrays[name].copy()
    if velocities:
        view.arrays["velo"] = atoms.get_velocities()
    if stress:
        analyse = getattr(atoms.calc, "analyse", None)
        if analyse is None:
            raise ValueError(f"stress=True needs a calculator with analyse(), not "
                             f"{type(atoms.calc).__name__}")
        view.arrays["stress"] = analyse(atoms).stress_n6
    view.info.update(info or {})
    if translated:
        view.info[TRANSLATION] = -origin_c
    return view


class ViewerTrajectory:
    """Append frames of ``atoms`` to an extxyz file, e.g. as an MD observer::

        traj = ViewerTrajectory("run.extxyz", atoms)
        dyn.attach(traj, interval=100)

    Each frame carries the particles' radius and orientation (OVITO's
    ``orientation`` column, where the atoms carry ``quat``), the per-atom
    ``arrays`` (colour
    by them in ``ase gui`` or OVITO; by default the calculator's outputs,
    ``calc.per_atom_outputs``, as the calculator of each frame has them), with
    ``velocities=True`` the velocities (column ``velo``), with ``stress=True``
    the per-atom stress (column ``stress``, from ``calc.analyse``), and, in
    its comment line, the step and kinetic energy (see :func:`viewing_copy`).
    The frames of a non-periodic scene share one box while it holds the
    particles (:func:`viewer_box`).  A name in ``arrays`` that is neither an
    output of the calculator nor an array on the atoms is refused here
    (ValueError naming it and the valid ones), and again at a frame.

    It is also an ASE dynamics' ``trajectory=`` (ASE's or ase_bpm's
    integrators, optimisers): a frame every ``loginterval`` steps::

        dyn = ase_bpm.VelocityVerlet(atoms, dt, trajectory=ViewerTrajectory("run.extxyz", atoms))

    The dynamics' description (its type and timestep) is kept as
    ``description``, not written: a viewer has no use for it.
    """

    def __init__(self, filename: str, atoms: Atoms, arrays: Sequence[str] | str | None = None,
                 mode: str = "w", velocities: bool = False, stress: bool = False):
        self.arrays = None if arrays is None else checked_arrays(atoms, arrays)
        self.atoms = atoms
        self.velocities = bool(velocities)
        self.stress = bool(stress)
        self.box = None  # (origin_c, cell_cc) of the last frame
        self.description = {}  # what an ASE dynamics says of itself (set_description)
        self._file = open(filename, mode)
        self.frames = 0

    def write(self, atoms=None, **info) -> None:
        """Write the current state as one frame, with ``info`` in its header:
        of the trajectory's atoms, or of ``atoms`` (Atoms, or what an ASE
        dynamics passes: anything with ``iterimages()``, a frame per image)."""
        images = ([self.atoms] if atoms is None
                  else atoms.iterimages() if hasattr(atoms, "iterimages") else [atoms])
        for image in images:
            frame_info = {"step": int(image.info.get("bpm_step", 0)),
                          "kinetic_energy": float(image.get_kinetic_energy()), **info}
            self.box = viewer_box(image, self.box)
            ase.io.write(self._file, viewing_copy(image, self.arrays, frame_info,
                                                  self.velocities, self.stress, self.box),
                         format="extxyz")
            self._file.flush()
            self.frames += 1

    __call__ = write

    def set_description(self, description: dict) -> None:
        """Keep what an ASE dynamics given this as ``trajectory=`` says of
        itself (ASE's ``Trajectory.set_description``)."""
        self.description.update(description)

    def __len__(self) -> int:
        """The frames written (ASE's optimisers ask before their first)."""
        return self.frames

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
