"""The compiled field kernels against their numpy references (wavepaths.fields.compiled).

The numpy chain (fields.chain, em.fresnel, em.utd) is itself checked against exact
solutions in test_fields_chain.py and tests/em; here the compiled twin must give the same
numbers, to rounding, everywhere the reference is defined: every angle, boundary, branch
(asymptotic transition function, thin slab, grazing, PEC, absorber) and material.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, trace
from wavepaths.em.fresnel import reflection_coefficients
from wavepaths.em.materials import ABSORBER, PEC, Material, itu_material, relative_permittivity
from wavepaths.em.utd import luebbers_coefficients
from wavepaths.fields import FieldConfig, compiled, compute_fields, transfer_matrices
from wavepaths.scene import load_scene

pytestmark = pytest.mark.skipif(not compiled.available(), reason="numba is not installed (the `fast` extra)")

F = 3.5e9


def _close(a, b, rtol):
    """|a - b| <= rtol * max(|a|, |b|, tiny), elementwise."""
    a, b = np.asarray(a), np.asarray(b)
    scale = np.maximum(np.maximum(np.abs(a), np.abs(b)), 1e-300)
    return np.abs(a - b) <= rtol * scale


def test_erfcx_is_scipys():
    from scipy.special import erfcx

    from wavepaths.fields import _numba

    rng = np.random.default_rng(0)
    z = rng.normal(scale=5, size=2000) + 1j * rng.normal(scale=5, size=2000)
    z = np.concatenate([z, np.exp(0.25j * np.pi) * np.sqrt(np.geomspace(1e-300, 1e12, 500)), [0j]])
    assert np.array_equal(_numba.erfcx_array(np.uint64(compiled.erfcx_address()), z), erfcx(z))


def test_compiled_transition_series_is_the_references_polynomial():
    from wavepaths.em.utd_terms import _f_series, transition_function
    from wavepaths.fields import _numba

    x = np.concatenate([[100.0, 1e8, 1e300, np.inf], np.geomspace(100.0, 1e12, 1000)])
    got = np.array([_numba.f_series(v) for v in x])
    assert np.array_equal(got, _f_series(x))
    assert np.array_equal(got, transition_function(x))


MATERIALS = [
    PEC, ABSORBER, itu_material("concrete"), itu_material("metal"), itu_material("glass", 0.003),
    itu_material("wood", 0.0), Material("near_vacuum", "custom", a=1.0 + 1e-12), Material("thick", "custom", a=5.0,
                                                                                         c=0.1, thickness_m=50.0),
    # a slab much thinner than the wavelength (q -> 0), a lossless one a quarter wave thick
    # inside at normal incidence (1 - e2 -> 0 there), a very lossy one
    Material("thin", "custom", a=5.0, c=0.01, thickness_m=1e-7),
    Material("resonant", "custom", a=4.0, thickness_m=0.25 * 2.99792458e8 / F),
    Material("lossy", "custom", a=5.0, c=1e4, thickness_m=0.2),
]


@pytest.mark.parametrize("slab", [True, False])
@pytest.mark.parametrize("material", MATERIALS, ids=lambda m: m.name)
def test_fresnel_kernel_matches_p2040_reference(material, slab):
    from wavepaths.fields import _numba

    c = np.concatenate([[0.0, 1e-300, 1e-12, 1e-6, 1.0, 1.0 + 5e-10, -0.3], np.linspace(0, 1, 101)])
    ref = reflection_coefficients(material, F, c, "slab" if slab else "half_space")
    kind = {"pec": _numba.KIND_PEC, "absorber": _numba.KIND_ABSORBER}.get(material.kind, _numba.KIND_DIELECTRIC)
    eta = complex(relative_permittivity(material, F)) if kind == _numba.KIND_DIELECTRIC else 1.0 + 0j
    thick = material.thickness_m / (2.99792458e8 / F)
    got = np.array([_numba.fresnel(kind, eta, thick, slab, x) for x in c])
    assert np.all(_close(got[:, 0], ref.r_te, 1e-13)), material.name
    assert np.all(_close(got[:, 1], ref.r_tm, 1e-13)), material.name


@pytest.mark.parametrize("c_loss,cos", [(1e-300, 0.0), (1e-190, 1e-160), (1e-200, 0.3)])
@pytest.mark.parametrize("slab", [False, True])
def test_fresnel_kernel_on_a_near_vacuum_matches_the_reference(c_loss, cos, slab):
    """|(eta - 1) + cos^2| below 1e-154: the kernel's square root must not square the
    modulus into an underflow (it divided by zero, or gave r = 0 for -1)."""
    from wavepaths.fields import _numba

    f = 3.5e9
    mat = Material("near_vacuum", "custom", a=1.0, c=c_loss, thickness_m=0.1)
    eta = complex(relative_permittivity(mat, f))
    ref = reflection_coefficients(mat, f, np.array([cos]), "slab" if slab else "half_space")
    got = _numba.fresnel(_numba.KIND_DIELECTRIC, eta, 0.1 * f / 299792458.0, slab, cos)
    np.testing.assert_allclose(got, [ref.r_te[0], ref.r_tm[0]], rtol=1e-12, atol=1e-300)


def test_luebbers_kernel_matches_the_reference_on_boundaries_and_both_branches():
    from wavepaths.fields import _numba

    rng = np.random.default_rng(3)
    m = 4000
    n = rng.choice([1.0 + 1e-9, 1.2, 1.5, 1.75, 2.0], m)
    pp = rng.uniform(0, 1, m) * n * np.pi
    phi = rng.uniform(0, 1, m) * n * np.pi
    # a quarter of the observers exactly on (or 1e-12 rad from) a shadow or reflection boundary
    on = rng.integers(0, 4, m)
    bnd = np.choose(on % 3, [pp + np.pi, np.pi - pp, (2 * n - 1) * np.pi - pp])
    pick = (on == 0) & (bnd >= 0) & (bnd <= n * np.pi)
    phi = np.where(pick, bnd + rng.choice([0.0, 1e-12, -1e-12], m), phi)
    b0 = rng.choice([np.pi / 2, 1e-9, np.pi - 1e-3, 0.7], m)
    L = rng.choice([0.0, 1e-6, 1.0, 300.0, 1e9], m)  # 1e9 m: F's asymptotic branch
    k = 2 * np.pi * F / 2.99792458e8
    r = rng.normal(size=(4, m)) * 0.4 + 1j * rng.normal(size=(4, m)) * 0.4
    ref = luebbers_coefficients(phi, pp, b0, n, k, L, *r)
    addr = np.uint64(compiled.erfcx_address())
    got = np.array([_numba.luebbers(addr, phi[i], pp[i], b0[i], n[i], k, L[i], r[0, i], r[1, i], r[2, i], r[3, i],
                                    1e-6) for i in range(m)])
    # a term near its boundary is a difference of nearly equal angles: the relative error is
    # that of its eps (~1e-16 / |eps|) times the term's share of D
    scale = np.maximum(np.maximum(np.abs(ref.d_s), np.abs(ref.d_h)), 1e-300)[:, None]  # L = 0 gives D = 0
    err = np.abs(got - np.stack(ref, axis=1)) / scale
    assert np.max(err) < 1e-9
    assert np.median(err) < 1e-15


@pytest.fixture(scope="module")
def canyon_paths():
    from wavepaths.bench.scenes import STREET_CANYON_TX, sionna_scene_xml, street_canyon_receivers

    scene = load_scene(sionna_scene_xml("simple_street_canyon"))  # concrete, marble, metal, ...
    rx = street_canyon_receivers(60)
    paths = trace(scene, STREET_CANYON_TX, rx,
                  TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=2))
    return scene, paths


@pytest.mark.parametrize("reflection_model", ["slab", "half_space"])
@pytest.mark.parametrize("model", ["utd", "gtd"])
def test_compiled_chain_equals_the_numpy_chain(canyon_paths, reflection_model, model):
    scene, paths = canyon_paths
    kinds = paths.interactions[paths.interactions > 0]
    assert {1, 2} <= set(kinds.tolist()) and len(paths) > 1000  # reflections and diffractions to check
    cfg = dict(frequency_hz=F, model=model, reflection_model=reflection_model)
    a_np = compute_fields(scene, paths, FieldConfig(**cfg, compiled=False)).a
    a_nb = compute_fields(scene, paths, FieldConfig(**cfg, compiled=True)).a
    assert np.all(_close(a_nb, a_np, 1e-11))
    t_np = transfer_matrices(scene, paths, FieldConfig(**cfg, compiled=False))
    t_nb = transfer_matrices(scene, paths, FieldConfig(**cfg, compiled=True))
    assert np.allclose(t_nb, t_np, rtol=0, atol=1e-11 * np.abs(t_np).max())


def test_compiled_false_never_enters_the_kernels(canyon_paths, monkeypatch):
    from wavepaths.fields import _numba

    scene, paths = canyon_paths

    def boom(*args):
        raise AssertionError("compiled kernel called")

    for name in ("reflect", "diffract", "diffract_parallel", "chain_fields", "chain_fields_parallel"):
        monkeypatch.setattr(_numba, name, boom)
    from wavepaths.em import antennas  # the antennas' compiled loop too

    monkeypatch.setattr(antennas, "_compiled_field_vectors", lambda: boom)
    compute_fields(scene, paths, FieldConfig(F, compiled=False))
    with pytest.raises(AssertionError, match="compiled kernel called"):
        compute_fields(scene, paths, FieldConfig(F, compiled=True))


def test_an_unusable_material_raises_as_in_numpy(canyon_paths):
    """A material outside its frequency range raises the reference's error, compiled or not,
    and only when a path meets it."""
    from wavepaths.errors import WavepathsError

    scene, paths = canyon_paths
    for flag in (False, True):
        with pytest.raises(WavepathsError, match="frequency"):
            compute_fields(scene, paths, FieldConfig(1e12, compiled=flag))


def test_compiled_wedge_geometry_equals_the_numpy_one(canyon_paths):
    from wavepaths.fields.chain import wedge_geometry

    scene, paths = canyon_paths
    for j in range(paths.max_depth):
        rows = np.nonzero(paths.interactions[:, j] == 2)[0]
        if not len(rows):
            continue
        ref = wedge_geometry(scene, paths, rows, j)
        got = wedge_geometry(scene, paths, rows, j, compiled=True)
        assert set(got) == set(ref)
        for key in ref:
            assert np.allclose(got[key], ref[key], rtol=0, atol=1e-12), key


def test_parallel_diffraction_kernel_equals_the_serial_one(canyon_paths, monkeypatch):
    import numba

    scene, paths = canyon_paths
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one CPU: no threads")
    monkeypatch.setattr(compiled, "PARALLEL_MIN_ROWS", 1 << 60)
    assert not compiled.parallel(1 << 40)
    serial = compute_fields(scene, paths, FieldConfig(F)).a
    monkeypatch.setattr(compiled, "PARALLEL_MIN_ROWS", 1)
    assert compiled.parallel(10)
    np.testing.assert_array_equal(compute_fields(scene, paths, FieldConfig(F)).a, serial)


@pytest.mark.parametrize("antennas", [("iso", "V"), ("tr38901", "VH"), ("dipole", "cross")])
@pytest.mark.parametrize("reflection_model", ["slab", "half_space"])
def test_the_one_pass_chain_equals_the_chain_interaction_by_interaction(canyon_paths, antennas, reflection_model):
    """``path_field_vectors`` runs each path's chain in one compiled pass
    (``_numba.chain_fields``); the compiled kernels called interaction by interaction over
    all paths (``_path_field_vectors_numpy`` with ``compiled=True``) give the same field
    vectors and spreading factors to the last bit, for one- and two-port antennas."""
    from wavepaths.em.antennas import Antenna
    from wavepaths.fields.chain import _path_field_vectors_compiled, _path_field_vectors_numpy

    scene, paths = canyon_paths
    ant = Antenna(*antennas)
    cfg = FieldConfig(F, reflection_model=reflection_model, tx_antenna=ant, rx_antenna=ant)
    E0, s0 = _path_field_vectors_numpy(scene, paths, cfg)
    E1, s1 = _path_field_vectors_compiled(scene, paths, cfg)
    np.testing.assert_array_equal(E1, E0)
    np.testing.assert_array_equal(s1, s0)


def test_paths_next_to_a_shadow_boundary_go_to_the_numpy_chain_with_their_pair(monkeypatch):
    """A receiver on the knife edge's incident shadow boundary: its diffraction takes the side
    of the line of sight, which needs the other paths of its pair. The one-pass kernel leaves
    that path; the numpy chain computes it among its pair's paths; the field vectors equal
    the numpy chain's (with the same compiled kernels) to the last bit."""
    from wavepaths.fields import chain

    scene = load_scene("half_plane")
    tx = np.array([[0.0, -10.0, 3.0]])
    # the screen is y = 0, z < 0, its edge the x axis: the incident shadow boundary through the
    # edge point (2, 0, 0) is the ray from tx through it, continued; receivers on it, a hair
    # either side, and one far from it
    on = tx[0] + 2.5 * (np.array([2.0, 0.0, 0.0]) - tx[0])
    rx = np.stack([on, on + [0, 0, 1e-7], on - [0, 0, 1e-7], [7.0, 4.0, -5.0]])
    paths = trace(scene, tx, rx, TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=0))
    assert (paths.interactions == 2).any(axis=1).sum() >= 3
    calls = []
    real = chain._path_field_vectors_numpy
    monkeypatch.setattr(chain, "_path_field_vectors_numpy", lambda sc, p, c: calls.append(len(p)) or real(sc, p, c))
    a = compute_fields(scene, paths, FieldConfig(F)).a
    assert calls and calls[0] < len(paths)  # only the pairs near the boundary
    monkeypatch.setattr(chain, "_path_field_vectors_numpy", real)
    E0, s0 = real(scene, paths, FieldConfig(F))
    E1, s1 = chain.path_field_vectors(scene, paths, FieldConfig(F))
    np.testing.assert_array_equal(E1, E0)
    np.testing.assert_array_equal(s1, s0)
    ref = compute_fields(scene, paths, FieldConfig(F, compiled=False)).a
    assert np.all(_close(a, ref, 1e-11))


@pytest.mark.parametrize("sigma", [1e155, 1e300])
def test_a_huge_conductivity_is_a_perfect_conductor_in_both_chains(canyon_paths, sigma):
    """sigma = 1e155 S/m made |eta| ~ 1e165: the rationalised Fresnel form's squares overflowed
    and r_tm was NaN in both chains. Above |eta| = 1e100 the coefficients are a perfect
    conductor's (within 2 / (cos(theta) sqrt|eta|) < 1e-16 of the formula); the field of
    every path equals the PEC scene's to rounding, numpy and compiled alike."""
    import dataclasses

    scene, paths = canyon_paths
    metal = Material("huge", "custom", a=1.0, c=sigma, thickness_m=0.2)
    huge = dataclasses.replace(scene, materials=tuple(metal for _ in scene.materials))
    pec = dataclasses.replace(scene, materials=tuple(PEC for _ in scene.materials))
    for flag in (False, True):  # (the two chains agree to 1e-11, test_compiled_chain_equals_the_numpy_chain)
        ref = compute_fields(pec, paths, FieldConfig(F, compiled=flag)).a
        got = compute_fields(huge, paths, FieldConfig(F, compiled=flag)).a
        assert np.all(np.isfinite(got))
        assert np.all(_close(got, ref, 1e-14))
