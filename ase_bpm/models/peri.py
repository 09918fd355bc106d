"""BPMPeri: peridynamics as breakable bonds (LAMMPS ``bond_style bpm/peri``
with ``pair_style bpm/peri`` by default; the legacy ``peri/*`` styles as an
option, ``follows="legacy"``): the model, :class:`PeriModel`, and its
calculator, :class:`BPMPeri`."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from typing import Mapping, Optional

import numpy as np
from ase import Atoms
from ase.geometry import wrap_positions

from ..core.arrays import Inputs, require_finite, same_array
from ..core.params import check_coeffs, coeff_tuple, outside_stacklevel, type_pair
from ..laws import compiled
from ..laws import peri as law
from ..laws.bond import LAWS, TOTAL_ENERGY, TOTALS, totals_virial
from ..laws.contact import ContactSums, PairTable, contact_forces, contact_springs
from .analysis import Analysis, add_pair_virials, bond_local, pair_local, stress_per_atom
from .base import digest, virial
from .bonded import (BondedCalculator, BondedEvaluation, BondedModel, BondSet, ContactList,
                     pair_keys, valid_in_order, write_bond_counts)
from .evaluation import Context
from .outputs import BOND_COUNTS, DAMAGE, DILATATION

#: the models, by name: their coefficients in LAMMPS ``bond_coeff`` order
MODELS = {name: law_.coefficients for name, law_ in LAWS.items() if law_.family == "peri"}


def check_follows(where: str, follows, values=law.FOLLOWS) -> str:
    """``follows`` if it is one of ``values`` (:data:`ase_bpm.laws.peri.FOLLOWS`),
    else ValueError naming ``where`` and the values."""
    if follows not in values:
        raise ValueError(f"{where} must be one of {', '.join(map(repr, values))} "
                         f"(which LAMMPS BPMPeri follows), got {follows!r}")
    return follows


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


# per-node state on the atoms
WVOLUME, VINTER, SMIN, LAMBDA = "peri_wvolume", "peri_vinter", "peri_smin", "peri_lambda"
SPACING = "peri_lattice_spacing"  # info
#: info: the LAMMPS styles the state on the atoms was computed following (a key
#: of law.RECORDED); atoms with PERI state and without it come from a run
#: before the option existed (law.BEFORE_OPTION)
FOLLOWED = "peri_follows"
@dataclass(frozen=True)
class PeriNodes:
    """Per-node state an evaluation leaves for the commit."""

    m_n: np.ndarray  # weighted volume (reference configuration)
    vinter_n: np.ndarray  # interaction volume of the intact reference bonds
    spacing: float  # lattice spacing used
    theta_n: Optional[np.ndarray]  # dilatation (state-based models)
    lambda_n: Optional[np.ndarray]  # plastic multiplier (eps)
    smin_n: Optional[np.ndarray]  # smallest stretch of each node's bonds, this step


@dataclass(kw_only=True)
class PeriEvaluation(BondedEvaluation):
    nodes: PeriNodes
    #: the NumPy route's touching pairs, kept for an analysis only
    contacts: Optional[ContactSums] = None


CONTACT_REACH = 1.35  # pair_style bpm/peri: contact within 1.35 lattice spacings
BROKEN_CONTACT = 0.9  # ...or within 0.9 r0 for the two nodes of a broken bond


class PeriModel(BondedModel):
    """The model of :class:`BPMPeri`: bonds of the registered PERI laws
    (pmb, lps, ves, eps) with their node state, and the ``pair_style
    bpm/peri`` contacts between nodes not bonded."""

    label = "BPMPeri"
    watched_arrays = ("type", "vfrac")
    signature_arrays = ("type", "vfrac")
    family = "peri"
    PAIR_LAW = law.PeriContact()  # pair_style bpm/peri
    laws_together = True  # (one compiled pass over the bonds: the node state)

    @property
    def per_atom_outputs(self) -> tuple:
        """``damage`` and ``nbonds``, and ``dilatation`` where a bond type
        has a state-based model (lps, ves, eps)."""
        return BOND_COUNTS + ((DILATATION,) if self._state_based else ())

    # -- coefficients ------------------------------------------------------------
    def setup(self, parameters) -> str:
        self.parameters = p = parameters
        self._setup_bonds()
        pairs = {}
        for key, values in p["pair_coeffs"].items():
            ti, tj = type_pair("pair_coeffs", key)
            names = self.PAIR_LAW.coefficients
            values = coeff_tuple("pair_coeffs for types", (ti, tj), values, names)
            pairs[ti, tj] = check_coeffs("pair_coeffs for types", (ti, tj), values, names,
                                         self.PAIR_LAW.positive)
        if p["timestep"] is not None and not float(p["timestep"]) > 0:
            raise ValueError(f"timestep must be positive, got {p['timestep']!r}")
        if p["lattice_spacing"] is not None and not float(p["lattice_spacing"]) > 0:
            raise ValueError(f"lattice_spacing must be positive, got {p['lattice_spacing']!r}")
        if p["follows"] is not None:
            check_follows("follows", p["follows"])
        self._followed = None  # what the laws were told last (_follow)
        self._pairs = pairs
        self._pair_table = PairTable(pairs, self.PAIR_LAW.coefficients)  # no mixing
        self._state_based = [name for name, law_ in self._laws.items() if law_.state_based]
        models = compiled.PERI_MODELS
        for t, name in enumerate(self._law_of_type):
            if name and name not in models:
                raise ValueError(
                    f"bond_coeffs for bond type {t}: BPMPeri has no node state for the "
                    f"registered law {name!r}: its bond laws are {', '.join(models)}")
        self._rows_t = law.coefficient_rows(self._coeff_table, [
            models.index(name) if name else np.nan for name in self._law_of_type])
        self.forget()
        return digest(self.label,
                      sorted((t, sorted(v.items())) for t, v in self._bond_values.items()),
                      sorted(self._law_of_type[1:].tolist()), sorted(pairs.items()),
                      p["lattice_spacing"], p["timestep"], p["break_bonds"],
                      # (not given: the digest of before the option, restarts run on)
                      *(() if p["follows"] is None else (p["follows"],)))

    def forget(self) -> None:
        super().forget()
        self._contact_list = None
        self._intact_volumes = None  # what write_counts worked out last
        self._reach_of = None  # (what it holds for, contact distances of the listed pairs)

    # -- which LAMMPS ----------------------------------------------------------------
    def followed(self, atoms: Atoms) -> str:
        """What this calculator follows on ``atoms`` (a key of
        :data:`ase_bpm.laws.peri.RECORDED`): ``follows`` where given, else
        what the atoms record, else, for atoms with PERI state from before the
        option, what that run computed (``BEFORE_OPTION``: the legacy styles,
        eps as it was), else ``"bpm/peri"``."""
        given = self.parameters["follows"]
        if given is not None:
            return given
        recorded = atoms.info.get(FOLLOWED)
        if recorded is not None:
            return check_follows(f'atoms.info["{FOLLOWED}"]', recorded, tuple(law.RECORDED))
        return law.BEFORE_OPTION if WVOLUME in atoms.arrays else law.BPM_PERI

    def _signature_extras(self, atoms: Atoms) -> tuple:
        """What the calculator follows, where it is ``bond_style bpm/peri``:
        the legacy styles add nothing, so the records of runs from before the
        option (which followed them) hold."""
        follows = self.followed(atoms)
        return () if follows != law.BPM_PERI else (follows,)

    def _follow(self, atoms: Atoms) -> bool:
        """Tell the laws what :meth:`followed` says (where it changed);
        returns whether that is the legacy styles (either form)."""
        follows = self.followed(atoms)
        if follows != self._followed:
            for law_ in self._laws.values():
                law_.follow(follows)
            self._followed = follows
            self._warn_of_kept_weighted_volumes(atoms, follows)
        return follows != law.BPM_PERI

    def _warn_of_kept_weighted_volumes(self, atoms: Atoms, follows: str) -> None:
        """The weighted volumes are taken once, at the reference state, and
        in a periodic cell the legacy styles take them otherwise
        (:meth:`_reference_weighted_volume`): say so when ``follows``
        changes between the two after they were taken."""
        recorded = atoms.info.get(FOLLOWED)
        # only "legacy" takes them otherwise (a run from before the option
        # took them as "bpm/peri" does, and BEFORE_OPTION keeps them so)
        if (recorded is None or WVOLUME not in atoms.arrays or not self._state_based
                or not atoms.pbc.any() or (recorded == law.LEGACY) == (follows == law.LEGACY)):
            return
        warnings.warn(
            f"BPMPeri follows {follows!r} on periodic atoms whose weighted volumes "
            f'(atoms.arrays["{WVOLUME}"]) were taken at the reference state following '
            f"{recorded!r}, which takes them otherwise (docs/lammps.md); they stay as "
            f"taken: give follows={follows!r} before the first evaluation for its own",
            UserWarning, stacklevel=outside_stacklevel())

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
    def _volumes(self, atoms: Atoms) -> np.ndarray:
        vol = atoms.arrays.get("vfrac")
        if vol is None:
            raise ValueError('BPMPeri needs the nodal volume of every node in '
                             'atoms.arrays["vfrac"]')
        if vol.shape != (len(atoms),) or vol.dtype.kind not in "fiu":
            raise ValueError(f'atoms.arrays["vfrac"] must hold one volume per node, '
                             f"got shape {vol.shape} and dtype {vol.dtype}")
        vol = np.asarray(vol, dtype=float)
        require_finite('atoms.arrays["vfrac"]', vol)
        if len(vol) and not vol.min() > 0:
            n = int(np.argmin(vol))
            raise ValueError(f'atoms.arrays["vfrac"] of node {n} is {vol[n]}: volumes must '
                             "be positive")
        return vol

    def _state_based_bonds(self, bonds: BondSet) -> np.ndarray:
        return bonds.per_bond("peri:state", lambda: np.isin(
            self._law_of_type[bonds.type_b], self._state_based))

    def _node_inputs(self, atoms: Atoms, bonds: BondSet, geometry: tuple, vol_n) -> tuple:
        """What every bond law of an evaluation shares: ``(spacing, extra,
        scene)``, with ``extra`` the per-bond extension, partial-volume factor
        and ``V_i V_j`` (the breaking stretch is the caller's)."""
        i_b, j_b = bonds.i_b, bonds.j_b
        r_bc, r_b, r0_b, fresh_b = geometry
        spacing = self.lattice_spacing(atoms, bonds, r0_b)
        self._check_horizon(bonds, spacing, r0_b)
        horizon_b = self.coefficients(bonds, "horizon")
        scale_b, vv_b = self._volume_factors(bonds, r0_b, horizon_b, spacing, vol_n,
                                             self._legacy, cacheable=fresh_b is None)
        dr_b = law.extension(r_b, r0_b)
        # node state taken in the reference configuration
        m_n = self._node_state(atoms, WVOLUME, lambda: self._reference_weighted_volume(
            atoms, bonds, r0_b, spacing, vol_n,
            summed=lambda: law.weighted_volume(i_b, j_b, r0_b, scale_b, vol_n)))
        theta_n = None
        if self._state_based:
            sb = self._state_based_bonds(bonds)
            theta_n = law.dilatation(i_b[sb], j_b[sb], dr_b[sb], scale_b[sb], vol_n, m_n)
        scene = law.PeriScene(vol_n=vol_n, m_n=m_n, theta_n=theta_n,
                              lambda_n=self._plastic_multipliers(atoms),
                              legacy=law.RECORDED[self._followed])
        return spacing, dict(dr=dr_b, scale=scale_b, vv=vv_b), scene

    def _reference_weighted_volume(self, atoms: Atoms, bonds: BondSet, r0_b, spacing: float,
                                   vol_n, summed) -> np.ndarray:
        """The weighted volumes ``m_n`` of the reference state: ``summed()``,
        which takes each bond's reference length ``r0`` as its ``|xi|``.

        Following the legacy styles in a periodic cell, ``|xi|`` is instead
        the distance between the two nodes' positions wrapped into the cell,
        without the minimum image, as the reference build's ``fix PERI_NEIGH``
        sums it: a bond that crosses a periodic face then counts its length
        across the whole cell, so the nodes within a horizon of a face get
        larger weighted volumes (docs/lammps.md).  The dilatation and the
        forces keep the minimum image in both styles."""
        if not (self._followed == law.LEGACY and atoms.pbc.any()):
            return summed()
        x_nc = wrap_positions(atoms.positions, atoms.cell, atoms.pbc, eps=0.0)
        xi_b = np.linalg.norm(x_nc[bonds.i_b] - x_nc[bonds.j_b], axis=1)
        scale_b = law.partial_volume(r0_b, self.coefficients(bonds, "horizon"), spacing)
        return law.weighted_volume(bonds.i_b, bonds.j_b, xi_b, scale_b, vol_n)

    def _check_horizon(self, bonds: BondSet, spacing: float, r0_b) -> None:
        """Every bond's horizon must reach the lattice spacing, and a tuple
        that the legacy ``pair_coeff`` order fits (a horizon that agrees with
        the bonds in that order, not in bpm/peri's) is refused, naming both
        orders (checked once per bond set and spacing: what holds for a set
        holds for its subsets)."""
        if not len(bonds) or bonds.cache.get("keep:peri:horizon") == spacing:
            return
        types = np.flatnonzero(np.bincount(bonds.type_b)[1:]) + 1  # the bond types present
        for t in types:
            self._check_order(t, float(np.max(r0_b[bonds.type_b == t])), spacing)
        horizon_t = self._coeff_table["horizon"]
        t = types[np.argmin(horizon_t[types])]
        if horizon_t[t] < spacing:
            raise ValueError(f"bond type {t}: horizon {horizon_t[t]} is smaller than the "
                             f"lattice spacing {spacing}")
        bonds.cache["keep:peri:horizon"] = spacing

    def _check_order(self, t: int, longest: float, spacing: float) -> None:
        """ValueError where bond type ``t``'s tuple fits the legacy order and
        not bpm/peri's (the horizon judged by :func:`law.horizon_fits`)."""
        model, values = self._laws[self._law_of_type[t]], self._bond_values[t]
        if t in self._named_types or model.legacy_order == model.coefficients:
            return  # (a mapping names each coefficient: no order to mistake)
        given = tuple(values[name] for name in model.coefficients)
        legacy = model.read_as_legacy(values)
        if (valid_in_order(model, given, model.legacy_order)
                and law.horizon_fits(legacy["horizon"], longest, spacing)
                and not law.horizon_fits(values["horizon"], longest, spacing)):
            ordered = ", ".join(repr(legacy[name]) for name in model.coefficients)
            raise ValueError(
                f"bond_coeffs for bond type {t}: ({model.name!r}, "
                f"{', '.join(map(repr, given))}) looks like a "
                f"legacy pair_coeff line: read in bpm/peri order its horizon is "
                f"{values['horizon']!r}, which disagrees with the bonds (the longest "
                f"{longest!r}) and the lattice spacing {spacing!r}, read in the legacy order "
                f"{legacy['horizon']!r}, which agrees ({model.order_note()}); give "
                f"({model.name!r}, {ordered}) or a mapping with names")

    def damped_laws(self, bonds: BondSet) -> dict:
        """No PERI law damps (said without per-bond coefficient columns,
        which every broken bond would then have to leave)."""
        return dict.fromkeys(self.law_groups(bonds), False)

    @staticmethod
    def _plastic_multipliers(atoms: Atoms) -> np.ndarray:
        """eps: each node's plastic multiplier as of the last step (0: none)."""
        stored = atoms.arrays.get(LAMBDA)
        if stored is not None and len(stored) == len(atoms):
            return np.nan_to_num(stored)
        return np.zeros(len(atoms))

    def evaluate(self, atoms: Atoms, ctx: Context) -> PeriEvaluation:
        self.ctx = ctx
        n = len(atoms)
        self._legacy = self._follow(atoms)
        vol_n = self._volumes(atoms)
        types_n = ctx.inputs.types
        bonds = self._bond_state.bonds(atoms, ctx.continues)
        i_b, j_b = bonds.i_b, bonds.j_b
        vinter_n = self._node_state(atoms, VINTER, lambda: law.node_sum(
            i_b, j_b, vol_n[j_b], vol_n[i_b], n))
        # breaking: Parks' criterion with the previous step's smallest stretch
        # (none of it without break_bonds: neither the test nor its history)
        smin_n = atoms.arrays.get(SMIN)
        if smin_n is not None and len(smin_n) != n:
            smin_n = None
        keeps_smin = self.parameters["break_bonds"] and (ctx.advancing or smin_n is None)
        if self.runs_compiled(bonds):
            return self._compiled_evaluation(atoms, bonds, types_n, vol_n, vinter_n, smin_n,
                                             keeps_smin)
        geometry = self.bond_geometry(atoms, bonds)
        spacing, extra, scene = self._node_inputs(atoms, bonds, geometry, vol_n)
        m_n, theta_n = scene.m_n, scene.theta_n
        if self.tests_breaking:
            critical_b = np.full(len(bonds), np.nan)  # no history yet: no break
            if smin_n is not None:
                smin_b = np.fmax(np.take(smin_n, i_b), np.take(smin_n, j_b))
                critical_b = (self.coefficients(bonds, "s00")
                              - self.coefficients(bonds, "alpha") * smin_b)
            extra["critical"] = critical_b
        part = self.bond_forces(atoms, bonds, geometry, extra=extra, scene=scene)
        f_nc, energy = part.f_nc, part.energy
        pair_forces = [part.virial_pairs]

        touching = None
        if self._pairs:
            touching = self._contacts(atoms, bonds, types_n, vol_n, spacing)
            f_nc = f_nc + touching.f_nc
            energy += touching.energy
            pair_forces.append((touching.r_pc, touching.f_pc))

        smin_new = None  # the history of the test in the next step
        if keeps_smin:
            smin_new = self._smallest_stretches(bonds, extra["dr"] / geometry[2], part.broken_b)
        nodes = PeriNodes(m_n=m_n, vinter_n=vinter_n, spacing=spacing, theta_n=theta_n,
                          lambda_n=part.node.get("lambda"), smin_n=smin_new)
        return PeriEvaluation(forces=f_nc, energy=energy, released_energy=part.released,
                              bonds=part, nodes=nodes,
                              contacts=touching if self._analysing else None,
                              virial=lambda: sum(virial(r, f) for r, f in pair_forces))

    def _smallest_stretches(self, bonds: BondSet, stretch_b, broken_b) -> np.ndarray:
        """Each node's smallest stretch this step, for the next step's test:
        over all its bonds (legacy), or over those that stay (bond_style
        bpm/peri: a bond that breaks now leaves none; NaN at a node with no
        bond left, which then decides no test)."""
        if self._legacy or not broken_b.any():
            return bonds.node_min(stretch_b)
        smin_n = bonds.node_min(np.where(broken_b, np.inf, stretch_b))
        smin_n[smin_n == np.inf] = np.nan
        return smin_n

    # -- the compiled route ---------------------------------------------------------------
    def _compiled_evaluation(self, atoms: Atoms, bonds: BondSet, types_n, vol_n, vinter_n,
                             smin_n, keeps_smin: bool) -> PeriEvaluation:
        """:meth:`evaluate` on the compiled route: the node pass
        (:meth:`_compiled_nodes`), each law's kernel and the contact kernel
        add their forces to one array; no per-bond arrays are made but the
        laws' history (and, when bonds break, the broken-bond mask)."""
        seed = law.PeriScene(
            vol_n=vol_n, m_n=None, theta_n=None, lambda_n=self._plastic_multipliers(atoms),
            smin_n=smin_n, smin_new_n=np.full(len(atoms), np.nan) if keeps_smin else None,
            legacy=law.RECORDED[self._followed])
        part = self.bond_forces(atoms, bonds, scene=seed)
        scene = part.nodes
        f_nc, energy, virials = part.f_nc, part.energy, [part.virial]
        if self._pairs:
            energy += self._compiled_contacts(atoms, bonds, types_n, vol_n, scene.spacing,
                                              f_nc, virials)
        smin_new = scene.smin_new_n  # (a copy on the atoms: the virial's replay notes it again)
        nodes = PeriNodes(m_n=scene.m_n, vinter_n=vinter_n, spacing=scene.spacing,
                          theta_n=scene.theta_n, lambda_n=part.node.get("lambda"),
                          smin_n=None if smin_new is None else smin_new.copy())
        return PeriEvaluation(forces=f_nc, energy=energy, released_energy=part.released,
                              bonds=part, nodes=nodes,
                              virial=lambda: sum((w() for w in virials), np.zeros((3, 3))))

    def _compiled_nodes(self, atoms: Atoms, bonds: BondSet, r0_b, box, scene):
        """The node state every law's kernel reads, from ``scene`` (volumes,
        plastic multipliers, smallest stretches): the reference lengths not
        taken yet (in ``r0_b``), the lattice spacing, the weighted volumes
        (stored, or summed at the first evaluation) and, for state-based
        models, the dilatation (a pass over the bonds before the laws')."""
        bond_rows = (bonds.i_b, bonds.j_b, bonds.type_b, r0_b, self._rows_t, atoms.positions,
                     box)
        if bonds.unset("r0") is not None:  # take them before anything needs them
            compiled.peri_nodes(*bond_rows, scene)
        spacing = self.lattice_spacing(atoms, bonds, r0_b)
        self._check_horizon(bonds, spacing, r0_b)
        scene = replace(scene, spacing=spacing)
        scene = replace(scene, m_n=self._node_state(atoms, WVOLUME, lambda: (
            self._reference_weighted_volume(
                atoms, bonds, r0_b, spacing, scene.vol_n,
                summed=lambda: compiled.peri_nodes(*bond_rows, scene, weighted=True)[0]))))
        if self._state_based:
            scene = replace(scene, theta_n=compiled.peri_nodes(*bond_rows, scene,
                                                               dilatation=True)[1])
        return scene

    def _compiled_split(self, atoms: Atoms, part, nodes) -> None:
        """pmb bonds take their own energy with them, as the kernels summed
        it; state-based energy is summed anew with the dilatation of the
        bonds that stay (as :meth:`_split_energy`)."""
        bonds = part.bonds
        if not any(self._laws[name].state_based for name in self.law_groups(bonds)):
            return
        total = part.energy + part.released
        part.energy = compiled.peri_kept_energy(
            bonds.i_b, bonds.j_b, bonds.type_b, part.r0_b, self._rows_t, atoms.positions,
            compiled.box(atoms.cell, atoms.pbc), nodes, part.broken_b)
        part.released = total - part.energy

    def _compiled_contacts(self, atoms: Atoms, bonds: BondSet, types_n, vol_n, spacing,
                           f_nc, virials: list) -> float:
        """``pair_style bpm/peri`` on the compiled route: the kernel takes the
        listed pairs not bonded now, finds those within their contact
        distance and adds their forces to ``f_nc`` in one pass; returns their
        energy and appends their virial to ``virials``."""
        nl, select = self._contact_search(spacing).listed(atoms, bonds)
        totals_t = np.zeros(TOTALS)
        compiled.peri_contacts(nl.i_p, nl.j_p, nl.shift_pc, select, types_n,
                               self._pair_table.rows(types_n), atoms.positions, vol_n,
                               CONTACT_REACH * spacing,
                               self._listed_reach(nl, select, bonds, spacing), self._legacy,
                               atoms.pbc.any(), f_nc, totals_t)
        virials.append(lambda: totals_virial(totals_t))
        return float(totals_t[TOTAL_ENERGY])

    def _listed_reach(self, nl, select, bonds: BondSet, spacing) -> Optional[np.ndarray]:
        """The contact distance of the listed pairs ``select`` where some
        are the two nodes of a broken bond (None: none is, all reach 1.35
        spacings); kept while the list and the bonds stay."""
        key = (nl.nbuilds, bonds.serial, spacing)
        if self._reach_of is None or self._reach_of[0] != key:
            reach_p = None
            if np.any(bonds.table.type_b == 0):
                reach_p = self._contact_reach(bonds, nl.i_p[select], nl.j_p[select], spacing)
            self._reach_of = (key, reach_p)
        return self._reach_of[1]


    @staticmethod
    def _volume_factors(bonds: BondSet, r0_b, horizon_b, spacing, vol_n, legacy: bool,
                        cacheable):
        """Partial-volume factors and volume factors (:func:`law.volume_product`)
        of the bonds (cached while the reference lengths, spacing, volumes
        and the LAMMPS followed stay)."""
        key = bonds.cache.get("keep:volumes")
        if (cacheable and key is not None and key[0] == (spacing, legacy)
                and same_array(key[1], vol_n)):
            return bonds.cache["bond:peri:scale"], bonds.cache["bond:peri:vv"]
        scale_b = law.partial_volume(r0_b, horizon_b, spacing)
        vv_b = law.volume_product(np.take(vol_n, bonds.i_b), np.take(vol_n, bonds.j_b), legacy)
        if cacheable:
            bonds.cache["keep:volumes"] = ((spacing, legacy), vol_n.copy())
            bonds.cache["bond:peri:scale"], bonds.cache["bond:peri:vv"] = scale_b, vv_b
        return scale_b, vv_b

    def _split_energy(self, atoms, bonds, broken_b, geometry, energy_b, energy, extra, scene):
        """Elastic energy once the ``broken_b`` bonds are gone: pmb bonds take
        their own energy with them; state-based energy is recomputed with the
        dilatation of the remaining bonds."""
        total = energy + float(energy_b.sum())
        i_b, j_b = bonds.i_b, bonds.j_b
        dr_b, scale_b, vv_b, r0_b = extra["dr"], extra["scale"], extra["vv"], geometry[2]
        pmb = self._law_of_type[bonds.type_b] == "pmb"

        def pmb_energy(mask_b) -> float:  # each pmb bond's energy is its own
            return float(np.sum(0.5 * law.pmb(dr_b[mask_b], r0_b[mask_b],
                                              self.coefficients(bonds, "c")[mask_b],
                                              scale_b[mask_b], vv_b[mask_b]).fi_b
                                * dr_b[mask_b]))

        if pmb.all():  # only the broken bonds' energy is computed
            released = pmb_energy(broken_b)
            return total - released, released
        kept = pmb_energy(pmb & ~broken_b) if pmb.any() else 0.0
        state = ~pmb & ~broken_b
        if state.any():
            theta_n = law.dilatation(i_b[state], j_b[state], dr_b[state], scale_b[state],
                                     scene.vol_n, scene.m_n)
            kept += law.lps(i_b[state], j_b[state], dr_b[state], r0_b[state],
                            self.coefficients(bonds, "K")[state],
                            self.coefficients(bonds, "G")[state], scale_b[state],
                            vv_b[state], theta_n, scene.m_n, scene.vol_n).energy
        return kept, total - kept

    def _node_state(self, atoms: Atoms, name: str, compute) -> np.ndarray:
        """Per-node reference state: stored, or computed where missing."""
        stored = atoms.arrays.get(name)
        if stored is not None and len(stored) == len(atoms) and not np.isnan(stored).any():
            return stored
        fresh = compute()
        if stored is None or len(stored) != len(atoms):
            return fresh
        return np.where(np.isnan(stored), fresh, stored)

    def _contact_search(self, spacing) -> ContactList:
        """The contact list of the run (made at its first use)."""
        if self._contact_list is None:
            skin = 0.3 * spacing if self.parameters["skin"] is None else self.parameters["skin"]
            self._contact_list = ContactList(CONTACT_REACH * spacing, float(skin))
        return self._contact_list

    def _contacts(self, atoms, bonds: BondSet, types_n, vol_n, spacing):
        """``pair_style bpm/peri`` between nodes not bonded now."""
        pair_table = self._pair_table(types_n)  # every pair of types present needs one
        i_p, j_p, r_pc, extra = self._contact_candidates(atoms, bonds, vol_n, spacing,
                                                         self._contact_search(spacing),
                                                         self._legacy)
        return contact_forces(self.PAIR_LAW, i_p, j_p, r_pc, types_n, pair_table, len(atoms),
                              extra=extra)

    @classmethod
    def _contact_candidates(cls, atoms, bonds: BondSet, vol_n, spacing, search: ContactList,
                            legacy: bool):
        """``(i_p, j_p, r_pc, extra)``: the pairs not bonded now within reach of
        ``search``, with their contact distance ``d`` (:meth:`_contact_reach`)
        and volume factor (:func:`law.volume_product`) in ``extra``."""
        i_p, j_p, r_pc = search.pairs(atoms, bonds)
        d_p = cls._contact_reach(bonds, i_p, j_p, spacing)
        return i_p, j_p, r_pc, dict(d=d_p, vv=law.volume_product(vol_n[i_p], vol_n[j_p], legacy))

    @staticmethod
    def _contact_reach(bonds: BondSet, i_p, j_p, spacing) -> np.ndarray:
        """The contact distance of the pairs: 1.35 spacings, or ``min(0.9 r0,
        1.35 spacings)`` for the two nodes of a broken bond, following either
        LAMMPS: legacy's rule, which pair_style bpm/peri means to keep (its
        source takes 1.35 spacings as legacy's distance for pairs beyond the
        horizon) and misses for the pairs of broken bonds, inside it; there
        1.35 spacings would push two nodes a spacing apart with some 3,500
        times the force that broke their bond (docs/lammps.md)."""
        n = bonds.natoms
        d_p = np.full(len(i_p), CONTACT_REACH * spacing)
        table = bonds.table
        gone = table.type_b == 0
        if gone.any():  # broken bonds: contact from min(0.9 r0, 1.35 spacings)
            broken_keys = pair_keys(table.owner_b[gone], table.partner_b[gone], n)
            order = np.argsort(broken_keys)
            keys_p = pair_keys(i_p, j_p, n)
            pos = np.minimum(np.searchsorted(broken_keys[order], keys_p), len(order) - 1)
            hit = broken_keys[order][pos] == keys_p
            r0_gone = bonds.state["r0"][gone][order][pos]
            d_p = np.where(hit & ~np.isnan(r0_gone), np.minimum(BROKEN_CONTACT * r0_gone, d_p),
                           d_p)
        return d_p

    # -- the stable timestep -------------------------------------------------------------
    def springs(self, atoms: Atoms, ctx: Context) -> list:
        """The bonds (with each node's dilatation coupling for the state-based
        models) and the pairs in contact now (found afresh)."""
        vol_n = self._volumes(atoms)
        self._legacy = self._follow(atoms)
        bonds = self._bond_state.aside(atoms)
        if not len(bonds) and not self._pairs:
            return []
        geometry = self.bond_geometry(atoms, bonds)
        spacing, extra, scene = self._node_inputs(atoms, bonds, geometry, vol_n)
        if self._state_based:
            sb = self._state_based_bonds(bonds)
            weight_n = law.dilatation(bonds.i_b[sb], bonds.j_b[sb], np.ones(int(sb.sum())),
                                      extra["scale"][sb], vol_n, scene.m_n)
            scene = replace(scene, dilatation_weight_n=weight_n)
        springs = [self.bond_springs(bonds, geometry, extra, scene)]
        if self._pairs:
            types_n = ctx.inputs.types
            search = ContactList(CONTACT_REACH * spacing, 0.0)
            i_p, j_p, r_pc, pair_extra = self._contact_candidates(atoms, bonds, vol_n, spacing,
                                                                  search, self._legacy)
            springs.append(contact_springs(self.PAIR_LAW, i_p, j_p, r_pc, types_n,
                                           self._pair_table(types_n), pair_extra))
        return springs

    # -- commit --------------------------------------------------------------------------
    def commit(self, atoms: Atoms, ev: PeriEvaluation, ctx: Context) -> None:
        nodes = ev.nodes
        if self.parameters["lattice_spacing"] is None:
            atoms.info[SPACING] = nodes.spacing
        atoms.info[FOLLOWED] = self._followed
        atoms.arrays[WVOLUME] = nodes.m_n
        atoms.arrays[VINTER] = nodes.vinter_n
        for name, values in ((SMIN, nodes.smin_n), (LAMBDA, nodes.lambda_n),
                             (DILATATION, nodes.theta_n)):
            if values is not None:
                atoms.arrays[name] = values
        if not self.parameters["break_bonds"]:  # no test, no history for one
            atoms.arrays.pop(SMIN, None)
        super().commit(atoms, ev, ctx)

    def write_counts(self, atoms: Atoms, bonds: BondSet, broken_ends=None) -> None:
        """``nbonds``, and ``damage`` as the lost share of each node's
        interaction volume: ``1 - sum_intact V_j / sum_initial V_j``."""
        write_bond_counts(atoms, bonds, broken_ends)
        n, vol_n, vinter_n = len(atoms), atoms.arrays["vfrac"], atoms.arrays[VINTER]
        last = self._intact_volumes  # (bond set, volumes, intact volume per node)
        if (broken_ends is not None and last is not None and last[0] == bonds.parent
                and same_array(last[1], vol_n)):  # those of the set before, less the broken
            i_k, j_k = broken_ends
            intact_n = last[2] - law.node_sum(i_k, j_k, vol_n[j_k], vol_n[i_k], n)
        else:
            intact_n = law.node_sum(bonds.i_b, bonds.j_b, vol_n[bonds.j_b], vol_n[bonds.i_b], n)
        self._intact_volumes = (bonds.serial, np.array(vol_n), intact_n)
        atoms.arrays[DAMAGE] = np.divide(vinter_n - intact_n, vinter_n,
                                           out=np.zeros(len(atoms)), where=vinter_n > 0)

    # -- analysis -------------------------------------------------------------------
    def analyse(self, atoms: Atoms) -> Analysis:
        """The bonds' forces (as ``compute bond/local`` would give them: the
        mean of the forces on the two nodes, LAMMPS' sign), the contacts
        (``pair/local``) and the per-atom stress (``compute stress/atom``:
        each node half the virial of its own force in each of its bonds and
        contacts; the kinetic part with the nodes' masses, where legacy PERI
        uses the density it keeps as a mass) at the atoms' state, on the
        NumPy laws, changing nothing: a twin model evaluates a copy of
        the atoms (history read, not advanced; no breaking tested, inside
        :func:`ase_bpm.pure` too), with the bonds they have now, as a LAMMPS
        ``run 0`` after the step would (after a step in which bonds broke
        that differs from the step's own stress, which bonds acting while
        they broke took part in).  It holds the per-bond arrays of the NumPy
        laws for a moment (some 0.4 kB a bond).  The dilatation and the
        damage are per-atom outputs of every evaluation (``atoms.arrays``)."""
        copy = atoms.copy()
        twin = type(self)()
        twin.setup({**self.parameters, "kernels": "numpy"})
        inputs = Inputs(copy)
        twin._analysing = True
        # (a setup evaluation: advancing False, nothing breaks)
        ev = twin.evaluate(copy, twin.analysis_context(copy, inputs))
        part = ev.bonds
        r_bc, f_bc = part.virial_pairs  # (the mean of the forces on i and on -j)
        bonds = bond_local(part.bonds, r_bc, f_bc, part.r0_b)
        # each node's own force: the state-based laws push the two unequally
        f_b, fj_b = part.magnitudes
        unit_bc = r_bc / bonds.length_b[:, None]
        w_n6 = np.zeros((len(atoms), 6))
        add_pair_virials(w_n6, bonds.i_b, bonds.j_b, r_bc, unit_bc * f_b[:, None],
                         None if fj_b is None else -unit_bc * fj_b[:, None])
        pairs = None
        if ev.contacts is not None:
            c = ev.contacts
            pairs = pair_local(c)
            add_pair_virials(w_n6, c.i_p, c.j_p, c.r_pc, c.f_pc)
        return Analysis(bonds, pairs,
                        stress_per_atom(inputs.masses, inputs.velocities, w_n6))


class BPMPeri(BondedCalculator):
    """Peridynamic solids as bonds: LAMMPS ``bond_style bpm/peri`` +
    ``pair_style bpm/peri``, with the force laws of the legacy ``peri/pmb``,
    ``peri/lps``, ``peri/ves`` and ``peri/eps`` styles.

    Nodes carry their volume in ``atoms.arrays["vfrac"]``; masses are true
    masses (density times volume) and forces true forces, so accelerations
    equal those of LAMMPS' PERI styles.  Bonds (integer arrays on the atoms, :mod:`ase_bpm.core.bonds`,
    usually from ``create_bonds(atoms, horizon)``) take their reference length
    at their first evaluation.  Units are the caller's (SI in the examples).

    Parameters
    ----------
    follows:
        Which LAMMPS the calculator follows where the two differ
        (docs/lammps.md lists each difference): ``"bpm/peri"``
        (``bond_style bpm/peri`` + ``pair_style bpm/peri``, LAMMPS 2026: a
        bond that breaks gives no force in that step and leaves no smallest
        stretch, volume factor ``((V_i + V_j)/2)^2``, ves and eps per bond)
        or ``"legacy"`` (the ``peri/*`` pair styles of released LAMMPS, as
        the reference build of 22 Jul 2025 has them: a bond acts in the step
        it breaks, ``V_i V_j``, ves and eps per bond end, eps with that
        build's defects).  Default (None): what
        the atoms record (``atoms.info["peri_follows"]``, written at every
        step); for atoms with PERI state of a run before this option
        existed, what that run computed (the legacy styles, eps returned
        radially at each bond end: a restart file keeps its behaviour);
        else ``"bpm/peri"``.
    bond_coeffs:
        ``{bond_type: model}``, each model a tuple in the order of the
        ``bond_coeff`` line of LAMMPS ``bond_style bpm/peri``:
        ``("pmb", c, horizon, s00, alpha)``,
        ``("lps", K, G, horizon, s00, alpha)``,
        ``("ves", K, G, lambda, tau, horizon, s00, alpha)`` or
        ``("eps", K, G, yield_stress, horizon, s00, alpha)`` (the legacy
        ``pair_coeff`` lines of ``peri/ves`` and ``peri/eps`` put the horizon
        third: such a tuple, whose horizon then disagrees with the bonds and
        the lattice spacing, raises ValueError naming both orders), or a
        mapping from those names, ``{"model": "lps", "K": ..., "G": ...,
        "horizon": ..., "s00": ..., "alpha": ...}``.  ``c`` is the
        micromodulus (energy/length^6, ``18 K / (pi horizon^4)`` for bulk
        modulus K), K and G the bulk and shear moduli (pressure), lambda the
        viscous fraction (0 to 1), tau the relaxation time, s00 and alpha the
        breaking parameters: a bond breaks when its stretch exceeds
        ``s00 - alpha * s_min`` (Parks et al. 2008), ``s_min`` the most
        compressive stretch of either node's bonds on the previous step.
    pair_coeffs:
        ``{(type_i, type_j): (k, horizon)}`` in the order of the
        ``pair_coeff`` line of ``pair_style bpm/peri`` (or the mapping
        ``{"k": ..., "horizon": ...}``): nodes
        that are not bonded repel when closer than ``d``,
        ``15 k v (d - r) / horizon`` with the volume factor ``v`` of the
        bonds; ``d = 1.35`` lattice spacings, or ``min(0.9 r0, 1.35
        spacings)`` for the two nodes of a broken bond (legacy's rule, kept
        following bpm/peri too: see :meth:`_contact_reach`).
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
        External force pieces, e.g. :class:`ase_bpm.SphericalIndenter`.
    skin:
        Verlet skin of the contact neighbour list (default 0.3 lattice
        spacings).
    break_bonds:
        Bonds break by Parks' criterion (default).  ``False``, which the
        LAMMPS PERI styles do not offer, computes neither the criterion nor
        its history (``peri_smin``, dropped from the atoms): every bond keeps
        acting however far it stretches.  Switched back on, breaking starts
        without history: nothing breaks in the first step.
    store_local:
        Log every broken bond in ``atoms.info["broken_bonds"]``, as
        :class:`~ase_bpm.BPMSpring` does.
    kernels:
        ``"auto"`` (compiled where built), ``"compiled"`` or ``"numpy"``: the
        route of the bond and contact kernels (:func:`ase_bpm.laws.kernel_route`);
        both give the same forces, energies, history and broken bonds to
        round-off.
        ``calc.kernel_route`` names the route resolved, ``calc.kernel_routes``
        what runs on it, per law: the bond laws' names, and ``"contacts"``
        where ``pair_coeffs`` are given, each ``"compiled"`` or ``"numpy"``
        (e.g. ``{"lps": "compiled", "contacts": "compiled"}``: the laws run
        in one compiled pass over the bonds, so a law without a compiled twin
        puts them all, the contacts included, on NumPy).

    Results: ``energy`` (elastic energy; for pmb and lps the potential of the
    forces, for ves and eps the recoverable part), ``forces``, ``stress``
    (periodic cells).  Per-atom outputs in ``atoms.arrays``
    (``calc.per_atom_outputs``): ``damage`` (``1 - sum_intact V_j /
    sum_initial V_j``), ``nbonds`` and, with a state-based model among the
    bond types, ``dilatation``.  Broken bonds are logged in
    ``atoms.info["broken_bonds"]`` as by :class:`~ase_bpm.BPMSpring`.

    Forces are true forces on true masses whichever LAMMPS is followed:
    the LAMMPS force densities (legacy: ``V_j`` times the law on node i;
    bond_style bpm/peri: the mean volume times it, which its example decks
    apply to true masses as if a force) times a second volume.  On equal
    volumes below breaking both options give the same accelerations as the
    legacy styles.
    """

    name = "bpm_peri"
    #: the model this calculator holds (``calc.model``)
    model_class = PeriModel
    default_parameters = dict(bond_coeffs={}, pair_coeffs={}, lattice_spacing=None,
                              timestep=None, skin=None, break_bonds=True, store_local=True,
                              kernels="auto", follows=None)
    def __init__(self, bond_coeffs: Mapping[int, tuple] = None,
                 pair_coeffs: Mapping[tuple, tuple] = None,
                 lattice_spacing: float | None = None, timestep: float | None = None,
                 skin: float | None = None, break_bonds: bool = True,
                 store_local: bool = True, kernels: str = "auto", fixes=(),
                 follows: str | None = None, **kwargs):
        self.model = self.model_class()
        super().__init__(fixes=fixes, bond_coeffs=dict(bond_coeffs or {}),
                         pair_coeffs=dict(pair_coeffs or {}), lattice_spacing=lattice_spacing,
                         timestep=timestep, skin=skin, break_bonds=break_bonds,
                         store_local=store_local, kernels=kernels, follows=follows, **kwargs)

    def followed(self, atoms: Atoms) -> str:
        """What this calculator follows on ``atoms`` (:meth:`PeriModel.followed`):
        ``follows`` where given, else what the atoms record, else
        ``"bpm/peri"`` (the legacy styles for atoms with PERI state from
        before the option)."""
        return self.model.followed(atoms)
