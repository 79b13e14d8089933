"""What a coverage picture tells its reader: a legend naming every special colour present
(and no other) with its cell count, the colour each category is drawn in, a title with the
quantity in words, the scene, frequency, transmit power, grid and transmitters, a colour bar
with units, building outlines on flat mesh grids, and the PNG file."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from wavepaths import load_scene  # noqa: E402
from wavepaths.coverage import CoverageMap, MeshGrid, PlanarGrid  # noqa: E402
from wavepaths.coverage.plot import (  # noqa: E402
    ABSENT_COLOR,
    BELOW_COLOR,
    INSIDE_COLOR,
    NO_PATH_COLOR,
    color_range,
    plot_coverage,
    save_png,
)

LOS, REFL = 0, 1
# one transmitter over 2 x 4 cells (row-major): path gain per mechanism
CELLS = [  # (inside, los gain, reflection gain)
    (True, 0.0, 0.0),     # 0 inside a building
    (False, 0.0, 0.0),    # 1 no path
    (False, 0.0, 1e-6),   # 2 -60 dB, reflection only: the top of the colour scale
    (False, 0.0, 1e-9),   # 3 -90 dB
    (False, 0.0, 1e-16),  # 4 -160 dB: below an 80 dB window
    (False, 0.0, 1e-17),  # 5 -170 dB: below
    (False, 1e-9, 1e-9),  # 6 line of sight and a reflection
    (False, 1e-7, 0.0),   # 7 line of sight only
]


def make_map(cells=CELLS, grid=None, tx_positions=((-3.0, 0.0, 10.0),), frequency_hz=3.5e9, tx_power_dbm=20.0,
             metadata=None) -> CoverageMap:
    """A coverage map built from per-cell mechanism gains (each mechanism one path, in phase),
    without tracing."""
    grid = grid if grid is not None else PlanarGrid(center=[0, 0], size=[4, 2], cell_size=1.0, height=1.5)
    shape = grid.shape
    m = len(tx_positions)
    inside = np.array([c[0] for c in cells]).reshape(shape)
    gains = np.zeros((3, m) + shape)
    for k, (_, los, refl) in enumerate(cells):
        idx = np.unravel_index(k, shape)
        for t in range(m):
            gains[(LOS, t) + idx] = los * 10.0 ** (-t)  # tx t is 10 t dB weaker
            gains[(REFL, t) + idx] = refl * 10.0 ** (-t)
    gains[:, :, inside] = np.nan  # as the solver leaves cells inside objects
    a_sum = np.sqrt(gains).astype(complex)
    return CoverageMap(
        grid=grid, cell_centers=grid.cell_centers(), inside=inside, tx_positions=np.array(tx_positions, float),
        a_total=a_sum.sum(axis=0), a_sum=a_sum, power_sum=gains, num_paths=(np.nan_to_num(gains) > 0).astype(np.int32),
        frequency_hz=frequency_hz, tx_power_dbm=tx_power_dbm,
        metadata={"scene": "tests/canyon.obj"} if metadata is None else metadata)


def legend_entries(ax) -> dict[str, object]:
    leg = ax.get_legend()
    assert leg is not None
    return {t.get_text(): h for t, h in zip(leg.get_texts(), leg.legend_handles, strict=True)}


def find(entries, start: str) -> tuple[str, object]:
    hits = [(text, h) for text, h in entries.items() if text.startswith(start)]
    assert len(hits) == 1, (start, list(entries))
    return hits[0]


def drawn_colors(ax) -> np.ndarray:
    """shape + (4,): the colour each cell of a planar map shows (the top image that is not
    transparent there)."""
    out = None
    for img in ax.images:
        rgba = img.to_rgba(img.get_array())
        rgba = np.asarray(rgba, dtype=float) / (255.0 if rgba.dtype == np.uint8 else 1.0)
        out = rgba if out is None else np.where(rgba[..., 3:] > 0, rgba, out)
    return out


def colorbar_of(ax):
    bars = [a for a in [*ax.figure.axes, *ax.child_axes] if a is not ax and hasattr(a, "_colorbar")]
    assert len(bars) == 1
    return bars[0]._colorbar


# ---- the legend: every special colour present, named, counted, and drawn in its colour -------
def test_legend_names_the_categories_present_with_their_counts_and_colours():
    cmap = make_map()
    art = plot_coverage(cmap)
    ax = art.axes
    entries = legend_entries(ax)
    values = cmap.path_gain_db()
    vmin, vmax = color_range(values)
    below = np.isfinite(values) & (values < vmin)
    assert (vmin, vmax) == pytest.approx((-140.0, -60.0)) and below.sum() == 2
    colors = drawn_colors(ax)
    for start, mask, color in [
        ("no path reached the cell", cmap.without_paths(), NO_PATH_COLOR),
        ("inside an object, masked", cmap.inside, INSIDE_COLOR),
        ("below the colour scale's 80 dB window", below, BELOW_COLOR),
    ]:
        text, handle = find(entries, start)
        n = int(mask.sum())
        assert f"({n} cell{'s' if n != 1 else ''})" in text
        assert handle.get_facecolor() == pytest.approx(to_rgba(color))
        np.testing.assert_allclose(colors[mask], np.broadcast_to(to_rgba(color), (n, 4)), atol=1e-6)
    assert "\u2212140.0 dB" in find(entries, "below the colour scale's")[0]  # the window's bottom, with its unit
    assert not any(t.startswith("reached, but by no") for t in entries)  # path gain: every reached cell has a value
    assert "transmitter" in entries
    # the colour bar's lower triangle: values below the range, in the colour they are drawn in
    bar = colorbar_of(ax)
    assert bar.extend == "min"
    assert bar.cmap.get_under() == pytest.approx(to_rgba(BELOW_COLOR))


def test_the_below_window_count_follows_the_window():
    cmap = make_map()
    values = cmap.path_gain_db()
    for kwargs, window, vmin in [({"dynamic_range_db": 95.0}, 95, -155.0), ({"vmin": -95.0}, 35, -95.0),
                                 ({"vmin": -165.0, "vmax": -50.0}, 115, -165.0)]:
        ax = plot_coverage(cmap, **kwargs).axes
        n = int((np.isfinite(values) & (values < vmin)).sum())
        text, _ = find(legend_entries(ax), f"below the colour scale's {window} dB window")
        assert f"({n} cell{'s' if n != 1 else ''})" in text
        assert int(np.all(drawn_colors(ax) == to_rgba(BELOW_COLOR), axis=-1).sum()) == n


def test_no_below_window_entry_nor_triangle_when_every_value_fits():
    ax = plot_coverage(make_map(), vmin=-200.0).axes
    entries = legend_entries(ax)
    assert not any("below the colour scale" in t for t in entries)
    assert colorbar_of(ax).extend == "neither"


def test_absent_categories_are_not_in_the_legend():
    reached = [(False, 0.0, 1e-6), (False, 1e-8, 0.0)] * 4  # every cell reached, none inside, 20 dB span
    ax = plot_coverage(make_map(reached)).axes
    assert list(legend_entries(ax)) == ["transmitter"]


def test_a_mechanism_names_cells_reached_by_no_path_of_its_kind():
    cmap = make_map()
    ax = plot_coverage(cmap, "los_gain_db").axes
    entries = legend_entries(ax)
    absent = np.isneginf(cmap.quantity("los_gain_db")) & ~cmap.without_paths() & ~cmap.inside
    text, handle = find(entries, "reached, but by no line-of-sight path")
    assert f"({int(absent.sum())} cells)" in text and absent.sum() == 4
    assert handle.get_facecolor() == pytest.approx(to_rgba(ABSENT_COLOR))
    np.testing.assert_allclose(drawn_colors(ax)[absent], np.broadcast_to(to_rgba(ABSENT_COLOR), (4, 4)), atol=1e-6)
    find(entries, "no path reached the cell")  # still told apart from "no path at all"


def test_no_legend_on_request():
    assert plot_coverage(make_map(), legend=False).axes.get_legend() is None


# ---- the title and the colour bar ------------------------------------------------------------
@pytest.mark.parametrize("quantity, words, unit", [
    ("path_gain_db", "Path gain [dB]", "dB"),
    ("received_power_dbm", "Received power [dBm]", "dBm"),
    ("field_strength_dbuv_m", "Field strength [dBµV/m]", "dBµV/m"),
    ("los_gain_db", "Line-of-sight gain [dB]", "dB"),
    ("reflection_gain_db", "Reflected-path gain [dB]", "dB"),
    ("diffraction_gain_db", "Diffracted-path gain [dB]", "dB"),
])
def test_title_and_colour_bar_name_the_quantity_with_its_unit(quantity, words, unit):
    cmap = make_map()
    ax = plot_coverage(cmap, quantity).axes
    title = ax.get_title()
    assert title.startswith(f"{words}, canyon.obj\n")
    assert quantity not in title
    flat = title.replace("\n", " ")
    assert "3.5 GHz" in flat and "height 1.5 m" in flat and "1 m cells" in flat
    assert "tx at (\u22123, 0, 10) m" in flat
    assert ("tx power 20 dBm" in flat) == (quantity in ("received_power_dbm", "field_strength_dbuv_m"))
    assert colorbar_of(ax).ax.get_ylabel() == words


def test_title_names_frequency_cells_and_transmitters():
    grid = PlanarGrid(center=[0, 0, 2.0], size=[8, 2], cell_size=[2.0, 1.0])
    cmap = make_map(grid=grid, tx_positions=[(-3.0, 0, 10), (3.0, 0, 10)], frequency_hz=28e9, metadata={})
    flat = plot_coverage(cmap).axes.get_title().replace("\n", " ")
    assert flat.startswith("Path gain [dB] ")  # no scene recorded: none named
    assert "28 GHz" in flat and "height 2 m" in flat and "2 x 1 m cells" in flat
    assert "2 transmitters, best server" in flat
    assert "tx 1 of 2 at (3, 0, 10) m" in plot_coverage(cmap, tx=1).axes.get_title().replace("\n", " ")
    vertical = PlanarGrid(center=[0, 3.9, 2.0], size=[4, 2], cell_size=1.0, orientation=[0, 0, np.pi / 2])
    flat = plot_coverage(make_map(grid=vertical)).axes.get_title().replace("\n", " ")
    assert "plane y = 3.9 m" in flat and "height" not in flat


def test_a_given_title_is_kept_with_identifiers_in_words_and_the_details_below():
    cmap = make_map()
    title = plot_coverage(cmap, "received_power_dbm", title="canyon: received_power_dbm").axes.get_title()
    head, details = title.split("\n", 1)
    assert head == "canyon: Received power [dBm]"
    assert "3.5 GHz" in details and "tx power 20 dBm" in details
    assert plot_coverage(cmap, title="my map", details=False).axes.get_title() == "my map"
    assert plot_coverage(cmap, details=False).axes.get_title() == "Path gain [dB], canyon.obj"


def test_a_narrow_panel_wraps_the_details():
    fig = Figure(figsize=(12, 4), layout="constrained")
    axes = fig.subplots(1, 3)
    cmap = make_map(tx_positions=[(-3.0, 0, 10), (3.0, 0, 10)])
    plot_coverage(cmap, "received_power_dbm", ax=axes[0])
    lines = axes[0].get_title().split("\n")
    assert len(lines) >= 3 and max(len(line) for line in lines[1:]) < len(", ".join(lines[1:]))


# ---- figures supplied by the caller ----------------------------------------------------------
def test_an_axes_without_a_layout_engine_gets_its_colour_bar_beside_it():
    fig = Figure()
    ax = fig.add_subplot()
    art = plot_coverage(make_map(), ax=ax)
    assert art.axes is ax and colorbar_of(ax).ax.get_ylabel() == "Path gain [dB]"
    fig.canvas.draw()


# ---- mesh grids: outlines when the receivers share a height ----------------------------------
def canyon_mesh(slope: float = 0.0) -> MeshGrid:
    xs, ys = np.linspace(-60, 60, 13), np.linspace(-30, 30, 7)
    x, y = np.meshgrid(xs, ys)
    verts = np.stack([x.ravel(), y.ravel(), 1.5 + slope * (x.ravel() + 60)], axis=1)
    nx = len(xs)
    faces = []
    for j in range(len(ys) - 1):
        for i in range(nx - 1):
            a = j * nx + i
            faces += [[a, a + 1, a + nx + 1], [a, a + nx + 1, a + nx]]
    return MeshGrid(verts, np.array(faces))


def mesh_map(grid: MeshGrid) -> CoverageMap:
    n = grid.num_cells
    cells = [(False, 1e-7, 0.0), (False, 0.0, 1e-9), (False, 0.0, 0.0)] * (n // 3)
    return make_map(cells + [(False, 1e-8, 0.0)] * (n - len(cells)), grid=grid)


def test_a_flat_mesh_grid_shows_the_building_outlines():
    canyon = load_scene("street_canyon")
    ax = plot_coverage(mesh_map(canyon_mesh()), scene=canyon).axes
    lines = [c for c in ax.collections if hasattr(c, "get_segments")]
    assert len(lines) == 1 and len(lines[0].get_segments()) > 0
    segments = np.concatenate(lines[0].get_segments())
    assert np.isclose(np.abs(segments[:, 1]), 10.0).any()  # the street's walls at y = +-10 m
    flat = ax.get_title().replace("\n", " ")
    assert "mesh of 144 faces, height 1.5 m" in flat
    find(legend_entries(ax), "no path reached the cell")


def test_a_sloped_mesh_grid_gets_no_outlines():
    canyon = load_scene("street_canyon")
    ax = plot_coverage(mesh_map(canyon_mesh(slope=0.1)), scene=canyon).axes
    assert not [c for c in ax.collections if hasattr(c, "get_segments")]
    assert "heights" in ax.get_title()


# ---- the file ----------------------------------------------------------------------------------
def test_save_png_writes_the_picture(tmp_path):
    out = save_png(make_map(), str(tmp_path / "coverage.png"), "received_power_dbm")
    assert out == str(tmp_path / "coverage.png")
    data = (tmp_path / "coverage.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
