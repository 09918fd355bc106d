"""Peridynamic horizon, PMB against LPS: the speed of a long elastic wave.

What it measures
----------------
The speed of a long longitudinal wave in BPMPeri's pmb and lps solids on a
simple cubic lattice of spacing ``h`` (as the LAMMPS PERI examples use), for
horizons of 3, 4 and 5 spacings, against continuum elasticity; and what a
step costs.  ``section(quick, figures)`` runs it for ``benchmarks/tradeoff.py``.

The material is the LAMMPS PERI example's (SI units): ``h = 0.5 mm``, node
volume ``V = h^3``, density ``rho = 2200 kg/m^3``, bulk modulus
``K = 14.9 GPa``.

* **pmb** takes the micromodulus ``c = 18 K / (pi delta^4)`` (Silling and
  Askari 2005; LAMMPS Howto_peri, eq. 6): bulk modulus ``K`` and Poisson
  ratio 1/4, so shear modulus ``G = 3K/5``.
* **lps** takes ``K`` and ``G`` (Silling et al. 2007; LAMMPS ``pair_style
  peri/lps``); here the LAMMPS example's ``G = K`` (Poisson ratio 1/8).
  ``G = 3K/5`` would test less: the dilatation term of the force carries the
  factor ``3K - 5G``, which then vanishes, and lps becomes a bond-based model
  with micromodulus ``18 K / m``, the weighted volume ``m = sum_j s r0 V`` in
  place of its continuum value ``pi delta^4``.

The horizon is ``delta = (n + 0.0002) h``: just above ``n`` spacings, as the
example's 0.0015001 m, so that round-off cannot drop the bonds of length
exactly ``n h``.  A bond within half a spacing of the horizon counts a
linearly reduced share ``s`` of its partner's volume, 1/2 at the horizon
(LAMMPS Howto_peri, "Modification to the particle volume";
``ase_bpm.laws.peri.partial_volume``).

The analytic speeds
-------------------
* Where the solid cannot contract sideways (uniaxial strain: an unbounded
  body, or a column periodic across), the P-wave speed
  ``c_P = sqrt((K + 4G/3) / rho)``: 3,492 m/s for pmb, 3,975 m/s for lps.
* In a free bar much thinner than the wavelength (uniaxial stress), the bar
  speed ``c_bar = sqrt(E / rho)``, ``E = 9 K G / (3K + G)``: 3,187 and
  3,904 m/s.

The main measurement uses the first, in a column periodic in all three
directions and the same for every horizon: ``2 n_max + 1`` spacings across
(the narrowest in which every pair within the largest horizon has a single
periodic image) and ``L = 12 n_max`` spacings long.  A plane wave along it is
uniform across, so the width does not matter and no node lacks bonds:
``c_P`` holds exactly in the long-wave limit.  A free bar cannot give its
limit as cleanly: the bar speed needs a width well below the wavelength, and
escaping the surface effect (nodes within a horizon of the surface lack
bonds) needs a width of many horizons, hundreds of thousands of nodes at
``delta = 5 h``.  The second table shows a free bar of ``BAR_WIDTH`` x
``BAR_WIDTH`` nodes against ``c_bar``: the surface effect at its strongest.

How the speed is measured
-------------------------
The nodes are displaced by the first two standing waves the box allows,
``u_x = a (sin(k x) + sin(2k x) / 2)``, ``k = 2 pi / L``, ``a k = 1e-5``
(linear; nothing breaks), and released at rest; the free bar's nodes also
start at the sideways contraction of uniaxial stress, ``-nu eps_xx (y -
y_mean)``, so that its breathing modes hardly ripple the projections.  On a
lattice periodic along ``x`` each wavenumber is a separate normal mode
(translation symmetry), so the projection of ``u_x`` on ``sin(j k x)``
oscillates as ``cos(omega_j t)`` with no phase: its zero crossings (linearly
interpolated between steps) fall at ``t = (i + 1/2) pi / omega_j``, and a
least-squares line through them gives ``omega_j``.  A pulse's time of
arrival would depend on how a dispersive front is read; a mode's period
does not.

The phase speed ``omega_j / (j k)`` of a peridynamic solid falls with the
wavenumber (dispersion, ``1 - 0.02 (k delta)^2`` for continuum pmb) and
velocity Verlet raises a frequency by ``(omega dt)^2 / 24``; both errors grow
as ``k^2``, so ``c0^2 = (4 c_1^2 - c_2^2) / 3`` (Richardson) removes them and
leaves the long-wave speed of the discrete model (to 1e-4 or better, ``L``
being at least 12 horizons).  The tables give that speed, the speed at
``lambda = L`` as a run shows it, and the long-wave speed the lattice sums
predict (:func:`lattice_long_wave`): for a wave along ``x``, summed over one
node's bonds (unit direction ``n``, length ``r0``),

* pmb: ``rho c^2 = (c V / 2) sum s r0 n_x^4``,
* lps: ``rho c^2 = K - 5G/3 + 15 G V sum s r0 n_x^4 / m``

(their continuum integrals give ``K + 4G/3``; lps's ``K`` is exact on the
lattice, its ``G`` part carries the lattice's fourth moment).  The timestep is
``TIMESTEP_FRACTION`` of ``calc.stable_timestep(atoms)`` in every run; the
cost is the wall time of the steps on one thread (set-up excluded).

Array suffixes as in the package: ``_n`` nodes, ``_b`` bonds, ``_c``
Cartesian components; here also ``_j`` the excited modes, ``_s`` samples in
time and ``_z`` zero crossings.
"""

from __future__ import annotations

import tradeoff_common  # noqa: F401  (one thread, before numpy is imported)

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from ase import Atoms

import ase_bpm
from ase_bpm.laws.peri import partial_volume
from ase_bpm import VelocityVerlet
from ase_bpm.models.peri import WVOLUME
from tradeoff_common import pyplot, save_figure, table, timed

TITLE = "## Peridynamic horizon, PMB against LPS: the wave speed of a bar"

SPACING = 0.0005  # lattice spacing h (m), the LAMMPS PERI example's
DENSITY = 2200.0  # kg/m^3
BULK = 14.9e9  # K (Pa)
LPS_SHEAR = BULK  # G of lps (Pa): the LAMMPS peri/lps example's, Poisson ratio 1/8
PMB_SHEAR = 0.6 * BULK  # G = 3K/5 of pmb: Poisson ratio 1/4
NODE_VOLUME = SPACING ** 3
HORIZON_MARGIN = 2e-4  # spacings beyond n: the example's 0.0015001 m = 3.0002 h
OTHER_MARGIN = 0.015  # another common choice (delta = 3.015 h), in the lattice sums only
HORIZONS = (3, 4, 5)  # in lattice spacings
QUICK_HORIZONS = (3, 4)
#: never reached (strains of 1e-5, and breaking is off); small, so that a
#: bond's reach (1 + s00) r0 stays within half the narrow periodic cell
BREAKING_STRETCH = 0.01
COLUMN_LENGTH = 12  # the periodic column, in largest horizons: the first mode's wavelength
BAR_WIDTH = 8  # nodes across the free bar
BAR_LENGTH = 60  # spacings along the free bar (periodic along it)
STRAIN = 1e-5  # largest strain of each mode
MODES = (1, 2)  # the standing waves excited, in units of 2 pi / L (Run.long_wave's)
TIMESTEP_FRACTION = 0.5  # of calc.stable_timestep(atoms)
#: how long to run, in periods of the first mode at the analytic speed: the
#: first mode's second zero crossing comes at 3/4 of its period, so this
#: leaves room for a wave 37 % slower than the analytic one
DURATION = 1.2
MODELS = ("pmb", "lps")


# -- the material and its analytic wave speeds ------------------------------------------
def horizon(n: int) -> float:
    """The horizon just above ``n`` lattice spacings (m)."""
    return (n + HORIZON_MARGIN) * SPACING


def shear_modulus(model: str) -> float:
    return PMB_SHEAR if model == "pmb" else LPS_SHEAR


def bond_coeffs(model: str, n: int) -> dict:
    """``bond_coeffs`` of BPMPeri for the model at horizon ``n`` spacings."""
    delta = horizon(n)
    if model == "pmb":
        micromodulus = 18.0 * BULK / (np.pi * delta ** 4)
        return {1: ("pmb", micromodulus, delta, BREAKING_STRETCH, 0.0)}
    return {1: ("lps", BULK, LPS_SHEAR, delta, BREAKING_STRETCH, 0.0)}


def p_wave_speed(model: str) -> float:
    """``sqrt((K + 4G/3) / rho)``: a long wave under uniaxial strain."""
    return float(np.sqrt((BULK + 4.0 * shear_modulus(model) / 3.0) / DENSITY))


def bar_speed(model: str) -> float:
    """``sqrt(E / rho)``, ``E = 9KG / (3K + G)``: a long wave in a thin free bar."""
    g = shear_modulus(model)
    return float(np.sqrt(9.0 * BULK * g / (3.0 * BULK + g) / DENSITY))


def poisson_ratio(model: str) -> float:
    """``(3K - 2G) / (2 (3K + G))``."""
    g = shear_modulus(model)
    return (3.0 * BULK - 2.0 * g) / (2.0 * (3.0 * BULK + g))


def neighbourhood(n: int, margin: float = HORIZON_MARGIN):
    """One node's bonds on an unbounded simple cubic lattice, horizon
    ``(n + margin)`` spacings: ``(xi_bc, r0_b, scale_b)``, the bond vectors,
    their lengths and their partial-volume factors."""
    reach = np.arange(-n - 1, n + 2)
    xi_bc = np.array(np.meshgrid(reach, reach, reach, indexing="ij")).reshape(3, -1).T
    xi_bc = xi_bc * SPACING
    r0_b = np.linalg.norm(xi_bc, axis=1)
    delta = (n + margin) * SPACING
    inside = (r0_b > 0) & (r0_b <= delta)
    return xi_bc[inside], r0_b[inside], partial_volume(r0_b[inside], delta, SPACING)


def weighted_volume(n: int, margin: float = HORIZON_MARGIN) -> float:
    """``m = sum_j s r0 V`` (influence function ``1/r0``) of a node inside
    the lattice: its continuum value is ``pi delta^4``."""
    _, r0_b, scale_b = neighbourhood(n, margin)
    return float(NODE_VOLUME * np.sum(scale_b * r0_b))


def lattice_long_wave(model: str, n: int, margin: float = HORIZON_MARGIN,
                      micromodulus: float | None = None) -> float:
    """The long-wave P speed of the discrete model on an unbounded simple
    cubic lattice, horizon ``(n + margin)`` spacings: the continuum integrals
    of the P-wave modulus replaced by the sums over one node's bonds (see the
    module docstring).  ``micromodulus``: pmb's ``c`` (default
    ``18 K / (pi delta^4)``)."""
    xi_bc, r0_b, scale_b = neighbourhood(n, margin)
    moment = NODE_VOLUME * np.sum(scale_b * r0_b * (xi_bc[:, 0] / r0_b) ** 4)
    if model == "pmb":
        delta = (n + margin) * SPACING
        c = 18.0 * BULK / (np.pi * delta ** 4) if micromodulus is None else micromodulus
        modulus = 0.5 * c * moment
    else:
        modulus = (BULK - 5.0 * LPS_SHEAR / 3.0
                   + 15.0 * LPS_SHEAR * moment / weighted_volume(n, margin))
    return float(np.sqrt(modulus / DENSITY))


# -- the scenes ----------------------------------------------------------------------------
def lattice_block(nx: int, width: int, pbc) -> Atoms:
    """``nx`` x ``width`` x ``width`` simple cubic nodes of the material."""
    grid = np.indices((nx, width, width)).reshape(3, -1).T
    atoms = Atoms(f"Si{len(grid)}", positions=grid * SPACING,
                  cell=np.diag([nx, width, width]) * SPACING, pbc=pbc)
    atoms.arrays["vfrac"] = np.full(len(atoms), NODE_VOLUME)
    atoms.set_masses(np.full(len(atoms), DENSITY * NODE_VOLUME))
    return atoms


def column(largest: int) -> Atoms:
    """Periodic in all three directions, the same for every horizon up to
    ``largest`` spacings: ``2 largest + 1`` spacings across (each pair within
    the horizon has one periodic image) and ``COLUMN_LENGTH * largest`` long."""
    return lattice_block(COLUMN_LENGTH * largest, 2 * largest + 1, pbc=True)


def free_bar() -> Atoms:
    """``BAR_WIDTH`` x ``BAR_WIDTH`` nodes across, free sideways, periodic along
    ``x`` (``BAR_LENGTH`` spacings)."""
    return lattice_block(BAR_LENGTH, BAR_WIDTH, pbc=(True, False, False))


# -- the measurement ---------------------------------------------------------------------
def zero_crossing_frequency(t_s, a_s) -> float:
    """Angular frequency of ``a(t) = A cos(omega t)`` from its zero crossings
    (linear interpolation between samples; crossing ``i`` at
    ``(i + 1/2) pi / omega``, a least-squares line through the origin)."""
    t_s, a_s = np.asarray(t_s), np.asarray(a_s)
    before_z = np.flatnonzero(np.sign(a_s[:-1]) * np.sign(a_s[1:]) < 0)
    if len(before_z) == 0:
        raise RuntimeError("the mode did not cross zero: run longer")
    after_z = before_z + 1
    crossing_z = t_s[before_z] - a_s[before_z] * (t_s[after_z] - t_s[before_z]) \
        / (a_s[after_z] - a_s[before_z])
    phase_z = (np.arange(len(before_z)) + 0.5) * np.pi
    return float(phase_z @ phase_z / (phase_z @ crossing_z))


@dataclass
class Run:
    model: str
    n: int  # horizon in spacings
    nodes: int
    bonds_per_node: float
    stable_dt: float  # s
    dt: float  # s, TIMESTEP_FRACTION of stable_dt
    steps: int
    ms_per_step: float
    length: float  # of the box along x: the first mode's wavelength (m)
    speed_j: np.ndarray  # phase speed of each mode of MODES (m/s)
    time_s: np.ndarray  # for the figure: the first mode's amplitude over time
    amplitude_s: np.ndarray

    @property
    def long_wave(self) -> float:
        """Richardson: the ``k^2`` errors of modes 1 and 2 cancel."""
        c1, c2 = self.speed_j
        return float(np.sqrt((4.0 * c1 ** 2 - c2 ** 2) / 3.0))


def measure(atoms: Atoms, model: str, n: int, reference_speed: float,
            nu: float = 0.0) -> Run:
    """Excite the modes of :data:`MODES` at rest, run velocity Verlet at
    ``TIMESTEP_FRACTION`` of the stable timestep for ``DURATION`` periods of
    the first mode at ``reference_speed``, and read each mode's frequency.

    A free bar contracts sideways as it stretches: Poisson's ratio ``nu`` starts
    its nodes at the lateral displacement of uniaxial stress,
    ``-nu eps_xx (y - y_mean)``, so that the bar's breathing modes, which
    would ripple the projections, are hardly excited."""
    ase_bpm.create_bonds(atoms, horizon(n))
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs=bond_coeffs(model, n), break_bonds=False)
    atoms.get_forces()  # the reference lengths and weighted volumes, at rest
    stable_dt = atoms.calc.stable_timestep(atoms)
    dt = TIMESTEP_FRACTION * stable_dt
    length = atoms.cell[0, 0]
    x0_n = atoms.positions[:, 0].copy()
    k_j = 2.0 * np.pi / length * np.asarray(MODES)
    shape_jn = np.sin(np.outer(k_j, x0_n))
    amplitude_j = STRAIN / k_j  # each mode's largest strain: STRAIN
    atoms.positions[:, 0] += amplitude_j @ shape_jn
    strain_n = (amplitude_j * k_j) @ np.cos(np.outer(k_j, x0_n))
    across_nc = atoms.positions[:, 1:] - atoms.positions[:, 1:].mean(axis=0)
    atoms.positions[:, 1:] -= nu * strain_n[:, None] * across_nc
    norm_j = np.einsum("jn,jn->j", shape_jn, shape_jn)
    projection = []

    def record():
        projection.append(shape_jn @ (atoms.positions[:, 0] - x0_n) / norm_j)

    steps = int(np.ceil(DURATION * length / reference_speed / dt))
    dyn = VelocityVerlet(atoms, timestep=dt)
    dyn.attach(record, interval=1)  # at the start and after each step
    _, wall = timed(dyn.run, steps)
    projection_sj = np.array(projection)
    time_s = np.arange(len(projection_sj)) * dt
    speed_j = np.array([zero_crossing_frequency(time_s, projection_sj[:, j]) / k_j[j]
                        for j in range(len(MODES))])
    bonds = int(np.count_nonzero(atoms.arrays["bond_type"] > 0))
    return Run(model, n, len(atoms), 2.0 * bonds / len(atoms), stable_dt, dt, steps,
               1e3 * wall / steps, length, speed_j, time_s,
               projection_sj[:, 0] / amplitude_j[0])


# -- the report ---------------------------------------------------------------------------
def percent(value: float) -> str:
    return f"{100.0 * value:+.2f} %"


def listing(values) -> str:
    return ", ".join(percent(v) for v in values)


def spread(values) -> str:
    """``"1.6 to 1.9"``, or ``"1.7"`` where the two ends round alike."""
    low, high = f"{min(values):.1f}", f"{max(values):.1f}"
    return low if low == high else f"{low} to {high}"


def column_rows(runs) -> list:
    rows = []
    for r in runs:
        reference = p_wave_speed(r.model)
        rows.append([r.model, r.n, f"{r.bonds_per_node:.0f}",
                     f"{1e6 * r.stable_dt:.3f}", f"{1e6 * r.dt:.3f}", r.steps,
                     f"{r.ms_per_step:.1f}", f"{r.ms_per_step / (1e6 * r.dt):.0f}",
                     f"{r.speed_j[0]:.0f}", f"{r.long_wave:.0f}",
                     percent(r.long_wave / reference - 1.0),
                     percent(lattice_long_wave(r.model, r.n) / reference - 1.0)])
    return rows


def bar_rows(bars, columns) -> list:
    rows = []
    for r in bars:
        bulk = next(c for c in columns if (c.model, c.n) == (r.model, r.n))
        rows.append([r.model, r.n, f"{r.bonds_per_node:.0f}", f"{1e6 * r.dt:.3f}",
                     f"{r.ms_per_step:.1f}", f"{r.long_wave:.0f}",
                     percent(r.long_wave / bar_speed(r.model) - 1.0),
                     percent(bulk.long_wave / p_wave_speed(r.model) - 1.0)])
    return rows


def figure(columns, bars, figures: Path) -> str:
    """Error against cost per node and step (column and free bar), and the
    first mode of each column run against time."""
    plt = pyplot()
    from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    colours = {"pmb": "tab:blue", "lps": "tab:red"}
    for runs, reference, marker, label in ((columns, p_wave_speed, "o", "periodic column"),
                                           (bars, bar_speed, "s", "free bar")):
        for model in MODELS:
            mine = [r for r in runs if r.model == model]
            cost = [1e3 * r.ms_per_step / r.nodes for r in mine]
            error = [100.0 * (r.long_wave / reference(model) - 1.0) for r in mine]
            left.plot(cost, error, marker=marker, color=colours[model],
                      fillstyle="full" if marker == "o" else "none",
                      label=f"{model}, {label}")
            for r, x, y in zip(mine, cost, error):
                left.annotate(f"{r.n}h", (x, y), textcoords="offset points", xytext=(4, 4),
                              fontsize=8, color=colours[model])
    left.axhline(0.0, color="grey", lw=0.5)
    left.set_xscale("log")
    left.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    left.xaxis.set_major_formatter(ScalarFormatter())
    left.xaxis.set_minor_formatter(NullFormatter())
    left.set_xlabel("cost per node and step (us, one thread)")
    left.set_ylabel("long-wave speed error (%)")
    left.set_title("error against cost, by horizon")
    left.legend(fontsize=8)
    styles = {3: ":", 4: "--", 5: "-"}
    phase_s = np.linspace(0.0, DURATION, 200)
    right.plot(phase_s, np.cos(2.0 * np.pi * phase_s), color="black", lw=0.8,
               label="continuum")
    for r in columns:
        period = r.length / p_wave_speed(r.model)
        right.plot(r.time_s / period, r.amplitude_s, styles.get(r.n, "-"),
                   color=colours[r.model], label=f"{r.model}, horizon {r.n}h")
    right.axhline(0.0, color="grey", lw=0.5)
    right.set_xlabel("time / continuum period of the first mode")
    right.set_ylabel("first mode / its initial amplitude")
    right.set_title("periodic column: the first mode")
    right.legend(fontsize=8)
    return save_figure(fig, figures, "horizon_wave_speed")


def section(quick: bool, figures: Path) -> str:
    horizons = QUICK_HORIZONS if quick else HORIZONS
    columns = [measure(column(max(horizons)), model, n, p_wave_speed(model))
               for model in MODELS for n in horizons]
    bars = [measure(free_bar(), model, n, bar_speed(model), poisson_ratio(model))
            for model in MODELS for n in horizons]
    # the lps bar once more, every node given the weighted volume of the interior
    smallest = min(horizons)
    bar = free_bar()
    bar.arrays[WVOLUME] = np.full(len(bar), weighted_volume(smallest))
    interior_m = measure(bar, "lps", smallest, bar_speed("lps"), poisson_ratio("lps"))

    def errors(runs, model, reference):
        return [r.long_wave / reference(model) - 1.0 for r in runs if r.model == model]

    def ratio(runs, model, value):
        mine = [value(r) for r in runs if r.model == model]
        return mine[-1] / mine[0]

    listed = ", ".join(f"{n}" for n in horizons)
    largest = max(horizons)
    agreement = max(abs(r.long_wave / lattice_long_wave(r.model, r.n) - 1.0)
                    for r in columns)
    dispersion = [r.speed_j[0] / r.long_wave - 1.0 for r in columns]
    volume_share = [weighted_volume(n) / (np.pi * horizon(n) ** 4) for n in horizons]
    calibrated = [lattice_long_wave("pmb", n, micromodulus=18.0 * BULK / weighted_volume(n))
                  / p_wave_speed("pmb") - 1.0 for n in horizons]
    other_margin = {model: [lattice_long_wave(model, n, margin=OTHER_MARGIN)
                            / p_wave_speed(model) - 1.0 for n in horizons]
                    for model in MODELS}
    lps_over_pmb = [c.ms_per_step / p.ms_per_step
                    for c, p in zip(columns[len(horizons):], columns[:len(horizons)])]

    lines = [
        TITLE, "",
        f"`benchmarks/tradeoff_horizon.py`.  The speed of a long longitudinal wave in "
        f"BPMPeri's pmb and lps solids with horizons of {listed} lattice spacings, "
        f"against continuum elasticity, and the cost of a step.  Simple cubic lattice "
        f"(spacing h = {1e3 * SPACING:g} mm, node volume h^3), the LAMMPS PERI example's "
        f"material: density {DENSITY:g} kg/m^3, K = {BULK / 1e9:g} GPa; pmb with "
        f"c = 18 K / (pi delta^4) (Poisson ratio 1/4), lps with G = K (the `peri/lps` "
        f"example's; Poisson ratio 1/8).  Horizon delta = (n + {HORIZON_MARGIN:g}) h, "
        f"just above n spacings as the example's 0.0015001 m.",
        "",
        f"**How.**  The first two standing waves of a box periodic along x (wavelengths "
        f"L and L/2, strain {STRAIN:g}, nothing breaks) are started at rest, and each "
        f"one's frequency is read from the zero crossings of its projection: on a lattice "
        f"periodic along x each wavenumber is a separate normal mode, a pure cosine.  "
        f"Dispersion and velocity Verlet's phase error both grow as k^2, so "
        f"c0^2 = (4 c1^2 - c2^2) / 3 is the long-wave speed of the discrete model.  "
        f"Velocity Verlet (`ase_bpm.VelocityVerlet`) at {TIMESTEP_FRACTION:g} x "
        f"`calc.stable_timestep(atoms)` (estimated at rest); cost is wall time per step "
        f"on one thread, set-up excluded.  Formulas and sources: the module docstring.",
        "",
        f"**Periodic column**, the same for every horizon ({columns[0].nodes:,} nodes, "
        f"{2 * largest + 1} x {2 * largest + 1} spacings across, L = "
        f"{COLUMN_LENGTH * largest} spacings, periodic in all directions: uniaxial "
        f"strain, no free surface), against the P-wave speed sqrt((K + 4G/3) / rho) = "
        f"{p_wave_speed('pmb'):.0f} m/s (pmb), {p_wave_speed('lps'):.0f} m/s (lps).  The "
        f"last column is the long-wave error the lattice sums predict, without a run:",
        "",
        table(["model", "horizon (h)", "bonds per node", "stable dt (us)", "dt used (us)",
               "steps", "ms/step", "ms per us simulated", "speed at lambda = L (m/s)",
               "long-wave speed (m/s)", "error vs c_P", "lattice sums predict"],
              column_rows(columns)),
        "",
        f"**Free bar**, the same for every horizon ({bars[0].nodes:,} nodes, {BAR_WIDTH} x "
        f"{BAR_WIDTH} across, {BAR_LENGTH} spacings long and periodic along its length, "
        f"started with the sideways contraction of uniaxial stress), against the bar "
        f"speed sqrt(E / rho), E = 9KG / (3K + G): {bar_speed('pmb'):.0f} m/s (pmb), "
        f"{bar_speed('lps'):.0f} m/s (lps).  Every node is within a horizon of the "
        f"surface, so this is the surface effect at its strongest:",
        "",
        table(["model", "horizon (h)", "bonds per node", "dt used (us)", "ms/step",
               "long-wave speed (m/s)", "error vs c_bar", "the column's error vs c_P"],
              bar_rows(bars, columns)),
        "",
        figure(columns, bars, figures),
        "",
        "**What it shows.**",
        "",
        f"* The measured long-wave speeds are the discrete models' own: they agree with "
        f"the lattice sums to {agreement:.1e}.  The error against elasticity is the "
        f"quadrature of the horizon integrals, not dispersion or the timestep (at "
        f"lambda = L the first mode runs {percent(min(dispersion))} to "
        f"{percent(max(dispersion))} off the long-wave limit).",
        f"* pmb is off by {listing(errors(columns, 'pmb', p_wave_speed))} (horizons "
        f"{listed}) and does not converge with the horizon.  Its stiffness is c times a "
        f"lattice sum that c = 18 K / (pi delta^4) takes at its continuum value, and the "
        f"sum falls short: LAMMPS' partial volumes count the nodes just inside the "
        f"horizon at 1/2 to 1 and those just outside at nothing, so the weighted volume "
        f"m = sum s r0 V is {', '.join(f'{v:.3f}' for v in volume_share)} of "
        f"pi delta^4.",
        f"* lps is off by {listing(errors(columns, 'lps', p_wave_speed))}: it divides by "
        f"the lattice's own m, so its bulk part is exact on the lattice and only its "
        f"shear part carries the lattice's anisotropy.  A pmb micromodulus from the same "
        f"sum, c = 18 K / m, would do as well: the lattice sums give "
        f"{listing(calibrated)} (lps with G = 3K/5 is that model exactly).",
        f"* Cost: a step's time grows with the bonds per node, a little faster (from "
        f"{smallest} to {largest} spacings "
        f"{ratio(columns, 'pmb', lambda r: r.bonds_per_node):.1f} times the bonds take "
        f"{ratio(columns, 'pmb', lambda r: r.ms_per_step):.1f} (pmb) and "
        f"{ratio(columns, 'lps', lambda r: r.ms_per_step):.1f} (lps) times the time); "
        f"lps costs {spread(lps_over_pmb)} times pmb.  The stable timestep grows with "
        f"the horizon ({ratio(columns, 'pmb', lambda r: r.stable_dt):.2f} times), so per "
        f"simulated microsecond the larger horizon costs "
        f"{ratio(columns, 'pmb', lambda r: r.ms_per_step / r.dt):.1f} (pmb) and "
        f"{ratio(columns, 'lps', lambda r: r.ms_per_step / r.dt):.1f} (lps) times as much.",
        f"* The surface effect: in a bar {BAR_WIDTH} nodes across, pmb is softer than in "
        f"the bulk (nodes near the surface lack bonds) and lps stiffer: a node near the "
        f"surface has a smaller m, so its remaining bonds, mostly along the surface, "
        f"count more.  Given the interior's m at every node, the lps bar "
        f"(horizon {smallest}) is {percent(interior_m.long_wave / bar_speed('lps') - 1.0)} "
        f"off c_bar instead of "
        f"{percent(bars[len(horizons)].long_wave / bar_speed('lps') - 1.0)}.  Both "
        f"effects grow with the horizon at a fixed width.",
        f"* Horizon convention: with delta = (n + {OTHER_MARGIN:g}) h instead (the same "
        f"bonds, the outermost weighted a little more, c smaller) the lattice sums give "
        f"pmb {listing(other_margin['pmb'])} and lps {listing(other_margin['lps'])}.",
    ]
    return "\n".join(lines)
