"""The version of ase_bpm, in one place: pyproject.toml reads it (statically,
without importing the package) and ``ase_bpm.__version__`` re-exports it."""

__version__ = "0.1.0"
