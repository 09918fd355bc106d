"""Lossless restart files for ase_bpm simulations.

:func:`write_restart` stores an ``Atoms`` object completely: every per-atom
array bit for bit (positions, momenta, masses, types, bonds, reference lengths,
the record of the last evaluation, outputs), the cell, pbc, ``info`` and the
constraints.  :func:`read_restart` gives it back; attach a new calculator and
the run continues exactly as if it had never stopped (files written before
atom IDs were stored as two int32 words too: their IDs are converted, as
are per-bond states of several numbers stored with three axes).

Why not ASE's formats: extxyz writes floats with 8 decimals (SI-scale momenta
of ~1e-8 become 0), ``.traj`` and ``.json`` drop custom per-atom arrays.  The
file is a NumPy ``.npz`` archive (no pickles): arrays under ``arrays/<name>``,
``info`` as JSON plus its arrays under ``info/<key>``.
"""

from __future__ import annotations

import json
import os
from typing import BinaryIO

import numpy as np
from ase import Atoms
from ase.constraints import dict2constraint
from ase.io.jsonio import decode, encode

from ..core.bonds import store_ids, store_states

FORMAT = "ase_bpm restart 1"


def _info_to_json(info: dict):
    """Split ``info`` into JSON-able values and arrays; reject the rest."""
    plain, arrays = {}, {}
    for key, value in info.items():
        if not isinstance(key, str):
            raise TypeError(f"atoms.info key {key!r} is not a string")
        if isinstance(value, np.ndarray):
            if value.dtype.hasobject:
                raise TypeError(f"atoms.info[{key!r}] is an object array")
            arrays[key] = value
        elif isinstance(value, np.generic):
            plain[key] = {"__numpy__": value.dtype.str, "value": value.item()}
        else:
            try:
                json.dumps(value)
            except TypeError:
                raise TypeError(f"atoms.info[{key!r}] of type {type(value).__name__} "
                                "cannot be stored in a restart file") from None
            plain[key] = value
    return plain, arrays


def _info_from_json(plain: dict, arrays: dict) -> dict:
    info = {}
    for key, value in plain.items():
        if isinstance(value, dict) and set(value) == {"__numpy__", "value"}:
            value = np.array(value["value"], dtype=value["__numpy__"])[()]
        info[key] = value
    info.update(arrays)
    return info


def write_restart(filename: str | os.PathLike | BinaryIO, atoms: Atoms) -> None:
    """Write ``atoms`` (state and all) to ``filename`` (a path or a binary
    file open for writing), losslessly."""
    content = {}
    for name, array in atoms.arrays.items():
        if array.dtype.hasobject:
            raise TypeError(f'atoms.arrays["{name}"] is an object array and cannot be '
                            "stored; convert it to numbers or fixed-width strings")
        content[f"arrays/{name}"] = array
    plain, info_arrays = _info_to_json(atoms.info)
    for key, value in info_arrays.items():
        content[f"info/{key}"] = value
    header = {
        "format": FORMAT,
        "info": plain,
        "constraints": encode([c.todict() for c in atoms.constraints]),
    }
    content["header"] = np.array(json.dumps(header))
    content["cell"] = atoms.cell.array
    content["celldisp"] = np.asarray(atoms.get_celldisp())
    content["pbc"] = atoms.pbc
    if hasattr(filename, "write"):  # a file ASE opened (ase.io.write)
        np.savez(filename, **content)
        return
    with open(filename, "wb") as fh:
        np.savez(fh, **content)


def read_restart(filename: str | os.PathLike | BinaryIO) -> Atoms:
    """Read an ``Atoms`` object written by :func:`write_restart` from
    ``filename`` (a path or a binary file open for reading)."""
    with np.load(filename, allow_pickle=False) as data:
        header = json.loads(str(data["header"])) if "header" in data.files else {}
        if header.get("format") != FORMAT:
            name = getattr(filename, "name", filename)
            raise ValueError(f"{name}: not an ase_bpm restart file (no {FORMAT!r} header)")
        arrays = {k[len("arrays/"):]: data[k] for k in data.files if k.startswith("arrays/")}
        info_arrays = {k[len("info/"):]: data[k] for k in data.files if k.startswith("info/")}
        atoms = Atoms(numbers=arrays["numbers"], positions=arrays["positions"],
                      cell=data["cell"], pbc=data["pbc"], celldisp=data["celldisp"])
    for name, array in arrays.items():
        atoms.arrays[name] = array
    atoms.info = _info_from_json(header["info"], info_arrays)
    atoms.set_constraint([dict2constraint(d) for d in decode(header["constraints"])])
    # files written before IDs were two words hold numbers, and before states
    # were two-dimensional, states of several numbers with three axes
    return store_states(store_ids(atoms))
