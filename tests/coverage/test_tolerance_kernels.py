"""The compiled work of ``tolerance_db`` (the diffracted candidates' amplitude bounds and the
choice of those dropped) against its numpy references, and the map it gives either way."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage
from wavepaths.coverage.tolerance import tolerance_drop_numpy as _tolerance_drop_numpy
from wavepaths.fields import FieldConfig
from wavepaths.scene import load_scene
from wavepaths.search import TraceOptions, kernels

pytestmark = pytest.mark.skipif(not kernels.available(), reason="needs numba")


def _bound_inputs(rng, m: int):
    """Candidates in reduced coordinates, a tenth of them degenerate: the point at an edge
    end of the source or receiver (zero distance to the edge and along it), sources on the
    edge's line, observers on shadow and reflection boundaries."""
    n = rng.choice([1.0 + 1e-9, 1.25, 1.5, 2.0], m)
    pp = rng.uniform(0, 1, m) * n * np.pi
    phi = rng.uniform(0, 1, m) * n * np.pi
    on = rng.integers(0, 6, m)
    bnd = np.choose(on % 3, [pp + np.pi, np.pi - pp, (2 * n - 1) * np.pi - pp])
    phi = np.where((on < 3) & (bnd >= 0) & (bnd <= n * np.pi), bnd, phi)
    t = rng.uniform(-5, 5, m)
    te, tr = rng.uniform(-50, 50, m), rng.uniform(-50, 50, m)
    de, dr = rng.uniform(0, 40, m), rng.uniform(0, 40, m)
    bad = rng.random(m) < 0.1
    kind = rng.integers(0, 3, m)
    te = np.where(bad & (kind == 0), t, te)
    de = np.where(bad & (kind <= 1), 0.0, de)
    tr = np.where(bad & (kind == 2), t, tr)
    dr = np.where(bad & (kind == 2), 0.0, dr)
    return phi, pp, n, te, de, tr, dr, t


def test_amplitude_bounds_kernel_matches_the_numpy_bound():
    """Candidate by candidate within 1e-12 (their sines and cosines may differ in the last bit),
    infinite exactly where the reference is not finite."""
    from types import SimpleNamespace

    from wavepaths.fields.chain import SIN_BETA_0_FLOOR
    from wavepaths.search import _numba_tolerance as _numba
    from wavepaths.search.diffraction import UTD_BOUND_FLOOR, _diffraction_amplitude_bound
    from wavepaths.search.paths import SPEED_OF_LIGHT

    rng = np.random.default_rng(11)
    args = _bound_inputs(rng, 20000)
    for f in (3.5e9, 28e9):
        ctx = SimpleNamespace(options=SimpleNamespace(prune_frequency_hz=f))
        ref = _diffraction_amplitude_bound(ctx, *args)
        got = _numba.amplitude_bounds(*args, 2 * np.pi * f / SPEED_OF_LIGHT, SIN_BETA_0_FLOOR, UTD_BOUND_FLOOR)
        fin = np.isfinite(ref)
        assert (~fin).sum() > 100 and fin.sum() > 10000  # both kinds are exercised
        np.testing.assert_array_equal(np.isinf(got), ~fin)
        np.testing.assert_allclose(got[fin], ref[fin], rtol=1e-12, atol=0)


def test_tolerance_drop_kernel_matches_the_numpy_reference():
    """The same candidates dropped, bit for bit: ties in bound (kept in their order), infinite
    bounds (never dropped, and not ending the drops of the pairs after them), empty pairs."""
    from wavepaths.search import _numba_tolerance as _numba

    rng = np.random.default_rng(5)
    for trial in range(20):
        k, n_pairs = int(rng.integers(1, 3000)), int(rng.integers(1, 400))
        pair = rng.integers(0, n_pairs, k).astype(np.int64)
        bound = rng.choice([1e-9, 1e-8, 3e-8], k) * rng.choice([1.0, rng.uniform(0.5, 2)], k)  # ties
        bound[rng.random(k) < 0.05] = np.inf
        go = rng.uniform(0, 2e-6, n_pairs)
        for eps in (10 ** 0.01 - 1, 10 ** 0.1 - 1, 1.0):
            ref = _tolerance_drop_numpy(pair, bound, go, eps)
            got = _numba.tolerance_drop(pair, bound, go, eps, n_pairs)
            np.testing.assert_array_equal(got, ref)
    # an infinite bound drops nothing itself and does not stop the other pairs' drops
    pair = np.array([0, 0, 1, 1], np.int64)
    bound = np.array([np.inf, 1.0, 1.0, 2.0])
    go = np.array([10.0, 10.0])
    for drop in (_tolerance_drop_numpy(pair, bound, go, 0.5), _numba.tolerance_drop(pair, bound, go, 0.5, 2)):
        np.testing.assert_array_equal(drop, [False, True, True, True])


def _both_drops(pair, bound, go, eps):
    """The compiled kernel's drops and the numpy reference's, the same to the candidate."""
    from wavepaths.search import _numba_tolerance as _numba

    got = _numba.tolerance_drop(pair, bound, go, eps, len(go))
    ref = _tolerance_drop_numpy(pair, bound, go, eps)
    np.testing.assert_array_equal(got, ref)
    return got


def test_each_cell_has_its_own_running_sum_170_db_below_another_cell():
    """A tile whose cell 0 is strong and cell 1 170 dB weaker: cell 1's candidates are each
    43 times its limit and must be kept. A running sum shared by the tile's cells (less its
    value at the cell's start) lost them in the strong cell's sum (1 + 1e-17 == 1) and dropped
    both (4.8 dB of cell 1's power, against a tolerance of 0.1 dB); a bound under its cell's
    limit, 142 dB below the other cell, came out at a rounding step of the shared sum
    (2.2e-16 > 1.5e-16) and was kept."""
    eps = 10 ** 0.01 - 1
    pair = np.array([0, 1, 1], np.int64)
    drop = _both_drops(pair, np.array([1.0, 1e-17, 1e-17]), np.array([1.0, 1e-17]), eps)
    np.testing.assert_array_equal(drop, [False, False, False])
    # the strong cell after the weak one, and a weak cell whose candidates fit its limit
    drop = _both_drops(np.array([1, 0, 0], np.int64), np.array([1.0, 1e-17, 1e-17]), np.array([1e-17, 1.0]), eps)
    np.testing.assert_array_equal(drop, [False, False, False])
    drop = _both_drops(pair, np.array([1.0, 1e-20, 2e-20]), np.array([1.0, 1e-17]), eps)
    np.testing.assert_array_equal(drop, [False, True, True])
    # under-drop: 1.2e-16 <= eps * go[1] = 1.5e-16, one cell at 1.0 before it
    drop = _both_drops(np.array([0, 1], np.int64), np.array([1.0, 1.2e-16]), np.array([1.0, 1.5e-16 / eps]), eps)
    np.testing.assert_array_equal(drop, [False, True])


def test_each_cells_dropped_bounds_stay_within_the_tolerance_of_its_power():
    """The stated bound, cell by cell, on tiles whose cells spread over 200 dB in random order:
    the dropped bounds of a (transmitter, cell) sum (exactly, math.fsum) to at most
    ``eps * go_power`` (the power of its line-of-sight and reflected paths, at most its kept
    total: the total then changes by at most the tolerance), up to the rounding of a sum of
    n terms; they are its weakest; and the drops stop only where the next finite bound would
    exceed the limit. Compiled and numpy the same."""
    import math

    rng = np.random.default_rng(23)
    for trial in range(30):
        n_pairs, k = int(rng.integers(2, 300)), int(rng.integers(2, 3000))
        go = 10.0 ** rng.uniform(-20, 0, n_pairs)
        go[rng.random(n_pairs) < 0.05] = 0.0
        pair = rng.integers(0, n_pairs, k).astype(np.int64)
        eps = float(rng.choice([10 ** 0.001 - 1, 10 ** 0.01 - 1, 10 ** 0.1 - 1, 1.0]))
        bound = eps * go[pair] * 10.0 ** rng.uniform(-4, 0.5, k) / 10
        bound[rng.random(k) < 0.02] = 0.0
        bound[rng.random(k) < 0.03] = np.inf
        tie = rng.random(k) < 0.1
        bound[tie] = eps * go[pair[tie]] / 30  # ties within a cell
        drop = _both_drops(pair, bound, go, eps)
        assert drop.any() and (~drop).any()
        for c in range(n_pairs):
            mine = pair == c
            dropped, kept = bound[mine & drop], bound[mine & ~drop]
            limit = eps * go[c]
            slack = 1 + 4 * (len(dropped) + 1) * 2.0 ** -53
            assert np.isfinite(dropped).all()
            total = math.fsum(dropped)
            assert total <= limit * slack, (trial, c, total, limit)
            finite = kept[np.isfinite(kept)]
            if len(finite):
                assert not len(dropped) or dropped.max() <= finite.min()
                assert total + finite.min() > limit / slack, (trial, c, total, finite.min(), limit)


def test_tolerance_drop_kernel_matches_the_numpy_reference_over_a_wide_spread():
    """Bit for bit where the sums span 600 decades: bounds from 1e-300 to 1e300, zeros,
    infinite bounds, cells without power, and one cell holding most candidates."""
    rng = np.random.default_rng(7)
    for trial in range(10):
        n_pairs, k = int(rng.integers(1, 500)), int(rng.integers(1, 5000))
        pair = np.where(rng.random(k) < 0.5, 0, rng.integers(0, n_pairs, k)).astype(np.int64)
        go = 10.0 ** rng.uniform(-300, 300, n_pairs)
        go[rng.random(n_pairs) < 0.1] = 0.0
        bound = go[pair] * 10.0 ** rng.uniform(-6, 1, k)
        bound[rng.random(k) < 0.02] = 0.0
        bound[rng.random(k) < 0.03] = np.inf
        for eps in (10 ** 0.01 - 1, 10 ** 0.1 - 1, 1.0):
            _both_drops(pair, bound, go, eps)
    for k in (0, 1):  # no candidates, one
        _both_drops(np.zeros(k, np.int64), np.ones(k), np.ones(3), 0.5)


def test_a_tolerance_map_is_the_same_with_and_without_the_compiled_kernels():
    """TraceOptions(compiled=False) runs every numpy reference (the bounds, the drops, the
    search): the same paths per cell and the same sums within 1e-12."""
    scene = load_scene("street_canyon")
    grid = PlanarGrid(center=[-37.3, 2.2], size=[56, 50], cell_size=[7, 5], height=1.5)
    tx = [[-60, 0, 10], [-20, 4, 6]]
    settings = CoverageOptions(workers=1, tile_size=32, coherent=False)
    maps = [coverage(scene, tx, grid, TraceOptions(tolerance_db=0.5, compiled=c), fields=FieldConfig(3.5e9),
                     settings=settings) for c in (True, False)]
    assert maps[0].stats["tolerance_dropped_candidates"] == maps[1].stats["tolerance_dropped_candidates"] > 0
    np.testing.assert_array_equal(maps[0].num_paths, maps[1].num_paths)
    ok = ~maps[0].inside
    np.testing.assert_allclose(maps[0].power_sum[..., ok], maps[1].power_sum[..., ok], rtol=1e-12, atol=0)


def test_the_antennas_peak_amplitude_is_sampled_once_per_antenna_not_per_tile():
    """``tolerance_db`` bounds each candidate with the antennas' peak pattern amplitudes, a
    65,000-direction sampling of each pattern (about 10 ms). It was sampled twice per tile,
    which made the street canyon's R2+D1 map with ``tolerance_db=0.1`` slower than without it
    (0.20 s against 0.16 s, now 0.14-0.15 s; docs/benchmarks-history.md, twenty-sixth session). A map of eight tiles with two
    different antennas now samples each once, and a second map none."""
    from wavepaths.coverage.tolerance import peak_pattern_amplitude
    from wavepaths.em.antennas import Antenna

    scene = load_scene("street_canyon")
    grid = PlanarGrid(center=[0.3, 0.7], size=[80, 40], cell_size=4.0, height=1.5)
    cfg = FieldConfig(3.5e9, tx_antenna=Antenna("tr38901", "V"), rx_antenna=Antenna("dipole", "V"))
    settings = CoverageOptions(workers=1, threads=1, tile_size=10, coherent=False)
    peak_pattern_amplitude.cache_clear()
    m = coverage(scene, [[-60.0, 0.0, 10.0]], grid, TraceOptions(tolerance_db=0.5), fields=cfg, settings=settings)
    assert m.metadata["cells_traced"] > 7 * 10  # eight tiles or more
    assert m.stats["tolerance_dropped_candidates"] > 0
    info = peak_pattern_amplitude.cache_info()
    assert info.misses == 2 and info.hits >= 2 * 8 - 2
    coverage(scene, [[-60.0, 0.0, 10.0]], grid, TraceOptions(tolerance_db=0.5), fields=cfg, settings=settings)
    assert peak_pattern_amplitude.cache_info().misses == 2
