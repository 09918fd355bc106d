"""Which technology for the compiled kernels: C through ctypes, numba or Cython.

    python benchmarks/kernel_technology.py [--quick] [--repeats 9]
                                           [--sizes 3,14,63] [--pbc]

Issue 16: choose the technology of the compiled kernels by measurement.  The
candidate kernel is ``bond_style bpm/spring`` on a bond set, in one pass:
gather the bond vector ``x[j] - x[i]`` (minimum image), the law with the
smoothing factor and damping (``spring_bond_magnitudes`` in
``ase_bpm/laws/spring.py``), the breaking test, and the scatter of the
forces (and their damping part) to the atoms, with the energy sums.  It runs
as

* ``C/ctypes``: the package's kernel (``ase_bpm/laws/c/spring.c``), called as
  the model calls it: ``SpringBond.add_sums`` on a ``BondScene``, i.e.
  ``ase_bpm.laws.compiled.spring_bonds`` through ctypes;
* ``numba``: a twin of ``spring.c`` in this file, ``@njit(cache=True)``,
  statement for statement but for three numba idioms (the bond vector as
  scalars, the box unpacked before the loop, ``inline="always"`` on the
  minimum image; without the first and last the twin ran 25-35 % slower
  than C), behind a wrapper with the same signature as the C route's;
* ``Cython``: the same twin in Cython (typed memoryviews, no bounds checks,
  ``cdivision``), compiled at benchmark time into a temporary folder with the
  flags of ``setup.py``; skipped where Cython or a C compiler is missing;
* ``C native`` (not shipped, for reference): ``spring.c`` compiled here with
  ``-march=native``, for this CPU, as numba compiles for the CPU it runs on;
* ``NumPy``: the ``kernels="numpy"`` route's pieces (``BondSet.geometry``,
  ``spring_bond_magnitudes``, ``past_eps_c``, ``BondSet.sum_forces``), for
  reference.

Every timed call allocates its outputs (``BondSums.zeros``), as a step does.
Scenes: jittered FCC cubes at reduced density 1 as in ``scaling.py``
(``readme_block``), bonds closer than 1.5 (``create_bonds``); the reference
lengths are those of the built block, then the atoms are displaced by
normal(0, 0.01) so that a few bonds (about 0.2 %) are past eps_c = 0.04 and
break (bonds of type 1: k 1, eps_c 0.04, gamma 1; velocities normal(0,
0.05)).  Sizes in FCC cells per side: 3 (481 bonds), 14 (65,620), 63 (about
6.3 million bonds, 1e6 atoms).  ``--pbc``: periodic cubes instead of open
ones (the kernels then take the minimum image).

What is measured, all on one thread (``OMP_NUM_THREADS=1``):

* time per call: routes interleaved round-robin, ``--repeats`` timed blocks
  each (a block runs enough calls to last about 0.2 s), the median, min and
  max over the blocks of the CPU time per call (``time.process_time``: on a
  shared machine, time spent descheduled is not counted; caches and memory
  bandwidth are still shared), the median wall time, and ns per bond from
  the CPU median;
* the fixed cost per call on one bond between two atoms: through the route's
  entry point (allocations, argument packing, the call) and bare (the
  ctypes function with addresses ready / the numba dispatcher / the Cython
  function, on arrays ready);
* first-call cost, each in fresh subprocesses: numba's compilation with an
  empty cache (cold) and its load from the cache (warm); Cython's
  cythonize + C compile (cold) and the import of the built module (warm);
  the import added (``ctypes.CDLL`` of the package's library and its
  argument types; ``import numba``; the Cython module);
* agreement with the NumPy route: the largest difference of the per-atom
  forces (and their damping parts) over the largest force, the energies,
  and whether the same bonds break;
* the install story (what each needs at install and at run time, sizes,
  OpenMP), printed from what is installed here.

Measured here (23 Nov 2026; AMD EPYC, 2 cores shared with other jobs; three
full runs, CPU-time medians of 9 blocks, the median of the three; numba
0.68.1, Cython 3.3.1, gcc 12.2, NumPy 2.4.6): per bond at 65,620 and 6.3M
bonds, C/ctypes 18.2 and 21.0 ns, numba 18.2 and 20.0, Cython 18.2 and 20.4
(within 5 % of one another, run to run), C native 21.5 and 22.4, NumPy 129
and 189 (bimodal from run to run: 55-143 and 89-203).  At 481 bonds a call
takes 35 us with C/ctypes, 20 with numba, 21 with Cython, 71 with NumPy: the
C route's entry point spends 13 us on ``ndarray.ctypes.data`` for 13 arrays
(the bare calls: 1.1 us ctypes, 1.1 numba, 1.9 Cython).  numba adds 147 ms of
``import numba`` and, per process, 1.2 s of compilation on a cold cache or
0.18 s of cache loading on a warm one; the Cython build takes 8 s; the C
library loads in 0.13 ms.  All routes agree with NumPy to 5e-15 of the
largest force and break the same bonds.

``--quick``: sizes 3 and 14, 5 repeats, one subprocess of each first-call
kind.  Without numba or Cython installed their columns are skipped with a
note.  Timings are indicative when another process shares the machine: the
spread (min/max) says how much.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
             "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one thread: set before numpy is imported

import argparse
import contextlib
import ctypes
import importlib.metadata
import importlib.util
import io
import json
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

import numpy as np

try:
    import numba
except ImportError:  # the numba column is skipped
    numba = None

HERE = Path(__file__).resolve().parent
SPRING_C = HERE.parent / "ase_bpm" / "laws" / "c" / "spring.c"
sys.path.insert(0, str(HERE))

SIZES = (3, 14, 63)  # FCC cells per side: ~500, ~65k, ~6.3M bonds
QUICK_SIZES = (3, 14)
COEFF = dict(k=1.0, eps_c=0.04, gamma=1.0)  # the README's bond coefficients
OPTIONS = dict(smooth=True, normalize=False)
#: the flags of setup.py (no fused multiply-adds: the same arithmetic as NumPy)
CFLAGS = ["-O3", "-fno-math-errno", "-fno-trapping-math", "-ffp-contract=off"]
BLOCK_SECONDS = 0.2


# -- the numba twin of c/spring.c ------------------------------------------------------

if numba is not None:
    # error_model="numpy": a division by zero gives inf/nan as in C (numba's
    # default, "python", adds a test and an exception to every division)
    _jit = numba.njit(cache=True, error_model="numpy", nogil=True)

    # inline="always": numba inlines these into the loop itself (left to
    # LLVM, the minimum image stayed a call and the kernel ran 35 % slower)
    @numba.njit(cache=True, error_model="numpy", nogil=True, inline="always")
    def _nb_round_even(x):
        if not (abs(x) < 2251799813685248.0):
            return np.rint(x)
        return (x + 6755399441055744.0) - 6755399441055744.0

    @numba.njit(cache=True, error_model="numpy", nogil=True, inline="always")
    def _nb_minimum_image(kind, pbc, cell, inv, rx, ry, rz):
        """bonds.h's minimum_image on the vector (rx, ry, rz), returned; the
        box unpacked (kind, periodic flags, cell rows, inverse rows)."""
        if kind == 0:
            return rx, ry, rz
        if kind == 1:
            if pbc[0]:
                rx -= cell[0] * _nb_round_even(rx / cell[0])
            if pbc[1]:
                ry -= cell[4] * _nb_round_even(ry / cell[4])
            if pbc[2]:
                rz -= cell[8] * _nb_round_even(rz / cell[8])
            return rx, ry, rz
        s0 = rx * inv[0] + ry * inv[3] + rz * inv[6]
        s1 = rx * inv[1] + ry * inv[4] + rz * inv[7]
        s2 = rx * inv[2] + ry * inv[5] + rz * inv[8]
        if pbc[0]:
            s0 -= _nb_round_even(s0)
        if pbc[1]:
            s1 -= _nb_round_even(s1)
        if pbc[2]:
            s2 -= _nb_round_even(s2)
        return (s0 * cell[0] + s1 * cell[3] + s2 * cell[6],
                s0 * cell[1] + s1 * cell[4] + s2 * cell[7],
                s0 * cell[2] + s1 * cell[5] + s2 * cell[8])

    @_jit
    def _nb_spring_bonds(nb, has_select, select, i_b, j_b, type_b, x_nc, damped, v_nc, box,
                         r0_b, coeff_tc, smooth, normalize, breaking, want_virial, has_fd,
                         f_nc, fd_nc, broken_b, out):
        # Two departures from spring.c's letter, both numba idiom: the bond
        # vector as three scalars (a 3-array, np.empty(3) as spring.c's double
        # r[3], ran 20-25 % slower), and the box read into scalars before the
        # loop (numba's arrays may alias one another, C's are restrict, so
        # LLVM reloads box[0] after every store to the forces otherwise).
        kind = int(box[0])
        pbc = (box[1] != 0.0, box[2] != 0.0, box[3] != 0.0)
        cell = (box[4], box[5], box[6], box[7], box[8], box[9], box[10], box[11], box[12])
        inv = (box[13], box[14], box[15], box[16], box[17], box[18], box[19], box[20],
               box[21])
        nbroken = 0
        kept = 0.0
        released = 0.0
        for s in range(nb):
            b = select[s] if has_select else s
            i = i_b[b]
            j = j_b[b]
            t = type_b[b]
            rx, ry, rz = _nb_minimum_image(kind, pbc, cell, inv, x_nc[j, 0] - x_nc[i, 0],
                                           x_nc[j, 1] - x_nc[i, 1], x_nc[j, 2] - x_nc[i, 2])
            length = np.sqrt(rx * rx + ry * ry + rz * rz)
            if np.isnan(r0_b[b]):
                r0_b[b] = length
            r0 = r0_b[b]
            rinv = 1.0 / length if length > 0.0 else 0.0
            e = (length - r0) / r0
            f = coeff_tc[t, 0] * (e if normalize else length - r0)
            energy = 0.5 * e * e
            w = 1.0
            if smooth:
                x2 = e / coeff_tc[t, 1]
                x2 *= x2
                x8 = x2 * x2
                x8 *= x8
                w = 1.0 - x8
                f *= w
                energy -= 0.1 * e * e * x8
            energy *= coeff_tc[t, 0] * (r0 if normalize else r0 * r0)
            if breaking and abs(length - r0) > coeff_tc[t, 1] * r0:
                broken_b[b] = 1
                nbroken += 1
                released += energy
                continue
            kept += energy
            if damped:
                fd = coeff_tc[t, 2] * rinv * (rx * (v_nc[j, 0] - v_nc[i, 0])
                                              + ry * (v_nc[j, 1] - v_nc[i, 1])
                                              + rz * (v_nc[j, 2] - v_nc[i, 2]))
                if smooth:
                    fd *= w
                f += fd
                if has_fd:
                    sd = fd * rinv
                    fd_nc[i, 0] += rx * sd
                    fd_nc[j, 0] -= rx * sd
                    fd_nc[i, 1] += ry * sd
                    fd_nc[j, 1] -= ry * sd
                    fd_nc[i, 2] += rz * sd
                    fd_nc[j, 2] -= rz * sd
            sf = f * rinv
            f_nc[i, 0] += rx * sf
            f_nc[j, 0] -= rx * sf
            f_nc[i, 1] += ry * sf
            f_nc[j, 1] -= ry * sf
            f_nc[i, 2] += rz * sf
            f_nc[j, 2] -= rz * sf
            if want_virial:
                out[2] += rx * (rx * sf)
                out[3] += rx * (ry * sf)
                out[4] += rx * (rz * sf)
                out[5] += ry * (rx * sf)
                out[6] += ry * (ry * sf)
                out[7] += ry * (rz * sf)
                out[8] += rz * (rx * sf)
                out[9] += rz * (ry * sf)
                out[10] += rz * (rz * sf)
        out[0] += kept
        out[1] += released
        return nbroken

_NO_INTS, _NO_DOUBLES, _NO_BYTES = (np.zeros(0, np.int64), np.zeros((0, 3)),
                                    np.zeros(0, np.int8))


def _twin_arguments(scene, coeff_tc):
    """The arguments of the numba and Cython twins for a BondScene, packed as
    ``compiled.spring_bonds`` packs them for C (None as an empty array and a
    flag)."""
    sums = scene.sums
    select = None if scene.select is None else np.ascontiguousarray(scene.select, np.int64)
    nb = len(scene.i_b) if select is None else len(select)
    v_nc = None if scene.v_nc is None else np.ascontiguousarray(scene.v_nc, np.float64)
    return (nb, select is not None, _NO_INTS if select is None else select,
            np.ascontiguousarray(scene.i_b, np.int64), np.ascontiguousarray(scene.j_b, np.int64),
            np.ascontiguousarray(scene.type_b, np.int64),
            np.ascontiguousarray(scene.x_nc, np.float64), v_nc is not None,
            _NO_DOUBLES if v_nc is None else v_nc, scene.box, scene.r0_b,
            np.ascontiguousarray(coeff_tc, np.float64),
            bool(scene.options.get("smooth", True)), bool(scene.options.get("normalize", False)),
            bool(scene.breaking), bool(scene.virial), sums.fd_nc is not None, sums.f_nc,
            _NO_DOUBLES if sums.fd_nc is None else sums.fd_nc,
            sums.broken_b if scene.breaking else _NO_BYTES, sums.totals_t)


def _coeff_tc(scene):
    return np.column_stack([scene.coeff_t[name] for name in ("k", "eps_c", "gamma")])


def numba_add_sums(scene):
    """``SpringBond.add_sums`` with the numba twin in place of the C kernel."""
    scene.sums.nbroken += _nb_spring_bonds(*_twin_arguments(scene, _coeff_tc(scene)))


# -- the Cython twin --------------------------------------------------------------------

CYTHON_SOURCE = r'''
# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
from libc.math cimport sqrt, fabs, isnan, nearbyint
from libc.stdint cimport int64_t, int8_t

cdef inline double round_even(double x) noexcept nogil:
    if not (fabs(x) < 2251799813685248.0):
        return nearbyint(x)
    return (x + 6755399441055744.0) - 6755399441055744.0

cdef inline void minimum_image(const double[::1] box, double *r) noexcept nogil:
    cdef int kind = <int>box[0], k
    cdef double s[3]
    cdef double length
    if kind == 0:
        return
    if kind == 1:
        for k in range(3):
            if box[1 + k] != 0.0:
                length = box[4 + 4 * k]
                r[k] -= length * round_even(r[k] / length)
        return
    for k in range(3):
        s[k] = r[0] * box[13 + k] + r[1] * box[16 + k] + r[2] * box[19 + k]
        if box[1 + k] != 0.0:
            s[k] -= round_even(s[k])
    for k in range(3):
        r[k] = s[0] * box[4 + k] + s[1] * box[7 + k] + s[2] * box[10 + k]

def spring_bonds(int64_t nb, bint has_select, const int64_t[::1] select,
                 const int64_t[::1] i_b, const int64_t[::1] j_b, const int64_t[::1] type_b,
                 const double[:, ::1] x_nc, bint damped, const double[:, ::1] v_nc,
                 const double[::1] box, double[::1] r0_b, const double[:, ::1] coeff_tc,
                 bint smooth, bint normalize, bint breaking, bint want_virial, bint has_fd,
                 double[:, ::1] f_nc, double[:, ::1] fd_nc, int8_t[::1] broken_b,
                 double[::1] out):
    cdef int64_t s, b, i, j, t, nbroken = 0
    cdef int c, a
    cdef double kept = 0.0, released = 0.0
    cdef double r[3]
    cdef double length, r0, rinv, e, f, energy, w, x2, x8, fd, sd, sf, g
    with nogil:
        for s in range(nb):
            b = select[s] if has_select else s
            i = i_b[b]
            j = j_b[b]
            t = type_b[b]
            for c in range(3):
                r[c] = x_nc[j, c] - x_nc[i, c]
            minimum_image(box, r)
            length = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
            if isnan(r0_b[b]):
                r0_b[b] = length
            r0 = r0_b[b]
            rinv = 1.0 / length if length > 0.0 else 0.0
            e = (length - r0) / r0
            f = coeff_tc[t, 0] * (e if normalize else length - r0)
            energy = 0.5 * e * e
            w = 1.0
            if smooth:
                x2 = e / coeff_tc[t, 1]
                x2 *= x2
                x8 = x2 * x2
                x8 *= x8
                w = 1.0 - x8
                f *= w
                energy -= 0.1 * e * e * x8
            energy *= coeff_tc[t, 0] * (r0 if normalize else r0 * r0)
            if breaking and fabs(length - r0) > coeff_tc[t, 1] * r0:
                broken_b[b] = 1
                nbroken += 1
                released += energy
                continue
            kept += energy
            if damped:
                fd = coeff_tc[t, 2] * rinv * (r[0] * (v_nc[j, 0] - v_nc[i, 0])
                                              + r[1] * (v_nc[j, 1] - v_nc[i, 1])
                                              + r[2] * (v_nc[j, 2] - v_nc[i, 2]))
                if smooth:
                    fd *= w
                f += fd
                if has_fd:
                    sd = fd * rinv
                    for c in range(3):
                        g = r[c] * sd
                        fd_nc[i, c] += g
                        fd_nc[j, c] -= g
            sf = f * rinv
            for c in range(3):
                g = r[c] * sf
                f_nc[i, c] += g
                f_nc[j, c] -= g
            if want_virial:
                for a in range(3):
                    for c in range(3):
                        out[2 + 3 * a + c] += r[a] * (r[c] * sf)
        out[0] += kept
        out[1] += released
    return nbroken
'''
CYTHON_MODULE = "_kt_spring_cython"


def cython_missing() -> str | None:
    """Why the Cython twin cannot be built here (None: it can)."""
    if importlib.util.find_spec("Cython") is None:
        return "Cython is not installed"
    if importlib.util.find_spec("setuptools") is None:
        return "setuptools is not installed"
    if shutil.which(sysconfig.get_config_var("CC").split()[0] if sysconfig.get_config_var("CC")
                    else "cc") is None:
        return "no C compiler"
    return None


def build_cython(folder: Path) -> Path:
    """cythonize and compile the Cython twin into ``folder``; the module's path."""
    import logging

    from Cython.Build import cythonize
    from setuptools import Distribution, Extension

    logging.getLogger("Cython").setLevel(logging.ERROR)
    pyx = folder / f"{CYTHON_MODULE}.pyx"
    pyx.write_text(CYTHON_SOURCE)
    ext = Extension(CYTHON_MODULE, [str(pyx)], extra_compile_args=CFLAGS)
    dist = Distribution({"ext_modules": cythonize([ext], quiet=True, build_dir=str(folder)),
                         "script_name": "kernel_technology"})
    cmd = dist.get_command_obj("build_ext")
    cmd.build_lib, cmd.build_temp = str(folder), str(folder / "tmp")
    cmd.ensure_finalized()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        cmd.run()
    return next(folder.glob(f"{CYTHON_MODULE}*.so"))


def load_module(path: Path):
    spec = importlib.util.spec_from_file_location(CYTHON_MODULE, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# -- C compiled for this CPU (not shipped) ------------------------------------------------

def build_native(folder: Path) -> ctypes.CDLL:
    """``spring.c`` compiled with ``-march=native`` (and setup.py's flags)."""
    out = folder / "spring_native.so"
    subprocess.run([os.environ.get("CC", "cc"), *CFLAGS, "-march=native", "-shared", "-fPIC",
                    "-o", str(out), str(SPRING_C)], check=True, capture_output=True)
    lib = ctypes.CDLL(str(out))
    lib.spring_bonds.restype = ctypes.c_int64
    lib.spring_bonds.argtypes = ([ctypes.c_int64] + [ctypes.c_void_p] * 14
                                 + [ctypes.c_int64] * 2)  # natoms, threads
    return lib


def native_add_sums(lib):
    from ase_bpm.laws import compiled

    def add_sums(scene):
        saved = compiled._lib
        compiled._lib = lib  # compiled.SpringBonds' packing, this library's function
        try:
            compiled.SpringBonds(scene, _coeff_tc(scene), scene.options.get("smooth", True),
                                 scene.options.get("normalize", False))(scene)
        finally:
            compiled._lib = saved
    return add_sums


# -- the scenes ---------------------------------------------------------------------------

class Scene:
    """A bonded FCC cube with everything each route reads, built once."""

    def __init__(self, cells: int, pbc: bool):
        from scaling import FCC, readme_block

        from ase_bpm import BPMSpring
        from ase_bpm.laws import compiled

        atoms = readme_block(cells)
        if pbc:
            atoms.cell = np.eye(3) * cells * FCC
            atoms.pbc = True
        calc = BPMSpring(bond_coeffs={1: (COEFF["k"], COEFF["eps_c"], COEFF["gamma"])},
                         kernels="numpy")
        self.bonds = calc.model._bond_state.bonds(atoms)  # the NumPy route's BondSet
        self.natoms, self.nbonds = len(atoms), len(self.bonds)
        self.cell, self.pbc = np.array(atoms.cell), np.array(atoms.pbc)
        self.r0_b = self.bonds.geometry(atoms.positions, self.cell, self.pbc)[1]
        rng = np.random.default_rng(2)
        self.x_nc = np.ascontiguousarray(atoms.positions + rng.normal(0, 0.01, (self.natoms, 3)))
        self.v_nc = np.ascontiguousarray(atoms.get_velocities())
        self.box = compiled.box(self.cell, self.pbc)
        self.i_b = np.ascontiguousarray(self.bonds.i_b, np.int64)
        self.j_b = np.ascontiguousarray(self.bonds.j_b, np.int64)
        self.type_b = np.ascontiguousarray(self.bonds.type_b, np.int64)
        # by type, as the model's coefficient table (type 0: none)
        self.coeff_t = {name: np.array([np.nan, value]) for name, value in COEFF.items()}
        self.coeff_b = {name: np.full(self.nbonds, value) for name, value in COEFF.items()}
        self.bonds.vectors(self.v_nc)  # build the sparse matrices (cached, as in a run)
        self.bonds.incidence

    def bond_scene(self):
        """A BondScene with fresh sums, as ``BondedModel._compiled_bond_forces``
        builds it."""
        from ase_bpm.laws.bond import BondScene, BondSums

        return BondScene(i_b=self.i_b, j_b=self.j_b, type_b=self.type_b, x_nc=self.x_nc,
                         box=self.box, r0_b=self.r0_b, coeff_t=self.coeff_t,
                         sums=BondSums.zeros(self.natoms, self.nbonds, True, True),
                         v_nc=self.v_nc, select=None, options=OPTIONS, breaking=True,
                         virial=bool(self.pbc.any()))


def tiny_scene():
    """One bond between two atoms (the fixed cost per call)."""
    from ase_bpm.laws.bond import BondScene, BondSums
    from ase_bpm.laws import compiled

    x = np.array([[0.0, 0.0, 0.0], [1.01, 0.0, 0.0]])

    def make():
        return BondScene(i_b=np.array([0]), j_b=np.array([1]), type_b=np.array([1]), x_nc=x,
                         box=compiled.box(np.zeros((3, 3)), np.zeros(3, bool)),
                         r0_b=np.array([1.0]),
                         coeff_t={n: np.array([np.nan, v]) for n, v in COEFF.items()},
                         sums=BondSums.zeros(2, 1, True, True), v_nc=np.zeros((2, 3)),
                         options=OPTIONS)
    return make


# -- the routes ---------------------------------------------------------------------------

def numpy_route(sc: Scene):
    """The kernels="numpy" route's bond part (BondedModel.bond_forces, one law)."""
    from ase_bpm.laws.spring import past_eps_c, spring_bond_magnitudes

    bonds = sc.bonds
    c = sc.coeff_b

    def run():
        r_bc, r_b = bonds.geometry(sc.x_nc, sc.cell, sc.pbc)
        f_b, fd_b, energy_b, _ = spring_bond_magnitudes(
            r_bc, bonds.vectors(sc.v_nc), sc.r0_b, c["k"], c["eps_c"], c["gamma"],
            OPTIONS["smooth"], OPTIONS["normalize"], r_b=r_b)
        broken_b = past_eps_c(r_b, sc.r0_b, c["eps_c"])
        if broken_b.any():
            f_b = np.where(broken_b, 0.0, f_b)
            fd_b = np.where(broken_b, 0.0, fd_b)
        f_nc, fd_nc, _ = bonds.sum_forces(r_bc, r_b, f_b, None, fd_b)
        return dict(f_nc=f_nc, fd_nc=fd_nc, broken_b=broken_b,
                    energy=float(energy_b[~broken_b].sum()),
                    released=float(energy_b[broken_b].sum()))
    return run


def scene_route(sc: Scene, add_sums):
    """A route that adds to a BondScene's sums (C, numba, Cython)."""
    def run():
        scene = sc.bond_scene()
        add_sums(scene)
        s = scene.sums
        return dict(f_nc=s.f_nc, fd_nc=s.fd_nc, broken_b=s.broken_b.view(bool),
                    energy=s.energy, released=s.released)
    return run


def c_add_sums():
    from ase_bpm.laws.spring import SpringBond

    return SpringBond().add_sums


def routes(cython_module, native_lib) -> dict:
    """name -> add_sums (None: the NumPy route); the missing ones with a note."""
    from ase_bpm.laws import compiled

    out, notes = {}, {}
    if compiled.available:
        out["C/ctypes"] = c_add_sums()
    else:
        notes["C/ctypes"] = ("the package's library is not built here (stale)" if compiled.stale
                             else "the package's library is not built here")
    if numba is not None:
        out["numba"] = numba_add_sums
    if cython_module is not None:
        def cython_add_sums(scene, f=cython_module.spring_bonds):
            scene.sums.nbroken += f(*_twin_arguments(scene, _coeff_tc(scene)))
        out["Cython"] = cython_add_sums
    if native_lib is not None:
        out["C native"] = native_add_sums(native_lib)
    out["NumPy"] = None
    return out, notes


# -- timing -------------------------------------------------------------------------------

def per_call(fn, seconds=BLOCK_SECONDS) -> int:
    """Calls of ``fn`` that take about ``seconds``."""
    fn()
    start = time.perf_counter()
    fn()
    once = max(time.perf_counter() - start, 1e-7)
    return max(1, int(seconds / once))


def time_routes(calls: dict, repeats: int) -> dict:
    """name -> {"cpu": [...], "wall": [...]}, seconds per call of each timed
    block, in CPU time of this process and in wall time; routes interleaved."""
    counts = {name: per_call(fn) for name, fn in calls.items()}
    times = {name: {"cpu": [], "wall": []} for name in calls}
    for _ in range(repeats):
        for name, fn in calls.items():
            n = counts[name]
            wall, cpu = time.perf_counter(), time.process_time()
            for _ in range(n):
                fn()
            times[name]["cpu"].append((time.process_time() - cpu) / n)
            times[name]["wall"].append((time.perf_counter() - wall) / n)
    return times


def agreement(ref: dict, got: dict) -> dict:
    scale = np.abs(ref["f_nc"]).max()
    return dict(
        force=float(np.abs(got["f_nc"] - ref["f_nc"]).max() / scale),
        damping=float(np.abs(got["fd_nc"] - ref["fd_nc"]).max() / scale),
        energy=abs(got["energy"] - ref["energy"]) / abs(ref["energy"]),
        released=(abs(got["released"] - ref["released"]) / abs(ref["released"])
                  if ref["released"] else 0.0),
        same_broken=bool(np.array_equal(got["broken_b"], ref["broken_b"])),
        nbroken=int(ref["broken_b"].sum()))


def measure_size(cells: int, pbc: bool, repeats: int, add_sums: dict) -> dict:
    print(f"FCC {cells}^3 cells: building ...", file=sys.stderr, flush=True)
    sc = Scene(cells, pbc)
    calls = {name: numpy_route(sc) if fn is None else scene_route(sc, fn)
             for name, fn in add_sums.items()}
    ref = calls["NumPy"]()
    agree = {name: agreement(ref, fn()) for name, fn in calls.items() if name != "NumPy"}
    print(f"  {sc.natoms} atoms, {sc.nbonds} bonds: timing ...", file=sys.stderr, flush=True)
    return dict(cells=cells, natoms=sc.natoms, nbonds=sc.nbonds,
                times=time_routes(calls, repeats), agree=agree)


def overhead(add_sums: dict, repeats: int, cython_module, native_lib) -> dict:
    """Seconds per call on one bond: through the entry point, and bare."""
    from ase_bpm.laws import compiled

    make = tiny_scene()
    entry = {}
    for name, fn in add_sums.items():
        if fn is not None:
            entry[name] = (lambda fn=fn: fn(make()))
    entry["(BondScene + BondSums.zeros alone)"] = make
    held = [make().sums.f_nc for _ in range(13)]  # compiled.spring_bonds takes 13 addresses
    entry["(13 x ndarray.ctypes.data alone)"] = lambda: [a.ctypes.data for a in held]
    bare = {}
    scene = make()
    coeff_tc = _coeff_tc(scene)
    flags = np.array([1, 0, 1, 0], np.int64)  # smooth, normalize, breaking, virial
    arrays = [None, scene.i_b, scene.j_b, scene.type_b, scene.x_nc, scene.v_nc, scene.box,
              scene.r0_b, coeff_tc, flags, scene.sums.f_nc, scene.sums.fd_nc,
              scene.sums.broken_b, scene.sums.totals_t]
    addresses = [None if a is None else a.ctypes.data for a in arrays]
    one_thread = (len(scene.x_nc), 1)  # the atoms, the threads
    if "C/ctypes" in add_sums:
        bare["C/ctypes"] = lambda f=compiled._lib.spring_bonds: f(1, *addresses, *one_thread)
    args = _twin_arguments(scene, coeff_tc)
    if numba is not None:
        bare["numba"] = lambda: _nb_spring_bonds(*args)
    if cython_module is not None:
        bare["Cython"] = lambda f=cython_module.spring_bonds: f(*args)
    if native_lib is not None:
        bare["C native"] = lambda f=native_lib.spring_bonds: f(1, *addresses, *one_thread)
    return dict(entry=time_routes(entry, repeats), bare=time_routes(bare, repeats))


# -- first calls and imports, in fresh subprocesses ----------------------------------------

def child(role: str, folder: str) -> dict:
    """Run in a subprocess: what one cold or warm start costs."""
    if role == "numba":  # NUMBA_CACHE_DIR set by the parent: empty (cold) or filled (warm)
        make = tiny_scene()
        start = time.perf_counter()
        numba_add_sums(make())
        first = time.perf_counter() - start
        start = time.perf_counter()
        numba_add_sums(make())
        return dict(first=first, second=time.perf_counter() - start)
    if role == "cython-build":
        start = time.perf_counter()
        build_cython(Path(folder))
        return dict(build=time.perf_counter() - start)
    raise ValueError(role)


IMPORTS = {  # what each route adds to the start of a process that has numpy
    "C/ctypes": "import ctypes; lib = ctypes.CDLL({so!r}); "
                "lib.spring_bonds.restype = ctypes.c_int64; "
                "lib.spring_bonds.argtypes = [ctypes.c_int64] + [ctypes.c_void_p] * 14 "
                "+ [ctypes.c_int64] * 2",
    "numba": "import numba",
    "Cython": "import importlib.util as u; s = u.spec_from_file_location({name!r}, {so!r}); "
              "m = u.module_from_spec(s); s.loader.exec_module(m)",
}


def import_time(what: str, **fmt) -> float:
    code = ("import time, numpy; t = time.perf_counter(); " + IMPORTS[what].format(**fmt)
            + "; print(time.perf_counter() - t)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    return float(done.stdout.split()[-1])


def spawn(role: str, folder: str, env=None) -> dict:
    done = subprocess.run([sys.executable, __file__, "--child", role, "--folder", folder],
                          capture_output=True, text=True, env={**os.environ, **(env or {})})
    if done.returncode != 0:
        raise RuntimeError(f"child {role} failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def first_calls(runs: int, cython_ok: bool) -> dict:
    from ase_bpm.laws import compiled

    out = {}
    if compiled.available:
        from ase_bpm.laws import _kernels

        out["import C/ctypes"] = [import_time("C/ctypes", so=_kernels.__file__)
                                  for _ in range(runs)]
    if numba is not None:
        out["import numba"] = [import_time("numba") for _ in range(runs)]
        cold, warm = [], []
        for _ in range(runs):
            with tempfile.TemporaryDirectory() as cache:
                env = {"NUMBA_CACHE_DIR": cache}
                cold.append(spawn("numba", cache, env))
                warm.append(spawn("numba", cache, env))
        out["numba first call, cold cache"] = [c["first"] for c in cold]
        out["numba first call, warm cache"] = [w["first"] for w in warm]
        out["numba second call"] = [w["second"] for w in warm]
    if cython_ok:
        builds, imports = [], []
        for _ in range(runs):
            with tempfile.TemporaryDirectory() as folder:
                builds.append(spawn("cython-build", folder)["build"])
                so = next(Path(folder).glob(f"{CYTHON_MODULE}*.so"))
                imports.append(import_time("Cython", name=CYTHON_MODULE, so=str(so)))
        out["Cython build (cythonize + cc), cold"] = builds
        out["import Cython module, warm"] = imports
    return out


# -- the install story ---------------------------------------------------------------------

def installed_mb(dist: str) -> float | None:
    try:
        files = importlib.metadata.files(dist) or []
    except importlib.metadata.PackageNotFoundError:
        return None
    return sum(f.size or 0 for f in files) / 1e6


def requires(dist: str) -> list:
    try:
        return importlib.metadata.requires(dist) or []
    except importlib.metadata.PackageNotFoundError:
        return []


def openmp_probe() -> str:
    """Does the C compiler here build and run an OpenMP loop?"""
    cc = os.environ.get("CC", "cc")
    if shutil.which(cc) is None:
        return "no C compiler"
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp, "omp.c")
        src.write_text("#include <omp.h>\nint main(void){int n=0;\n#pragma omp parallel "
                       "reduction(+:n)\nn+=1;\nreturn n>0?0:1;}\n")
        built = subprocess.run([cc, "-fopenmp", "-o", str(Path(tmp, "omp")), str(src)],
                               capture_output=True)
        if built.returncode != 0:
            return "cc -fopenmp fails"
        ran = subprocess.run([str(Path(tmp, "omp"))], capture_output=True)
        return "cc -fopenmp builds and runs" if ran.returncode == 0 else "built, fails to run"


def numba_threading() -> str:
    if numba is None:
        return "numba not installed"
    layers = []
    for layer in ("tbb", "omp", "workqueue"):
        probe = (f"import numba, numpy as np\nnumba.config.THREADING_LAYER={layer!r}\n"
                 "@numba.njit(parallel=True)\ndef f(a):\n    s = 0.0\n"
                 "    for i in numba.prange(a.size):\n        s += a[i]\n    return s\n"
                 "f(np.ones(10)); print(numba.threading_layer())")
        done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                              env={**os.environ, "NUMBA_NUM_THREADS": "2"})
        layers.append(f"{layer}: {'yes' if done.returncode == 0 else 'no'}")
    return ", ".join(layers)


def install_story(cython_ok: bool) -> list:
    from ase_bpm.laws import compiled

    size = "not built here"
    if compiled.available:
        from ase_bpm.laws import _kernels

        size = f"{Path(_kernels.__file__).stat().st_size / 1e3:.0f} kB"
    lines = [f"C/ctypes: the package's library {size}; a C compiler at install only "
             "(setup.py, optional: without one the NumPy route runs); at run time nothing "
             "but ctypes (standard library); OpenMP: " + openmp_probe()
             + " (libgomp comes with gcc; a wheel would bundle it)"]
    if numba is not None:
        lines.append(
            f"numba {numba.__version__}: installed {installed_mb('numba'):.0f} MB + llvmlite "
            f"{importlib.metadata.version('llvmlite')} {installed_mb('llvmlite'):.0f} MB "
            "(an LLVM in a wheel, needed at run time: it compiles on first use); requires "
            + "; ".join(r for r in requires("numba") if "numpy" in r or "llvmlite" in r)
            + "; each numba release caps numpy and Python; threading layers (prange): "
            + numba_threading())
    else:
        lines.append("numba: not installed here (nothing measured)")
    if cython_ok:
        import Cython

        lines.append(f"Cython {Cython.__version__}: installed {installed_mb('Cython'):.0f} MB, "
                     "at build time only (a build requirement, with a C compiler); at run time "
                     "nothing; OpenMP through cython.parallel.prange with -fopenmp (as C)")
    else:
        lines.append(f"Cython: {cython_missing()} (nothing measured)")
    return lines


# -- the report ----------------------------------------------------------------------------

def spread(values, scale=1.0, fmt="{:.3g}") -> str:
    v = np.asarray(values) * scale
    return (fmt.format(np.median(v)) + " (" + fmt.format(v.min()) + "-" + fmt.format(v.max())
            + ")")


def unit(seconds: float) -> tuple:
    if seconds >= 0.1:
        return 1.0, "s"
    if seconds >= 1e-4:
        return 1e3, "ms"
    return 1e6, "us"


def report(rows, over, first, story, notes, repeats, pbc):
    print(f"\nbpm/spring bond kernel (gather, law with smoothing and damping, breaking test, "
          f"scatter), {'periodic' if pbc else 'open'} FCC cubes, one thread.")
    print(f"Time per call in CPU time of the process (not counting time spent descheduled): "
          f"median (min-max) of {repeats} timed blocks of about {BLOCK_SECONDS} s, routes "
          "interleaved; wall: the median in wall time; ns/bond and x C (over C/ctypes) from "
          "the CPU medians.  Differences: forces and their damping parts over the largest "
          "force, energies relative; same broken: the same bonds break as in NumPy.")
    for r in rows:
        times = r["times"]
        scale, name = unit(np.median(times.get("C/ctypes", times["NumPy"])["cpu"]))
        nbroken = r["agree"][next(iter(r["agree"]))]["nbroken"] if r["agree"] else "?"
        print(f"\n{r['natoms']} atoms, {r['nbonds']} bonds ({r['cells']}^3 cells), "
              f"{nbroken} break")
        print(f"  {'route':<10s} {'CPU per call, ' + name:>26s} {'wall':>7s} {'ns/bond':>8s} "
              f"{'x C':>5s} {'force':>8s} {'damping':>8s} {'energy':>8s} {'same broken':>11s}")
        c_med = np.median(times["C/ctypes"]["cpu"]) if "C/ctypes" in times else None
        for route, t in times.items():
            a = r["agree"].get(route)
            med = np.median(t["cpu"])
            ratio = f"{med / c_med:5.2f}" if c_med else "    -"
            agree = (f"{a['force']:8.1e} {a['damping']:8.1e} {a['energy']:8.1e} "
                     f"{str(a['same_broken']):>11s}" if a else f"{'(reference)':>12s}")
            print(f"  {route:<10s} {spread(t['cpu'], scale):>26s} "
                  f"{scale * np.median(t['wall']):7.3g} {1e9 * med / r['nbonds']:8.2f} "
                  f"{ratio} {agree}")
    print("\nFixed cost per call, one bond between two atoms, CPU us: median (min-max)")
    for kind, label in (("entry", "through the entry point (allocation, packing, call)"),
                        ("bare", "bare call, arguments ready")):
        print(f"  {label}:")
        for route, t in over[kind].items():
            print(f"    {route:<36s} {spread(t['cpu'], 1e6)}")
    print("\nFirst calls and imports, fresh processes, wall ms: median (min-max) of "
          f"{len(next(iter(first.values()), []))}")
    for what, t in first.items():
        print(f"  {what:<40s} {spread(t, 1e3)}")
    print("\nInstall and run time:")
    for line in story:
        print("  " + line)
    for route, note in notes.items():
        print(f"  skipped {route}: {note}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="sizes 3 and 14, 5 repeats")
    ap.add_argument("--repeats", type=int, help="timed blocks per route and size (9)")
    ap.add_argument("--sizes", help="FCC cells per side, comma-separated (3,14,63)")
    ap.add_argument("--pbc", action="store_true", help="periodic cubes")
    ap.add_argument("--first-runs", type=int, help="subprocesses per first-call figure (5)")
    ap.add_argument("--json", help="also write the figures to this file")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--folder", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.folder)))
        return
    repeats = args.repeats or (5 if args.quick else 9)
    first_runs = args.first_runs or (1 if args.quick else 5)
    sizes = ([int(s) for s in args.sizes.split(",")] if args.sizes
             else QUICK_SIZES if args.quick else SIZES)

    notes = {}
    cython_module = native_lib = None
    missing = cython_missing()
    build = tempfile.TemporaryDirectory()
    if missing is None:
        try:
            folder = Path(build.name, "cython")
            folder.mkdir()
            cython_module = load_module(build_cython(folder))
        except Exception as error:  # noqa: BLE001 -- any failure: skip the column
            notes["Cython"] = f"build failed: {error}"
    try:
        native_lib = build_native(Path(build.name))
    except Exception as error:  # noqa: BLE001
        notes["C native"] = f"build failed: {error}"
    add_sums, more = routes(cython_module, native_lib)
    notes.update(more)

    if numba is not None:  # compile (or load) before timing; timed apart below
        numba_add_sums(tiny_scene()())
    rows = [measure_size(n, args.pbc, repeats, add_sums) for n in sizes]
    print("fixed costs ...", file=sys.stderr, flush=True)
    over = overhead(add_sums, repeats, cython_module, native_lib)
    print("first calls ...", file=sys.stderr, flush=True)
    first = first_calls(first_runs, cython_module is not None)
    story = install_story(cython_module is not None)
    report(rows, over, first, story, notes, repeats, args.pbc)
    if args.json:
        Path(args.json).write_text(json.dumps(dict(rows=rows, overhead=over, first=first,
                                                   story=story, notes=notes), indent=1))
    build.cleanup()


if __name__ == "__main__":
    main()
