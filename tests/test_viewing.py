"""Viewing files: what a viewer shows and nothing of the calculator's state;
OVITO reads the radius and the damage from them."""

import numpy as np
import pytest
from ase.calculators.singlepoint import SinglePointCalculator
from ase.io import read
from ase.md.verlet import VelocityVerlet as AseVelocityVerlet
from ase.optimize import BFGS

import ase_bpm
from ase_bpm import SphereVelocityVerlet, VelocityVerlet
from ase_bpm.scene.viewing import (ViewerTrajectory, display_radius, encloses, is_state,
                                   viewing_copy)
from scenes import fcc_cluster, peri_model, sc_block, sphere_pile


def breaking_block():
    """A bonded block whose bonds break within a few dozen steps, with an
    indenter (a fix) and the whole calculator state on the atoms."""
    atoms, rng = fcc_cluster(4, seed=3)
    ase_bpm.create_bonds(atoms, 1.5)
    atoms.set_velocities(rng.normal(0, 0.08, atoms.positions.shape))
    atoms.calc = ase_bpm.BPMSpring(bond_coeffs={1: (1.0, 0.06, 0.2)},
                                   pair_coeffs={(1, 1): (1.0, 1.0, 0.5)})
    return atoms, VelocityVerlet(atoms, timestep=0.1)


def pile():
    atoms = sphere_pile(n=3, seed=4, lift=0.3)
    atoms.calc = ase_bpm.Granular("hooke/history", kn=2000.0, gamma_n=50.0, xmu=0.5,
                                  fixes=[ase_bpm.Gravity(9.81)])
    return atoms, SphereVelocityVerlet(atoms, timestep=1e-3)


def test_frames_carry_what_a_viewer_shows_and_no_state(tmp_path):
    atoms, dyn = breaking_block()
    with ViewerTrajectory(tmp_path / "run.extxyz", atoms, velocities=True) as traj:
        dyn.attach(traj, interval=20)
        dyn.run(60)
    assert sorted(name for name in atoms.arrays if is_state(name)) == [
        "bond_partner", "bond_r0", "bond_type", "bpm_f_last", "bpm_fd_last", "bpm_id",
        "bpm_x_last", "bpm_x_ref"]  # the state the atoms carry, which the frames leave out
    frames = read(tmp_path / "run.extxyz", ":")
    assert len(frames) == 4
    for frame in frames:
        assert set(frame.arrays) == {"numbers", "positions", "radius", "damage", "nbonds",
                                     "velo"}
        # (the block pokes out of its cell: the frames' positions are translated into a box)
        assert set(frame.info) == {"step", "kinetic_energy", "translation"}
        assert frame.calc is None
    last = frames[-1]
    assert last.info["step"] == 60 and (last.arrays["damage"] > 0).sum() > 5
    assert np.allclose(last.positions - last.info["translation"], atoms.positions, rtol=0,
                       atol=1e-8)
    assert np.allclose(last.arrays["velo"], atoms.get_velocities(), rtol=0, atol=1e-8)
    assert np.array_equal(last.arrays["nbonds"], atoms.arrays["nbonds"])


def test_state_is_refused_by_name(tmp_path):
    atoms, dyn = breaking_block()
    dyn.run(2)
    for name in ("bond_r0", "bpm_x_last", "gran_shear", "peri_theta0", "bonds"):
        with pytest.raises(ValueError, match=rf"\['{name}'\] is calculator state.*write_restart"):
            viewing_copy(atoms, arrays=("damage", name))
    with pytest.raises(ValueError, match=r"\['bpm_f_last'\] is calculator state"):
        ViewerTrajectory(tmp_path / "x.extxyz", atoms, arrays=("bpm_f_last",))
    traj = ViewerTrajectory(tmp_path / "y.extxyz", atoms)
    with pytest.raises(ValueError, match=r"info\['broken_bonds'\] is calculator state"):
        traj.write(broken_bonds=np.zeros((0, 9)))
    traj.close()


def test_display_radius():
    """Spheres: their radius.  Point particles with bonds: half their
    shortest reference bond length, the bonds' length at the first
    evaluation.  Neither: none (a viewer draws the element's size)."""
    spheres, _ = pile()
    assert display_radius(spheres) is spheres.arrays["radius"]

    atoms, dyn = breaking_block()
    assert display_radius(atoms) is None  # bonds without reference lengths yet
    i, j, _ = ase_bpm.get_bonds(atoms)
    shortest = np.linalg.norm(atoms.positions[j] - atoms.positions[i], axis=1).min()
    dyn.run(30)
    assert np.array_equal(display_radius(atoms), np.full(len(atoms), 0.5 * shortest))
    assert "radius" not in viewing_copy(fcc_cluster(2)[0]).arrays


def ovito_frames(path):
    """The particle properties OVITO reads from each frame of ``path``."""
    pytest.importorskip("ovito")
    from ovito.io import import_file

    pipeline = import_file(str(path))
    return [pipeline.compute(n).particles for n in range(pipeline.source.num_frames)]


def test_ovito_reads_radius_and_damage(tmp_path):
    atoms, dyn = breaking_block()
    with ViewerTrajectory(tmp_path / "run.extxyz", atoms, velocities=True) as traj:
        dyn.attach(traj, interval=30)
        dyn.run(60)
    frames = read(tmp_path / "run.extxyz", ":")
    seen = ovito_frames(tmp_path / "run.extxyz")
    assert len(seen) == len(frames) == 3
    for particles, frame in zip(seen, frames):
        # OVITO's standard Radius (the drawn size) and Velocity; damage its own
        assert np.allclose(particles["Radius"], frame.arrays["radius"], rtol=1e-6, atol=0)
        assert np.array_equal(particles["damage"], frame.arrays["damage"])
        assert np.allclose(particles["Velocity"], frame.arrays["velo"], rtol=1e-6, atol=0)
    assert np.asarray(seen[-1]["damage"]).max() > 0


def test_ovito_draws_spheres_at_their_radius(tmp_path):
    atoms, dyn = pile()
    with ViewerTrajectory(tmp_path / "pour.extxyz", atoms, arrays=("ncontacts", "omega")) as traj:
        dyn.attach(traj, interval=10)
        dyn.run(20)
    (particles,) = ovito_frames(tmp_path / "pour.extxyz")[-1:]
    assert np.allclose(particles["Radius"], atoms.arrays["radius"], rtol=1e-6, atol=0)
    assert np.array_equal(particles["ncontacts"], atoms.arrays["ncontacts"])
    assert np.allclose(particles["Angular Velocity"], atoms.arrays["omega"], rtol=0, atol=1e-8)


def test_frames_carry_the_per_atom_stress_on_request(tmp_path):
    """``stress=True``: the analysis' per-atom stress (compute stress/atom),
    which OVITO reads as its Stress Tensor; a model without one says so."""
    atoms, dyn = breaking_block()
    dyn.run(10)
    with ViewerTrajectory(tmp_path / "run.extxyz", atoms, stress=True) as traj:
        traj.write()
    frame = read(tmp_path / "run.extxyz")
    expected = atoms.calc.analyse(atoms).stress_n6
    assert np.abs(expected).max() > 1e-3
    # (ASE's extxyz reader hands a column named stress to the frame's calculator)
    assert np.allclose(frame.calc.results["stress"], expected, rtol=0, atol=1e-8)
    ovito = pytest.importorskip("ovito.io")
    data = ovito.import_file(str(tmp_path / "run.extxyz")).compute()
    assert np.allclose(np.asarray(data.particles["Stress Tensor"]), expected, atol=1e-8)
    from ase.calculators.emt import EMT

    spheres, _ = pile()
    assert viewing_copy(spheres, stress=True).arrays["stress"].shape == (len(spheres), 6)
    spheres.calc = EMT()
    with pytest.raises(ValueError, match="stress=True needs a calculator with analyse"):
        viewing_copy(spheres, stress=True)


# -- the per-atom outputs: declared by each model, the default of a frame ------------

def peri_block(model):
    atoms = sc_block(4)
    atoms.calc = ase_bpm.BPMPeri(bond_coeffs={1: peri_model(model)})
    return atoms


MODEL_SCENES = {  # a scene per model, and the outputs its calculator declares
    "spring": (lambda: breaking_block()[0], ("damage", "nbonds")),
    "pmb": (lambda: peri_block("pmb"), ("damage", "nbonds")),
    "lps": (lambda: peri_block("lps"), ("damage", "nbonds", "dilatation")),
    "eps": (lambda: peri_block("eps"), ("damage", "nbonds", "dilatation")),
    "granular": (lambda: pile()[0], ("ncontacts",)),
}


@pytest.mark.parametrize("model", MODEL_SCENES)
def test_each_model_declares_the_per_atom_outputs_it_writes(model):
    """``calc.per_atom_outputs`` are the arrays an evaluation adds to the
    atoms, calculator state aside."""
    scene, declared = MODEL_SCENES[model]
    atoms = scene()
    assert atoms.calc.per_atom_outputs == declared
    before = set(atoms.arrays)
    atoms.get_forces()
    written = {name for name in set(atoms.arrays) - before if not is_state(name)}
    assert written == set(declared)


@pytest.mark.parametrize("model", MODEL_SCENES)
def test_frames_carry_the_calculators_outputs_by_default(model, tmp_path):
    scene, declared = MODEL_SCENES[model]
    atoms = scene()
    with ViewerTrajectory(tmp_path / "run.extxyz", atoms) as traj:
        atoms.get_forces()
        traj.write()
    (frame,) = read(tmp_path / "run.extxyz", ":")
    assert set(frame.arrays) == {"numbers", "positions", "radius", *declared}
    for name in declared:
        assert np.allclose(frame.arrays[name], atoms.arrays[name], rtol=0, atol=1e-8)


def test_an_unknown_array_is_refused_naming_it_and_the_valid_ones(tmp_path):
    atoms, dyn = breaking_block()
    path = tmp_path / "run.extxyz"
    for name, hint in (("damag", "damage"), ("Damage", "damage"), ("nbond", "nbonds")):
        with pytest.raises(ValueError, match=rf"arrays: no per-atom array '{name}' "
                                             rf"\(did you mean '{hint}'\?\); BPMSpring "
                                             "writes damage, nbonds, and the atoms carry "
                                             "type, masses, momenta$"):
            ViewerTrajectory(path, atoms, arrays=("nbonds", name))
        assert not path.exists()  # refused before the file is opened
    with pytest.raises(ValueError, match=r"no per-atom array 'ncontacts'; BPMSpring writes "
                                         r"damage, nbonds"):
        viewing_copy(atoms, arrays=["ncontacts"])
    for name, flag in (("velo", "velocities"), ("stress", "stress")):
        with pytest.raises(ValueError, match=rf"no per-atom array '{name}' \(ask with "
                                             rf"{flag}=True\); BPMSpring writes"):
            viewing_copy(atoms, arrays=[name])
    spheres, _ = pile()
    with pytest.raises(ValueError, match=r"no per-atom array 'damage'; Granular writes "
                                         r"ncontacts, and the atoms carry radius, masses, "
                                         r"momenta, omega$"):
        ViewerTrajectory(path, spheres, arrays="damage")
    spheres.calc = None
    with pytest.raises(ValueError, match=r"'ncontacts'; the atoms have no calculator, "
                                         r"and the atoms carry radius"):
        viewing_copy(spheres, arrays="ncontacts")
    # not refused: the calculator's outputs before it first wrote them, the atoms'
    # own arrays, one name as a string, the positions every frame has
    with ViewerTrajectory(path, atoms, arrays=("damage", "type", "positions")) as traj:
        assert "damage" not in atoms.arrays
        traj.write()
        dyn.run(3)
        traj.write()
    first, last = read(path, ":")
    assert set(first.arrays) == {"numbers", "positions", "type"}  # nothing evaluated yet
    assert set(last.arrays) == {"numbers", "positions", "radius", "damage", "type"}
    assert set(viewing_copy(atoms, arrays="nbonds").arrays) == {"numbers", "positions",
                                                                "radius", "nbonds"}


# -- the frame's cell encloses the particles -------------------------------------------

def inside(frame) -> bool:
    """Is every particle's centre in the frame's cell, as written (from the
    origin: extxyz has no other)?"""
    s_nc = frame.cell.scaled_positions(frame.positions) if frame.cell.rank == 3 else None
    return s_nc is not None and bool(np.all((s_nc >= 0) & (s_nc <= 1)))


@pytest.mark.parametrize("demo", ["impact", "shatter", "pour"])
def test_a_demo_scenes_frame_encloses_its_particles(demo, tmp_path):
    import importlib

    atoms = importlib.import_module(f"ase_bpm.scene.demos.{demo}").demo_scene(quick=True)
    atoms.get_forces()
    with ViewerTrajectory(tmp_path / "scene.extxyz", atoms) as traj:
        traj.write()
    frame = read(tmp_path / "scene.extxyz")
    assert inside(frame)
    shift = frame.info.get("translation", np.zeros(3))
    assert np.allclose(frame.positions - shift, atoms.positions, rtol=0, atol=1e-8)
    if demo == "impact":  # its own cell, from its origin (celldisp)
        assert np.allclose(shift, -atoms.get_celldisp().ravel(), rtol=0, atol=1e-8)
        assert np.allclose(frame.cell, atoms.cell, rtol=0, atol=1e-8)
    elif demo == "shatter":  # no cell of its own: a box with a node's radius around them
        r = frame.arrays["radius"].max()
        assert np.allclose(frame.cell.lengths(), np.ptp(atoms.positions, axis=0) + 2 * r,
                           rtol=1e-12, atol=0)
        assert np.allclose(frame.positions.min(axis=0), r, rtol=1e-12, atol=0)
    else:  # the box of its walls encloses them: kept, positions as they are
        assert "translation" not in frame.info and np.array_equal(frame.cell, atoms.cell)


def test_a_trajectorys_box_grows_where_particles_leave_it(tmp_path):
    """A non-periodic box is kept while it holds every particle; where one
    leaves it, it grows a quarter of its length beyond it, on that side only
    (the other particles keep their place in the frames but along it)."""
    atoms = fcc_cluster(3, jitter=0.0)[0]
    length = atoms.cell.lengths()[0]
    extent = []  # largest extent of the particles at each frame (no radius: the margin
    with ViewerTrajectory(tmp_path / "run.extxyz", atoms) as traj:  # is a twentieth of it)
        for move in [(0, 0, 0),  # in the atoms' own cell
                     (-2.0, 0.5, 0.0),  # out through the low x face
                     (1.0, 0.0, 0.0),  # back a little, still outside the cell
                     (0.0, 0.0, 2.0 * length)]:  # out through the high z face
            atoms.positions[0] += move
            extent.append(np.ptp(atoms.positions, axis=0).max())
            traj.write()
    frames = read(tmp_path / "run.extxyz", ":")
    assert all(inside(frame) for frame in frames)
    assert "translation" not in frames[0].info
    assert np.array_equal(frames[0].cell, atoms.cell)
    low = -2.0 - 0.05 * extent[1] - 0.25 * length
    assert np.allclose(frames[1].info["translation"], (-low, 0.0, 0.0), rtol=0, atol=1e-12)
    assert np.allclose(frames[1].cell.lengths(), (length - low, length, length), rtol=1e-12)
    assert np.array_equal(frames[2].cell, frames[1].cell)  # it still holds them
    assert np.array_equal(frames[2].info["translation"], frames[1].info["translation"])
    top = atoms.positions[0, 2] + 0.05 * extent[3] + 0.25 * length
    assert np.array_equal(frames[3].info["translation"], frames[1].info["translation"])
    assert np.allclose(frames[3].cell.lengths(), (length - low, length, top), rtol=1e-12)
    # a periodic cell stays as it is, whatever lies outside it
    atoms.pbc = True
    assert np.array_equal(viewing_copy(atoms).cell, atoms.cell)
    assert "translation" not in viewing_copy(atoms).info


def test_ovito_draws_the_frames_box_around_them(tmp_path):
    atoms = importlib_demo("shatter")
    with ViewerTrajectory(tmp_path / "run.extxyz", atoms) as traj:
        traj.write()
    (particles,) = ovito_frames(tmp_path / "run.extxyz")
    from ovito.io import import_file

    cell = np.asarray(import_file(str(tmp_path / "run.extxyz")).compute().cell[...])
    assert np.array_equal(cell[:, 3], np.zeros(3))  # (translation is no origin to OVITO)
    frame = read(tmp_path / "run.extxyz")
    assert np.allclose(cell[:, :3], frame.cell, rtol=1e-12, atol=0)
    assert np.allclose(particles.positions, frame.positions, rtol=1e-6, atol=0)
    assert encloses((np.zeros(3), frame.cell.array), np.asarray(particles.positions))


def importlib_demo(name):
    import importlib

    return importlib.import_module(f"ase_bpm.scene.demos.{name}").demo_scene(quick=True)


# -- atoms without a calculator, names every frame can carry, ASE's trajectory= ---------

@pytest.mark.parametrize("model", MODEL_SCENES)
def test_without_a_calculator_frames_carry_the_models_outputs_they_hold(model, tmp_path):
    """Atoms read from a restart file have no calculator, and those of
    ase.io.read one that declares no outputs: the frames carry the outputs of
    any model that the atoms hold, as the calculator's would."""
    scene, declared = MODEL_SCENES[model]
    atoms = scene()
    atoms.get_forces()
    ase_bpm.write_restart(tmp_path / "state.bpm", atoms)
    back = ase_bpm.read_restart(tmp_path / "state.bpm")
    assert back.calc is None
    for calc in (None, SinglePointCalculator(back, energy=0.0)):
        back.calc = calc
        with ViewerTrajectory(tmp_path / "post.extxyz", back) as traj:
            traj.write()
        (frame,) = read(tmp_path / "post.extxyz", ":")
        assert set(frame.arrays) == {"numbers", "positions", "radius", *declared}
        for name in declared:
            assert np.allclose(frame.arrays[name], atoms.arrays[name], rtol=0, atol=1e-8)
    del back.arrays[declared[0]]  # only those it holds
    assert set(viewing_copy(back).arrays) == {"numbers", "positions", "radius", *declared[1:]}


def columns(path) -> list:
    """The column names of an extxyz file's first frame, as written."""
    with open(path) as fh:
        fh.readline()
        properties = fh.readline().split("Properties=")[1].split()[0]
    return properties.split(":")[::3]


def test_a_granular_scenes_omega_is_zero_before_its_first_run(tmp_path):
    """The README: omega is zero when absent; asked for on spheres that have
    none yet, frames write zeros (N x 3)."""
    atoms, _ = pile()
    del atoms.arrays["omega"]
    with ViewerTrajectory(tmp_path / "pile.extxyz", atoms, arrays=["omega"]) as traj:
        traj.write()
    (frame,) = read(tmp_path / "pile.extxyz", ":")
    assert np.array_equal(frame.arrays["omega"], np.zeros((len(atoms), 3)))
    assert "omega" not in atoms.arrays  # the atoms are left as they were
    assert set(frame.arrays) == {"numbers", "positions", "radius", "omega"}


def test_radius_is_asked_for_and_written_once(tmp_path):
    """A frame always has its radius column where there is one (for point
    particles half their shortest bond): asking for it is no error and writes
    it once.  A point particle has no omega to ask for."""
    atoms, dyn = breaking_block()
    dyn.run(1)
    assert "radius" not in atoms.arrays
    path = tmp_path / "run.extxyz"
    with ViewerTrajectory(path, atoms, arrays=["radius", "damage"]) as traj:
        traj.write()
    assert columns(path) == ["species", "pos", "radius", "damage"]
    assert np.allclose(read(path).arrays["radius"], display_radius(atoms), rtol=0, atol=1e-8)
    spheres, _ = pile()
    assert set(viewing_copy(spheres, ["radius"]).arrays) == {"numbers", "positions", "radius"}
    with pytest.raises(ValueError, match=r"no per-atom array 'omega' .*; BPMSpring writes"):
        viewing_copy(atoms, arrays="omega")


@pytest.mark.parametrize("integrator", [AseVelocityVerlet, VelocityVerlet])
def test_an_integrator_writes_to_a_viewer_trajectory(integrator, tmp_path):
    """``trajectory=ViewerTrajectory(...)`` of ASE's or ase_bpm's velocity
    Verlet: a frame at the start and every loginterval steps; the integrator's
    description kept."""
    atoms, _ = breaking_block()
    path = tmp_path / "run.extxyz"
    with ViewerTrajectory(path, atoms) as traj:
        dyn = integrator(atoms, 0.1, trajectory=traj, loginterval=2)
        dyn.run(6)
        assert len(traj) == 4
    assert traj.description == {"type": "molecular-dynamics", "md-type": "VelocityVerlet",
                                "timestep": 0.1, "interval": 2}
    frames = read(path, ":")
    assert [frame.info["step"] for frame in frames] == [0, 2, 4, 6]
    last = frames[-1]
    assert set(last.arrays) == {"numbers", "positions", "radius", "damage", "nbonds"}
    assert np.allclose(last.positions - last.info.get("translation", 0), atoms.positions,
                       rtol=0, atol=1e-8)


def test_an_optimiser_writes_to_a_viewer_trajectory(tmp_path):
    atoms, dyn = breaking_block()
    path = tmp_path / "relax.extxyz"
    with ase_bpm.pure(atoms), ViewerTrajectory(path, atoms) as traj:
        BFGS(atoms, trajectory=traj, logfile=None).run(fmax=1e-9, steps=2)
    assert len(read(path, ":")) == 3  # the start and two steps
