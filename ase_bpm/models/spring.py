"""BPMSpring: LAMMPS ``bond_style bpm/spring`` with ``pair_style bpm/spring``."""

from __future__ import annotations

from typing import Mapping

import numpy as np
from ase import Atoms

from ..core.bonds import BondTable
from .bonded import BondSet, BondState, ContactList, X_REF, write_bond_counts
from .base import (BPMCalculator, Evaluation, digest, particle_types, same_array,
                         scatter_pairs, velocities, virial)
from ..laws.spring import spring_bonds, spring_pairs
from ..core.neighbours import minimum_image, periodic_half_widths
from ..core.params import check_coeffs, check_type, json_coeffs, type_pair


class BPMSpring(BPMCalculator):
    """Spring bonded-particle model: LAMMPS ``bond_style bpm/spring`` +
    ``pair_style bpm/spring``.

    Bonds (integer arrays on the atoms, see :mod:`ase_bpm.bonds`) are springs
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
        such a strain raises ``ValueError`` instead; it needs ``smooth=False``
        (as in LAMMPS: the smoothing factor turns negative beyond ``eps_c``).
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
    timestep:
        The MD timestep (time), for fixes that move with time.
    fixes:
        External force pieces (:mod:`ase_bpm.fixes`), evaluated with the bonds.

    Results: ``energy`` (elastic energy of bonds and contacts, consistent with
    the forces), ``forces``, ``stress`` (periodic cells), and the ledger
    entries ``dissipated_energy`` and ``broken_bond_energy`` (see
    :mod:`ase_bpm.calculator`).  Per-atom outputs written to ``atoms.arrays``:
    ``nbonds`` (intact bonds) and ``damage`` (fraction of the atom's bonds that
    have broken).  The reference length of each bond (``bond_r0``) is taken at
    its first evaluation and kept.

    Bonds break in every evaluation at a new configuration.  LAMMPS does not
    break bonds in the setup evaluation that starts each ``run``; along a
    trajectory the two agree, since the first evaluation takes the reference
    lengths and later ones are steps.
    """

    name = "bpm_spring"
    default_parameters = dict(
        bond_coeffs={}, pair_coeffs={}, mix="geometric", smooth=True,
        normalize=False, break_bonds=True, overlay_pair=False,
        store_local=True, skin=None, timestep=None)
    watched_arrays = ("type",)

    def __init__(self, bond_coeffs: Mapping[int, tuple] = None,
                 pair_coeffs: Mapping[tuple, tuple] = None, mix: str = "geometric",
                 smooth: bool = True, normalize: bool = False,
                 break_bonds: bool = True, overlay_pair: bool = False,
                 store_local: bool = True, skin: float | None = None,
                 timestep: float | None = None, fixes=(), **kwargs):
        super().__init__(fixes=fixes, bond_coeffs=dict(bond_coeffs or {}),
                         pair_coeffs=dict(pair_coeffs or {}), mix=mix, smooth=smooth,
                         normalize=normalize, break_bonds=break_bonds,
                         overlay_pair=overlay_pair, store_local=store_local,
                         skin=skin, timestep=timestep, **kwargs)

    def set(self, **kwargs):
        changed = super().set(**kwargs)
        self._setup()
        return changed

    def todict(self, skip_default=True) -> dict:
        """Parameters for ASE's trajectory files (JSON: keys become strings,
        which the constructor accepts back)."""
        params = dict(super().todict(skip_default=skip_default))
        for name in ("bond_coeffs", "pair_coeffs"):
            if name in params:
                params[name] = json_coeffs(params[name])
        return params

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
            t = check_type("bond_coeffs", t)
            bonds[t] = check_coeffs("bond_coeffs for bond type", t, values,
                                    ("k", "eps_c", "gamma"), ("k", "eps_c"), ("gamma",))
        pairs = {}
        for key, values in p["pair_coeffs"].items():
            ti, tj = type_pair("pair_coeffs", key)
            pairs[ti, tj] = check_coeffs("pair_coeffs for types", (ti, tj), values,
                                         ("k", "r_c", "gamma"), ("k", "r_c"), ("gamma",))
        self._bond_coeffs, self._pair_coeffs = bonds, pairs
        self._bond_table = np.full((3, max(bonds, default=0) + 1), np.nan)
        for t, values in bonds.items():
            self._bond_table[:, t] = values
        self._bond_damped = any(g > 0 for _, _, g in bonds.values())
        self._pair_damped = any(g > 0 for _, _, g in pairs.values())
        self._pair_tables = {}
        self._param_digest = digest(type(self).__name__, sorted(bonds.items()),
                                    sorted(pairs.items()), p["mix"], p["smooth"],
                                    p["normalize"], p["break_bonds"], p["overlay_pair"])
        self._forget()

    def _forget(self) -> None:
        self._types_digest = None
        self._bond_state = BondState(self._check_bond_types)
        self._contacts = None
        if self._pair_coeffs:
            max_rc = max(rc for _, rc, _ in self._pair_coeffs.values())
            skin = 0.3 * max_rc if self.parameters["skin"] is None else self.parameters["skin"]
            self._contacts = ContactList(max_rc, float(skin), self.parameters["overlay_pair"])

    def pair_coefficients(self, types) -> np.ndarray:
        """Tables ``[k, r_c, gamma][ti, tj]`` for the particle types present,
        unlisted pairs mixed.  Raises ``ValueError`` naming a particle type that
        has no coefficients."""
        last = self._pair_tables.get("last")
        if last is not None and same_array(last[0], types):
            return last[1]
        present = tuple(int(t) for t in np.unique(types))
        if present in self._pair_tables:
            self._pair_tables["last"] = (types.copy(), self._pair_tables[present])
            return self._pair_tables[present]
        tables = np.full((3, max(present) + 1, max(present) + 1), np.nan)
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
        self._pair_tables["last"] = (types.copy(), tables)
        return tables

    def _check_bond_types(self, table: BondTable) -> None:
        size = self._bond_table.shape[1]
        live = table.type_b > 0
        known = np.zeros(live.shape, dtype=bool)
        inside = table.type_b < size
        known[inside] = ~np.isnan(self._bond_table[0, table.type_b[inside]])
        unknown = live & ~known
        if unknown.any():
            b = int(np.argmax(unknown))
            raise ValueError(
                f"unknown bond type {table.type_b[b]} (bond {table.owner_b[b]}-"
                f"{table.partner_b[b]}): bond_coeffs has no entry for it")

    # -- contacts ---------------------------------------------------------------
    def _handover_energy(self, types_n, i_k, j_k, r_kc) -> float:
        """Contact energy that appears when broken bonds hand their pairs to
        the pair law while the two particles overlap (not with overlay_pair,
        where the pair law acted all along)."""
        if self._contacts is None or self.parameters["overlay_pair"]:
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
    def _state_replaced(self, atoms: Atoms) -> bool:
        return not self._bond_state.is_current(atoms)

    def _signature(self, atoms: Atoms, evaluation) -> str:
        bonds = (self._bond_state.current if evaluation is not None
                 else self._bond_state.bonds(atoms))
        types = particle_types(atoms)
        if self._types_digest is None or not same_array(self._types_digest[0], types):
            self._types_digest = (types.copy(), digest(types))
        return digest(self._param_digest, bonds.fingerprint, self._types_digest[1],
                      self._fixes_digest())

    def _evaluate(self, atoms: Atoms) -> Evaluation:
        n = len(atoms)
        x_nc, cell, pbc = atoms.positions, atoms.cell, atoms.pbc
        types_n = particle_types(atoms)
        bonds = self._bond_state.bonds(atoms)
        contacts = self._contacts is not None
        damped = (self._bond_damped and len(bonds) > 0) or (self._pair_damped and contacts)
        v_nc = velocities(atoms) if damped else None
        smooth, normalize = self.parameters["smooth"], self.parameters["normalize"]

        f_nc = np.zeros((n, 3))
        fd_nc = np.zeros((n, 3)) if damped else None
        energy, released = 0.0, 0.0
        pair_forces = []  # (r_xc, f_xc) of bonds and contacts, for the virial
        extra = dict(bonds=bonds)

        if len(bonds):
            i_b, j_b = bonds.i_b, bonds.j_b
            r_bc = bonds.vectors(x_nc)
            v_bc = bonds.vectors(v_nc) if self._bond_damped else None
            if pbc.any():
                r_bc = minimum_image(r_bc, cell, pbc)
            r_b = np.sqrt(np.einsum("bc,bc->b", r_bc, r_bc))
            k_b, ecrit_b, gamma_b = bonds.per_bond(
                "spring", lambda: self._bond_table[:, bonds.type_b])
            r0_b = bonds.of_bonds("r0")
            fresh_b = np.isnan(r0_b)
            if fresh_b.any():
                r0_b = np.where(fresh_b, r_b, r0_b)
            if pbc.any():
                self._check_bond_reach(bonds, r0_b, ecrit_b, cell, pbc)
            broken_b = np.abs(r_b - r0_b) > ecrit_b * r0_b
            if not self.advancing:  # bonds break in steps only, as in LAMMPS
                broken_b[:] = False
            if broken_b.any() and not self.parameters["break_bonds"]:
                b = int(np.argmax(broken_b))
                raise ValueError(
                    f"bond {i_b[b]}-{j_b[b]} (type {bonds.type_b[b]}) reached strain "
                    f"{(r_b[b] - r0_b[b]) / r0_b[b]:.6g} beyond eps_c = {ecrit_b[b]} "
                    "with break_bonds=False")
            res = spring_bonds(r_bc, v_bc, r0_b, k_b, ecrit_b,
                               gamma_b if self._bond_damped else None, smooth, normalize,
                               r_b=r_b)
            f_bc, fd_bc, energy_b = res
            if broken_b.any():
                # broken bonds give no force now; their energy is released
                released = float(energy_b[broken_b].sum()) - self._handover_energy(
                    types_n, i_b[broken_b], j_b[broken_b], r_bc[broken_b])
                f_bc[broken_b] = 0.0
                energy_b = energy_b[~broken_b]
                if fd_bc is not None:
                    fd_bc[broken_b] = 0.0
            f_nc += bonds.incidence @ f_bc
            if fd_bc is not None:
                fd_nc += bonds.incidence @ fd_bc
            energy += float(energy_b.sum())
            pair_forces.append((r_bc, f_bc))
            extra.update(fresh_b=fresh_b, r0_b=r0_b, broken_b=broken_b, r_bc=r_bc)

        if contacts:
            k_tt, rc_tt, gamma_tt = self.pair_coefficients(types_n)
            i_p, j_p, r_pc = self._contacts.pairs(atoms, bonds)
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
                pair_forces.append((r_pc, res.f_xc))

        return Evaluation(forces=f_nc, energy=energy, f_damp=fd_nc,
                          virial=lambda: sum((virial(r, f) for r, f in pair_forces),
                                             np.zeros((3, 3))),
                          released_energy=released, extra=extra)

    @staticmethod
    def _check_bond_reach(bonds: BondSet, r0_b, ecrit_b, cell, pbc) -> None:
        """A bond must break before it could reach half the cell: beyond, the
        minimum image would silently flip it to another periodic image."""
        reach_b = r0_b * (1.0 + ecrit_b)
        half_width = periodic_half_widths(cell, pbc)
        if reach_b.max() >= half_width:
            b = int(np.argmax(reach_b))
            raise ValueError(
                f"periodic cell too small for bond {bonds.i_b[b]}-{bonds.j_b[b]}: with "
                f"r0 = {r0_b[b]:.6g} and eps_c = {ecrit_b[b]} it may stretch to "
                f"{reach_b[b]:.6g}, beyond half the cell width ({half_width:.6g})")

    def _commit(self, atoms: Atoms, ev: Evaluation, step: int) -> None:
        state = self._bond_state
        bonds: BondSet = ev.extra["bonds"]
        log = self.parameters["store_local"]
        if log and (X_REF not in atoms.arrays
                    or atoms.arrays[X_REF].shape != (len(atoms), 3)):
            atoms.arrays[X_REF] = atoms.positions.copy()
        counts_stale = (self._bond_state.reread or "nbonds" not in atoms.arrays
                        or len(atoms.arrays["nbonds"]) != len(atoms))
        if len(bonds):
            if ev.extra["fresh_b"].any():
                bonds.set_bonds("r0", ev.extra["r0_b"], ev.extra["fresh_b"])
            broken_b = ev.extra["broken_b"]
            if broken_b.any():
                bonds = state.break_bonds(atoms, bonds, broken_b, step, ev.extra["r_bc"], log)
                counts_stale = True
        state.write(atoms, bonds)
        if counts_stale:
            write_bond_counts(atoms, bonds)

    # -- LAMMPS export ---------------------------------------------------------------
    def contact_skin(self) -> float | None:
        """The Verlet skin of the contact search (LAMMPS ``neighbor``); None
        without pair coefficients, where there is no search."""
        return None if self._contacts is None else self._contacts.neighbours.skin

    def lammps_scene(self, atoms: Atoms, data_file: str, *, units: str | None = None,
                     timestep: float | None = None, thermo: int = 100,
                     broken_bonds_fix: str | bool | None = True):
        """The scene in LAMMPS (:class:`ase_bpm.core.lammps_text.LammpsScene`):
        ``bond_style`` and ``pair_style bpm/spring`` on ``atom_style bond``, or
        on ``bpm/sphere`` with ``fix nve/sphere`` when a fix ``needs_spheres``
        (granular walls).  ``units`` default ``"lj"``, ``timestep`` the
        calculator's.  ``broken_bonds_fix`` names a ``store/local`` fix that
        records broken bonds every ``thermo`` steps, dumped next to the data
        file (``<stem>.broken``, columns as ``atoms.info["broken_bonds"]``,
        1-based atom IDs); ``True`` (default): ``"broken"`` with
        ``store_local``, else none; ``False`` or ``None``: none.
        """
        import os

        from ..core.bonds import get_bonds
        from ..core.lammps_text import (DEFAULT_SKIN, LammpsScene, bond_data, exact,
                                        integrator, neighbour_lists, preamble,
                                        sphere_densities)

        p = self.parameters
        bond_coeffs, pair_coeffs = p["bond_coeffs"], p["pair_coeffs"]
        if broken_bonds_fix is True:
            broken_bonds_fix = "broken" if p["store_local"] else None
        spheres = any(getattr(fix, "needs_spheres", False) for fix in self.fixes)
        types_n = particle_types(atoms)
        ntypes = max([int(types_n.max(initial=1))] + [max(k) for k in pair_coeffs])
        nbondtypes = max([1] + list(bond_coeffs))
        rc_p = [rc for _, rc, _ in pair_coeffs.values()]
        data = bond_data(atoms, ntypes, nbondtypes, margin=max(rc_p, default=1.0),
                         spheres=spheres)

        i_b, j_b, _ = get_bonds(atoms)
        r_bc = minimum_image(atoms.positions[j_b] - atoms.positions[i_b], atoms.cell, atoms.pbc)
        r_b = np.linalg.norm(r_bc, axis=1)
        # r0 may already be known; else the current lengths become the reference
        stretch = 1.0 + max([e for _, e, _ in bond_coeffs.values()], default=0.0)
        skin = self.contact_skin()
        skin = DEFAULT_SKIN if skin is None else skin
        comm_cut = max(max(rc_p, default=0.0), stretch * r_b.max(initial=0.0)) + skin

        yes = lambda flag: "yes" if flag else "no"  # noqa: E731
        style = (f"bond_style bpm/spring smooth {yes(p['smooth'])} "
                 f"normalize {yes(p['normalize'])} break {yes(p['break_bonds'])} "
                 f"overlay/pair {yes(p['overlay_pair'])}")
        columns = "id1 id2 time x y z x/ref y/ref z/ref".split()
        if broken_bonds_fix:
            style += f" store/local {broken_bonds_fix} {thermo} {' '.join(columns)}"
        cmds = [*preamble(atoms, units or "lj", "bpm/sphere" if spheres else "bond"),
                "newton on off",
                "special_bonds lj/coul 1 1 1" if p["overlay_pair"]
                else "special_bonds lj 0 1 1 coul 1 1 1",
                f"read_data {data_file}",
                *(sphere_densities(atoms)[1] if spheres else ()),
                f"comm_modify vel yes cutoff {exact(comm_cut)}", style]
        for t in range(1, nbondtypes + 1):
            k, e, gamma = bond_coeffs.get(t, (1.0, 1.0, 0.0))  # unused types need values
            cmds.append(f"bond_coeff {t} {exact(k)} {exact(e)} {exact(gamma)}")
        if pair_coeffs:
            cmds += ["pair_style bpm/spring", f"pair_modify mix {p['mix']}"]
            for (ti, tj), (k, rc, gamma) in sorted(pair_coeffs.items()):
                cmds.append(f"pair_coeff {ti} {tj} {exact(k)} {exact(rc)} {exact(gamma)}")
        else:
            cmds += [f"pair_style zero {exact(max(stretch * r_b.max(initial=1.0), 1e-300))}",
                     "pair_coeff * *"]
        cmds += neighbour_lists(skin)
        cmds += integrator("nve/sphere" if spheres else "nve",
                           p["timestep"] if timestep is None else timestep)

        dumps = ()
        if broken_bonds_fix:
            stem = os.path.splitext(data_file)[0]
            dumps = (f"dump {broken_bonds_fix} all local {thermo} {stem}.broken "
                     + " ".join(f"f_{broken_bonds_fix}[{k + 1}]" for k in range(len(columns))),
                     f"dump_modify {broken_bonds_fix} format float %.17g")
        return LammpsScene(data, tuple(cmds), spheres=spheres, dumps=dumps,
                           thermo=("compute nbond all nbond/atom",
                                   "compute tbond all reduce sum c_nbond",
                                   "thermo_style custom step ke pe c_tbond"))
