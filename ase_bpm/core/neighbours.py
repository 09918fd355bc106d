"""Pair search with matscipy and a Verlet skin.

LAMMPS equivalent: ``neighbor <skin> bin`` with ``neigh_modify every 1 delay 0
check yes``: the list holds every pair within ``cutoff + skin`` and is rebuilt
exactly when some atom has moved more than half the skin since the last build
(or the cell, the periodicity or the number of atoms changed).  The list of
spheres (:class:`SphereVerletList`) looks at how the spheres moved relative
to one another: a drift they share (a falling heap) changes no pair, and
it is rebuilt when the two spheres that moved furthest from that drift
together moved more than the skin (LAMMPS: either of them more than half).

Pair vectors follow matscipy: ``r_pc = x[j] - x[i] + shift_pc``, pointing from
``i`` to ``j``.  A Verlet list built with no periodic direction keeps no
shifts (``shift_pc`` None: they would all be zero, 24 bytes a pair).
"""

from __future__ import annotations

import numpy as np
from ase.geometry.cell import complete_cell
from matscipy.neighbours import neighbour_list

from .arrays import NATIVE


def periodic_half_widths(cell, pbc) -> float:
    """Half the smallest width of the cell across its periodic directions.

    Vectors shorter than this have a unique minimum image.  ``inf`` when no
    direction is periodic.
    """
    pbc = np.asarray(pbc, dtype=bool)
    if not pbc.any():
        return np.inf
    cell = np.asarray(cell, dtype=float)
    volume = abs(np.linalg.det(cell))
    widths = []
    for k in np.flatnonzero(pbc):
        a, b = cell[(k + 1) % 3], cell[(k + 2) % 3]
        widths.append(volume / np.linalg.norm(np.cross(a, b)))
    return 0.5 * min(widths)


def minimum_image(r_xc: np.ndarray, cell, pbc) -> np.ndarray:
    """Vectors ``r_xc`` mapped to their minimum image along periodic
    directions (``r_xc`` itself where that changes nothing: no periodic
    direction, or an orthorhombic cell and no component longer than half its
    shortest periodic edge, as a step's displacements)."""
    pbc = np.asarray(pbc, dtype=bool)
    if not pbc.any():
        return r_xc
    cell = np.asarray(cell, dtype=float)
    if np.count_nonzero(cell - np.diag(np.diag(cell))) == 0:  # orthorhombic: per axis
        if _within_half(r_xc, np.abs(np.diag(cell))[pbc].min()):
            return r_xc
        r_xc = r_xc.copy()
        for k in np.flatnonzero(pbc):
            length = cell[k, k]
            r_xc[:, k] -= length * np.round(r_xc[:, k] / length)
        return r_xc
    s_xc = r_xc @ np.linalg.inv(cell)
    s_xc[:, pbc] -= np.round(s_xc[:, pbc])
    return s_xc @ cell


def _within_half(r_xc: np.ndarray, edge: float) -> bool:
    """Is no component of ``r_xc`` longer than half of ``edge`` (> 0)?  Then
    every ``round(r / length)`` of :func:`minimum_image` is zero, and the
    rounding would give back ``r_xc`` (but for the sign of a zero).  Two
    passes over the flat array without temporaries: a tenth of the
    rounding's cost.  NaN, or an edge of zero, answers no."""
    if not r_xc.size:
        return True
    half = 0.5 * edge
    return bool(half > 0.0 and r_xc.max() <= half and r_xc.min() >= -half)


def _search_cell(positions, cell, pbc, cutoff):
    """Cell and origin that matscipy can bin efficiently.

    Along non-periodic directions the cell vector is stretched (and the origin
    moved) to span the atoms; matscipy fails on a singular cell and is slow
    when atoms lie far outside a non-periodic cell.
    """
    pbc = np.asarray(pbc, dtype=bool)
    cell = np.array(cell, dtype=float)
    zero = np.linalg.norm(cell, axis=1) == 0.0
    if (zero & pbc).any():
        raise ValueError(f"cell vector {np.flatnonzero(zero & pbc)[0]} is zero "
                         "along a periodic direction")
    cell = complete_cell(cell)  # zero vectors become orthogonal unit vectors
    origin = np.zeros(3)
    if (~pbc).any() and len(positions):
        s_nc = positions @ np.linalg.inv(cell)
        for k in np.flatnonzero(~pbc):
            lo, hi = s_nc[:, k].min(), s_nc[:, k].max()
            length = np.linalg.norm(cell[k])
            origin = origin + lo * cell[k]
            cell[k] = cell[k] * ((hi - lo) + cutoff / length + 1e-9)
    return cell, origin


#: beyond this many bins of the cutoff's size (and BINS_PER_ATOM per atom), a
#: scene is searched with a k-d tree where one fits (:func:`_tree_fits`):
#: binning a box that atoms spread over (a far particle, an exploded body)
#: takes seconds in matscipy, a tree takes no longer than for a compact scene
MAX_BINS = 10 ** 6
BINS_PER_ATOM = 64


def _bins(search_cell, reach: float) -> float:
    """How many bins of side ``reach`` the search cell holds."""
    return float(np.prod(np.maximum(np.linalg.norm(search_cell, axis=1) / reach, 1.0)))


def _tree_fits(cell, pbc, reach: float) -> bool:
    """Can the k-d tree search this scene?  With no periodic direction,
    always; else the cell must be orthorhombic (scipy's periodic box) and
    wider than twice the reach along each periodic direction (one image per
    pair; matscipy handles the others)."""
    pbc = np.asarray(pbc, dtype=bool)
    if not pbc.any():
        return True
    cell = np.asarray(cell, dtype=float)
    if np.count_nonzero(cell - np.diag(np.diag(cell))):
        return False
    return bool(np.all(np.diag(cell)[pbc] > 2.0 * reach))


def _tree_pairs(positions, cutoff, reach: float, cell=None, pbc=(False, False, False)):
    """:func:`neighbour_pairs` by a k-d tree, for scenes :func:`_tree_fits`:
    the same pairs (closer than ``cutoff``, or than the sum of the two
    reaches), ``i < j``, with their shifts along periodic directions."""
    from scipy.spatial import cKDTree

    pbc = np.asarray(pbc, dtype=bool)
    x_nc = positions - positions.min(axis=0)
    box_c = 2.0 * x_nc.max(axis=0) + 2.0 * reach + 1.0  # never wraps where not periodic
    if pbc.any():
        length_c = np.diag(np.asarray(cell, dtype=float))
        x_nc[:, pbc] = np.mod(positions[:, pbc], length_c[pbc])
        x_nc[:, pbc] = np.where(x_nc[:, pbc] >= length_c[pbc], 0.0, x_nc[:, pbc])
        box_c[pbc] = length_c[pbc]
    tree = cKDTree(x_nc, boxsize=box_c if pbc.any() else None)
    ij = tree.query_pairs(reach, output_type="ndarray").astype(np.int64)
    i_p, j_p = ij[:, 0], ij[:, 1]
    d_pc = positions[j_p] - positions[i_p]
    shift_pc = np.zeros_like(d_pc)
    for k in np.flatnonzero(pbc):  # the one image within reach
        shift_pc[:, k] = -length_c[k] * np.round(d_pc[:, k] / length_c[k])
    d_pc += shift_pc
    limit_p = cutoff[i_p] + cutoff[j_p] if np.ndim(cutoff) else cutoff
    keep = np.einsum("pc,pc->p", d_pc, d_pc) < limit_p * limit_p
    return i_p[keep], j_p[keep], shift_pc[keep]


def neighbour_pairs(positions, cell, pbc, cutoff, open_shifts: bool = True,
                    in_order: bool = False):
    """Every pair within ``cutoff``, each once: ``(i_p, j_p, shift_pc)``.

    ``cutoff`` is a distance, or one reach per atom (an array): then a pair is
    listed when closer than the sum of the two reaches (spheres: radius plus
    half the skin).  ``shift_pc`` is the Cartesian image shift, so
    ``x[j] - x[i] + shift`` is the pair vector; with no periodic direction
    it is zeros, or None with ``open_shifts=False``.  A pair listed twice by
    matscipy (``i->j`` and ``j->i``) is kept as ``i < j``; an atom near its own
    periodic image keeps one of the two images.  The indices are int64.
    ``in_order``: the pairs in order of ``(i, j)``, as :func:`in_pair_order`
    puts them (a Verlet list's, whose sums then do not depend on where it
    was built), in one pass in C where the library is built.
    """
    positions = np.asarray(positions, dtype=float)
    pbc = np.asarray(pbc, dtype=bool)
    if len(positions) == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z.copy(), np.zeros((0, 3)) if open_shifts or pbc.any() else None
    if np.ndim(cutoff):
        cutoff = np.asarray(cutoff, dtype=float)
        reach = 2.0 * float(cutoff.max())
    else:
        cutoff = reach = float(cutoff)
    search_cell, origin = _search_cell(positions, cell, pbc, reach)
    crowded = max(MAX_BINS, BINS_PER_ATOM * len(positions))
    if _bins(search_cell, reach) > crowded and _tree_fits(cell, pbc, reach):
        i_p, j_p, shift_pc = _tree_pairs(positions, cutoff, reach, cell, pbc)
        shift_pc = shift_pc if open_shifts or pbc.any() else None
        if in_order:
            return in_pair_order(len(positions), i_p, j_p, shift_pc)
        return i_p, j_p, shift_pc
    if not pbc.any():  # one image of everything: no shifts to ask for or sort out
        i_p, j_p = neighbour_list("ij", positions=positions, cell=search_cell, pbc=pbc,
                                  cutoff=cutoff, cell_origin=origin)
        return _kept(len(positions), i_p, j_p, i_p < j_p, None, None, open_shifts, in_order)
    i_p, j_p, s_pc = neighbour_list(
        "ijS",
        positions=positions,
        cell=search_cell,
        pbc=pbc,
        cutoff=cutoff,
        cell_origin=origin,
    )
    first_image = (s_pc[:, 0] > 0) | (
        (s_pc[:, 0] == 0) & ((s_pc[:, 1] > 0) | ((s_pc[:, 1] == 0) & (s_pc[:, 2] > 0)))
    )
    keep = (i_p < j_p) | ((i_p == j_p) & first_image)
    return _kept(len(positions), i_p, j_p, keep, s_pc, search_cell, True, in_order)


def _kept(natoms: int, i_p, j_p, keep_p, s_pc, search_cell, shifts: bool, in_order: bool):
    """The pairs ``keep_p`` of matscipy's list (``i_p`` ascending), as
    :func:`neighbour_pairs` gives them: their indices as int64, their
    Cartesian image shifts from the cell shifts ``s_pc`` (None: no periodic
    direction; then zeros with ``shifts``, else None), in order of ``(i,
    j)`` with ``in_order`` (the C twin ``pairs_in_order`` where it takes
    them, else :func:`in_pair_order`: the same order)."""
    count = int(np.count_nonzero(keep_p))
    shift_pc = None if s_pc is None else s_pc[keep_p] @ search_cell
    if shift_pc is None and shifts:
        shift_pc = np.zeros((count, 3))
    twin = NATIVE.get("pairs_in_order") if in_order else None
    if twin is not None:
        i_k, j_k = np.empty(count, dtype=np.int64), np.empty(count, dtype=np.int64)
        rows_k = None if shift_pc is None else np.empty(count, dtype=np.int64)
        if twin(i_p, j_p, keep_p, i_k, j_k, rows_k) is not NotImplemented:
            return i_k, j_k, None if shift_pc is None else shift_pc[rows_k]
    i_p, j_p = i_p[keep_p], j_p[keep_p]
    if in_order:
        return in_pair_order(natoms, i_p, j_p, shift_pc)
    return i_p.astype(np.int64, copy=False), j_p.astype(np.int64, copy=False), shift_pc


_SQRT3 = np.sqrt(3.0)


def moved_more_than(x_nc: np.ndarray, x0_nc: np.ndarray, distance: float) -> bool:
    """Has some atom moved more than ``distance`` from ``x0_nc`` to ``x_nc``?
    (LAMMPS' neighbour-list trigger, at half the skin.)"""
    twin = NATIVE.get("largest_displacement_squared")  # one pass, no temporary
    if twin is not None:
        largest = twin(x_nc, x0_nc, None)
        if largest is not NotImplemented:
            return largest > distance ** 2
    moved = x_nc - x0_nc
    # no component beyond distance / sqrt(3): no atom moved that far (one
    # pass, no temporaries; the full lengths only when it is close, and only
    # of the atoms with such a component)
    if np.abs(moved, out=moved).max(initial=0.0) * _SQRT3 <= distance:
        return False
    return largest_square(moved) > distance ** 2


def largest_square(d_nc: np.ndarray) -> float:
    """The largest ``|d_n|^2`` of the rows of a C-contiguous n x 3 float array,
    which it overwrites (the squares in place, then three columns added: a
    third of ``einsum("nc,nc->n")``'s cost for three columns)."""
    if not len(d_nc):
        return 0.0
    flat = d_nc.reshape(-1)
    flat *= flat
    return float((d_nc[:, 0] + d_nc[:, 1] + d_nc[:, 2]).max())


def two_largest_lengths(d_nc: np.ndarray) -> tuple[float, float]:
    """The two largest ``|d_n|`` of the rows of a C-contiguous n x 3 float
    array, which it overwrites (0 for a row that is not there)."""
    if not len(d_nc):
        return 0.0, 0.0
    flat = d_nc.reshape(-1)
    flat *= flat
    square_n = d_nc[:, 0] + d_nc[:, 1] + d_nc[:, 2]  # as largest_square adds them
    first = int(np.argmax(square_n))
    largest = float(square_n[first])
    square_n[first] = 0.0
    return np.sqrt(largest), np.sqrt(float(square_n.max()))


def in_pair_order(natoms: int, i_p, j_p, shift_pc) -> tuple:
    """The pairs sorted by ``(i, j)`` (pairs listed twice, through two
    periodic images, stay in the order given; ``shift_pc`` may be None),
    their indices as int64 whatever integers they came in.  One stable sort
    of the key ``i * natoms + j``: matscipy lists the pairs by ``i``
    already, and a stable sort of nearly sorted keys costs a tenth of
    ``np.lexsort``.  The key is built in place and dropped before the pairs
    are gathered (peak memory at a rebuild)."""
    key = i_p.astype(np.int64)  # a copy in any case: int64 before the product
    key *= natoms
    key += j_p
    order = np.argsort(key, kind="stable")
    del key
    return (i_p[order].astype(np.int64, copy=False), j_p[order].astype(np.int64, copy=False),
            None if shift_pc is None else shift_pc[order])


class VerletList:
    """Pairs within ``cutoff + skin``, rebuilt only when needed.

    Call :meth:`update` before each force evaluation.  Between rebuilds the
    pairs and their image shifts are reused; an atom that gets wrapped into the
    cell jumps by a lattice vector and so triggers a rebuild.  ``i_p``,
    ``j_p``: the pairs; ``shift_pc``: their image shifts, None when the list
    was built with no periodic direction (all zero).
    """

    def __init__(self, cutoff: float, skin: float):
        if not cutoff > 0:
            raise ValueError(f"neighbour cutoff must be positive, got {cutoff!r}")
        if not skin >= 0:
            raise ValueError(f"skin must be non-negative, got {skin!r}")
        self.cutoff = float(cutoff)
        self.skin = float(skin)
        self.nbuilds = 0
        self._cell = None
        self._pbc = None
        self._forget_pairs()

    def _forget_pairs(self) -> None:
        """No pairs, and no build: the next :meth:`update` builds the list."""
        self._x_build = None
        self.i_p = self.j_p = np.zeros(0, dtype=np.int64)
        self.shift_pc = None
        #: no pair listed twice (through two periodic images), no atom with its
        #: own image: then no two atoms can interact through two images
        self.one_image = True

    def needs_rebuild(self, positions, cell, pbc) -> bool:
        """Must the list be built anew (:meth:`stale`)?"""
        return self.stale(positions, cell, pbc)

    def _apart_too_far(self, positions) -> bool:
        """Past LAMMPS' test (some atom moved more than half the skin since
        the build), must the list be built anew?  Always, here; a list with
        a rule of its own says where it need not (SphereVerletList)."""
        return True

    def update(self, positions, cell, pbc) -> bool:
        """Rebuild the list if needed; return whether it was rebuilt."""
        if not self.stale(positions, cell, pbc):
            return False
        self.rebuild(positions, cell, pbc)
        return True

    def stale(self, positions, cell, pbc) -> bool:
        """Must the list be built anew?  When there is no build for these
        atoms, the cell or the periodicity changed, or the atoms moved too
        far since the build: some atom more than half the skin (LAMMPS'
        test, :func:`moved_more_than`) and, where the list has a rule of its
        own for that case, as that rule says (:meth:`_apart_too_far`)."""
        x_build = self._x_build
        if not (x_build is not None and len(positions) == len(x_build)
                and np.asarray(cell, dtype=float).tobytes() == self._cell.tobytes()
                and np.asarray(pbc, dtype=bool).tobytes() == self._pbc.tobytes()):
            return True
        positions = np.asarray(positions, dtype=float)
        return (moved_more_than(positions, x_build, 0.5 * self.skin)
                and self._apart_too_far(positions))

    def rebuild(self, positions, cell, pbc) -> None:
        """Build the list anew.  The old pairs go before the new ones are
        searched (at a million atoms both lists at once were the peak of a
        run: whoever keeps arrays made from them drops those first, see
        ``ContactList.listed``); should the search fail, the list is empty
        and the next update builds it again."""
        positions = np.asarray(positions, dtype=float)
        cell = np.asarray(cell, dtype=float)
        pbc = np.asarray(pbc, dtype=bool)
        self._forget_pairs()
        self.i_p, self.j_p, self.shift_pc = self._pairs(positions, cell, pbc)
        self.one_image = self._one_image(cell, pbc)
        self._x_build = positions.copy()
        self._cell, self._pbc = cell.copy(), pbc.copy()
        self.nbuilds += 1

    def _pairs(self, positions, cell, pbc):
        """The pairs of a new build, ``(i_p, j_p, shift_pc)``, in order of
        ``(i, j)``: sums over them then do not depend on where the list was
        built (a run continues bit for bit after a restart or a trial move)."""
        return neighbour_pairs(positions, cell, pbc, self.cutoff + self.skin,
                               open_shifts=False, in_order=True)

    def _reach(self) -> float:
        """The longest distance at which a pair is listed."""
        return self.cutoff + self.skin

    def _one_image(self, cell, pbc) -> bool:
        """:attr:`one_image` of the pairs just built: at once where every
        periodic width of the cell is more than twice the reach (two images
        of an atom, or an atom and its own, are a width apart), else from
        the pairs in order, where a pair listed twice sits next to itself."""
        if periodic_half_widths(cell, pbc) > self._reach():
            return True
        i_p, j_p = self.i_p, self.j_p
        return not ((i_p == j_p).any() or ((i_p[1:] == i_p[:-1]) & (j_p[1:] == j_p[:-1])).any())

    def pair_vectors(self, positions, select=slice(None)) -> np.ndarray:
        """``r_pc = x[j] - x[i] + shift`` for the listed pairs (or a subset)."""
        i_p, j_p = self.i_p[select], self.j_p[select]
        r_pc = np.take(positions, j_p, axis=0) - np.take(positions, i_p, axis=0)
        if self.shift_pc is not None:
            r_pc += self.shift_pc[select]
        return r_pc


class SphereVerletList(VerletList):
    """Pairs of spheres closer than ``R_i + R_j + skin``, rebuilt only when
    needed: when the radii changed, or when the spheres moved relative to one
    another by more than the skin can take.  Pairs are listed in order of
    ``(i, j)``, ``i < j``.  LAMMPS: ``neighbor <skin> bin`` for finite-size
    particles, which rebuilds when some sphere moved more than half the skin.

    Relative motion: with ``d_n`` each sphere's displacement since the build
    and any vector ``u``, a pair's vector changed by ``d_j - d_i``, at most
    ``|d_i - u| + |d_j - u|``, so by no more than the two largest
    ``|d_n - u|`` together.  A pair not listed was at least ``R_i + R_j +
    skin`` apart at the build: while those two add up to no more than the
    skin, every pair closer than ``R_i + R_j`` is still listed.  LAMMPS'
    test (``u = 0``, the largest alone at most half the skin) is the case of
    two spheres moving equally far; one sphere ahead of the rest (a rattler,
    the fastest of a gas) gets further before a rebuild, and a drift shared
    by all the spheres (falling, or translated together) costs none.  ``u``
    is the spheres' mean drift, updated only when LAMMPS' test against the
    last ``u`` fails.  Which pairs beyond contact are listed changes no
    result: sums run over the touching pairs in order of ``(i, j)``.
    """

    def __init__(self, skin: float):
        super().__init__(cutoff=1.0, skin=skin)  # cutoffs come from the radii
        self._radii = None
        self._radii_given = None  # the array last given (compared by identity if read-only)

    def update(self, positions, cell, pbc, radii) -> bool:
        """Rebuild the list if needed (new radii, or :meth:`stale`); return
        whether it was rebuilt."""
        radii = np.asarray(radii, dtype=float)
        unchanged = radii is self._radii_given and not radii.flags.writeable  # read-only: same
        if not unchanged and (self._radii is None or radii.tobytes() != self._radii.tobytes()):
            self._x_build = None  # new radii: rebuild
            self._radii = radii.copy()
        self._radii_given = radii
        if not self.stale(positions, cell, pbc):
            return False
        self.rebuild(positions, cell, pbc)
        return True

    def _apart_too_far(self, positions) -> bool:
        """Have the spheres moved relative to one another by more than the
        skin allows (asked where LAMMPS' test fails)?  Have the two spheres
        that moved furthest from the spheres' mean drift together moved
        more than the skin?  Measured from
        ``_x_build``, where they were at the build, carried along with their
        mean drift when they have not (a later step whose spheres all stay
        within half the skin of there passes as cheaply as LAMMPS' test)."""
        moved = positions - self._x_build
        drift = np.einsum("nc->c", moved) / len(moved)  # u: the mean displacement (no BLAS)
        moved -= drift
        first, second = two_largest_lengths(moved)
        if first + second > self.skin:
            return True
        self._x_build += drift
        return False

    def _reach(self) -> float:
        return 2.0 * float(self._radii.max(initial=0.0)) + self.skin

    def _pairs(self, positions, cell, pbc):
        # in order (i, j), as contact history is kept too
        return neighbour_pairs(positions, cell, pbc, self._radii + 0.5 * self.skin,
                               open_shifts=False, in_order=True)
