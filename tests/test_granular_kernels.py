"""The compiled granular kernels against the NumPy ones: the same contacts,
forces, torques, energies, virials and shear histories, to round-off."""

import os

import numpy as np
import pytest

from ase_bpm.kernels import compiled, granular, granular_kernels
from ase_bpm.neighbours import neighbour_pairs
from scenes import sphere_pile

# in CI the compiled kernels must be there (.ci/run checks it too)
needs_compiled = pytest.mark.skipif(not compiled.available and not os.environ.get("CI"),
                                    reason="compiled kernels not built")
MODELS = {"hooke": dict(hertz=False, history=False),
          "hooke/history": dict(hertz=False, history=True),
          "hertz/history": dict(hertz=True, history=True)}
OPTIONS = [dict(gamma_t=5.0), dict(gamma_t=0.0), dict(gamma_t=5.0, limit_damping=True),
           dict(gamma_t=5.0, gamma_n=0.0, xmu=0.05)]


def coefficients(model, **options):
    kn = 6000.0 if MODELS[model]["hertz"] else 1000.0
    return {"kn": kn, "kt": 0.3 * kn, "gamma_n": 40.0, "gamma_t": 10.0, "xmu": 0.3,
            "limit_damping": False, **MODELS[model], **options}


def close(a, b, rel=1e-12):
    scale = max(np.abs(b).max(initial=0.0), 1e-300)
    return np.abs(np.asarray(a) - np.asarray(b)).max(initial=0.0) <= rel * scale


def dense_scene(seed):
    atoms = sphere_pile(n=5, seed=seed, speed=1.0, spin=3.0)
    rng = np.random.default_rng(seed)
    atoms.positions += rng.uniform(-0.1, 0.1, atoms.positions.shape)
    atoms.cell = [5.0, 5.0, 5.0]
    atoms.pbc = [True, True, False]
    return atoms


@needs_compiled
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("options", OPTIONS)
@pytest.mark.parametrize("update", [False, True])
def test_pair_contacts_agree(model, options, update):
    atoms = dense_scene(seed=len(model) + len(options))
    r = atoms.arrays["radius"]
    i_l, j_l, shift_lc = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc, r + 0.1)
    rng = np.random.default_rng(7)
    shear_lc = rng.normal(0.0, 0.05, (len(i_l), 3))  # some beyond the Coulomb limit
    hold = np.zeros(len(atoms), dtype=bool)
    hold[[3, 40, 77]] = True
    args = (i_l, j_l, shift_lc, atoms.positions, atoms.get_velocities(),
            atoms.arrays["omega"], r, atoms.get_masses(), hold, shear_lc)
    kwargs = dict(coefficients(model, **options), dt=1e-3, update=update)
    ours = compiled.pair_contacts(*args, **kwargs)
    ref = granular.pair_contacts(*args, **kwargs)
    assert len(ref.touch) > 100 and np.array_equal(ours.touch, ref.touch)
    for name in ("f_nc", "fd_nc", "t_nc"):
        assert close(getattr(ours, name), getattr(ref, name)), name
    assert close(ours.energy, ref.energy)
    assert close(ours.virial, ref.virial())
    if MODELS[model]["history"]:
        assert close(ours.shear_xc, ref.shear_xc, rel=1e-14)
        assert not np.allclose(ours.shear_xc, shear_lc[ref.touch])  # slipping resets
    assert np.array_equal(shear_lc, args[-1])  # the input is not written


@needs_compiled
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("lammps_wall", [True, False])
@pytest.mark.parametrize("bounds", [(0.0, None), (None, 3.5), (0.0, 3.5)])
def test_wall_contacts_agree(model, lammps_wall, bounds):
    atoms = dense_scene(seed=3)
    atoms.positions[:, 2] -= 0.2
    rng = np.random.default_rng(8)
    shear_nc = rng.normal(0.0, 0.05, (len(atoms), 3))
    args = (2, *bounds, atoms.positions, atoms.get_velocities(), atoms.arrays["omega"],
            atoms.arrays["radius"], atoms.get_masses(), shear_nc)
    kwargs = dict(coefficients(model), dt=1e-3, update=True, lammps_wall=lammps_wall)
    ours = compiled.wall_contacts(*args, **kwargs)
    ref = granular.wall_contacts(*args, **kwargs)
    assert len(ref.touch) > 5 and np.array_equal(ours.touch, ref.touch)
    for name in ("f_nc", "fd_nc", "t_nc"):
        assert close(getattr(ours, name), getattr(ref, name), rel=1e-14), name
    assert close(ours.energy, ref.energy)
    if MODELS[model]["history"]:
        assert close(ours.shear_xc, ref.shear_xc, rel=1e-14)


@pytest.mark.parametrize("kernels", ["numpy", pytest.param("compiled", marks=needs_compiled)])
def test_coincident_spheres_and_centres_on_a_wall_raise(kernels):
    kernels = granular_kernels(kernels)
    x = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [3.0, 0.0, 0.0]])
    v = w = np.zeros((3, 3))
    r, m = np.full(3, 0.5), np.ones(3)
    law = coefficients("hooke")
    with pytest.raises(ValueError, match="spheres 0 and 1 are at the same position"):
        kernels.pair_contacts(np.array([0]), np.array([1]), np.zeros((1, 3)), x, v, w, r, m,
                              None, None, **law)
    with pytest.raises(ValueError, match="sphere 2 has its centre on the wall"):
        kernels.wall_contacts(2, 0.0, None, x, v, w, r, m, None, **law)


def test_kernel_choice():
    assert granular_kernels("numpy") is granular
    assert granular_kernels("auto") is (compiled if compiled.available else granular)
    with pytest.raises(ValueError, match="kernels must be 'auto', 'compiled' or 'numpy'"):
        granular_kernels("fortran")


@needs_compiled
def test_a_library_built_from_another_source_is_not_used(tmp_path):
    edited = tmp_path / "_granular.c"
    edited.write_text(compiled.SOURCE.read_text() + "\n/* edited */\n")
    assert compiled._load(compiled.SOURCE) != (None, True)
    assert compiled._load(edited) == (None, True)
