"""The model a calculator holds, and what the calculator calls on it.

A calculator (:class:`ase_bpm.models.base.BPMCalculator`) is the ASE side:
parameters, results, the record on the atoms, the ledger and the guard.  Its
``model`` computes the forces and keeps the model's own state on the atoms
(bonds, shear history, per-atom outputs).  The model never reads the
calculator: it is set up from the parameters (:meth:`Model.setup`), and each
evaluation hands it a :class:`~ase_bpm.models.evaluation.Context`, what that
evaluation is (a step or not, pure or not, its step, timestep and checked
inputs).  :class:`Model` is the protocol with its defaults; the models are
:class:`~ase_bpm.models.bonded.BondedModel` (with
:class:`~ase_bpm.models.spring.SpringModel` and
:class:`~ase_bpm.models.peri.PeriModel`) and
:class:`~ase_bpm.models.granular.GranularModel`.
"""

from __future__ import annotations

from typing import Optional

from ase import Atoms

from ..core.arrays import Inputs
from .record import STEP, InputDigests
from .evaluation import Context, Evaluation


class Model:
    """What a calculator's model does (see the module doc).

    A model sets ``label``, the name of the calculator it serves: its
    messages name it, and the digest of its parameters starts with it (the
    signature recorded on the atoms by runs from before models and
    calculators were two objects).
    """

    label = ""
    #: the model itself advances history by the MD timestep in each step
    #: (e.g. viscoelastic bonds, shear history)
    needs_timestep = False
    #: the model's own forces come with torques (frictional granular contacts)
    own_torques = False
    #: its elastic forces and torques derive from the ``energy`` it reports,
    #: so that the ledger balances (kinetic + rotational + energy + dissipated
    #: + broken-bond energy is conserved); False where they do not
    #: (``bpm/rotational``, whose energy LAMMPS and ase_bpm report as zero)
    ledger_balances = True
    #: per-atom arrays whose change means a new configuration
    watched_arrays: tuple = ("type",)
    #: the per-atom outputs each evaluation writes to ``atoms.arrays`` (names;
    #: what :class:`ase_bpm.ViewerTrajectory` writes by default)
    per_atom_outputs: tuple = ()
    #: the kernels' route, as :meth:`setup` resolved it (``"compiled"`` or
    #: ``"numpy"``), and what runs on it: law name (and ``"contacts"``) -> route
    kernel_route = "numpy"
    kernel_routes: dict = {}

    def __init__(self):
        #: the calculator's parameters, as :meth:`setup` read them
        self.parameters = None
        #: the evaluation under way (or the last one), as the calculator told it
        self.ctx: Optional[Context] = None
        self._digests = InputDigests()  # of the inputs the signature names

    def setup(self, parameters) -> str:
        """Read ``parameters`` into the model's laws and tables (ValueError on
        bad ones); returns the digest of everything they decide."""
        raise NotImplementedError

    def forget(self) -> None:
        """Drop caches of what was read from the atoms."""

    def state_replaced(self, atoms: Atoms) -> bool:
        """Has the model state on the atoms (bonds) been replaced since the
        last evaluation?  (Noticed by identity: the model's arrays are
        read-only between evaluations.)"""
        return False

    def state_arrays(self) -> Optional[dict]:
        """The arrays of the model's own state on the atoms (bonds), by name,
        as the last evaluation read or wrote them: while the atoms hold these
        very arrays under these names, that state is not replaced (the
        calculator looks by identity); None where the model cannot tell
        (:meth:`state_replaced` is asked then)."""
        return {}

    def signature_parts(self, atoms: Atoms, evaluation: Optional[Evaluation]) -> tuple:
        """What the forces depend on besides positions, velocities and the
        parameters: types, bonds...  With ``evaluation``, of the state that
        evaluation left on the atoms (after its commit)."""
        raise NotImplementedError

    def evaluate(self, atoms: Atoms, ctx: Context) -> Evaluation:
        """Forces and energy of the atoms, touching nothing on them."""
        raise NotImplementedError

    def commit(self, atoms: Atoms, evaluation: Evaluation, ctx: Context) -> None:
        """Write model state (broken bonds, reference lengths, outputs)."""

    def springs(self, atoms: Atoms, ctx: Context) -> list:
        """The model's bonds and contacts acting now, as
        :class:`ase_bpm.laws.timestep.Springs` (read from the atoms and
        ``ctx.inputs``, nothing written)."""
        raise NotImplementedError(f"{self.label} gives no stable timestep")

    def analysis_context(self, atoms: Atoms, inputs: Inputs) -> Context:
        """The context of an analysis (``analyse``): a pure look at the atoms
        as they are, with ``inputs``; no step, so no timestep."""
        return Context(advancing=False, pure=True, step=int(atoms.info.get(STEP, 0)),
                       timestep=None, inputs=inputs, parameters=self.parameters)
