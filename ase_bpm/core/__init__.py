"""Layer 1, core: what every model stands on.

The per-atom arrays and their checks (:mod:`.arrays`, :mod:`.spheres`), bonds
stored as integers keyed by atom IDs (:mod:`.bonds`) and read into sets for
the kernels (:mod:`.bond_set`), the neighbour search
(:mod:`.neighbours`), coefficient checks (:mod:`.params`) and the text of
LAMMPS data files and decks (:mod:`.lammps_text`, numbers written a column at a
time by :mod:`.text_columns`).  Imports nothing
from the other layers.
"""
