"""Force laws of LAMMPS ``bond_style bpm/spring`` and ``pair_style bpm/spring``.

Pure functions over arrays, no ASE and no state: a compiled backend can replace
them one for one.  Conventions (matscipy's): ``r_xc = x[j] - x[i]`` points from
the first atom ``i`` to the second ``j``, ``v_xc = v[j] - v[i]``; the returned
force acts on ``i`` and its opposite on ``j``.  Coefficients may be scalars or
one value per bond (pair).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Optional

import numpy as np

from . import compiled
from .bond import BondForces, BondInput, BondLaw, BondScene, register
from .contact import PairForces, PairInput, PairLaw, register_contact
from .timestep import LawStiffness


class SpringForces(NamedTuple):
    f_xc: np.ndarray  # force on the first atom, elastic + damping
    fd_xc: Optional[np.ndarray]  # its damping part (None when undamped)
    energy_x: np.ndarray  # elastic energy, consistent with the elastic force


def lengths(r_xc: np.ndarray) -> tuple:
    """Lengths and inverse lengths (0 for zero-length vectors: no direction)."""
    r_x = np.sqrt(np.einsum("xc,xc->x", r_xc, r_xc))
    rinv_x = np.divide(1.0, r_x, out=np.zeros_like(r_x), where=r_x > 0)
    return r_x, rinv_x


def spring_bond_magnitudes(r_bc, v_bc, r0_b, k_b, ecrit_b, gamma_b, smooth=True,
                           normalize=False, r_b=None, volume_b=None):
    """``bond_style bpm/spring``: force magnitudes of bonds, as if none had broken.

    Elastic force ``k (r - r0)`` (``k (r - r0)/r0`` with ``normalize``), along the
    bond and pulling a stretched bond together; damping ``-gamma (r_hat . v)``
    against the normal relative velocity; both times
    ``w = 1 - ((r - r0)/(r0 eps_c))^8`` when ``smooth``.  The energy is the
    integral of the (smoothed) elastic force from ``r0``:
    ``k r0^2 (e^2/2 - e^10/(10 eps_c^8))`` with ``e`` the strain (one factor
    ``r0`` less with ``normalize``; no ``e^10`` term without ``smooth``).

    ``v_bc`` and ``gamma_b`` are ``None`` for an undamped model; ``r_b`` may
    pass precomputed lengths; ``volume_b``, the volumetric force of
    ``volume/factor`` (:func:`volumetric_force`), adds to the elastic force
    before smoothing (it has no energy: LAMMPS reports none either).  Returns ``(f_b, fd_b, energy_b, rinv_b)``: the
    magnitude on ``i`` along ``r_hat`` (elastic + damping), its damping part
    (None when undamped), the energy and the inverse lengths.  Breaking
    (``|e| > eps_c``) is the caller's business: LAMMPS drops such bonds before
    computing any force.
    """
    if r_b is None:
        r_b = np.sqrt(np.einsum("bc,bc->b", r_bc, r_bc))
    rinv_b = np.divide(1.0, r_b, out=np.zeros_like(r_b), where=r_b > 0)
    e_b = (r_b - r0_b) / r0_b
    fmag_b = k_b * (e_b if normalize else r_b - r0_b)  # along r_hat, on i
    if volume_b is not None:
        fmag_b = fmag_b + volume_b
    energy_b = 0.5 * e_b * e_b
    if smooth:
        x2_b = e_b / ecrit_b
        x2_b *= x2_b
        x8_b = x2_b * x2_b
        x8_b *= x8_b
        w_b = 1.0 - x8_b
        fmag_b *= w_b
        energy_b -= 0.1 * e_b * e_b * x8_b
    energy_b *= k_b * (r0_b if normalize else r0_b * r0_b)
    fd_b = None
    if gamma_b is not None:
        fd_b = bond_damping(gamma_b, rinv_b, r_bc, v_bc, w_b if smooth else None)
        fmag_b += fd_b
    return fmag_b, fd_b, energy_b, rinv_b


def bond_damping(gamma_b, rinv_b, r_bc, v_bc, w_b=None) -> np.ndarray:
    """The damping force of BPM spring bonds along each bond (on ``i``,
    positive pulling together): ``gamma (r_hat . v)``, times the smoothing
    factor ``w_b`` where given."""
    fd_b = gamma_b * rinv_b * np.einsum("bc,bc->b", r_bc, v_bc)
    if w_b is not None:
        fd_b *= w_b
    return fd_b


#: the exponent of the volume ratio in ``volume/factor``: 1/3, the ratio of
#: volumes as a ratio of lengths (three dimensions)
VOLUME_EXPONENT = 1.0 / 3.0


def bond_volumes(i_b, j_b, length_b, natoms: int) -> np.ndarray:
    """``volume/factor``'s volume of each atom: the sum of the cubed lengths
    of its bonds (the bonds given: those intact), a measure whose constant
    factors cancel in the ratio of two of them."""
    cube_b = length_b * length_b * length_b
    return (np.bincount(i_b, cube_b, minlength=natoms)
            + np.bincount(j_b, cube_b, minlength=natoms))


def volume_ratios(i_b, j_b, r_b, r0_b, natoms: int) -> np.ndarray:
    """``volume/factor``: per bond, the volume of its two atoms now over their
    volume in the reference state, ``(V_i + V_j) / (V0_i + V0_j)``, the
    volumes :func:`bond_volumes` of the lengths ``r_b`` and of the reference
    lengths ``r0_b`` of the same (intact) bonds."""
    v_n = bond_volumes(i_b, j_b, r_b, natoms)
    v0_n = bond_volumes(i_b, j_b, r0_b, natoms)
    return (v_n[i_b] + v_n[j_b]) / (v0_n[i_b] + v0_n[j_b])


def volumetric_force(r_b, r0_b, ratio_b, a_v_b) -> np.ndarray:
    """``bond_style bpm/spring volume/factor yes``: the multibody force along
    each bond (on ``i``, positive pulling together),
    ``a_v (e - (ratio^(1/3) - 1))``, which pulls a bond towards the strain
    of the volume around its two atoms (Clemmer, Monti and Lechman, Soft
    Matter 20, 1702 (2024)); ``a_v`` (force) may be negative."""
    e_b = (r_b - r0_b) / r0_b
    return -a_v_b * ((ratio_b ** VOLUME_EXPONENT - 1.0) - e_b)


def past_eps_c(r_b, r0_b, ecrit_b) -> np.ndarray:
    """The breaking test of ``bond_style bpm/spring``: ``|r - r0| > eps_c r0``
    (in tension or compression)."""
    return np.abs(r_b - r0_b) > ecrit_b * r0_b


def spring_bonds(r_bc, v_bc, r0_b, k_b, ecrit_b, gamma_b, smooth=True, normalize=False,
                 r_b=None) -> SpringForces:
    """:func:`spring_bond_magnitudes` as force vectors on ``i``."""
    f_b, fd_b, energy_b, rinv_b = spring_bond_magnitudes(r_bc, v_bc, r0_b, k_b, ecrit_b,
                                                         gamma_b, smooth, normalize, r_b)
    fd_bc = None if fd_b is None else r_bc * (fd_b * rinv_b)[:, None]
    return SpringForces(r_bc * (f_b * rinv_b)[:, None], fd_bc, energy_b)


@dataclass(frozen=True)
class BondVolumes:
    """``volume/factor`` on the compiled route: what the model works out over
    all its bonds before the laws (``BondScene.nodes``), for
    :meth:`SpringBond.add_sums`."""

    a_v_t: np.ndarray  # a_v by bond type (NaN: a type without it)
    vol_n: np.ndarray  # the atoms' volumes now (bond_volumes of the lengths)
    vol0_n: np.ndarray  # and in the reference state (of the reference lengths)


#: the names of ``volume/factor``'s per-bond data in ``BondInput.extra``:
#: the coefficient ``a_v`` and the volume ratio (:func:`volume_ratios`)
VOLUME_FACTOR, VOLUME_RATIO = "a_v", "volume_ratio"


@register
class SpringBond(BondLaw):
    """``bond_style bpm/spring``: ``bond_coeff t k eps_c gamma``.

    Stiffness ``k`` (force/distance; force with ``normalize``), critical strain
    ``eps_c``, damping ``gamma`` (force/velocity).  A bond breaks when its
    strain exceeds ``eps_c`` in either direction; the model's ``smooth`` and
    ``normalize`` switches arrive in ``options``.
    """

    name = "bpm/spring"
    lammps_style = "bpm/spring"
    skips_broken = True  # c/spring.c passes over type-0 bonds
    coefficients = ("k", "eps_c", "gamma")
    positive = ("k", "eps_c")
    non_negative = ("gamma",)

    breaking_strain = "eps_c"
    compiled = True

    @staticmethod
    def uses_velocities(coeff) -> bool:
        return bool(np.any(coeff["gamma"] > 0))

    def prepare(self, scene: BondScene) -> compiled.SpringBonds:
        """The C kernel, its arguments for these bonds converted once
        (:class:`ase_bpm.laws.compiled.SpringBonds`); with ``volume/factor``
        (``scene.nodes`` a :class:`BondVolumes`) its kernel, ``a_v`` beside
        the coefficients."""
        columns = [scene.coeff_t[name] for name in self.coefficients]
        volume = isinstance(scene.nodes, BondVolumes)
        if volume:
            columns.append(scene.nodes.a_v_t)
        return compiled.SpringBonds(scene, np.column_stack(columns),
                                    scene.options.get("smooth", True),
                                    scene.options.get("normalize", False), volume=volume)

    def add_sums(self, scene: BondScene) -> None:
        self.prepare(scene)(scene)

    def forces(self, bonds: BondInput) -> BondForces:
        """The bonds' forces; with ``volume/factor`` (``extra["a_v"]`` and
        ``extra["volume_ratio"]``, which the model gives) the volumetric
        force too (:func:`volumetric_force`)."""
        c = bonds.coeff
        volume_b = None
        if VOLUME_FACTOR in bonds.extra:
            volume_b = volumetric_force(bonds.r_b, bonds.r0_b, bonds.extra[VOLUME_RATIO],
                                        bonds.extra[VOLUME_FACTOR])
        f_b, fd_b, energy_b, _ = spring_bond_magnitudes(
            bonds.r_bc, bonds.v_bc, bonds.r0_b, c["k"], c["eps_c"],
            c["gamma"] if bonds.v_bc is not None else None,
            bonds.options.get("smooth", True), bonds.options.get("normalize", False),
            r_b=bonds.r_b, volume_b=volume_b)
        breaks_b = (past_eps_c(bonds.r_b, bonds.r0_b, c["eps_c"]) if bonds.breaking
                    else None)
        return BondForces(f_b, energy_b, breaks_b, fd_b=fd_b)

    def stiffness(self, bonds: BondInput) -> LawStiffness:
        """``k`` along the bond (``k / r0`` with ``normalize``), ``gamma``
        against the relative velocity along it, and across it the tension
        over the length: bounds for the smoothed law, whose factor
        ``w = 1 - (e/eps_c)^8`` is at most 1 and whose tangent
        ``k (1 - 9 (e/eps_c)^8)`` is at most ``k``.  With ``volume/factor``,
        ``2 |a_v| / r0`` more along it: ``a_v / r0`` from the bond's own
        strain and at most as much from its share of the volume ratio."""
        c, r_b, r0_b = bonds.coeff, bonds.r_b, bonds.r0_b
        k_b = c["k"] / r0_b if bonds.options.get("normalize", False) else c["k"] + 0.0 * r_b
        if VOLUME_FACTOR in bonds.extra:
            k_b = k_b + 2.0 * np.abs(bonds.extra[VOLUME_FACTOR]) / r0_b
        tension_b = np.maximum(k_b * (r_b - r0_b), 0.0)
        return LawStiffness(k_b, c["gamma"], np.divide(tension_b, r_b, out=np.zeros_like(r_b),
                                                       where=r_b > 0))


def eighth_power(x):
    """``x^8`` by three squarings."""
    x2 = x * x
    x4 = x2 * x2
    return x4 * x4


def plastic_strain(e_b, ep_b, eps_p_b) -> np.ndarray:
    """``bond_style bpm/spring/plastic``: the plastic strain after this
    strain ``e_b``, from the last step's ``ep_b``.  A bond yields where its
    elastic strain ``e - ep`` passes ``eps_p`` in either direction; the
    plastic strain then follows so that the elastic strain stays at
    ``eps_p``."""
    ep_b = np.where(e_b > ep_b + eps_p_b, e_b - eps_p_b, ep_b)
    return np.where(e_b < ep_b - eps_p_b, e_b + eps_p_b, ep_b)


def plastic_bond_magnitudes(r_b, rinv_b, r_bc, v_bc, r0_b, ep_b, k_b, ecrit_b, gamma_b,
                            smooth=True, normalize=False):
    """``bond_style bpm/spring/plastic``: force magnitudes of bonds with
    plastic strains ``ep_b``, as if none had broken.

    Elastic force ``k (r - (1 + ep) r0)`` (``k (e - ep)`` with ``normalize``)
    along the bond, pulling a bond longer than its plastic rest length
    together; damping ``gamma (r_hat . v)``; both times
    ``w = 1 - (e/eps_c)^8`` (the total strain ``e``) when ``smooth``.  The
    energy is the elastic energy the bond holds at this plastic strain: the
    integral of the (smoothed) elastic force from the plastic rest length,
    ``k r0^2 [(e - ep)^2/2 - ((e^10 - ep^10)/10 - ep (e^9 - ep^9)/9) / eps_c^8]``
    (one factor ``r0`` less with ``normalize``; no ``eps_c`` term without
    ``smooth``).  Returns ``(f_b, fd_b, energy_b)`` as
    :func:`spring_bond_magnitudes` (``fd_b`` None where ``gamma_b`` is)."""
    e_b = (r_b - r0_b) / r0_b
    elastic_b = e_b - ep_b
    fmag_b = k_b * (elastic_b if normalize else r_b - (1.0 + ep_b) * r0_b)
    energy_b = 0.5 * elastic_b * elastic_b
    if smooth:  # (eighth powers by squaring, as c/spring.c takes them)
        x8_b = eighth_power(e_b / ecrit_b)
        w_b = 1.0 - x8_b
        fmag_b *= w_b
        e9_b, ep9_b = eighth_power(e_b) * e_b, eighth_power(ep_b) * ep_b
        energy_b -= (0.1 * (e9_b * e_b - ep9_b * ep_b) - ep_b * (e9_b - ep9_b) / 9.0) \
            / eighth_power(ecrit_b)
    energy_b *= k_b * (r0_b if normalize else r0_b * r0_b)
    fd_b = None
    if gamma_b is not None:
        fd_b = bond_damping(gamma_b, rinv_b, r_bc, v_bc, w_b if smooth else None)
        fmag_b += fd_b
    return fmag_b, fd_b, energy_b


@register
class SpringPlasticBond(BondLaw):
    """``bond_style bpm/spring/plastic``: ``bond_coeff t k eps_c gamma eps_p``.

    The ``bpm/spring`` bond with a plastic strain ``ep`` per bond (its
    history, ``bond_plastic``, 0 at first): stiffness ``k`` (force/distance;
    force with ``normalize``), critical strain ``eps_c``, damping ``gamma``
    (force/velocity), plastic yield strain ``eps_p`` (unitless).  Where the
    elastic strain ``e - ep`` passes ``eps_p`` the bond yields, its plastic
    strain moving with it (:func:`plastic_strain`); the force pulls it back
    to its plastic rest length ``(1 + ep) r0``.  It breaks when its total
    strain passes ``eps_c`` in either direction, before it yields.  Every
    evaluation uses the plastic strain it reaches; a step keeps it.
    """

    name = "bpm/spring/plastic"
    lammps_style = "bpm/spring/plastic"
    coefficients = ("k", "eps_c", "gamma", "eps_p")
    positive = ("k", "eps_c")
    non_negative = ("gamma", "eps_p")
    states = {compiled.SpringBonds.PLASTIC: ()}
    breaking_strain = "eps_c"
    compiled = True
    skips_broken = True  # c/spring.c passes over type-0 bonds

    def prepare(self, scene: BondScene) -> compiled.SpringBonds:
        """The C kernel (``plastic_bonds``), its arguments for these bonds
        converted once."""
        coeff_tc = np.column_stack([scene.coeff_t[name] for name in self.coefficients])
        return compiled.SpringBonds(scene, coeff_tc, scene.options.get("smooth", True),
                                    scene.options.get("normalize", False), plastic=True)

    def add_sums(self, scene: BondScene) -> None:
        self.prepare(scene)(scene)

    @staticmethod
    def uses_velocities(coeff) -> bool:
        return bool(np.any(coeff["gamma"] > 0))

    @staticmethod
    def _plastic(bonds: BondInput) -> np.ndarray:
        """The plastic strain each bond reaches now (from its last step's,
        0 where it has none yet)."""
        e_b = (bonds.r_b - bonds.r0_b) / bonds.r0_b
        last_b = np.nan_to_num(bonds.history[compiled.SpringBonds.PLASTIC], nan=0.0)
        return plastic_strain(e_b, last_b, bonds.coeff["eps_p"])

    def forces(self, bonds: BondInput) -> BondForces:
        c = bonds.coeff
        ep_b = self._plastic(bonds)
        r_b = bonds.r_b
        rinv_b = np.divide(1.0, r_b, out=np.zeros_like(r_b), where=r_b > 0)
        f_b, fd_b, energy_b = plastic_bond_magnitudes(
            r_b, rinv_b, bonds.r_bc, bonds.v_bc, bonds.r0_b, ep_b, c["k"], c["eps_c"],
            c["gamma"] if bonds.v_bc is not None else None,
            bonds.options.get("smooth", True), bonds.options.get("normalize", False))
        breaks_b = past_eps_c(r_b, bonds.r0_b, c["eps_c"]) if bonds.breaking else None
        return BondForces(f_b, energy_b, breaks_b, fd_b=fd_b,
                          history={compiled.SpringBonds.PLASTIC: ep_b} if bonds.advance else {})

    def stiffness(self, bonds: BondInput) -> LawStiffness:
        """As ``bpm/spring`` (:meth:`SpringBond.stiffness`), its tension
        measured from the plastic rest length: ``k`` (``k / r0`` with
        ``normalize``) along the bond, ``gamma`` against the relative
        velocity along it, the tension over the length across it."""
        c, r_b, r0_b = bonds.coeff, bonds.r_b, bonds.r0_b
        k_b = c["k"] / r0_b if bonds.options.get("normalize", False) else c["k"] + 0.0 * r_b
        rest_b = (1.0 + self._plastic(bonds)) * r0_b
        tension_b = np.maximum(k_b * (r_b - rest_b), 0.0)
        return LawStiffness(k_b, c["gamma"], np.divide(tension_b, r_b, out=np.zeros_like(r_b),
                                                       where=r_b > 0))


def spring_pair_magnitudes(r_p, rinv_p, r_pc, v_pc, k_p, rc_p, gamma_p):
    """``pair_style bpm/spring`` on pairs closer than ``r_c``: ``(f_p, fd_p,
    energy_p)``, force magnitudes on ``i`` along ``r_hat`` and the energy.

    Repulsion ``k (r_c - r)`` along the pair; damping ``-gamma w (r_hat . v)``
    with ``w = 1 - (r/r_c)^8``.  Energy ``k (r_c - r)^2 / 2``.  Coincident
    particles (``r = 0``) have no defined direction and get zero force.
    """
    overlap_p = rc_p - r_p
    fmag_p = -k_p * overlap_p
    energy_p = 0.5 * k_p * overlap_p * overlap_p
    fd_p = None
    if gamma_p is not None:
        x2_p = (r_p / rc_p) ** 2
        w_p = 1.0 - (x2_p * x2_p) ** 2
        fd_p = gamma_p * w_p * rinv_p * np.einsum("pc,pc->p", r_pc, v_pc)
        fmag_p = fmag_p + fd_p
    return fmag_p, fd_p, energy_p


def spring_pairs(r_pc, v_pc, k_p, rc_p, gamma_p) -> SpringForces:
    """:func:`spring_pair_magnitudes` as force vectors on ``i`` (the caller
    passes only pairs with ``r < r_c``)."""
    r_p, rinv_p = lengths(r_pc)
    f_p, fd_p, energy_p = spring_pair_magnitudes(r_p, rinv_p, r_pc, v_pc, k_p, rc_p, gamma_p)
    fd_pc = None if fd_p is None else r_pc * (fd_p * rinv_p)[:, None]
    return SpringForces(r_pc * (f_p * rinv_p)[:, None], fd_pc, energy_p)


@register_contact
class SpringPair(PairLaw):
    """``pair_style bpm/spring``: ``pair_coeff ti tj k r_c gamma``."""

    name = "bpm/spring"
    coefficients = ("k", "r_c", "gamma")
    positive = ("k", "r_c")
    non_negative = ("gamma",)
    compiled = True  # (compiled.spring_pairs)

    @staticmethod
    def reach(coeff, extra):
        return coeff["r_c"]

    @staticmethod
    def uses_velocities(coeff) -> bool:
        return bool(np.any(coeff["gamma"] > 0))

    def forces(self, pairs: PairInput) -> PairForces:
        c, r_p = pairs.coeff, pairs.r_p
        rinv_p = np.divide(1.0, r_p, out=np.zeros_like(r_p), where=r_p > 0)
        f_p, fd_p, energy_p = spring_pair_magnitudes(
            r_p, rinv_p, pairs.r_pc, pairs.v_pc, c["k"], c["r_c"],
            c["gamma"] if pairs.v_pc is not None else None)
        return PairForces(f_p, energy_p, fd_p)

    def stiffness(self, pairs: PairInput) -> LawStiffness:
        """``k`` and ``gamma`` (times ``w <= 1``) along the pair; nothing
        across (a repulsive pair softens sideways)."""
        return LawStiffness(pairs.coeff["k"], pairs.coeff["gamma"])


def anharmonic_pair_magnitudes(r_p, rinv_p, r_pc, v_pc, k_p, rc_p, gamma_p, ka_p):
    """``pair_style bpm/spring anharmonic yes`` on pairs closer than ``r_c``:
    :func:`spring_pair_magnitudes` with the cubic repulsion
    ``k_a (r_c - r)^3`` added, and its energy ``k_a (r_c - r)^4 / 4``."""
    f_p, fd_p, energy_p = spring_pair_magnitudes(r_p, rinv_p, r_pc, v_pc, k_p, rc_p, gamma_p)
    overlap2_p = (rc_p - r_p) ** 2
    f_p = f_p - ka_p * overlap2_p * (rc_p - r_p)
    return f_p, fd_p, energy_p + 0.25 * ka_p * overlap2_p * overlap2_p


class AnharmonicSpringPair(SpringPair):
    """``pair_style bpm/spring anharmonic yes``: ``pair_coeff ti tj k r_c
    gamma k_a``, the ``bpm/spring`` contact with a cubic repulsion ``k_a``
    (force/distance^3) that keeps particles from overlapping far.  The
    reference LAMMPS build mixes no ``k_a`` (pairs of types without a line
    get none), so every pair of types present needs its coefficients.
    BPMSpring's ``anharmonic`` chooses it."""

    coefficients = ("k", "r_c", "gamma", "k_a")
    non_negative = ("gamma", "k_a")
    compiled = True  # (compiled.spring_pairs, with k_a)

    def forces(self, pairs: PairInput) -> PairForces:
        c, r_p = pairs.coeff, pairs.r_p
        rinv_p = np.divide(1.0, r_p, out=np.zeros_like(r_p), where=r_p > 0)
        f_p, fd_p, energy_p = anharmonic_pair_magnitudes(
            r_p, rinv_p, pairs.r_pc, pairs.v_pc, c["k"], c["r_c"],
            c["gamma"] if pairs.v_pc is not None else None, c["k_a"])
        return PairForces(f_p, energy_p, fd_p)

    def stiffness(self, pairs: PairInput) -> LawStiffness:
        """The tangent ``k + 3 k_a (r_c - r)^2`` and ``gamma`` along the
        pair; nothing across (a repulsive pair softens sideways)."""
        c = pairs.coeff
        overlap_p = c["r_c"] - pairs.r_p
        return LawStiffness(c["k"] + 3.0 * c["k_a"] * overlap_p * overlap_p, c["gamma"])


#: (its style line names it among the contact laws, for the harness of
#: tests/test_every_law.py)
register_contact(AnharmonicSpringPair, f"{SpringPair.name} anharmonic yes")


def contact_energy(law: SpringPair, r_kc, coeff: dict) -> np.ndarray:
    """The energy of ``bpm/spring`` contacts (``law``: with or without
    ``anharmonic``) at vectors ``r_kc`` closer than ``r_c``, coefficients
    ``coeff`` by name."""
    r_k, _ = lengths(r_kc)
    return law.forces(PairInput(r_kc, r_k, coeff, coeff["r_c"])).energy_p
