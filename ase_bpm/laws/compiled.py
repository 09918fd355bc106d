"""ase_bpm's compiled kernels: C (``ase_bpm/laws/c/``), called through ctypes.

One library, ``_kernels``, built at install from every C file of
``laws/c/`` (``setup.py``, optional): ``available`` says whether it is
there, and ``stale`` whether it was built from other sources than those
beside it (then it is not used: rebuild with ``pip install -e .``).  This
module loads it and holds the wrappers of its kernels: granular contacts,
``bpm/spring`` bonds and pairs, ``bpm/rotational`` bonds (forces and
torques), the PERI bonds (pmb, lps, ves, eps, the node pass, the energy left
when bonds break) and the ``bpm/peri`` contact.
The bpm/spring kernels can run on threads where the library was built with
OpenMP (:func:`set_threads`, ``ASE_BPM_THREADS``; one by default).

The granular kernels have the same functions, arguments and results as the
NumPy kernels in :mod:`ase_bpm.laws.granular` (:func:`pair_contacts`,
:func:`wall_contacts`, :func:`walls_contacts`), with the same arithmetic one contact at a time;
per-atom sums are accumulated in a different order, so results agree to
round-off.  Each kernel comes in two variants (:func:`variant`): the
general one and a frictionless one, which computes no tangential velocity,
shear or torque; the law's ``frictional`` coefficient picks one.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import warnings
from pathlib import Path

import numpy as np

from ..core import arrays
from . import KERNELS_VARIABLE
from .granular import CentredOnWall, SceneContacts, sums_into


#: the C sources of the library (as setup.py lists them)
SOURCES = sorted(Path(__file__).with_name("c").glob("*.[ch]"))


def sources_digest(sources) -> str:
    """The digest setup.py builds into the library, of these source files."""
    return hashlib.sha256(b"".join(Path(p).read_bytes() for p in sources)).hexdigest()[:16]


def _load(sources=SOURCES):
    """The library, or None if it is not built; and whether it is stale
    (built from other texts than ``sources``, where these files exist)."""
    try:
        from . import _kernels

        lib = ctypes.CDLL(_kernels.__file__)
    except (ImportError, OSError):  # not built: the NumPy kernels serve
        return None, False
    try:
        lib.kernels_source_digest.restype = ctypes.c_char_p
        built_from = lib.kernels_source_digest().decode()
    except AttributeError:  # older than the digest itself
        return None, True
    if sources and all(Path(p).exists() for p in sources):  # a source checkout
        if built_from != sources_digest(sources):
            return None, True
    return lib, False


_lib, stale = _load()
available = _lib is not None

# arrays go over as bare addresses (ctypes' own array checks cost more than a
# small scene's contacts): every array is made C-contiguous of the right type
# first, and kept referenced until the call returns
_PTR, _INT, _DBL = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double

#: the C function of each kernel, with friction (True) and without (False)
VARIANTS = {("pairs", True): "granular_pairs", ("pairs", False): "granular_pairs_frictionless",
            ("walls", True): "granular_walls",
            ("walls", False): "granular_walls_frictionless"}

if available:
    _lib.kernels_openmp.restype = _INT
    for (_kind, _), _name in VARIANTS.items():
        _function = getattr(_lib, _name)
        _function.restype = _INT
        _function.argtypes = ([_INT] + [_PTR] * 20 + [_INT] * 2 if _kind == "pairs"
                              else [_INT] * 2 + [_PTR] * 17)
    _lib.granular_place_contacts.restype = _INT
    _lib.granular_place_contacts.argtypes = [_INT, _INT] + [_PTR] * 4 + [_INT, _PTR, _INT] \
        + [_PTR] * 3


def variant(kind: str, frictional: bool) -> str:
    """The C function run for ``kind`` (``"pairs"`` or ``"walls"``) with or
    without friction (:attr:`ase_bpm.laws.granular.ContactLaw.frictional`)."""
    return VARIANTS[kind, bool(frictional)]


def _doubles(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _ints(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int64)


def _shifts(shift_xc):
    """A neighbour list's image shifts for C, or None (NULL) where it has
    none (built in an open box: every shift zero, see
    :class:`ase_bpm.core.neighbours.VerletList`)."""
    return None if shift_xc is None else _doubles(shift_xc)


def _address(a):
    """The address of a C-contiguous array's data (None for None); replaced
    by the library's own ``address`` where it is built (a tenth of the cost
    of ``a.ctypes.data``)."""
    return None if a is None else a.ctypes.data


if available:
    from ._kernels import address as _address  # noqa: F811


@functools.lru_cache(maxsize=64)
def _law(kn, kt, gamma_n, gamma_t, xmu, dt, hertz, history, update, limit_damping,
         lammps_wall, virial=False):
    """The ``law`` and ``flags`` arrays of the C functions (which only read
    them), read-only and kept: a run asks for the same few every step."""
    law = np.array([kn, kt, gamma_n, gamma_t, xmu, dt], dtype=np.float64)
    flags = np.array([hertz, history, update, limit_damping, lammps_wall, virial],
                     dtype=np.int64)
    law.flags.writeable = flags.flags.writeable = False
    return law, flags


def _written(a, dtype, name: str):
    """``a``, an array a kernel writes into, checked to be what C will take it
    for (C-contiguous, writable, of ``dtype``; None passes): a converted copy
    would lose the kernel's output, a wrong type would be read out of bounds."""
    if a is None:
        return None
    if not (a.dtype == dtype and a.flags.c_contiguous and a.flags.writeable):
        raise ValueError(f"the compiled kernels write into {name}: it must be a writable, "
                         f"C-contiguous array of {np.dtype(dtype).name}, not {a.dtype} "
                         f"(contiguous {a.flags.c_contiguous}, writable {a.flags.writeable})")
    return a


def _sums_into(into, n: int, frictional: bool) -> tuple:
    """:func:`ase_bpm.laws.granular.sums_into` for C: the arrays of ``into``
    where each is n x 3 (else ValueError, as NumPy's addition would raise)
    and all are writable C-contiguous doubles, which C can add into; else
    new zeroed ones (the caller then finds them not to be those of ``into``)."""
    if into is None:
        return sums_into(None, n, frictional)
    takes = True
    for a, name in zip(into, ("the forces", "the damping forces", "the torques")):
        if a is None:
            continue
        if a.shape != (n, 3):
            raise ValueError(f"the compiled kernels add into {name}: it must be {n} x 3, "
                             f"not {' x '.join(map(str, a.shape))}")
        takes = (takes and a.dtype == np.float64 and a.flags.c_contiguous
                 and a.flags.writeable)
    f_nc, fd_nc, t_nc = into
    if takes and fd_nc is not None and (t_nc is not None or not frictional):
        return f_nc, fd_nc, t_nc  # (the usual step: an evaluation's own arrays)
    return sums_into(into if takes else None, n, frictional)


def _spheres(x_nc, v_nc, w_nc, r_n, m_n, frictional: bool, damped: bool) -> list:
    """The spheres' positions, velocities, angular velocities, radii and
    masses as the granular kernels read them: C doubles, the velocities
    only where the law uses them (friction or normal damping, ``damped``),
    the angular velocities only with friction (else None, NULL).  A
    missing array that the kernel would read is refused here, not read
    through NULL."""
    uses_v = bool(frictional or damped)
    for a, used, name in ((v_nc, uses_v, "velocities"),
                          (w_nc, frictional, "angular velocities")):
        if used and a is None:
            raise ValueError(f"the compiled granular kernel needs {name} for this law")
    return [np.ascontiguousarray(x_nc, dtype=np.float64),
            np.ascontiguousarray(v_nc, dtype=np.float64) if uses_v else None,
            np.ascontiguousarray(w_nc, dtype=np.float64) if frictional else None,
            np.ascontiguousarray(r_n, dtype=np.float64),
            np.ascontiguousarray(m_n, dtype=np.float64)]


def pair_contacts(i_l, j_l, shift_lc, x_nc, v_nc, w_nc, r_n, m_n, hold_n, shear_lc, *,
                  kn, kt, gamma_n, gamma_t, xmu, hertz=False, history=False, dt=0.0,
                  update=False, limit_damping=False, virial=True,
                  frictional=True) -> SceneContacts:
    """:func:`ase_bpm.laws.granular.pair_contacts`, compiled (the virial
    only if asked for)."""
    natoms, nl = len(x_nc), len(i_l)
    history = history and frictional
    # (the list's pairs are int64 and its shifts doubles already: no copies)
    inputs = [np.ascontiguousarray(i_l, dtype=np.int64),
              np.ascontiguousarray(j_l, dtype=np.int64),
              None if shift_lc is None else np.ascontiguousarray(shift_lc, dtype=np.float64),
              *_spheres(x_nc, v_nc, w_nc, r_n, m_n, frictional, gamma_n),
              None if hold_n is None else np.ascontiguousarray(hold_n, dtype=np.int8)]
    shear = new_shear_lc = touch_shear = None
    if history:  # the stored shear (only read); the new one of every row, of the touching ones
        shear = np.ascontiguousarray(shear_lc, dtype=np.float64)
        new_shear_lc, touch_shear = np.empty((nl, 3)), np.empty((nl, 3))
    law, flags = _law(kn, kt, gamma_n, gamma_t, xmu, dt, hertz, history, update,
                      limit_damping, False, virial)
    f_nc, fd_nc = np.zeros((natoms, 3)), np.zeros((natoms, 3))
    t_nc = np.zeros((natoms, 3)) if frictional else None
    touch = np.empty((3, nl), dtype=np.int64)  # the touching rows, their i, their j
    count_n = np.zeros(natoms, dtype=np.int64)
    out = np.zeros(10)
    kernel = getattr(_lib, VARIANTS["pairs", bool(frictional)])
    count = kernel(nl, *map(_address, inputs + [shear, law, flags, new_shear_lc, touch_shear,
                                                 f_nc, fd_nc, t_nc, touch, count_n, out]),
                   natoms, _threads_for(nl, natoms, CONTACTS_THREADED_FROM))
    if count == _NO_MEMORY:
        raise MemoryError("pair_contacts: out of memory for the threads' force buffers")
    if count < 0:
        row = -1 - count
        raise ValueError(f"spheres {i_l[row]} and {j_l[row]} are at the same position: "
                         "their contact has no normal direction")
    return SceneContacts(f_nc, fd_nc, t_nc, float(out[0]), touch[0, :count],
                         touch_shear[:count] if history else None,
                         virial=out[1:].reshape(3, 3) if virial else None,
                         shear_lc=new_shear_lc, i_p=touch[1, :count], j_p=touch[2, :count],
                         count_n=count_n)


def wall_contacts(axis, lo, hi, x_nc, v_nc, w_nc, r_n, m_n, shear_nc, **law) -> SceneContacts:
    """:func:`ase_bpm.laws.granular.wall_contacts`, compiled: one wall of
    :func:`walls_contacts`."""
    res = walls_contacts([(axis, lo, hi)], x_nc, v_nc, w_nc, r_n, m_n,
                         None if shear_nc is None else np.asarray(shear_nc)[None], **law)
    if res.shear_xc is not None:
        res.shear_xc = res.shear_xc[0]
    return res


@functools.lru_cache(maxsize=16)
def _planes(planes: tuple) -> tuple:
    """The walls' axes, lower and upper planes (a tuple of ``(axis, lo, hi)``)
    as the C function takes them (-inf and inf where a wall has no such
    side), read-only."""
    axis_w = np.array([axis for axis, _, _ in planes], dtype=np.int64)
    lo_w = np.array([-np.inf if lo is None else lo for _, lo, _ in planes], dtype=np.float64)
    hi_w = np.array([np.inf if hi is None else hi for _, _, hi in planes], dtype=np.float64)
    for a in (axis_w, lo_w, hi_w):
        a.flags.writeable = False
    return axis_w, lo_w, hi_w


def walls_contacts(planes, x_nc, v_nc, w_nc, r_n, m_n, shear_wnc, *, kn, kt, gamma_n, gamma_t,
                   xmu, hertz=False, history=False, dt=0.0, update=False,
                   limit_damping=False, lammps_wall=True, frictional=True,
                   into=None) -> SceneContacts:
    """:func:`ase_bpm.laws.granular.walls_contacts`, compiled: every wall in
    one call, added into the arrays of ``into`` where C can add into them
    (else into zeros: see :func:`_sums_into`)."""
    n, nw = len(x_nc), len(planes)
    history = history and frictional
    inputs = [*_planes(tuple(map(tuple, planes))),
              *_spheres(x_nc, v_nc, w_nc, r_n, m_n, frictional, gamma_n)]
    # each wall's stored shear, only read (a NULL address for a wall without),
    # and a new array for the new shear, which the kernel writes whole
    stored, stored_w = [], np.zeros(nw, dtype=np.uintp)  # (the arrays, their addresses)
    if history and shear_wnc is not None:
        for w, a in enumerate(shear_wnc):
            if a is not None:
                stored.append(np.ascontiguousarray(a, dtype=np.float64))
                stored_w[w] = _address(stored[-1])
    shear = np.empty((nw, n, 3)) if history else None
    law, flags = _law(kn, kt, gamma_n, gamma_t, xmu, dt, hertz, history, update,
                      limit_damping, lammps_wall)
    f_nc, fd_nc, t_nc = _sums_into(into, n, frictional)
    touch_x = np.empty(nw * n, dtype=np.int64)
    out = np.zeros(1)
    kernel = getattr(_lib, VARIANTS["walls", bool(frictional)])
    count = kernel(n, nw, *map(_address, inputs + [stored_w, shear, law, flags, f_nc, fd_nc,
                                                    t_nc, touch_x, out]))
    if count < 0:
        wall, sphere = divmod(-1 - count, n)
        raise CentredOnWall(sphere, wall if nw > 1 else None)
    return SceneContacts(f_nc, fd_nc, t_nc, float(out[0]), touch_x[:count], shear)


def place_contacts(i_p, j_p, ids_n, shear_pc, partner_nk, shear, occupied):
    """The array work of :func:`ase_bpm.models.contacts.write_contacts`:
    the contacts ``(i_p, j_p)`` (in order of ``i``) and their shear into the
    slot arrays ``partner_nk`` (n x width, int64) and ``shear`` (n x 3 width),
    in place, after emptying the flat slots ``occupied`` (None: none).
    Returns ``(width, at_p)``: the width the contacts need and their flat
    slots, or None for ``at_p`` (nothing written) when the arrays are not of
    that width."""
    n, width = partner_nk.shape
    i_p, j_p, ids_n = _ints(i_p), _ints(j_p), _ints(ids_n)
    shear_pc = _doubles(shear_pc)
    occupied = np.zeros(0, dtype=np.int64) if occupied is None else _ints(occupied)
    at_p = np.empty(len(i_p), dtype=np.int64)
    need = _lib.granular_place_contacts(
        n, len(i_p), *map(_address, (i_p, j_p, ids_n, shear_pc)), len(occupied),
        _address(occupied), width,
        *map(_address, (_written(partner_nk, np.int64, "the contact partners"),
                        _written(shear, np.float64, "the contact shear"), at_p)))
    if need < 0:
        raise RuntimeError("place_contacts: a slot to empty lies outside the arrays")
    return need, (at_p if need == width else None)


# -- a step's sums outside the kernels (c/module.c) ----------------------------------------

#: the sums of a step outside the kernels (the ledger's work, the guard's
#: kinetic energy and finite checks, the comparisons of the state checks,
#: the Verlet skin check, the integrators' kicks, drifts and turns) run in C
#: in a process where the library is built and current, for every calculator
#: (they are no force law: a calculator's kernels="numpy" leaves them in C),
#: unless ASE_BPM_KERNELS=numpy (which runs NumPy everywhere).  They are
#: core's (:data:`ase_bpm.core.arrays.NATIVE`), which takes the C twins from here.
NATIVE_SUMS = (available and not stale
               and os.environ.get(KERNELS_VARIABLE, "auto") != "numpy")

if NATIVE_SUMS:
    from . import _kernels

    arrays.NATIVE.update(dot_sum=_kernels.dot_sum, damping_work=_kernels.damping_work,
                         all_finite=_kernels.all_finite,
                         same_bytes=_kernels.same_bytes,
                         largest_displacement_squared=_kernels.largest_displacement_squared,
                         add_to=_kernels.add_to, any_nonzero=_kernels.any_nonzero,
                         put_rows=_kernels.put_rows, pairs_in_order=_kernels.pairs_in_order,
                         members=_kernels.members)


# -- what the bond and pair kernels share (c/bonds.h) ------------------------------------

#: kinds of cell in the packed box (c/bonds.h)
BOX_OPEN, BOX_ORTHORHOMBIC, BOX_GENERAL = 0, 1, 2
_boxes: dict = {}  # the last cell packed, by its bytes


def box(cell, pbc) -> np.ndarray:
    """The cell packed for the kernels' minimum image (``c/bonds.h``): its
    kind, the three periodic flags, the cell's rows and its inverse's rows
    (zero where not needed)."""
    cell = np.asarray(cell, dtype=np.float64)
    pbc = np.asarray(pbc, dtype=bool)
    key = cell.tobytes() + pbc.tobytes()
    packed = _boxes.get(key)
    if packed is None:
        packed = np.zeros(22)
        if pbc.any():
            orthorhombic = np.count_nonzero(cell - np.diag(np.diag(cell))) == 0
            packed[0] = BOX_ORTHORHOMBIC if orthorhombic else BOX_GENERAL
            packed[1:4] = pbc
            packed[4:13] = cell.ravel()
            if not orthorhombic:
                packed[13:22] = np.linalg.inv(cell).ravel()
        packed.flags.writeable = False
        _boxes.clear()
        _boxes[key] = packed
    return packed


# -- threads (c/bonds.h, run_in_chunks) --------------------------------------------------

#: the environment variable that gives the kernels' thread count (default 1)
#: where set_threads has not
THREADS_VARIABLE = "ASE_BPM_THREADS"
#: whether the library was built with OpenMP; without, every kernel runs on one thread
threads_available = available and _lib.kernels_openmp() > 0
#: the fewest bonds (listed pairs) a kernel call takes threads for, and the fewest
#: per atom: measured on two idle cores, a bond or pair costs 10-13 ns, and two
#: threads add about 25 us a call (waking the second) and 1.5 ns per atom (its
#: force buffers, zeroed and added up), so that they pay from about 4,000 +
#: atoms / 4 items; these leave a margin (x1.5 at 20,000 bonds of 11,000 atoms)
THREADED_FROM = 20_000
THREADED_PER_ATOM = 0.5
#: the same for the granular pair kernel: a listed pair costs about twice a
#: bond (20 ns a row on a settled pour, half of them touching) and a call has
#: about twice the buffers (torques, counts), so that threads pay from about
#: 2,000 + atoms / 4 rows; this leaves a margin of two at 3,000 spheres
CONTACTS_THREADED_FROM = 5_000
#: what the granular pair kernel returns where the threads' buffers cannot be
#: allocated (PAIRS_NO_MEMORY in c/granular.c)
_NO_MEMORY = -(2 ** 63)
_threads_set = None  # set_threads' count (None: the environment's)


def set_threads(count: int | None):
    """Run the bpm/spring kernels (``spring_bonds``, ``spring_pairs``) and
    the granular pair kernel (``pair_contacts``) on ``count`` threads from
    now on (None: as the environment variable ``ASE_BPM_THREADS`` says, else
    1); returns the count set before (None if none was), for
    ``set_threads(before)`` to restore.

    A call takes threads only for ``THREADED_FROM`` bonds (listed pairs) or
    more (``CONTACTS_THREADED_FROM`` listed sphere pairs), and
    ``THREADED_PER_ATOM`` per atom.  The forces depend on the count through
    the order of their sums (to round-off), but a run with a given count
    gives the same results bit for bit every time; with 1 the kernels run
    their serial code.  They run on one thread where the library was built
    without OpenMP (``threads_available``), whatever the count."""
    global _threads_set
    if count is not None:
        _checked_count(count, "the thread count")
    before, _threads_set = _threads_set, count
    return before


def threads() -> int:
    """The thread count the kernels that run on threads take (1 without OpenMP)."""
    count = _threads_set
    if count is None:
        said = os.environ.get(THREADS_VARIABLE, "1")
        count = _checked_count(int(said) if said.strip().isdigit() else said,
                               f"the environment variable {THREADS_VARIABLE}")
    return count if threads_available else 1


def _checked_count(count, what: str) -> int:
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ValueError(f"{what} must be a positive integer, not {count!r}")
    if count > 1 and not threads_available:
        warnings.warn("ase_bpm: the compiled kernels were built without OpenMP: they run "
                      "on one thread", stacklevel=3)
    return int(count)


def _threads_for(items: int, natoms: int, fewest: int | None = None) -> int:
    """The threads a kernel call on ``items`` bonds or pairs takes (from
    ``fewest`` items on, ``THREADED_FROM`` unless given)."""
    fewest = THREADED_FROM if fewest is None else fewest
    enough = items >= fewest and items >= THREADED_PER_ATOM * natoms
    return threads() if enough else 1


# -- bpm/spring (c/spring.c) ---------------------------------------------------------------

if available:
    _lib.spring_bonds.restype = _INT
    _lib.spring_bonds.argtypes = [_INT] + [_PTR] * 14 + [_INT] * 2
    _lib.plastic_bonds.restype = _INT
    _lib.plastic_bonds.argtypes = [_INT] + [_PTR] * 16 + [_INT] * 2
    _lib.spring_volume_bonds.restype = _INT
    _lib.spring_volume_bonds.argtypes = [_INT] + [_PTR] * 16 + [_INT] * 2
    _lib.bond_volumes.restype = None
    _lib.bond_volumes.argtypes = [_INT] + [_PTR] * 8 + [_INT]
    _lib.spring_pairs.restype = _INT
    _lib.spring_pairs.argtypes = ([_INT] + [_PTR] * 5 + [_INT] + [_PTR] * 3 + [_INT] * 2
                                  + [_PTR] * 3 + [_INT] * 2)


def _run(function, name: str, count: int, natoms: int, arguments: tuple,
         outputs: tuple, prepared) -> int:
    """A bond or pair kernel of c/bonds.h's ``run_in_chunks`` on ``count``
    bonds or pairs of ``natoms`` atoms: ``function(count, *arguments, *the
    outputs' addresses, natoms, threads)``.  Each output, ``(array, dtype,
    name)``, is checked as :func:`_written` checks one (None passes, as
    NULL); the threads are :func:`_threads_for`'s, kept by the ``prepared``
    kernel (SpringBonds, SpringPairs) while the count set (set_threads), the
    environment's and the atom count stay.  Returns the kernel's count;
    MemoryError where the threads' force buffers cannot be had."""
    addresses = []
    for a, dtype, what in outputs:
        if a is not None and not (a.dtype == dtype and a.flags.c_contiguous
                                  and a.flags.writeable):
            _written(a, dtype, what)  # raises, naming it
        addresses.append(_address(a))
    asked = (_threads_set, os.environ.get(THREADS_VARIABLE), natoms)
    if prepared.threads[0] != asked:
        prepared.threads = (asked, _threads_for(count, natoms))
    result = function(count, *arguments, *addresses, natoms, prepared.threads[1])
    if result < 0:
        raise MemoryError(f"{name}: out of memory for the threads' force buffers")
    return result


def _spring_flags(smooth: bool, normalize: bool) -> dict:
    """The flags array of c/spring.c's ``spring_bonds`` (SMOOTH, NORMALIZE,
    BREAKING, VIRIAL) for each ``(breaking, virial)``, read-only, with its
    address: ``{(breaking, virial): (flags, address)}``."""
    made = {}
    for breaking in (False, True):
        for virial in (False, True):
            flags = np.array([smooth, normalize, breaking, virial], dtype=np.int64)
            flags.flags.writeable = False
            made[breaking, virial] = (flags, _address(flags))
    return made


class SpringBonds:
    """``bond_style bpm/spring`` on the bonds of a scene (a
    :class:`ase_bpm.laws.bond.BondScene`), made ready once for them:
    ``coeff_tc`` holds ``k, eps_c, gamma`` per bond type.  What stays while
    the bonds do (the bonds, their selection, the coefficients, the model's
    switches) is converted for C here, once; each call with a scene of the
    same bonds (positions, velocities, reference lengths, types and sums may
    be others) adds that scene's forces, energy and virial to its sums, marks
    the bonds that break and counts them in ``sums.nbroken``.  On
    :func:`threads` threads for enough bonds.

    ``plastic``: ``bond_style bpm/spring/plastic`` (c/spring.c's
    ``plastic_bonds``), ``coeff_tc`` holding ``eps_p`` fourth; each call reads
    the scene's history ``"plastic"`` and, in a step (``scene.advance``),
    puts the plastic strains reached in ``sums.history``.  ``volume``:
    ``volume/factor yes`` (``spring_volume_bonds``), ``coeff_tc`` holding
    ``a_v`` fourth; each call reads the atoms' volumes from ``scene.nodes``
    (:class:`ase_bpm.laws.spring.BondVolumes`)."""

    #: the history of bpm/spring/plastic: each bond's plastic strain
    PLASTIC = "plastic"

    def __init__(self, scene, coeff_tc, smooth: bool, normalize: bool, plastic: bool = False,
                 volume: bool = False):
        self.plastic, self.volume = plastic, volume
        select = None if scene.select is None else _ints(scene.select)
        #: how many bonds a call passes over
        self.count = len(scene.i_b) if select is None else len(select)
        # held: C reads them through these addresses at every call
        self._held = (select, _ints(scene.i_b), _ints(scene.j_b), _doubles(coeff_tc))
        self._bonds = tuple(map(_address, self._held[:3]))
        self._coeff = _address(self._held[3])
        self._flags = _spring_flags(smooth, normalize)
        self._r0 = None  # the reference lengths checked last (an array stays what it is)
        #: (what the count was asked for, the threads a call takes): see _run
        self.threads = (None, 1)

    def __call__(self, scene) -> None:
        sums, r0_b = scene.sums, scene.r0_b
        if r0_b is not self._r0:  # (set anew only where bonds take their lengths)
            self._r0 = _reference_lengths(r0_b)
        x_nc = np.ascontiguousarray(scene.x_nc, dtype=np.float64)
        v_nc = None if scene.v_nc is None else np.ascontiguousarray(scene.v_nc,
                                                                      dtype=np.float64)
        type_b = np.ascontiguousarray(scene.type_b, dtype=np.int64)
        box = np.ascontiguousarray(scene.box, dtype=np.float64)
        arguments = (*self._bonds, _address(type_b), _address(x_nc), _address(v_nc),
                     _address(box), _address(r0_b), self._coeff,
                     self._flags[bool(scene.breaking), bool(scene.virial)][1])
        function, name = _lib.spring_bonds, "spring_bonds"
        if self.plastic:
            ep_b = np.ascontiguousarray(scene.history[self.PLASTIC], dtype=np.float64)
            ep_out = np.empty(self.count)
            arguments += (_address(ep_b), _address(ep_out))
            function, name = _lib.plastic_bonds, "plastic_bonds"
        elif self.volume:
            arguments += (_address(scene.nodes.vol_n), _address(scene.nodes.vol0_n))
            function, name = _lib.spring_volume_bonds, "spring_volume_bonds"
        sums.nbroken += _run(
            function, name, self.count, len(sums.f_nc), arguments,
            ((sums.f_nc, np.float64, "the forces"), (sums.fd_nc, np.float64, "the damping forces"),
             (sums.broken_b if scene.breaking else None, np.int8, "the broken-bond marks"),
             (sums.totals_t, np.float64, "the totals")), self)
        if self.plastic and scene.advance:
            sums.history[self.PLASTIC] = (scene.select, ep_out)


def bond_volumes(i_b, j_b, type_b, x_nc, box, r0_b) -> tuple:
    """``(vol_n, vol0_n)``: c/spring.c's ``bond_volumes``, the twin of two
    :func:`ase_bpm.laws.spring.bond_volumes` over the intact bonds (type > 0)
    of a set, of their lengths now and of their reference lengths ``r0_b``
    (NaN: the length now)."""
    natoms = len(x_nc)
    vol_n, vol0_n = np.empty(natoms), np.empty(natoms)
    held = (_ints(i_b), _ints(j_b), _ints(type_b), _doubles(x_nc), _doubles(box),
            _doubles(r0_b))
    _lib.bond_volumes(len(held[0]), *map(_address, held), _address(vol_n), _address(vol0_n),
                      natoms)
    return vol_n, vol0_n


def _reference_lengths(r0_b: np.ndarray) -> np.ndarray:
    """The reference lengths as the bond kernels take them: C-contiguous
    doubles, writable where some are NaN (the kernels write those: a
    converted copy would lose them)."""
    if not (r0_b.dtype == np.float64 and r0_b.flags.c_contiguous):
        raise ValueError("the compiled bond kernels read the reference lengths as "
                         f"C-contiguous doubles, not {r0_b.dtype}")
    return r0_b


class SpringPairs:
    """``pair_style bpm/spring`` on the listed pairs ``select`` (None: all)
    of a neighbour list (``r = x[j] - x[i] + shift``; ``shift_pc`` None: no
    shifts, an open box), made ready once for them: the pairs are converted
    for C here, and each call (:meth:`__call__`) passes over them.  A new
    list, or another selection, takes a new one."""

    def __init__(self, i_p, j_p, shift_pc, select):
        select = None if select is None else _ints(select)
        #: how many listed pairs a call passes over
        self.count = len(i_p) if select is None else len(select)
        # held: C reads them through these addresses at every call
        self._held = (select, _ints(i_p), _ints(j_p), _shifts(shift_pc))
        self._pairs = tuple(map(_address, self._held))
        #: (what the count was asked for, the threads a call takes): see _run
        self.threads = (None, 1)

    def __call__(self, types_n, coeff_ttc: np.ndarray, x_nc, v_nc, virial: bool,
                 f_nc: np.ndarray, fd_nc, totals_t: np.ndarray) -> int:
        """Adds the forces of the pairs closer than ``r_c`` to ``f_nc``
        (damping part to ``fd_nc``, where given and ``v_nc`` is), their
        energy and virial to ``totals_t`` (as in
        :class:`ase_bpm.laws.bond.BondSums`).  ``coeff_ttc``: ``k, r_c,
        gamma`` per type pair, and ``k_a`` fourth for ``anharmonic yes``.
        Returns how many pairs touch."""
        types_n = np.ascontiguousarray(types_n, dtype=np.int64)
        coeff_ttc = np.ascontiguousarray(coeff_ttc, dtype=np.float64)
        x_nc = np.ascontiguousarray(x_nc, dtype=np.float64)
        v_nc = None if v_nc is None else np.ascontiguousarray(v_nc, dtype=np.float64)
        return _run(_lib.spring_pairs, "spring_pairs", self.count, len(f_nc),
                    (*self._pairs, _address(types_n), coeff_ttc.shape[0], _address(x_nc),
                     _address(v_nc), _address(coeff_ttc), coeff_ttc.shape[2], bool(virial)),
                    ((f_nc, np.float64, "the forces"), (fd_nc, np.float64, "the damping forces"),
                     (totals_t, np.float64, "the totals")), self)


def spring_pairs(i_p, j_p, shift_pc, select, types_n, coeff_ttc: np.ndarray, x_nc, v_nc,
                 virial: bool, f_nc: np.ndarray, fd_nc, totals_t: np.ndarray) -> int:
    """:class:`SpringPairs` for one call: ``pair_style bpm/spring`` on the
    listed pairs ``select`` of a neighbour list; returns how many pairs
    touch.  On :func:`threads` threads for enough pairs."""
    return SpringPairs(i_p, j_p, shift_pc, select)(types_n, coeff_ttc, x_nc, v_nc, virial,
                                                    f_nc, fd_nc, totals_t)


# -- PERI (c/peri.c) -----------------------------------------------------------------------

#: the coefficients of a bond type's row, in the order of c/peri.c (PERI_*):
#: "yield" is the pointwise yield value of eps, "model" the place of the
#: type's model in PERI_MODELS
PERI_COLUMNS = ("c", "K", "G", "lambda", "tau", "yield", "horizon", "s00", "alpha", "model")
PERI_MODELS = ("pmb", "lps", "ves", "eps")


class PeriBonds(ctypes.Structure):
    """``struct peri_bonds`` of c/peri.c, field for field."""

    _fields_ = [(name, _INT if kind == "i" else _DBL if kind == "d" else _PTR)
                for name, kind in (
                    ("nb", "i"), ("select", "p"), ("i_b", "p"), ("j_b", "p"), ("type_b", "p"),
                    ("r0_b", "p"), ("coeff_t", "p"), ("natoms", "i"), ("x_nc", "p"),
                    ("box", "p"), ("vol_n", "p"), ("m_n", "p"), ("theta_n", "p"),
                    ("smin_n", "p"), ("lambda_n", "p"), ("history_b", "p"), ("spacing", "d"),
                    ("dt", "d"), ("breaking", "i"), ("acts", "i"), ("advance", "i"),
                    ("virial", "i"), ("legacy", "i"), ("f_nc", "p"), ("broken_b", "p"),
                    ("smin_new_n", "p"), ("history_out", "p"), ("lambda_out", "p"),
                    ("out", "p"))]


if available:
    for _name in ("peri_pmb", "peri_lps", "peri_ves", "peri_eps"):
        getattr(_lib, _name).restype = _INT
        getattr(_lib, _name).argtypes = [ctypes.POINTER(PeriBonds)]
    _lib.peri_nodes.restype = _INT
    _lib.peri_nodes.argtypes = [ctypes.POINTER(PeriBonds)] + [_PTR] * 2
    _lib.peri_kept_energy.restype = _DBL
    _lib.peri_kept_energy.argtypes = [ctypes.POINTER(PeriBonds)]
    _lib.peri_contacts.restype = _INT
    _lib.peri_contacts.argtypes = ([_INT] + [_PTR] * 5 + [_INT] + [_PTR] * 3
                                   + [_DBL, _PTR, _INT, _INT] + [_PTR] * 2)


#: the fields of PeriBonds the kernels write into (broken_b is read by
#: peri_kept_energy), with their C types: checked, never converted (a copy
#: would lose what is written)
_PERI_OUTPUTS = {"f_nc": np.float64, "broken_b": np.int8, "smin_new_n": np.float64,
                 "history_out": np.float64, "lambda_out": np.float64, "out": np.float64}


def _peri_bonds(i_b, j_b, type_b, r0_b, coeff_tc, x_nc, box, nodes, keep: list,
                **fields) -> PeriBonds:
    """The C view of the bonds and the node state ``nodes`` (a
    :class:`ase_bpm.laws.peri.PeriScene`); every array it points to is
    appended to ``keep``, which the caller holds until the call returns."""
    def at(a, kind=_doubles):
        if a is None:
            return None
        a = kind(a)
        keep.append(a)
        return _address(a)

    select = fields.pop("select", None)
    view = PeriBonds(nb=len(i_b) if select is None else len(select), select=at(select, _ints),
                     i_b=at(i_b, _ints), j_b=at(j_b, _ints), type_b=at(type_b, _ints),
                     r0_b=at(_reference_lengths(r0_b)), coeff_t=at(coeff_tc), natoms=len(x_nc), x_nc=at(x_nc),
                     box=at(box), vol_n=at(nodes.vol_n), m_n=at(nodes.m_n),
                     theta_n=at(nodes.theta_n), lambda_n=at(nodes.lambda_n),
                     spacing=np.nan if nodes.spacing is None else float(nodes.spacing),
                     legacy=int(nodes.legacy))
    for name, value in fields.items():
        if isinstance(value, (bool, int, float)) or value is None:
            setattr(view, name, value)
        elif name in _PERI_OUTPUTS:
            setattr(view, name, at(value, lambda a, name=name: _written(
                a, _PERI_OUTPUTS[name], f"the {name}")))
        else:
            setattr(view, name, at(value))
    return view


def _peri_call(function, view, *arguments):
    count = function(ctypes.byref(view), *arguments)
    if count < 0:
        raise MemoryError(f"{function.__name__}: out of memory for its node sums")
    return count


def peri_nodes(i_b, j_b, type_b, r0_b: np.ndarray, coeff_tc, x_nc, box, nodes, *,
               weighted=False, dilatation=False) -> tuple:
    """The node pass over the bonds: the reference lengths not known yet (NaN
    in ``r0_b``, C-contiguous doubles) taken as the lengths now, in place,
    and per node those of ``(weighted volume, dilatation)`` asked for (else
    None), as :func:`ase_bpm.laws.peri.weighted_volume` and
    :func:`ase_bpm.laws.peri.dilatation` (with ``nodes.m_n``, over the
    state-based bonds) give them."""
    keep, n = [], len(x_nc)
    view = _peri_bonds(i_b, j_b, type_b, r0_b, coeff_tc, x_nc, box, nodes, keep)
    sums = [np.zeros(n) if wanted else None for wanted in (weighted, dilatation)]
    _peri_call(_lib.peri_nodes, view, *map(_address, sums))
    return tuple(sums)


def peri_bonds(model: str, scene, coeff_tc, acts: bool, history_out=None,
               lambda_out=None) -> int:
    """The PERI ``model``'s kernel on ``scene`` (a
    :class:`ase_bpm.laws.bond.BondScene` whose ``nodes`` is a
    :class:`ase_bpm.laws.peri.PeriScene`): adds the forces of its bonds to
    ``scene.sums``, their energy to its totals (pmb: that of the bonds that
    break to the released energy), marks the bonds that break by Parks'
    criterion (with ``nodes.smin_n``) and notes each node's smallest stretch
    in ``nodes.smin_new_n`` (where not None); ves and eps write their updated
    history into ``history_out`` (one row per bond of the law), eps its
    plastic multiplier into ``lambda_out``.  With ``acts``, a bond that
    breaks still gives its force in a step (``scene.advance``; not in a pure
    evaluation).  Returns how many bonds break."""
    nodes, sums, keep = scene.nodes, scene.sums, []
    history = next(iter(scene.history.values()), None)  # ves, eps: their one state
    view = _peri_bonds(
        scene.i_b, scene.j_b, scene.type_b, scene.r0_b, coeff_tc, scene.x_nc, scene.box,
        nodes, keep, select=scene.select, smin_n=nodes.smin_n if scene.breaking else None,
        history_b=history, dt=float(scene.timestep or 0.0),
        breaking=bool(scene.breaking and nodes.smin_n is not None),
        acts=bool(acts and scene.advance), advance=bool(scene.advance),
        virial=bool(scene.virial),
        f_nc=sums.f_nc, broken_b=sums.broken_b, smin_new_n=nodes.smin_new_n,
        history_out=history_out, lambda_out=lambda_out, out=sums.totals_t)
    return _peri_call(getattr(_lib, "peri_" + model), view)


def peri_kept_energy(i_b, j_b, type_b, r0_b, coeff_tc, x_nc, box, nodes, broken_b) -> float:
    """The elastic energy of the bonds once those marked in ``broken_b`` are
    gone (as ``BPMPeri._split_energy`` gives it): pmb bonds keep their own,
    the state-based ones take the lps energy with the dilatation of the bonds
    that stay."""
    keep = []
    view = _peri_bonds(i_b, j_b, type_b, r0_b, coeff_tc, x_nc, box, nodes, keep,
                       broken_b=np.array(broken_b, dtype=np.int8))
    energy = _lib.peri_kept_energy(ctypes.byref(view))
    if np.isnan(energy):
        raise MemoryError("peri_kept_energy: out of memory for its node sums")
    return float(energy)


def peri_contacts(i_p, j_p, shift_pc, select, types_n, coeff_ttc: np.ndarray, x_nc, vol_n,
                  reach: float, reach_p, legacy: bool, virial: bool, f_nc: np.ndarray,
                  totals_t: np.ndarray) -> int:
    """``pair_style bpm/peri`` on the listed pairs ``select`` (None: all) of a
    neighbour list (``r = x[j] - x[i] + shift``; ``shift_pc`` None: no
    shifts, an open box): the pairs closer than their
    contact distance (``reach_p``, one per pair of ``select``, or ``reach``
    where None) repel, with the volume factor of
    :func:`ase_bpm.laws.peri.volume_product` (``legacy``: ``V_i V_j``); adds
    their forces to ``f_nc``, their energy and virial
    to ``totals_t`` (as in :class:`ase_bpm.laws.bond.BondSums`).
    ``coeff_ttc``: ``k, horizon`` per type pair.  Returns how many touch."""
    select = None if select is None else _ints(select)
    n = len(i_p) if select is None else len(select)
    arrays = [select, _ints(i_p), _ints(j_p), _shifts(shift_pc), _ints(types_n)]
    rest = [_doubles(x_nc), _doubles(vol_n), _doubles(coeff_ttc)]
    reach_p = None if reach_p is None else _doubles(reach_p)
    return _lib.peri_contacts(n, *map(_address, arrays), coeff_ttc.shape[0],
                              *map(_address, rest), float(reach), _address(reach_p),
                              bool(legacy), bool(virial),
                              *map(_address, [_written(f_nc, np.float64, "the forces"),
                                              _written(totals_t, np.float64, "the totals")]))


# -- bpm/rotational (c/rotational.c) -------------------------------------------------------

class RotationalBondsView(ctypes.Structure):
    """``struct rotational_bonds`` of c/rotational.c, field for field."""

    _fields_ = [(name, _INT if kind == "i" else _PTR)
                for name, kind in (
                    ("nb", "i"), ("select", "p"), ("i_b", "p"), ("j_b", "p"), ("type_b", "p"),
                    ("x_nc", "p"), ("v_nc", "p"), ("q_nq", "p"), ("w_nc", "p"), ("box", "p"),
                    ("r0_b", "p"), ("dir_bc", "p"), ("dir_out", "p"), ("coeff_t", "p"),
                    ("smooth", "i"), ("normalize", "i"), ("breaking", "i"), ("virial", "i"),
                    ("f_nc", "p"), ("fd_nc", "p"), ("t_nc", "p"), ("td_nc", "p"),
                    ("broken_b", "p"), ("out", "p"))]


if available:
    _lib.rotational_bonds.restype = _INT
    _lib.rotational_bonds.argtypes = [ctypes.POINTER(RotationalBondsView)]


class RotationalBonds:
    """``bond_style bpm/rotational`` on the bonds of a scene (a
    :class:`ase_bpm.laws.bond.BondScene` with ``spins``: ``"quat"`` and,
    where damped, ``"omega"``), made ready once for them: ``coeff_tc`` holds
    the twelve coefficients per bond type in ``bond_coeff`` order.  As
    :class:`SpringBonds`, what stays while the bonds do is converted once;
    each call adds the scene's forces, torques (``sums.t_nc``), their damping
    parts and the virial to its sums, marks the bonds that break and counts
    them in ``sums.nbroken``.  The reference directions not taken yet (NaN
    rows of the history ``direction``) are taken from the bonds now and
    handed back as history, as :class:`ase_bpm.laws.rotational.RotationalBond`
    does.  On one thread."""

    def __init__(self, scene, coeff_tc, smooth: bool, normalize: bool, direction: str):
        select = None if scene.select is None else _ints(scene.select)
        # held: C reads them through these addresses at every call
        self._held = (select, _ints(scene.i_b), _ints(scene.j_b), _doubles(coeff_tc))
        self.select, self.direction = scene.select, direction
        self._view = RotationalBondsView(
            nb=len(scene.i_b) if select is None else len(select), select=_address(select),
            i_b=_address(self._held[1]), j_b=_address(self._held[2]),
            coeff_t=_address(self._held[3]), smooth=bool(smooth), normalize=bool(normalize))
        self._r0 = None  # the reference lengths checked last (as SpringBonds)
        #: the history of reference directions checked last, and whether
        #: some of this law's bonds had none there (an array stays what it is)
        self._directions = (None, False)

    def _unset(self, dir_bc: np.ndarray) -> bool:
        """Have some of the law's bonds no reference direction in ``dir_bc``
        (looked at once per history array)?"""
        if dir_bc is not self._directions[0]:
            if not (dir_bc.dtype == np.float64 and dir_bc.flags.c_contiguous):
                raise ValueError("the compiled bpm/rotational kernel reads the reference "
                                 f"directions as C-contiguous doubles, not {dir_bc.dtype}")
            mine = dir_bc[:, 0] if self.select is None else dir_bc[self.select, 0]
            self._directions = (dir_bc, bool(np.isnan(mine).any()))
        return self._directions[1]

    def __call__(self, scene) -> None:
        sums, r0_b, view = scene.sums, scene.r0_b, self._view
        if r0_b is not self._r0:
            self._r0 = _reference_lengths(r0_b)
        dir_bc = scene.history[self.direction]
        dir_out = None
        if self._unset(dir_bc):  # taken now: the history handed back, those rows new
            dir_out = np.array(dir_bc if self.select is None else dir_bc[self.select])
            sums.history[self.direction] = (self.select, dir_out)
        x_nc = np.ascontiguousarray(scene.x_nc, dtype=np.float64)
        v_nc = None if scene.v_nc is None else np.ascontiguousarray(scene.v_nc,
                                                                      dtype=np.float64)
        q_nq = np.ascontiguousarray(scene.spins["quat"], dtype=np.float64)
        w_nc = None if v_nc is None else np.ascontiguousarray(scene.spins["omega"],
                                                                dtype=np.float64)
        type_b = np.ascontiguousarray(scene.type_b, dtype=np.int64)
        box = np.ascontiguousarray(scene.box, dtype=np.float64)
        damped = v_nc is not None
        view.type_b, view.x_nc, view.v_nc = _address(type_b), _address(x_nc), _address(v_nc)
        view.q_nq, view.w_nc, view.box = _address(q_nq), _address(w_nc), _address(box)
        view.r0_b, view.dir_bc, view.dir_out = (_address(r0_b), _address(dir_bc),
                                                _address(dir_out))
        view.breaking, view.virial = bool(scene.breaking), bool(scene.virial)
        for field, a, dtype, what, needed in (
                ("f_nc", sums.f_nc, np.float64, "the forces", True),
                ("fd_nc", sums.fd_nc, np.float64, "the damping forces", damped),
                ("t_nc", sums.t_nc, np.float64, "the torques", True),
                ("td_nc", sums.td_nc, np.float64, "the damping torques", damped),
                ("broken_b", sums.broken_b, np.int8, "the broken-bond marks", scene.breaking),
                ("out", sums.totals_t, np.float64, "the totals", True)):
            if needed and a is None:
                raise ValueError(f"the compiled bpm/rotational kernel adds into {what}: "
                                 "the sums have none")
            setattr(view, field, _address(_written(a, dtype, what)) if needed else None)
        sums.nbroken += _lib.rotational_bonds(ctypes.byref(view))
