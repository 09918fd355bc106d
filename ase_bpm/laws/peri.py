"""Peridynamic bond laws: LAMMPS PERI models (pmb, lps, ves, eps) as bonds.

Pure functions over arrays, no ASE and no state.  Forces are *true* forces
(the legacy PERI styles compute force densities; node ``i`` gets ``V_i`` times
that), so a bond between nodes of volumes ``V_i`` and ``V_j`` carries the
factor ``V_i V_j`` following the legacy styles, or the square of their mean
volume following ``bond_style bpm/peri`` (:func:`volume_product`).

Conventions: bond ``b`` joins ``i_b`` and ``j_b``; ``dr_b = r_b - r0_b`` its
extension; ``scale_b`` the partial-volume factor (:func:`partial_volume`).
Bond forces are returned as magnitudes along the bond direction, positive when
pulling the two nodes together: ``fi_b`` on ``i`` (towards ``j``) and ``fj_b``
on ``j`` (towards ``i``).  For pmb and lps ``fi_b == fj_b``; ves and eps, like
the legacy styles, use each end's own dilatation and history, so the two ends
differ where the dilatation varies.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple, Optional

import numpy as np

from . import compiled
from .bond import BondForces, BondInput, BondLaw, BondScene, register
from .contact import PairForces, PairInput, PairLaw, register_contact
from .timestep import LawStiffness

NEAR_ZERO = 2.2204e-16  # extensions below this count as zero (legacy PERI)

#: which LAMMPS BPMPeri follows (its ``follows``): ``bond_style bpm/peri`` +
#: ``pair_style bpm/peri`` (LAMMPS 2026, the default), or the legacy
#: ``peri/pmb``, ``peri/lps``, ``peri/ves`` and ``peri/eps`` pair styles of
#: the reference build (22 Jul 2025); docs/lammps.md lists what differs
BPM_PERI, LEGACY = "bpm/peri", "legacy"
FOLLOWS = (BPM_PERI, LEGACY)
#: what BPMPeri followed before it had the option, which the atoms of such a
#: run (PERI state, no record of what they followed) keep: the legacy styles,
#: but eps returned radially at each bond end by the norm of its trial state
BEFORE_OPTION = "legacy, eps as before the option"
#: what the atoms may record, each with its code in the compiled kernels
#: (``struct peri_bonds``'s ``legacy``)
RECORDED = {BPM_PERI: 0, LEGACY: 1, BEFORE_OPTION: 2}


def volume_product(vi_x, vj_x, legacy: bool) -> np.ndarray:
    """The volume factor of a bond or contact between nodes of volumes
    ``vi_x`` and ``vj_x``, which makes the law's force density a true force:
    ``V_i V_j`` (legacy: node i's force density carries ``V_j``, its force
    ``V_i`` times that), or ``Vbar^2`` with ``Vbar = (V_i + V_j) / 2``
    (``bond_style bpm/peri`` puts the mean volume where legacy has ``V_j``;
    the second factor is that of its virial).  Equal for equal volumes."""
    if legacy:
        return vi_x * vj_x
    mean_x = 0.5 * (vi_x + vj_x)
    return mean_x * mean_x


class PeriForces(NamedTuple):
    fi_b: np.ndarray  # force magnitude on i, towards j
    fj_b: np.ndarray  # force magnitude on j, towards i
    energy: float  # elastic (recoverable) energy
    history: Optional[np.ndarray] = None  # updated per-bond history (ves, eps)
    node: Optional[np.ndarray] = None  # per-node output (eps: plastic multiplier)


def partial_volume(r0_b, horizon_b, spacing: float) -> np.ndarray:
    """Share of the partner's volume a bond sees (linear taper, Silling 2007):
    1 well inside the horizon, falling to 1/2 at it, for bonds whose reference
    length is within half a lattice spacing of the horizon."""
    half = 0.5 * spacing
    taper = (horizon_b + half - r0_b) / spacing
    return np.where(np.abs(r0_b - horizon_b) <= half, taper, 1.0)


#: more lattice spacings than any peridynamic horizon spans in practice (3 is
#: usual): a horizon beyond both them and the bonds is taken as no horizon
MAX_HORIZON_SPACINGS = 20.0


def horizon_fits(horizon: float, longest: float, spacing: float) -> bool:
    """Does ``horizon`` agree with bonds whose longest reference length is
    ``longest``, on a lattice of ``spacing``: at least one spacing, reaching
    the longest bond within the partial-volume taper (half a spacing), and
    not beyond it by a spacing unless the body is smaller than the horizon
    (then at most :data:`MAX_HORIZON_SPACINGS`)?"""
    reaches = longest <= horizon + 0.5 * spacing
    not_beyond = horizon < max(longest + spacing, MAX_HORIZON_SPACINGS * spacing)
    return spacing <= horizon and reaches and not_beyond


def extension(r_b, r0_b) -> np.ndarray:
    """``r - r0``, with round-off-sized values set to zero."""
    dr_b = r_b - r0_b
    dr_b[np.abs(dr_b) < NEAR_ZERO] = 0.0
    return dr_b


def node_sum(i_b, j_b, to_i_b, to_j_b, natoms: int) -> np.ndarray:
    """Per-node sums over bonds: node ``i_b`` gets ``to_i_b``, ``j_b`` gets ``to_j_b``."""
    total = np.zeros(natoms)
    if len(i_b):
        total += np.bincount(i_b, to_i_b, minlength=natoms)
        total += np.bincount(j_b, to_j_b, minlength=natoms)
    return total


def weighted_volume(i_b, j_b, r0_b, scale_b, vol_n) -> np.ndarray:
    """``m_i = sum_j omega |xi|^2 V_j scale`` with ``omega = 1/|xi|``, ``|xi| = r0``."""
    w_b = r0_b * scale_b
    return node_sum(i_b, j_b, w_b * vol_n[j_b], w_b * vol_n[i_b], len(vol_n))


def dilatation(i_b, j_b, dr_b, scale_b, vol_n, m_n) -> np.ndarray:
    """``theta_i = (3/m_i) sum_j omega r0 dr V_j scale`` (zero without bonds)."""
    w_b = dr_b * scale_b
    total = node_sum(i_b, j_b, w_b * vol_n[j_b], w_b * vol_n[i_b], len(vol_n))
    return np.divide(3.0 * total, m_n, out=np.zeros_like(total), where=m_n > 0)


def pmb(dr_b, r0_b, c_b, scale_b, vv_b) -> PeriForces:
    """Prototype microelastic brittle: ``c s scale V_i V_j``, ``s = dr/r0``."""
    f_b = c_b * scale_b * vv_b * (dr_b / r0_b)
    return PeriForces(f_b, f_b, float(0.5 * np.sum(f_b * dr_b)))


def lps(i_b, j_b, dr_b, r0_b, k_b, g_b, scale_b, vv_b, theta_n, m_n, vol_n) -> PeriForces:
    """Linear peridynamic solid (legacy ``peri/lps``), symmetric in i and j.

    ``f = V_i V_j scale [(3K - 5G)(theta_i/m_i + theta_j/m_j)
    + 15 G (1/m_i + 1/m_j) dr / r0]``.  Energy: ``sum_i V_i K theta_i^2 / 2``
    plus ``15 G / (2 m_i) omega (dr - theta_i r0 / 3)^2 V_j scale`` per bond end,
    whose derivative the force is.
    """
    minv_n = np.divide(1.0, m_n, out=np.zeros_like(m_n), where=m_n > 0)
    wt_i, wt_j = theta_n[i_b] * minv_n[i_b], theta_n[j_b] * minv_n[j_b]
    w_sum = minv_n[i_b] + minv_n[j_b]
    a_b = scale_b * vv_b
    f_b = a_b * ((3.0 * k_b - 5.0 * g_b) * (wt_i + wt_j) + 15.0 * g_b * w_sum * dr_b / r0_b)
    # volumetric energy with each node's (mean) bulk modulus
    k_n = _node_mean(i_b, j_b, k_b, len(vol_n))
    energy = 0.5 * np.sum(vol_n * k_n * theta_n * theta_n)
    dev_i = dr_b - theta_n[i_b] * r0_b / 3.0
    dev_j = dr_b - theta_n[j_b] * r0_b / 3.0
    energy += np.sum(7.5 * g_b / r0_b * a_b
                     * (dev_i * dev_i * minv_n[i_b] + dev_j * dev_j * minv_n[j_b]))
    return PeriForces(f_b, f_b, float(energy))


def ves(i_b, j_b, dr_b, r0_b, k_b, g_b, lam_b, tau_b, scale_b, vv_b, theta_n, m_n, vol_n,
        history_b, dt: float, advance: bool, legacy: bool = True) -> PeriForces:
    """Viscoelastic solid.  ``legacy`` (``peri/ves``): each bond end with its
    own dilatation and history; else (``bond_style bpm/peri``) one deviatoric
    extension per bond, with the mean dilatation of its two nodes, and one
    history, so that both ends pull alike.

    ``history_b`` holds, per bond, ``(ed_i, edb_i, ed_j, edb_j)``: deviatoric
    extension and back extension at each end as of the last step (bpm/peri:
    the bond's pair, twice).  With ``advance`` the back extensions take one
    step of ``dt``: ``edb' = ed (1 - d) + edb d + beta (ed_now - ed)``,
    ``d = exp(-dt/tau)``, ``beta = 1 - (tau/dt)(1 - d)``; else the stored
    ones are used as they are.
    """
    minv_n = np.divide(1.0, m_n, out=np.zeros_like(m_n), where=m_n > 0)
    a_b = scale_b * vv_b
    elastic_b = 3.0 * k_b * a_b * (theta_n[i_b] * minv_n[i_b] + theta_n[j_b] * minv_n[j_b])
    gfac_b = 15.0 * g_b * a_b * (minv_n[i_b] + minv_n[j_b]) / r0_b
    new = np.empty_like(history_b)
    forces, energy = [], 0.0
    mean_theta_b = None if legacy else 0.5 * (theta_n[i_b] + theta_n[j_b])
    for end, node in ((0, i_b), (1, j_b)):
        theta_b = theta_n[node] if legacy else mean_theta_b
        ed = dr_b - theta_b * r0_b / 3.0
        slot = end if legacy else 0  # (bpm/peri: the bond's one history)
        ed_old, edb_old = history_b[:, 2 * slot], history_b[:, 2 * slot + 1]
        if advance:
            c1 = tau_b / dt
            decay = np.exp(-1.0 / c1)
            beta = 1.0 - c1 * (1.0 - decay)
            edb = ed_old * (1.0 - decay) + edb_old * decay + beta * (ed - ed_old)
        else:
            edb = edb_old
        new[:, 2 * end], new[:, 2 * end + 1] = ed, edb
        forces.append(elastic_b + gfac_b * ((1.0 - lam_b) * ed + lam_b * (ed - edb)))
        minv_end = minv_n[node]
        energy += np.sum(7.5 * g_b / r0_b * a_b * minv_end
                         * ((1.0 - lam_b) * ed * ed + lam_b * (ed - edb) ** 2))
    k_n = _node_mean(i_b, j_b, k_b, len(vol_n))
    energy += 0.5 * np.sum(vol_n * k_n * theta_n * theta_n)
    return PeriForces(forces[0], forces[1], float(energy), new)


def eps(i_b, j_b, dr_b, r0_b, k_b, g_b, yield_b, scale_b, vv_b, theta_n, m_n, vol_n,
        history_b, lambda_n, advance: bool, follows: str = LEGACY) -> PeriForces:
    """Elastic-plastic solid: the elastic dilatation term of lps with a
    deviatoric force state returned onto the yield surface where it exceeds
    it (pointwise yield value ``Y_p = 25 Y^2 / (8 pi horizon^5)``).

    ``follows`` (a key of :data:`RECORDED`) ``LEGACY``: ``peri/eps`` of the
    reference build (22 Jul 2025), defects included.  Each bond end has its deviatoric extension ``ed = dr - theta_i
    r0 / 3`` and plastic extension ``edp``; the trial state is ``td = 15 G
    (1/m_i + 1/m_j) (ed - edp) / r0``, but node i's norm sums ``(15 G
    (theta_i/m_i + theta_j/m_j) (ed - edp) / r0)^2 V_j scale`` (a
    dilatation factor where ``1/m`` belongs: LAMMPS pull request 5046); a
    node past ``|td|^2 / 2 > Y_p`` takes ``dlambda = (norm / sqrt(2 Y_p) - 1)
    m_i / (15 G)``, its bonds ``sqrt(2 Y_p) td / norm`` and ``edp' = edp +
    that * dlambda`` (a force added to an extension: the update 5046 also
    fixed); a node below yield applies ``td`` and forgets its plastic
    extensions (``edp' = 0``).

    ``BEFORE_OPTION``: what BPMPeri computed before it had ``follows``: the
    legacy per-end extensions, the norm of ``td`` itself, and a node past
    ``norm > sqrt(2 Y_p)`` returning each of its bond ends radially, ``edp'
    = edp + (ed - edp)(1 - sqrt(2 Y_p) / norm)``.

    ``BPM_PERI``: ``bond_style bpm/peri`` (LAMMPS 2026) yielding where
    Mitchell's model (SAND2011-3166) says: one deviatoric extension ``ed``
    per bond with the mean dilatation of its nodes and one plastic extension
    ``edp``.  Mitchell's node i has the deviatoric force state ``t_i = 15 G
    (ed - edp) / (m_i r0)`` on each of its bonds and yields when ``|t_i|^2 /
    2 > Y_p``, ``|t_i|^2 = sum_j t_i^2 V_j scale`` over its own bonds; the
    bond pulls with the sum of its two nodes' states, ``td = t_i + t_j``.
    Each node's norm here is ``|t_i|``, its own state with its own ``m_i``
    (the mean ``(1/m_i + 1/m_j) / 2`` would put the partner's weighted
    volume into node i's test: the two agree on a uniform lattice); a bond
    whose nodes' mean norm exceeds ``sqrt(2 Y_p)`` is scaled back, ``td
    sqrt(2 Y_p) / norm``, ``edp' = edp + (ed - edp)(1 - sqrt(2 Y_p) /
    norm)`` (the exact radial return of LAMMPS issue 5064; one plastic
    extension per bond takes one factor for both states, bond_style
    bpm/peri's mean norm).  Where the nodes agree, as in a homogeneous
    strain, each is returned exactly as Mitchell's node is.  bond_style
    bpm/peri (src/BPM/bond_bpm_peri.cpp) takes the norm of ``td`` itself,
    twice ``|t_i|`` on a uniform lattice: it yields at half Mitchell's
    strain, an inconsistency not copied (docs/lammps.md).

    ``history_b`` holds ``(edp_i, edp_j)`` per bond (bpm/peri: the bond's
    value twice).  Only with ``advance`` (a step) is the return made and the
    plastic extensions and multiplier (``node``, per node) advanced; else the
    stored plastic extensions are used as they are.
    """
    natoms = len(vol_n)
    minv_n = np.divide(1.0, m_n, out=np.zeros_like(m_n), where=m_n > 0)
    minv_i, minv_j = minv_n[i_b], minv_n[j_b]
    a_b = scale_b * vv_b
    theta_i, theta_j = theta_n[i_b], theta_n[j_b]
    elastic_b = 3.0 * k_b * a_b * (theta_i * minv_i + theta_j * minv_j)
    gfac_b = 15.0 * g_b * (minv_i + minv_j) / r0_b
    ends = ((0, i_b), (1, j_b))
    per_end = follows != BPM_PERI
    if per_end:
        ed = [dr_b - theta_n[node] * r0_b / 3.0 for _, node in ends]
        edp = [history_b[:, 0], history_b[:, 1]]
        nfac_b = gfac_b if follows == BEFORE_OPTION else \
            15.0 * g_b * (theta_i * minv_i + theta_j * minv_j) / r0_b
        norm_terms = [nfac_b * (ed[end] - edp[end]) for end, _ in ends]
        trial = [gfac_b * (ed[end] - edp[end]) for end, _ in ends]
        norm_n = np.sqrt(node_sum(i_b, j_b, norm_terms[0] ** 2 * scale_b * vol_n[j_b],
                                  norm_terms[1] ** 2 * scale_b * vol_n[i_b], natoms))
    else:
        mean_ed = dr_b - 0.5 * (theta_i + theta_j) * r0_b / 3.0
        ed, edp = [mean_ed, mean_ed], [history_b[:, 0], history_b[:, 0]]
        trial = [gfac_b * (mean_ed - edp[0])] * 2
        # node i's own state on the bond, Mitchell's, is shear_b / m_i (the
        # bond's is the sum of its nodes'): 1/m_i comes out of node i's sum
        shear_b = 15.0 * g_b * (mean_ed - edp[0]) / r0_b
        weight_b = shear_b * shear_b * scale_b
        norm_n = minv_n * np.sqrt(node_sum(i_b, j_b, weight_b * vol_n[j_b],
                                           weight_b * vol_n[i_b], natoms))
    y_n = np.zeros(natoms)  # pointwise yield value of each node (max over bonds)
    np.maximum.at(y_n, i_b, yield_b)
    np.maximum.at(y_n, j_b, yield_b)
    limit_n = np.sqrt(2.0 * y_n)
    if follows == BEFORE_OPTION:  # (its own test, to the bit)
        plastic_n = (norm_n > limit_n) & (y_n > 0) & advance
    else:
        plastic_n = (0.5 * norm_n * norm_n - y_n > 0.0) & (y_n > 0) & advance
    g_n = _node_mean(i_b, j_b, g_b, natoms)
    dlambda_n = np.where(plastic_n, (norm_n / np.where(limit_n > 0, limit_n, 1.0) - 1.0)
                         * m_n / np.where(g_n > 0, 15.0 * g_n, 1.0), 0.0)
    returned, edp_new = [], []
    if follows == BEFORE_OPTION:
        radial_n = np.where(plastic_n, limit_n / np.where(plastic_n, norm_n, 1.0), 1.0)
        for end, node in ends:
            radial = radial_n[node]
            returned.append(trial[end] * radial)
            edp_new.append(edp[end] + (ed[end] - edp[end]) * (1.0 - radial))
    elif follows == LEGACY:
        for end, node in ends:
            plastic = plastic_n[node]
            back = np.where(plastic, limit_n[node] * trial[end]
                            / np.where(plastic, norm_n[node], 1.0), trial[end])
            returned.append(back)
            edp_new.append(np.where(plastic, edp[end] + back * dlambda_n[node],
                                    0.0 if advance else edp[end]))
    else:
        limit_b = np.sqrt(2.0 * yield_b)
        norm_b = 0.5 * (norm_n[i_b] + norm_n[j_b])
        plastic_b = (norm_b > limit_b) & advance
        radial_b = np.where(plastic_b, limit_b / np.where(plastic_b, norm_b, 1.0), 1.0)
        back = trial[0] * radial_b
        kept = edp[0] + (ed[0] - edp[0]) * (1.0 - radial_b)
        returned, edp_new = [back, back], [kept, kept]
    new = np.column_stack(edp_new) if advance else history_b.copy()
    lambda_new = lambda_n + dlambda_n
    forces = [elastic_b + a_b * returned[end] for end, _ in ends]
    energy = 0.0
    for end, node in ends:
        elastic_ext = ed[end] - (edp[end] if follows == LEGACY else new[:, end])
        energy += np.sum(7.5 * g_b / r0_b * a_b * minv_n[node] * elastic_ext * elastic_ext)
    k_n = _node_mean(i_b, j_b, k_b, natoms)
    energy += 0.5 * np.sum(vol_n * k_n * theta_n * theta_n)
    return PeriForces(forces[0], forces[1], float(energy), new, lambda_new)


def past_critical_stretch(dr_b, r0_b, critical_b) -> np.ndarray:
    """Parks' breaking test: the stretch ``dr / r0`` beyond the critical
    stretch (``s00 - alpha s_min``; NaN, no history yet, breaks nothing)."""
    return dr_b / r0_b > critical_b


def pointwise_yield(yield_stress, horizon):
    """``25 Y^2 / (8 pi horizon^5)``, the yield value of the eps model."""
    return 25.0 * yield_stress ** 2 / (8.0 * np.pi * horizon ** 5)


def coefficient_rows(coeff_t, model_t) -> np.ndarray:
    """The coefficients of each bond type as the compiled kernels take them
    (:data:`ase_bpm.laws.compiled.PERI_COLUMNS`): ``coeff_t`` by name, one
    value per type (NaN where a type's model has none), ``model_t`` the place
    of each type's model in :data:`~ase_bpm.laws.compiled.PERI_MODELS` (one
    for all types, or one per type)."""
    columns = compiled.PERI_COLUMNS
    types = len(np.atleast_1d(model_t))  # (no bond_coeffs: the one type 0, no model)
    rows = np.full((len(coeff_t["horizon"]) if coeff_t else types, len(columns)), np.nan)
    for k, name in enumerate(columns):
        if name in coeff_t:
            rows[:, k] = coeff_t[name]
    if "yield_stress" in coeff_t:
        rows[:, columns.index("yield")] = pointwise_yield(coeff_t["yield_stress"],
                                                          coeff_t["horizon"])
    rows[:, columns.index("model")] = model_t
    return rows


def _node_mean(i_b, j_b, values_b, natoms: int) -> np.ndarray:
    """Mean of a per-bond coefficient over each node's bonds."""
    count = node_sum(i_b, j_b, np.ones(len(i_b)), np.ones(len(i_b)), natoms)
    total = node_sum(i_b, j_b, values_b, values_b, natoms)
    return np.divide(total, count, out=np.zeros(natoms), where=count > 0)


# -- the laws, as bond laws of the protocol (:mod:`ase_bpm.laws.bond`) -----------------

@dataclass(frozen=True)
class PeriScene:
    """Node state that every peridynamic bond of a model shares in one evaluation."""

    vol_n: np.ndarray  # nodal volumes
    m_n: np.ndarray  # weighted volumes (reference configuration)
    theta_n: Optional[np.ndarray]  # dilatation (None without state-based bonds)
    lambda_n: np.ndarray  # plastic multiplier of each node (eps), as of the last step
    #: the dilatation of each node if every state-based bond stretched by 1
    #: (``3/m_i sum_j V_j scale``), for the stiffness bound (None: not worked out)
    dilatation_weight_n: Optional[np.ndarray] = None
    # -- what the compiled kernels take here instead of per-bond ``extra`` --
    spacing: Optional[float] = None  # lattice spacing (partial volumes)
    #: each node's smallest stretch in the step before, for Parks' test (None:
    #: no history, nothing breaks)
    smin_n: Optional[np.ndarray] = None
    #: this step's smallest stretch of each node, written by the kernels (NaN
    #: where no bond; None: not kept)
    smin_new_n: Optional[np.ndarray] = None
    #: what the compiled kernels follow: the code of :data:`RECORDED` (0:
    #: bond_style bpm/peri; else the legacy styles' volume factor and forms)
    legacy: int = 0


class PeriBond(BondLaw):
    """Shared by the four models: breaking by Parks' criterion, with the
    timing of the LAMMPS styles a model follows (:meth:`follow`).

    The model passes per-bond ``extra``: ``dr`` (extension), ``scale``
    (partial-volume factor), ``vv`` (the volume factor,
    :func:`volume_product`) and, where breaking is tested
    (``BondInput.breaking``), ``critical`` (the breaking stretch
    ``s00 - alpha s_min``, NaN where no history yet).
    """

    family = "peri"
    lammps_style = "bpm/peri"  # newer than the reference build: exported as legacy
    #: the ``pair_coeff`` order of the legacy ``peri/<name>`` pair style
    legacy_order: tuple = ()
    legacy_prefix = "peri/"  # the legacy pair styles' names: it and the law's name

    @classmethod
    def legacy_style(cls) -> str:
        """The legacy pair style that runs this law, ``peri/<name>``."""
        return f"{cls.legacy_prefix}{cls.name}"

    @classmethod
    def read_as_legacy(cls, values: dict) -> dict:
        """The coefficients ``values`` (by name, read in ``bond_style bpm/peri``
        order) as the legacy ``pair_coeff`` line would read the same tuple."""
        return dict(zip(cls.legacy_order, (values[name] for name in cls.coefficients)))

    @classmethod
    def order_note(cls) -> str:
        """Both orders, for errors about a tuple that may be in the other."""
        return (f"bond_style bpm/peri orders {cls.name} as {' '.join(cls.coefficients)}, "
                f"the legacy pair_coeff line of {cls.legacy_style()} as "
                f"{' '.join(cls.legacy_order)}")
    #: a bond that breaks gives no force in that step, as in bond_style
    #: bpm/peri (``follow(LEGACY)``: it still acts, as in the legacy styles)
    acts_while_breaking = False
    state_based: bool = True  # needs the dilatation (all but pmb)

    #: follow the legacy styles' forms of the laws (ves, eps: :meth:`follow`)
    legacy = False
    #: what the law follows (a key of :data:`RECORDED`; eps has three forms)
    follows = BPM_PERI

    def follow(self, follows: str) -> None:
        """Take the behaviour of ``follows`` (a key of :data:`RECORDED`)
        where it lies in the law: the breaking step, and the ves and eps
        forms."""
        self.acts_while_breaking = self.legacy = follows != BPM_PERI
        self.follows = follows
    positive = ("c", "K", "horizon", "tau", "yield_stress")
    non_negative = ("G", "s00", "alpha", "lambda")

    breaking_strain = "s00"
    compiled = True

    def add_sums(self, scene: BondScene) -> None:
        """The compiled kernel of the model, with the node state
        ``scene.nodes`` (a :class:`PeriScene`: volumes, weighted volumes,
        dilatation, the smallest stretches) in place of ``extra``."""
        self._add_sums(scene)

    def _add_sums(self, scene: BondScene, lambda_out=None) -> None:
        history_out = None
        for name, shape in self.states.items():  # ves, eps: one state each
            size = len(scene.i_b) if scene.select is None else len(scene.select)
            history_out = np.empty((size,) + shape)
            scene.sums.history[name] = (scene.select, history_out)
        rows = coefficient_rows(scene.coeff_t, compiled.PERI_MODELS.index(self.name))
        scene.sums.nbroken += compiled.peri_bonds(self.name, scene, rows,
                                                  self.acts_while_breaking, history_out,
                                                  lambda_out)

    @staticmethod
    def breaks(bonds: BondInput) -> Optional[np.ndarray]:
        """Parks' test where the input asks for it (None: not tested)."""
        if not bonds.breaking:
            return None
        return past_critical_stretch(bonds.extra["dr"], bonds.r0_b, bonds.extra["critical"])

    @staticmethod
    def args(bonds: BondInput) -> tuple:
        x = bonds.extra
        return x["dr"], bonds.r0_b, x["scale"], x["vv"]

    def volumetric_modulus(self, coeff) -> np.ndarray:
        """The modulus of the dilatation term of the energy,
        ``sum_i V_i (K - 5G/3) theta_i^2 / 2`` for lps (not negative)."""
        return np.maximum(coeff["K"] - 5.0 * coeff["G"] / 3.0, 0.0)

    def stiffness(self, bonds: BondInput) -> LawStiffness:
        """The bonds as springs, weighted by partial volumes as the forces are.

        pmb: ``c V_i V_j scale / r0`` along each bond.  The state-based
        models write their energy (below yield, without viscous relaxation)
        as ``sum_b k_b dr_b^2 / 2 + sum_i V_i kappa theta_i^2 / 2`` with
        ``k_b = 15 G V_i V_j scale (1/m_i + 1/m_j) / r0`` and
        ``kappa = K - 5G/3``; the dilatation ``theta_i = sum_b a_b dr_b``
        (``a_b = 3 V_j scale / m_i``) couples all bonds of a node, and
        Cauchy-Schwarz, ``(sum a y)^2 <= (sum a)(sum a y^2)``, bounds that
        term by bonds of stiffness ``3 kappa V_i V_j scale (A_i/m_i + A_j/m_j)``
        with ``A_i = sum_b a_b`` (the scene's ``dilatation_weight_n``), added
        to ``k_b``: exact for a node whose bonds all stretch alike.  Across
        each bond: its tension over its length.  No damping."""
        x, c, s = bonds.extra, bonds.coeff, bonds.scene
        i_b, j_b, r_b = bonds.i_b, bonds.j_b, bonds.r_b
        a_b = x["scale"] * x["vv"]
        if self.state_based:
            minv_n = np.divide(1.0, s.m_n, out=np.zeros_like(s.m_n), where=s.m_n > 0)
            k_b = 15.0 * c["G"] * a_b * (minv_n[i_b] + minv_n[j_b]) / bonds.r0_b
            kappa_b = self.volumetric_modulus(c)
            if np.any(kappa_b > 0):
                weight_n = s.dilatation_weight_n * minv_n
                k_b = k_b + 3.0 * kappa_b * a_b * (weight_n[i_b] + weight_n[j_b])
        else:
            k_b = c["c"] * a_b / bonds.r0_b
        out = self.forces(replace(bonds, advance=False))
        pull_b = out.f_b if out.fj_b is None else np.maximum(out.f_b, out.fj_b)
        tension_b = np.divide(np.maximum(pull_b, 0.0), r_b, out=np.zeros_like(r_b),
                              where=r_b > 0)
        return LawStiffness(k_b, 0.0, tension_b)


@register
class Pmb(PeriBond):
    """``pmb c horizon s00 alpha``: bond-based, micromodulus ``c``."""

    name = "pmb"
    coefficients = ("c", "horizon", "s00", "alpha")
    legacy_order = ("c", "horizon", "s00", "alpha")
    state_based = False

    def forces(self, bonds: BondInput) -> BondForces:
        dr_b, r0_b, scale_b, vv_b = self.args(bonds)
        res = pmb(dr_b, r0_b, bonds.coeff["c"], scale_b, vv_b)
        return BondForces(res.fi_b, 0.5 * res.fi_b * dr_b, self.breaks(bonds))


@register
class Lps(PeriBond):
    """``lps K G horizon s00 alpha``: linear peridynamic solid."""

    name = "lps"
    coefficients = ("K", "G", "horizon", "s00", "alpha")
    legacy_order = ("K", "G", "horizon", "s00", "alpha")

    def forces(self, bonds: BondInput) -> BondForces:
        dr_b, r0_b, scale_b, vv_b = self.args(bonds)
        s, c = bonds.scene, bonds.coeff
        res = lps(bonds.i_b, bonds.j_b, dr_b, r0_b, c["K"], c["G"], scale_b, vv_b,
                  s.theta_n, s.m_n, s.vol_n)
        return BondForces(res.fi_b, np.zeros(len(dr_b)), self.breaks(bonds),
                          energy=res.energy)


@register
class Ves(PeriBond):
    """``ves K G lambda tau horizon s00 alpha``: viscoelastic solid."""

    name = "ves"
    coefficients = ("K", "G", "lambda", "tau", "horizon", "s00", "alpha")
    legacy_order = ("K", "G", "horizon", "s00", "alpha", "lambda", "tau")
    states = {"ves": (4,)}
    needs_timestep = True

    @classmethod
    def check(cls, values: dict, where: str) -> None:
        if not values["lambda"] <= 1.0:
            raise ValueError(f"{where}: lambda = {values['lambda']} must lie between 0 and 1")

    def volumetric_modulus(self, coeff) -> np.ndarray:
        """``K - 5 G (1 - lambda) / 3``: at most what the relaxing part leaves of
        the shear coupling (its share of ``G`` in the step, ``lambda beta``,
        lies between 0 and ``lambda``)."""
        return np.maximum(coeff["K"] - 5.0 * coeff["G"] * (1.0 - coeff["lambda"]) / 3.0, 0.0)

    def forces(self, bonds: BondInput) -> BondForces:
        dr_b, r0_b, scale_b, vv_b = self.args(bonds)
        s, c = bonds.scene, bonds.coeff
        res = ves(bonds.i_b, bonds.j_b, dr_b, r0_b, c["K"], c["G"], c["lambda"], c["tau"],
                  scale_b, vv_b, s.theta_n, s.m_n, s.vol_n,
                  np.nan_to_num(bonds.history["ves"]), bonds.timestep, bonds.advance,
                  self.legacy)
        return BondForces(res.fi_b, np.zeros(len(dr_b)), self.breaks(bonds), fj_b=res.fj_b,
                          history={"ves": res.history}, energy=res.energy)


@register
class Eps(PeriBond):
    """``eps K G yield_stress horizon s00 alpha``: elastic-plastic solid."""

    name = "eps"
    coefficients = ("K", "G", "yield_stress", "horizon", "s00", "alpha")
    legacy_order = ("K", "G", "horizon", "s00", "alpha", "yield_stress")
    states = {"eps": (2,)}

    def forces(self, bonds: BondInput) -> BondForces:
        dr_b, r0_b, scale_b, vv_b = self.args(bonds)
        s, c = bonds.scene, bonds.coeff
        res = eps(bonds.i_b, bonds.j_b, dr_b, r0_b, c["K"], c["G"],
                  pointwise_yield(c["yield_stress"], c["horizon"]), scale_b, vv_b,
                  s.theta_n, s.m_n, s.vol_n, np.nan_to_num(bonds.history["eps"]),
                  s.lambda_n, bonds.advance, self.follows)
        return BondForces(res.fi_b, np.zeros(len(dr_b)), self.breaks(bonds), fj_b=res.fj_b,
                          history={"eps": res.history}, node={"lambda": res.node},
                          energy=res.energy)

    def add_sums(self, scene: BondScene) -> None:
        lambda_out = scene.sums.node["lambda"] = np.empty(len(scene.x_nc))
        self._add_sums(scene, lambda_out)


@register_contact
class PeriContact(PairLaw):
    """``pair_style bpm/peri``: ``pair_coeff ti tj k horizon``; nodes closer than
    ``d`` (the model's per-pair ``extra["d"]``) repel with
    ``15 k v (d - r) / horizon`` (``extra["vv"]``: the volume factor ``v``,
    :func:`volume_product`)."""

    name = "bpm/peri"
    coefficients = ("k", "horizon")
    positive = ("k", "horizon")
    compiled = True  # (compiled.peri_contacts)

    @staticmethod
    def reach(coeff, extra):
        return extra["d"]

    def forces(self, pairs: PairInput) -> PairForces:
        gap_p = pairs.r_p - pairs.reach_p
        f_p = 15.0 * pairs.coeff["k"] * pairs.extra["vv"] * gap_p / pairs.coeff["horizon"]
        return PairForces(f_p, 0.5 * f_p * gap_p)

    def stiffness(self, pairs: PairInput) -> LawStiffness:
        """``15 k V_i V_j / horizon`` along the pair."""
        return LawStiffness(15.0 * pairs.coeff["k"] * pairs.extra["vv"] / pairs.coeff["horizon"])
