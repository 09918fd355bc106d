"""ase_bpm inside ASE's files: the ``ase-bpm`` format and calculators from
their ``todict()``.

**The format.**  ``ase.io.write("run.bpm", atoms)`` and
``ase.io.read("run.bpm")`` (any name with ``format="ase-bpm"``) call
:func:`ase_bpm.write_restart` and :func:`ase_bpm.read_restart`: the same
lossless ``.npz`` archive, one ``Atoms`` per file, state and all.  ASE finds
the format through the entry point group ``ase.ioformats``, whose entry
names an ``ase.utils.plugins.ExternalIOFormat``; its ``module`` is this one,
which holds the reader and writer ASE calls (``read_ase_bpm``,
``write_ase_bpm``, after the format's name).  The entry point names the
top-level module ``ase_bpm_ioformat``, outside the package: ASE imports it
while it imports ``ase.io``, where importing ase_bpm (which needs ``ase.io``
and ``ase.md`` complete) would fail, and this module only when a file is
read or written.

**Calculators.**  ``calc.todict()`` gives the parameters with the fixes'
own ``todict()`` (ASE stores it in trajectories and databases);
:func:`calculator_from_dict` builds the calculator again from it and its
``name``, as a trajectory frame holds them.
"""

from __future__ import annotations

from typing import BinaryIO, Mapping

from ase import Atoms

from ..models.base import BPMCalculator
from ..models.granular import Granular
from ..models.peri import BPMPeri
from ..models.spring import BPMSpring
from .restart import read_restart, write_restart

#: the calculators by their ASE ``name`` and by their class name
CALCULATORS = {key: cls for cls in (BPMSpring, BPMPeri, Granular)
               for key in (cls.name, cls.__name__)}


def read_ase_bpm(fd: BinaryIO) -> Atoms:
    """ASE's reader of the ``ase-bpm`` format: :func:`ase_bpm.read_restart`."""
    return read_restart(fd)


def write_ase_bpm(fd: BinaryIO, atoms: Atoms) -> None:
    """ASE's writer of the ``ase-bpm`` format: :func:`ase_bpm.write_restart`."""
    write_restart(fd, atoms)


def calculator_from_dict(name: str, parameters: Mapping) -> BPMCalculator:
    """The calculator ``name`` (its ASE name, e.g. ``"bpm_spring"`` as a
    trajectory stores it in ``frame.calc.name``, or its class name) with the
    ``parameters`` of its ``todict()`` (through JSON too), fixes included."""
    cls = CALCULATORS.get(name)
    if cls is None:
        raise ValueError(f"no ase_bpm calculator is named {name!r}; the names are "
                         f"{', '.join(sorted(CALCULATORS))}")
    return cls(**parameters)
