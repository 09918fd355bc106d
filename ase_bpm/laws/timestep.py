"""The largest stable timestep of velocity Verlet on springs and dampers.

Model-independent and pure: functions over arrays.  Each law says what its
bonds or contacts are as linear springs and dampers (:class:`Springs`); this
module bounds the fastest mode they make and turns it into a timestep.

**One damped mode.**  Velocity Verlet as LAMMPS' ``fix nve`` and
:class:`ase_bpm.VelocityVerlet` run it evaluates the damping force with
the half-step velocity.  On ``x'' = -w^2 x - c x'`` one step maps
``(x_n, v_{n-1/2})`` with trace ``2 - (w dt)^2 - c dt`` and determinant
``1 - c dt``; both eigenvalues stay in the unit circle (Jury's conditions)
exactly while ``(w dt)^2 + 2 c dt <= 4``, that is up to

    dt = 4 / (c + sqrt(c^2 + 4 w^2)) = (2 / w) (sqrt(1 + z^2) - z),  z = c / (2 w)

(:func:`damped_limit`): ``2/w`` without damping, ``2/c`` for a damper
alone.  It falls with ``w`` and with ``c``.

**Many bodies, a per-node bound.**  A spring between the points ``a`` and
``b`` of two bodies stores ``(d_a - d_b)^T W (d_a - d_b) / 2`` with ``W``
positive semi-definite (stiffness ``k`` along the unit vector ``n``, ``k_t``
across it), and ``(d_a - d_b)^T W (d_a - d_b) <= 2 (d_a^T W d_a + d_b^T W
d_b)``.  So the stiffness matrix is bounded by its per-node diagonal blocks
taken ``COUPLING = 2`` times, and the largest squared frequency of the whole
network by the largest eigenvalue of any one node's block over its mass:

    w_max^2 <= max_n  lambda_max( M_n^-1/2  sum_(x at n) q_x B_x^T W_x B_x  M_n^-1/2 )

with ``q_x = 2`` for a spring between two moving nodes and ``q_x = 1`` where
the partner cannot move (a wall, an atom held by ``FixAtoms``: there the
term is exact).  ``B_x`` maps the node's motion to that of its end of the
spring: the identity for point particles, ``[I, -[r]_x]`` for a sphere with
lever arm ``r`` from its centre to the contact point, whose mass matrix is
``diag(m, m, m, I, I, I)``.  A node's own block alone already has frequency
``lambda_max`` (displace that node only), so the bound lies within a factor 2
of ``w_max^2``: the timestep within ``sqrt 2`` of the limit.  For two equal
spheres it is exact: ``k / m_eff`` for the normal mode and
``(1 + m r^2 / I) k_t / m_eff = 3.5 k_t / m_eff`` for the tangential-rotational
mode of solid spheres (O'Sullivan and Bray 2004 show that the rotations of
DEM spheres lower the critical timestep this way).  Measured on the README's
jittered FCC block (500 particles, 2,604 bonds within 1.5, k = 1, unit
masses): the largest ``w^2`` is 8.82, this bound 10.83, a Gershgorin row sum
16.0.

Damping is bounded the same way (``c``: the largest eigenvalue of the
per-node blocks of the damping matrices over the masses), and the two bounds
combine conservatively, as the largest ``w`` with the largest ``c``:
:func:`damped_limit` falls with both.  Where damping is proportional to
stiffness (``bpm/spring``: ``gamma`` along the bond like ``k``) every mode has
``c = (gamma/k) w^2`` and this is the exact per-mode limit at the bound.

**Safety.**  The bound holds for the springs of the configuration given: the
linearised forces, the contacts present, Hertzian stiffness at the overlaps
now.  Contacts that form later, overlaps that grow and bonds that stiffen are
not in it; :data:`SAFETY` (0.9, the default scale factor of explicit
finite-element codes such as LS-DYNA's ``TSSFAC``) leaves room for them.  It
is a stability limit, not an accuracy target: velocity Verlet's energy error
grows as ``(w dt)^2`` long before it (issue 15 measured on a 576-particle
block: the energy ledger off by 3 % at a third of the limit, 13 % at two
thirds).

Sources: the damped limit from the one-step map above (checked against its
eigenvalues); O'Sullivan C. and Bray J. D., Engineering Computations 21,
278-303 (2004) and Otsubo M., O'Sullivan C. and Shire T., Computers and
Geotechnics 86, 67-79 (2017) for critical timesteps of DEM with rotations
and many contacts; Burns S. J. and Hanley K. J., Int. J. Numer. Meth. Engng
110, 186-200 (2017) for the effect of damping; Silling S. A. and Askari E.,
Computers and Structures 83, 1526-1535 (2005) for the bond-based peridynamic
estimate, a row-sum bound that this one tightens.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable, Optional, Sequence

import numpy as np

#: the estimate is this fraction of the bound on the stability limit
SAFETY = 0.9
#: weight of a spring between two moving nodes in each node's block (see module doc)
COUPLING = 2.0
#: nodes per piece of :func:`largest_rates`: the scaled blocks (and LAPACK's
#: copies of them) are made for one piece at a time (at a million nodes, all
#: at once, they took 0.17 GB for a moment)
RATES_PIECE = 2 ** 16


def damped_limit(w, c):
    """The largest stable timestep of velocity Verlet, with the damping force
    at the half-step velocity, for a mode of angular frequency ``w`` and
    damping rate ``c`` (force per velocity per mass; damping ratio
    ``z = c / (2 w)``): ``4 / (c + sqrt(c^2 + 4 w^2))``, which is
    ``(2/w)(sqrt(1 + z^2) - z)``.  ``inf`` when both are zero."""
    w, c = np.asarray(w, dtype=float), np.asarray(c, dtype=float)
    denominator = c + np.sqrt(c * c + 4.0 * w * w)
    with np.errstate(divide="ignore"):
        out = np.where(denominator > 0, 4.0 / np.where(denominator > 0, denominator, 1.0),
                       np.inf)
    return out[()] if out.ndim == 0 else out


@dataclass(frozen=True)
class LawStiffness:
    """What a bond or pair law says of its bonds or pairs ``x`` for the
    timestep bound (scalars or one value each): ``k_x``, the stiffness along
    the pair (force/distance), at least the tangent ``dF/dr`` of the law;
    ``c_x``, the damping coefficient along it (force/velocity); ``kt_x``, the
    stiffness across it, the tension over the length (``F/r`` where the pair
    pulls, else 0), or a tangential spring; ``ct_x``, a tangential damper.

    Bonds that turn the spheres (``bpm/rotational``) say more: ``midpoint``,
    the spring and damper across act at the bond's midpoint (lever arms of
    half the bond from each centre), and springs and dampers on the relative
    rotation of the two spheres, ``kb_x`` and ``cb_x`` about the axes across
    the bond (bending, rolling), ``ktw_x`` and ``ctw_x`` about the bond
    (twisting): torque per radian, torque per angular velocity."""

    k_x: object
    c_x: object = 0.0
    kt_x: object = 0.0
    ct_x: object = 0.0
    midpoint: bool = False
    kb_x: object = 0.0
    ktw_x: object = 0.0
    cb_x: object = 0.0
    ctw_x: object = 0.0


@dataclass(frozen=True)
class Springs:
    """Bonds or contacts as linear springs and dampers, one row ``x`` each.

    ``i_x`` and ``j_x`` are the two nodes (``j_x`` None: the partner is fixed,
    e.g. a wall); ``n_xc`` the unit vector between them; ``k_x`` the stiffness
    along ``n`` (force/distance: at least the tangent ``dF/dr``), ``kt_x`` the
    one across it; ``c_x`` and ``ct_x`` the damping coefficients along and
    across (force/velocity).  ``arm_i_xc``, ``arm_j_xc``: lever arms from each
    centre to the contact point of spheres that turn (None: point particles,
    or the spring acts at the centre).  ``kb_x``, ``ktw_x``, ``cb_x``,
    ``ctw_x``: springs and dampers on the relative rotation of the two
    spheres, across ``n`` and about it (:class:`LawStiffness`).
    Coefficients may be scalars.
    """

    i_x: np.ndarray
    j_x: Optional[np.ndarray]
    n_xc: np.ndarray
    k_x: object = 0.0
    kt_x: object = 0.0
    c_x: object = 0.0
    ct_x: object = 0.0
    arm_i_xc: Optional[np.ndarray] = None
    arm_j_xc: Optional[np.ndarray] = None
    kb_x: object = 0.0
    ktw_x: object = 0.0
    cb_x: object = 0.0
    ctw_x: object = 0.0

    def __len__(self) -> int:
        return len(self.i_x)

    @property
    def turning(self) -> bool:
        """Do the springs act on the rotation of spheres?"""
        return (self.arm_i_xc is not None or self.arm_j_xc is not None
                or any(np.any(v) for v in (self.kb_x, self.ktw_x, self.cb_x, self.ctw_x)))

    def pieces(self):
        """The springs in pieces (:class:`SpringPieces`): here one, all of them."""
        return (self,)


class SpringPieces:
    """Springs between point particles, made one piece at a time.

    ``make()`` gives a fresh iterable of :class:`Springs` (or None for a
    piece without springs), ``count`` springs in all.  :func:`node_blocks`
    adds each piece to the blocks and drops it before the next is made, so
    the per-spring arrays (unit vectors, coefficients) of one piece live at a
    time, not those of every bond of a large body at once.  ``turning``: the
    springs of the pieces may turn spheres (else they act between centres).
    """

    def __init__(self, make: Callable[[], Iterable[Optional[Springs]]], count: int,
                 turning: bool = False):
        self.make, self.count, self.turning = make, count, turning

    def __len__(self) -> int:
        return self.count

    def pieces(self):
        return self.make()


def _cross_matrices(r_xc: np.ndarray) -> np.ndarray:
    """``[r]_x`` (x, 3, 3): ``[r]_x v = r x v``."""
    out = np.zeros((len(r_xc), 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -r_xc[:, 2], r_xc[:, 1]
    out[:, 1, 0], out[:, 1, 2] = r_xc[:, 2], -r_xc[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -r_xc[:, 1], r_xc[:, 0]
    return out


def _end_blocks(n_xc, along, across, arm_xc, dof: int, turn_across=0.0,
                turn_along=0.0) -> np.ndarray:
    """``B^T W B`` (x, dof, dof) of one end of each spring, ``W = across I +
    (along - across) n n^T``, ``B = [I, -[arm]_x]`` (or ``I`` for 3 DOFs),
    plus on the rotation ``turn_across (I - n n^T) + turn_along n n^T`` (a
    spring on the relative rotation of the two spheres)."""
    nx = len(n_xc)
    along = np.broadcast_to(np.asarray(along, dtype=float), (nx,))
    across = np.broadcast_to(np.asarray(across, dtype=float), (nx,))
    w_xcc = (along - across)[:, None, None] * n_xc[:, :, None] * n_xc[:, None, :]
    w_xcc[:, [0, 1, 2], [0, 1, 2]] += across[:, None]
    if dof == 3:
        return w_xcc
    out = np.zeros((nx, 6, 6))
    out[:, :3, :3] = w_xcc
    if arm_xc is not None:
        # with A = [arm]_x, u = arm x n (so n^T A = -u^T) and A^2 = arm arm^T
        # - |arm|^2 I, in closed form (no products of 3 x 3 matrices):
        # W B_rot = -W A = -across A + (along - across) n u^T, and
        # B_rot^T W B_rot = A^T W A = across (|arm|^2 I - arm arm^T) + (along - across) u u^T
        radial = (along - across)[:, None, None]
        u_xc = np.cross(arm_xc, n_xc)
        wa = radial * n_xc[:, :, None] * u_xc[:, None, :]
        wa -= across[:, None, None] * _cross_matrices(arm_xc)
        out[:, :3, 3:] = wa
        out[:, 3:, :3] = np.transpose(wa, (0, 2, 1))
        rot = radial * u_xc[:, :, None] * u_xc[:, None, :]
        rot -= across[:, None, None] * arm_xc[:, :, None] * arm_xc[:, None, :]
        rot[:, [0, 1, 2], [0, 1, 2]] += (across * np.einsum("xc,xc->x", arm_xc, arm_xc))[:, None]
        out[:, 3:, 3:] = rot
    if np.any(turn_across) or np.any(turn_along):
        turn_across = np.broadcast_to(np.asarray(turn_across, dtype=float), (nx,))
        turn_along = np.broadcast_to(np.asarray(turn_along, dtype=float), (nx,))
        out[:, 3:, 3:] += (turn_along - turn_across)[:, None, None] * n_xc[:, :, None] \
            * n_xc[:, None, :]
        out[:, [3, 4, 5], [3, 4, 5]] += turn_across[:, None]
    return out


def lower_entries(dof: int) -> tuple:
    """``(rows, cols)`` of the lower triangle of a dof x dof block, in the
    order in which :func:`node_blocks` packs it (``np.tril_indices``)."""
    return np.tril_indices(dof)


def _entry(dof: int, row: int, col: int) -> int:
    """Where the entry ``(row, col)``, ``row >= col``, of a block is packed."""
    return row * (row + 1) // 2 + col


def _add_point_blocks(blocks_ne, node_x, n_xc, along, across, weight_x) -> None:
    """``blocks_ne[node] += weight W`` (packed lower triangles) for spring
    ends on point particles, ``W = across I + (along - across) n n^T``: its
    six distinct sums over the ends and the isotropic one (no per-end 3x3
    blocks)."""
    natoms = len(blocks_ne)
    nx = len(n_xc)
    along = np.broadcast_to(np.asarray(along, dtype=float), (nx,))
    across = np.broadcast_to(np.asarray(across, dtype=float), (nx,))
    radial_x = weight_x * (along - across)
    iso_n = np.bincount(node_x, weight_x * across, minlength=natoms)
    for a in range(3):
        blocks_ne[:, _entry(3, a, a)] += iso_n
        for b in range(a, 3):
            blocks_ne[:, _entry(3, b, a)] += np.bincount(
                node_x, radial_x * n_xc[:, a] * n_xc[:, b], minlength=natoms)


def node_blocks(springs: Sequence, natoms: int, dof: int = 3,
                hold_n: Optional[np.ndarray] = None) -> tuple:
    """Per-node blocks ``(K_n, C_n)`` of the stiffness and damping of
    ``springs`` (:class:`Springs` or :class:`SpringPieces`, added in order,
    piece by piece), each spring end weighted by :data:`COUPLING` (1 where
    the partner is fixed or held in ``hold_n``); ends at held nodes are left
    out.  The blocks are symmetric: each is packed as its lower triangle,
    ``_ne`` (natoms, dof (dof + 1) / 2 entries) in the order of
    :func:`lower_entries` (at a million atoms the full blocks took 48 MB
    more)."""
    rows, cols = lower_entries(dof)
    k_ne = np.zeros((natoms, len(rows)))
    c_ne = np.zeros((natoms, len(rows)))
    for s in (piece for group in springs for piece in group.pieces()):
        if s is None or len(s) == 0:
            continue
        ends = [(s.i_x, s.arm_i_xc, s.j_x)]
        if s.j_x is not None:
            ends.append((s.j_x, s.arm_j_xc, s.i_x))
        for node_x, arm_xc, partner_x in ends:
            weight_x = np.full(len(s), COUPLING if partner_x is not None else 1.0)
            if hold_n is not None:
                if partner_x is not None:
                    weight_x[hold_n[partner_x]] = 1.0
                weight_x[hold_n[node_x]] = 0.0
            # the sums run over the nodes from the lowest to the highest this
            # piece touches, not over every node (the bonds of a piece of a
            # large body touch few of its atoms: summed over all a million, a
            # piece's sums made the estimate 7 s); the same sums, bit for bit
            nodes = slice(int(node_x.min()), int(node_x.max()) + 1)
            local_x = node_x - nodes.start
            for blocks, along, across, turn_across, turn_along in (
                    (k_ne, s.k_x, s.kt_x, s.kb_x, s.ktw_x),
                    (c_ne, s.c_x, s.ct_x, s.cb_x, s.ctw_x)):
                if not any(np.any(v) for v in (along, across, turn_across, turn_along)):
                    continue
                if dof == 3:  # W alone, summed as its isotropic and n n^T parts
                    _add_point_blocks(blocks[nodes], local_x, s.n_xc, along, across,
                                      weight_x)
                    continue
                part = _end_blocks(s.n_xc, along, across, arm_xc, dof, turn_across,
                                   turn_along) * weight_x[:, None, None]
                for t, (row, col) in enumerate(zip(rows, cols)):
                    blocks[nodes, t] += np.bincount(local_x, part[:, row, col],
                                                    minlength=nodes.stop - nodes.start)
    return k_ne, c_ne


def largest_rates(blocks_ne: np.ndarray, m_n: np.ndarray,
                  inertia_n: Optional[np.ndarray] = None,
                  nodes: Optional[np.ndarray] = None) -> np.ndarray:
    """``lambda_max(M_n^-1/2 B_n M_n^-1/2)`` per node: the largest squared
    frequency (stiffness blocks) or damping rate (damping blocks), with
    ``M_n = diag(m, m, m[, I, I, I])`` and ``B_n`` packed as
    :func:`node_blocks` gives it; of the nodes ``nodes`` (indices into the
    three arrays; None: all), in pieces of :data:`RATES_PIECE` nodes (each
    node's value is the same whatever the pieces)."""
    dof = int(np.sqrt(2 * blocks_ne.shape[-1]))  # 2 entries = dof^2 + dof
    rows, cols = lower_entries(dof)
    count = len(blocks_ne) if nodes is None else len(nodes)
    rates = np.zeros(count)
    for start in range(0, count, RATES_PIECE):
        piece = slice(start, min(start + RATES_PIECE, count))
        if nodes is not None:
            piece = nodes[piece]
        scale_nd = np.repeat(1.0 / np.sqrt(m_n[piece])[:, None], dof, axis=1)
        if dof == 6:
            scale_nd[:, 3:] = 1.0 / np.sqrt(inertia_n[piece])[:, None]
        # the lower triangles, which alone eigvalsh reads (UPLO "L")
        block_ndd = np.zeros((len(scale_nd), dof, dof))
        block_ndd[:, rows, cols] = blocks_ne[piece]
        scaled = block_ndd * scale_nd[:, :, None] * scale_nd[:, None, :]
        rates[start:start + len(scaled)] = np.linalg.eigvalsh(scaled, UPLO="L")[:, -1]
    return rates


def stable_timestep(springs: Sequence[Springs], m_n: np.ndarray,
                    inertia_n: Optional[np.ndarray] = None,
                    hold_n: Optional[np.ndarray] = None, safety: float = SAFETY) -> float:
    """``safety`` times :func:`damped_limit` at the per-node bounds of the
    largest frequency and damping rate of ``springs`` on nodes of masses
    ``m_n`` (and moments of inertia ``inertia_n``, needed when some springs
    turn spheres); nodes in ``hold_n`` do not move.  ``inf`` without springs."""
    return stiffest(springs, m_n, inertia_n, hold_n, safety)[0]


def stiffest(springs: Sequence[Springs], m_n: np.ndarray,
             inertia_n: Optional[np.ndarray] = None,
             hold_n: Optional[np.ndarray] = None, safety: float = SAFETY) -> tuple:
    """``(dt, node)``: :func:`stable_timestep` and the node with the largest
    frequency bound (None without springs)."""
    springs = [s for s in springs if s is not None and len(s)]
    natoms = len(m_n)
    if not springs or natoms == 0:
        return float("inf"), None
    turning = any(s.turning for s in springs)
    if turning and inertia_n is None:
        raise ValueError("springs that turn spheres need the moments of inertia")
    k_ne, c_ne = node_blocks(springs, natoms, 6 if turning else 3, hold_n)
    moving = None if hold_n is None else np.flatnonzero(~hold_n)  # (indices: no copies)
    w2 = largest_rates(k_ne, m_n, inertia_n, moving)
    c = largest_rates(c_ne, m_n, inertia_n, moving)
    if len(w2) == 0:
        return float("inf"), None
    w_max = np.sqrt(max(float(w2.max()), 0.0))
    node = int(np.argmax(w2)) if moving is None else int(moving[int(np.argmax(w2))])
    return float(safety * damped_limit(w_max, max(float(c.max()), 0.0))), node
