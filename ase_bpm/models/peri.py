"""BPMPeri: peridynamics as breakable bonds (LAMMPS ``bond_style bpm/peri``
with ``pair_style bpm/peri``; the physics of the legacy ``peri/*`` styles)."""

from __future__ import annotations

from typing import Mapping

import numpy as np
from ase import Atoms

from ..core.bonds import BondTable
from .bonded import BondSet, BondState, ContactList, pair_keys, write_bond_counts
from .base import (BPMCalculator, Evaluation, digest, particle_types,
                         require_finite, same_array, scatter_pairs, virial)
from ..laws import peri as law
from ..core.neighbours import minimum_image, periodic_half_widths
from ..core.params import check_coeffs, check_type, json_coeffs, type_pair

#: coefficients of each model, in LAMMPS ``bond_coeff`` order
MODELS = {
    "pmb": ("c", "horizon", "s00", "alpha"),
    "lps": ("K", "G", "horizon", "s00", "alpha"),
    "ves": ("K", "G", "lambda", "tau", "horizon", "s00", "alpha"),
    "eps": ("K", "G", "yield_stress", "horizon", "s00", "alpha"),
}
POSITIVE = ("c", "K", "horizon", "tau", "yield_stress")
NON_NEGATIVE = ("G", "s00", "alpha", "lambda")
COLUMNS = ("c", "K", "G", "lambda", "tau", "yield_stress", "horizon", "s00", "alpha")
STATE_BASED = ("lps", "ves", "eps")

def simple_cubic_spacing(positions, bond_lengths) -> float:
    """The spacing of a simple cubic lattice with equal spacing: the shortest
    bond, checked against the positions (ValueError if they are no such
    lattice)."""
    if len(bond_lengths) == 0:
        raise ValueError("lattice_spacing cannot be inferred without bonds: pass it")
    spacing = float(np.min(bond_lengths))
    grid = (positions - positions[0]) / spacing
    if np.abs(grid - np.round(grid)).max() > 1e-6:
        raise ValueError(
            "the reference positions are not a simple cubic lattice with equal spacing "
            f"(nearest-neighbour distance {spacing:.6g}): the partial-volume correction "
            "needs one; pass lattice_spacing= for other arrangements")
    return spacing


class _Columns(dict):
    """Per-bond coefficient columns, looked up (and cached on the bond set) when
    first used."""

    def __init__(self, bonds: BondSet, column):
        super().__init__()
        self._bonds, self._column = bonds, column

    def __missing__(self, name):
        value = self._bonds.per_bond("peri:" + name, lambda: self._column(name))
        self[name] = value
        return value


# per-node state on the atoms
WVOLUME, VINTER, SMIN, LAMBDA = "peri_wvolume", "peri_vinter", "peri_smin", "peri_lambda"
SPACING = "peri_lattice_spacing"  # info


class BPMPeri(BPMCalculator):
    """Peridynamic solids as bonds: LAMMPS ``bond_style bpm/peri`` +
    ``pair_style bpm/peri``, with the force laws of the legacy ``peri/pmb``,
    ``peri/lps``, ``peri/ves`` and ``peri/eps`` styles.

    Nodes carry their volume in ``atoms.arrays["vfrac"]``; masses are true
    masses (density times volume) and forces true forces, so accelerations
    equal those of LAMMPS' PERI styles.  Bonds (integer arrays on the atoms, :mod:`ase_bpm.bonds`,
    usually from ``create_bonds(atoms, horizon)``) take their reference length
    at their first evaluation.  Units are the caller's (SI in the examples).

    Parameters
    ----------
    bond_coeffs:
        ``{bond_type: model}``, each model a tuple in LAMMPS ``bond_coeff``
        order: ``("pmb", c, horizon, s00, alpha)``,
        ``("lps", K, G, horizon, s00, alpha)``,
        ``("ves", K, G, lambda, tau, horizon, s00, alpha)`` or
        ``("eps", K, G, yield_stress, horizon, s00, alpha)``.  ``c`` is the
        micromodulus (energy/length^6, ``18 K / (pi horizon^4)`` for bulk
        modulus K), K and G the bulk and shear moduli (pressure), lambda the
        viscous fraction (0 to 1), tau the relaxation time, s00 and alpha the
        breaking parameters: a bond breaks when its stretch exceeds
        ``s00 - alpha * s_min`` (Parks et al. 2008), ``s_min`` the most
        compressive stretch of either node's bonds on the previous step.
    pair_coeffs:
        ``{(type_i, type_j): (k, horizon)}``, ``pair_style bpm/peri``: nodes
        that are not bonded repel when closer than ``d``,
        ``15 k V_i V_j (d - r) / horizon``; ``d = 1.35`` lattice spacings, or
        ``min(0.9 r0, 1.35 spacings)`` for the two nodes of a broken bond.
        Every pair of particle types present needs an entry (no mixing).
    lattice_spacing:
        Spacing of the simple cubic lattice (length), used by the
        partial-volume correction and the contact distance.  Default: the
        nearest-neighbour distance of the reference configuration, which must
        then be a simple cubic lattice with equal spacing.
    timestep:
        The MD timestep (time), needed by ves and by moving fixes.  When the
        atoms move ballistically between evaluations (velocity Verlet), a
        mismatch with the integrator's step raises.
    fixes:
        External force pieces, e.g. :class:`ase_bpm.fixes.SphericalIndenter`.
    skin:
        Verlet skin of the contact neighbour list (default 0.3 lattice
        spacings).

    Results: ``energy`` (elastic energy; for pmb and lps the potential of the
    forces, for ves and eps the recoverable part), ``forces``, ``stress``
    (periodic cells).  Per-atom outputs in ``atoms.arrays``: ``damage``
    (``1 - sum_intact V_j / sum_initial V_j``), ``nbonds`` and, for the
    state-based models, ``dilatation``.  Broken bonds are logged in
    ``atoms.info["broken_bonds"]`` as by :class:`~ase_bpm.BPMSpring`.

    As in the legacy styles, a bond that breaks still acts in the step it
    breaks, and pmb/lps energy and forces use ``V_i V_j`` (equal to the legacy
    styles' ``V_j`` convention for uniform volumes, and momentum-conserving
    otherwise).  The ves and eps forces use each end's own dilatation and
    history, as the legacy styles do; eps returns to the yield surface
    radially (``bond_style bpm/peri``), the legacy style differently, so the
    two agree below yield.
    """

    name = "bpm_peri"
    default_parameters = dict(bond_coeffs={}, pair_coeffs={}, lattice_spacing=None,
                              timestep=None, skin=None, break_bonds=True, store_local=True)
    watched_arrays = ("type", "vfrac")

    def __init__(self, bond_coeffs: Mapping[int, tuple] = None,
                 pair_coeffs: Mapping[tuple, tuple] = None,
                 lattice_spacing: float | None = None, timestep: float | None = None,
                 skin: float | None = None, break_bonds: bool = True,
                 store_local: bool = True, fixes=(), **kwargs):
        super().__init__(fixes=fixes, bond_coeffs=dict(bond_coeffs or {}),
                         pair_coeffs=dict(pair_coeffs or {}), lattice_spacing=lattice_spacing,
                         timestep=timestep, skin=skin, break_bonds=break_bonds,
                         store_local=store_local, **kwargs)

    def set(self, **kwargs):
        changed = super().set(**kwargs)
        self._setup()
        return changed

    def todict(self, skip_default=True) -> dict:
        params = dict(super().todict(skip_default=skip_default))
        for name in ("bond_coeffs", "pair_coeffs"):
            if name in params:
                params[name] = json_coeffs(params[name])
        return params

    # -- coefficients ------------------------------------------------------------
    def _setup(self) -> None:
        p = self.parameters
        models, table = {}, {}
        for t, coeffs in p["bond_coeffs"].items():
            t = check_type("bond_coeffs", t)
            coeffs = tuple(coeffs)
            if not coeffs or coeffs[0] not in MODELS:
                model = coeffs[0] if coeffs else None
                raise ValueError(f"bond_coeffs for bond type {t}: unknown model {model!r} "
                                 f"(one of {', '.join(MODELS)})")
            names = MODELS[coeffs[0]]
            values = check_coeffs(f"bond_coeffs for bond type {t}, model", coeffs[0],
                                  coeffs[1:], names, POSITIVE, NON_NEGATIVE)
            values = dict(zip(names, values))
            if coeffs[0] == "ves" and not values["lambda"] <= 1.0:
                raise ValueError(f"bond_coeffs for bond type {t}, model ves: lambda = "
                                 f"{values['lambda']} must lie between 0 and 1")
            models[t], table[t] = coeffs[0], values
        pairs = {}
        for key, values in p["pair_coeffs"].items():
            ti, tj = type_pair("pair_coeffs", key)
            pairs[ti, tj] = check_coeffs("pair_coeffs for types", (ti, tj), values,
                                         ("k", "horizon"), ("k", "horizon"))
        if p["timestep"] is not None and not float(p["timestep"]) > 0:
            raise ValueError(f"timestep must be positive, got {p['timestep']!r}")
        if p["lattice_spacing"] is not None and not float(p["lattice_spacing"]) > 0:
            raise ValueError(f"lattice_spacing must be positive, got {p['lattice_spacing']!r}")
        self._models, self._pairs = models, pairs
        self.needs_timestep = "ves" in models.values()
        size = max(models, default=0) + 1
        self._coeffs = np.full((len(COLUMNS), size), np.nan)
        self._model_of = np.full(size, "", dtype=object)
        self._model_code = np.zeros(size, dtype=np.int64)
        for t, values in table.items():
            for c, column in enumerate(COLUMNS):
                self._coeffs[c, t] = values.get(column, 0.0)
            self._model_of[t] = models[t]
            self._model_code[t] = list(MODELS).index(models[t])
        self._param_digest = digest(type(self).__name__, sorted(models.items()),
                                    sorted((t, sorted(v.items())) for t, v in table.items()),
                                    sorted(pairs.items()), p["lattice_spacing"],
                                    p["timestep"], p["break_bonds"])
        self._forget()

    def _forget(self) -> None:
        states = {"r0": ()}
        if "ves" in self._models.values():
            states["ves"] = (4,)
        if "eps" in self._models.values():
            states["eps"] = (2,)
        self._bond_state = BondState(self._check_bond_types, states)
        self._contact_list = None
        self._types_digest = None
        self._pair_cache = None

    def _check_bond_types(self, table: BondTable) -> None:
        live = table.type_b > 0
        known = np.zeros(live.shape, dtype=bool)
        inside = table.type_b < len(self._model_of)
        known[inside] = self._model_of[table.type_b[inside]] != ""
        unknown = live & ~known
        if unknown.any():
            b = int(np.argmax(unknown))
            raise ValueError(f"unknown bond type {table.type_b[b]} (bond {table.owner_b[b]}-"
                             f"{table.partner_b[b]}): bond_coeffs has no entry for it")

    def _column(self, name: str, type_b: np.ndarray) -> np.ndarray:
        return self._coeffs[COLUMNS.index(name), type_b]

    def _per_bond(self, bonds: BondSet) -> dict:
        """Coefficients and model selections of the intact bonds (cached, and
        carried over when bonds break)."""
        t_b = bonds.type_b
        data = _Columns(bonds, lambda name: self._column(name, t_b))
        code_b = bonds.per_bond("peri:model", lambda: self._model_code[t_b])
        present = np.flatnonzero(np.bincount(code_b, minlength=len(MODELS)))
        names = [list(MODELS)[c] for c in present]
        # one model: no selection (None), else the bonds of each model
        data["models"] = {m: None if len(names) == 1 else
                          np.flatnonzero(code_b == list(MODELS).index(m)) for m in names}
        state_codes = [list(MODELS).index(m) for m in STATE_BASED]
        data["state_based"] = np.isin(code_b, state_codes)
        data["any_state_based"] = any(m in STATE_BASED for m in names)
        return data

    # -- lattice -------------------------------------------------------------------
    def lattice_spacing(self, atoms: Atoms, bonds: BondSet, r_b) -> float:
        """The given spacing, the one recorded on the atoms, or the nearest-
        neighbour distance of a simple cubic reference configuration."""
        if self.parameters["lattice_spacing"] is not None:
            return float(self.parameters["lattice_spacing"])
        if SPACING in atoms.info:
            return float(atoms.info[SPACING])
        return simple_cubic_spacing(atoms.positions, r_b)

    # -- evaluation ------------------------------------------------------------------
    def _state_replaced(self, atoms: Atoms) -> bool:
        return not self._bond_state.is_current(atoms)

    def _signature(self, atoms: Atoms, evaluation) -> str:
        bonds = (self._bond_state.current if evaluation is not None
                 else self._bond_state.bonds(atoms))
        types = particle_types(atoms)
        if self._types_digest is None or not same_array(self._types_digest[0], types):
            self._types_digest = (types.copy(), digest(types))
        return digest(self._param_digest, bonds.fingerprint, self._types_digest[1],
                      atoms.arrays.get("vfrac"), self._fixes_digest())

    def _volumes(self, atoms: Atoms) -> np.ndarray:
        vol = atoms.arrays.get("vfrac")
        if vol is None:
            raise ValueError('BPMPeri needs the nodal volume of every node in '
                             'atoms.arrays["vfrac"]')
        vol = np.asarray(vol, dtype=float)
        if vol.shape != (len(atoms),):
            raise ValueError(f'atoms.arrays["vfrac"] must hold one volume per node, '
                             f"got shape {vol.shape}")
        require_finite('atoms.arrays["vfrac"]', vol)
        if len(vol) and not vol.min() > 0:
            n = int(np.argmin(vol))
            raise ValueError(f'atoms.arrays["vfrac"] of node {n} is {vol[n]}: volumes must '
                             "be positive")
        return vol

    def _evaluate(self, atoms: Atoms) -> Evaluation:
        n = len(atoms)
        x_nc, cell, pbc = atoms.positions, atoms.cell, atoms.pbc
        vol_n = self._volumes(atoms)
        types_n = particle_types(atoms)
        bonds = self._bond_state.bonds(atoms)
        advance = self.advancing

        f_nc = np.zeros((n, 3))
        energy, released = 0.0, 0.0
        pair_forces = []  # (r_xc, f_xc) of bonds and contacts, for the virial
        extra = dict(bonds=bonds)
        i_b, j_b, t_b = bonds.i_b, bonds.j_b, bonds.type_b

        r_bc = bonds.vectors(x_nc)
        if pbc.any():
            r_bc = minimum_image(r_bc, cell, pbc)
        r_b = np.sqrt(np.einsum("bc,bc->b", r_bc, r_bc))
        r0_b = bonds.of_bonds("r0")
        fresh_b = np.isnan(r0_b)
        if fresh_b.any():
            r0_b = np.where(fresh_b, r_b, r0_b)
        spacing = self.lattice_spacing(atoms, bonds, r0_b)
        coeff = self._per_bond(bonds)
        horizon_b = coeff["horizon"]
        if len(t_b) and horizon_b.min() < spacing:
            b = int(np.argmin(horizon_b))
            raise ValueError(f"bond type {t_b[b]}: horizon {horizon_b[b]} is smaller than the "
                             f"lattice spacing {spacing}")
        if pbc.any() and len(r0_b):
            reach = r0_b.max() * (1.0 + coeff["s00"].max())
            if reach >= periodic_half_widths(cell, pbc):
                raise ValueError("periodic cell too small for the horizon: a bond may reach "
                                 "half the cell width before it breaks")
        scale_b, vv_b = self._volume_factors(bonds, r0_b, horizon_b, spacing, vol_n,
                                             cacheable=not fresh_b.any())
        dr_b = law.extension(r_b, r0_b)
        stretch_b = dr_b / r0_b

        # node state taken in the reference configuration
        m_n = self._node_state(atoms, WVOLUME, lambda: law.weighted_volume(
            i_b, j_b, r0_b, scale_b, vol_n))
        vinter_n = self._node_state(atoms, VINTER, lambda: law.node_sum(
            i_b, j_b, vol_n[j_b], vol_n[i_b], n))

        # breaking: Parks' criterion with the previous step's smallest stretch
        broken_b = np.zeros(len(bonds), dtype=bool)
        smin_n = atoms.arrays.get(SMIN)
        if advance and self.parameters["break_bonds"] and smin_n is not None \
                and len(smin_n) == n:
            smin_b = np.fmax(np.take(smin_n, i_b), np.take(smin_n, j_b))
            critical_b = coeff["s00"] - coeff["alpha"] * smin_b
            broken_b = stretch_b > critical_b  # NaN (no history yet): no break
        theta_n = None
        if coeff["any_state_based"]:
            sb = coeff["state_based"]
            theta_n = law.dilatation(i_b[sb], j_b[sb], dr_b[sb], scale_b[sb], vol_n, m_n)

        fi_b, fj_b = np.zeros(len(bonds)), np.zeros(len(bonds))
        history = {}
        lambda_n = None
        for model, sel in coeff["models"].items():
            res = self._bond_law(model, sel, bonds, dr_b, r0_b, scale_b, vv_b, theta_n, m_n,
                                 vol_n, advance, atoms)
            if sel is None:
                fi_b, fj_b = res.fi_b, res.fj_b
                sel = slice(None)
            else:
                fi_b[sel], fj_b[sel] = res.fi_b, res.fj_b
            energy += res.energy
            if res.history is not None:
                history[model] = (sel, res.history)
            if res.node is not None:
                lambda_n = res.node
        if broken_b.any():
            # legacy timing: a breaking bond still acts now; its energy goes
            energy_kept = self._energy_without(broken_b, bonds, dr_b, r0_b, scale_b, vv_b,
                                               m_n, vol_n, history, atoms)
            released, energy = energy - energy_kept, energy_kept
        rinv_b = np.divide(1.0, r_b, out=np.zeros_like(r_b), where=r_b > 0)
        fi_bc = r_bc * (fi_b * rinv_b)[:, None]
        if np.array_equal(fi_b, fj_b):
            f_nc += bonds.forces(fi_bc)
            f_mean_bc = fi_bc
        else:
            fj_bc = -r_bc * (fj_b * rinv_b)[:, None]
            f_nc += bonds.forces(fi_bc, fj_bc)
            f_mean_bc = 0.5 * (fi_bc - fj_bc)
        pair_forces.append((r_bc, f_mean_bc))

        if self._pairs:
            pair_table = self._pair_table(types_n)
            f_c, e_c, r_pc, f_pc = self._contacts(atoms, bonds, types_n, vol_n, spacing,
                                                  pair_table)
            f_nc += f_c
            energy += e_c
            pair_forces.append((r_pc, f_pc))

        extra.update(fresh_b=fresh_b, r0_b=r0_b, broken_b=broken_b, r_bc=r_bc,
                     history=history, lambda_n=lambda_n, theta_n=theta_n, m_n=m_n,
                     vinter_n=vinter_n, spacing=spacing,
                     smin_n=bonds.node_min(stretch_b) if advance or smin_n is None else None)
        return Evaluation(forces=f_nc, energy=energy, released_energy=released, extra=extra,
                          virial=lambda: sum(virial(r, f) for r, f in pair_forces))

    @staticmethod
    def _volume_factors(bonds: BondSet, r0_b, horizon_b, spacing, vol_n, cacheable):
        """Partial-volume factors and ``V_i V_j`` of the bonds (cached while the
        reference lengths, spacing and volumes stay)."""
        key = bonds.cache.get("keep:volumes")
        if cacheable and key is not None and key[0] == spacing and same_array(key[1], vol_n):
            return bonds.cache["bond:peri:scale"], bonds.cache["bond:peri:vv"]
        scale_b = law.partial_volume(r0_b, horizon_b, spacing)
        vv_b = np.take(vol_n, bonds.i_b) * np.take(vol_n, bonds.j_b)
        if cacheable:
            bonds.cache["keep:volumes"] = (spacing, vol_n.copy())
            bonds.cache["bond:peri:scale"], bonds.cache["bond:peri:vv"] = scale_b, vv_b
        return scale_b, vv_b

    def _bond_law(self, model, sel, bonds, dr_b, r0_b, scale_b, vv_b, theta_n, m_n, vol_n,
                  advance, atoms) -> law.BondLaw:
        if sel is None:
            sel = slice(None)
        i_b, j_b = bonds.i_b[sel], bonds.j_b[sel]
        coeff = self._per_bond(bonds)
        col = lambda name: coeff[name][sel]  # noqa: E731
        args = (dr_b[sel], r0_b[sel])
        if model == "pmb":
            return law.pmb(*args, col("c"), scale_b[sel], vv_b[sel])
        if model == "lps":
            return law.lps(i_b, j_b, *args, col("K"), col("G"), scale_b[sel], vv_b[sel],
                           theta_n, m_n, vol_n)
        history_b = np.nan_to_num(bonds.of_bonds(model)[sel])  # unset history: zero
        if model == "ves":
            return law.ves(i_b, j_b, *args, col("K"), col("G"), col("lambda"), col("tau"),
                           scale_b[sel], vv_b[sel], theta_n, m_n, vol_n, history_b,
                           self._timestep(advance), advance)
        lambda_n = np.nan_to_num(atoms.arrays.get(LAMBDA, np.zeros(len(vol_n))))
        if len(lambda_n) != len(vol_n):
            lambda_n = np.zeros(len(vol_n))
        return law.eps(i_b, j_b, *args, col("K"), col("G"),
                       law.pointwise_yield(col("yield_stress"), col("horizon")),
                       scale_b[sel], vv_b[sel], theta_n, m_n, vol_n, history_b, lambda_n,
                       advance)

    def _energy_without(self, broken_b, bonds, dr_b, r0_b, scale_b, vv_b, m_n, vol_n,
                        history, atoms) -> float:
        """Elastic energy once the ``broken_b`` bonds are gone: pmb bonds take
        their own energy with them; state-based energy is recomputed with the
        dilatation of the remaining bonds."""
        i_b, j_b, t_b = bonds.i_b, bonds.j_b, bonds.type_b
        models = self._model_of[t_b]
        energy = 0.0
        pmb = models == "pmb"
        if pmb.any():
            keep = pmb & ~broken_b
            energy += law.pmb(dr_b[keep], r0_b[keep], self._column("c", t_b[keep]),
                              scale_b[keep], vv_b[keep]).energy
        state = ~pmb & ~broken_b
        if state.any():
            theta_n = law.dilatation(i_b[state], j_b[state], dr_b[state], scale_b[state],
                                     vol_n, m_n)
            energy += law.lps(i_b[state], j_b[state], dr_b[state], r0_b[state],
                              self._column("K", t_b[state]), self._column("G", t_b[state]),
                              scale_b[state], vv_b[state], theta_n, m_n, vol_n).energy
        return energy

    def _node_state(self, atoms: Atoms, name: str, compute) -> np.ndarray:
        """Per-node reference state: stored, or computed where missing."""
        stored = atoms.arrays.get(name)
        if stored is not None and len(stored) == len(atoms) and not np.isnan(stored).any():
            return stored
        fresh = compute()
        if stored is None or len(stored) != len(atoms):
            return fresh
        return np.where(np.isnan(stored), fresh, stored)

    def _contacts(self, atoms, bonds: BondSet, types_n, vol_n, spacing, pair_table):
        """``pair_style bpm/peri`` between nodes not bonded now."""
        n = len(atoms)
        if self._contact_list is None:
            skin = 0.3 * spacing if self.parameters["skin"] is None else self.parameters["skin"]
            self._contact_list = ContactList(1.35 * spacing, float(skin))
        i_p, j_p, r_pc = self._contact_list.pairs(atoms, bonds)
        r_p = np.sqrt(np.einsum("pc,pc->p", r_pc, r_pc))
        d_p = np.full(len(i_p), 1.35 * spacing)
        table = bonds.table
        gone = table.type_b == 0
        if gone.any():  # broken bonds: contact from min(0.9 r0, 1.35 spacings)
            broken_keys = pair_keys(table.owner_b[gone], table.partner_b[gone], n)
            order = np.argsort(broken_keys)
            keys_p = pair_keys(i_p, j_p, n)
            pos = np.minimum(np.searchsorted(broken_keys[order], keys_p), len(order) - 1)
            hit = broken_keys[order][pos] == keys_p
            r0_gone = bonds.state["r0"][gone][order][pos]
            d_p = np.where(hit & ~np.isnan(r0_gone), np.minimum(0.9 * r0_gone, d_p), d_p)
        touch = r_p < d_p
        f_nc = np.zeros((n, 3))
        if not touch.any():
            return f_nc, 0.0, np.zeros((0, 3)), np.zeros((0, 3))
        i_p, j_p, r_pc, r_p, d_p = i_p[touch], j_p[touch], r_pc[touch], r_p[touch], d_p[touch]
        k_p, horizon_p = pair_table[:, types_n[i_p], types_n[j_p]]
        f_p, energy = law.contact(r_p, k_p, d_p, horizon_p, vol_n[i_p] * vol_n[j_p])
        rinv_p = np.divide(1.0, r_p, out=np.zeros_like(r_p), where=r_p > 0)
        f_pc = r_pc * (f_p * rinv_p)[:, None]
        return scatter_pairs(i_p, j_p, f_pc, n), energy, r_pc, f_pc

    def _pair_table(self, types_n) -> np.ndarray:
        """``[k, horizon][ti, tj]`` for the particle types present."""
        last = self._pair_cache
        if last is not None and same_array(last[0], types_n):
            return last[1]
        present = [int(t) for t in np.unique(types_n)]
        size = max(present) + 1
        table = np.full((2, size, size), np.nan)
        for a in present:
            for b in present:
                key = (min(a, b), max(a, b))
                if key not in self._pairs:
                    raise ValueError(f"unknown particle type pair {key}: pair_coeffs needs an "
                                     "entry for every pair of types present (no mixing)")
                table[:, a, b] = self._pairs[key]
        self._pair_cache = (types_n.copy(), table)
        return table

    # -- commit --------------------------------------------------------------------------
    def _commit(self, atoms: Atoms, ev: Evaluation, step: int) -> None:
        state = self._bond_state
        bonds: BondSet = ev.extra["bonds"]
        x = ev.extra
        if self.parameters["lattice_spacing"] is None:
            atoms.info[SPACING] = x["spacing"]
        if self.parameters["store_local"] and (
                "bpm_x_ref" not in atoms.arrays or len(atoms.arrays["bpm_x_ref"]) != len(atoms)):
            atoms.arrays["bpm_x_ref"] = atoms.positions.copy()
        if x["fresh_b"].any():
            bonds.set_bonds("r0", x["r0_b"], x["fresh_b"])
        for model, (sel, values) in x["history"].items():
            full = np.nan_to_num(bonds.of_bonds(model))
            full[slice(None) if sel is None else sel] = values
            bonds.set_bonds(model, full)
        atoms.arrays[WVOLUME] = x["m_n"]
        atoms.arrays[VINTER] = x["vinter_n"]
        if x["smin_n"] is not None:
            atoms.arrays[SMIN] = x["smin_n"]
        if x["lambda_n"] is not None:
            atoms.arrays[LAMBDA] = x["lambda_n"]
        if x["theta_n"] is not None:
            atoms.arrays["dilatation"] = x["theta_n"]
        broken_b = x["broken_b"]
        counts_stale = (state.reread or broken_b.any() or "damage" not in atoms.arrays
                        or len(atoms.arrays["damage"]) != len(atoms))
        if broken_b.any():
            bonds = state.break_bonds(atoms, bonds, broken_b, step, x["r_bc"],
                                      self.parameters["store_local"])
        state.write(atoms, bonds)
        if counts_stale:
            write_bond_counts(atoms, bonds)
            vol_n = atoms.arrays["vfrac"]
            intact_n = law.node_sum(bonds.i_b, bonds.j_b, vol_n[bonds.j_b], vol_n[bonds.i_b],
                                    len(atoms))
            atoms.arrays["damage"] = np.divide(x["vinter_n"] - intact_n, x["vinter_n"],
                                               out=np.zeros(len(atoms)),
                                               where=x["vinter_n"] > 0)

    # -- LAMMPS export: the legacy PERI styles of the reference build ------------------
    #: legacy ``pair_coeff`` order of each model (after the two types)
    LEGACY_PAIR_COEFFS = {
        "pmb": ("c", "horizon", "s00", "alpha"),
        "lps": ("K", "G", "horizon", "s00", "alpha"),
        "ves": ("K", "G", "horizon", "s00", "alpha", "lambda", "tau"),
        "eps": ("K", "G", "horizon", "s00", "alpha", "yield_stress"),
    }

    def lammps_scene(self, atoms: Atoms, data_file: str, *, units: str | None = None,
                     timestep: float | None = None, thermo: int = 100,
                     spacing: float | None = None):
        """The scene in LAMMPS (:class:`ase_bpm.core.lammps_text.LammpsScene`):
        the legacy ``peri/<model>`` pair style on ``atom_style peri``, the
        peridynamics of the reference build.  Legacy PERI bonds every pair of
        nodes within the horizon by itself and takes the reference at its
        first run: export an unbroken scene.  ``units`` default ``"si"``,
        ``timestep`` the calculator's, ``spacing`` the lattice spacing (default:
        the calculator's, the one recorded on the atoms, or that of the simple
        cubic positions).  The thermo output reports the mean damage.  LAMMPS'
        ``f`` holds force densities here, so fixes need one node volume.
        """
        from ..core.bonds import get_bonds
        from ..core.lammps_text import (LammpsScene, exact, integrator, neighbour_lists,
                                        peri_data, preamble)

        p = self.parameters
        head = preamble(atoms, units or "si", "peri")
        name, coeffs = self._legacy_pair_coeffs(atoms)
        if spacing is None:
            i_b, j_b, _ = get_bonds(atoms)
            r_bc = minimum_image(atoms.positions[j_b] - atoms.positions[i_b], atoms.cell,
                                 atoms.pbc)
            spacing = self.lattice_spacing(atoms, None, np.linalg.norm(r_bc, axis=1))
        vol_n = atoms.arrays["vfrac"]
        if self.fixes and np.any(vol_n != vol_n[0]):
            raise ValueError("legacy PERI fixes act on force densities: exporting them "
                             "needs one node volume")
        cmds = [*head, "atom_modify map array", f"lattice sc {exact(spacing)}",
                f"read_data {data_file}", f"pair_style peri/{name}",
                "pair_coeff * * " + " ".join(exact(c) for c in coeffs),
                *neighbour_lists(p["skin"] or 0.3 * spacing),
                *integrator("nve", p["timestep"] if timestep is None else timestep)]
        return LammpsScene(peri_data(atoms), tuple(cmds),
                           force_per_lammps_force=float(vol_n[0]),
                           thermo=("compute damage all damage/atom",
                                   "compute mean_damage all reduce ave c_damage",
                                   "thermo_style custom step ke pe c_mean_damage"))

    def _legacy_pair_coeffs(self, atoms: Atoms):
        """The scene's single model and its coefficients in legacy ``pair_coeff``
        order, checked to be expressible in legacy PERI."""
        from ..core.bonds import bond_table
        from ..core.neighbours import neighbour_pairs

        models = self.parameters["bond_coeffs"]
        if len(models) != 1:
            raise ValueError("legacy PERI has one model per scene: the calculator has bond "
                             f"types {sorted(models)}")
        (btype, coeffs), = models.items()
        name = coeffs[0]
        values = dict(zip(("model",) + MODELS[name], coeffs))
        types_n = particle_types(atoms)
        if np.any(types_n != types_n[0]):
            raise ValueError("legacy PERI export supports one particle type")
        table = bond_table(atoms)
        if np.any(table.type_b != btype):
            raise ValueError("legacy PERI bonds every pair within the horizon and breaks them "
                             "itself: the scene has broken bonds or bonds of other types")
        i_p, j_p, _ = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc, values["horizon"])
        want = {(min(a, b), max(a, b)) for a, b in zip(i_p, j_p)}
        have = {(min(a, b), max(a, b)) for a, b in zip(table.owner_b, table.partner_b)}
        if want != have:
            raise ValueError(f"legacy PERI bonds every pair within the horizon: the scene lacks "
                             f"{len(want - have)} of them and has {len(have - want)} beyond it")
        pairs = self.parameters["pair_coeffs"]
        if pairs:
            (_, (k, horizon)), = pairs.items()
            legacy_k = values["c"] if name == "pmb" else \
                18.0 * values["K"] / (np.pi * values["horizon"] ** 4)
            if not (np.isclose(k, legacy_k, rtol=1e-12) and horizon == values["horizon"]):
                raise ValueError(f"legacy PERI ties the contact stiffness to the bond law: "
                                 f"pair_coeffs must be (k={legacy_k!r}, horizon="
                                 f"{values['horizon']!r})")
        return name, [values[key] for key in self.LEGACY_PAIR_COEFFS[name]]
