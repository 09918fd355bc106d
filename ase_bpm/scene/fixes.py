"""External force pieces that compose with any ase_bpm calculator.

LAMMPS equivalents: ``fix indent`` (:class:`SphericalIndenter`), ``fix
gravity`` (:class:`Gravity`) and ``fix wall/gran`` (:class:`GranularWall`).
Pass them to a calculator, ``BPMSpring(..., fixes=[Gravity(9.81),
GranularWall(...)])``; the calculator evaluates them with the same
configuration and step as its own forces, so they work with any ASE
integrator, restart and cache like the rest.  A piece that moves with time
gets ``time = step * timestep`` (LAMMPS' ``step*dt``).

A piece provides ``todict()`` and either ``forces(atoms, time) -> (f_nc,
energy)`` or, when it needs more (torques, per-atom state, the step),
``contribute(atoms, clock) -> Contribution``; such a piece may add its
forces (damping forces, torques) into the evaluation's own arrays,
``clock.into``, and return them with ``added=True`` rather than new arrays
to be added (the walls do).  Pieces that follow the clock
say so with ``needs_time = True``, pieces whose history advances by the
timestep in each step with ``needs_timestep = True``.  A piece that
contributes and never returns torques says so with ``produces_torques =
False`` (one without the attribute is taken to turn the spheres).
A piece that pushes particles may also offer ``springs(atoms, clock) ->
Springs`` (:mod:`ase_bpm.laws.timestep`): what it acts with as springs and
dampers against a fixed partner, for the calculators' ``stable_timestep``.

A piece that LAMMPS can run too writes its own commands:
``lammps_commands(index, force_per_lammps_force) -> list[str]`` (``index``:
its place among the calculator's fixes, for unique LAMMPS IDs;
``force_per_lammps_force``: what a true force is in LAMMPS' ``f``, 1 but for
legacy PERI, whose ``f`` holds force densities).  It raises ``ValueError``
for what LAMMPS cannot reproduce.  Lines that must follow the deck's
``thermo_style`` (which resets ``thermo_modify``) come from
``lammps_after_thermo() -> list[str]`` (:class:`ase_bpm.LostAtoms`).  A piece that treats particles as
finite-size spheres (radius, angular velocity, torque) says so with
``needs_spheres = True``: the export then uses sphere atom styles.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms

from ..core.arrays import Inputs, dot_sum
from ..models.base import register_fix, state_taken  # noqa: F401 (the protocol of a fix)
from ..models.evaluation import Clock, Contribution  # noqa: F401 (the protocol of a fix)
from ..core.lammps_text import exact
from ..core.params import check_keywords, keyword_names
from ..laws import HoldsKernels
from ..laws.granular import CentredOnWall
from ..laws.timestep import Springs


class SphericalIndenter:
    """A rigid sphere pushing particles out: LAMMPS ``fix indent K sphere``.

    A particle at distance ``r < R`` from the centre feels ``K (R - r)^2``
    outwards (energy ``K (R - r)^3 / 3``).  The centre moves with constant
    ``velocity``: ``centre(t) = centre + velocity * t``, as the LAMMPS example
    ``variable y equal "v_y0 + step*dt*v_vy"``.

    Parameters: ``k`` (force/distance^2), ``radius`` (distance), ``centre``
    (distance, at time 0), ``velocity`` (distance/time).
    """

    needs_time = True
    needs_spheres = False
    produces_torques = False

    def __init__(self, k: float, radius: float, centre, velocity=(0.0, 0.0, 0.0), **unknown):
        check_keywords("SphericalIndenter", unknown, keyword_names(SphericalIndenter.__init__))
        if not k > 0:
            raise ValueError(f"indenter stiffness k must be positive, got {k!r}")
        if not radius > 0:
            raise ValueError(f"indenter radius must be positive, got {radius!r}")
        self.k, self.radius = float(k), float(radius)
        self.centre = np.asarray(centre, dtype=float).reshape(3)
        self.velocity = np.asarray(velocity, dtype=float).reshape(3)
        if not (np.isfinite(self.centre).all() and np.isfinite(self.velocity).all()):
            raise ValueError("indenter centre and velocity must be finite")

    def centre_at(self, time: float) -> np.ndarray:
        return self.centre + self.velocity * time

    def forces(self, atoms: Atoms, time: float):
        d_nc = atoms.positions - self.centre_at(time)
        r_n = np.sqrt(np.einsum("nc,nc->n", d_nc, d_nc))
        inside = r_n < self.radius
        f_nc = np.zeros_like(d_nc)
        if not inside.any():
            return f_nc, 0.0
        depth = self.radius - r_n[inside]
        rinv = np.divide(1.0, r_n[inside], out=np.zeros_like(depth), where=r_n[inside] > 0)
        f_nc[inside] = d_nc[inside] * (self.k * depth * depth * rinv)[:, None]
        return f_nc, float(np.sum(self.k * depth ** 3 / 3.0))

    def springs(self, atoms: Atoms, clock) -> Springs:
        """The particles inside as springs against a fixed partner, for
        ``calc.stable_timestep``: ``2 K (R - r)``, the tangent of the force,
        along the radius (the force softens sideways)."""
        d_nc = atoms.positions - self.centre_at(clock.time)
        r_n = np.sqrt(np.einsum("nc,nc->n", d_nc, d_nc))
        (atom_p,) = np.nonzero((r_n < self.radius) & (r_n > 0))
        return Springs(atom_p, None, d_nc[atom_p] / r_n[atom_p, None],
                       2.0 * self.k * (self.radius - r_n[atom_p]))

    def lammps_commands(self, index: int, force_per_lammps_force: float = 1.0) -> list[str]:
        """``fix indent ... sphere`` whose centre moves as ``centre +
        step*dt*velocity`` (an ``equal`` variable per axis)."""
        names = [f"ase_bpm_indent{index}_{axis}" for axis in "xyz"]
        moving = [f'variable {name} equal "{exact(x)} + step*dt*{exact(v)}"'
                  for name, x, v in zip(names, self.centre, self.velocity)]
        return moving + [f"fix ase_bpm_indent{index} all indent "
                         f"{exact(self.k / force_per_lammps_force)} sphere "
                         + " ".join(f"v_{name}" for name in names)
                         + f" {exact(self.radius)} units box"]

    def todict(self) -> dict:
        return {"type": "SphericalIndenter", "k": self.k, "radius": self.radius,
                "centre": self.centre.tolist(), "velocity": self.velocity.tolist()}

    def __repr__(self) -> str:
        return (f"SphericalIndenter(k={self.k!r}, radius={self.radius!r}, "
                f"centre={self.centre.tolist()!r}, velocity={self.velocity.tolist()!r})")


#: the directions :class:`Gravity` takes by name: an axis with its sign (in
#: either letter case)
SIGNED_AXES = {f"{sign}{axis}": tuple(value if k == i else 0.0 for k in range(3))
               for i, axis in enumerate("xyz") for sign, value in (("+", 1.0), ("-", -1.0))}
#: what Gravity's direction may be, for its errors
DIRECTION_FORMS = ("a 3-vector such as (0, 0, -1), or a signed axis: "
                   f"{', '.join(repr(name) for name in SIGNED_AXES)}")


class Gravity:
    """Uniform gravity: LAMMPS ``fix gravity g vector x y z``.

    Every atom feels ``m g d`` with ``d`` the unit vector along
    ``direction``; the energy is ``-sum m g d . x``.  Parameters: ``g``
    (acceleration, distance/time^2, >= 0) and ``direction``: a 3-vector of
    any length (default ``(0, 0, -1)``, down the z axis), or an axis with
    its sign, ``"-z"`` for ``(0, 0, -1)``, ``"+x"`` for ``(1, 0, 0)`` and so
    on, in either letter case (``"-Z"``).  A bare ``"z"`` is refused: it
    does not say whether gravity pulls up or down the axis.
    """

    needs_time = False
    needs_spheres = False
    produces_torques = False

    def __init__(self, g: float, direction=(0.0, 0.0, -1.0), **unknown):
        check_keywords("Gravity", unknown, keyword_names(Gravity.__init__))
        try:
            g = float(g)
        except (TypeError, ValueError):
            raise ValueError(f"Gravity: g must be a number, got {g!r}") from None
        if not np.isfinite(g) or g < 0:
            raise ValueError(f"Gravity: g = {g} must be finite and non-negative")
        direction = self._vector(direction)
        length = float(np.linalg.norm(direction))
        if not (np.isfinite(length) and length > 0):
            raise ValueError(f"Gravity: direction {direction.tolist()} must be a finite, "
                             "non-zero vector")
        self.g, self.direction = g, _read_only(direction / length)
        self._weights = None  # (masses, g, direction, m g per atom) of the last contribution

    @staticmethod
    def _vector(direction) -> np.ndarray:
        """``direction`` as 3 floats (a signed axis name as its unit vector);
        ValueError naming the accepted forms for anything else."""
        if isinstance(direction, str):
            if direction.lower() in SIGNED_AXES:
                return np.array(SIGNED_AXES[direction.lower()])
            why = (f"has no sign: give '-{direction}' or '+{direction}'"
                   if f"-{direction.lower()}" in SIGNED_AXES else "is not a direction")
            raise ValueError(f"Gravity: direction {direction!r} {why}; a direction is "
                             f"{DIRECTION_FORMS}")
        try:
            vector = np.asarray(direction, dtype=float)
        except (TypeError, ValueError):
            vector = None
        if vector is None or vector.size != 3:
            raise ValueError(f"Gravity: direction {direction!r} is not a direction; a "
                             f"direction is {DIRECTION_FORMS}")
        return vector.reshape(3)

    @property
    def acceleration(self) -> np.ndarray:
        return self.g * self.direction

    def contribute(self, atoms: Atoms, clock) -> Contribution:
        """The weights ``m g`` (read-only: the caller adds them) and their
        energy.  The weights are kept while the evaluation's checked masses,
        the direction (both read-only: the same arrays, the same values) and
        ``g`` stay: a step computes only the energy."""
        inputs = clock.inputs or Inputs(atoms)
        m_n, d = inputs.masses, self.direction
        kept = self._weights
        if not (kept is not None and kept[0] is m_n and kept[2] is d and kept[1] == self.g
                and not (m_n.flags.writeable or d.flags.writeable)):
            weights = m_n[:, None] * self.acceleration
            weights.flags.writeable = False
            kept = self._weights = (m_n, self.g, d, weights)
        f_nc = kept[3]
        return Contribution(f_nc, -dot_sum(f_nc, atoms.positions))

    def forces(self, atoms: Atoms, time: float, m_n=None):
        m_n = atoms.get_masses() if m_n is None else m_n
        f_nc = m_n[:, None] * self.acceleration
        return f_nc, -dot_sum(f_nc, atoms.positions)

    def lammps_commands(self, index: int, force_per_lammps_force: float = 1.0) -> list[str]:
        """``fix gravity g vector x y z``.  LAMMPS pulls with its own per-atom
        mass: for legacy PERI that is the density, which makes the force
        density it expects (so no conversion here)."""
        d = self.direction
        return [f"fix ase_bpm_gravity{index} all gravity {exact(self.g)} vector "
                f"{exact(d[0])} {exact(d[1])} {exact(d[2])}"]

    def todict(self) -> dict:
        return {"type": "Gravity", "g": self.g, "direction": self.direction.tolist()}

    @classmethod
    def from_dict(cls, fields: dict) -> "Gravity":
        """The gravity of a :meth:`todict`: its direction, a unit vector
        already, is kept as written (normalising it again could change its
        last bits, and so the forces)."""
        gravity = cls(**fields)
        written = cls._vector(fields.get("direction", gravity.direction))
        if abs(float(np.linalg.norm(written)) - 1.0) < 1e-12:
            gravity.direction = _read_only(written)
        return gravity

    def __repr__(self) -> str:
        return f"Gravity(g={self.g!r}, direction={self.direction.tolist()!r})"


def _read_only(a: np.ndarray) -> np.ndarray:
    """``a``, made read-only (a cache may then trust it by identity)."""
    a.flags.writeable = False
    return a


AXES = {"x": 0, "y": 1, "z": 2, "xplane": 0, "yplane": 1, "zplane": 2}
#: the start of the name of a wall's shear history array, ``gran_wall_<name>``
WALL_HISTORY = "gran_wall_"


class GranularWall(HoldsKernels):
    """A flat frictional wall (or a pair of parallel walls): LAMMPS ``fix
    wall/gran <model> ... xplane|yplane|zplane lo hi``.

    The wall is the plane ``x[axis] = lo`` (particles above it) and/or
    ``x[axis] = hi`` (particles below it); ``None`` for no wall on that side.
    A sphere touches the wall nearer to it when its centre is closer than its
    radius, and feels the contact law of :class:`ase_bpm.Granular` with a
    partner of infinite radius and mass at rest: the same ``model``, ``kn``,
    ``gamma_n``, ``xmu``, ``kt``, ``gamma_t``, ``dampflag`` and
    ``limit_damping`` (the wall has its own coefficients, as in LAMMPS).
    Only ``model`` may be given by position: the coefficients are keywords
    (TypeError otherwise), as named in the LAMMPS line ``fix wall/gran
    <model> Kn Kt gamma_n gamma_t xmu dampflag <axis>plane lo hi``.

    History models keep one shear displacement per atom in
    ``atoms.arrays["gran_wall_<name>"]``; ``name`` defaults to the axis and
    must differ between walls that keep history.  ``kernels``: as for
    :class:`ase_bpm.Granular`.  Spheres need
    ``atoms.arrays["radius"]``; torques turn them under
    :class:`ase_bpm.SphereVelocityVerlet`.

    The history models follow the reference LAMMPS (22 Jul 2025), whose
    walls differ from its pair styles: the tangential spring is ``kt a``
    with the contact radius ``a = sqrt(delta R)`` for Hooke too, and a
    sliding contact resets its shear without that factor, so after a slip
    the spring force drops to ``a`` times the Coulomb limit (visible with
    weak tangential damping).  ``pair_law=True`` uses the pair-style law
    instead (a partner of infinite radius), which no LAMMPS wall reproduces:
    such a wall cannot be exported.
    """

    def __init__(self, model: str, *positional, kn: float = None, kt: float | None = None,
                 gamma_n: float = None, gamma_t: float | None = None, xmu: float = None,
                 dampflag: int = 1, axis: str = "z", lo: float | None = 0.0,
                 hi: float | None = None, limit_damping: bool = False, name: str | None = None,
                 pair_law: bool = False, kernels: str = "auto", **unknown):
        from ..laws import granular_kernels
        from ..laws.granular import ContactLaw

        ContactLaw.check_call("GranularWall", model, positional)
        check_keywords("GranularWall", unknown, keyword_names(GranularWall.__init__))
        ContactLaw.check_given("GranularWall", TypeError,
                               dict(kn=kn, gamma_n=gamma_n, xmu=xmu))
        self.law = ContactLaw.create(model, kn, gamma_n, xmu, kt, gamma_t, dampflag,
                                     limit_damping, who="GranularWall")
        if axis not in AXES:
            raise ValueError(f"GranularWall: axis must be 'x', 'y' or 'z', got {axis!r}")
        self.axis = AXES[axis]
        if lo is None and hi is None:
            raise ValueError("GranularWall: give lo, hi or both")
        for label, value in (("lo", lo), ("hi", hi)):
            if value is not None and not np.isfinite(value):
                raise ValueError(f"GranularWall: {label} = {value} must be finite")
        if lo is not None and hi is not None and not lo < hi:
            raise ValueError(f"GranularWall: lo = {lo} must be below hi = {hi}")
        self.lo = None if lo is None else float(lo)
        self.hi = None if hi is None else float(hi)
        self.name = str(name) if name is not None else "xyz"[self.axis]
        self.pair_law = bool(pair_law)
        try:
            self.kernels = granular_kernels(kernels)
        except ValueError as exc:
            raise ValueError(f"GranularWall: {exc}") from None
        self._kernels_asked = kernels  # (for todict)
        #: the kernel variant chosen for these coefficients
        self.kernel_variant = self.kernels.variant("walls", self.law.frictional)
        #: walls next to each other in a calculator's fixes with equal keys
        #: (the same law, wall law and kernels) contribute in one kernel call
        #: (:meth:`contribute_together`); set here with what it names
        self.together_key = (GranularWall, self.law, self.pair_law, self.kernels)

    needs_time = False  # a wall at rest: no clock
    needs_spheres = True  # radius, angular velocity and torque

    @property
    def needs_timestep(self) -> bool:
        """History walls advance their shear by the timestep in each step."""
        return self.law.keeps_history

    @property
    def produces_torques(self) -> bool:
        """A frictional wall turns the spheres; a frictionless one cannot."""
        return self.law.frictional

    @property
    def history_array(self) -> str:
        """The name of the wall's shear history array on the atoms."""
        return WALL_HISTORY + self.name

    def contribute(self, atoms: Atoms, clock) -> Contribution:
        return self.contribute_together([self], atoms, clock)

    @staticmethod
    def contribute_together(walls, atoms: Atoms, clock) -> Contribution:
        """The contribution of ``walls`` (of one :attr:`together_key`) in one
        kernel call: their forces, torques and energies added up wall after
        wall (into the evaluation's own arrays, ``clock.into``, where given),
        the shear history of each in its own array."""
        n = len(atoms)
        first = walls[0]
        law = first.law
        # each wall's plane, the name of its history array and its stored
        # shear (None for none: the kernels only read it)
        planes, names, shear_wnc = [], [], []
        for wall in walls:
            if atoms.pbc[wall.axis]:
                raise ValueError(f"GranularWall {wall.name!r}: a wall across the periodic "
                                 f"direction {'xyz'[wall.axis]} (LAMMPS: cannot use wall in "
                                 "periodic dimension)")
            planes.append((wall.axis, wall.lo, wall.hi))
            names.append(WALL_HISTORY + wall.name)  # (wall.history_array)
            stored = atoms.arrays.get(names[-1])
            shear_wnc.append(stored if stored is not None and stored.shape == (n, 3) else None)
        if law.keeps_history and clock.advancing and clock.timestep is None:
            raise ValueError(f"GranularWall {first.name!r} with shear history needs the "
                             "MD timestep")
        inputs = clock.inputs or Inputs(atoms)
        try:
            res = first.kernels.walls_contacts(
                planes, atoms.positions,
                inputs.velocities if law.uses_velocities else None,
                inputs.omega if law.frictional else None,
                inputs.radii("GranularWall"), inputs.masses,
                shear_wnc if law.keeps_history else None, **law.coefficients,
                dt=clock.timestep or 0.0, update=clock.advancing,
                lammps_wall=not first.pair_law, into=clock.into)
        except ValueError as exc:
            wall = walls[exc.wall or 0] if isinstance(exc, CentredOnWall) else first
            raise ValueError(f"GranularWall {wall.name!r}: {exc}") from None
        # None drops a history left by a frictional run (it would come back with friction)
        arrays = {}
        for w, name in enumerate(names):
            if name in arrays:  # (as the calculator says of fixes apart)
                raise state_taken(name)
            arrays[name] = res.shear_xc[w] if law.keeps_history else None
        # (the compiled kernels add into zeros instead where they cannot into these)
        added = clock.into is not None and res.f_nc is clock.into[0]
        return Contribution(res.f_nc, res.energy, torques=res.t_nc, f_damp=res.fd_nc,
                            arrays=arrays, added=added)

    def springs(self, atoms: Atoms, clock) -> Springs:
        """The spheres touching the wall as springs and dampers against a fixed
        partner (the law's ``stiffness`` with the sphere's radius and mass),
        with the lever arm ``R`` to the contact point, for
        ``calc.stable_timestep``."""
        from ..laws.granular import wall_gaps

        inputs = clock.inputs or Inputs(atoms)
        r_n = inputs.radii("GranularWall")
        atom_p, dx_p = wall_gaps(self.axis, self.lo, self.hi, atoms.positions, r_n)
        rad_p, m_p = r_n[atom_p], inputs.masses[atom_p]
        law = self.law.stiffness(rad_p - np.abs(dx_p), rad_p, m_p,
                                 lammps_wall=not self.pair_law)
        n_pc = np.zeros((len(atom_p), 3))
        n_pc[:, self.axis] = np.sign(dx_p)  # from the wall to the sphere
        return Springs(atom_p, None, n_pc, law.k_x, law.kt_x, law.c_x, law.ct_x,
                       arm_i_xc=-rad_p[:, None] * n_pc)

    def lammps_style(self) -> str:
        """``<model args> xplane lo hi`` for ``fix ... wall/gran``."""
        bounds = " ".join("NULL" if v is None else repr(v) for v in (self.lo, self.hi))
        # (limit_damping stays with the model's arguments, before the wall style:
        # the reference build refuses it after the bounds)
        return f"{self.law.lammps_args()} {'xyz'[self.axis]}plane {bounds}"

    def lammps_commands(self, index: int, force_per_lammps_force: float = 1.0) -> list[str]:
        """``fix ase_bpm_wall_<name> all wall/gran <model args> <axis>plane lo
        hi``; refuses the walls that no LAMMPS wall reproduces."""
        if force_per_lammps_force != 1.0:
            raise ValueError("no LAMMPS export for GranularWall in this scene: fix wall/gran "
                             "adds true forces, the scene's LAMMPS forces are force densities")
        if self.pair_law and self.law.history:
            raise ValueError(f"GranularWall {self.name!r} uses pair_law=True, which no "
                             "LAMMPS fix wall/gran reproduces: export it with the "
                             "default wall law")
        if self.law.gamma_n == 0.0:
            # it stores gamma_t / gamma_n: 0/0, and the wall exerts no force
            raise ValueError(f"GranularWall {self.name!r}: LAMMPS fix wall/gran (22 Jul "
                             "2025) fails with gamma_n = 0 (it divides gamma_t by "
                             "gamma_n); export needs gamma_n > 0")
        return [f"fix ase_bpm_wall_{self.name} all wall/gran {self.lammps_style()}"]

    def todict(self) -> dict:
        law = self.law
        return {"type": "GranularWall", "model": law.model, "kn": law.kn,
                "gamma_n": law.gamma_n, "xmu": law.xmu, "kt": law.kt, "gamma_t": law.gamma_t,
                "dampflag": law.dampflag, "axis": "xyz"[self.axis], "lo": self.lo,
                "hi": self.hi, "limit_damping": law.limit_damping, "name": self.name,
                "pair_law": self.pair_law,
                # (as ASE's todict, the default left out: the digest of walls stays)
                **({"kernels": self._kernels_asked} if self._kernels_asked != "auto" else {})}

    def __repr__(self) -> str:
        d = self.todict()
        d.pop("type")
        return "GranularWall(" + ", ".join(f"{k}={v!r}" for k, v in d.items()) + ")"


for _fix in (SphericalIndenter, Gravity, GranularWall):  # rebuilt from todict() by name
    register_fix(_fix)
del _fix
