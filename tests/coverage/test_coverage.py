"""Coverage maps: each cell equals trace() at its centre, the mechanism split adds up,
cells inside objects (and only they) are NaN, files round-trip, bad input is refused."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, WavepathsError, load_scene, trace
from wavepaths.coverage import (
    MECHANISMS,
    CoverageMap,
    CoverageOptions,
    MeshGrid,
    PlanarGrid,
    coverage,
    inside_solid_objects,
    solid_objects,
)
from wavepaths.em.materials import PEC
from wavepaths.fields import FieldConfig, compute_fields
from wavepaths.scene import build_scene

RTOL = 1e-9  # a cell is the same computation as trace() at its centre: only summation order may differ
IN_PROCESS = CoverageOptions(workers=1, tile_size=16)
POWER_SUM = CoverageOptions(workers=1, tile_size=16, coherent=False)  # the total tolerance_db bounds


@pytest.fixture(scope="module")
def canyon():
    return load_scene("street_canyon")


@pytest.fixture(scope="module")
def box():
    return load_scene("box_on_ground")


def canyon_grid():
    # offsets keep every cell centre off the buildings' walls and their planes
    return PlanarGrid(center=[-37.3, 2.2], size=[56, 50], cell_size=[7, 5], height=1.5)


@pytest.fixture(scope="module")
def canyon_map(canyon):
    """Two transmitters, reflections to order 2, diffraction with one reflection; several tiles."""
    return coverage(canyon, [[-60, 0, 10], [-20, 4, 6]], canyon_grid(), TraceOptions(), settings=IN_PROCESS)


def reference(scene, tx, points, options=None, config=None):
    paths = trace(scene, tx, points, options or TraceOptions())
    return paths, compute_fields(scene, paths, config or FieldConfig())


# ---- a cell is trace() at its centre ---------------------------------------------------
def test_cell_value_equals_trace_at_cell_centre(canyon, canyon_map):
    flat = canyon_map.cell_centers.reshape(-1, 3)
    out = ~canyon_map.inside.ravel()
    assert out.sum() > 30 and canyon_map.inside.any()
    paths, ref = reference(canyon, canyon_map.tx_positions, flat[out])
    for coherent in (True, False):
        got = canyon_map.path_gain_per_tx(coherent).reshape(2, -1)[:, out]
        want = ref.path_gain(coherent)
        assert (want > 0).mean() > 0.8
        np.testing.assert_allclose(got, want, rtol=RTOL, atol=0)
    # path counts per cell, and the map's best server is the strongest transmitter
    counts = np.zeros((2, out.sum()), int)
    np.add.at(counts, (paths.tx_index, paths.rx_index), 1)
    np.testing.assert_array_equal(canyon_map.num_paths.sum(axis=0).reshape(2, -1)[:, out], counts)
    best = canyon_map.best_server.ravel()[out]
    np.testing.assert_array_equal(best, np.argmax(ref.path_gain(True), axis=0))
    np.testing.assert_allclose(canyon_map.path_gain().ravel()[out], ref.path_gain(True).max(axis=0), rtol=RTOL)


def test_received_power_and_field_strength_match_the_field_result(canyon):
    cfg = FieldConfig(frequency_hz=2.4e9, tx_power_dbm=33.0)
    grid = PlanarGrid(center=[-61.3, -2.1, 1.5], size=[21, 14], cell_size=7)
    cmap = coverage(canyon, [-60, 0, 10], grid, fields=cfg, settings=IN_PROCESS)
    _, ref = reference(canyon, [[-60, 0, 10]], cmap.cell_centers.reshape(-1, 3), config=cfg)
    np.testing.assert_allclose(cmap.received_power_dbm(0).ravel(), ref.received_power_dbm()[0], rtol=RTOL)
    np.testing.assert_allclose(cmap.field_strength_dbuv_m().ravel(), ref.field_strength_dbuv_m()[0], rtol=RTOL)
    np.testing.assert_allclose(cmap.received_power_dbm(), 33.0 + cmap.path_gain_db(), rtol=1e-12)


def test_mesh_grid_cells_are_traced_at_face_centroids(box):
    verts = np.array([[-20, -15, 2.0], [20, -15, 2.0], [20, 15, 3.0], [-20, 15, 3.0], [-20.0, 0.0, 8.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    mesh = MeshGrid(verts, faces, offset=0.25)
    cmap = coverage(box, [12, -14, 6], mesh, TraceOptions(max_reflections=1), settings=IN_PROCESS)
    assert cmap.shape == (3,) and cmap.cell_centers.shape == (3, 3)
    centroid = verts[faces].mean(axis=1)
    assert np.allclose(np.linalg.norm(cmap.cell_centers - centroid, axis=1), 0.25)
    _, ref = reference(box, [[12, -14, 6]], cmap.cell_centers, TraceOptions(max_reflections=1))
    np.testing.assert_allclose(cmap.path_gain(0), ref.path_gain()[0], rtol=RTOL)


# ---- mechanisms ------------------------------------------------------------------------
def test_mechanism_split_adds_up_to_the_incoherent_total(canyon, canyon_map):
    total = canyon_map.path_gain_per_tx(coherent=False)
    split = sum(canyon_map.power_sum[i] for i in range(3))
    np.testing.assert_allclose(split, total, rtol=1e-12)
    for tx in (0, 1):
        parts = sum(canyon_map.mechanism_gain(m, tx) for m in MECHANISMS)
        np.testing.assert_allclose(parts, canyon_map.path_gain(tx, coherent=False), rtol=1e-12)
    # coherent sums per mechanism add up to the coherent total amplitude
    np.testing.assert_allclose(canyon_map.a_sum.sum(axis=0), canyon_map.a_total, rtol=1e-9, atol=1e-300)
    # each mechanism has what trace() calls it: no interaction / reflections only / a diffraction
    flat = canyon_map.cell_centers.reshape(-1, 3)
    out = ~canyon_map.inside.ravel()
    paths, ref = reference(canyon, canyon_map.tx_positions[:1], flat[out])
    diffracted = (paths.interactions == 2).any(axis=1)
    kinds = {"los": paths.depth == 0, "reflection": (paths.depth > 0) & ~diffracted, "diffraction": diffracted}
    for name, sel in kinds.items():
        want = np.zeros(out.sum())
        np.add.at(want, paths.rx_index[sel], np.abs(ref.a[sel]) ** 2)
        np.testing.assert_allclose(canyon_map.mechanism_gain(name, 0).ravel()[out], want, rtol=1e-12)
        assert want.max() > 0


def test_incoherent_option_changes_only_the_default_sum(canyon):
    grid = PlanarGrid(center=[-61.3, -2.1], size=[14, 7], cell_size=7, height=1.5)
    coh = coverage(canyon, [-60, 0, 10], grid, settings=IN_PROCESS)
    inc = coverage(canyon, [-60, 0, 10], grid, settings=CoverageOptions(workers=1, coherent=False))
    np.testing.assert_array_equal(inc.path_gain(), coh.path_gain(coherent=False))
    np.testing.assert_array_equal(coh.path_gain(), np.abs(coh.a_total[0]) ** 2)


# ---- cells inside objects ----------------------------------------------------------------
def test_cells_inside_objects_are_nan_and_only_they(box):
    # 1 m cells: centres at +-0.5, +-1.5, ...: none on the box walls at +-5
    grid = PlanarGrid(center=[0, 0], size=[30, 20], cell_size=1.0, height=5.0)
    cmap = coverage(box, [-14.2, -8.1, 7.0], grid, TraceOptions(max_reflections=1, diffraction=False),
                    settings=CoverageOptions(workers=1, tile_size=128))
    c = cmap.cell_centers
    expected = (np.abs(c[..., 0]) < 5) & (np.abs(c[..., 1]) < 5)
    assert expected.sum() == 100
    for q in ("path_gain_db", "received_power_dbm", "field_strength_dbuv_m", "los_gain_db"):
        values = cmap.quantity(q)
        np.testing.assert_array_equal(np.isnan(values), expected)
    assert (cmap.num_paths.sum(axis=(0, 1))[expected] == 0).all()
    assert (cmap.best_server[expected] == -1).all()


def test_inside_test_is_robust_on_edges_diagonals_and_open_bases():
    # a closed box, the same box without a floor, and a flat ground (never solid)
    def box_arrays(lo, hi, bottom):
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                      [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
        quads = [(4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
        quads += [(0, 3, 2, 1)] if bottom else []
        return v, np.array([t for a, b, c, d in quads for t in ([a, b, c], [a, c, d])])

    va, ta = box_arrays((0, 0, 0), (4, 4, 6), True)
    vb, tb = box_arrays((10, 0, 0), (14, 4, 6), False)
    vg = np.array([[-20, -20, 0], [30, -20, 0], [30, 20, 0], [-20, 20, 0]], float)
    tg = np.array([[0, 1, 2], [0, 2, 3]])
    # the open box's roof is its own object (as Sionna RT's city scenes split roof and walls)
    obj_b = np.where(np.arange(len(tb)) < 2, 2, 1)
    scene = build_scene(np.concatenate([va, vb, vg]), np.concatenate([ta, tb + 8, tg + 16]),
                        np.concatenate([np.zeros(len(ta), int), obj_b, [3, 3]]), np.zeros(len(ta) + len(tb) + 2, int),
                        ["closed", "open_base_walls", "open_base_roof", "ground"], [PEC])
    solids = solid_objects(scene)
    assert solids.objects.tolist() == [(0,), (1, 2)] and solids.closed.tolist() == [True, False]
    # points on the diagonals of the roof quads' triangulation, on a regular lattice, below the base
    t = np.linspace(0.25, 3.75, 15)
    diag = np.stack([t, t, np.full_like(t, 3.0)], axis=1)
    anti = np.stack([t, 4 - t, np.full_like(t, 5.0)], axis=1)
    pts = np.concatenate([diag, anti, diag + [10, 0, 0], anti + [10, 0, 0]])
    assert inside_solid_objects(scene, pts).all()
    outside = np.array([[2, 2, 6.5], [2, 2, -0.5], [12, 2, -0.5], [-1, 2, 3], [7, 2, 3], [12, 2, 6.01], [2, -0.01, 1]])
    assert not inside_solid_objects(scene, outside).any()


def test_solids_across_objects_and_within_components():
    # blocks touching along one edge (four faces on it) are one solid; the block with an
    # awning hinged on its roof edge (three faces) is found object by object
    touching = load_scene("touching_blocks")
    assert [len(o) for o in solid_objects(touching).objects] == [2]
    pts = np.array([[2, 2, 3], [6, 6, 3], [6, 2, 3], [2, 6, 3]])
    np.testing.assert_array_equal(inside_solid_objects(touching, pts), [True, True, False, False])
    awning = load_scene("three_face_edge")
    solids = solid_objects(awning)
    assert [awning.object_names[o] for o in solids.objects[0]] == ["block"] and len(solids) == 1
    np.testing.assert_array_equal(inside_solid_objects(awning, [[2, 2, 2], [5, 2, 3.9]]), [True, False])


@pytest.mark.parametrize("copy", ["same_winding", "reversed_winding"])
def test_a_double_sided_export_keeps_its_inside(copy):
    """Every face written twice (double-sided exports): each crossing counted twice made ray
    parity call every point outside (a review: a map's 328 inside cells became 0). A solid whose
    triangles all come in pairs counts each once; two touching blocks' coincident faces on a
    shared wall, in a solid where the other faces are single, still both count."""
    from wavepaths.scene.builtin import builtin_arrays

    v, t, o, m, names, mats = builtin_arrays("box_on_ground")
    twin = t if copy == "same_winding" else t[:, ::-1]
    scene = build_scene(v, np.vstack([t, twin]), np.concatenate([o, o]), np.concatenate([m, m]), names, mats)
    clean = build_scene(v, t, o, m, names, mats)
    pts = np.array([[0.0, 0.0, 5.0], [0.3, 0.2, 1.5], [20.0, 0.0, 1.5], [0.0, 0.0, 50.0]])
    want = inside_solid_objects(clean, pts)
    assert want.tolist() == [True, True, False, False]
    np.testing.assert_array_equal(inside_solid_objects(scene, pts), want)
    # a party wall: two closed blocks, each with its own face on x = 0 (the same corners)
    from ..conftest import boxes_scene

    party = boxes_scene([((-10, -5, 0), (0, 5, 15)), ((0, -5, 0), (10, 5, 15))], ground=50)
    inner = np.array([[-5.0, 0.0, 3.0], [5.0, 0.0, 3.0], [-0.01, 4.9, 14.9], [0.01, -4.9, 0.1], [20.0, 0.0, 3.0]])
    np.testing.assert_array_equal(inside_solid_objects(party, inner), [True, True, True, True, False])


# ---- files and pictures -----------------------------------------------------------------
def test_npz_round_trip_and_keys(canyon_map, tmp_path):
    path = canyon_map.save(tmp_path / "map.npz")
    with np.load(path, allow_pickle=False) as data:
        assert data["path_gain_db"].shape == canyon_map.shape == (10, 8)
        assert data["cell_centers"].shape == (10, 8, 3)
        np.testing.assert_array_equal(np.isnan(data["path_gain_db"]), canyon_map.inside)
        assert not np.isnan(data["cell_centers"]).any()
    back = CoverageMap.load(path)
    for name in ("path_gain_db", "received_power_dbm", "field_strength_dbuv_m", "diffraction_gain_db"):
        np.testing.assert_array_equal(back.quantity(name), canyon_map.quantity(name))
    np.testing.assert_array_equal(back.best_server, canyon_map.best_server)
    np.testing.assert_array_equal(back.cell_centers, canyon_map.cell_centers)
    assert back.metadata["trace_options"]["max_reflections"] == 2
    assert back.elapsed_s == canyon_map.elapsed_s > 0
    with pytest.raises(WavepathsError, match="not a wavepaths coverage map"):
        np.savez(tmp_path / "other.npz", x=np.zeros(3))
        CoverageMap.load(tmp_path / "other.npz")


def test_vertical_grid_orientation_and_plot(tmp_path):
    scene = load_scene("slit_shutter")
    grid = PlanarGrid(center=[0.05, 3.9, 2.03], size=[2, 1], cell_size=0.5, orientation=[0, 0, np.pi / 2])
    c = grid.cell_centers()
    assert c.shape == (2, 4, 3)
    np.testing.assert_allclose(c[..., 1], 3.9)  # a wall at y = 3.9: u = x, v = z
    np.testing.assert_allclose(c[0, :, 0], [-0.70, -0.20, 0.30, 0.80])
    np.testing.assert_allclose(c[:, 0, 2], [1.78, 2.28])
    cmap = coverage(scene, [0.1, -6, 1.6], grid, TraceOptions(max_reflections=1), settings=IN_PROCESS)
    from wavepaths.coverage.plot import save_png

    out = save_png(cmap, str(tmp_path / "wall.png"), scene=scene)
    assert (tmp_path / "wall.png").stat().st_size > 1000 and out.endswith(".png")


# ---- bad input -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: PlanarGrid([0, 0], [0, 10], 1.0, height=1.5), "empty grid"),
        (lambda: PlanarGrid([0, 0], [10, 10], 0.0, height=1.5), "`cell_size` must be positive"),
        (lambda: PlanarGrid([np.nan, 0], [10, 10], 1.0, height=1.5), "`center` has NaN"),
        (lambda: PlanarGrid([0, 0], [10, 10], 1.0), "give the grid's `height`"),
        (lambda: PlanarGrid([0, 0, 1], [10, 10], 1.0, height=2.0), "give one of them"),
        (lambda: MeshGrid(np.zeros((3, 3)), np.zeros((0, 3), int)), "no cells"),
        (lambda: MeshGrid([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]], [[0, 1, 2]]), "NaN"),
    ],
)
def test_bad_grids_are_clear_errors(make, message):
    with pytest.raises(WavepathsError, match=message):
        make()


def test_bad_coverage_calls_are_clear_errors(box):
    grid = PlanarGrid([0, 0], [30, 30], 3.0, height=5.0)
    with pytest.raises(WavepathsError, match="`tx` has NaN"):
        coverage(box, [np.nan, 0, 1], grid, settings=IN_PROCESS)
    with pytest.raises(WavepathsError, match="inside a solid object"):
        coverage(box, [0, 0, 5], grid, settings=IN_PROCESS)
    with pytest.raises(WavepathsError, match=r"cell \(0, 0\) has its centre on transmitter 0"):
        coverage(box, grid.cell_centers()[0, 0], grid, settings=IN_PROCESS)
    huge = PlanarGrid([0, 0], [1e5, 1e5], 0.01, height=5.0)
    with pytest.raises(WavepathsError, match=r"100,000,000,000,000 cells \(10000000 x 10000000\).* GiB"):
        coverage(box, [0, 0, 20], huge, settings=IN_PROCESS)
    with pytest.raises(WavepathsError, match="`grid` must be a PlanarGrid or MeshGrid"):
        coverage(box, [0, 0, 20], np.zeros((4, 3)), settings=IN_PROCESS)
    with pytest.raises(WavepathsError, match="`tile_size` must be None or a positive integer"):
        CoverageOptions(tile_size=0)
    with pytest.raises(WavepathsError, match="`quantity` must be one of"):
        coverage(box, [0, 0, 20], PlanarGrid([20, 20], 2, 2, height=1), settings=IN_PROCESS).quantity("gain")


def test_automatic_tile_size_bounds_the_receiver_images_a_tile_holds(canyon, monkeypatch):
    import importlib

    from wavepaths.search.context import build_tx_context

    solver = importlib.import_module("wavepaths.coverage.solver")  # `wavepaths.coverage` is also a function

    tx = np.array([[-60.0, 0.0, 10.0]])
    ctx = build_tx_context(canyon, tx, TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=2))
    per_rx = 1 + ctx.stats["images_order_1"] + ctx.stats["images_order_2"]
    assert per_rx > 1
    assert solver.auto_tile_size(ctx, 100_000, workers=1) == min(1024, solver.TILE_IMAGE_BUDGET // per_rx)
    monkeypatch.setattr(solver, "TILE_IMAGE_BUDGET", 40 * per_rx)
    assert solver.auto_tile_size(ctx, 100_000, workers=1) == 40  # budget / images per receiver
    monkeypatch.setattr(solver, "TILE_IMAGE_BUDGET", 1)
    assert solver.auto_tile_size(ctx, 100_000, workers=1) == 16  # never below 16
    monkeypatch.undo()
    # without diffraction a receiver holds no image tree: the largest tiles, but two per worker
    ctx0 = build_tx_context(canyon, tx, TraceOptions(max_reflections=2, diffraction=False))
    assert solver.auto_tile_size(ctx0, 100_000, workers=1) == 1024
    assert solver.auto_tile_size(ctx0, 1000, workers=2) == 250
    # workers=None: shrunk for the workers down to THREAD_TILE_MIN only (the map may stay in
    # this process, on threads, which share the tiles and never shrink them)
    assert solver.auto_tile_size(ctx0, 1000, workers=None) == 1024
    assert solver.auto_tile_size(ctx0, 100_000, workers=None) == 1024
    # the automatic size is reported, and the map equals one with explicit tiles
    grid = canyon_grid()
    auto = coverage(canyon, tx, grid, TraceOptions(max_reflections=1), settings=CoverageOptions(workers=1, threads=1))
    fixed = coverage(canyon, tx, grid, TraceOptions(max_reflections=1), settings=IN_PROCESS)
    assert auto.timings["tile_size"] == 1024
    np.testing.assert_allclose(auto.path_gain(), fixed.path_gain(), rtol=RTOL)


def test_prune_db_prunes_diffraction_only_with_an_explicit_frequency(canyon, canyon_map):
    """On a map, prune_db leaves diffraction alone unless prune_frequency_hz is given (a
    free-space bound would empty shadowed cells); with it, fewer diffracted paths and no
    cell gains power (the bound itself is tested per path in tests/search)."""
    tx = [[-60, 0, 10], [-20, 4, 6]]
    full_d = np.nansum(canyon_map.num_paths[2])
    same = coverage(canyon, tx, canyon_grid(), TraceOptions(prune_db=15.0), settings=IN_PROCESS)
    assert np.nansum(same.num_paths[2]) == full_d
    pruned = coverage(canyon, tx, canyon_grid(), TraceOptions(prune_db=15.0, prune_frequency_hz=3.5e9),
                      settings=IN_PROCESS)
    assert 0 < np.nansum(pruned.num_paths[2]) < 0.7 * full_d
    assert pruned.stats["pruned_paths_upper_bound"] > 0
    ok = ~canyon_map.inside
    assert np.all(pruned.power_sum[..., ok] <= canyon_map.power_sum[..., ok] * (1 + 1e-9))


def test_prune_db_warns_where_its_diffraction_bound_does_not_hold(canyon):
    """The diffraction bound of prune_db holds at prune_frequency_hz and above, for the UTD:
    a map at a lower frequency, or with Keller's GTD, is warned about; at or above it, or
    without diffracted pruning, nothing is said (warnings are errors in this suite)."""
    from wavepaths.scene import WavepathsWarning

    tx = [[-60, 0, 10]]
    grid = PlanarGrid(center=[-37.3, 2.2], size=[14, 10], cell_size=[7, 5], height=1.5)
    pruning = TraceOptions(max_reflections=1, prune_db=15.0, prune_frequency_hz=3.5e9)
    with pytest.warns(WavepathsWarning, match="above the map's frequency"):
        coverage(canyon, tx, grid, pruning, fields=FieldConfig(2.4e9), settings=IN_PROCESS)
    with pytest.warns(WavepathsWarning, match="'gtd'"):
        coverage(canyon, tx, grid, pruning, fields=FieldConfig(3.5e9, model="gtd"), settings=IN_PROCESS)
    for options, cfg in ((pruning, FieldConfig(3.5e9)), (pruning, FieldConfig(9.5e9)),
                         (pruning.with_(prune_frequency_hz=None), FieldConfig(2.4e9)),
                         (pruning.with_(diffraction=False), FieldConfig(3.5e9, model="gtd"))):
        coverage(canyon, tx, grid, options, fields=cfg, settings=IN_PROCESS)


@pytest.mark.parametrize("antenna", ["iso", "tr38901"])
def test_tolerance_db_changes_no_cells_power_sum_by_more_than_the_tolerance(canyon, antenna):
    """tolerance_db drops diffracted contributions (fewer diffracted paths) and every cell's
    power-sum path gain stays within the tolerance of the full map's, also with a directive
    antenna (whose peak gain the bound includes); cells that only diffraction reaches keep
    every path."""
    from wavepaths.em.antennas import Antenna

    tx = [[-60, 0, 10], [-20, 4, 6]]
    cfg = FieldConfig(3.5e9, tx_antenna=Antenna(antenna, "V"))
    grid = PlanarGrid(center=[-37.3, 2.2], size=[112, 100], cell_size=[3.5, 2.5], height=1.5)
    full = coverage(canyon, tx, grid, TraceOptions(), fields=cfg, settings=IN_PROCESS)
    for tol in (0.1, 1.0):
        cut = coverage(canyon, tx, grid, TraceOptions(tolerance_db=tol), fields=cfg, settings=POWER_SUM)
        assert np.nansum(cut.num_paths[2]) < 0.8 * np.nansum(full.num_paths[2])
        assert cut.stats["tolerance_dropped_candidates"] > 0
        ok = ~full.inside
        p_full, p_cut = full.power_sum.sum(axis=0)[:, ok], cut.power_sum.sum(axis=0)[:, ok]  # (m, cells)
        assert (p_cut <= p_full * (1 + 1e-12)).all()
        reached = p_full > 0
        change_db = 10 * np.log10(p_full[reached] / np.maximum(p_cut[reached], 1e-300))
        assert change_db.max() <= tol * (1 + 1e-9)
        assert change_db.max() > 0.01 * tol  # it did drop something that counts
        go = (full.num_paths[:2].sum(axis=0)[:, ok] > 0)
        np.testing.assert_array_equal(cut.num_paths[2][:, ok][~go], full.num_paths[2][:, ok][~go])


def test_tolerance_db_bound_is_tight_on_a_perfectly_conducting_wedge():
    """The same promise where the bound is nearly reached: a vertical grid of 1 m cells around the
    built-in wedge (perfectly conducting, UTD's amplitude bound attained at normal incidence), one
    transmitter. The worst cell moves by 0.71 of the tolerance at 0.1 dB, so this fails if the
    diffraction amplitude bound were 1.5x too small (a review's injected fault gave 1.19 of it;
    the street canyon's test above moves by 0.23 of it and passes a bound 2x too small)."""
    scene = load_scene("wedge")
    grid = PlanarGrid(center=[3.0, 0.0, 0.0], size=[40.0, 40.0], cell_size=[1.0, 1.0],
                      orientation=[np.pi / 2, 0, np.pi / 2])
    tx, cfg = [[3.0, 5.0, 6.0]], FieldConfig(3.5e9)
    full = coverage(scene, tx, grid, TraceOptions(), fields=cfg, settings=IN_PROCESS)
    ok = ~full.inside
    for tol in (0.1, 1.0):
        cut = coverage(scene, tx, grid, TraceOptions(tolerance_db=tol), fields=cfg, settings=POWER_SUM)
        p_full, p_cut = full.power_sum.sum(axis=0)[:, ok], cut.power_sum.sum(axis=0)[:, ok]
        reached = p_full > 0
        change = 10 * np.log10(p_full[reached] / np.maximum(p_cut[reached], 1e-300))
        assert change.max() <= tol * (1 + 1e-9)
        assert change.max() > 0.5 * tol  # the bound is nearly reached: tight enough to catch a weaker one


def test_tolerance_db_checks_each_path_for_crossed_faces_once(canyon):
    """With tolerance_db the geometrical-optics paths are checked for faces crossed at a
    reflection once, not again with the diffracted paths: E-D-R paths have no reflection, so the
    map casts exactly the chords of the map without diffraction (twice as many before)."""
    tx, grid = [[-60, 0, 10], [-20, 4, 6]], canyon_grid()
    go = coverage(canyon, tx, grid, TraceOptions(diffraction=False), settings=IN_PROCESS)
    cut = coverage(canyon, tx, grid, TraceOptions(diffraction_reflections=0, tolerance_db=0.5), settings=POWER_SUM)
    assert np.nansum(cut.num_paths[2]) > 0 and go.stats["rays_cast_reflection_chords"] > 0
    assert cut.stats["rays_cast_reflection_chords"] == go.stats["rays_cast_reflection_chords"]
    np.testing.assert_array_equal(cut.num_paths[:2], go.num_paths[:2])


def test_concatenate_keeps_every_path_padded_to_the_deeper(canyon):
    from wavepaths.search.paths import concatenate

    found = trace(canyon, [[-60, 0, 10]], [[0, 0, 1.5], [20, 5, 1.5]], TraceOptions(max_reflections=2))
    shallow = found.depth <= 1
    both = concatenate(found.select(shallow), found.select(~shallow))
    order = np.concatenate([np.flatnonzero(shallow), np.flatnonzero(~shallow)])
    assert len(both) == len(found) and both.interactions.shape == found.interactions.shape
    for name in ("tx_index", "rx_index", "depth", "interactions", "primitive", "triangle", "wedge_faces", "vertices"):
        np.testing.assert_array_equal(getattr(both, name), getattr(found, name)[order], err_msg=name)
    # the shallow part alone is narrower: padded as assemble pads it
    part = found.select(shallow)
    narrow = type(part)(part.tx_positions, part.rx_positions, part.tx_index, part.rx_index, part.depth,
                        part.interactions[:, :1], part.primitive[:, :1], part.triangle[:, :1], part.wedge_faces,
                        part.vertices[:, :3])
    np.testing.assert_array_equal(concatenate(narrow, found.select(~shallow)).vertices, found.vertices[order])


def test_a_tolerance_on_a_coherent_map_is_warned_about(canyon):
    """tolerance_db bounds the power sum; the coherent total, the map's default, is not bounded
    (a review measured 10.8 dB in a cell of the street canyon at 0.1 dB): coverage() says so,
    not only the command line, and not for the power sum."""
    from wavepaths.scene import WavepathsWarning

    opts = TraceOptions(max_reflections=1, diffraction_reflections=0, tolerance_db=0.1)
    with pytest.warns(WavepathsWarning, match="bounds the power sum"):
        coverage(canyon, [[-60, 0, 10]], canyon_grid(), opts, settings=IN_PROCESS)
    coverage(canyon, [[-60, 0, 10]], canyon_grid(), opts, settings=POWER_SUM)  # warnings are errors here


def test_tolerance_db_is_refused_by_trace_and_with_gtd(canyon):
    with pytest.raises(WavepathsError, match="coverage maps only"):
        trace(canyon, [[-60, 0, 10]], [[0, 0, 1.5]], TraceOptions(tolerance_db=0.5))
    with pytest.raises(WavepathsError, match="UTD"):
        coverage(canyon, [[-60, 0, 10]], canyon_grid(), TraceOptions(tolerance_db=0.5), fields=FieldConfig(model="gtd"),
                 settings=IN_PROCESS)
    with pytest.raises(WavepathsError, match="tolerance_db"):
        TraceOptions(tolerance_db=-1.0)


def test_a_launched_map_equals_the_exhaustive_map(canyon):
    """Launched candidates for both the reflections and the diffraction (R2+D2) on the
    street canyon: every cell's total and per-mechanism path gains and path counts equal the
    exhaustive map's (the launch finds every path there; its tests are the same exact ones),
    and the tiles follow the launched rule (as large as one worker allows)."""
    from wavepaths.coverage.solver import auto_tile_size
    from wavepaths.search.context import build_tx_context

    grid = PlanarGrid(center=[-17.3, 2.2], size=[96, 50], cell_size=[4, 5], height=1.5)
    base = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=2)
    launched = base.with_(diffraction_candidates="launched", reflection_candidates="launched", launch_rays=1 << 16)
    ex = coverage(canyon, [[-60, 0, 10]], grid, base, settings=CoverageOptions(workers=1))
    la = coverage(canyon, [[-60, 0, 10]], grid, launched, settings=CoverageOptions(workers=1, threads=1))
    assert la.metadata["tiles"] == 1
    np.testing.assert_array_equal(np.nan_to_num(la.num_paths), np.nan_to_num(ex.num_paths))
    assert np.nansum(ex.num_paths) > 2000
    np.testing.assert_allclose(la.path_gain_db(), ex.path_gain_db(), rtol=0, atol=1e-9, equal_nan=True)
    ctx = build_tx_context(canyon, np.array([[-60.0, 0, 10]]), launched)
    assert auto_tile_size(ctx, 20000, 2) == 2048 and auto_tile_size(ctx, 300, 1) == 300
    # in square tiles of at most 16 cells (4 x 4 blocks), the same map
    sq = coverage(canyon, [[-60, 0, 10]], grid, launched, settings=CoverageOptions(workers=1, tile_size=16))
    assert sq.metadata["tiles"] >= 8
    np.testing.assert_allclose(sq.path_gain_db(), ex.path_gain_db(), rtol=0, atol=1e-9, equal_nan=True)


def test_block_tiles_cover_every_active_cell_once_in_compact_squares():
    """A 37 x 53 grid with a hole: every active cell in exactly one tile, none larger than
    the size, and every tile inside a run of squares of one row of squares (at most
    ``floor(sqrt(size))`` grid rows tall); a 1-D grid gets runs of consecutive cells."""
    from wavepaths.coverage.solver import block_tiles

    ny, nx, size = 37, 53, 50
    flat = np.arange(ny * nx)
    r, c = np.divmod(flat, nx)
    active = flat[~((r > 10) & (r < 20) & (c > 5) & (c < 30))]
    tiles = block_tiles((ny, nx), active, size)
    got = np.concatenate(tiles)
    assert len(got) == len(active) and set(got.tolist()) == set(active.tolist())
    side = int(np.sqrt(size))
    for t in tiles:
        assert 0 < len(t) <= size
        rows = t // nx
        assert rows.max() - rows.min() < side and len(set((rows // side).tolist())) == 1
    assert max(len(t) for t in tiles) > side * side // 2
    runs = block_tiles((ny * nx,), active, size)
    assert [len(t) for t in runs[:-1]] == [size] * (len(runs) - 1)


@pytest.mark.parametrize("cell", [1e-18, 1e-300, 5e-324])
def test_a_cell_far_too_small_for_the_grid_is_refused(cell):
    """size / cell_size beyond 2^31 cells per axis (or overflowing) raises; it used to wrap the
    cell count round to a 1 x 1 map."""
    with pytest.raises(WavepathsError, match="too small"):
        PlanarGrid(center=[0.0, 0.0], size=[200.0, 80.0], cell_size=cell, height=1.5)


def test_a_truncated_map_file_is_a_clear_error(tmp_path):
    from wavepaths.coverage import CoverageMap

    scene = load_scene("box_on_ground")
    grid = PlanarGrid(center=[0.0, 0.0], size=[20.0, 20.0], cell_size=4.0, height=12.0)
    cmap = coverage(scene, np.array([[-14.0, -8.0, 7.0]]), grid, TraceOptions(max_reflections=1),
                    settings=CoverageOptions(workers=1))
    path = cmap.save(str(tmp_path / "m.npz"))
    (tmp_path / "t.npz").write_bytes((tmp_path / "m.npz").read_bytes()[:300])
    with pytest.raises(WavepathsError, match="cannot read a coverage map"):
        CoverageMap.load(str(tmp_path / "t.npz"))
    assert CoverageMap.load(path).num_cells == cmap.num_cells


def _points_on_wall_faces(scene) -> tuple[np.ndarray, np.ndarray]:
    """One point on each vertical polygon of ``scene`` (its corners' mean, lifted to 2 m and
    projected back onto the plane), with that polygon's index."""
    from wavepaths.search.trace import points_on_faces

    n = scene.polygon_normal
    walls = np.nonzero(np.abs(n[:, 2]) < 1e-9)[0]
    pts = []
    for q in walls:
        corners = scene.vertices[scene.triangles[scene.triangle_polygon == q]].reshape(-1, 3)
        c = corners.mean(axis=0)
        c[2] = min(max(c[2], 2.0), corners[:, 2].max() - 0.5)
        pts.append(c - (c @ n[q] - scene.polygon_offset[q]) * n[q])
    pts = np.array(pts)
    assert (points_on_faces(scene, pts) == walls).all()  # each point is on its wall, within the tolerance
    return pts, walls


def test_a_transmitter_on_a_wall_face_is_treated_alike_on_every_face(canyon):
    """A transmitter exactly on a wall face is on no side of it: trace() and coverage() warn
    that it lies on a face, on every face. The ray-parity inside test answers either way on
    a surface; it had a coverage map refuse a transmitter on 8 of the 24 walls as "inside a
    solid object" and accept it on the other 16, and trace() warn "inside" on those 8."""
    from wavepaths.scene.model import WavepathsWarning

    pts, walls = _points_on_wall_faces(canyon)
    assert len(walls) >= 20
    inside = inside_solid_objects(canyon, pts, solid_objects(canyon))
    assert inside.any() and not inside.all()  # the parity rule does split the faces
    grid = PlanarGrid(center=[-37.3, 2.2], size=[14, 10], cell_size=[7, 5], height=1.5)
    rx = grid.cell_centers().reshape(-1, 3)
    for p in pts:
        opts = TraceOptions(max_reflections=1, diffraction=False)
        with pytest.warns(WavepathsWarning, match="lie exactly on a face") as rec:
            paths = trace(canyon, p[None], rx, opts)
        assert not [w for w in rec if "inside closed" in str(w.message)]
        with pytest.warns(WavepathsWarning, match="lie exactly on a face"):
            cmap = coverage(canyon, p, grid, opts, settings=IN_PROCESS)
        count = cmap.path_count(0).reshape(-1)
        assert (count == np.bincount(paths.rx_index, minlength=len(rx))).all()


def test_cell_centres_on_walls_are_reported(canyon):
    """The footprint grid at 2 m puts whole rows and columns of cell centres on the street
    canyon's walls (x = -45 m, y = -25 m, ...): the map warns, naming how many; offset by half a
    metre it does not."""
    from wavepaths.scene.model import WavepathsWarning

    opts = TraceOptions(max_reflections=0, diffraction=False)
    on_wall = PlanarGrid(center=[-45.0, 0.0], size=[2.0, 60.0], cell_size=2.0, height=1.5)  # x = -45; y = -29 .. 29
    with pytest.warns(WavepathsWarning, match=r"cell centres lie exactly on a face: (\d+) on the surface"):
        cmap = coverage(canyon, [-60, 0, 10], on_wall, opts, settings=IN_PROCESS)
    # the centres on the buildings' walls (10 <= |y| <= 25) are masked, every one: the ray-parity
    # test alone answered either way there (121 of 220 masked on a 200 x 80 m grid)
    y = on_wall.cell_centers().reshape(-1, 3)[:, 1]
    assert (cmap.inside.reshape(-1) == ((np.abs(y) >= 10) & (np.abs(y) <= 25))).all()
    on_ground = PlanarGrid(center=[-30.5, 0.5], size=[4.0, 4.0], cell_size=2.0, height=0.0)
    with pytest.warns(WavepathsWarning, match=r": 0 on the surface of a solid object, masked .*; 4 traced"):
        cmap = coverage(canyon, [-60, 0, 10], on_ground, opts, settings=IN_PROCESS)
    assert not cmap.inside.any()
    shifted = PlanarGrid(center=[-45.5, 0.5], size=[2.0, 60.0], cell_size=2.0, height=1.5)
    coverage(canyon, [-60, 0, 10], shifted, opts, settings=IN_PROCESS)  # no warning (warnings are errors here)


@pytest.mark.parametrize("variant", ["one_object", "flipped_walls", "no_floors"])
def test_cells_on_walls_are_masked_whatever_the_files_objects(canyon, variant):
    """The same walls packed differently (every face in one object, some faces wound the other
    way, the buildings without floors: none of them a closed object by itself) mask the same
    cells on the walls as the street canyon's closed buildings (a review found some traced)."""
    from wavepaths.scene.model import WavepathsWarning

    obj, tri = canyon.triangle_object.copy(), canyon.triangles.copy()
    names = list(canyon.object_names)
    if variant == "one_object":
        obj[:], names = 0, ["city"]
    elif variant == "flipped_walls":
        tri[::3] = tri[::3, ::-1]
    keep = np.ones(len(tri), bool)
    if variant == "no_floors":
        n = canyon.polygon_normal[canyon.triangle_polygon]
        keep = ~((n[:, 2] < -0.99) & (canyon.vertices[tri][:, :, 2].max(axis=1) < 1e-9))
    scene = build_scene(canyon.vertices, tri[keep], obj[keep], canyon.triangle_material[keep], names,
                        list(canyon.materials))
    assert not scene.solid_object_mask.any() or variant == "no_floors"
    opts = TraceOptions(max_reflections=0, diffraction=False)
    grid = PlanarGrid(center=[-45.0, 0.0], size=[2.0, 60.0], cell_size=2.0, height=1.5)
    with pytest.warns(WavepathsWarning, match=r"cell centres lie exactly on a face: 16 on the surface"):
        cmap = coverage(scene, [-60, 0, 10], grid, opts, settings=IN_PROCESS)
    y = grid.cell_centers().reshape(-1, 3)[:, 1]
    np.testing.assert_array_equal(cmap.inside.reshape(-1), (np.abs(y) >= 10) & (np.abs(y) <= 25))


@pytest.mark.parametrize("suffix, up_axis", [(".glb", "auto"), (".obj", "y")])
def test_a_measurement_mesh_is_turned_up_as_its_scene_is(tmp_path, suffix, up_axis):
    """A +Y-up measurement plane at y = 1.5 (glTF by its specification, an OBJ with
    up_axis="y") lies at z = 1.5 after loading, as a scene from the same file would."""
    import trimesh

    plane = trimesh.creation.box(extents=(6.0, 0.0, 6.0))  # a flat 6 x 6 m sheet in the xz plane
    plane = trimesh.Trimesh(plane.vertices + [0.0, 1.5, 0.0], plane.faces, process=False)
    path = str(tmp_path / f"meas{suffix}")
    plane.export(path)
    centres = MeshGrid.from_file(path, up_axis=up_axis).cell_centers()
    assert np.allclose(centres[:, 2], 1.5)
    assert np.abs(centres[:, :2]).max() <= 3.0 + 1e-12
