"""Build the optional compiled kernels (everything else is in pyproject.toml).

Every C file in ``ase_bpm/laws/c/`` goes into one library,
``ase_bpm.laws._kernels``, which ase_bpm calls through ctypes
(``ase_bpm/laws/compiled.py``).  It is optional: where no C compiler is at
hand the install still succeeds and ase_bpm runs its NumPy kernels.  The
library records a digest of its sources, so that ase_bpm can tell a library
built from older sources (after editing a C file, rebuild: ``pip install -e
.``) and refuses to use it.  It is built with OpenMP where the compiler
takes ``-fopenmp`` (the bond and pair kernels can then run on threads:
``ase_bpm.set_threads``), else without (they run serially).
"""

import hashlib
import tempfile
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CCompilerError

HERE = Path(__file__).parent
FOLDER = "ase_bpm/laws/c"
# the same list and digest as ase_bpm/laws/compiled.py (sources_digest)
SOURCES = sorted((HERE / FOLDER).glob("*.[ch]"))
DIGEST = hashlib.sha256(b"".join(p.read_bytes() for p in SOURCES)).hexdigest()[:16]

OPENMP = "-fopenmp"
# a program that needs OpenMP's pragmas, header and runtime library alike
OPENMP_PROBE = """#include <omp.h>
int probe(void)
{
    int threads = 0;
#pragma omp parallel reduction(+ : threads)
    threads += omp_get_thread_num() >= 0;
    return threads;
}
"""


class BuildWithOpenMP(build_ext):
    """build_ext that adds OpenMP to the kernels where the compiler (the one
    setuptools picked, with its own flags) compiles and links a probe with
    it; a compiler without (Apple's clang, say) builds them serial."""

    def build_extensions(self):
        if self.takes_openmp():
            for extension in self.extensions:
                extension.extra_compile_args.append(OPENMP)
                extension.extra_link_args.append(OPENMP)
        else:
            print(f"ase_bpm: the C compiler does not take {OPENMP}: "
                  "the compiled kernels are built without threads")
        super().build_extensions()

    def takes_openmp(self) -> bool:
        with tempfile.TemporaryDirectory() as folder:
            source = Path(folder, "openmp_probe.c")
            source.write_text(OPENMP_PROBE)
            try:
                objects = self.compiler.compile([str(source)], output_dir=folder,
                                                extra_postargs=[OPENMP])
                self.compiler.link_shared_object(objects, str(Path(folder, "probe.so")),
                                                 extra_postargs=[OPENMP])
            except (CCompilerError, OSError):
                return False
        return True


setup(cmdclass={"build_ext": BuildWithOpenMP}, ext_modules=[
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
