"""Unit quaternions over arrays: the orientations of ``atom_style bpm/sphere``.

A quaternion is four numbers ``(w, i, j, k)`` in LAMMPS's order, the last axis
of an array (suffix ``_q``: ``q_nq`` per atom, ``q_bq`` per bond).  A unit
quaternion ``q`` turns a vector ``v`` into ``q v q*`` (:func:`rotate`): the
body frame of a particle into the laboratory's.  Each function computes what
LAMMPS's ``MathExtra`` of the same purpose computes, term by term in its
order, so that results agree to round-off.
"""

from __future__ import annotations

import numpy as np

W, I, J, K = 0, 1, 2, 3  # the components, LAMMPS's order
#: the identity: no turn (what atom_style bpm/sphere gives every particle it reads)
IDENTITY = (1.0, 0.0, 0.0, 0.0)
X, Y, Z = 0, 1, 2


def conjugate(q_xq: np.ndarray) -> np.ndarray:
    """``q*``: the inverse of a unit quaternion."""
    out = -q_xq
    out[..., W] = q_xq[..., W]
    return out


def multiply(a_xq: np.ndarray, b_xq: np.ndarray) -> np.ndarray:
    """The product ``a b``."""
    a0, a1, a2, a3 = (a_xq[..., m] for m in (W, I, J, K))
    b0, b1, b2, b3 = (b_xq[..., m] for m in (W, I, J, K))
    return np.stack([a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
                     a0 * b1 + b0 * a1 + a2 * b3 - a3 * b2,
                     a0 * b2 + b0 * a2 + a3 * b1 - a1 * b3,
                     a0 * b3 + b0 * a3 + a1 * b2 - a2 * b1], axis=-1)


def vector_times(v_xc: np.ndarray, q_xq: np.ndarray) -> np.ndarray:
    """The product ``(0, v) q`` of a vector taken as a pure quaternion."""
    a0, a1, a2 = (v_xc[..., c] for c in (X, Y, Z))
    b0, b1, b2, b3 = (q_xq[..., m] for m in (W, I, J, K))
    return np.stack([-a0 * b1 - a1 * b2 - a2 * b3,
                     b0 * a0 + a1 * b3 - a2 * b2,
                     b0 * a1 + a2 * b1 - a0 * b3,
                     b0 * a2 + a0 * b2 - a1 * b1], axis=-1)


def rotate(q_xq: np.ndarray, v_xc: np.ndarray) -> np.ndarray:
    """``q v q*``: the vectors ``v`` turned by the unit quaternions ``q``."""
    a0, a1, a2, a3 = (q_xq[..., m] for m in (W, I, J, K))
    b0, b1, b2 = (v_xc[..., c] for c in (X, Y, Z))
    t0 = -a1 * b0 - a2 * b1 - a3 * b2  # q (0, v)
    t1 = a0 * b0 + a2 * b2 - a3 * b1
    t2 = a0 * b1 + a3 * b0 - a1 * b2
    t3 = a0 * b2 + a1 * b1 - a2 * b0
    return np.stack([-a1 * t0 + a0 * t1 - a3 * t2 + a2 * t3,  # (q (0, v)) q*
                     -a2 * t0 + a3 * t1 + a0 * t2 - a1 * t3,
                     -a3 * t0 - a2 * t1 + a1 * t2 + a0 * t3], axis=-1)


def normalised(q_xq: np.ndarray) -> np.ndarray:
    """Each quaternion divided by its norm (times the inverse norm, as LAMMPS)."""
    inverse_x = 1.0 / np.sqrt(q_xq[..., W] * q_xq[..., W] + q_xq[..., I] * q_xq[..., I]
                              + q_xq[..., J] * q_xq[..., J] + q_xq[..., K] * q_xq[..., K])
    return q_xq * inverse_x[..., None]


def turned(q_nq: np.ndarray, w_nc: np.ndarray, dt: float) -> np.ndarray:
    """The orientations ``q`` after turning for ``dt`` at the angular
    velocities ``w`` (laboratory frame): ``dq/dt = (0, w) q / 2`` integrated
    by Richardson's extrapolation as LAMMPS ``fix nve/bpm/sphere`` does (a
    full step and two half steps of the first-order update, each
    normalised; twice the two halves minus the full, normalised)."""
    dtq = 0.5 * dt
    wq_nq = vector_times(w_nc, q_nq)
    full_nq = normalised(q_nq + dtq * wq_nq)
    half_nq = normalised(q_nq + 0.5 * dtq * wq_nq)
    half_nq = normalised(half_nq + 0.5 * dtq * vector_times(w_nc, half_nq))
    return normalised(2.0 * half_nq - full_nq)
