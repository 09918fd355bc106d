"""BPMSpring: LAMMPS ``bond_style bpm/spring`` with ``pair_style bpm/spring``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Optional

import numpy as np
from ase import Atoms

from .bonds import BondTable, bond_table, format_atom_bonds, widen_bond_state
from .calculator import (BPMCalculator, Evaluation, digest, particle_types,
                         scatter_pairs, velocities, virial)
from .kernels.spring import bond_strain, spring_bonds, spring_pairs
from .neighbours import VerletList, minimum_image, periodic_half_widths

R0 = "bond_r0"  # per-bond reference length, NaN until the first evaluation
X_REF = "bpm_x_ref"  # per-atom reference position (for the broken-bond log)
BROKEN_LOG = "broken_bonds"  # info: one row per broken bond, see BPMSpring
BROKEN_LOG_COLUMNS = ("i", "j", "step", "x", "y", "z", "x_ref", "y_ref", "z_ref")


def _same(a, b) -> bool:
    """Both absent, or equal arrays (NaN equal to NaN)."""
    if a is None or b is None:
        return a is None and b is None
    if a.shape != b.shape or a.dtype.kind != b.dtype.kind:
        return False
    return bool(np.array_equal(a, b, equal_nan=a.dtype.kind == "f"))


def _copy(a):
    return None if a is None else a.copy()


def _check_coeffs(kind: str, key, values, names, positive, non_negative):
    """Validate one coefficient tuple; return it as floats."""
    if len(values) != len(names):
        raise ValueError(f"{kind} {key}: expected {len(names)} coefficients "
                         f"({', '.join(names)}), got {len(values)}")
    values = tuple(float(v) for v in values)
    for name, value in zip(names, values):
        if not np.isfinite(value):
            raise ValueError(f"{kind} {key}: {name} = {value} is not finite")
        if name in positive and not value > 0:
            raise ValueError(f"{kind} {key}: {name} = {value} must be positive")
        if name in non_negative and not value >= 0:
            raise ValueError(f"{kind} {key}: {name} = {value} must be non-negative")
    return values


def _check_type(kind, t):
    if int(t) != t or t < 1:
        raise ValueError(f"{kind}: type {t!r} must be an integer >= 1")
    return int(t)


@dataclass
class _Bonds:
    """A bond table with its coefficients and reference lengths (cached)."""

    table: BondTable
    r0_rows: np.ndarray  # reference length of every table row, NaN until taken
    intact_b: np.ndarray  # rows of the table that are intact
    i_b: np.ndarray
    j_b: np.ndarray
    k_b: np.ndarray
    ecrit_b: np.ndarray
    gamma_b: Optional[np.ndarray]
    digest: str
    r0_stale: bool  # atoms.arrays["bond_r0"] needs rewriting from r0_rows


def _r0_from_slots(r0_nm, table: BondTable) -> np.ndarray:
    """Reference lengths of the table rows from ``bond_r0`` (slot-aligned)."""
    r0_rows = np.full(len(table), np.nan)
    if r0_nm is not None and r0_nm.ndim == 2 and len(table):
        inside = table.slot_b < r0_nm.shape[1]
        r0_rows[inside] = r0_nm[table.owner_b[inside], table.slot_b[inside]]
    return r0_rows


def _r0_by_key(old: "_Bonds", table: BondTable, natoms: int) -> np.ndarray:
    """Reference lengths carried over from an earlier table, bond by bond."""
    key = lambda t: (np.minimum(t.owner_b, t.partner_b) * natoms  # noqa: E731
                     + np.maximum(t.owner_b, t.partner_b))
    old_key = key(old.table)
    order = np.argsort(old_key, kind="stable")
    new_key = key(table)
    pos = np.clip(np.searchsorted(old_key[order], new_key), 0, max(len(order) - 1, 0))
    r0_rows = np.full(len(table), np.nan)
    if len(order):
        found = old_key[order][pos] == new_key
        r0_rows[found] = old.r0_rows[order][pos][found]
    return r0_rows


class BPMSpring(BPMCalculator):
    """Spring bonded-particle model: LAMMPS ``bond_style bpm/spring`` +
    ``pair_style bpm/spring``.

    Bonds (``atoms.arrays["bonds"]``, see :mod:`ase_bpm.bonds`) are springs
    between particles that break beyond a critical strain; particles that are
    not bonded repel when closer than a contact distance.  All units are the
    caller's, as long as they are consistent (LAMMPS ``lj`` or ``si`` numbers
    can be used unchanged; the timestep given to the ASE integrator is then in
    the same time unit).

    Parameters
    ----------
    bond_coeffs:
        ``{bond_type: (k, eps_c, gamma)}`` as LAMMPS ``bond_coeff``: stiffness
        ``k`` (force/distance, or force with ``normalize``), critical strain
        ``eps_c`` (unitless) and damping ``gamma`` (force/velocity).
    pair_coeffs:
        ``{(type_i, type_j): (k, r_c, gamma)}`` as LAMMPS ``pair_coeff``:
        stiffness (force/distance), contact distance ``r_c`` (distance) and
        damping (force/velocity).  Unlisted pairs of types mix from the two
        like-type entries.  Empty: no contact forces (and no neighbour list).
    mix:
        ``"geometric"`` or ``"arithmetic"`` rule for ``r_c`` of unlisted type
        pairs (LAMMPS ``pair_modify mix``); ``k`` and ``gamma`` always mix
        geometrically.
    smooth:
        Multiply bond forces by ``1 - (strain/eps_c)^8`` (``smooth yes``).
    normalize:
        Elastic bond force ``k (r - r0)/r0`` instead of ``k (r - r0)``.
    break_bonds:
        Bonds break when ``|strain| > eps_c`` (``break yes``).  With ``False``
        such a strain raises ``ValueError`` instead.
    overlay_pair:
        Bonded particles also interact through the pair law (``overlay/pair``).
    store_local:
        Log every broken bond in ``atoms.info["broken_bonds"]``, one row
        ``(i, j, step, x, y, z, x_ref, y_ref, z_ref)``: the two atoms, the
        evaluation step, the bond's centre when it broke and in the reference
        state (LAMMPS ``store/local`` with all attributes).
    skin:
        Verlet skin of the contact neighbour list (distance); default 0.3 times
        the largest ``r_c``.

    Results: ``energy`` (elastic energy of bonds and contacts, consistent with
    the forces), ``forces``, ``stress`` (periodic cells), and the ledger
    entries ``dissipated_energy`` and ``broken_bond_energy`` (see
    :mod:`ase_bpm.calculator`).  Per-atom outputs written to ``atoms.arrays``:
    ``nbonds`` (intact bonds) and ``damage`` (fraction of the atom's bonds that
    have broken).  The reference length of each bond (``bond_r0``) is taken at
    its first evaluation and kept.
    """

    default_parameters = dict(
        bond_coeffs={}, pair_coeffs={}, mix="geometric", smooth=True,
        normalize=False, break_bonds=True, overlay_pair=False,
        store_local=True, skin=None)
    watched_arrays = ("type", "bonds")

    def __init__(self, bond_coeffs: Mapping[int, tuple] = None,
                 pair_coeffs: Mapping[tuple, tuple] = None, mix: str = "geometric",
                 smooth: bool = True, normalize: bool = False,
                 break_bonds: bool = True, overlay_pair: bool = False,
                 store_local: bool = True, skin: float | None = None, **kwargs):
        super().__init__(bond_coeffs=dict(bond_coeffs or {}),
                         pair_coeffs=dict(pair_coeffs or {}), mix=mix, smooth=smooth,
                         normalize=normalize, break_bonds=break_bonds,
                         overlay_pair=overlay_pair, store_local=store_local,
                         skin=skin, **kwargs)

    def set(self, **kwargs):
        changed = super().set(**kwargs)
        self._setup()
        return changed

    # -- coefficients ------------------------------------------------------------
    def _setup(self) -> None:
        """Check the parameters and build the coefficient tables."""
        p = self.parameters
        if p["smooth"] and not p["break_bonds"]:
            raise ValueError("smooth=True needs break_bonds=True: beyond eps_c the smoothing "
                             "factor turns negative (LAMMPS: must turn off smoothing with "
                             "break no)")
        if p["mix"] not in ("geometric", "arithmetic"):
            raise ValueError(f'mix must be "geometric" or "arithmetic", got {p["mix"]!r}')
        bonds = {}
        for t, values in p["bond_coeffs"].items():
            t = _check_type("bond_coeffs", t)
            bonds[t] = _check_coeffs("bond_coeffs for bond type", t, values,
                                     ("k", "eps_c", "gamma"), ("k", "eps_c"), ("gamma",))
        pairs = {}
        for key, values in p["pair_coeffs"].items():
            if len(key) != 2:
                raise ValueError(f"pair_coeffs key {key!r} must be a pair of particle types")
            ti, tj = sorted(_check_type("pair_coeffs", t) for t in key)
            pairs[ti, tj] = _check_coeffs("pair_coeffs for types", (ti, tj), values,
                                          ("k", "r_c", "gamma"), ("k", "r_c"), ("gamma",))
        self._bond_coeffs, self._pair_coeffs = bonds, pairs
        ntypes = max(bonds, default=0) + 1
        self._bond_k, self._bond_ecrit, self._bond_gamma = (
            np.full(ntypes, np.nan) for _ in range(3))
        for t, (k, ecrit, gamma) in bonds.items():
            self._bond_k[t], self._bond_ecrit[t], self._bond_gamma[t] = k, ecrit, gamma
        self._bond_damped = any(g > 0 for _, _, g in bonds.values())
        self._pair_damped = any(g > 0 for _, _, g in pairs.values())
        self._pair_tables = {}
        self._neighbours = None
        if pairs:
            max_rc = max(rc for _, rc, _ in pairs.values())
            skin = 0.3 * max_rc if p["skin"] is None else float(p["skin"])
            self._neighbours = VerletList(max_rc, skin)
        self._param_digest = digest(type(self).__name__, sorted(bonds.items()),
                                    sorted(pairs.items()), p["mix"], p["smooth"],
                                    p["normalize"], p["break_bonds"], p["overlay_pair"])
        self._bonds_cache = None  # (bonds strings seen, _Bonds)
        self._exclusion_cache = None

    def pair_coefficients(self, types) -> tuple:
        """Tables ``k[ti, tj]``, ``r_c[ti, tj]``, ``gamma[ti, tj]`` for the
        particle types present, with unlisted pairs mixed.

        Raises ``ValueError`` naming a particle type that has no coefficients.
        """
        present = tuple(np.unique(types))
        if present in self._pair_tables:
            return self._pair_tables[present]
        size = max(present) + 1
        tables = np.full((3, size, size), np.nan)
        for a in present:
            for b in present:
                lo, hi = min(a, b), max(a, b)
                if (lo, hi) in self._pair_coeffs:
                    k, rc, gamma = self._pair_coeffs[lo, hi]
                elif (lo, lo) in self._pair_coeffs and (hi, hi) in self._pair_coeffs:
                    (k1, rc1, g1), (k2, rc2, g2) = (self._pair_coeffs[lo, lo],
                                                    self._pair_coeffs[hi, hi])
                    k, gamma = np.sqrt(k1 * k2), np.sqrt(g1 * g2)
                    rc = (np.sqrt(rc1 * rc2) if self.parameters["mix"] == "geometric"
                          else 0.5 * (rc1 + rc2))
                else:
                    missing = lo if (lo, lo) not in self._pair_coeffs else hi
                    raise ValueError(
                        f"unknown particle type {missing}: pair_coeffs has no entry "
                        f"for types ({lo}, {hi}) and none for ({missing}, {missing}) "
                        "to mix from")
                tables[:, a, b] = k, rc, gamma
        self._pair_tables[present] = tables
        return tables

    # -- bonds -----------------------------------------------------------------------
    def _bonds(self, atoms: Atoms) -> _Bonds:
        """Parsed and checked bonds with their reference lengths.

        Cached while ``bonds`` and ``bond_r0`` on the atoms stay as this
        calculator last saw or wrote them.  When the bonds strings change under
        it (bonds added, removed or retyped), reference lengths follow their
        bonds by atom pair; otherwise they are read slot by slot.
        """
        strings, r0_nm = atoms.arrays.get("bonds"), atoms.arrays.get(R0)
        cache = self._bonds_cache
        if cache is not None:
            seen_strings, seen_r0, cached = cache
            same_strings = _same(strings, seen_strings)
            if same_strings and _same(r0_nm, seen_r0):
                return cached
        table = bond_table(atoms)
        self._check_bond_types(table)
        if cache is not None and not same_strings and cached.table is not None:
            r0_rows, stale = _r0_by_key(cached, table, len(atoms)), True
        else:
            r0_rows = _r0_from_slots(r0_nm, table)
            stale = r0_nm is None or r0_nm.ndim != 2 or r0_nm.shape[1] < table.nslots
        bonds = self._compile(table, r0_rows, stale)
        self._bonds_cache = (_copy(strings), _copy(r0_nm), bonds)
        return bonds

    def _check_bond_types(self, table: BondTable) -> None:
        live = table.type_b > 0
        known = np.zeros(live.shape, dtype=bool)
        inside = table.type_b < len(self._bond_k)
        known[inside] = ~np.isnan(self._bond_k[table.type_b[inside]])
        unknown = live & ~known
        if unknown.any():
            b = int(np.argmax(unknown))
            raise ValueError(
                f"unknown bond type {table.type_b[b]} (bond {table.owner_b[b]}-"
                f"{table.partner_b[b]}): bond_coeffs has no entry for it")

    def _compile(self, table: BondTable, r0_rows, r0_stale) -> _Bonds:
        intact = np.flatnonzero(table.type_b > 0)
        t_b = table.type_b[intact]
        return _Bonds(
            table=table, r0_rows=r0_rows, intact_b=intact,
            i_b=table.owner_b[intact], j_b=table.partner_b[intact],
            k_b=self._bond_k[t_b], ecrit_b=self._bond_ecrit[t_b],
            gamma_b=self._bond_gamma[t_b] if self._bond_damped else None,
            digest=digest(table.owner_b, table.partner_b, table.type_b),
            r0_stale=r0_stale)

    # -- pairs -------------------------------------------------------------------
    def _contact_candidates(self, atoms: Atoms, bonds: _Bonds) -> np.ndarray:
        """Indices into the Verlet list of pairs that may interact.

        Without ``overlay_pair``, pairs joined by an intact bond (at the start
        of this evaluation, as LAMMPS' special list) are left out, whatever the
        periodic image.
        """
        nl = self._neighbours
        nl.update(atoms.positions, atoms.cell, atoms.pbc)
        key = (nl.nbuilds, bonds.digest)
        if self._exclusion_cache is not None and self._exclusion_cache[0] == key:
            return self._exclusion_cache[1]
        if self.parameters["overlay_pair"] or len(bonds.i_b) == 0:
            select = np.arange(len(nl.i_p))
        else:
            n = len(atoms)
            bonded = np.unique(np.minimum(bonds.i_b, bonds.j_b) * n
                               + np.maximum(bonds.i_b, bonds.j_b))
            select = np.flatnonzero(~np.isin(nl.i_p * n + nl.j_p, bonded,
                                             assume_unique=False))
        self._exclusion_cache = (key, select)
        return select

    def _handover_energy(self, types_n, i_k, j_k, r_kc) -> float:
        """Contact energy that appears when broken bonds hand their pairs to
        the pair law while the two particles overlap (not with overlay_pair,
        where the pair law acted all along)."""
        if self._neighbours is None or self.parameters["overlay_pair"]:
            return 0.0
        k_tt, rc_tt, _ = self.pair_coefficients(types_n)
        ti_k, tj_k = np.take(types_n, i_k), np.take(types_n, j_k)
        rc_k = rc_tt[ti_k, tj_k]
        touch = np.einsum("kc,kc->k", r_kc, r_kc) < rc_k * rc_k
        if not touch.any():
            return 0.0
        res = spring_pairs(r_kc[touch], None, k_tt[ti_k, tj_k][touch], rc_k[touch], None)
        return float(res.energy_x.sum())

    # -- evaluation ------------------------------------------------------------------
    def _signature(self, atoms: Atoms) -> str:
        return digest(self._param_digest, self._bonds(atoms).digest,
                      particle_types(atoms))

    def _evaluate(self, atoms: Atoms) -> Evaluation:
        n = len(atoms)
        x_nc, cell, pbc = atoms.positions, atoms.cell, atoms.pbc
        types_n = particle_types(atoms)
        bonds = self._bonds(atoms)
        damped = (self._bond_damped and len(bonds.i_b)) or (
            self._pair_damped and self._neighbours is not None)
        v_nc = velocities(atoms) if damped else None
        periodic = pbc.all()

        f_nc = np.zeros((n, 3))
        fd_nc = np.zeros((n, 3)) if damped else None
        energy = 0.0
        w_cc = np.zeros((3, 3)) if periodic else None

        # bonds
        i_b, j_b = bonds.i_b, bonds.j_b
        r_bc = np.take(x_nc, j_b, axis=0) - np.take(x_nc, i_b, axis=0)
        if pbc.any():
            r_bc = minimum_image(r_bc, cell, pbc)
        r_b = np.sqrt(np.einsum("bc,bc->b", r_bc, r_bc))
        r0_stored = bonds.r0_rows[bonds.intact_b]
        fresh_b = np.isnan(r0_stored)
        r0_b = np.where(fresh_b, r_b, r0_stored)
        if pbc.any() and len(r0_b):
            # a bond must break before it could reach half the cell (minimum image)
            reach_b = r0_b * (1.0 + bonds.ecrit_b)
            half_width = periodic_half_widths(cell, pbc)
            if reach_b.max() >= half_width:
                b = int(np.argmax(reach_b))
                raise ValueError(
                    f"periodic cell too small for bond {i_b[b]}-{j_b[b]}: with r0 = "
                    f"{r0_b[b]:.6g} and eps_c = {bonds.ecrit_b[b]} it may stretch to "
                    f"{reach_b[b]:.6g}, beyond half the cell width ({half_width:.6g})")
        strain_b = bond_strain(r_b, r0_b)
        broken_b = np.abs(strain_b) > bonds.ecrit_b
        if broken_b.any() and not self.parameters["break_bonds"]:
            b = int(np.argmax(broken_b))
            raise ValueError(
                f"bond {i_b[b]}-{j_b[b]} (type {bonds.table.type_b[bonds.intact_b[b]]}) "
                f"reached strain {strain_b[b]:.6g} beyond eps_c = {bonds.ecrit_b[b]} "
                "with break_bonds=False")
        released = 0.0
        if broken_b.any():
            keep = ~broken_b
            gone = spring_bonds(r_bc[broken_b], None, r0_b[broken_b],
                                bonds.k_b[broken_b], bonds.ecrit_b[broken_b], None,
                                self.parameters["smooth"], self.parameters["normalize"])
            released = float(gone.energy_x.sum()) - self._handover_energy(
                types_n, i_b[broken_b], j_b[broken_b], r_bc[broken_b])
        else:
            keep = slice(None)
        if len(i_b):
            v_bc = None
            if bonds.gamma_b is not None:
                v_bc = np.take(v_nc, j_b, axis=0) - np.take(v_nc, i_b, axis=0)
                v_bc = v_bc[keep]
            res = spring_bonds(r_bc[keep], v_bc, r0_b[keep], bonds.k_b[keep],
                               bonds.ecrit_b[keep],
                               None if bonds.gamma_b is None else bonds.gamma_b[keep],
                               self.parameters["smooth"], self.parameters["normalize"])
            f_nc += scatter_pairs(i_b[keep], j_b[keep], res.f_xc, n)
            if res.fd_xc is not None:
                fd_nc += scatter_pairs(i_b[keep], j_b[keep], res.fd_xc, n)
            energy += float(res.energy_x.sum())
            if periodic:
                w_cc += virial(r_bc[keep], res.f_xc)

        # contacts
        if self._neighbours is not None:
            k_tt, rc_tt, gamma_tt = self.pair_coefficients(types_n)
            nl = self._neighbours
            cand = self._contact_candidates(atoms, bonds)
            r_pc = nl.pair_vectors(x_nc, cand)
            i_p, j_p = nl.i_p[cand], nl.j_p[cand]
            ti_p, tj_p = np.take(types_n, i_p), np.take(types_n, j_p)
            rc_p = rc_tt[ti_p, tj_p]
            touch = np.einsum("pc,pc->p", r_pc, r_pc) < rc_p * rc_p
            if touch.any():
                i_p, j_p, r_pc = i_p[touch], j_p[touch], r_pc[touch]
                ti_p, tj_p, rc_p = ti_p[touch], tj_p[touch], rc_p[touch]
                v_pc = gamma_p = None
                if self._pair_damped:
                    v_pc = np.take(v_nc, j_p, axis=0) - np.take(v_nc, i_p, axis=0)
                    gamma_p = gamma_tt[ti_p, tj_p]
                res = spring_pairs(r_pc, v_pc, k_tt[ti_p, tj_p], rc_p, gamma_p)
                f_nc += scatter_pairs(i_p, j_p, res.f_xc, n)
                if res.fd_xc is not None:
                    fd_nc += scatter_pairs(i_p, j_p, res.fd_xc, n)
                energy += float(res.energy_x.sum())
                if periodic:
                    w_cc += virial(r_pc, res.f_xc)

        return Evaluation(
            forces=f_nc, energy=energy, f_damp=fd_nc, virial=w_cc,
            released_energy=released,
            extra=dict(bonds=bonds, fresh_b=fresh_b, r0_b=r0_b, broken_b=broken_b,
                       r_bc=r_bc))

    def _commit(self, atoms: Atoms, ev: Evaluation, step: int) -> None:
        bonds: _Bonds = ev.extra["bonds"]
        if self.parameters["store_local"] and (
                X_REF not in atoms.arrays or atoms.arrays[X_REF].shape != (len(atoms), 3)):
            atoms.arrays[X_REF] = atoms.positions.copy()
        fresh_b = ev.extra["fresh_b"]
        bonds.r0_rows[bonds.intact_b[fresh_b]] = ev.extra["r0_b"][fresh_b]
        broken_b = ev.extra["broken_b"]
        if broken_b.any():
            bonds = self._break(atoms, bonds, broken_b, ev.extra["r_bc"], step)
        if fresh_b.any() or bonds.r0_stale:
            table = bonds.table
            r0_nm = np.full((len(atoms), table.nslots), np.nan)
            r0_nm[table.owner_b, table.slot_b] = bonds.r0_rows
            atoms.arrays[R0] = r0_nm
            bonds.r0_stale = False
        self._bonds_cache = (_copy(atoms.arrays.get("bonds")), _copy(atoms.arrays.get(R0)),
                             bonds)

        table = bonds.table
        intact = table.type_b > 0
        n = len(atoms)
        nbonds = (np.bincount(table.owner_b[intact], minlength=n)
                  + np.bincount(table.partner_b[intact], minlength=n))
        listed = (np.bincount(table.owner_b, minlength=n)
                  + np.bincount(table.partner_b, minlength=n))
        atoms.arrays["nbonds"] = nbonds
        atoms.arrays["damage"] = np.divide(listed - nbonds, listed,
                                           out=np.zeros(n), where=listed > 0)

    def _break(self, atoms, bonds: _Bonds, broken_b, r_bc, step) -> _Bonds:
        """Set broken bonds to type 0 in the bonds strings and log them."""
        table = bonds.table
        rows = bonds.intact_b[broken_b]
        new_type = table.type_b.copy()
        new_type[rows] = 0
        strings = atoms.arrays["bonds"].copy()  # type 0 is never longer: fits
        for owner in np.unique(table.owner_b[rows]):
            s = np.searchsorted(table.owner_b, owner)
            e = np.searchsorted(table.owner_b, owner, side="right")
            strings[owner] = format_atom_bonds(table.partner_b[s:e], new_type[s:e])
        atoms.arrays["bonds"] = strings

        if self.parameters["store_local"]:
            i_k, j_k = bonds.i_b[broken_b], bonds.j_b[broken_b]
            centre = np.take(atoms.positions, i_k, axis=0) + 0.5 * r_bc[broken_b]
            x_ref = atoms.arrays[X_REF]
            d_ref = minimum_image(np.take(x_ref, j_k, axis=0) - np.take(x_ref, i_k, axis=0),
                                  atoms.cell, atoms.pbc)
            centre_ref = np.take(x_ref, i_k, axis=0) + 0.5 * d_ref
            log = np.column_stack([np.minimum(i_k, j_k), np.maximum(i_k, j_k),
                                   np.full(len(i_k), step), centre, centre_ref])
            old = atoms.info.get(BROKEN_LOG, np.zeros((0, len(BROKEN_LOG_COLUMNS))))
            atoms.info[BROKEN_LOG] = np.vstack([old, log])
        new_table = BondTable(table.owner_b, table.slot_b, table.partner_b, new_type)
        return self._compile(new_table, bonds.r0_rows, bonds.r0_stale)
