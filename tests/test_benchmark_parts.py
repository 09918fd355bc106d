"""The machinery the benchmarks print the parts of a step with
(``benchmarks/engines.py``): the probe table of a BPMSpring step points at
callables that exist and are called in a step, the parts table sums what it
says, and a LAMMPS run continued with ``pre no`` (as ``scaling.py`` times
them) still logs the timing breakdown it is read from."""

import os
import sys

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import engines  # noqa: E402
import scaling  # noqa: E402


@pytest.mark.compiled
def test_every_probe_of_a_spring_step_is_called():
    """Each callable of ``spring_probes`` exists and runs in a step of
    scaling.py's block on the compiled kernels (as the benchmarks run), the
    nested ones inside the part they are listed in (never longer), and the
    probes go again afterwards."""
    from ase_bpm import BPMSpring

    probes, within = engines.spring_probes()
    assert set(within) <= set(probes) and set(within.values()) <= set(probes)
    atoms = scaling.readme_block(3)
    atoms.positions *= 1.05  # stretched: contacts and rebuilds in a few steps
    atoms.calc = BPMSpring(bond_coeffs=scaling.BOND_COEFFS, pair_coeffs=scaling.PAIR_COEFFS,
                           kernels="compiled")
    dyn = VelocityVerlet(atoms, timestep=scaling.TIMESTEP)
    atoms.get_forces()
    originals = {name: getattr(owner, attr) for name, (owner, attr) in probes.items()}
    seconds, _, timed = engines.probed_run(dyn.run, 30, probes)
    for name, (owner, attr) in probes.items():
        assert getattr(owner, attr) == originals[name], name  # put back
        assert timed.calls[name] > 0, name
    for inner, outer in within.items():
        assert timed.seconds[inner] <= timed.seconds[outer], inner
    assert timed.seconds["calculator"] < seconds


def test_the_parts_table_gives_each_part_its_own_time_and_the_rest():
    names = ("outer", "a", "b", "c", "alone")
    within = {"a": "outer", "b": "outer", "c": "a"}
    result = dict(seconds=10.0, parts=dict(outer=6.0, a=3.0, b=1.0, c=0.5, alone=1.5),
                  calls=dict(outer=5, a=5, b=5, c=5, alone=4))
    lines = engines.parts_lines([result], 1000, names, within, "alone")
    table = {line.split()[0].rstrip(",") + (" own" if "its own" in line else ""):
             float(line.split()[-2]) for line in lines[1:-1]}
    assert table["outer own"] == pytest.approx(2.0)  # 6 - 3 - 1 s over 1000 steps, ms
    assert table["a own"] == pytest.approx(2.5)
    assert table["the"] == pytest.approx(2.5)  # the rest: 10 - 6 - 1.5
    assert "b own" not in table and "alone own" not in table
    assert lines[-1].split()[-3] == "375.00"  # alone per call: 1.5 s / 4, in ms


def test_a_run_continued_without_setup_logs_its_breakdown(tmp_path):
    from ase_bpm.scene.lammps import lammps_commands, lammps_data

    atoms, calc = scaling.readme_block(2), scaling.readme_calculator()
    data = tmp_path / "scene.data"
    data.write_text(lammps_data(atoms, calc))
    lmp = engines.new_lammps()
    try:
        lmp.commands_list([*lammps_commands(atoms, calc, str(data),
                                            timestep=scaling.TIMESTEP), "run 0"])
        seconds, cpu, breakdown = engines.timed_lammps_run(lmp, 200, str(tmp_path / "log"),
                                                           "pre no")
    finally:
        lmp.close()
    assert breakdown["Bond"] > 0 and breakdown["builds"] >= 0
    parts = sum(breakdown[name] for name in engines.SECTIONS)
    assert 0 < parts <= seconds * 1.01 + 1e-3
    assert np.isfinite(cpu)


def test_every_probe_of_a_rotational_step_is_called():
    """Each callable of ``rotational_probes`` exists and runs in the steps of
    the quick rotational impact (bench_impact.py's second scene), but for
    one of the two routes of the bonds (NumPy or compiled, whichever ase_bpm
    runs); the nested ones inside the part they are listed in; the probes
    go again afterwards."""
    from ase_bpm import SphereVelocityVerlet
    from ase_bpm.scene.demos import impact

    probes, within = engines.rotational_probes()
    assert set(within) <= set(probes) and set(within.values()) <= set(probes)
    atoms = impact.demo_scene(quick=True, bonds="rotational")
    dyn = SphereVelocityVerlet(atoms, timestep=impact.VARIANTS["rotational"].timestep)
    atoms.get_forces()
    originals = {name: getattr(owner, attr) for name, (owner, attr) in probes.items()}
    seconds, _, timed = engines.probed_run(dyn.run, 60, probes)
    routes = {"bonds, NumPy route", "rotational law", "bonds, compiled route"}
    numpy_route = atoms.calc.kernel_routes["bpm/rotational"] == "numpy"
    idle = {"bonds, compiled route"} if numpy_route else {"bonds, NumPy route",
                                                          "rotational law"}
    for name, (owner, attr) in probes.items():
        assert getattr(owner, attr) == originals[name], name  # put back
        assert (timed.calls[name] == 0) == (name in idle), name
    assert timed.calls["rebuilds"] > 0 and timed.calls["bonded pairs"] > 0
    for inner, outer in within.items():
        assert timed.seconds[inner] <= timed.seconds[outer], inner
    assert timed.seconds["calculator"] < seconds
    assert routes <= set(probes)
