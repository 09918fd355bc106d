"""LAMMPS data files in bulk: numbers written as text by array arithmetic read
back bit for bit, sections parsed whole, and a line that cannot be read is
still named by its number."""

import io
import re

import numpy as np
import pytest

import ase_bpm
from ase_bpm.core.bonds import find_sorted
from ase_bpm.core.text_columns import FAST_RANGE, float_text, int_text, write_rows
from scenes import fcc_cluster


def text_of(columns, count):
    out = io.BytesIO()
    write_rows(out, columns, count)
    return out.getvalue().decode()


def awkward_floats(rng, count):
    """Random bit patterns (every exponent, subnormals), the edges of the fast
    range, powers of ten and their neighbours, zeros of both signs."""
    random = rng.integers(0, 2 ** 63, count, dtype=np.int64).view(np.float64)
    random = random[np.isfinite(random)] * rng.choice([-1.0, 1.0], count)[np.isfinite(random)]
    powers = np.array([float(f"1e{p}") for p in range(-323, 309)])
    edges = np.array([*FAST_RANGE, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308,
                      0.1, 1 / 3, 2.0, 2.0 ** 53, 2.0 ** 53 + 2, 1e16, 1e17])
    return np.concatenate([[0.0, -0.0, 1e-300, -1e-300], random, edges,
                           -edges, powers, np.nextafter(powers, 0), np.nextafter(powers, 2e308)])


def test_floats_written_in_bulk_read_back_bit_for_bit():
    x = awkward_floats(np.random.default_rng(0), 200_000)
    text = text_of([x], len(x))
    back = np.array([float(word) for word in text.split()])
    assert np.array_equal(back.view(np.int64), x.view(np.int64))  # (-0.0 kept too)
    loaded = np.loadtxt(io.StringIO(text))  # as read_lammps reads them
    assert np.array_equal(loaded.view(np.int64), x.view(np.int64))
    assert text.split()[:4] == ["0.0", "-0.0", "1e-300", "-1e-300"]


def test_float_text_has_at_most_17_significant_digits_and_no_padding():
    rng = np.random.default_rng(1)
    x = rng.uniform(-1e3, 1e3, 10_000) * 10.0 ** rng.integers(-200, 200, 10_000)
    words = text_of([x], len(x)).split()
    mantissas = [re.sub(r"[-.]", "", w.split("e")[0]) for w in words]
    assert max(len(m) for m in mantissas) == 17 and all(m[-1] != "0" or len(m) == 1
                                                         for m in mantissas)
    assert "\0" not in "".join(words)
    assert float_text(np.array([2.5]))[0].tobytes().replace(b"\0", b"") == b"2.5"


def test_integers_written_in_bulk_are_their_decimal_text():
    n = np.array([0, 7, 9, 10, 99, 9999, 10_000, 12_345_678, 10 ** 8, 2 ** 62, 10 ** 18])
    assert text_of([n, "x", n[::-1]], len(n)).splitlines() == [
        f"{a} x {b}" for a, b in zip(n.tolist(), n[::-1].tolist())]
    with pytest.raises(ValueError, match="from 0 up, got -1"):
        int_text(np.array([3, -1]))


def test_find_sorted_finds_what_searchsorted_finds():
    rng = np.random.default_rng(2)
    for ids in (rng.integers(1, 2 ** 62, 5000), np.arange(1, 5001) * 7,
                np.concatenate([np.arange(1, 5000), [2 ** 61]]),  # (bunched: halving)
                rng.integers(-2 ** 62, 2 ** 62, 5000)):  # (a span beyond int64: halving)
        ids = np.sort(ids)
        keys = np.concatenate([ids[rng.integers(0, len(ids), 30_000)],
                               rng.integers(-3, 2 ** 62, 500), [ids[0] - 1, ids[-1] + 1]])
        at = find_sorted(ids, keys)
        assert at.min() >= 0 and at.max() < len(ids)
        present = np.isin(keys, ids)
        assert np.array_equal(ids[at] == keys, present)
        assert np.array_equal(at[present], np.searchsorted(ids, keys[present]))


def awkward_scene():
    """A bonded block whose positions and velocities hold awkward floats."""
    atoms, rng = fcc_cluster(3, seed=11, ntypes=2, masses=(1 / 3, 7e-300))
    ase_bpm.create_bonds(atoms, 1.25)
    odd = np.array([1e-300, -0.0, 5e-324, -2.2250738585072014e-308, 1e300, 0.1,
                    1e23, 9.999999999999999e22, 123456789.123456789])
    x = atoms.positions.copy()
    x[: len(odd), 0] += odd  # (tiny ones vanish against the coordinate: set some alone)
    x[1, 1], x[2, 2], x[3, 1] = -0.0, 1e-300, 5e-324
    atoms.positions = x
    v = rng.normal(0, 1, x.shape) * 10.0 ** rng.integers(-300, 300, x.shape)
    v[: len(odd), 2] = odd
    atoms.set_velocities(v)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.1)}, timestep=0.1)
    return atoms


def test_awkward_values_come_back_bit_for_bit(tmp_path):
    atoms = awkward_scene()
    data, deck = ase_bpm.write_lammps(str(tmp_path / "odd"), atoms)
    back = ase_bpm.read_lammps(data, deck)
    for array in ("positions", "momenta", "masses", "numbers"):
        assert np.array_equal(back.arrays[array].view(np.uint8),
                              atoms.arrays[array].view(np.uint8)), array
    assert sorted(map(tuple, np.column_stack(ase_bpm.get_bonds(back)))) == sorted(
        map(tuple, np.column_stack(ase_bpm.get_bonds(atoms))))


def written(tmp_path, edit=None):
    """A small scene written, its data file's lines changed by ``edit``."""
    atoms, _ = fcc_cluster(2, seed=12)
    ase_bpm.create_bonds(atoms, 1.25)
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.5, 0.1)}, timestep=0.1)
    data, deck = ase_bpm.write_lammps(str(tmp_path / "scene"), atoms)
    lines = open(data).read().splitlines()
    if edit:
        with open(data, "w") as fh:
            fh.write("\n".join(edit(lines)) + "\n")
    return atoms, data, deck, lines


def first_line(lines, section):
    """The index of the first row of ``section`` (lines are numbered from 1)."""
    return lines.index(section) + 2


def test_rows_out_of_order_with_comments_and_blank_lines_are_read(tmp_path):
    def shuffle(lines):
        k = first_line(lines, "Atoms # bond")
        rows = lines[k:k + 32]
        rows = rows[::-1]
        rows[5] = rows[5].split("#")[0]  # no symbol: X
        rows[7] = rows[7].split("#")[0] + "# Ar and more"
        return lines[:k] + ["# a comment", ""] + rows + lines[k + 32:]

    atoms, data, deck, _ = written(tmp_path, shuffle)
    back = ase_bpm.read_lammps(data, deck)
    assert np.array_equal(back.positions, atoms.positions)
    symbols = list(atoms.symbols)
    symbols[31 - 5], symbols[31 - 7] = "X", "Ar"
    assert list(back.symbols) == symbols


@pytest.mark.parametrize("section,row,new,message", [
    ("Atoms # bond", 3, "4 0 1 0.5 0.5", r"line {}: Atoms needs 6 columns, got '4 0 1 0.5 0.5'"),
    ("Atoms # bond", 4, "5 0 1 0.5 abc 0.5", r"line {}: Atoms: 'abc' is not a number"),
    ("Atoms # bond", 5, "6 0 1 0.5 1_0 0.5", r"line {}: Atoms: '1_0' is not a number"),
    ("Atoms # bond", 2, "3.5 0 1 0.5 0.5 0.5", r"line {}: Atoms: atom ID 3.5 is not an integer"),
    ("Atoms # bond", 6, "2 0 1 0.5 0.5 0.5", r"line {}: atom ID 2 out of 1..32 or given twice"),
    ("Atoms # bond", 1, "33 0 1 0.5 0.5 0.5", r"line {}: atom ID 33 out of 1..32 or given "
                                               r"twice"),
    ("Velocities", 5, "6 0.1 0.2", r"line {}: Velocities needs 4 columns"),
    ("Bonds", 2, "3 1 4", r"line {}: Bonds needs 4 columns, got '3 1 4'"),
    ("Bonds", 0, "1 1 1.0 2", r"line {}: Bonds: '1.0' is not an integer"),
    ("Bonds", 7, "8 1 3 40", r"line {}: Bonds: atom ID 40 out of 1..32"),
    ("Bonds", 4, "5 1 0 3", r"line {}: Bonds: atom ID 0 out of 1..32"),
])
def test_a_line_that_cannot_be_read_is_named(tmp_path, section, row, new, message):
    def spoil(lines):
        lines[first_line(lines, section) + row] = new
        return lines

    _, data, deck, lines = written(tmp_path, spoil)
    number = first_line(lines, section) + row + 1
    with pytest.raises(ValueError, match=re.escape(data) + " " + message.format(number)):
        ase_bpm.read_lammps(data, deck)


def test_a_missing_atom_id_is_named(tmp_path):
    _, data, deck, _ = written(tmp_path, lambda lines: [
        line for line in lines if not line.startswith("17 0 1 ")])
    with pytest.raises(ValueError, match=re.escape(data) + ": Atoms lacks atom ID 17"):
        ase_bpm.read_lammps(data, deck)
    _, data, deck, _ = written(tmp_path, lambda lines: lines[:first_line(lines, "Velocities")]
                               + lines[first_line(lines, "Velocities") + 1:])
    with pytest.raises(ValueError, match="Velocities lacks atom ID 1$"):
        ase_bpm.read_lammps(data, deck)
