"""Build the optional compiled kernels (everything else is in pyproject.toml).

Every C file in ``ase_bpm/laws/c/`` goes into one library,
``ase_bpm.laws._kernels``, which ase_bpm calls through ctypes
(``ase_bpm/laws/compiled.py``).  It is optional: where no C compiler is at
hand the install still succeeds and ase_bpm runs its NumPy kernels.  The
library records a digest of its sources, so that ase_bpm can tell a library
built from older sources (after editing a C file, rebuild: ``pip install -e
.``) and refuses to use it.
"""

import hashlib
from pathlib import Path

from setuptools import Extension, setup

HERE = Path(__file__).parent
FOLDER = "ase_bpm/laws/c"
# the same list and digest as ase_bpm/laws/compiled.py (sources_digest)
SOURCES = sorted((HERE / FOLDER).glob("*.[ch]"))
DIGEST = hashlib.sha256(b"".join(p.read_bytes() for p in SOURCES)).hexdigest()[:16]

setup(ext_modules=[
    Extension("ase_bpm.laws._kernels",
              [f"{FOLDER}/{p.name}" for p in SOURCES if p.suffix == ".c"],
              depends=[f"{FOLDER}/{p.name}" for p in SOURCES if p.suffix == ".h"],
              define_macros=[("ASE_BPM_SOURCE_DIGEST", f'"{DIGEST}"')],
              # the same arithmetic as the NumPy kernels: no fused multiply-adds (and
              # no fast-math); errno and the floating-point exception flags are never
              # read (-fno-trapping-math lets branch-free kernels vectorize; IEEE
              # results are unchanged)
              extra_compile_args=["-O3", "-fno-math-errno", "-fno-trapping-math",
                                  "-ffp-contract=off"],
              optional=True),
])
