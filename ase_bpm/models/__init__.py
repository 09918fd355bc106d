"""Layer 3, models: the ASE calculators, each a composition of laws.

:mod:`.base` (the ASE plumbing every calculator shares: one evaluation per
configuration, the record on the atoms, the energy ledger), :mod:`.bonded`
(the bond machinery: reference state, breaking, the broken-bond record),
:mod:`.contacts` (granular shear history) and the calculators
:mod:`.spring`, :mod:`.peri`, :mod:`.granular`.  Imports from core and laws.
"""
