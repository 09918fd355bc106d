"""Demo scenes, run by the ``ase-bpm demo`` command."""
