"""The record of the last evaluation, kept on the atoms.

Each evaluation that is not pure leaves on the atoms what a run needs to go
on from there, in a new calculator or from a restart file, bit for bit: the
positions it was made at (``X_LAST``), its forces, damping forces and torques
(``F_LAST``, ``FD_LAST``, ``T_LAST``), its energy and stress, the step count,
the ledger's totals, the signature of everything else the forces depend on
(``SIGNATURE``) and a checksum of the atom IDs it was made for
(``RECORD_IDS``: the record holds for these atoms in any order, not after
atoms were deleted, added or combined).  :class:`Record` writes it and reads
it back; :func:`digest` and :class:`InputDigests` make the signatures.
"""

from __future__ import annotations

import hashlib

import numpy as np
from ase import Atoms

from ..core.arrays import same_array
from ..core.bonds import ID, id_words, ids_checksum, read_ids, same_checksum
from .evaluation import Evaluation

# names of the record of the last evaluation
X_LAST, F_LAST, FD_LAST = "bpm_x_last", "bpm_f_last", "bpm_fd_last"
T_LAST = "bpm_t_last"
#: the damping part of the torques, where some are elastic (rotational bonds)
TD_LAST = "bpm_td_last"
STEP, ENERGY, STRESS = "bpm_step", "bpm_energy", "bpm_stress"
#: info: checksum of the atom IDs of the last evaluation (its atoms, any order)
RECORD_IDS = "bpm_record_ids"
DISSIPATED, BROKEN_ENERGY, SIGNATURE = (
    "bpm_dissipated_energy", "bpm_broken_bond_energy", "bpm_signature")


def digest(*parts) -> str:
    """Short hash of arrays and strings (for the signature of a configuration)."""
    h = hashlib.blake2b(digest_size=16)
    for part in parts:
        h.update(np.ascontiguousarray(part).tobytes() if isinstance(part, np.ndarray)
                 else repr(part).encode())
    return h.hexdigest()


class InputDigests:
    """Digests of per-atom input arrays (types, volumes, radii, masses), each
    recomputed only when the array's content changed since it was last asked
    for: a comparison per evaluation, no hashing."""

    def __init__(self):
        self._kept = {}  # name -> (copy of the array, its digest)

    def __call__(self, name: str, array) -> str:
        kept = self._kept.get(name)
        if kept is not None and (kept[2] is array and array is not None
                                 and not array.flags.writeable or same_array(kept[0], array)):
            return kept[1]  # (a read-only array seen last time: unchanged)
        value = "" if array is None else digest(array)
        self._kept[name] = (None if array is None else np.array(array, copy=True), value, array)
        return value


def stress_of(atoms: Atoms, virial) -> np.ndarray:
    """Stress from a virial (or a function giving it), Voigt order xx yy zz
    yz xz xy from the upper triangle, as LAMMPS tallies it (the contact
    virial of frictional spheres is not symmetric); energy per volume."""
    s_cc = (virial() if callable(virial) else virial) / atoms.get_volume()
    return np.array([s_cc[0, 0], s_cc[1, 1], s_cc[2, 2], s_cc[1, 2], s_cc[0, 2],
                     s_cc[0, 1]])


class Record:
    """Writes and reads the record of the last evaluation on the atoms, and
    keeps what saves work between evaluations (the IDs' checksum, zero
    torques, a virial not yet asked for)."""

    def __init__(self):
        self._ids_kept = (None, None)  # (the ID array, its checksum)
        self._ids_written = None  # the complete ID array the last record left on the atoms
        self._no_torques = None  # zeros, the torques of models without any
        self._virial_later = None  # virial of the last evaluation, if not yet asked

    def forget_ids(self) -> None:
        """Check the atoms' ID array afresh at the next record (after a
        refresh, or atoms removed)."""
        self._ids_written = None

    def ids_checksum(self, atoms: Atoms):
        """Checksum of the atoms' IDs (None without IDs), kept while the ID
        array is the same object (ASE's operations make new ones)."""
        ids = atoms.arrays.get(ID)
        if ids is None:
            return None
        if ids is not self._ids_kept[0]:
            self._ids_kept = (ids, ids_checksum(read_ids(atoms, ID)))
        return self._ids_kept[1]

    def holds_for(self, atoms: Atoms) -> bool:
        """Was the record on the atoms written for these atoms, in any order
        (the checksum of their IDs, where recorded, as theirs)?  At once
        while the ID array and the recorded checksum are the ones kept."""
        info = atoms.info
        if RECORD_IDS not in info:
            return True
        recorded = info[RECORD_IDS]
        ids, checksum = self._ids_kept
        if recorded is checksum and checksum is not None and atoms.arrays.get(ID) is ids:
            return True  # (the checksum this record kept for this very ID array)
        return same_checksum(recorded, self.ids_checksum(atoms))

    def restore(self, atoms: Atoms) -> dict:
        """The results of the recorded last evaluation at this very
        configuration (without the ledger's, see :mod:`.ledger`)."""
        results = {"forces": atoms.arrays[F_LAST].copy(), "energy": float(atoms.info[ENERGY])}
        results["free_energy"] = results["energy"]
        torques = atoms.arrays.get(T_LAST)
        results["torques"] = torques.copy() if torques is not None else np.zeros((len(atoms), 3))
        if STRESS in atoms.info:
            results["stress"] = np.array(atoms.info[STRESS], dtype=float)
        return results

    def late_stress(self, atoms: Atoms, results: dict, evaluate) -> None:
        """Stress asked for after the evaluation at this configuration: from
        that evaluation's pairs if this record wrote it, else from a fresh
        (pure) evaluation, ``evaluate(atoms)``, whose forces are not used."""
        virial_of = self._virial_later
        if virial_of is None:
            virial_of = evaluate(atoms).virial
        set_stress(results, atoms, virial_of)

    def write(self, atoms: Atoms, ev: Evaluation, step: int, signature,
              wants_stress: bool) -> dict:
        """Write the record of evaluation ``ev``, step ``step``, on the atoms
        (``signature``: the signature itself where it is the last one, else
        ``signature(atoms, ev)`` gives it, once the fixes' state is written)
        and return its results (the ledger's aside)."""
        info, arrays = atoms.info, atoms.arrays
        info[STEP] = step
        written = arrays.get(ID)
        if written is None or written is not self._ids_written:  # else complete already
            ids = id_words(atoms)
            if arrays.get(ID) is not ids:
                arrays[ID] = ids
            self._ids_written = ids
        ids, checksum = self._ids_kept
        info[RECORD_IDS] = checksum if arrays.get(ID) is ids else self.ids_checksum(atoms)
        for name, values in ev.fix_arrays.items():
            if values is None:  # the fix keeps no such state (any more)
                arrays.pop(name, None)
            else:
                arrays[name] = values
        info[ENERGY] = float(ev.energy)
        info[SIGNATURE] = signature if isinstance(signature, str) else signature(atoms, ev)
        arrays[X_LAST] = atoms.positions.copy()
        arrays[X_LAST].flags.writeable = False  # also what check_state compares with
        arrays[F_LAST] = ev.forces  # shared with results: ASE hands out copies
        if ev.f_damp is not None:
            arrays[FD_LAST] = ev.f_damp
        else:
            arrays.pop(FD_LAST, None)
        if ev.torques is not None:
            arrays[T_LAST] = ev.torques
        else:
            arrays.pop(T_LAST, None)
        if ev.t_damp is not None:
            arrays[TD_LAST] = ev.t_damp
        else:
            arrays.pop(TD_LAST, None)

        energy, torques = float(ev.energy), ev.torques
        if torques is None:
            torques = self._no_torques
            if torques is None or len(torques) != len(atoms):
                torques = self.torques(ev, len(atoms))
        results = {"energy": energy, "free_energy": energy, "forces": ev.forces,
                   "torques": torques}
        info.pop(STRESS, None)
        self._virial_later = None
        if ev.virial is not None and atoms.pbc.all():
            if wants_stress:  # else computed only if asked for (see late_stress)
                set_stress(results, atoms, ev.virial)
            else:
                self._virial_later = ev.virial
        return results

    def results_of(self, ev: Evaluation, natoms: int) -> dict:
        """The ASE results of an evaluation: energy, forces, torques."""
        return {"energy": float(ev.energy), "free_energy": float(ev.energy),
                "forces": ev.forces, "torques": self.torques(ev, natoms)}

    def torques(self, ev: Evaluation, natoms: int) -> np.ndarray:
        """The evaluation's torques, or zeros (one read-only array, kept: ASE
        hands out copies of results)."""
        if ev.torques is not None:
            return ev.torques
        zeros = self._no_torques
        if zeros is None or len(zeros) != natoms:
            zeros = self._no_torques = np.zeros((natoms, 3))
            zeros.flags.writeable = False
        return zeros


def set_stress(results: dict, atoms: Atoms, w_cc) -> None:
    """Put the stress of virial ``w_cc`` in ``results`` and in the record."""
    stress = stress_of(atoms, w_cc)
    results["stress"] = stress
    atoms.info[STRESS] = stress.copy()


def rebase(atoms: Atoms) -> None:
    """Re-base the record on where the atoms are, if they moved since it was
    written (a relaxation in pure evaluations): the next evaluation is then
    not a step, and its forces are not the record's."""
    x_last = atoms.arrays.get(X_LAST)
    if x_last is not None and not np.array_equal(x_last, atoms.positions):
        atoms.arrays[X_LAST] = atoms.positions.copy()
        for name in (F_LAST, FD_LAST, T_LAST, TD_LAST):
            atoms.arrays.pop(name, None)
        atoms.info.pop(STRESS, None)

