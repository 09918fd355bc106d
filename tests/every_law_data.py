"""The data of tests/test_every_law.py: one entry for each registered law.

As LAMMPS's force-style unit tests keep one harness and a data file per
style, the harness here runs the same checks on every law registered in
``ase_bpm.laws.bond.LAWS`` (bond laws) and ``ase_bpm.laws.contact.CONTACT_LAWS``
(contact laws), and each law gives, in :data:`BOND_LAWS` or
:data:`CONTACT_LAWS`, what the checks need: a calculator running it with its
coefficients, a scene of a few particles that exercises it (bonds or
contacts stretched and pressed, particles moving), two particles joined by
one bond or contact for its stiffness, and how LAMMPS checks it.  A law
registered without an entry fails the harness, asking for one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
from ase import Atoms

import ase_bpm
from scenes import (HORIZON, MICROMODULUS, NODE_VOLUME, DENSITY, SPACING, fcc_cluster,
                    peri_model, sc_block, sphere_pile)

#: the names of the oracles the harness knows (tests/oracle.py and its kin)
SPRING, PERI, GRANULAR = "spring", "peri", "granular"


@dataclass(frozen=True)
class LawCase:
    """What the harness needs of one law."""

    #: ``calc(kernels, **parameters)``: a calculator running the law
    #: (``parameters`` override its own)
    calc: Callable
    #: a few particles in their reference state, moving (velocities; spins
    #: for spheres), bonded where the law is a bond law
    scene: Callable[[], Atoms]
    #: two particles at rest, joined by one bond or contact along x
    pair: Callable[[], Atoms]
    #: how far the second particle of :attr:`pair` moves along x from there
    #: for the stiffness check (stretching a bond, pressing a contact)
    stretch: float
    #: the largest random displacement of :attr:`scene` after its reference
    #: state (keeping every bond below its breaking strain)
    jitter: float
    dt: float  # the MD timestep
    spheres: bool = False  # driven by SphereVelocityVerlet (turning spheres)
    #: the oracle that checks the law's LAMMPS export (SPRING, PERI,
    #: GRANULAR), or None with :attr:`no_oracle` saying why
    oracle: Optional[str] = None
    no_oracle: Optional[str] = None
    #: parameters of the calculator for the oracle's check
    oracle_parameters: dict = field(default_factory=dict)
    #: parameters of the calculator for :attr:`pair`
    pair_parameters: dict = field(default_factory=dict)
    #: why the energy the calculator reports is not the potential of the
    #: law's forces (None: it is, and the harness checks it)
    not_potential: Optional[str] = None
    #: the history the law advances in a step and a pure evaluation only
    #: reads, so that the two differ (None: none; a pure evaluation then gives
    #: the step's forces, and the harness checks it)
    history: Optional[str] = None


def spring_cluster(bonded: int) -> Callable[[], Atoms]:
    """A jittered fcc block of 32 particles, moving; nearest neighbours
    among the first ``bonded`` bonded, the others touching through the
    pair law."""
    def scene():
        atoms, rng = fcc_cluster(2, seed=3)
        ase_bpm.create_bonds(atoms, 1.3, mask=np.arange(len(atoms)) < bonded)
        atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
        return atoms
    return scene


def rotational_cluster() -> Atoms:
    """A jittered fcc block of 32 spheres, nearest neighbours bonded,
    turned a little, moving and spinning."""
    atoms, rng = fcc_cluster(2, seed=3)
    ase_bpm.create_bonds(atoms, 1.3)
    atoms.arrays["radius"] = np.full(len(atoms), 0.5)
    axis_nc = rng.normal(size=(len(atoms), 3))
    axis_nc /= np.linalg.norm(axis_nc, axis=1)[:, None]
    half_n = rng.uniform(0, 0.02, len(atoms))
    atoms.arrays["quat"] = np.column_stack([np.cos(half_n), axis_nc * np.sin(half_n)[:, None]])
    atoms.arrays["omega"] = rng.normal(0, 0.02, atoms.positions.shape)
    atoms.set_velocities(rng.normal(0, 0.05, atoms.positions.shape))
    return atoms


def two(distance: float, bonded: bool, **arrays) -> Callable[[], Atoms]:
    """Two particles ``distance`` apart along x, at rest, with the per-atom
    ``arrays`` (each value for both); bonded where ``bonded``."""
    def scene():
        atoms = Atoms("H2", positions=[[0, 0, 0], [distance, 0, 0]], masses=[1.0, 1.0])
        for name, value in arrays.items():
            atoms.arrays[name] = np.array([value, value])
        if bonded:
            ase_bpm.create_bonds(atoms, 1.01 * distance)
        return atoms
    return scene


def peri_nodes(distance_in_spacings: float, bonded: bool) -> Callable[[], Atoms]:
    def scene():
        atoms = two(distance_in_spacings * SPACING, bonded, vfrac=NODE_VOLUME)()
        atoms.set_masses(np.full(2, DENSITY * NODE_VOLUME))
        return atoms
    return scene


def peri_block() -> Atoms:
    atoms = sc_block(4)
    atoms.set_velocities(np.random.default_rng(7).normal(0, 1.0, atoms.positions.shape))
    return atoms


def peri_bodies() -> Atoms:
    """Two blocks 1.2 spacings apart along x, closing: the contact acts
    between them (within 1.35 spacings)."""
    a, b = sc_block(3), sc_block(3, offset=(3.2, 0.3, 0.1))
    atoms = a + ase_bpm.renew_ids(b)
    v = np.random.default_rng(8).normal(0, 0.5, atoms.positions.shape)
    v[:len(a), 0] += 2.0
    v[len(a):, 0] -= 2.0
    atoms.set_velocities(v)
    return atoms


def spring_calc(**own):
    return lambda kernels, **parameters: ase_bpm.BPMSpring(
        **{**own, "kernels": kernels, **parameters})


def peri_calc(**own):
    return lambda kernels, **parameters: ase_bpm.BPMPeri(
        **{"timestep": PERI_DT, **own, "kernels": kernels, **parameters})


def granular_calc(model: str, kn: float):
    return lambda kernels, **parameters: ase_bpm.Granular(
        model, **{"kn": kn, "gamma_n": 20.0, "xmu": 0.3, "timestep": GRANULAR_DT,
                  "kernels": kernels, **parameters})


PERI_DT = 1e-7
GRANULAR_DT = 1e-3
#: bond_style and pair_style bpm/peri are newer than the reference LAMMPS
#: build (/work/shared/REFERENCE.md): the PERI laws are checked against the
#: legacy peri/* pair styles, which they follow with follows="legacy"; those
#: carry the contact, so their export asks for its coefficients
PERI_LEGACY = dict(follows="legacy", pair_coeffs={(1, 1): (MICROMODULUS, HORIZON)})


#: (BPMPeri's docstring: "for ves and eps the recoverable part"; following
#: bond_style bpm/peri, even ves with lambda = 0 and eps below yield differ
#: from the derivative of their energy by about 1 %, while lps does not)
RECOVERABLE = ("BPMPeri reports the recoverable part of the energy of ves and eps, not a "
               "potential of their forces")


def peri_bond(name: str, not_potential: Optional[str] = None,
              history: Optional[str] = None) -> LawCase:
    return LawCase(
        calc=peri_calc(bond_coeffs={1: peri_model(name)}), scene=peri_block,
        pair=peri_nodes(1.0, bonded=True), stretch=0.01 * SPACING, jitter=0.01 * SPACING,
        dt=PERI_DT, oracle=PERI, oracle_parameters=PERI_LEGACY,
        pair_parameters=dict(lattice_spacing=SPACING), not_potential=not_potential,
        history=history)


def granular(model: str, kn: float) -> LawCase:
    history = "the shear displacement of each contact (gran_shear)"
    return LawCase(
        calc=granular_calc(model, kn), scene=lambda: sphere_pile(n=3, seed=1),
        pair=two(0.95, bonded=False, radius=0.5, omega=np.zeros(3)), stretch=-0.02, jitter=0.02, dt=GRANULAR_DT,
        spheres=True, oracle=GRANULAR, history=history if "history" in model else None)


#: bond laws (``ase_bpm.laws.bond.LAWS``) by name
BOND_LAWS = {
    # smooth=False: the energy LAMMPS reports leaves the smoothing factor out,
    # so only then is it the potential of the forces
    "bpm/spring": LawCase(
        calc=spring_calc(bond_coeffs={1: (1.0, 0.2, 0.5)}, smooth=False),
        scene=spring_cluster(bonded=32), pair=two(1.0, bonded=True), stretch=0.05,
        jitter=0.03, dt=0.05, oracle=SPRING),
    "bpm/rotational": LawCase(
        calc=spring_calc(bond_coeffs={1: ("bpm/rotational", 1.0, 0.6, 0.05, 0.08, 0.2, 0.15,
                                          0.05, 0.06, 0.3, 0.2, 0.02, 0.01)}),
        scene=rotational_cluster, pair=two(1.0, bonded=True, radius=0.5,
                                           omega=np.zeros(3), quat=np.array([1.0, 0, 0, 0])),
        stretch=0.05, jitter=0.03, dt=0.05, spheres=True, oracle=SPRING,
        not_potential="the forces and torques of bpm/rotational derive from no energy: "
                      "LAMMPS reports it as zero, and so does ase_bpm"),
    # eps_p above the scene's strains: elastic, so that its energy is the
    # potential of its forces (tests/test_spring_variants.py makes it yield)
    "bpm/spring/plastic": LawCase(
        calc=spring_calc(bond_coeffs={1: ("bpm/spring/plastic", 1.0, 0.2, 0.5, 0.1)}),
        scene=spring_cluster(bonded=32), pair=two(1.0, bonded=True), stretch=0.05,
        jitter=0.03, dt=0.05, oracle=SPRING),
    "pmb": peri_bond("pmb"),
    "lps": peri_bond("lps"),
    "ves": peri_bond("ves", RECOVERABLE, history="the viscous part of each bond's "
                                                "extension (bond_ves)"),
    "eps": peri_bond("eps", RECOVERABLE),
}

#: contact laws (``ase_bpm.laws.contact.CONTACT_LAWS``) by LAMMPS pair style
CONTACT_LAWS = {
    # (a few bonds too: the bonded pairs are left out of contact, as LAMMPS's
    # special_bonds lj 0 leaves them; a scene without bonds is in
    # tests/test_lammps_round_trip.py)
    "bpm/spring": LawCase(
        calc=spring_calc(pair_coeffs={(1, 1): (1.0, 1.3, 0.5)},
                         bond_coeffs={1: (1.0, 0.2, 0.0)}),
        scene=spring_cluster(bonded=8), pair=two(1.0, bonded=False), stretch=-0.05,
        jitter=0.03, dt=0.05, oracle=SPRING, pair_parameters=dict(bond_coeffs={})),
    "bpm/spring anharmonic yes": LawCase(
        calc=spring_calc(pair_coeffs={(1, 1): (1.0, 1.3, 0.5, 20.0)},
                         bond_coeffs={1: (1.0, 0.2, 0.0)}, anharmonic=True),
        scene=spring_cluster(bonded=8), pair=two(1.0, bonded=False), stretch=-0.05,
        jitter=0.03, dt=0.05, oracle=SPRING, pair_parameters=dict(bond_coeffs={})),
    "bpm/peri": LawCase(
        calc=peri_calc(bond_coeffs={1: peri_model("pmb")},
                       pair_coeffs={(1, 1): (MICROMODULUS, HORIZON)}, lattice_spacing=SPACING),
        scene=peri_bodies, pair=peri_nodes(1.2, bonded=False), stretch=-0.01 * SPACING,
        jitter=0.01 * SPACING, dt=PERI_DT,
        no_oracle="pair_style bpm/peri is newer than the reference LAMMPS build "
                  "(/work/shared/REFERENCE.md), and the legacy peri/* styles it has bond "
                  "every pair within the horizon: two bodies in contact have no legacy form",
        pair_parameters=dict(bond_coeffs={})),
    "gran/hooke": granular("hooke", 1000.0),
    "gran/hooke/history": granular("hooke/history", 1000.0),
    # Hertz stiffness is per unit sqrt(overlap * R_eff)
    "gran/hertz/history": granular("hertz/history", 6000.0),
}
