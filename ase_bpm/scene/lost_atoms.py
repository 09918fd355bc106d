"""Atoms that leave a box through a fixed face are removed, as LAMMPS removes them.

LAMMPS' ``boundary f`` faces do not move, and an atom that crosses one is
lost: ``thermo_modify lost ignore`` lets the run go on without it (the
``examples/bpm`` decks use it), ``lost warn`` says so, and the default,
``lost error``, stops the run.  :class:`LostAtoms` does the same in ase_bpm,
for any integrator (ASE's own too), as a fix the calculator carries:
before the force evaluation of a step, it deletes the atoms outside with
``del atoms[...]``, which takes their bonds along (LAMMPS' ``thermo_modify
lost/bond ignore``, which leaves a bond to a lost atom out of the forces).

When.  LAMMPS finds lost atoms when they migrate between processors: at the
set-up of each run and at each step where it rebuilds its neighbour lists,
after the drift and before the forces.  With the default ``neigh_modify every
1 delay 0 check yes`` it rebuilds at a step where some atom has moved more
than half the neighbour skin since the last rebuild (``every``, ``delay``
and ``check`` as LAMMPS applies them).  An atom is outside when ``x < lo`` or
``x >= hi`` along an axis whose face is fixed.  So an atom that leaves the
box goes at the first rebuild after it left, possibly some steps later, as
measured in the reference build.  Where LAMMPS' box moves (a shrink-wrapped
``s`` or ``m`` face with a periodic axis), its rebuild distance shrinks with
the box's motion, which ase_bpm does not follow: there an atom goes at the
first step it is outside (``rebuilds=False``).
"""

from __future__ import annotations

import warnings

import numpy as np
from ase import Atoms

from ..core.neighbours import moved_more_than
from ..models.base import register_fix
from ..models.evaluation import Contribution

#: what happens to a lost atom, as LAMMPS' ``thermo_modify lost`` and ``lost/bond``
POLICIES = ("error", "warn", "ignore")


class LostAtomsWarning(UserWarning):
    """Atoms left the box and were removed (``lost warn``), or bonds to them
    went with them (``lost/bond warn``)."""


@register_fix
class LostAtoms:
    """Remove atoms that leave the box through its fixed faces (LAMMPS
    ``boundary f`` with ``thermo_modify lost ignore``).

    Parameters: ``lo`` and ``hi``, the box's corners (distance), with ``None``
    for a face that removes nothing (periodic, shrink-wrapped); ``skin``, the
    LAMMPS neighbour skin (distance) and ``every``, ``delay``, ``check``
    (``neigh_modify``; ``once``: no rebuild within a run), which decide at
    which steps LAMMPS finds them;
    ``rebuilds=False`` looks at every step instead; ``lost`` (``"ignore"``:
    remove them, ``"warn"``: remove them with a :class:`LostAtomsWarning`,
    ``"error"``: stop with ValueError, as LAMMPS' default) and ``lost_bonds``
    (the same for a lost atom's intact bonds: ``"error"``, LAMMPS' default,
    stops where one would go); ``periodic``: the periodic axes (for the
    LAMMPS export, which writes the box's faces).

    ASE's Langevin draws its random forces for the atoms it had before the
    evaluation: it cannot go on once atoms are removed mid-step (NumPy's
    shape error); ase_bpm's integrators and ASE's VelocityVerlet can.
    """

    needs_time = False
    needs_spheres = False
    produces_torques = False

    def __init__(self, lo, hi, skin: float = 0.0, every: int = 1, delay: int = 0,
                 check: bool = True, once: bool = False, rebuilds: bool = True,
                 lost: str = "ignore", lost_bonds: str = "ignore",
                 periodic=(False, False, False)):
        self.lo = [None if v is None else float(v) for v in lo]
        self.hi = [None if v is None else float(v) for v in hi]
        self.periodic = [bool(p) for p in periodic]
        if len(self.lo) != 3 or len(self.hi) != 3 or len(self.periodic) != 3:
            raise ValueError(f"LostAtoms: lo, hi and periodic are 3 each, got {lo!r}, {hi!r}, "
                             f"{periodic!r}")
        for axis in range(3):
            if self.periodic[axis] and (self.lo[axis], self.hi[axis]) != (None, None):
                raise ValueError(f"LostAtoms: axis {'xyz'[axis]} is periodic: it has no "
                                 "fixed face")
        for name, policy in (("lost", lost), ("lost_bonds", lost_bonds)):
            if policy not in POLICIES:
                raise ValueError(f"LostAtoms: {name}={policy!r}, expected one of "
                                 f"{', '.join(POLICIES)}")
        if not (skin >= 0 and int(every) >= 1 and int(delay) >= 0):
            raise ValueError(f"LostAtoms: skin {skin!r} >= 0, every {every!r} >= 1 and "
                             f"delay {delay!r} >= 0 expected")
        self.skin, self.every, self.delay = float(skin), int(every), int(delay)
        self.check, self.once, self.rebuilds = bool(check), bool(once), bool(rebuilds)
        self.lost, self.lost_bonds = lost, lost_bonds
        self._held = None  # positions at LAMMPS' last rebuild (its xhold)
        self._ago = 0  # steps since then

    def start_run(self) -> None:
        """A new run starts (LAMMPS' set-up): the next evaluation looks for
        lost atoms whatever they moved."""
        self._held = None

    def lost_atoms(self, atoms: Atoms, stepping: bool) -> np.ndarray:
        """The indices of the atoms to remove before this evaluation (none at
        most steps); ``stepping``: the evaluation is a new step.  Raises
        ValueError, removing nothing, where the policy is ``error``."""
        x_nc = atoms.positions
        if self._held is not None and len(self._held) == len(atoms):
            if not stepping or not self._rebuilds_now(x_nc):
                return np.empty(0, dtype=np.int64)
        # (a run's set-up, the first evaluation, atoms added or taken by hand)
        gone = self.outside(x_nc)
        if len(gone):
            self._police(atoms, gone)
        self._held = np.delete(x_nc, gone, axis=0)
        self._ago = 0
        return gone

    def _rebuilds_now(self, x_nc: np.ndarray) -> bool:
        """LAMMPS' ``Neighbor::decide`` for this step."""
        if not self.rebuilds:
            return True
        self._ago += 1
        if self.once or self._ago < self.delay or self._ago % self.every:
            return False
        if not self.check:
            return True
        return moved_more_than(x_nc, self._held, 0.5 * self.skin)

    def outside(self, x_nc: np.ndarray) -> np.ndarray:
        """Indices of the atoms beyond a fixed face (``x < lo`` or ``x >= hi``)."""
        out_n = np.zeros(len(x_nc), dtype=bool)
        for axis in range(3):
            if self.lo[axis] is not None:
                out_n |= x_nc[:, axis] < self.lo[axis]
            if self.hi[axis] is not None:
                out_n |= x_nc[:, axis] >= self.hi[axis]
        return np.flatnonzero(out_n)

    def _police(self, atoms: Atoms, gone: np.ndarray) -> None:
        """Stop or warn as ``lost`` and ``lost_bonds`` say."""
        from ..core.bonds import get_bonds, stored

        named = ", ".join(str(i) for i in gone[:5]) + (" ..." if len(gone) > 5 else "")
        if self.lost == "error":
            raise ValueError(f"LostAtoms: {len(gone)} atoms left the box through a fixed "
                             f"face (indices {named}): LAMMPS stops here ('Lost atoms', "
                             "thermo_modify lost error); with lost='ignore' (thermo_modify "
                             "lost ignore) they are removed")
        broken_off = 0
        if stored(atoms):
            i_b, j_b, _ = get_bonds(atoms)
            leaving = np.zeros(len(atoms), dtype=bool)
            leaving[gone] = True
            broken_off = int(np.count_nonzero(leaving[i_b] != leaving[j_b]))
        if broken_off and self.lost_bonds == "error":
            raise ValueError(f"LostAtoms: {len(gone)} atoms left the box (indices {named}) "
                             f"with {broken_off} intact bonds to atoms in it: LAMMPS stops "
                             "here ('Bond atoms missing', thermo_modify lost/bond error); "
                             "with lost_bonds='ignore' (thermo_modify lost/bond ignore) the "
                             "bonds go with them")
        if self.lost == "warn" or (broken_off and self.lost_bonds == "warn"):
            warnings.warn(f"LostAtoms: {len(gone)} atoms left the box and are removed "
                          f"(indices {named}), with {broken_off} intact bonds",
                          LostAtomsWarning, stacklevel=2)

    def contribute(self, atoms: Atoms, clock) -> Contribution:
        """No force: the evaluation's own arrays, unchanged."""
        forces, f_damp, torques = clock.into
        return Contribution(forces, added=True)

    def todict(self) -> dict:
        return {"type": "LostAtoms", "lo": self.lo, "hi": self.hi, "skin": self.skin,
                "every": self.every, "delay": self.delay, "check": self.check, "once": self.once,
                "rebuilds": self.rebuilds, "lost": self.lost, "lost_bonds": self.lost_bonds,
                "periodic": self.periodic}

    def lammps_commands(self, index: int, force_per_lammps_force: float = 1.0) -> list[str]:
        """The box's fixed faces where they are (``change_box``; the other
        faces shrink-wrapped, ``m``, as write_lammps writes them, from where
        the data file puts them, :func:`box_bound`) and the
        neighbour settings that decide when LAMMPS finds lost atoms (every
        step where ase_bpm looks at every step, ``rebuilds=False``)."""
        from ..core.lammps_text import exact

        finals, faces = [], []
        for axis, name in enumerate("xyz"):
            lo, hi = self.lo[axis], self.hi[axis]
            if self.periodic[axis]:
                faces.append("p")
                continue
            low, high = ("m" if lo is None else "f"), ("m" if hi is None else "f")
            faces.append(low if low == high else low + high)
            if lo is not None or hi is not None:  # (a face that removes nothing: where it is)
                finals.append(f"{name} final {box_bound(name, 'lo', lo)} "
                              f"{box_bound(name, 'hi', hi)}")
        every, delay, check = ((self.every, self.delay, "yes" if self.check else "no")
                               if self.rebuilds else (1, 0, "no"))
        return [f"change_box all {' '.join(finals)} boundary {' '.join(faces)} units box",
                f"neighbor {exact(self.skin)} bin",
                f"neigh_modify every {every} delay {delay} check {check} once "
                f"{'yes' if self.once and self.rebuilds else 'no'}"]

    def lammps_after_thermo(self) -> list[str]:
        """``thermo_modify lost`` and ``lost/bond`` (after the deck's
        thermo_style, which resets them)."""
        return [f"thermo_modify lost {self.lost} lost/bond {self.lost_bonds}"]

    def __repr__(self) -> str:
        return (f"LostAtoms(lo={self.lo!r}, hi={self.hi!r}, skin={self.skin!r}, "
                f"lost={self.lost!r}, lost_bonds={self.lost_bonds!r})")


def box_bound(axis: str, side: str, value: float | None) -> str:
    """A bound of ``change_box ... <axis> final <lo> <hi>``: ``value``, or
    for a face that removes nothing (None) LAMMPS's immediate ``$(<axis><side>)``,
    the bound where it is (the data file's)."""
    from ..core.lammps_text import exact

    return f"$({axis}{side})" if value is None else exact(value)
