"""The demo scenes as the trade report runs them, and what is read off a run.

A :class:`Scene` builds fresh atoms with their calculator and integrator at a
given timestep; :func:`simulate` runs it for the scene's simulated time and
returns a :class:`Run`: cost, the observables a user reads off the run, the
kinetic energy history and the energy ledger.  Every run of a scene covers
the same simulated time and is sampled at the same times, whatever its
timestep: the number of steps is a multiple of the number of samples, so the
timestep is at most the one asked for.
"""

from __future__ import annotations

import tradeoff_common  # noqa: F401  (one thread, before numpy is imported)

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ase_bpm.core.bonds import get_bonds
from ase_bpm.core.spheres import rotational_energy
from ase_bpm.scene.demos import impact, pour, shatter

#: kinetic-energy samples per run (the history compared between runs)
SAMPLES = 50
#: bins of the per-atom damage histogram, on [0, 1]
DAMAGE_BINS = 10
NUDGE_SEED = 20261123
#: impact trajectories are compared at this time: 20 time units into the contact
IMPACT_HORIZON = 50.0


@dataclass
class Run:
    """One run of a scene at one timestep."""

    dt: float
    steps: int
    seconds: float
    observables: dict  # name -> value (scalars) or array (damage histogram)
    kinetic_n: np.ndarray  # kinetic energy at the SAMPLES + 1 sample times
    ledger_n: np.ndarray  # kinetic + potential + dissipated + broken-bond energy
    early_nc: np.ndarray  # positions at the scene's ``horizon``
    extra: dict = field(default_factory=dict)

    @property
    def ms_per_step(self) -> float:
        return 1e3 * self.seconds / self.steps


def damage_histogram(damage_n) -> np.ndarray:
    """Fraction of atoms per damage bin (bins of width 1 / DAMAGE_BINS)."""
    counts, _ = np.histogram(damage_n, bins=DAMAGE_BINS, range=(0.0, 1.0))
    return counts / max(len(damage_n), 1)


def fragments(atoms, members) -> np.ndarray:
    """Sizes of the pieces (connected by intact bonds) among the atoms
    ``members`` (a boolean mask), largest first."""
    i_b, j_b, _ = get_bonds(atoms)
    n = len(atoms)
    graph = coo_matrix((np.ones(len(i_b)), (i_b, j_b)), shape=(n, n))
    _, label_n = connected_components(graph, directed=False)
    sizes = np.bincount(label_n[members])
    return np.sort(sizes[sizes > 0])[::-1]


def slab_volume(z_n, r_n, lo: float, hi: float) -> np.ndarray:
    """Volume of each sphere (centre height ``z_n``, radius ``r_n``) between
    the planes ``z = lo`` and ``z = hi``: the integral of the cross-section
    pi (r^2 - t^2) over the part of ``t`` in [-r, r] inside the slab."""
    def integral(t_n):
        return np.pi * (r_n ** 2 * t_n - t_n ** 3 / 3)

    below = np.clip(lo - z_n, -r_n, r_n)
    above = np.clip(hi - z_n, -r_n, r_n)
    return integral(above) - integral(below)


def bond_counts(atoms) -> np.ndarray:
    """Intact bonds per atom."""
    i_b, j_b, _ = get_bonds(atoms)
    return np.bincount(np.r_[i_b, j_b], minlength=len(atoms))


def bond_damage(atoms, nbonds0_n) -> np.ndarray:
    """Per-atom fraction of its starting bonds that are broken."""
    has = nbonds0_n > 0
    return 1.0 - bond_counts(atoms)[has] / nbonds0_n[has]


class Scene:
    """A demo scene: ``build()`` gives atoms with a calculator, ``integrator``
    the dynamics at a timestep, ``observe`` what is read off at the end."""

    name: str
    duration: float  # simulated time of every run
    demo_dt: float  # the demo's own timestep
    horizon: float  # trajectories are compared at this time (before chaos takes over)

    def build(self):
        raise NotImplementedError

    def integrator(self, atoms, dt):
        from ase.md.verlet import VelocityVerlet

        return VelocityVerlet(atoms, timestep=dt)

    def prepare(self, atoms) -> dict:
        """What ``observe`` needs from the start of the run."""
        return {}

    def observe(self, atoms, start: dict) -> dict:
        raise NotImplementedError

    def estimate(self) -> float:
        """``stable_timestep`` of the scene as it starts."""
        atoms = self.build()
        return atoms.calc.stable_timestep(atoms)


class Impact(Scene):
    """``ase-bpm demo impact``: BPMSpring, a ball through a bonded disk."""

    name = "impact"
    demo_dt = impact.TIMESTEP

    def __init__(self, quick: bool):
        self.size = impact.QUICK if quick else impact.FULL
        self.duration = (impact.QUICK_STEPS if quick else impact.STEPS) * impact.TIMESTEP
        # the ball reaches the disk after about 30 time units (both sizes)
        self.horizon = self.duration / SAMPLES * round(IMPACT_HORIZON * SAMPLES / self.duration)

    def build(self):
        from ase_bpm import BPMSpring

        atoms = impact.impact_scene(**self.size)
        atoms.calc = BPMSpring(bond_coeffs=impact.BOND_COEFFS, pair_coeffs=impact.PAIR_COEFFS)
        return atoms

    def prepare(self, atoms) -> dict:
        counts_n = bond_counts(atoms)
        return {"nbonds": counts_n, "bonds": int(counts_n.sum()) // 2}

    def observe(self, atoms, start: dict) -> dict:
        disk = atoms.arrays["body"] == 0
        pieces = fragments(atoms, disk)
        return {"broken bonds": start["bonds"] - len(get_bonds(atoms)[0]),
                "damage histogram": damage_histogram(bond_damage(atoms, start["nbonds"])),
                "disk fragments": int((pieces >= 2).sum()),
                "largest disk fragment": int(pieces[0])}


class Shatter(Scene):
    """``ase-bpm demo shatter``: BPMPeri (pmb), a cylinder and an indenter."""

    name = "shatter"
    demo_dt = shatter.TIMESTEP

    def __init__(self, quick: bool):
        self.duration = (shatter.QUICK_STEPS if quick else shatter.STEPS) * shatter.TIMESTEP
        self.horizon = 0.1 * self.duration  # the indenter touches within 5 demo steps

    def build(self):
        from ase_bpm import BPMPeri
        from ase_bpm.scene.fixes import SphericalIndenter

        atoms = shatter.cylinder()
        # the spacing given: the chaos floor's nudged nodes are not on a lattice
        atoms.calc = BPMPeri(bond_coeffs=shatter.BOND_COEFFS, pair_coeffs=shatter.PAIR_COEFFS,
                             fixes=[SphericalIndenter(**shatter.INDENTER)],
                             lattice_spacing=shatter.SPACING, follows="legacy")  # (the demo's)
        return atoms

    def integrator(self, atoms, dt):
        from ase_bpm.scene.md import VelocityVerlet  # the indenter's clock

        return VelocityVerlet(atoms, timestep=dt)

    def prepare(self, atoms) -> dict:
        return {"bonds": len(get_bonds(atoms)[0])}

    def observe(self, atoms, start: dict) -> dict:
        pieces = fragments(atoms, np.ones(len(atoms), bool))
        return {"broken bonds": start["bonds"] - len(get_bonds(atoms)[0]),
                "damage histogram": damage_histogram(atoms.arrays["damage"]),
                "mean damage": float(atoms.arrays["damage"].mean()),
                "fragments": int((pieces >= 2).sum())}


class Pour(Scene):
    """``ase-bpm demo pour``: Granular (hooke/history), spheres settling in a box.
    Nothing touches at the start, so its estimate is taken on the settled
    pile of a run at the demo's timestep."""

    name = "pour"
    demo_dt = pour.TIMESTEP

    def __init__(self, quick: bool, kernels: str = "auto"):
        self.size = pour.QUICK if quick else pour.FULL
        self.duration = (pour.QUICK_STEPS if quick else pour.STEPS) * pour.TIMESTEP
        self.kernels = kernels
        self.horizon = 0.1 * self.duration  # falling, the first spheres reach the floor
        self._settled = None

    def build(self):
        atoms = pour.pour_scene(**self.size)
        atoms.calc = pour.pour_calculator(self.size["width"], kernels=self.kernels)
        return atoms

    def integrator(self, atoms, dt):
        from ase_bpm.scene.md import SphereVelocityVerlet

        return SphereVelocityVerlet(atoms, dt)

    def observe(self, atoms, start: dict) -> dict:
        r_n, z_n = atoms.arrays["radius"], atoms.positions[:, 2]
        top = float(np.quantile(z_n + r_n, 0.95))
        # the bulk of the pile: a slab one largest diameter clear of the
        # floor and of the surface
        lo, hi = 2 * r_n.max(), top - 2 * r_n.max()
        solid = slab_volume(z_n, r_n, lo, hi).sum()
        width = self.size["width"]
        bulk = (z_n > lo) & (z_n < hi)
        return {"packing fraction": solid / (width * width * (hi - lo)),
                "coordination number": float(atoms.arrays["ncontacts"][bulk].mean()),
                "pile height": top}

    def estimate(self) -> float:
        """On the pile settled at the demo's timestep (the start has no contacts)."""
        if self._settled is None:
            self._settled = simulate(self, self.demo_dt)
        return self._settled.extra["estimate_at_end"]


def steps_for(scene: Scene, dt: float) -> int:
    """Steps covering the scene's duration at a timestep of at most ``dt``,
    a multiple of SAMPLES."""
    return SAMPLES * math.ceil(scene.duration / (dt * SAMPLES) - 1e-9)


def simulate(scene: Scene, dt_asked: float, nudge: float = 0.0, keep_atoms: bool = False,
             **options) -> Run:
    """Run ``scene`` over its duration at (at most) ``dt_asked``, with the
    calculator's parameters ``options`` changed from the demo's and every
    position moved at random by up to ``nudge`` (seeded) along each axis;
    with ``keep_atoms`` the final atoms are in ``extra["atoms"]``."""
    steps = steps_for(scene, dt_asked)
    dt = scene.duration / steps
    atoms = scene.build()
    if nudge:
        atoms.positions += np.random.default_rng(NUDGE_SEED).uniform(
            -nudge, nudge, atoms.positions.shape)
    if options:
        atoms.calc.set(**options)
    start = scene.prepare(atoms)
    calc = atoms.calc
    dyn = scene.integrator(atoms, dt)
    every = steps // SAMPLES
    early = round(scene.horizon / scene.duration * SAMPLES)
    kinetic, ledger, early_nc = [], [], None

    def energy_total():
        r = calc.results
        spin = rotational_energy(atoms) if "omega" in atoms.arrays else 0.0
        return (atoms.get_kinetic_energy() + spin + atoms.get_potential_energy()
                + r.get("dissipated_energy", 0.0) + r.get("broken_bond_energy", 0.0))

    seconds = 0.0
    kinetic.append(atoms.get_kinetic_energy())
    ledger.append(energy_total())
    for sample in range(1, SAMPLES + 1):
        _, took = tradeoff_common.timed(dyn.run, every)
        seconds += took
        kinetic.append(atoms.get_kinetic_energy())
        ledger.append(energy_total())
        if sample == early:
            early_nc = atoms.positions.copy()
    extra = {}
    if isinstance(scene, Pour):
        extra["estimate_at_end"] = calc.stable_timestep(atoms)
    if keep_atoms:
        extra["atoms"] = atoms
    return Run(dt, steps, seconds, scene.observe(atoms, start), np.array(kinetic),
               np.array(ledger), early_nc, extra)


def scenes(quick: bool) -> list:
    return [Impact(quick), Shatter(quick), Pour(quick)]
