"""The typed values the stages of an evaluation hand each other.

* :class:`Context`: what the evaluation under way is (a step or not, pure or
  not, its step number and timestep, its checked inputs, the calculator's
  parameters and fixes), handed by the calculator to its model.
* :class:`Evaluation`: what the model's evaluation produced, before anything
  is written back on the atoms.
* :class:`Clock` and :class:`Contribution`: what a fix is told and what it
  gives back (the protocol of :mod:`ase_bpm.scene.fixes`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..core.arrays import Inputs


@dataclass
class Context:
    """What one evaluation is, as the calculator hands it to its model."""

    #: an MD step: bonds may break and history advances
    advancing: bool
    #: a pure evaluation (:func:`ase_bpm.pure`): nothing is written or advanced
    pure: bool
    step: int
    #: the MD timestep where the model or a fix uses it, else None
    timestep: Optional[float]
    #: the evaluation's per-atom inputs, read and checked once
    inputs: Optional[Inputs]
    #: the calculator's parameters
    parameters: object
    #: the calculator's fixes (external force pieces)
    fixes: tuple = ()
    #: the ordinary step: every input but the positions and velocities as
    #: the last evaluation saw them (lifecycle.Seen.continued_by)
    continues: bool = False


@dataclass
class Clock:
    """When an evaluation happens: its step, ``time = step * timestep``, and
    whether it is an MD step (history advances) or a setup/re-evaluation."""

    step: int
    time: float
    timestep: Optional[float]
    advancing: bool
    #: the evaluation's per-atom inputs, read and checked once (velocities,
    #: radii, ...): a fix takes them from here rather than from the atoms
    inputs: Optional[Inputs] = None
    #: the evaluation's forces, damping forces and torques so far (f_nc,
    #: fd_nc, t_nc; the last two None where it has none): a fix may add its
    #: own into them in place and say so (``Contribution.added``)
    into: Optional[tuple] = None

    @classmethod
    def of(cls, ctx: Context) -> "Clock":
        """The clock of the evaluation ``ctx`` (time 0 without a timestep)."""
        time = ctx.step * ctx.timestep if ctx.timestep is not None else 0.0
        return cls(step=ctx.step, time=time, timestep=ctx.timestep, advancing=ctx.advancing,
                   inputs=ctx.inputs)


@dataclass
class Contribution:
    """What a piece adds to an evaluation."""

    forces: np.ndarray  # f_nc
    energy: float = 0.0  # potential energy of the conservative part
    torques: Optional[np.ndarray] = None  # t_nc on finite-size spheres
    f_damp: Optional[np.ndarray] = None  # non-conservative part of forces
    arrays: dict = field(default_factory=dict)  # per-atom state to keep on the atoms (None: drop it)
    #: forces, f_damp and torques are the evaluation's own (``Clock.into``)
    #: with this piece's added in place (f_damp or torques made where it had none)
    added: bool = False


@dataclass
class Evaluation:
    """What one force evaluation produced, before anything is written back.

    Each model extends it with what its commit needs (``BondedEvaluation``,
    ``PeriEvaluation``, ``GranularEvaluation``).
    """

    forces: np.ndarray  # f_nc, total
    energy: float  # elastic energy
    f_damp: Optional[np.ndarray] = None  # damping part of f_nc (None if undamped)
    #: sum over pairs of r (x) f (3x3), or a function computing it when asked
    virial: Optional[object] = None
    released_energy: float = 0.0  # elastic energy of bonds broken in this evaluation
    #: torques on finite-size particles (N x 3; None: none)
    torques: Optional[np.ndarray] = None
    #: their damping part, where some are elastic (rotational bonds; None:
    #: the torques, if any, are all dissipative, as frictional contacts')
    t_damp: Optional[np.ndarray] = None
    #: per-atom state of external pieces (fixes), written with the commit
    fix_arrays: dict = field(default_factory=dict)
    #: work the damping forces and torques took in the step (for the ledger)
    dissipated: float = 0.0
    #: a bond, contact or pushing fix acts: elastic energy is stored (set by
    #: the calculator; the guard checks the timestep when contacts form)
    touching: bool = False
    #: the model's commit left its state arrays (``Model.state_arrays``) and
    #: its signature's parts as the last evaluation did (an ordinary step,
    #: ``Context.continues``, in which no bond broke): the record keeps the
    #: last signature and the calculator what it saw, without asking again
    kept_state: bool = False
