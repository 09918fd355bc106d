"""``bond_style bpm/rotational``: bonds that resist stretching, shearing,
bending and twisting (Wang 2009; Mora and Wang 2009), between particles that
carry an orientation (``atoms.arrays["quat"]``, :mod:`ase_bpm.core.quaternions`).

Pure functions over arrays, as LAMMPS 22 Jul 2025 (the reference build)
computes them.  LAMMPS orders the two ends of a bond by atom ID: particle 1
has the smaller one, the bond vector is ``r = x_1 - x_2`` and the reference
direction points the same way.  Here particle 1 is the one with the smaller
index when the bond takes its reference state (the IDs of an export), and
the per-bond state keeps the reference direction along the bond as listed
(from its first atom to its second) and which end particle 1 is, so that
both survive ASE's reordering of the atoms.

Which end is particle 1 is settled when the bond takes its reference state
and kept with it (the smaller index then, as an export numbers the atoms).

The law (all per bond, ``r0`` the reference length and direction, ``q_1``,
``q_2`` the orientations):

* ``rb = q_2* r q_2``, the bond in particle 2's frame; normal force
  ``k_r (|r| - r0)`` along ``rb``; a shear force ``k_s |r| gamma`` and torque
  from the angle ``gamma`` between ``rb`` and ``r0``;
* the relative rotation ``q_2* q_1``, taken into the frame whose z axis is
  the bond: twisting by ``psi`` about it (torque ``k_t psi``), bending by
  ``theta`` (torque ``k_b theta``, and the shear that goes with it);
* breaking at ``B = F_r/F_rc + |F_s|/F_sc + |T_b|/T_bc + |T_t|/T_tc >= 1``
  (a bond that breaks gives no force in that step); with ``smooth``, every
  force and torque times ``w = 1 - B^4``;
* damping of the normal, sliding, rolling and twisting relative motion
  (Wang, Alonso-Marroquin and Guo 2015), with the coefficients
  ``gamma_n``, ``gamma_s``, ``gamma_r``, ``gamma_t``.

The forces are not derived from an energy: LAMMPS reports the energy of
these bonds as zero, and so does this law (the ledger cannot book it).
"""

from __future__ import annotations

import warnings
from typing import NamedTuple, Optional

import numpy as np

from ..core.params import outside_stacklevel

from ..core.quaternions import conjugate, multiply, rotate
from . import compiled
from .bond import BondForces, BondInput, BondLaw, BondScene, register
from .timestep import LawStiffness

#: sqrt(2) / 2, in the components of the quaternion that turns z onto the bond
HALF_SQRT2 = 0.5 * np.sqrt(2.0)
#: the per-bond state: the reference direction, along the bond as listed (three
#: numbers), and which end is LAMMPS's particle 1 (the fourth: +1 the bond's
#: first atom, -1 its second), both taken with the reference length
REFERENCE_DIRECTION = "r0_dir"
#: where the fourth number says so, the first atom is particle 1
FIRST_IS_ONE, SECOND_IS_ONE = 1.0, -1.0


#: how far from the identity (largest of i, j, k) an orientation may be where a
#: bond takes its reference state before RotatedReferenceWarning is given
TURNED = 1e-12


class RotatedReferenceWarning(UserWarning):
    """Rotational bonds take their reference state between particles turned
    away from the identity orientation: they start bent, twisted and sheared
    (LAMMPS 22 Jul 2025 keeps the reference direction in the laboratory
    frame and measures the bond in the particles' frames)."""


def _warn_turned(q1_bq, q2_bq, p1_b, p2_b) -> None:
    """:class:`RotatedReferenceWarning` where bonds take their reference
    state between particles turned away from the identity."""
    turn_b = np.maximum(np.abs(q1_bq[:, 1:]).max(axis=1), np.abs(q2_bq[:, 1:]).max(axis=1))
    turned = turn_b > TURNED
    if not turned.any():
        return
    b = int(np.argmax(turn_b))
    atom = int(p1_b[b] if np.abs(q1_bq[b, 1:]).max() >= np.abs(q2_bq[b, 1:]).max() else p2_b[b])
    degrees = np.degrees(2.0 * np.arcsin(min(1.0, float(np.linalg.norm(
        (q1_bq if atom == p1_b[b] else q2_bq)[b, 1:])))))
    warnings.warn(
        f"bpm/rotational: {int(turned.sum())} bonds take their reference state between "
        f"particles turned away from the identity orientation (the most: atom {atom}, "
        f"{degrees:.3g} degrees): they start bent, twisted and sheared, as in LAMMPS 22 Jul "
        "2025, which keeps the reference direction in the laboratory frame and measures "
        "the bond in the particles' frames (a body turned as a whole is strained too).  "
        'Set atoms.arrays["quat"] to the identity (or delete it) before the first '
        "evaluation, as atom_style bpm/sphere gives every particle it reads",
        RotatedReferenceWarning, stacklevel=outside_stacklevel())


class RotationalForces(NamedTuple):
    """One evaluation of rotational bonds, as LAMMPS names the parts (per bond,
    before breaking and smoothing)."""

    f_bc: np.ndarray  # force on particle 2 from particle 1 (LAMMPS force1on2), with damping
    fd_bc: Optional[np.ndarray]  # its damping part (None: undamped)
    t12_bc: np.ndarray  # torque on particle 2 (torque1on2), with damping
    t21_bc: np.ndarray  # torque on particle 1 (torque2on1), with damping
    td12_bc: Optional[np.ndarray]  # the damping parts of the two torques
    td21_bc: Optional[np.ndarray]
    breaking_b: np.ndarray  # B, the breaking measure (>= 0)
    normal_b: np.ndarray  # F_r, the elastic normal force (positive: stretched)


def _cross(a, b):
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
                     a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=-1)


def _dot(a, b):
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _unit(v):
    """``v`` over its length; zero vectors stay zero (LAMMPS ``norm3``)."""
    length2 = _dot(v, v)
    scale = np.divide(1.0, np.sqrt(length2), out=np.zeros_like(length2), where=length2 > 0)
    return v * scale[:, None]


def _arccos(c):
    return np.arccos(np.clip(c, -1.0, 1.0))


def rotational_bonds(r_bc, r0_b, r0_bc, q1_bq, q2_bq, c, normalize=False,
                     v12_bc=None, w1_bc=None, w2_bc=None) -> RotationalForces:
    """The forces and torques of rotational bonds in LAMMPS's convention.

    ``r_bc = x_1 - x_2``; ``r0_b``, ``r0_bc``: the reference length and unit
    direction (same sense); ``q1_bq``, ``q2_bq``: the two orientations;
    ``c``: the coefficients by name (one value per bond); ``v12_bc = v_1 -
    v_2``, ``w1_bc``, ``w2_bc``: velocities and angular velocities, or None
    for an undamped evaluation."""
    nb = len(r_bc)
    r_b = np.sqrt(_dot(r_bc, r_bc))
    rinv_b = 1.0 / r_b
    r0inv_b = 1.0 / r0_b
    kr_b, ks_b = c["k_r"], c["k_s"]
    if normalize:
        kr_b, ks_b = kr_b * r0inv_b, ks_b * r0inv_b
    r0v_bc = r0_bc * r0_b[:, None]

    # stretching and shear, in particle 2's frame
    q2inv_bq = conjugate(q2_bq)
    rb_bc = rotate(q2inv_bq, r_bc)
    fr_b = kr_b * (r_b - r0_b)
    f_rot_bc = rb_bc * (fr_b * rinv_b)[:, None]
    gamma_b = _arccos(_dot(r0v_bc, rb_bc) * rinv_b * r0inv_b)
    s_bc = _unit(_cross(rb_bc, _cross(rb_bc, r0v_bc)))
    fs_bc = s_bc * (ks_b * r_b * gamma_b)[:, None]
    t_bc = _unit(_cross(r0v_bc, rb_bc))
    ts_bc = t_bc * (0.5 * r_b * ks_b * r_b * gamma_b)[:, None]

    # the quaternion turning z onto the bond (Wang and Mora's X'Y'Z' rotations)
    mq_bq = np.zeros((nb, 4))
    mq_bq[:, 0] = HALF_SQRT2 * np.sqrt(np.maximum(r_b + rb_bc[:, 2], 0.0) * rinv_b)
    in_xy_b = np.sqrt(rb_bc[:, 0] * rb_bc[:, 0] + rb_bc[:, 1] * rb_bc[:, 1])
    tilted = in_xy_b != 0.0  # (else along z: no x, y terms)
    m1_b = np.zeros(nb)
    m1_b[tilted] = -HALF_SQRT2 / in_xy_b[tilted]
    m1_b *= np.sqrt(np.maximum(r_b - rb_bc[:, 2], 0.0) * rinv_b)
    mq_bq[:, 1] = m1_b * rb_bc[:, 1]
    mq_bq[:, 2] = -m1_b * rb_bc[:, 0]

    # the relative rotation in that frame: twist psi about z, bend theta
    q21_bq = multiply(multiply(conjugate(mq_bq), multiply(q2inv_bq, q1_bq)), mq_bq)
    a0, a1, a2, a3 = q21_bq[:, 0], q21_bq[:, 1], q21_bq[:, 2], q21_bq[:, 3]
    out_b = np.sqrt(a0 * a0 + a3 * a3)
    psi_b = np.where(out_b != 0.0, 2.0 * _arccos(np.divide(a0, out_b, out=np.zeros(nb),
                                                          where=out_b != 0.0)), 0.0)
    psi_b = np.where(a3 < 0.0, -psi_b, psi_b)
    psi_b = np.where(a3 == 0.0, 0.0, psi_b)
    theta_b = _arccos(a0 * a0 - a1 * a1 - a2 * a2 + a3 * a3)
    mag_out_b, mag_in_b = a0 * a0 + a3 * a3, a1 * a1 + a2 * a2
    cos_phi_b, sin_phi_b = np.zeros(nb), np.zeros(nb)
    flat = (mag_in_b != 0.0) & (mag_out_b == 0.0)  # (no rotation in the plane: 0, 0)
    root_b = np.sqrt(mag_in_b[flat])
    cos_phi_b[flat], sin_phi_b[flat] = a2[flat] / root_b, -a1[flat] / root_b
    general = (mag_in_b != 0.0) & (mag_out_b != 0.0)
    root_b = np.sqrt(mag_out_b[general] * mag_in_b[general])
    g = general
    cos_phi_b[g] = (a1[g] * a3[g] + a0[g] * a2[g]) / root_b
    sin_phi_b[g] = (a2[g] * a3[g] - a0[g] * a1[g]) / root_b

    kb_theta_b = c["k_b"] * theta_b
    zero_b = np.zeros(nb)
    tbp_bc = np.stack([-kb_theta_b * sin_phi_b, kb_theta_b * cos_phi_b, zero_b], axis=-1)
    ttp_bc = np.stack([zero_b, zero_b, c["k_t"] * psi_b], axis=-1)
    fsp_bc = np.stack([-0.5 * ks_b * r_b * theta_b * cos_phi_b,
                       -0.5 * ks_b * r_b * theta_b * sin_phi_b, zero_b], axis=-1)
    tsp_bc = np.stack([0.25 * ks_b * r_b * r_b * theta_b * sin_phi_b,
                       -0.25 * ks_b * r_b * r_b * theta_b * cos_phi_b, zero_b], axis=-1)
    fs_bc = fs_bc + rotate(mq_bq, fsp_bc)
    ts_bc = ts_bc + rotate(mq_bq, tsp_bc)
    tb_bc = rotate(mq_bq, tbp_bc)
    tt_bc = rotate(mq_bq, ttp_bc)

    f12_bc = rotate(q2_bq, f_rot_bc + fs_bc)
    t12_bc = rotate(q2_bq, ts_bc + tt_bc + tb_bc)
    t21_bc = rotate(q2_bq, ts_bc - tt_bc - tb_bc)

    def length(v):
        return np.sqrt(_dot(v, v))

    breaking_b = np.maximum(fr_b / c["f_rc"] + length(fs_bc) / c["f_sc"]
                            + length(tb_bc) / c["tau_bc"] + length(tt_bc) / c["tau_tc"], 0.0)

    fd_bc = td12_bc = td21_bc = None
    if v12_bc is not None:
        fd_bc, td12_bc, td21_bc = rotational_damping(r_bc, rinv_b, c, v12_bc, w1_bc, w2_bc)
        f12_bc = f12_bc + fd_bc
        t12_bc = t12_bc + td12_bc
        t21_bc = t21_bc + td21_bc
    return RotationalForces(f12_bc, fd_bc, t12_bc, t21_bc, td12_bc, td21_bc, breaking_b, fr_b)


def rotational_damping(r_bc, rinv_b, c, v12_bc, w1_bc, w2_bc) -> tuple:
    """The damping force on particle 2 and torques on 2 and 1 (LAMMPS's
    ``damping_forces``): normal and sliding velocities, rolling and twisting
    angular velocities, each against its coefficient."""
    rhat_bc = r_bc * rinv_b[:, None]
    vn_b = _dot(v12_bc, rhat_bc)  # (v_1 - v_2) . n
    vn12_bc = rhat_bc * vn_b[:, None]
    f_bc = vn12_bc * c["gamma_n"][:, None]
    half_vt21_bc = 0.5 * ((-v12_bc) - (-vn12_bc))  # (v_t2 - v_t1) / 2
    s1_bc = -0.5 * _cross(w1_bc, r_bc) - half_vt21_bc
    s2_bc = 0.5 * _cross(w2_bc, r_bc) + half_vt21_bc
    slide_bc = (s1_bc - s2_bc) * c["gamma_s"][:, None]
    f_bc = f_bc + slide_bc
    t_slide_bc = 0.5 * _cross(r_bc, slide_bc)
    roll_bc = _cross(r_bc, _cross(w1_bc, rhat_bc) - _cross(w2_bc, rhat_bc))
    roll_bc = roll_bc * (0.5 * c["gamma_r"])[:, None]
    twist_bc = (rhat_bc * _dot(w1_bc, rhat_bc)[:, None] - rhat_bc * _dot(w2_bc, rhat_bc)[:, None])
    twist_bc = twist_bc * (0.5 * c["gamma_t"])[:, None]
    t12_bc = t_slide_bc + roll_bc + twist_bc
    t21_bc = t_slide_bc - roll_bc - twist_bc
    return f_bc, t12_bc, t21_bc


@register
class RotationalBond(BondLaw):
    """``bond_style bpm/rotational``: ``bond_coeff t k_r k_s k_t k_b f_rc
    f_sc tau_tc tau_bc gamma_n gamma_s gamma_r gamma_t``.

    Stiffnesses: ``k_r`` normal and ``k_s`` shear (force/distance; force
    with ``normalize``), ``k_t`` twisting and ``k_b`` bending
    (force x distance / radian).  Critical values: ``f_rc`` normal and
    ``f_sc`` shear force, ``tau_tc`` twisting and ``tau_bc`` bending torque.
    Damping: ``gamma_n`` normal and ``gamma_s`` sliding (force/velocity),
    ``gamma_r`` rolling and ``gamma_t`` twisting (force x distance x time).

    The order is the one LAMMPS 22 Jul 2025 reads its ``bond_coeff`` line
    in (``BondBPMRotational::coeff``): the twisting critical torque before
    the bending one.  LAMMPS's documentation of ``bond_style
    bpm/rotational`` lists the two the other way round; the source decides.

    The model's ``smooth`` and ``normalize`` switches arrive in ``options``
    (``normalize`` divides ``k_r`` and ``k_s`` by the reference length).
    Particles need an orientation (``atoms.arrays["quat"]``, the identity
    when absent) and, where damped, angular velocities (``omega``).
    """

    name = "bpm/rotational"
    lammps_style = "bpm/rotational"
    coefficients = ("k_r", "k_s", "k_t", "k_b", "f_rc", "f_sc", "tau_tc", "tau_bc",
                    "gamma_n", "gamma_s", "gamma_r", "gamma_t")
    positive = ("f_rc", "f_sc", "tau_tc", "tau_bc")
    non_negative = ("k_r", "k_s", "k_t", "k_b", "gamma_n", "gamma_s", "gamma_r", "gamma_t")
    states = {REFERENCE_DIRECTION: (4,)}
    #: the law gives force vectors and torques (BondForces.f_bc, t_bc),
    #: and needs orientations and angular velocities (BondInput.spins)
    turns = True
    has_energy = False  # (zero, as LAMMPS reports it)
    #: its compiled twin: c/rotational.c (:class:`ase_bpm.laws.compiled.RotationalBonds`),
    #: which passes over type-0 bonds
    compiled = True
    skips_broken = True

    @staticmethod
    def uses_velocities(coeff) -> bool:
        return bool(any(np.any(coeff[name] > 0)
                        for name in ("gamma_n", "gamma_s", "gamma_r", "gamma_t")))

    def prepare(self, scene: BondScene):
        """The C kernel, its arguments for these bonds converted once
        (:class:`ase_bpm.laws.compiled.RotationalBonds`); where bonds take
        their reference state, the orientations are looked at first, as
        :meth:`forces` does (:class:`RotatedReferenceWarning`)."""
        coeff_tc = np.column_stack([scene.coeff_t[name] for name in self.coefficients])
        kernel = compiled.RotationalBonds(scene, coeff_tc, scene.options.get("smooth", True),
                                          scene.options.get("normalize", False),
                                          REFERENCE_DIRECTION)

        def run(scene: BondScene) -> None:
            reference_bq = scene.history[REFERENCE_DIRECTION]
            if kernel._unset(reference_bq):  # (once per history array)
                rows = np.arange(len(scene.i_b)) if scene.select is None else scene.select
                rows = rows[np.isnan(reference_bq[rows, 0])]
                i_b, j_b = scene.i_b[rows], scene.j_b[rows]
                p1_b, p2_b = np.minimum(i_b, j_b), np.maximum(i_b, j_b)
                q_nq = scene.spins["quat"]
                _warn_turned(q_nq[p1_b], q_nq[p2_b], p1_b, p2_b)
            kernel(scene)
        return run

    def add_sums(self, scene: BondScene) -> None:
        self.prepare(scene)(scene)

    def forces(self, bonds: BondInput) -> BondForces:
        """The forces and torques on both ends, as vectors on the first atom
        of each bond as listed (``f_bc``, its opposite on the second) and
        torques on each (``ti_bc``, ``tj_bc``); zero energy (as LAMMPS)."""
        i_b, j_b = bonds.i_b, bonds.j_b
        nb = len(i_b)
        # LAMMPS's particle 1 (smaller ID: smaller index) first; r = x_1 - x_2
        reference_bq = bonds.history[REFERENCE_DIRECTION]
        fresh_b = np.isnan(reference_bq[:, 0])
        if fresh_b.any():  # the reference direction is taken with the length
            reference_bq = reference_bq.copy()  # (times the inverse length, as LAMMPS
            # and the C twin: the shear angle's arccos near 1 turns the last bit of
            # the direction into 1e-8 of a force; the model sums the lengths in order)
            reference_bq[fresh_b, :3] = (bonds.r_bc[fresh_b]
                                         * (1.0 / bonds.r_b[fresh_b])[:, None])
            # LAMMPS's particle 1: the smaller ID, as an export numbers the atoms
            # (the smaller index), kept with the bond: ASE's reordering of the
            # atoms (ase.build.sort, atoms[order]) changes nothing
            reference_bq[fresh_b, 3] = np.where(i_b[fresh_b] < j_b[fresh_b], FIRST_IS_ONE,
                                                SECOND_IS_ONE)
        dir_bc = reference_bq[:, :3]
        first_b = reference_bq[:, 3] == FIRST_IS_ONE
        sense_b = np.where(first_b, -1.0, 1.0)
        r_bc = bonds.r_bc * sense_b[:, None]
        spins = bonds.spins
        p1_b, p2_b = np.where(first_b, i_b, j_b), np.where(first_b, j_b, i_b)
        q_nq = spins["quat"]
        if fresh_b.any():
            _warn_turned(q_nq[p1_b[fresh_b]], q_nq[p2_b[fresh_b]], p1_b[fresh_b],
                         p2_b[fresh_b])
        damped = bonds.v_bc is not None
        out = rotational_bonds(
            r_bc, bonds.r0_b, dir_bc * sense_b[:, None], q_nq[p1_b], q_nq[p2_b], bonds.coeff,
            bonds.options.get("normalize", False),
            v12_bc=bonds.v_bc * sense_b[:, None] if damped else None,
            w1_bc=spins["omega"][p1_b] if damped else None,
            w2_bc=spins["omega"][p2_b] if damped else None)
        w_b = np.ones(nb)
        if bonds.options.get("smooth", True):
            b2_b = out.breaking_b * out.breaking_b
            w_b = 1.0 - b2_b * b2_b
        w_bc = w_b[:, None]
        # on the first atom as listed: particle 1 gets -force1on2, particle 2 +force1on2
        f_bc = out.f_bc * (w_b * sense_b)[:, None]
        ti_bc = np.where(first_b[:, None], out.t21_bc, out.t12_bc) * w_bc
        tj_bc = np.where(first_b[:, None], out.t12_bc, out.t21_bc) * w_bc
        fd_bc = td_i_bc = td_j_bc = None
        if damped:
            fd_bc = out.fd_bc * (w_b * sense_b)[:, None]
            td_i_bc = np.where(first_b[:, None], out.td21_bc, out.td12_bc) * w_bc
            td_j_bc = np.where(first_b[:, None], out.td12_bc, out.td21_bc) * w_bc
        # the force along the bond, on i towards j (bond/local's force)
        f_b = _dot(f_bc, bonds.r_bc) / bonds.r_b
        breaks_b = out.breaking_b >= 1.0 if bonds.breaking else None
        history = {REFERENCE_DIRECTION: reference_bq} if fresh_b.any() else {}
        return BondForces(f_b=f_b, energy_b=np.zeros(nb), breaks_b=breaks_b,
                          fd_b=None if fd_bc is None else _dot(fd_bc, bonds.r_bc) / bonds.r_b,
                          history=history, f_bc=f_bc, fd_bc=fd_bc, ti_bc=ti_bc, tj_bc=tj_bc,
                          tdi_bc=td_i_bc, tdj_bc=td_j_bc)

    def stiffness(self, bonds: BondInput) -> LawStiffness:
        """``k_r`` along the bond and ``k_s`` across it at its midpoint
        (each over ``r0`` with ``normalize``: LAMMPS's shear force ``k_s |r|
        gamma`` is ``k_s`` times the sideways displacement, half of it from
        each sphere's turn), ``k_b`` on the relative rotation across the
        bond and ``k_t`` about it; the dampers ``gamma_n`` along,
        ``gamma_s`` across at the midpoint, rolling ``gamma_r |r| / 2`` and
        twisting ``gamma_t / 2`` (LAMMPS's damping torques on the relative
        angular velocity).  The smoothing factor ``1 - B^4`` is at most 1."""
        c, r_b = bonds.coeff, bonds.r_b
        scale_b = 1.0 / bonds.r0_b if bonds.options.get("normalize", False) else 1.0
        return LawStiffness(c["k_r"] * scale_b, c["gamma_n"], c["k_s"] * scale_b,
                            c["gamma_s"], midpoint=True, kb_x=c["k_b"], ktw_x=c["k_t"],
                            cb_x=0.5 * c["gamma_r"] * r_b, ctw_x=0.5 * c["gamma_t"])
