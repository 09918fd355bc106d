"""Frictional contact between spheres: the classic LAMMPS granular laws.

Pure functions over arrays of contacts (``_p``), shared by particle-particle
contacts (LAMMPS ``pair_style gran/hooke``, ``gran/hooke/history``,
``gran/hertz/history``) and particle-wall contacts (``fix wall/gran`` with the
same model names).  Geometry follows LAMMPS: ``del_pc = x_i - x_j`` points
from the partner (or the wall) to particle ``i``; the overlap is
``delta = radsum - r``.  A wall is a partner of radius 0, infinite mass and no
motion.

Normal force on ``i``, along ``del / r``:

* Hooke: ``kn delta - meff gamma_n v_n``
* Hertz: the same times ``sqrt(delta R_eff)``

with ``v_n = (v_i - v_j) . del / r``.  Tangential force: the relative
velocity of the surfaces at the contact, ``v_tr``, drives a damper
``-meff gamma_t v_tr`` and (history models) a spring ``-kt s`` on the
accumulated shear displacement ``s``; the total is truncated at the Coulomb
limit ``xmu |F_n|``.  The no-history model uses the damper alone, capped at
the Coulomb limit.  Torques on the two spheres follow from the tangential
force acting at their surfaces.  Where no tangential force can act
(:attr:`ContactLaw.frictional`), the kernels' frictionless variant computes
the normal force alone.

Walls in the reference LAMMPS (22 Jul 2025, ``fix wall/gran`` through its
``GranularModel`` "classic" models) differ from the pair styles in the history
models, as measured against that build: the tangential spring is
``kt a`` with the contact radius ``a = sqrt(delta R)`` for Hooke as well as
Hertz, and where the contact slides the shear is reset to
``(damper - F_t) / kt``, without the factor ``a``.  ``lammps_wall=True``
selects that variant.
"""

from __future__ import annotations

import functools
import numbers
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..core.params import check_name
from .contact import register_contact
from .timestep import LawStiffness

#: model names: today's LAMMPS names and those of the old manual page
MODEL_NAMES = {
    "hooke": "hooke", "no_history": "hooke",
    "hooke/history": "hooke/history", "history": "hooke/history",
    "hertz/history": "hertz/history", "hertzian": "hertz/history",
}
#: the smallest normal double: a squared distance below it is no direction
#: (contacts closer than that are coincident; 1 / r^2 would overflow)
TINY = float(np.finfo(float).tiny)


@dataclass(frozen=True)
class ContactLaw:
    """A classic LAMMPS granular contact law with its coefficients resolved:
    the arguments of ``pair_style gran/<model>`` and ``fix wall/gran <model>``.

    Build it with :meth:`create`, which applies the LAMMPS defaults
    (``kt = 2/7 kn``, ``gamma_t = 1/2 gamma_n``, ``dampflag 0`` -> no
    tangential damping) and checks every coefficient.  The law is frozen:
    what follows from the coefficients (:attr:`frictional`, ...) is worked
    out once, at its first use (each evaluation asks several times).
    """

    #: the coefficients in the order of LAMMPS's ``pair_style gran/<model>``
    #: and ``fix wall/gran <model>`` lines (``Kn Kt gamma_n gamma_t xmu
    #: dampflag``), which Granular and GranularWall take by keyword
    LAMMPS_ORDER = ("kn", "kt", "gamma_n", "gamma_t", "xmu", "dampflag")
    #: the pair styles' names: ``gran/`` and the model (``gran/hooke/history``)
    STYLE_PREFIX = "gran/"
    #: the coefficients that have no default
    REQUIRED = ("kn", "gamma_n", "xmu")
    #: every model has its compiled kernels (ase_bpm.laws.compiled)
    compiled = True

    model: str  # "hooke", "hooke/history" or "hertz/history"
    kn: float
    kt: float
    gamma_n: float
    gamma_t: float
    xmu: float
    dampflag: int
    limit_damping: bool = False

    @classmethod
    def create(cls, model: str, kn: float, gamma_n: float, xmu: float,
               kt: float | None = None, gamma_t: float | None = None,
               dampflag: int = 1, limit_damping: bool = False,
               who: str = "Granular") -> "ContactLaw":
        name = cls.model_name(model, who)

        def number(label, value, positive=False):
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"{who}: {label} must be a number, got {value!r}") from None
            if not np.isfinite(value) or (value <= 0 if positive else value < 0):
                need = "positive" if positive else "non-negative"
                raise ValueError(f"{who}: {label} = {value} must be finite and {need}")
            return value

        kn = number("kn", kn, positive=True)
        kt = 2.0 / 7.0 * kn if kt is None else number("kt", kt, positive=name != "hooke")
        gamma_n = number("gamma_n", gamma_n)
        gamma_t = 0.5 * gamma_n if gamma_t is None else number("gamma_t", gamma_t)
        xmu = number("xmu", xmu)
        if xmu > 10000.0:
            raise ValueError(f"{who}: xmu = {xmu} is beyond 10000, which LAMMPS rejects")
        if dampflag not in (0, 1) or isinstance(dampflag, bool):
            raise ValueError(f"{who}: dampflag must be 0 or 1, got {dampflag!r}")
        if dampflag == 0:
            gamma_t = 0.0
        return cls(name, kn, kt, gamma_n, gamma_t, xmu, int(dampflag), bool(limit_damping))

    @classmethod
    def model_name(cls, model: str, who: str = "Granular") -> str:
        """The model's name as :attr:`model` holds it (``gran/`` and the names
        of the old manual page taken); ValueError for any other, naming the
        valid names and the nearest one."""
        return MODEL_NAMES[check_name(who, "model", model, MODEL_NAMES,
                                      prefix=cls.STYLE_PREFIX)]

    @classmethod
    def check_call(cls, who: str, model: str, args: tuple) -> None:
        """Check the model's name first (:meth:`model_name`: a misspelt model
        is named before any coefficient is asked for), then refuse, with a
        TypeError, coefficients given by position after it (the LAMMPS line
        orders them otherwise than this package once did: a positional call
        cannot be read safely)."""
        if isinstance(model, numbers.Real):  # (a coefficient given first, for the model)
            args, model = (model, *args), "hooke/history"
        cls.model_name(model, who)
        if args:
            keywords = ", ".join(f"{name}=..." for name in cls.LAMMPS_ORDER)
            raise TypeError(f"{who} takes every argument after the model by keyword: "
                            f"{who}({model!r}, {keywords}) (LAMMPS gran/{model} orders them "
                            f"Kn Kt gamma_n gamma_t xmu dampflag); got {len(args)} "
                            "coefficient(s) by position")

    @classmethod
    def check_given(cls, who: str, error: type, given: dict) -> None:
        """Raise ``error`` naming every coefficient of :attr:`REQUIRED` that
        ``given`` (name: value) leaves None, all of them at once."""
        missing = [f"{name}=" for name in cls.REQUIRED if given[name] is None]
        if missing:
            listed = (f"{', '.join(missing[:-1])} and {missing[-1]}" if len(missing) > 1
                      else missing[0])
            raise error(f"{who} needs {listed}")

    @functools.cached_property
    def history(self) -> bool:
        """Does the law keep a shear displacement per contact?"""
        return self.model != "hooke"

    @functools.cached_property
    def hertz(self) -> bool:
        return self.model == "hertz/history"

    @functools.cached_property
    def frictional(self) -> bool:
        """Can a tangential force act?  Not with ``xmu = 0`` (the Coulomb
        limit ``xmu |F_n|`` caps it at zero, whatever ``kt`` and ``gamma_t``),
        nor for ``"hooke"`` without tangential damping (``gamma_t = 0``, e.g.
        ``dampflag 0``: no shear spring, no damper).  (``kt`` cannot be 0 for
        the history models.)  Without friction there is no shear history, no
        torque, and the angular velocities play no part."""
        return self.xmu > 0.0 and (self.history or self.gamma_t > 0.0)

    @functools.cached_property
    def keeps_history(self) -> bool:
        """Does a contact keep a shear displacement?  History models with
        friction (without, the shear could never act)."""
        return self.history and self.frictional

    @functools.cached_property
    def uses_velocities(self) -> bool:
        """Do the forces depend on velocities (normal or tangential damping,
        or the sliding of a frictional contact)?"""
        return self.gamma_n > 0.0 or self.frictional

    @functools.cached_property
    def coefficients(self) -> dict:
        """The keyword arguments of the kernels (:mod:`ase_bpm.laws.granular`)."""
        return dict(kn=self.kn, kt=self.kt, gamma_n=self.gamma_n, gamma_t=self.gamma_t,
                    xmu=self.xmu, hertz=self.hertz, history=self.keeps_history,
                    limit_damping=self.limit_damping, frictional=self.frictional)

    def stiffness(self, overlap_p, reff_p, meff_p, lammps_wall: bool = False) -> LawStiffness:
        """The contacts as springs and dampers, for the timestep bound.

        Normal: ``kn`` and ``meff gamma_n`` (Hooke); Hertz multiplies the
        whole normal force by the contact radius ``a = sqrt(delta R_eff)``,
        so its tangent stiffness is ``1.5 kn a`` and its damping
        ``meff gamma_n a``, at each contact's overlap ``delta`` now.
        Tangential (none without friction, :attr:`frictional`): the shear spring ``kt`` (history
        models; ``kt a`` for Hertz and for the reference build's walls,
        ``lammps_wall``) and the damper ``meff gamma_t`` (times ``a`` for
        Hertz), before the Coulomb limit, which only lowers them."""
        a_p = np.sqrt(overlap_p * reff_p)
        scale_p = a_p if self.hertz else 1.0
        k_p = (1.5 * self.kn) * a_p if self.hertz else self.kn + 0.0 * a_p
        kt_p = ct_p = 0.0
        if self.frictional:
            if self.history:
                kt_p = self.kt * (a_p if self.hertz or lammps_wall else 1.0)
            ct_p = self.gamma_t * meff_p * scale_p
        return LawStiffness(k_p, self.gamma_n * meff_p * scale_p, kt_p, ct_p)

    def lammps_args(self) -> str:
        """``<model> Kn Kt gamma_n gamma_t xmu dampflag [limit_damping]``
        (:attr:`LAMMPS_ORDER`), the numbers at full precision."""
        *numbers, dampflag = (getattr(self, name) for name in self.LAMMPS_ORDER)
        numbers = " ".join(repr(float(v)) for v in numbers)
        return (f"{self.model} {numbers} {dampflag}"
                + (" limit_damping" if self.limit_damping else ""))


for _model in sorted(set(MODEL_NAMES.values())):  # gran/hooke, gran/hooke/history, ...
    register_contact(ContactLaw, "gran/" + _model)
del _model


@dataclass
class ContactForces:
    """What :func:`contact_forces` returns, per contact."""

    f_pc: np.ndarray  # total force on i (the partner gets -f_pc)
    f_elastic_pc: np.ndarray  # the conservative part (normal spring) of f_pc
    #: (del x f_t) / r: torque on i is -R_i tor, on j -R_j tor (None: frictionless)
    tor_pc: Optional[np.ndarray]
    energy_p: np.ndarray  # elastic energy of the normal spring
    shear_pc: Optional[np.ndarray]  # the shear history after this evaluation
    #: the tangential part of f_pc (LAMMPS "fs"; None: frictionless), which
    #: may lean out of the tangent plane where the stored shear does
    fs_pc: Optional[np.ndarray] = None


def _cross(a_pc: np.ndarray, b_pc: np.ndarray) -> np.ndarray:
    out = np.empty_like(a_pc)
    out[:, 0] = a_pc[:, 1] * b_pc[:, 2] - a_pc[:, 2] * b_pc[:, 1]
    out[:, 1] = a_pc[:, 2] * b_pc[:, 0] - a_pc[:, 0] * b_pc[:, 2]
    out[:, 2] = a_pc[:, 0] * b_pc[:, 1] - a_pc[:, 1] * b_pc[:, 0]
    return out


def _dot(a_pc: np.ndarray, b_pc: np.ndarray) -> np.ndarray:
    return a_pc[:, 0] * b_pc[:, 0] + a_pc[:, 1] * b_pc[:, 1] + a_pc[:, 2] * b_pc[:, 2]


def normal_forces(rinv_p, rsqinv_p, overlap_p, reff_p, vnnr_p, meff_p, *, kn: float,
                  gamma_n: float, hertz: bool, limit_damping: bool) -> tuple:
    """The normal part of touching contacts: ``(ccel_p, elastic_p,
    polyhertz_p, energy_p)``, the normal force per unit length of ``del``
    (LAMMPS "ccel"), its elastic part, the Hertz factor (None for Hooke) and
    the elastic energy.  ``vnnr_p = vr . del`` is read only with ``gamma_n``."""
    elastic_p = kn * overlap_p * rinv_p
    ccel_p = elastic_p - meff_p * gamma_n * vnnr_p * rsqinv_p if gamma_n else elastic_p
    if hertz:
        polyhertz_p = np.sqrt(overlap_p * reff_p)
        ccel_p = ccel_p * polyhertz_p
        elastic_p = elastic_p * polyhertz_p
        energy_p = 0.4 * kn * polyhertz_p * overlap_p * overlap_p
    else:
        polyhertz_p = None
        energy_p = 0.5 * kn * overlap_p * overlap_p
    if limit_damping:
        ccel_p = np.maximum(ccel_p, 0.0)
    return ccel_p, elastic_p, polyhertz_p, energy_p


def contact_forces(del_pc, radsum_p, reff_p, vr_pc, wr_pc, meff_p, shear_pc=None, *,
                   kn: float, kt: float, gamma_n: float, gamma_t: float, xmu: float,
                   hertz: bool = False, history: bool = False, dt: float = 0.0,
                   update: bool = False, limit_damping: bool = False,
                   lammps_wall: bool = False, frictional: bool = True) -> ContactForces:
    """Forces and torques of touching contacts.

    Parameters (per contact ``p``)
    ------------------------------
    del_pc: ``x_i - x_j`` (particle minus wall contact point for walls).
    radsum_p: ``R_i + R_j`` (``R_i`` for walls), greater than ``|del|``.
    reff_p: ``R_i R_j / (R_i + R_j)`` (``R_i`` for walls); Hertz only.
    vr_pc: ``v_i - v_j``.
    wr_pc: ``R_i omega_i + R_j omega_j``.
    meff_p: effective mass.
    shear_pc: shear history (history models), the state after the last step.
    dt, update: advance the history by one step of ``dt`` (not in the setup
        evaluation, as in LAMMPS).
    lammps_wall: the wall variant of the history models (module doc).
    frictional: False when no tangential force can act
        (:attr:`ContactLaw.frictional`): then no tangential velocity, shear
        or torque is computed (``tor_pc`` and ``shear_pc`` are None),
        ``wr_pc`` and ``shear_pc`` are not read, nor ``vr_pc`` with
        ``gamma_n = 0``.  The forces are those of the general path.
    """
    rsq_p = _dot(del_pc, del_pc)
    r_p = np.sqrt(rsq_p)
    rinv_p = 1.0 / r_p
    rsqinv_p = 1.0 / rsq_p
    overlap_p = radsum_p - r_p
    normal = dict(kn=kn, gamma_n=gamma_n, hertz=hertz, limit_damping=limit_damping)

    if not frictional:
        vnnr_p = _dot(vr_pc, del_pc) if gamma_n else None
        ccel_p, elastic_p, _, energy_p = normal_forces(rinv_p, rsqinv_p, overlap_p, reff_p,
                                                       vnnr_p, meff_p, **normal)
        return ContactForces(f_pc=del_pc * ccel_p[:, None],
                             f_elastic_pc=del_pc * elastic_p[:, None], tor_pc=None,
                             energy_p=energy_p, shear_pc=None)

    # relative velocity: normal and tangential parts, and of the surfaces
    vnnr_p = _dot(vr_pc, del_pc)
    vt_pc = vr_pc - del_pc * (vnnr_p * rsqinv_p)[:, None]
    vtr_pc = vt_pc - _cross(wr_pc * rinv_p[:, None], del_pc)

    # normal force per unit length of del (LAMMPS "ccel")
    ccel_p, elastic_p, polyhertz_p, energy_p = normal_forces(
        rinv_p, rsqinv_p, overlap_p, reff_p, vnnr_p, meff_p, **normal)
    fn_p = xmu * np.abs(ccel_p * r_p)  # Coulomb limit
    # tangential damper (none with gamma_t = 0, e.g. dampflag 0)
    damp_pc = (meff_p * gamma_t)[:, None] * vtr_pc if gamma_t else None

    if not history and damp_pc is None:  # no spring, no damper: no tangential force
        fs_pc, new_shear = np.zeros_like(del_pc), None
    elif not history:
        vrel_p = np.sqrt(_dot(vtr_pc, vtr_pc))
        fs_p = meff_p * gamma_t * vrel_p
        ft_p = np.divide(np.minimum(fn_p, fs_p), vrel_p, out=np.zeros_like(vrel_p),
                         where=vrel_p != 0.0)
        fs_pc = -ft_p[:, None] * vtr_pc
        new_shear = None
    else:
        new_shear = shear_pc.copy()
        if update:
            new_shear += vtr_pc * dt
        shrsq_p = _dot(new_shear, new_shear)
        if update:  # keep the shear displacement in the tangent plane
            new_shear -= del_pc * (_dot(new_shear, del_pc) * rsqinv_p)[:, None]
        if lammps_wall:
            if hertz and damp_pc is not None:
                damp_pc *= polyhertz_p[:, None]
            spring_p = np.sqrt(overlap_p * reff_p)  # the contact radius
            fs_pc = -kt * spring_p[:, None] * new_shear
        else:
            fs_pc = -kt * new_shear
        if damp_pc is not None:
            fs_pc -= damp_pc
        if hertz and not lammps_wall:
            fs_pc *= polyhertz_p[:, None]
        # beyond the Coulomb limit: squares compared (LAMMPS compares the
        # lengths; the two differ only where fs and fn agree to round-off,
        # and the square root is then taken of the slipping contacts only)
        fssq_p = _dot(fs_pc, fs_pc)
        slip = fssq_p > fn_p * fn_p
        if slip.any():
            # at the Coulomb limit: scale the force down, and the spring to
            # what is left of it after the damper
            scale = fn_p[slip] / np.sqrt(fssq_p[slip])
            sticky = shrsq_p[slip] != 0.0
            damp = damp_pc[slip] if damp_pc is not None else 0.0
            if lammps_wall:
                reset = -(fs_pc[slip] * scale[:, None] + damp) / kt
            else:
                lag = damp / kt
                reset = scale[:, None] * (new_shear[slip] + lag) - lag
            new_shear[slip] = np.where(sticky[:, None], reset, new_shear[slip])
            fs_pc[slip] = np.where(sticky[:, None], fs_pc[slip] * scale[:, None], 0.0)

    f_elastic_pc = del_pc * elastic_p[:, None]
    f_pc = del_pc * ccel_p[:, None] + fs_pc
    tor_pc = _cross(del_pc, fs_pc) * rinv_p[:, None]
    return ContactForces(f_pc=f_pc, f_elastic_pc=f_elastic_pc, tor_pc=tor_pc,
                         energy_p=energy_p, shear_pc=new_shear, fs_pc=fs_pc)


# -- whole scenes: a neighbour list of sphere pairs, a wall ---------------------------

@dataclass
class SceneContacts:
    """What :func:`pair_contacts`, :func:`wall_contacts` and
    :func:`walls_contacts` return."""

    f_nc: np.ndarray  # force on each sphere
    fd_nc: np.ndarray  # its dissipative part (all but the normal springs)
    t_nc: Optional[np.ndarray]  # torque on each sphere (None: frictionless, no torque)
    energy: float  # elastic energy of the normal springs
    #: touching rows of the list (pairs) or touching spheres (walls, wall after wall)
    touch: np.ndarray
    #: new shear (history models): of the touching rows (pairs), of every
    #: sphere, zero where not touching (a wall; several: walls x spheres x 3)
    shear_xc: Optional[np.ndarray]
    virial: object = None  # sum r (x) f (3 x 3), or a function computing it (pairs)
    #: new shear of every listed row, zero where not touching (pairs of
    #: history models; else None): the next step's stored shear, if this one
    #: is kept, while the list is not rebuilt
    shear_lc: Optional[np.ndarray] = None
    #: the touching pairs, first and second sphere, and each sphere's number
    #: of touching partners (pairs; walls: None)
    i_p: Optional[np.ndarray] = None
    j_p: Optional[np.ndarray] = None
    count_n: Optional[np.ndarray] = None


def _scatter(i_p, j_p, wi_p, wj_p, v_pc, natoms: int) -> np.ndarray:
    """Per-atom sums of ``wi v`` on ``i`` and ``wj v`` on ``j``."""
    index = np.concatenate([i_p, j_p])
    out = np.empty((natoms, 3))
    for c in range(3):
        out[:, c] = np.bincount(index, np.concatenate([wi_p * v_pc[:, c], wj_p * v_pc[:, c]]),
                                minlength=natoms)
    return out


def variant(kind: str, frictional: bool) -> str:
    """The name of the kernel variant run for ``kind`` (``"pairs"`` or
    ``"walls"``) with or without friction (:attr:`ContactLaw.frictional`)."""
    name = {"pairs": "pair_contacts", "walls": "walls_contacts"}[kind]
    return f"numpy {name}" + ("" if frictional else " (frictionless)")


def pair_contacts(i_l, j_l, shift_lc, x_nc, v_nc, w_nc, r_n, m_n, hold_n, shear_lc, *,
                  kn: float, kt: float, gamma_n: float, gamma_t: float, xmu: float,
                  hertz: bool = False, history: bool = False, dt: float = 0.0,
                  update: bool = False, limit_damping: bool = False,
                  virial: bool = True, frictional: bool = True) -> SceneContacts:
    """Forces and torques of the touching pairs among the listed ones (LAMMPS
    ``pair_style gran/*``).

    ``i_l``, ``j_l``, ``shift_lc``: a neighbour list (``x_j - x_i + shift`` is
    the pair vector; ``shift_lc`` None: no shifts, an open box); ``x_nc``, ``v_nc``, ``w_nc`` (angular velocities),
    ``r_n`` (radii), ``m_n`` (masses) per sphere; ``hold_n``: spheres held
    still (LAMMPS ``fix freeze``: the partner's mass alone is the effective
    mass) or None; ``shear_lc``: the stored shear of each listed pair
    (history models).  Raises ``ValueError`` for touching spheres at the same
    position.  ``virial``: also return the virial (here a function that
    computes it when called).  ``frictional=False``: the frictionless variant
    (:func:`contact_forces`): ``w_nc`` and ``shear_lc`` are not read (may be
    None), nor ``v_nc`` with ``gamma_n = 0``; no torques (``t_nc`` None).
    """
    natoms = len(x_nc)
    r_lc = np.take(x_nc, j_l, axis=0) - np.take(x_nc, i_l, axis=0)
    if shift_lc is not None:
        r_lc += shift_lc
    del_lc = -r_lc
    radsum_l = np.take(r_n, i_l) + np.take(r_n, j_l)
    (l_p,) = np.nonzero(_dot(del_lc, del_lc) < radsum_l * radsum_l)
    i_p, j_p, del_pc, radsum_p = i_l[l_p], j_l[l_p], del_lc[l_p], radsum_l[l_p]
    coincide = _dot(del_pc, del_pc) < TINY  # or so close that 1 / r^2 overflows
    if coincide.any():
        p = int(np.argmax(coincide))
        raise ValueError(f"spheres {i_p[p]} and {j_p[p]} are at the same position: "
                         "their contact has no normal direction")

    ri_p, rj_p = np.take(r_n, i_p), np.take(r_n, j_p)
    mi_p, mj_p = np.take(m_n, i_p), np.take(m_n, j_p)
    meff_p = mi_p * mj_p / (mi_p + mj_p)
    if hold_n is not None:  # fix freeze: the frozen partner counts as a wall
        meff_p = np.where(hold_n[i_p], mj_p, meff_p)
        meff_p = np.where(hold_n[j_p], mi_p, meff_p)
    history = history and frictional
    vr_pc = wr_pc = None
    if frictional or gamma_n:
        vr_pc = np.take(v_nc, i_p, axis=0) - np.take(v_nc, j_p, axis=0)
    if frictional:
        wr_pc = (ri_p[:, None] * np.take(w_nc, i_p, axis=0)
                 + rj_p[:, None] * np.take(w_nc, j_p, axis=0))
    res = contact_forces(del_pc, radsum_p, ri_p * rj_p / radsum_p, vr_pc, wr_pc, meff_p,
                         shear_lc[l_p] if history else None, kn=kn, kt=kt,
                         gamma_n=gamma_n, gamma_t=gamma_t, xmu=xmu, hertz=hertz,
                         history=history, dt=dt, update=update,
                         limit_damping=limit_damping, frictional=frictional)
    one = np.ones(len(l_p))
    f_nc = _scatter(i_p, j_p, one, -one, res.f_pc, natoms)
    fd_nc = f_nc - _scatter(i_p, j_p, one, -one, res.f_elastic_pc, natoms)
    t_nc = None if res.tor_pc is None else _scatter(i_p, j_p, -ri_p, -rj_p, res.tor_pc,
                                                     natoms)
    f_pc = res.f_pc
    new_shear_lc = None
    if history:
        new_shear_lc = np.zeros((len(i_l), 3))
        new_shear_lc[l_p] = res.shear_pc
    return SceneContacts(f_nc, fd_nc, t_nc, float(res.energy_p.sum()), l_p, res.shear_pc,
                         virial=(lambda: -del_pc.T @ f_pc) if virial else None,
                         shear_lc=new_shear_lc, i_p=i_p, j_p=j_p,
                         count_n=np.bincount(np.concatenate([i_p, j_p]), minlength=natoms))


class CentredOnWall(ValueError):
    """A sphere whose centre is on a wall: the contact has no normal direction.
    ``sphere``, and ``wall``: the wall's index among those of one call (None
    for one wall)."""

    def __init__(self, sphere: int, wall: int | None = None):
        super().__init__(f"sphere {sphere} has its centre on the wall: the contact has no "
                         "normal direction")
        self.sphere, self.wall = int(sphere), wall


def wall_gaps(axis: int, lo, hi, x_nc, r_n) -> tuple:
    """``(atom_p, dx_p)``: the spheres touching a wall ``x[axis] = lo`` (from
    above) or ``hi`` (from below), and their signed distance from the nearer
    wall (LAMMPS: ``dx = x - lo`` or ``-(hi - x)``)."""
    n = len(x_nc)
    x_n = x_nc[:, axis]
    below = x_n - lo if lo is not None else np.full(n, np.inf)
    above = hi - x_n if hi is not None else np.full(n, np.inf)
    dx_n = np.where(below < above, below, -above)
    (atom_p,) = np.nonzero(dx_n * dx_n < r_n * r_n)
    dx_p = dx_n[atom_p]
    centred = dx_p == 0.0
    if centred.any():
        raise CentredOnWall(atom_p[np.argmax(centred)])
    return atom_p, dx_p


def wall_contacts(axis: int, lo, hi, x_nc, v_nc, w_nc, r_n, m_n, shear_nc, *, kn: float,
                  kt: float, gamma_n: float, gamma_t: float, xmu: float, hertz: bool = False,
                  history: bool = False, dt: float = 0.0, update: bool = False,
                  limit_damping: bool = False, lammps_wall: bool = True,
                  frictional: bool = True) -> SceneContacts:
    """Forces and torques of the spheres touching a flat wall ``x[axis] = lo``
    (spheres above it) and/or ``x[axis] = hi`` (below it), ``None`` for no
    wall there (LAMMPS ``fix wall/gran ... xplane|yplane|zplane lo hi``).

    ``shear_nc``: each sphere's stored shear against the wall (history
    models; None: none stored, zero).  ``lammps_wall``: the reference
    build's wall variant of the history models (module doc); False applies
    the pair-style law.
    ``frictional=False``: the frictionless variant, as for :func:`pair_contacts`.
    """
    n = len(x_nc)
    atom_p, dx_p = wall_gaps(axis, lo, hi, x_nc, r_n)
    history = history and frictional
    f_nc, fd_nc = np.zeros((n, 3)), np.zeros((n, 3))
    t_nc = np.zeros((n, 3)) if frictional else None
    new_shear = np.zeros((n, 3)) if history else None
    energy = 0.0
    if len(atom_p):
        del_pc = np.zeros((len(atom_p), 3))
        del_pc[:, axis] = dx_p
        rad_p = r_n[atom_p]
        stored_pc = None
        if history:  # (none stored: zero)
            stored_pc = np.zeros((len(atom_p), 3)) if shear_nc is None else shear_nc[atom_p]
        res = contact_forces(del_pc, rad_p, rad_p,
                             v_nc[atom_p] if frictional or gamma_n else None,
                             rad_p[:, None] * w_nc[atom_p] if frictional else None,
                             m_n[atom_p], stored_pc, kn=kn,
                             kt=kt, gamma_n=gamma_n, gamma_t=gamma_t, xmu=xmu, hertz=hertz,
                             history=history, dt=dt, update=update,
                             limit_damping=limit_damping, lammps_wall=lammps_wall,
                             frictional=frictional)
        f_nc[atom_p] = res.f_pc
        fd_nc[atom_p] = res.f_pc - res.f_elastic_pc
        if frictional:
            t_nc[atom_p] = -rad_p[:, None] * res.tor_pc
        energy = float(res.energy_p.sum())
        if history:
            new_shear[atom_p] = res.shear_pc
    return SceneContacts(f_nc, fd_nc, t_nc, energy, atom_p, new_shear)


def sums_into(into, n: int, frictional: bool) -> tuple:
    """``(f_nc, fd_nc, t_nc)`` that a wall kernel adds its forces, their
    dissipative part and torques into: the arrays of ``into`` (an
    evaluation's so far, added to in place), zeros for those it has as None
    or for ``into=None``; ``t_nc`` stays as given without friction."""
    f_nc, fd_nc, t_nc = (None, None, None) if into is None else into
    f_nc = np.zeros((n, 3)) if f_nc is None else f_nc
    fd_nc = np.zeros((n, 3)) if fd_nc is None else fd_nc
    if frictional and t_nc is None:
        t_nc = np.zeros((n, 3))
    return f_nc, fd_nc, t_nc


def walls_contacts(planes, x_nc, v_nc, w_nc, r_n, m_n, shear_wnc, *, into=None,
                   **law) -> SceneContacts:
    """:func:`wall_contacts` of several walls with one law, in one call (as
    the compiled kernels take them): ``planes`` are ``(axis, lo, hi)`` of each
    wall, ``shear_wnc`` their stored shear (walls x spheres x 3, or a
    sequence of one spheres x 3 array per wall, None for a wall with none;
    history models; not changed), ``law`` the keywords of
    :func:`wall_contacts`.  Forces, their dissipative parts, torques and
    energies are added up wall after wall, into the arrays of ``into``
    (``(f_nc, fd_nc, t_nc)``, each None or n x 3, changed in place and
    returned; :func:`sums_into`) or into zeros; the touching spheres are
    listed wall after wall.  A sphere centred on a wall raises
    :class:`CentredOnWall` with that wall's index."""
    n = len(x_nc)
    frictional = law.get("frictional", True)
    f_nc, fd_nc, t_nc = sums_into(into, n, frictional)
    energy, touch, shear = 0.0, [], []
    for w, (axis, lo, hi) in enumerate(planes):
        try:
            res = wall_contacts(axis, lo, hi, x_nc, v_nc, w_nc, r_n, m_n,
                                None if shear_wnc is None else shear_wnc[w], **law)
        except CentredOnWall as exc:
            raise CentredOnWall(exc.sphere, w) from None
        f_nc += res.f_nc
        fd_nc += res.fd_nc
        if frictional:
            t_nc += res.t_nc
        energy += res.energy
        touch.append(res.touch)
        shear.append(res.shear_xc)
    shear_wnc = np.stack(shear) if shear and shear[0] is not None else None
    return SceneContacts(f_nc, fd_nc, t_nc, energy,
                         np.concatenate(touch) if touch else np.zeros(0, dtype=np.int64),
                         shear_wnc)
