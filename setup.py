"""Build the optional compiled kernels (everything else is in pyproject.toml).

``ase_bpm/laws/_granular.c`` is plain C that ase_bpm calls through ctypes.
It is optional: where no C compiler is at hand the install still succeeds and
ase_bpm runs its NumPy kernels.  The library records a digest of its source,
so that ase_bpm can tell a library built from an older source (after editing
the C file, rebuild: ``pip install -e .``) and refuses to use it.
"""

import hashlib
from pathlib import Path

from setuptools import Extension, setup

SOURCE = "ase_bpm/laws/_granular.c"
DIGEST = hashlib.sha256((Path(__file__).parent / SOURCE).read_bytes()).hexdigest()[:16]

setup(ext_modules=[
    Extension("ase_bpm.laws._granular", [SOURCE],
              define_macros=[("ASE_BPM_SOURCE_DIGEST", f'"{DIGEST}"')],
              # the same arithmetic as the NumPy kernels: no fused multiply-adds (and
              # no fast-math); errno is never read
              extra_compile_args=["-O3", "-fno-math-errno", "-ffp-contract=off"],
              optional=True),
])
