"""Per-atom inputs every model reads, checked, with errors that name the atom.

The names of the per-atom arrays live with what they describe:
:mod:`ase_bpm.core.bonds` (``bpm_id``, ``bond_*``), :mod:`ase_bpm.core.spheres`
(``radius``, ``omega``); particle types are ``atoms.arrays["type"]``.
"""

from __future__ import annotations

from functools import cached_property
from typing import Optional

import numpy as np
from ase import Atoms

TYPE = "type"  # LAMMPS atom type of each particle (all 1 when absent)


#: C twins of the sums a step makes outside the kernels (``dot_sum``, the
#: ledger's ``damping_work``, ``all_finite``, ``same_bytes``,
#: ``largest_displacement_squared``),
#: installed by :mod:`ase_bpm.laws.compiled` where the library is built and
#: current, unless ASE_BPM_KERNELS=numpy (core builds nothing itself).  A
#: twin returns NotImplemented for arrays it does not take (not C-contiguous
#: float64; for same_bytes, not C-contiguous); NumPy's way runs then, and
#: without twins.
NATIVE = {}


def dot_sum(a: np.ndarray, b: np.ndarray) -> float:
    """``sum(a * b)`` over every element, in one pass, without BLAS: NumPy's
    ``vdot`` calls OpenBLAS, whose threads on a machine with busy cores made
    the dot product of 11,000 forces and displacements take 3 ms instead of
    16 us (measured here, with two other processes running).  ``a`` and
    ``b`` are arrays (their own ``ravel``: no dispatch, 0.6 us less a call).
    The C twin (:data:`NATIVE`) keeps four running sums: its last digits may
    differ; it costs 0.15 us a call against einsum's 4."""
    twin = NATIVE.get("dot_sum")
    if twin is not None:
        value = twin(a, b)
        if value is not NotImplemented:
            return value
    return float(np.einsum("i,i->", a.ravel(), b.ravel()))


def all_finite(values: np.ndarray, *more: Optional[np.ndarray]) -> bool:
    """Are all ``values``, and all of each array in ``more`` (None: none),
    finite?  (One pass over each when all is well; the C twin makes no
    temporary.)"""
    twin = NATIVE.get("all_finite")
    for array in (values, *more):
        if array is None:
            continue
        finite = NotImplemented if twin is None else twin(array)
        if finite is NotImplemented:
            finite = bool(np.isfinite(array).all())
        if not finite:
            return False
    return True


def add_to(a: np.ndarray, s: float, b: np.ndarray, c=None, divide: bool = False) -> None:
    """``a += s * b``, times ``c`` or divided by it (``divide``) where given,
    in place: the integrators' kicks, drifts and turns.  The C twin makes
    one pass without temporaries and the same arithmetic (``s * b`` first)."""
    twin = NATIVE.get("add_to")
    if twin is not None and twin(a, s, b, c, divide) is not NotImplemented:
        return
    if c is None:
        a += s * b
    elif divide:
        a += s * b / c
    else:
        a += s * b * c


def put_rows(dst: np.ndarray, src: np.ndarray, at_b: np.ndarray, slot_b=None,
             rows=None) -> None:
    """``dst[at_b, slot_b] = src`` (``dst[at_b] = src`` without ``slot_b``),
    for the rows ``rows`` of ``src``, ``at_b`` and ``slot_b`` only where
    given: per-bond state put back in place.  The C twin makes one pass
    without NumPy's gathered temporaries (a quarter of the time of a ves
    step on the PERI benchmark block went to them); same errors either way."""
    twin = NATIVE.get("put_rows")
    if twin is not None and twin(dst, src, at_b, slot_b, rows) is not NotImplemented:
        return
    if rows is not None:
        src, at_b = src[rows], at_b[rows]
        slot_b = None if slot_b is None else slot_b[rows]
    dst[at_b if slot_b is None else (at_b, slot_b)] = src


def any_nonzero(values: np.ndarray) -> bool:
    """Is some value not zero?  (The C twin stops at the first.)"""
    twin = NATIVE.get("any_nonzero")
    if twin is not None:
        value = twin(values)
        if value is not NotImplemented:
            return value
    return bool(values.any())


def first_non_finite(values: np.ndarray) -> Optional[int]:
    """The first atom (row) with a value that is not finite, or None."""
    if all_finite(values):
        return None
    return int(np.argwhere(~np.isfinite(values))[0][0])


def require_finite(name: str, values: np.ndarray) -> None:
    """Raise ``ValueError`` naming the array and the first bad atom."""
    atom = first_non_finite(values)
    if atom is not None:
        raise ValueError(f"{name} of atom {atom} is not finite: {values[atom]}")


def particle_types(atoms: Atoms) -> np.ndarray:
    """``atoms.arrays["type"]`` (all 1 when absent), checked to be ints >= 1."""
    if "type" not in atoms.arrays:
        return np.ones(len(atoms), dtype=np.int64)
    types = atoms.arrays["type"]
    if (types.ndim != 1 or types.dtype.kind not in "iuf"
            or not (types.dtype.kind in "iu" or np.all(np.mod(types, 1) == 0))):
        raise ValueError('atoms.arrays["type"] must hold one integer per atom, got shape '
                         f"{types.shape} and dtype {types.dtype}")
    if types.dtype != np.int64:
        types = types.astype(np.int64)
    if len(types) and types.min() < 1:
        atom = int(np.argmin(types))
        raise ValueError(f'particle type {types[atom]} of atom {atom} is invalid: '
                         'types are integers >= 1')
    return types


def positive_masses(m_n: np.ndarray) -> np.ndarray:
    """The masses, checked finite and positive (``ValueError`` naming the
    first atom that is not)."""
    if len(m_n) and not (m_n.min() > 0 and all_finite(m_n)):
        atom = int(np.argmax(~((m_n > 0) & np.isfinite(m_n))))
        raise ValueError(f"mass of atom {atom} is {m_n[atom]}: masses must be finite and "
                         "positive")
    return m_n


def velocities(atoms: Atoms, masses=None) -> np.ndarray:
    """Velocities from momenta and masses (``atoms.get_masses()`` unless
    given), checked to be finite; zero for atoms held by ``FixAtoms`` (which do
    not move, whatever momenta they carry).  A new array (:attr:`Inputs.velocities`'
    values)."""
    known = None if masses is None else {"masses": positive_masses(masses)}
    return Inputs(atoms, known).velocities.copy()


def checked_masses(atoms: Atoms) -> np.ndarray:
    """``atoms.get_masses()``, checked finite and positive, read-only.  While
    ``atoms.arrays["masses"]`` holds the values last checked, the same array
    is returned without a new check (scenes keep their masses)."""
    return Inputs(atoms).masses


#: the masses checked last, as given and as returned
_checked_masses = [None, None]
#: (masses, the same per component) of the last call of per_component
_per_component = [None, None]


def per_component(m_n: np.ndarray) -> np.ndarray:
    """``m_n[:, None]`` as an n x 3 array: the same quotients, but numpy
    divides by it several times faster than by a broadcast column (kept for a
    read-only ``m_n``, such as the checked masses)."""
    kept = _per_component
    if kept[0] is m_n and not m_n.flags.writeable:
        return kept[1]
    m_nc = np.repeat(m_n, 3).reshape(-1, 3)
    if not m_n.flags.writeable:
        kept[:] = [m_n, m_nc]
    return m_nc


def same_array(a, b, *pairs) -> bool:
    """Both absent, or arrays of the same shape, type and bytes (so NaN equals
    NaN); with more ``pairs`` (``(a, b)`` tuples), each of them too, in one
    call (the state checks compare several).  The bytes are compared in
    place, as unsigned integers of the items' width (``tobytes`` would copy
    both arrays: 40 ms for a million positions, against 1.5 ms).  Small
    arrays are still copied: up to ``SMALL_BYTES`` the copies cost less than
    the in-place comparison's calls (0.7 against 4 us for 500 positions, 4.2
    against 5.4 for 3,000; a step compares a dozen).  The C twin
    (:data:`NATIVE`) compares C-contiguous arrays in place whatever their
    size (0.2 us for 500 positions)."""
    twin = NATIVE.get("same_bytes")
    for a, b in ((a, b), *pairs):
        if a is b:
            continue
        if a is None or b is None or a.shape != b.shape or a.dtype != b.dtype:
            return False
        if twin is not None and not a.dtype.hasobject:
            same = twin(a, b)  # memcmp in place
            if same is not NotImplemented:
                if not same:
                    return False
                continue
        if a.dtype.hasobject or a.nbytes <= SMALL_BYTES:
            if a.tobytes() != b.tobytes():
                return False
        elif not np.array_equal(_raw(a), _raw(b)):
            return False
    return True


#: arrays up to this size are compared by copies of their bytes (same_array)
SMALL_BYTES = 131072


def _raw(a: np.ndarray) -> np.ndarray:
    """The bytes of ``a`` as a flat array of unsigned integers."""
    a = np.ascontiguousarray(a).reshape(-1)
    width = a.dtype.itemsize
    return a.view(f"u{width}" if width in (1, 2, 4, 8) else "u1")


class Inputs:
    """The per-atom inputs of one evaluation, each read and checked once and
    shared by the model and its fixes (read-only: nobody may change them).
    The spins and particle types are read-only views of the atoms' own
    arrays, which stay writable (an integrator turns the spheres in place
    after the evaluation): caches that trust a read-only array not to change
    (``InputDigests``, ``Gravity``'s weights, a search's radii, a pair
    table's rows) may keep them across evaluations only because a new
    evaluation makes new ones, unless it hands on the values of the last
    one (``known``, :meth:`kept`), which its caller has found unchanged (the
    ordinary step, :class:`ase_bpm.models.lifecycle.Seen`).

    ``atoms`` is only read.  Each input is an attribute (``inputs.velocities``,
    ``masses``, ``types``, ``omega``, ``orientations``, ``frozen``; ``radii(who)`` names who
    asks), read and checked when first asked for, with the errors of the
    functions it calls (:func:`velocities`, :func:`particle_types`,
    :func:`ase_bpm.core.spheres.radii`...), and a plain attribute from then
    on (a step asks for the velocities and masses several times).
    """

    def __init__(self, atoms: Atoms, known: Optional[dict] = None):
        self.atoms = atoms
        self._radii = None
        if known:  # checked by an evaluation of the same values (Inputs.kept)
            self.__dict__.update(known)

    #: the inputs an evaluation may hand to the next one where their arrays
    #: (masses or numbers, ``type``, ``radius``) keep their values
    REUSABLE = ("masses", "masses_c", "types", "_radii")

    def kept(self) -> dict:
        """The inputs read so far that the next evaluation may take as
        ``known`` (of :data:`REUSABLE`), where the caller has made sure that
        the arrays they were read from keep their values: the velocities and
        spins change at every step, and the constraints are read afresh."""
        read = self.__dict__
        known = {}
        for name in self.REUSABLE:
            value = read.get(name)
            if value is not None and value.base is not None:
                # a view of the atoms' own array, which the user may detach
                # (an equal copy put in its place) and then change: a copy
                value = value.copy()
                value.flags.writeable = False
            if value is not None:
                known[name] = value
        return known

    @cached_property
    def masses(self) -> np.ndarray:
        """:func:`checked_masses`: the same read-only array while the masses
        keep the values last checked (in this process: one comparison)."""
        given = self.atoms.arrays.get("masses")
        kept = _checked_masses
        if given is not None and kept[0] is not None and same_array(kept[0], given):
            return kept[1]
        m_n = positive_masses(self.atoms.get_masses())
        m_n.flags.writeable = False
        if given is not None:
            kept[:] = [given.copy(), m_n]
        return m_n

    @cached_property
    def masses_c(self) -> np.ndarray:
        """The masses as an n x 3 array (:func:`per_component`)."""
        return per_component(self.masses)

    @cached_property
    def velocities(self) -> np.ndarray:
        """Momenta over masses, checked finite (``ValueError`` naming the
        first atom that is not); zero for atoms held by ``FixAtoms``.
        Read-only."""
        momenta = self.atoms.arrays.get("momenta")
        if momenta is None:
            v_nc = np.zeros((len(self.atoms), 3))
        else:
            v_nc = momenta / self.masses_c
            if not all_finite(v_nc):
                require_finite("velocity", v_nc)
            if self.atoms.constraints and self.frozen is not None:
                v_nc[self.frozen] = 0.0
        v_nc.flags.writeable = False  # (a new array)
        return v_nc

    @cached_property
    def types(self) -> np.ndarray:
        """:func:`particle_types` (read-only)."""
        return _read_only(particle_types(self.atoms))

    def radii(self, who: str) -> np.ndarray:
        r_n = self._radii
        if r_n is None:
            r_n = self._radii = _read_only(_spheres.radii(self.atoms, who))
        return r_n

    @cached_property
    def omega(self) -> np.ndarray:
        """:func:`ase_bpm.core.spheres.angular_velocities` (read-only)."""
        return _read_only(_spheres.angular_velocities(self.atoms))

    @cached_property
    def orientations(self) -> np.ndarray:
        """:func:`ase_bpm.core.spheres.orientations` (read-only)."""
        return _read_only(_spheres.orientations(self.atoms))

    @cached_property
    def frozen(self):
        """Mask of the atoms held by ``FixAtoms`` (None when there are none)."""
        return _spheres.frozen(self.atoms) if self.atoms.constraints else None


def _read_only(value: np.ndarray) -> np.ndarray:
    """``value``, or a read-only view of it (the atoms' own array, if it is
    one, stays writable)."""
    if value.flags.writeable:
        value = value.view()
        value.flags.writeable = False
    return value


from . import spheres as _spheres  # noqa: E402  (spheres imports this module)
