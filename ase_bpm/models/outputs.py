"""The per-atom outputs of the models: the names of the arrays an evaluation
writes to ``atoms.arrays`` for looking at, in one place.  Each model's
``per_atom_outputs`` draws from them, and viewers fall back on
:data:`PER_ATOM_OUTPUTS` for atoms that carry no such calculator (read from a
restart file, in post-processing)."""

#: each bonded atom's fraction of its bonds broken (for PERI, of its bonded
#: volume), and its intact bonds
DAMAGE, NBONDS = "damage", "nbonds"
#: the per-atom outputs of every bonded model
BOND_COUNTS = (DAMAGE, NBONDS)
#: each node's dilatation, of the state-based PERI models (lps, ves, eps)
DILATATION = "dilatation"
#: the spheres each granular sphere touches
NCONTACTS = "ncontacts"
#: the per-atom outputs any model writes
PER_ATOM_OUTPUTS = (*BOND_COUNTS, DILATATION, NCONTACTS)
