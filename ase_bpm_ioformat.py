"""ase_bpm's file format for ASE, found through the ``ase.ioformats`` entry point.

ASE imports this module while it imports ``ase.io``, for every user of the
environment: it imports nothing of ase_bpm (whose import needs ``ase.io`` and
``ase.md`` complete), and ASE imports the reader and writer,
:mod:`ase_bpm.scene.aseio`, only when a ``*.bpm`` file is read or written.
"""

from ase.utils.plugins import ExternalIOFormat

#: ``ase.io.write("run.bpm", atoms)``, ``ase.io.read("run.bpm")``, or any name
#: with ``format="ase-bpm"``: one ``Atoms`` per file ("1"), binary ("B")
BPM_FORMAT = ExternalIOFormat(
    desc="ase_bpm restart: lossless simulation state (.npz)", code="1B",
    module="ase_bpm.scene.aseio", ext="bpm", glob="*.bpm")
