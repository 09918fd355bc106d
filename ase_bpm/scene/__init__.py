"""Layer 4, scene: what a simulation is built from around a calculator.

Fixes (:mod:`.fixes`), integrators (:mod:`.md`), restart files
(:mod:`.restart`), LAMMPS export (:mod:`.lammps`), viewer files
(:mod:`.viewing`), the demos and the ``ase-bpm`` command (:mod:`.cli`).
Imports from every layer before it.
"""
