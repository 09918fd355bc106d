"""The orientation of bpm/sphere particles (``atoms.arrays["quat"]``, N x 4,
LAMMPS's ``(w, i, j, k)``) lives on the atoms: it survives ``atoms.copy()``,
masks, ``a + b``, restart files (ase_bpm's own and ASE's ``ase-bpm``
format) bit for bit and extxyz files to their 8 decimals; viewer frames carry
it as the column OVITO reads as its ``Orientation`` (X, Y, Z, W)."""

import ase.io
import numpy as np
import pytest
from ase import Atoms

import ase_bpm
from ase_bpm.core.spheres import QUAT, QUAT_NORM_TOLERANCE, orientations
from scenes import sphere_pile


def oriented(atoms: Atoms, seed: int = 0) -> Atoms:
    """``atoms`` with a random orientation each (unit quaternions, w of either sign)."""
    q_nq = np.random.default_rng(seed).normal(size=(len(atoms), 4))
    atoms.arrays[QUAT] = q_nq / np.linalg.norm(q_nq, axis=1)[:, None]
    return atoms


@pytest.fixture
def balls():
    return oriented(sphere_pile(seed=4))


def test_copies_and_masks_keep_each_orientation_bit_for_bit(balls):
    q_nq = balls.arrays[QUAT].copy()
    assert np.array_equal(balls.copy().arrays[QUAT], q_nq)
    mask = np.arange(len(balls)) % 3 != 1
    assert np.array_equal(balls[mask].arrays[QUAT], q_nq[mask])
    order = np.argsort(balls.positions[:, 0])
    assert np.array_equal(balls[order].arrays[QUAT], q_nq[order])
    assert np.array_equal(orientations(balls[mask]), q_nq[mask])


def test_added_atoms_keep_their_orientations(balls):
    other = oriented(sphere_pile(seed=5), seed=1)
    both = balls + other
    assert np.array_equal(both.arrays[QUAT],
                          np.concatenate([balls.arrays[QUAT], other.arrays[QUAT]]))
    assert np.array_equal(orientations(both), both.arrays[QUAT])


def test_atoms_added_without_orientations_are_refused_naming_the_remedy(balls):
    """ASE fills the rows of atoms added without the array with zeros, which
    are no orientation: refused, naming the atom and the remedy (before, the
    message spoke of a norm of 0 only)."""
    plain = sphere_pile(seed=5)
    both = balls + plain
    with pytest.raises(ValueError, match=rf'atoms.arrays\["quat"\] of atom {len(balls)} is '
                                         r"all zero, as ASE fills the rows of atoms that had "
                                         r"no orientation .* \(a \+ b, extend, where b has "
                                         r'no "quat"\): give b its orientations'):
        orientations(both)
    plain.arrays[QUAT] = np.tile([1.0, 0.0, 0.0, 0.0], (len(plain), 1))  # (the remedy)
    assert np.array_equal(orientations(balls + plain)[len(balls):], plain.arrays[QUAT])


@pytest.mark.parametrize("how", ["write_restart", "ase-bpm"])
def test_restart_files_keep_each_orientation_bit_for_bit(balls, tmp_path, how):
    path = str(tmp_path / "run.bpm")
    if how == "write_restart":
        ase_bpm.write_restart(path, balls)
        back = ase_bpm.read_restart(path)
    else:
        ase.io.write(path, balls)
        back = ase.io.read(path)
    assert back.arrays[QUAT].dtype == np.float64
    assert np.array_equal(back.arrays[QUAT], balls.arrays[QUAT])


def test_extxyz_keeps_each_orientation_to_its_eight_decimals(balls, tmp_path):
    path = str(tmp_path / "run.extxyz")
    ase.io.write(path, balls)
    back = ase.io.read(path)
    assert np.abs(back.arrays[QUAT] - balls.arrays[QUAT]).max() <= 5e-9
    norm_n = np.linalg.norm(back.arrays[QUAT], axis=1)
    assert np.abs(norm_n - 1).max() < QUAT_NORM_TOLERANCE  # (still orientations)
    assert np.array_equal(orientations(back), back.arrays[QUAT])


def _properties(path) -> str:
    """The Properties= of the first frame's comment line."""
    comment = open(path).read().splitlines()[1]
    return next(word for word in comment.split() if word.startswith("Properties="))


def test_a_viewer_frame_carries_the_orientation_as_ovito_reads_it(balls, tmp_path):
    """OVITO maps a column ``orientation`` to its Orientation, components X,
    Y, Z, W: the vector part first."""
    path = str(tmp_path / "view.extxyz")
    with ase_bpm.ViewerTrajectory(path, balls, arrays=["quat"]) as traj:
        traj.write()
    assert ":orientation:R:4" in _properties(path)
    assert ":quat:" not in _properties(path)  # (asked for, it adds nothing)
    frame = ase.io.read(path)
    w_n, i_n, j_n, k_n = balls.arrays[QUAT].T
    assert np.abs(frame.arrays["orientation"] - np.column_stack([i_n, j_n, k_n, w_n])).max() \
        <= 5e-9


@pytest.mark.parametrize("asked", [None, "orientation", "quat"])
def test_the_orientation_is_one_column_however_asked_for(balls, tmp_path, asked):
    path = str(tmp_path / "view.extxyz")
    with ase_bpm.ViewerTrajectory(path, balls, arrays=asked) as traj:
        traj.write()
    assert _properties(path).count("orientation") == 1 and "quat" not in _properties(path)


def test_a_viewer_frame_has_no_orientation_where_the_atoms_have_none(tmp_path):
    path = str(tmp_path / "view.extxyz")
    with ase_bpm.ViewerTrajectory(path, sphere_pile(seed=4)) as traj:
        traj.write()
    assert "orientation" not in _properties(path)
    with pytest.raises(ValueError, match=r"no per-atom array 'orientation'"):
        ase_bpm.ViewerTrajectory(path, sphere_pile(seed=4), arrays=["orientation"])


def test_a_viewer_frame_of_atoms_added_without_orientations_is_refused(balls, tmp_path):
    path = str(tmp_path / "view.extxyz")
    with ase_bpm.ViewerTrajectory(path, balls) as traj:
        with pytest.raises(ValueError, match=r"all zero"):
            traj.write(balls + sphere_pile(seed=5))
