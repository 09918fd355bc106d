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
force acting at their surfaces.

Walls in the reference LAMMPS (22 Jul 2025, ``fix wall/gran`` through its
``GranularModel`` "classic" models) differ from the pair styles in the history
models, as measured against that build: the tangential spring is
``kt a`` with the contact radius ``a = sqrt(delta R)`` for Hooke as well as
Hertz, and where the contact slides the shear is reset to
``(damper - F_t) / kt``, without the factor ``a``.  ``lammps_wall=True``
selects that variant.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass
class ContactForces:
    """What :func:`contact_forces` returns, per contact."""

    f_pc: np.ndarray  # total force on i (the partner gets -f_pc)
    f_elastic_pc: np.ndarray  # the conservative part (normal spring) of f_pc
    tor_pc: np.ndarray  # (del x f_t) / r: torque on i is -R_i tor, on j -R_j tor
    energy_p: np.ndarray  # elastic energy of the normal spring
    shear_pc: Optional[np.ndarray]  # the shear history after this evaluation


def _cross(a_pc: np.ndarray, b_pc: np.ndarray) -> np.ndarray:
    out = np.empty_like(a_pc)
    out[:, 0] = a_pc[:, 1] * b_pc[:, 2] - a_pc[:, 2] * b_pc[:, 1]
    out[:, 1] = a_pc[:, 2] * b_pc[:, 0] - a_pc[:, 0] * b_pc[:, 2]
    out[:, 2] = a_pc[:, 0] * b_pc[:, 1] - a_pc[:, 1] * b_pc[:, 0]
    return out


def _dot(a_pc: np.ndarray, b_pc: np.ndarray) -> np.ndarray:
    return a_pc[:, 0] * b_pc[:, 0] + a_pc[:, 1] * b_pc[:, 1] + a_pc[:, 2] * b_pc[:, 2]


def contact_forces(del_pc, radsum_p, reff_p, vr_pc, wr_pc, meff_p, shear_pc=None, *,
                   kn: float, kt: float, gamma_n: float, gamma_t: float, xmu: float,
                   hertz: bool = False, history: bool = False, dt: float = 0.0,
                   update: bool = False, limit_damping: bool = False,
                   lammps_wall: bool = False) -> ContactForces:
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
    """
    rsq_p = _dot(del_pc, del_pc)
    r_p = np.sqrt(rsq_p)
    rinv_p = 1.0 / r_p
    rsqinv_p = 1.0 / rsq_p
    overlap_p = radsum_p - r_p

    # relative velocity: normal and tangential parts, and of the surfaces
    vnnr_p = _dot(vr_pc, del_pc)
    vt_pc = vr_pc - del_pc * (vnnr_p * rsqinv_p)[:, None]
    vtr_pc = vt_pc - _cross(wr_pc * rinv_p[:, None], del_pc)

    # normal force per unit length of del (LAMMPS "ccel")
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
        shrmag_p = np.sqrt(_dot(new_shear, new_shear))
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
        fs_p = np.sqrt(_dot(fs_pc, fs_pc))
        slip = fs_p > fn_p
        if slip.any():
            # at the Coulomb limit: scale the force down, and the spring to
            # what is left of it after the damper
            scale = fn_p[slip] / fs_p[slip]
            sticky = shrmag_p[slip] != 0.0
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
                         energy_p=energy_p, shear_pc=new_shear)
