"""Granular: frictional contacts between spheres (LAMMPS ``pair_style gran/*``):
the model, :class:`GranularModel`, and its calculator, :class:`Granular`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from ase import Atoms

from .analysis import Analysis, PairLocal, add_pair_virials, signed_force, stress_per_atom
from .base import BPMCalculator, digest
from .evaluation import Context, Evaluation
from .model import Model
from .contacts import ContactHistory, lookup_shear, read_contacts
from .outputs import NCONTACTS
from ..laws import HoldsKernels, granular_kernels, kernel_route, law_routes
from ..laws.granular import MODEL_NAMES, ContactLaw, contact_forces  # noqa: F401
from ..core.neighbours import SphereVerletList, neighbour_pairs
from ..laws.timestep import Springs
from ..core.arrays import Inputs
from ..core.spheres import frozen, radii



@dataclass(frozen=True)
class ContactPart:
    """The touching pairs of an evaluation, for the commit."""

    i_p: np.ndarray  # first sphere (i < j)
    j_p: np.ndarray  # second sphere
    shear_pc: Optional[np.ndarray]  # shear history after this evaluation
    l_p: np.ndarray  # their rows in the neighbour list
    build: int  # that list's build number
    shear_lc: Optional[np.ndarray] = None  # the shear of every row of that list (history)
    count_n: Optional[np.ndarray] = None  # each sphere's number of touching partners
    stored_lc: Optional[np.ndarray] = None  # the stored shear it read (ContactHistory.shear_rows)


@dataclass(kw_only=True)
class GranularEvaluation(Evaluation):
    contacts: ContactPart
    #: the checked radii, masses and mask of held spheres it read (the signature's inputs)
    spheres: tuple = (None, None, None)


class GranularModel(HoldsKernels, Model):
    """The model of :class:`Granular`: frictional contacts between spheres,
    their shear history on the atoms and the per-atom contact counts."""

    label = "Granular"
    per_atom_outputs = (NCONTACTS,)
    watched_arrays = ("radius",)
    #: the pairs left out of contact (a bonded model's: the bonded pairs): a
    #: callable ``(search) -> (rows, key)``, the rows of the search's list
    #: that may touch and a key that changes when they do (None: all rows)
    exclude = None

    def setup(self, parameters) -> str:
        self.parameters = p = parameters
        ContactLaw.model_name(p["model"], "Granular")  # (named before what it lacks)
        ContactLaw.check_given("Granular", ValueError, p)
        self.law = ContactLaw.create(p["model"], p["kn"], p["gamma_n"], p["xmu"], p["kt"],
                                     p["gamma_t"], p["dampflag"], p["limit_damping"])
        if p["skin"] is not None and not (np.isfinite(p["skin"]) and p["skin"] >= 0):
            raise ValueError(f"Granular: skin = {p['skin']} must be non-negative")
        try:
            self.kernels = granular_kernels(p["kernels"])
            #: "compiled" or "numpy", as BPMSpring's
            self.kernel_route = kernel_route(p["kernels"])
        except ValueError as exc:
            raise ValueError(f"Granular: {exc}") from None
        #: the kernel variant chosen for these coefficients (e.g.
        #: "granular_pairs_frictionless": no tangential force, torque or shear)
        self.kernel_variant = self.kernels.variant("pairs", self.law.frictional)
        #: what runs on that route, as BPMSpring's
        self.kernel_routes = law_routes(self.kernel_route, (), self.law)
        #: the shear history advances by the timestep in each step
        self.needs_timestep = self.law.keeps_history
        #: frictional contacts turn the spheres; frictionless ones cannot
        self.own_torques = self.law.frictional
        self.forget()
        return digest(self.label, self.law)

    def forget(self) -> None:
        self._search = None
        self._search_radii = None  # the read-only radii the search's skin is for
        # (the read-only inputs of the last evaluation's signature, its parts)
        self._parts = (None, None)
        # the compiled route writes the history's arrays in C, the NumPy one in NumPy
        self._history = ContactHistory(getattr(self.kernels, "place_contacts", None))

    def signature_parts(self, atoms: Atoms, evaluation) -> tuple:
        # the evaluation's checked inputs: the same read-only arrays while
        # radii and masses do not change, whose parts are then those of the
        # last evaluation (no comparison at a step)
        if evaluation is not None:
            r_n, m_n, hold_n = spheres = evaluation.spheres
            parts = self._parts_kept(spheres)
            if parts is not None:
                return parts
        else:
            r_n, m_n, hold_n = spheres = (radii(atoms, "Granular"), atoms.get_masses(),
                                          frozen(atoms))
        parts = (self._digests("radius", r_n), self._digests("masses", m_n),
                 self._digests("frozen", hold_n))
        if evaluation is not None:
            self._parts = (spheres, parts)
        return parts

    def _parts_kept(self, spheres: tuple) -> Optional[tuple]:
        """The last evaluation's signature parts where ``spheres`` (an
        evaluation's radii, masses and frozen mask) are what it took: the
        same read-only radii and masses, nothing frozen; else None."""
        r_n, m_n, hold_n = spheres
        kept, parts = self._parts
        if (hold_n is None and kept is not None and r_n is kept[0] and m_n is kept[1]
                and not (r_n.flags.writeable or m_n.flags.writeable)):
            return parts
        return None

    def contact_skin(self, r_n) -> float:
        """The Verlet skin for spheres of radii ``r_n`` (LAMMPS ``neighbor``)."""
        skin = self.parameters["skin"]
        return 0.4 * float(r_n.max(initial=0.0)) if skin is None else float(skin)

    def _contact_search(self, r_n) -> SphereVerletList:
        search = self._search
        if search is not None and r_n is self._search_radii:
            return search  # the same read-only radii: the same skin
        skin = self.contact_skin(r_n)
        if search is None or search.skin != skin:
            search = self._search = SphereVerletList(skin)
        self._search_radii = r_n if not r_n.flags.writeable else None
        return search

    def evaluate(self, atoms: Atoms, ctx: Context) -> GranularEvaluation:
        self.ctx = ctx
        n = len(atoms)
        law = self.law
        inputs = ctx.inputs
        r_n, m_n, hold_n = inputs.radii("Granular"), inputs.masses, inputs.frozen
        # only what the law can use: without friction, no spins; without
        # damping either, no velocities
        w_nc = inputs.omega if law.frictional else None
        v_nc = inputs.velocities if law.uses_velocities else None

        search = self._search
        if search is None or r_n is not self._search_radii:  # (else the same skin)
            search = self._contact_search(r_n)
        search.update(atoms.positions, atoms.cell.array, atoms.pbc, r_n)
        i_l, j_l, shift_lc, build = search.i_p, search.j_p, search.shift_pc, search.nbuilds
        if self.exclude is not None:
            rows, build = self.exclude(search)
            i_l, j_l = i_l[rows], j_l[rows]
            shift_lc = None if shift_lc is None else shift_lc[rows]
        shear_lc = (self._history.shear_rows(atoms, i_l, j_l, build)
                    if law.keeps_history else None)
        dt = ctx.timestep if law.keeps_history else None
        res = self.kernels.pair_contacts(i_l, j_l, shift_lc, atoms.positions, v_nc,
                                         w_nc, r_n, m_n, hold_n, shear_lc, **law.coefficients, dt=dt or 0.0,
                                         update=ctx.advancing,
                                         virial=bool(atoms.pbc.all()))  # for stress
        i_p, j_p = res.i_p, res.j_p
        if atoms.pbc.any() and not search.one_image:  # (else no pair can touch twice)
            self._check_images(i_p, j_p, n)
        return GranularEvaluation(
            forces=res.f_nc, energy=res.energy, f_damp=res.fd_nc, torques=res.t_nc,
            virial=res.virial, contacts=ContactPart(i_p, j_p, res.shear_xc, res.touch,
                                                    build, res.shear_lc, res.count_n,
                                                    shear_lc),
            spheres=(r_n, m_n, hold_n))

    def _touching(self, atoms: Atoms, inputs: Inputs) -> tuple:
        """The pairs of spheres touching now, found afresh (the run's
        neighbour list left as it is): ``(i_p, j_p, del_pc, r_p, ri_p, rj_p,
        meff_p)``, ``del = x_i - x_j``, with the effective mass of the
        kernels (a sphere held by ``FixAtoms`` counts as a wall)."""
        r_n, m_n, hold_n = inputs.radii("Granular"), inputs.masses, inputs.frozen
        i_p, j_p, shift_pc = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc, r_n)
        del_pc = (np.take(atoms.positions, i_p, axis=0) - np.take(atoms.positions, j_p, axis=0)
                  - shift_pc)
        r_p = np.sqrt(np.einsum("pc,pc->p", del_pc, del_pc))
        ri_p, rj_p = np.take(r_n, i_p), np.take(r_n, j_p)
        touch = (r_p < ri_p + rj_p) & (r_p > 0)
        i_p, j_p, del_pc, r_p = i_p[touch], j_p[touch], del_pc[touch], r_p[touch]
        ri_p, rj_p = ri_p[touch], rj_p[touch]
        mi_p, mj_p = np.take(m_n, i_p), np.take(m_n, j_p)
        meff_p = mi_p * mj_p / (mi_p + mj_p)
        if hold_n is not None:
            meff_p = np.where(hold_n[i_p], mj_p, np.where(hold_n[j_p], mi_p, meff_p))
        return i_p, j_p, del_pc, r_p, ri_p, rj_p, meff_p

    def springs(self, atoms: Atoms, ctx: Context) -> list:
        """The pairs of spheres touching now as springs, with lever arms
        ``R`` to the contact point."""
        i_p, j_p, del_pc, r_p, ri_p, rj_p, meff_p = self._touching(atoms, ctx.inputs)
        if not len(i_p):
            return []
        law = self.law.stiffness(ri_p + rj_p - r_p, ri_p * rj_p / (ri_p + rj_p), meff_p)
        n_pc = del_pc / r_p[:, None]  # from j to i
        return [Springs(i_p, j_p, n_pc, law.k_x, law.kt_x, law.c_x, law.ct_x,
                        arm_i_xc=-ri_p[:, None] * n_pc, arm_j_xc=rj_p[:, None] * n_pc)]

    def analyse(self, atoms: Atoms) -> Analysis:
        """LAMMPS' ``compute pair/local`` and ``stress/atom`` of the contacts
        at the atoms' state, its velocities and spins now
        (:mod:`ase_bpm.models.analysis`; no bonds), on the NumPy law with
        the stored shear, changing nothing (the shear does not advance).  The
        fixes (walls, gravity) add nothing to the stress, as in LAMMPS.  (An
        MD step's forces saw the half-step velocities: the damping of an
        analysis after the step differs, as a LAMMPS ``run 0`` then does.)"""
        inputs = Inputs(atoms)
        n = len(atoms)
        i_p, j_p, del_pc, r_p, ri_p, rj_p, meff_p = self._touching(atoms, inputs)
        if atoms.pbc.any():
            self._check_images(i_p, j_p, n)
        v_nc, w_nc = inputs.velocities, inputs.omega
        shear_pc = None
        if self.law.keeps_history:
            # stored as seen from the lower index, which i_p is (neighbour_pairs)
            keys_k, shear_kc = read_contacts(atoms)
            shear_pc = lookup_shear(keys_k, shear_kc, i_p * n + j_p)
        res = contact_forces(del_pc, ri_p + rj_p, ri_p * rj_p / (ri_p + rj_p),
                             np.take(v_nc, i_p, axis=0) - np.take(v_nc, j_p, axis=0),
                             ri_p[:, None] * np.take(w_nc, i_p, axis=0)
                             + rj_p[:, None] * np.take(w_nc, j_p, axis=0), meff_p, shear_pc,
                             **self.law.coefficients)
        ft_pc = res.fs_pc  # (None without friction)
        # LAMMPS' force: the normal part (del times "ccel"), along the line of centres
        dist_p, force_p = signed_force(-del_pc, res.f_pc if ft_pc is None else res.f_pc - ft_pc)
        w_n6 = np.zeros((n, 6))
        add_pair_virials(w_n6, i_p, j_p, -del_pc, res.f_pc)
        return Analysis(None, PairLocal(i_p, j_p, dist_p, force_p, res.f_pc, ft_pc),
                        stress_per_atom(inputs.masses, v_nc, w_n6))

    @staticmethod
    def _check_images(i_p, j_p, n: int) -> None:
        """One contact per pair of spheres: none through two periodic images."""
        keys_p = np.sort(i_p * n + j_p)
        twice = (i_p == j_p) | np.isin(i_p * n + j_p, keys_p[1:][np.diff(keys_p) == 0])
        if twice.any():
            p = int(np.argmax(twice))
            raise ValueError(f"periodic cell too small: sphere {i_p[p]} touches sphere "
                             f"{j_p[p]} through more than one periodic image (or its own "
                             "image)")

    def commit(self, atoms: Atoms, ev: GranularEvaluation, ctx: Context) -> None:
        c = ev.contacts
        i_p, j_p = c.i_p, c.j_p
        changed = True
        if self.law.keeps_history:
            changed = self._history.write(atoms, i_p, j_p, c.shear_pc, c.l_p, c.build,
                                          c.shear_lc, c.stored_lc)
        else:  # a history left by a frictional run would come back with friction
            self._history.forget(atoms)
        counts = atoms.arrays.get(NCONTACTS)
        if changed or counts is None or len(counts) != len(atoms):
            atoms.arrays[NCONTACTS] = c.count_n
        # (no state arrays; the signature's parts as last time)
        ev.kept_state = ctx.continues and self._parts_kept(ev.spheres) is not None


class Granular(BPMCalculator):
    """Frictional contacts between spheres: LAMMPS ``pair_style gran/hooke``,
    ``gran/hooke/history`` and ``gran/hertz/history``.

    Particles are spheres: ``atoms.arrays["radius"]`` (required) and the
    angular velocity ``atoms.arrays["omega"]`` (N x 3, zero when absent); the
    masses are the atoms'.  Two spheres interact while they overlap
    (``|x_i - x_j| < R_i + R_j``).  Run them with
    :class:`ase_bpm.SphereVelocityVerlet` (``fix nve/sphere``), which turns
    the spheres with the torques; ``FixAtoms`` holds particles as ``fix
    freeze``.  Units are the caller's, consistent (LAMMPS ``lj`` or ``si``
    numbers carry over unchanged).

    Parameters
    ----------
    model:
        ``"hooke"`` (no shear history), ``"hooke/history"`` or
        ``"hertz/history"``; the old names ``"no_history"``, ``"history"`` and
        ``"hertzian"`` too.  The only argument that may be given by position:
        every other one is a keyword (TypeError otherwise), listed here in the
        order of the LAMMPS line ``pair_style gran/<model> Kn Kt gamma_n
        gamma_t xmu dampflag``.
    kn:
        Normal stiffness: force/distance (Hooke) or force/distance^2 (Hertz).
    kt:
        Tangential stiffness, same units as ``kn``; default ``2/7 kn``
        (LAMMPS ``NULL``).  Unused by ``"hooke"``.
    gamma_n:
        Normal damping, 1/time (force = ``meff gamma_n`` times velocity).
    gamma_t:
        Tangential damping, 1/time; default ``gamma_n / 2`` (``NULL``).
    xmu:
        Friction coefficient: the tangential force is at most ``xmu`` times
        the normal force.
    dampflag:
        0 drops the tangential damping (LAMMPS ``dampflag``), 1 keeps it.
    limit_damping:
        Never let damping make the normal force attractive (LAMMPS keyword
        ``limit_damping``).
    skin:
        Verlet skin (distance) of the contact search; default 0.4 times the
        largest radius.
    kernels:
        ``"compiled"`` (C, built when ase_bpm is installed), ``"numpy"``, or
        ``"auto"`` (compiled where built); the two agree to round-off.
        ``calc.kernel_route`` names the route resolved, ``calc.kernel_routes``
        what runs on it: ``{"contacts": "compiled"}`` or ``"numpy"``.
    timestep:
        The MD timestep (time).  History models advance the shear by one
        timestep per step; the ase_bpm integrators announce it, otherwise pass
        it here.
    fixes:
        External pieces (:mod:`ase_bpm.scene.fixes`): gravity, granular walls...

    Results: ``forces``, ``torques`` (N x 3, ``calc.get_property("torques",
    atoms)``), ``energy`` (elastic energy of the normal overlaps; every other
    contact force does work that ends in ``dissipated_energy``, so kinetic
    plus rotational plus ``energy`` plus ``dissipated_energy`` is conserved)
    and ``stress`` (periodic cells).  Per-atom output (``calc.per_atom_outputs``):
    ``ncontacts``.

    Shear history: one displacement per touching pair, on the atoms
    (``gran_partner``, ``gran_shear``), so it travels with ``atoms.copy()``
    and restart files.  It advances once per MD step with the timestep, is
    rotated into the tangent plane, truncated where the contact slides
    (Coulomb), and dropped when the contact opens.  The first evaluation (the
    setup of a run in LAMMPS) does not advance it.

    Without friction (``xmu = 0``, or ``"hooke"`` with ``gamma_t = 0``: no
    tangential force can act, ``calc.law.frictional`` is False) only the
    normal force is computed: no shear history is kept, ``omega`` is not
    read, the torques are zero (``calc.produces_torques`` is False unless a
    fix turns the spheres, and :class:`~ase_bpm.SphereVelocityVerlet` then
    leaves ``omega`` as it is), and without ``gamma_n`` the velocities are
    not read either.  ``calc.kernel_variant`` names the kernel chosen.
    """

    name = "granular"
    #: the model this calculator holds (``calc.model``)
    model_class = GranularModel
    #: (the coefficients in the order of the LAMMPS line)
    default_parameters = dict(model="hooke/history", kn=None, kt=None, gamma_n=None,
                              gamma_t=None, xmu=None, dampflag=1, limit_damping=False,
                              skin=None, timestep=None, kernels="auto")

    def __init__(self, model: str = "hooke/history", *positional, kn: float | None = None,
                 kt: float | None = None, gamma_n: float | None = None,
                 gamma_t: float | None = None, xmu: float | None = None, dampflag: int = 1,
                 limit_damping: bool = False, skin: float | None = None,
                 timestep: float | None = None, kernels: str = "auto", fixes=(), **kwargs):
        ContactLaw.check_call("Granular", model, positional)
        self.model = self.model_class()
        super().__init__(fixes=fixes, model=model, kn=kn, gamma_n=gamma_n, xmu=xmu, kt=kt,
                         gamma_t=gamma_t, dampflag=dampflag, limit_damping=limit_damping,
                         skin=skin, timestep=timestep, kernels=kernels, **kwargs)

    @property
    def law(self) -> ContactLaw:
        """The contact law of these parameters (``calc.law.frictional``: can a
        tangential force act?)."""
        return self.model.law

    @property
    def kernels(self):
        """The kernels of the route chosen (:func:`ase_bpm.laws.granular_kernels`)."""
        return self.model.kernels

    @property
    def kernel_variant(self) -> str:
        """The kernel variant chosen for these coefficients (e.g.
        "granular_pairs_frictionless": no tangential force, torque or shear)."""
        return self.model.kernel_variant

    def contact_skin(self, r_n) -> float:
        """The Verlet skin for spheres of radii ``r_n`` (LAMMPS ``neighbor``)."""
        return self.model.contact_skin(r_n)

    def analyse(self, atoms: Atoms) -> Analysis:
        """LAMMPS' ``compute pair/local`` and ``stress/atom`` of the contacts
        now, changing nothing (:meth:`GranularModel.analyse`)."""
        return self.model.analyse(atoms)
