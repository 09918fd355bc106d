"""Layer 3, models: the ASE calculators, each holding a model, a composition of laws.

:mod:`.base` (the ASE plumbing every calculator shares: one evaluation per
configuration, the record on the atoms, the energy ledger), :mod:`.model`
(what a calculator calls on its model), :mod:`.bonded` (the bond machinery:
reference state, breaking, the broken-bond record), :mod:`.contacts`
(granular shear history) and the models with their calculators
:mod:`.spring`, :mod:`.peri`, :mod:`.granular`.  Imports from core and laws.
"""
