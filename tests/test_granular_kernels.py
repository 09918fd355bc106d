"""The compiled granular kernels against the NumPy ones: the same contacts,
forces, torques, energies, virials and shear histories, to round-off, for
each variant (general and frictionless); and the frictionless variant
against the general one with ``xmu = 0``."""

import os

import numpy as np
import pytest

from ase_bpm.laws import compiled, granular, granular_kernels
from ase_bpm.core.neighbours import neighbour_pairs
from scenes import sphere_pile

MODELS = {"hooke": dict(hertz=False, history=False),
          "hooke/history": dict(hertz=False, history=True),
          "hertz/history": dict(hertz=True, history=True)}
OPTIONS = [dict(gamma_t=5.0), dict(gamma_t=0.0), dict(gamma_t=5.0, limit_damping=True),
           dict(gamma_t=5.0, gamma_n=0.0, xmu=0.05)]
#: the frictionless variant (no tangential force can act)
FRICTIONLESS = [dict(xmu=0.0, frictional=False),
                dict(xmu=0.0, gamma_n=0.0, limit_damping=True, frictional=False)]


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


def pair_args(model, options):
    """A dense periodic scene's neighbour list and per-sphere inputs, with
    stored shear (some beyond the Coulomb limit) and three frozen spheres."""
    atoms = dense_scene(seed=len(model) + len(options))
    r = atoms.arrays["radius"]
    i_l, j_l, shift_lc = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc, r + 0.1)
    rng = np.random.default_rng(7)
    shear_lc = rng.normal(0.0, 0.05, (len(i_l), 3))
    hold = np.zeros(len(atoms), dtype=bool)
    hold[[3, 40, 77]] = True
    return (i_l, j_l, shift_lc, atoms.positions, atoms.get_velocities(),
            atoms.arrays["omega"], r, atoms.get_masses(), hold, shear_lc)


def wall_args(bounds):
    atoms = dense_scene(seed=3)
    atoms.positions[:, 2] -= 0.2
    rng = np.random.default_rng(8)
    shear_nc = rng.normal(0.0, 0.05, (len(atoms), 3))
    return (2, *bounds, atoms.positions, atoms.get_velocities(), atoms.arrays["omega"],
            atoms.arrays["radius"], atoms.get_masses(), shear_nc)


@pytest.mark.compiled
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("options", OPTIONS + FRICTIONLESS)
@pytest.mark.parametrize("update", [False, True])
def test_pair_contacts_agree(model, options, update):
    args = pair_args(model, options)
    shear_lc = args[-1].copy()
    kwargs = dict(coefficients(model, **options), dt=1e-3, update=update)
    ours = compiled.pair_contacts(*args, **kwargs)
    ref = granular.pair_contacts(*args, **kwargs)
    assert len(ref.touch) > 100 and np.array_equal(ours.touch, ref.touch)
    for res in (ours, ref):  # the touching pairs and each sphere's count of them
        assert np.array_equal(res.i_p, args[0][res.touch])
        assert np.array_equal(res.j_p, args[1][res.touch])
        assert np.array_equal(res.count_n, np.bincount(np.concatenate([res.i_p, res.j_p]),
                                                       minlength=len(args[3])))
    for name in ("f_nc", "fd_nc"):
        assert close(getattr(ours, name), getattr(ref, name)), name
    assert close(ours.energy, ref.energy)
    assert close(ours.virial, ref.virial())
    if options.get("frictional", True):
        assert close(ours.t_nc, ref.t_nc)
    else:  # no torque, no shear
        assert ours.t_nc is ref.t_nc is None and ours.shear_xc is ref.shear_xc is None
    if MODELS[model]["history"] and options.get("frictional", True):
        assert close(ours.shear_xc, ref.shear_xc, rel=1e-14)
        assert not np.allclose(ours.shear_xc, shear_lc[ref.touch])  # slipping resets
        # every row's new shear: that of the touching rows, zero elsewhere
        for res in (ours, ref):
            assert res.shear_lc.shape == shear_lc.shape
            assert np.array_equal(res.shear_lc[res.touch], res.shear_xc)
            apart = np.ones(len(shear_lc), dtype=bool)
            apart[res.touch] = False
            assert apart.sum() > 100 and not res.shear_lc[apart].any()
    else:
        assert ours.shear_lc is ref.shear_lc is None
    assert np.array_equal(shear_lc, args[-1])  # the input is not written


@pytest.mark.compiled
@pytest.mark.parametrize("model", ["hooke", "hertz/history"])
def test_a_contact_is_the_same_alone_as_among_others(model):
    """The compiled law runs on blocks of contacts, several per vector
    instruction: a contact's new shear and its force are the same, bit for
    bit, computed alone (the only lane of its block) as among all the others
    (in whichever lane it falls)."""
    args = pair_args(model, {})
    kwargs = dict(coefficients(model), dt=1e-3, update=True, virial=False)
    together = compiled.pair_contacts(*args, **kwargs)
    i_l, j_l, shift_lc, *per_atom, shear_lc = args
    assert len(together.touch) > 3 * 64  # several blocks
    for k in range(0, len(together.touch), 7):
        l = together.touch[k]
        alone = compiled.pair_contacts(i_l[l:l + 1], j_l[l:l + 1], shift_lc[l:l + 1],
                                       *per_atom, shear_lc[l:l + 1], **kwargs)
        assert alone.touch.tolist() == [0]
        if together.shear_xc is not None:
            assert np.array_equal(alone.shear_xc[0], together.shear_xc[k])
        # the force on i alone is the contact's own: the same as the numpy law's
        # for this one pair, to round-off, and the pair's opposite on j exactly
        ref = granular.pair_contacts(i_l[l:l + 1], j_l[l:l + 1], shift_lc[l:l + 1],
                                     *per_atom, shear_lc[l:l + 1], **kwargs)
        assert close(alone.f_nc, ref.f_nc)
        assert np.array_equal(alone.f_nc[i_l[l]], -alone.f_nc[j_l[l]])


@pytest.mark.compiled
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("lammps_wall", [True, False])
@pytest.mark.parametrize("bounds", [(0.0, None), (None, 3.5), (0.0, 3.5)])
@pytest.mark.parametrize("frictional", [True, False])
def test_wall_contacts_agree(model, lammps_wall, bounds, frictional):
    args = wall_args(bounds)
    stored = args[-1].copy()
    kwargs = dict(coefficients(model, **({} if frictional else FRICTIONLESS[0])), dt=1e-3,
                  update=True, lammps_wall=lammps_wall)
    ours = compiled.wall_contacts(*args, **kwargs)
    ref = granular.wall_contacts(*args, **kwargs)
    assert len(ref.touch) > 5 and np.array_equal(ours.touch, ref.touch)
    for name in ("f_nc", "fd_nc") + (("t_nc",) if frictional else ()):
        assert close(getattr(ours, name), getattr(ref, name), rel=1e-14), name
    assert close(ours.energy, ref.energy)
    if MODELS[model]["history"] and frictional:
        assert close(ours.shear_xc, ref.shear_xc, rel=1e-14)
        apart = np.ones(len(stored), dtype=bool)
        apart[ours.touch] = False
        assert apart.any() and not ours.shear_xc[apart].any()  # zero where not touching
        # no stored shear (None) is zero stored shear
        none = [kernels.wall_contacts(*args[:-1], None, **kwargs) for kernels in (compiled,
                                                                                   granular)]
        zero = granular.wall_contacts(*args[:-1], np.zeros_like(stored), **kwargs)
        for res in none:
            assert close(res.shear_xc, zero.shear_xc) and close(res.f_nc, zero.f_nc)
    elif not frictional:
        assert ours.t_nc is ref.t_nc is None and ours.shear_xc is ref.shear_xc is None
    assert np.array_equal(args[-1], stored)  # the stored shear is not written


#: a box of walls around the dense scene: spheres in its edges and corners touch two or three
BOX = [(0, 0.2, 4.0), (1, 0.2, 4.0), (2, 0.2, None)]


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("frictional", [True, False])
def test_walls_in_one_call_are_the_walls_one_by_one(model, frictional):
    """``walls_contacts`` takes several walls of one law in one call (as a
    calculator's neighbouring walls go): on each route, its forces, damping
    parts, torques and energy are those of the walls one by one added up, to
    round-off; the touching spheres are listed wall after wall, and each
    wall's new shear is that of its own call, bit for bit.  The two routes
    agree too."""
    _, _, _, x, v, w, r, m, shear_nc = wall_args((None, None))
    shear_wnc = np.stack([shear_nc, 0.5 * shear_nc, -shear_nc])
    kwargs = dict(coefficients(model, **({} if frictional else FRICTIONLESS[0])), dt=1e-3,
                  update=True)
    routes = [granular] + ([compiled] if compiled.available or os.environ.get("CI") else [])
    together = {}
    for kernels in routes:
        res = together[kernels] = kernels.walls_contacts(BOX, x, v, w, r, m, shear_wnc,
                                                         **kwargs)
        apart = [kernels.wall_contacts(*plane, x, v, w, r, m, shear_wnc[k], **kwargs)
                 for k, plane in enumerate(BOX)]
        assert np.array_equal(res.touch, np.concatenate([one.touch for one in apart]))
        assert len(res.touch) > len(np.unique(res.touch)) > 10  # spheres at edges
        names = ("f_nc", "fd_nc") + (("t_nc",) if frictional else ())
        for name in names:
            assert close(getattr(res, name), sum(getattr(one, name) for one in apart),
                         rel=1e-14), name
        assert close(res.energy, sum(one.energy for one in apart))
        if MODELS[model]["history"] and frictional:
            for k, one in enumerate(apart):
                assert np.array_equal(res.shear_xc[k], one.shear_xc)
        else:
            assert res.shear_xc is None
    if compiled in together:
        ours, ref = together[compiled], together[granular]
        for name in ("f_nc", "fd_nc") + (("t_nc",) if frictional else ()):
            assert close(getattr(ours, name), getattr(ref, name), rel=1e-14), name
        if ref.shear_xc is not None:
            assert close(ours.shear_xc, ref.shear_xc, rel=1e-14)


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
@pytest.mark.parametrize("frictional", [True, False])
def test_walls_add_into_the_arrays_they_are_given(kernels, frictional):
    """``into=(f_nc, fd_nc, t_nc)``: the walls add their forces, damping parts
    and torques into those very arrays (an evaluation's so far), which come
    back; the sums are the given values plus those of the walls from zeros,
    to round-off (bit for bit where a sphere touches one wall).  A None
    member starts from zeros; without friction the torques are left as given;
    an array of the wrong shape is refused by name, and arrays the compiled
    kernels cannot add into are left as they are (new ones come back)."""
    kernels = granular_kernels(kernels)
    _, _, _, x, v, w, r, m, shear_nc = wall_args((None, None))
    shear_wnc = np.stack([shear_nc, 0.5 * shear_nc, -shear_nc])
    kwargs = dict(coefficients("hooke/history", **({} if frictional else FRICTIONLESS[0])),
                  dt=1e-3, update=True)
    alone = kernels.walls_contacts(BOX, x, v, w, r, m, shear_wnc, **kwargs)
    rng = np.random.default_rng(3)
    given = [rng.normal(0.0, 50.0, x.shape) for _ in range(3)]
    into = [a.copy() for a in given]
    res = kernels.walls_contacts(BOX, x, v, w, r, m, shear_wnc, **kwargs, into=tuple(into))
    assert res.f_nc is into[0] and res.fd_nc is into[1] and res.t_nc is into[2]
    once = np.bincount(alone.touch, minlength=len(x)) == 1
    pairs = [(into[0], given[0] + alone.f_nc), (into[1], given[1] + alone.fd_nc)]
    if frictional:
        pairs.append((into[2], given[2] + alone.t_nc))
    else:
        assert np.array_equal(into[2], given[2])  # not touched
    for ours, expected in pairs:
        assert close(ours, expected, rel=1e-14)
        assert np.array_equal(ours[once], expected[once])
    assert res.energy == alone.energy and np.array_equal(res.touch, alone.touch)
    fresh = kernels.walls_contacts(BOX, x, v, w, r, m, shear_wnc, **kwargs,
                                   into=(given[0].copy(), None, None))
    assert np.array_equal(fresh.fd_nc, alone.fd_nc)
    assert (fresh.t_nc is None) == (not frictional)
    if frictional:
        assert np.array_equal(fresh.t_nc, alone.t_nc)
    if kernels is compiled:
        with pytest.raises(ValueError,
                           match=f"add into the forces: it must be {len(x)} x 3, not 100 x 3"):
            kernels.walls_contacts(BOX, x, v, w, r, m, shear_wnc, **kwargs,
                                   into=(np.zeros((100, 3)), None, None))
        # arrays C cannot add into (Fortran order here): new ones, the given untouched
        fortran = [np.asfortranarray(a) for a in given]
        apart = kernels.walls_contacts(BOX, x, v, w, r, m, shear_wnc, **kwargs,
                                       into=tuple(fortran))
        assert apart.f_nc is not fortran[0] and np.array_equal(apart.f_nc, alone.f_nc)
        assert all(np.array_equal(a, b) for a, b in zip(fortran, given))


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_a_sphere_centred_on_one_of_several_walls_names_that_wall(kernels):
    kernels = granular_kernels(kernels)
    _, _, _, x, v, w, r, m, _ = wall_args((None, None))
    x = x.copy()
    x[17, 1] = 4.0  # on the upper plane of the second wall
    with pytest.raises(granular.CentredOnWall, match="sphere 17 has its centre on the wall") \
            as caught:
        kernels.walls_contacts(BOX, x, v, w, r, m, None, **coefficients("hooke"))
    assert caught.value.wall == 1 and caught.value.sphere == 17


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("options", FRICTIONLESS)
def test_the_frictionless_variant_gives_the_forces_of_the_general_one(kernels, model,
                                                                       options):
    """With ``xmu = 0`` the general kernels scale every tangential force to
    zero; the frictionless variant, which never computes it, gives the same
    forces, damping parts, energy and virial, bit for bit (both kernels:
    the normal part is the same arithmetic, and adding a zero changes
    nothing), and no torques."""
    kernels = granular_kernels(kernels)
    args = pair_args(model, options)
    kwargs = dict(coefficients(model, **options), dt=1e-3, update=True)
    general = kernels.pair_contacts(*args, **dict(kwargs, frictional=True))
    short = kernels.pair_contacts(*args, **kwargs)
    assert np.abs(general.t_nc).max() == 0.0 and short.t_nc is None
    virial = lambda v: v() if callable(v) else v  # noqa: E731
    for a, b in ((short.f_nc, general.f_nc), (short.fd_nc, general.fd_nc),
                 (short.energy, general.energy),
                 (virial(short.virial), virial(general.virial))):
        assert np.array_equal(a, b)
    walls = [kernels.wall_contacts(*wall_args((0.0, 3.5)), **dict(kwargs, frictional=f))
             for f in (True, False)]
    assert np.array_equal(walls[0].f_nc, walls[1].f_nc)
    assert np.array_equal(walls[0].fd_nc, walls[1].fd_nc)
    assert walls[0].energy == walls[1].energy and walls[1].t_nc is None


@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
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


def test_kernel_choice(monkeypatch):
    monkeypatch.delenv("ASE_BPM_KERNELS", raising=False)
    assert granular_kernels("numpy") is granular
    assert granular_kernels("auto") is (compiled if compiled.available else granular)
    with pytest.raises(ValueError, match="kernels must be 'auto', 'compiled' or 'numpy'"):
        granular_kernels("fortran")


def test_the_environment_says_what_auto_means(monkeypatch):
    """ASE_BPM_KERNELS=numpy runs the NumPy kernels wherever a calculator
    asks for "auto" (CI runs the suite so); a word said explicitly stays."""
    monkeypatch.setenv("ASE_BPM_KERNELS", "numpy")
    assert granular_kernels("auto") is granular
    if compiled.available:
        assert granular_kernels("compiled") is compiled
    monkeypatch.setenv("ASE_BPM_KERNELS", "fast")
    with pytest.raises(ValueError, match="ASE_BPM_KERNELS must be .* not 'fast'"):
        granular_kernels("auto")


@pytest.mark.parametrize("stale", [False, True])
def test_without_the_compiled_kernels_numpy_runs_with_one_warning(stale, monkeypatch):
    import ase_bpm.laws as laws

    monkeypatch.delenv("ASE_BPM_KERNELS", raising=False)
    monkeypatch.setattr(compiled, "available", False)
    monkeypatch.setattr(compiled, "stale", stale)
    monkeypatch.setattr(laws, "_warned", [])
    with pytest.warns(UserWarning, match="NumPy kernels run") as caught:
        assert granular_kernels("auto") is granular
        assert granular_kernels("auto") is granular
    assert len(caught) == 1
    with pytest.raises(ValueError, match="kernels='compiled'"):
        granular_kernels("compiled")


@pytest.mark.compiled
def test_a_library_built_from_another_source_is_not_used(tmp_path):
    edited = []
    for source in compiled.SOURCES:  # the sources, one of them edited
        copy = tmp_path / source.name
        copy.write_text(source.read_text() + ("\n/* edited */\n" if not edited else ""))
        edited.append(copy)
    assert compiled._load(compiled.SOURCES) != (None, True)
    assert compiled._load(edited) == (None, True)


@pytest.mark.compiled
@pytest.mark.parametrize("frictional", [True, False])
def test_a_list_without_shifts_gives_what_zero_shifts_give(frictional):
    """A neighbour list built in an open box keeps no shifts (None): both
    kernels give bit for bit what they give with zero shifts."""
    atoms = dense_scene(seed=5)
    atoms.pbc = False
    r = atoms.arrays["radius"]
    i_l, j_l, shift_lc = neighbour_pairs(atoms.positions, atoms.cell, atoms.pbc, r + 0.1)
    assert not shift_lc.any()
    rest = (atoms.positions, atoms.get_velocities(), atoms.arrays["omega"], r,
            atoms.get_masses(), None, np.zeros((len(i_l), 3)))
    kwargs = dict(coefficients("hooke/history", **({} if frictional else FRICTIONLESS[0])),
                  dt=1e-3, update=True)
    for kernels in (compiled, granular):
        zeros = kernels.pair_contacts(i_l, j_l, shift_lc, *rest, **kwargs)
        none = kernels.pair_contacts(i_l, j_l, None, *rest, **kwargs)
        assert len(zeros.touch) > 100 and np.array_equal(none.touch, zeros.touch)
        for name in ("f_nc", "fd_nc", "t_nc", "shear_xc"):
            assert np.array_equal(getattr(none, name), getattr(zeros, name)), name
        assert none.energy == zeros.energy


@pytest.mark.compiled
def test_the_compiled_history_placement_writes_what_numpy_writes():
    """The shear history on the atoms (``gran_partner``, ``gran_shear``) as
    the compiled route writes it, in place or into new arrays, is the NumPy
    route's bit for bit, along a run of contact sets that grow, shrink,
    change width and empty."""
    from ase import Atoms

    from ase_bpm.models.contacts import write_contacts

    rng = np.random.default_rng(5)
    n = 30
    routes = {None: Atoms(f"Ar{n}"), compiled.place_contacts: Atoms(f"Ar{n}")}
    ids_n = rng.permutation(np.arange(1, n + 1)) * 1000  # the same IDs on both
    for atoms in routes.values():
        atoms.arrays["bpm_id"] = ids_n.copy()
    occupied = dict.fromkeys(routes)
    in_place = []  # whether the compiled route wrote into the arrays it wrote before
    i_p = j_p = np.zeros(0, dtype=np.int64)
    # new contact sets of some size, or "fewer": every other contact of the last set left
    for size in (0, 12, 40, "fewer", 90, "fewer", 25, 0, 60, "fewer", "fewer", 3):
        before = routes[compiled.place_contacts].arrays.get("gran_partner")
        if size == "fewer":
            i_p, j_p = i_p[::2], j_p[::2]
        else:
            keys = np.unique(rng.integers(0, n * n, size))
            i_p, j_p = np.divmod(keys, n)
            keep = i_p < j_p
            i_p, j_p = i_p[keep], j_p[keep]
        shear_pc = rng.normal(size=(len(i_p), 3))
        written = {}
        for place, atoms in routes.items():
            reuse = occupied[place] is not None
            *arrays, at_p = write_contacts(atoms, i_p, j_p, shear_pc, reuse=reuse,
                                           occupied=occupied[place], place=place)
            occupied[place] = at_p
            written[place] = (*arrays, at_p)
        for ours, ref in zip(written[compiled.place_contacts], written[None]):
            assert ours.shape == ref.shape and np.array_equal(ours, ref)
        # partner IDs where contacts are, nothing elsewhere
        assert np.count_nonzero(written[None][0]) == len(i_p)
        in_place.append(written[compiled.place_contacts][0] is before)
    assert 2 <= sum(in_place) <= len(in_place) - 3  # both ways, several times
