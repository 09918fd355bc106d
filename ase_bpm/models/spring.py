"""BPMSpring: LAMMPS ``bond_style bpm/spring`` with ``pair_style bpm/spring``
(the model, :class:`SpringModel`, and its calculator, :class:`BPMSpring`)."""

from __future__ import annotations

from typing import Mapping, Optional

import numpy as np
from ase import Atoms

from ..core.arrays import Inputs
from ..core.params import check_coeffs, check_type, coeff_tuple, type_pair
from ..laws import COMPILED, CONTACTS, compiled
from ..laws.bond import TOTAL_ENERGY, TOTALS, totals_virial
from ..laws.contact import PairTable, arithmetic, contact_forces, contact_springs, geometric
from ..laws.rotational import REFERENCE_DIRECTION  # (and registers bpm/rotational)
from ..laws.spring import (VOLUME_FACTOR, VOLUME_RATIO, AnharmonicSpringPair, BondVolumes,
                           SpringBond, SpringPair, SpringPlasticBond, contact_energy,
                           volume_ratios)
from ..laws.timestep import SpringPieces
from .analysis import Analysis, add_pair_virials, bond_local, pair_local, stress_per_atom
from .base import digest, virial
from .bonded import PLAN, BondedCalculator, BondedEvaluation, BondedModel, ContactList
from .evaluation import Context
from .granular import Granular, GranularModel
from .outputs import NCONTACTS

#: bonds per piece of the stable-timestep estimate: the per-bond arrays of the
#: bonds' geometry and stiffness are made for one piece at a time, and each
#: piece's springs are summed into the per-node blocks and dropped before the
#: next piece is made (at a million particles, all at once, they took 0.9 GB
#: for a moment; made in pieces but kept until the sum, 0.3 GB)
ESTIMATE_PIECE = 2 ** 18


class SpringModel(BondedModel):
    """The model of :class:`BPMSpring`: bonds of the registered bond laws
    (``bpm/spring`` by default) and the ``pair_style bpm/spring`` contacts
    between particles not bonded."""

    label = "BPMSpring"
    default_law = "bpm/spring"
    law_options = ("smooth", "normalize")
    PAIR_LAW = SpringPair()  # pair_style bpm/spring
    _granular = None  # the granular contacts' model, where given (pair_style gran/*)
    ANHARMONIC_PAIR_LAW = AnharmonicSpringPair()  # pair_style bpm/spring anharmonic yes
    #: volume/factor's a_v by bond type (NaN: a type it does not act on);
    #: None: no volume/factor
    _volume_t = None

    # -- coefficients ------------------------------------------------------------
    def setup(self, parameters) -> str:
        """Check the parameters and build the coefficient tables."""
        self.parameters = p = parameters
        if p["smooth"] and not p["break_bonds"]:
            raise ValueError("smooth=True needs break_bonds=True: beyond eps_c the smoothing "
                             "factor turns negative (LAMMPS: must turn off smoothing with "
                             "break no)")
        if p["mix"] not in ("geometric", "arithmetic"):
            raise ValueError(f'mix must be "geometric" or "arithmetic", got {p["mix"]!r}')
        if not isinstance(p["anharmonic"], (bool, np.bool_)):
            raise ValueError(f"anharmonic must be True or False, got {p['anharmonic']!r}")
        # (an instance attribute: the class's own is the plain law)
        self.PAIR_LAW = self.ANHARMONIC_PAIR_LAW if p["anharmonic"] else SpringModel.PAIR_LAW
        self._setup_bonds()
        self._setup_volume_factor(p["volume_factor"])
        pairs = {}
        for key, values in p["pair_coeffs"].items():
            ti, tj = type_pair("pair_coeffs", key)
            law = self.PAIR_LAW
            values = coeff_tuple("pair_coeffs for types", (ti, tj), values, law.coefficients)
            pairs[ti, tj] = check_coeffs("pair_coeffs for types", (ti, tj), values,
                                         law.coefficients, law.positive, law.non_negative)
        rule = geometric if p["mix"] == "geometric" else arithmetic

        def mix(a, b):  # k and gamma geometric, r_c by the rule (LAMMPS pair_modify mix)
            return geometric(a[0], b[0]), rule(a[1], b[1]), geometric(a[2], b[2])

        self._pair_coeffs = pairs
        # (anharmonic: the reference build mixes no k_a, so nothing is mixed)
        self.pair_coefficients = PairTable(pairs, self.PAIR_LAW.coefficients,
                                           None if p["anharmonic"] else mix)
        at_gamma = self.PAIR_LAW.coefficients.index("gamma")
        self._pair_damped = any(values[at_gamma] > 0 for values in pairs.values())
        granular = self._setup_granular(p)
        self.forget()
        # (the options only where on: the signatures of scenes without them,
        # restart files' included, stay what they were)
        options = (("anharmonic",) if p["anharmonic"] else ()) + (
            () if self._volume_t is None else (("volume_factor", self._volume_t.tolist()),))
        return digest(self.label, sorted(self._bond_values.items()), self._law_of_type.tolist(),
                      sorted(pairs.items()), p["mix"], p["smooth"], p["normalize"],
                      p["break_bonds"], p["overlay_pair"], *options, *granular)

    def _setup_granular(self, p) -> tuple:
        """The granular contacts (``pair_style gran/*``) of ``p["granular"]``,
        a model of their own whose pairs leave the bonded ones out
        (:meth:`_unbonded_rows`); returns what the digest takes of them."""
        given = p.get("granular")
        self._granular = None
        if given is None:
            return ()
        if not isinstance(given, Mapping):
            raise ValueError("BPMSpring: granular must be a mapping of Granular's parameters "
                             "(model, kn, gamma_n, xmu, ...), got "
                             f"{type(given).__name__}")
        if p["pair_coeffs"] or p["anharmonic"]:
            raise ValueError("BPMSpring: pair_coeffs or anharmonic (pair_style bpm/spring) "
                             "and granular (pair_style gran/*) both given: a scene has one "
                             "pair style")
        own = Granular.default_parameters
        unknown = sorted(set(given) - set(own) - {"kernels", "timestep"})
        if unknown or "kernels" in given or "timestep" in given:
            raise ValueError(f"BPMSpring: granular takes {', '.join(sorted(own))} but the "
                             "kernels and the timestep (BPMSpring's own), got "
                             f"{', '.join(unknown or [k for k in given if k in own])}")
        model = self._granular = GranularModel()
        granular_digest = model.setup({**own, **given, "kernels": p["kernels"],
                                       "timestep": p["timestep"]})
        model.exclude = self._unbonded_rows
        self.own_torques = self.own_torques or model.own_torques
        self.needs_timestep = self.needs_timestep or model.needs_timestep
        self.watched_arrays = self.watched_arrays + model.watched_arrays
        self.per_atom_outputs = type(self).per_atom_outputs + (NCONTACTS,)
        self.kernel_routes = {**self.kernel_routes, **model.kernel_routes}
        return (granular_digest,)

    def _unbonded_rows(self, search) -> tuple:
        """The rows of the granular search's list that may touch (not joined
        by an intact bond, unless ``overlay_pair``), and a key that changes
        with them (``GranularModel.exclude``)."""
        bonds, rows = self._bonds_now, self._granular_rows
        if rows is None or rows.neighbours is not search:
            rows = self._granular_rows = ContactList(0.0, 0.0, self.parameters["overlay_pair"],
                                                     neighbours=search)
        return rows.rows(bonds.natoms, bonds), (search.nbuilds, bonds.serial)

    def _setup_volume_factor(self, given) -> None:
        """``volume_factor`` (LAMMPS ``volume/factor yes`` with ``a_v`` the
        last ``bond_coeff`` value) into :attr:`_volume_t`: None (off), one
        ``a_v`` (force) for every ``bpm/spring`` bond type, or ``{bond_type:
        a_v}`` naming each of them (and no type of another law)."""
        self._volume_t = self._compiled_nodes = None
        if given is None:
            return
        spring_types = [t for t in sorted(self._bond_values)
                        if self._law_of_type[t] == SpringBond.name]
        if isinstance(given, (bool, np.bool_)) or not (
                isinstance(given, Mapping) or np.isscalar(given)):
            raise ValueError(f"volume_factor takes a_v (force): one number for every "
                             f"bpm/spring bond type, or {{bond_type: a_v}}; got {given!r}")
        if not spring_types:
            raise ValueError("volume_factor is a keyword of bond_style bpm/spring, and no "
                             "bond type of bond_coeffs follows bpm/spring")
        if isinstance(given, Mapping):
            values = {check_type("volume_factor", t): v for t, v in given.items()}
            for t in sorted(values):
                if t not in self._bond_values:
                    raise ValueError(f"volume_factor for bond type {t}: bond_coeffs has no "
                                     "entry for it")
                if t not in spring_types:
                    raise ValueError(f"volume_factor for bond type {t}: its law is "
                                     f"{self._law_of_type[t]!r}, and volume/factor is a "
                                     "keyword of bond_style bpm/spring only")
            missing = [t for t in spring_types if t not in values]
            if missing:
                raise ValueError(f"volume_factor gives no a_v for bond type(s) "
                                 f"{', '.join(map(str, missing))} (bpm/spring): give each "
                                 "one, or one number for all")
        else:
            values = dict.fromkeys(spring_types, given)
        table = np.full(len(self._law_of_type), np.nan)
        for t, value in values.items():
            table[t], = check_coeffs("volume_factor for bond type", t, (value,),
                                     (VOLUME_FACTOR,))
        self._volume_t = table
        self._compiled_nodes = self._bond_volumes  # (the volumes, before the laws)

    def _bond_volumes(self, atoms: Atoms, bonds, r0_b, box, scene) -> BondVolumes:
        """``volume/factor`` on the compiled route: the atoms' volumes over
        the intact bonds, for the laws (``BondScene.nodes``)."""
        return BondVolumes(self._volume_t, *compiled.bond_volumes(
            bonds.i_b, bonds.j_b, bonds.type_b, atoms.positions, box, r0_b))

    def _volume_extra(self, atoms: Atoms, bonds, geometry: tuple) -> Optional[dict]:
        """``volume/factor``'s per-bond data for the laws (``BondInput.extra``):
        ``a_v`` and the volume ratio of the two atoms of each bond, over the
        bonds intact at this evaluation (those breaking now included, as in
        LAMMPS, whose reference volumes lose a bond after the step it breaks
        in); None without volume/factor."""
        if self._volume_t is None:
            return None
        _, r_b, r0_b, _ = geometry
        intact = bonds.type_b > 0
        ratio_b = np.ones(len(r_b))
        ratio_b[intact] = volume_ratios(bonds.i_b[intact], bonds.j_b[intact], r_b[intact],
                                        r0_b[intact], len(atoms))
        return {VOLUME_FACTOR: self._volume_t[bonds.type_b], VOLUME_RATIO: ratio_b}

    def forget(self) -> None:
        super().forget()
        self._contacts = None
        if self._granular is not None:
            self._granular.forget()
            #: the granular pairs' selection (its neighbours: the granular search)
            self._granular_rows = None  # made with the granular search it selects from
            self._bonds_now = None  # the bond set of the evaluation under way
        if self._pair_coeffs:
            at_rc = self.PAIR_LAW.coefficients.index("r_c")
            max_rc = max(values[at_rc] for values in self._pair_coeffs.values())
            skin = 0.3 * max_rc if self.parameters["skin"] is None else self.parameters["skin"]
            self._contacts = ContactList(max_rc, float(skin), self.parameters["overlay_pair"])

    def _handed_over(self, atoms, bonds, broken_b, r_kc) -> float:
        """Broken bonds hand their pairs to the pair law: where the two particles
        overlap, that contact energy appears (not with overlay_pair, where the
        pair law acted all along)."""
        if self._contacts is None or self.parameters["overlay_pair"]:
            return 0.0
        types_n = self.ctx.inputs.types
        tables = self.pair_coefficients(types_n)
        ti_k = np.take(types_n, bonds.i_b[broken_b])
        tj_k = np.take(types_n, bonds.j_b[broken_b])
        coeff = {name: tables[c][ti_k, tj_k] for c, name in enumerate(self.PAIR_LAW.coefficients)}
        rc_k = coeff["r_c"]
        touch = np.einsum("kc,kc->k", r_kc, r_kc) < rc_k * rc_k
        if not touch.any():
            return 0.0
        return float(contact_energy(self.PAIR_LAW, r_kc[touch],
                                    {name: values[touch] for name, values in coeff.items()}
                                    ).sum())

    # -- evaluation ------------------------------------------------------------------
    def evaluate(self, atoms: Atoms, ctx: Context) -> BondedEvaluation:
        self.ctx = ctx
        n = len(atoms)
        types_n = ctx.inputs.types
        bonds = self._bond_state.bonds(atoms, ctx.continues)
        plan = bonds.cache.get(PLAN) or self.plan(bonds)
        contacts = self._contacts is not None
        damped = plan.damped or (self._pair_damped and contacts)
        v_nc = ctx.inputs.velocities if damped else None

        if self._volume_t is not None and not any(  # (NumPy: the data need the geometry)
                group.law.name == SpringBond.name for group in plan.twins):
            geometry = self.bond_geometry(atoms, bonds)
            part = self.bond_forces(atoms, bonds, geometry, v_nc=v_nc,
                                    extra=self._volume_extra(atoms, bonds, geometry))
        elif plan.compiled:
            part = self._compiled_bond_forces(atoms, bonds, v_nc)
        else:
            part = self.bond_forces(atoms, bonds, v_nc=v_nc)
        f_nc = part.f_nc  # a new array: contacts add to it
        fd_nc = part.fd_nc if part.fd_nc is not None or not damped else np.zeros((n, 3))
        energy, released = part.energy, part.released
        virials = [part.virial]  # of bonds and contacts

        if contacts and self.kernel_routes[CONTACTS] == COMPILED:
            energy += self._compiled_contacts(atoms, bonds, types_n, v_nc, f_nc, fd_nc,
                                              virials)
        elif contacts:
            i_p, j_p, r_pc = self._contacts.pairs(atoms, bonds)
            res = contact_forces(self.PAIR_LAW, i_p, j_p, r_pc, types_n,
                                 self.pair_coefficients(types_n), n, v_nc)
            f_nc += res.f_nc
            if res.fd_nc is not None:
                fd_nc += res.fd_nc
            energy += res.energy
            virials.append(lambda: virial(res.r_pc, res.f_pc))

        t_nc, td_nc, granular = part.t_nc, part.td_nc, None
        if t_nc is not None and td_nc is None:
            td_nc = np.zeros((n, 3))
        if self._granular is not None:
            self._bonds_now = bonds
            granular = self._granular.evaluate(atoms, ctx)
            f_nc += granular.forces
            energy += granular.energy
            if granular.f_damp is not None:
                fd_nc = granular.f_damp if fd_nc is None else fd_nc + granular.f_damp
            if granular.torques is not None:  # (all dissipative: friction)
                t_nc = granular.torques if t_nc is None else t_nc + granular.torques
                td_nc = None if td_nc is None else td_nc + granular.torques
            w_cc = granular.virial  # (an array, a function giving it, or None)
            if w_cc is not None:
                virials.append(w_cc if callable(w_cc) else lambda: w_cc)
        return BondedEvaluation(forces=f_nc, energy=energy, f_damp=fd_nc,
                                virial=lambda: sum((w() for w in virials), np.zeros((3, 3))),
                                released_energy=released, bonds=part, torques=t_nc,
                                t_damp=td_nc, granular=granular)

    def commit(self, atoms: Atoms, ev: BondedEvaluation, ctx: Context) -> None:
        super().commit(atoms, ev, ctx)
        if ev.granular is not None:
            self._granular.commit(atoms, ev.granular, ctx)
            ev.kept_state = ev.kept_state and ev.granular.kept_state

    def signature_parts(self, atoms: Atoms, evaluation) -> tuple:
        parts = super().signature_parts(atoms, evaluation)
        if self._granular is None:
            return parts
        return parts + self._granular.signature_parts(
            atoms, None if evaluation is None else evaluation.granular)

    def _compiled_contacts(self, atoms: Atoms, bonds, types_n, v_nc, f_nc, fd_nc,
                           virials: list) -> float:
        """The pair law on the compiled route: the kernel takes the listed
        pairs that are not bonded, finds those closer than ``r_c`` and adds
        their forces to ``f_nc`` (damping part to ``fd_nc``) in one pass;
        returns their energy and appends their virial to ``virials``."""
        contacts = self._contacts
        nl, select = contacts.listed(atoms, bonds)
        prepared_for, kernel = contacts.prepared
        if prepared_for is not select:  # the list was built anew, or bonds broke
            kernel = compiled.SpringPairs(nl.i_p, nl.j_p, nl.shift_pc, select)
            contacts.prepared = (select, kernel)
        totals_t = np.zeros(TOTALS)
        kernel(types_n, self.pair_coefficients.rows(types_n), atoms.positions,
               v_nc if self._pair_damped else None, atoms.pbc.any(), f_nc, fd_nc, totals_t)
        virials.append(lambda: totals_virial(totals_t))
        return float(totals_t[TOTAL_ENERGY])

    def springs(self, atoms: Atoms, ctx: Context) -> list:
        """The bonds, in pieces made as the estimate sums them, and the pairs
        touching now (found afresh: the contact list of the run is left as it
        is)."""
        bonds = self._bond_state.aside(atoms)

        def bond_pieces():
            for piece in bonds.pieces(ESTIMATE_PIECE):
                extra = (None if self._volume_t is None
                         else {VOLUME_FACTOR: self._volume_t[piece.type_b]})
                yield self.bond_springs(piece, self.bond_geometry(atoms, piece), extra)

        springs = [SpringPieces(bond_pieces, len(bonds), turning=self.turns)]
        if self._granular is not None:  # (bonded pairs that overlap too: an upper bound)
            springs += self._granular.springs(atoms, ctx)
        if self._contacts is not None:
            search = ContactList(self._contacts.neighbours.cutoff, 0.0, self._contacts.overlay)
            i_p, j_p, r_pc = search.pairs(atoms, bonds)
            types_n = ctx.inputs.types
            springs.append(contact_springs(self.PAIR_LAW, i_p, j_p, r_pc, types_n,
                                           self.pair_coefficients(types_n)))
        return springs

    # -- analysis -------------------------------------------------------------------
    def analyse(self, atoms: Atoms) -> Analysis:
        """LAMMPS' ``compute bond/local``, ``pair/local`` and ``stress/atom``
        of the bonds and contacts the atoms have now (as a LAMMPS ``run 0``
        after the step: bonds that broke in it are gone, their pairs are
        contacts), with the velocities of now (:mod:`ase_bpm.models.analysis`),
        on the NumPy laws, changing nothing: nothing is written, and no
        breaking is tested, inside :func:`ase_bpm.pure` too (a bond past its
        criterion, which the next step breaks, shows its law's force there,
        extrapolated; bonds without a reference length yet take their
        length now, strain 0)."""
        inputs = Inputs(atoms)
        types_n, v_nc = inputs.types, inputs.velocities
        n = len(atoms)
        bonds = self._bond_state.aside(atoms)
        kept = self.ctx
        self.ctx, self._analysing = self.analysis_context(atoms, inputs), True
        try:
            geometry = self.bond_geometry(atoms, bonds)
            part = self.bond_forces(atoms, bonds, geometry, v_nc=v_nc,
                                    extra=self._volume_extra(atoms, bonds, geometry))
        finally:
            self.ctx, self._analysing = kept, False
        r_bc, f_bc = part.virial_pairs
        w_n6 = np.zeros((n, 6))
        add_pair_virials(w_n6, bonds.i_b, bonds.j_b, r_bc, f_bc)
        pairs = None
        if self._contacts is not None:
            search = ContactList(self._contacts.neighbours.cutoff, 0.0, self._contacts.overlay)
            i_p, j_p, r_pc = search.pairs(atoms, bonds)
            res = contact_forces(self.PAIR_LAW, i_p, j_p, r_pc, types_n,
                                 self.pair_coefficients(types_n), n, v_nc)
            pairs = pair_local(res)
            add_pair_virials(w_n6, res.i_p, res.j_p, res.r_pc, res.f_pc)
        plastic_b = None
        if SpringPlasticBond.name in self._laws:  # (as stored: LAMMPS' single() reads it so)
            plastic = self._law_of_type[bonds.type_b] == SpringPlasticBond.name
            stored_b = bonds.of_bonds(compiled.SpringBonds.PLASTIC)
            plastic_b = np.where(plastic, np.nan_to_num(stored_b, nan=0.0), np.nan)
        extra = dict(part.per_bond)
        if REFERENCE_DIRECTION in self._states:  # (bpm/rotational's; as LAMMPS's bond/local)
            direction_bc = bonds.of_bonds(REFERENCE_DIRECTION)[:, :3]
            extra["r0_dir_bc"] = np.where(np.isnan(direction_bc),
                                          r_bc / np.linalg.norm(r_bc, axis=1)[:, None],
                                          direction_bc)
        return Analysis(bond_local(bonds, r_bc, f_bc, part.r0_b, plastic_b, extra), pairs,
                        stress_per_atom(inputs.masses, v_nc, w_n6))

    # -- the contact search ---------------------------------------------------------------
    def contact_skin(self, r_n=None) -> float | None:
        """The Verlet skin of the contact search (LAMMPS ``neighbor``); None
        without contacts, where there is no search.  Granular contacts'
        default skin follows the radii ``r_n`` (None: not known without)."""
        if self._granular is not None:
            skin = self._granular.parameters["skin"]
            return (float(skin) if skin is not None
                    else None if r_n is None else self._granular.contact_skin(r_n))
        return None if self._contacts is None else self._contacts.neighbours.skin


class BPMSpring(BondedCalculator):
    """Spring bonded-particle model: LAMMPS ``bond_style bpm/spring`` +
    ``pair_style bpm/spring``.

    Bonds (integer arrays on the atoms, see :mod:`ase_bpm.core.bonds`) are springs
    between particles that break beyond a critical strain; particles that are
    not bonded repel when closer than a contact distance.  All units are the
    caller's, as long as they are consistent (LAMMPS ``lj`` or ``si`` numbers
    can be used unchanged; the timestep given to the ASE integrator is then in
    the same time unit).

    Parameters
    ----------
    bond_coeffs:
        ``{bond_type: (k, eps_c, gamma)}`` in the order of the LAMMPS line
        ``bond_coeff t k eps_c gamma`` (or the mapping ``{"k": ..., "eps_c":
        ..., "gamma": ...}``): stiffness ``k`` (force/distance, or force
        with ``normalize``), critical strain ``eps_c`` (unitless) and damping
        ``gamma`` (force/velocity).  A tuple (or a mapping's ``"model"``)
        that starts with the name of another registered bond law
        (:mod:`ase_bpm.laws.bond`) gives that bond type that law, e.g.
        ``("bpm/spring/plastic", k, eps_c, gamma, eps_p)`` (LAMMPS ``bond_style
        bpm/spring/plastic``: the plastic yield strain ``eps_p`` last, each
        bond's plastic strain kept in ``bond_plastic``).
    pair_coeffs:
        ``{(type_i, type_j): (k, r_c, gamma)}`` in the order of the LAMMPS
        line ``pair_coeff i j k r_c gamma`` (or the mapping ``{"k": ...,
        "r_c": ..., "gamma": ...}``): stiffness (force/distance), contact
        distance ``r_c`` (distance) and
        damping (force/velocity).  Unlisted pairs of types mix from the two
        like-type entries.  Empty: no contact forces (and no neighbour list).
        With ``anharmonic``, four values ``(k, r_c, gamma, k_a)``.
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
        (``break no``) the breaking test is not computed at all: a bond past
        ``eps_c`` keeps acting, as in LAMMPS.  It needs ``smooth=False`` (as
        in LAMMPS: the smoothing factor turns negative beyond ``eps_c``).  In
        a periodic cell nothing then bounds a bond's length: the cell check
        still assumes ``eps_c`` (a bond stretched past half the cell would
        be taken to its nearer periodic image, as in LAMMPS).
    overlay_pair:
        Bonded particles also interact through the pair law (``overlay/pair``).
    volume_factor:
        ``a_v`` (force) of LAMMPS ``bond_style bpm/spring volume/factor yes``
        (None: off): one number for every ``bpm/spring`` bond type, or
        ``{bond_type: a_v}`` naming each of them; ``a_v`` may be negative.
        Each bond also pulls by ``a_v (e - ((V_i + V_j)/(V0_i + V0_j))^(1/3)
        + 1)`` (smoothed with the rest), ``V`` the sum of the cubed lengths
        of an atom's intact bonds now and ``V0`` of their reference lengths:
        a multibody term that sets the Poisson ratio (Clemmer, Monti and
        Lechman, Soft Matter 20, 1702 (2024)).  It has no energy (LAMMPS
        reports none).
    anharmonic:
        ``pair_style bpm/spring anharmonic yes``: contacts repel by
        ``k_a (r_c - r)^3`` more, energy ``k_a (r_c - r)^4 / 4``; each
        ``pair_coeffs`` entry gives ``k_a`` fourth, and every pair of
        particle types present needs an entry (the reference LAMMPS build
        mixes no ``k_a``).
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
    kernels:
        ``"auto"`` (compiled where built), ``"compiled"`` or ``"numpy"``: the
        route of the bond and pair kernels (:func:`ase_bpm.laws.kernel_route`);
        both give the same forces to round-off.
        ``calc.kernel_route`` names the route resolved, ``calc.kernel_routes``
        what runs on it, per law: the bond laws' names, and ``"contacts"``
        where ``pair_coeffs`` are given, each ``"compiled"`` or ``"numpy"``
        (e.g. ``{"bpm/spring": "compiled", "contacts": "compiled"}``: a law
        without a compiled twin runs NumPy beside the others, which stay compiled).
    fixes:
        External force pieces (:mod:`ase_bpm.scene.fixes`), evaluated with the bonds.
    granular:
        Granular contacts instead of ``pair_coeffs`` (LAMMPS ``pair_style
        gran/hooke``, ``gran/hooke/history`` or ``gran/hertz/history`` beside
        the bond style, as LAMMPS's rotational impact example combines them):
        a mapping of :class:`ase_bpm.Granular`'s parameters (``model``,
        ``kn``, ``kt``, ``gamma_n``, ``gamma_t``, ``xmu``, ``dampflag``,
        ``limit_damping``, ``skin``), e.g. ``{"model": "hooke/history",
        "kn": 1.0, "gamma_n": 0.5, "xmu": 0.1}``.  Particles then need radii;
        bonded pairs do not touch (unless ``overlay_pair``); the shear
        history and ``ncontacts`` are kept as by ``Granular``.

    Results: ``energy`` (elastic energy of bonds and contacts, consistent with
    the forces), ``forces``, ``stress`` (periodic cells), and the ledger
    entries ``dissipated_energy`` and ``broken_bond_energy`` (see
    :mod:`ase_bpm.models.base`).  Per-atom outputs written to ``atoms.arrays``
    (``calc.per_atom_outputs``): ``nbonds`` (intact bonds) and ``damage``
    (fraction of the atom's bonds that have broken).  The reference length of
    each bond (``bond_r0``) is taken at its first evaluation and kept.

    Bonds break in every step: every evaluation at a new configuration but
    the first (which takes the reference lengths), and every evaluation an
    ase_bpm integrator announces.  LAMMPS does not break bonds in the setup
    evaluation that starts each ``run``; along a trajectory the two agree.
    Inside :func:`ase_bpm.pure` nothing breaks.
    """

    name = "bpm_spring"
    #: the model this calculator holds (``calc.model``)
    model_class = SpringModel
    default_parameters = dict(
        bond_coeffs={}, pair_coeffs={}, mix="geometric", smooth=True,
        normalize=False, break_bonds=True, overlay_pair=False,
        store_local=True, skin=None, timestep=None, kernels="auto", granular=None,
        volume_factor=None, anharmonic=False)
    def __init__(self, bond_coeffs: Mapping[int, tuple] = None,
                 pair_coeffs: Mapping[tuple, tuple] = None, mix: str = "geometric",
                 smooth: bool = True, normalize: bool = False,
                 break_bonds: bool = True, overlay_pair: bool = False,
                 store_local: bool = True, skin: float | None = None,
                 timestep: float | None = None, kernels: str = "auto", fixes=(),
                 granular: Mapping | None = None, volume_factor=None,
                 anharmonic: bool = False, **kwargs):
        self.model = self.model_class()
        super().__init__(fixes=fixes, bond_coeffs=dict(bond_coeffs or {}),
                         pair_coeffs=dict(pair_coeffs or {}), mix=mix, smooth=smooth,
                         normalize=normalize, break_bonds=break_bonds,
                         overlay_pair=overlay_pair, store_local=store_local,
                         skin=skin, timestep=timestep, kernels=kernels,
                         granular=None if granular is None else dict(granular),
                         volume_factor=volume_factor, anharmonic=anharmonic, **kwargs)

    def contact_skin(self, r_n=None) -> float | None:
        """The Verlet skin of the contact search (LAMMPS ``neighbor``); None
        without contacts, where there is no search; with ``granular``
        contacts and no ``skin`` given, 0.4 times the largest of the radii
        ``r_n`` (None without them)."""
        return self.model.contact_skin(r_n)
