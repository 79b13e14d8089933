"""Pictures of coverage maps with matplotlib (no pyplot state: figures are built directly).

A planar map is drawn in the grid's plane: axes that coincide with a world axis are
labelled and offset like it (a horizontal grid shows world ``x``, ``y``; the vertical
wall of the shutter example shows ``x``, ``z``). The scene is drawn as white lines (with a
dark edge) where its triangles cut the grid's plane (building walls at the receiver
height); a mesh grid whose receivers share one height (within a tenth of a face edge) gets
the same outlines at that height, a sloped or curved mesh none. Each transmitter is a red
star at its projection on the plane.

Cells that show no value of the colour scale have their own colours, named in a legend
under the map with their counts (only the categories present):

* dark grey: no path reaches the cell (:meth:`CoverageMap.without_paths`, whatever the
  quantity);
* light grey: inside a solid object (masked, not traced);
* mid grey: reached, but by no path of the quantity's kind (``-inf`` dB of a mechanism);
* white: a value below the colour scale's window (``vmin``; by default the top value minus
  ``dynamic_range_db``). The colour bar's lower triangle, drawn only when such cells exist,
  has the same colour: matplotlib's usual meaning, "below the range". Values above the
  window (a ``vmax`` given) take its top colour, with an upper triangle.

The default title names the quantity in words with its unit, the scene, and on a second
line the frequency, the transmit power (for received power and field strength), how the
paths add up, the grid (height, cell size) and the transmitters.
"""

from __future__ import annotations

import os
import re
from typing import TYPE_CHECKING

import numpy as np

from .grid import MeshGrid, PlanarGrid

if TYPE_CHECKING:  # pragma: no cover
    import matplotlib.artist

    from ..scene.model import Scene
    from .result import CoverageMap

LABELS = {
    "path_gain_db": "Path gain [dB]",
    "received_power_dbm": "Received power [dBm]",
    "field_strength_dbuv_m": "Field strength [dBµV/m]",
    "los_gain_db": "Line-of-sight gain [dB]",
    "reflection_gain_db": "Reflected-path gain [dB]",
    "diffraction_gain_db": "Diffracted-path gain [dB]",
}
UNITS = {
    "path_gain_db": "dB",
    "received_power_dbm": "dBm",
    "field_strength_dbuv_m": "dBµV/m",
    "los_gain_db": "dB",
    "reflection_gain_db": "dB",
    "diffraction_gain_db": "dB",
}
KINDS = {  # the paths a mechanism quantity keeps, for "reached, but by no ... path"
    "los_gain_db": "line-of-sight",
    "reflection_gain_db": "reflected",
    "diffraction_gain_db": "diffracted",
}
TX_POWER_QUANTITIES = ("received_power_dbm", "field_strength_dbuv_m")  # depend on tx_power_dbm

NO_PATH_COLOR = "0.15"  # cells no path reaches
INSIDE_COLOR = "0.85"  # cells inside solid objects (masked)
ABSENT_COLOR = "0.5"  # cells reached only by paths the quantity leaves out
BELOW_COLOR = "white"  # cells whose value lies below the colour scale's window
OUTLINE_COLOR = "white"  # where the scene cuts the map's plane


def color_range(values: np.ndarray, dynamic_range_db: float = 80.0) -> tuple[float, float]:
    """(vmin, vmax) covering the finite values, at most ``dynamic_range_db`` below the top."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return -1.0, 0.0
    vmax = float(finite.max())
    vmin = max(float(finite.min()), vmax - dynamic_range_db)
    return (vmin, vmax) if vmin < vmax else (vmax - 1.0, vmax)


def _axis_name(vec: np.ndarray) -> tuple[str, int] | None:
    for i, name in enumerate("xyz"):
        if abs(abs(vec[i]) - 1.0) < 1e-9:
            return name, i
    return None


def plane_axes(grid: PlanarGrid) -> list[tuple[float, float, str]]:
    """How the plot shows the grid's ``u`` and ``v``: ``(offset, sign, label)`` for each.

    A grid axis along a world axis ``i`` is shown in world coordinates: ``shown = offset +
    sign * local`` with ``offset = center[i]`` and ``sign`` the direction of the grid axis
    along world axis ``i`` (``+1`` or ``-1``); otherwise in metres from the grid centre.
    """
    r = grid.rotation
    out = []
    for j, local in ((0, "u"), (1, "v")):
        named = _axis_name(r[:, j])
        if named is None:
            out.append((0.0, 1.0, f"{local} [m] (from the grid centre)"))
        else:
            name, i = named
            sign = float(np.sign(r[i, j]))
            out.append((float(grid.center[i]), sign, f"{name} [m]"))  # world = centre + sign * local
    return out


def _cuts(local: np.ndarray, tol: float) -> np.ndarray:
    """(k, 3, 3) triangles in a plane's frame ``(u, v, distance)`` -> (s, 2, 2) segments
    where they cross ``distance = 0``, in ``(u, v)``."""
    d = local[:, :, 2]
    d = np.where(np.abs(d) <= tol, 0.0, d)
    straddle = (d.min(axis=1) < 0) & (d.max(axis=1) > 0)
    local, d = local[straddle], d[straddle]
    segs = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        da, db = d[:, a], d[:, b]
        cross = (da * db < 0) | ((da == 0) ^ (db == 0))
        t = np.where(cross, da / np.where(da - db != 0, da - db, 1.0), np.nan)
        p = local[:, a, :2] + t[:, None] * (local[:, b, :2] - local[:, a, :2])
        segs.append(np.where(cross[:, None], p, np.nan))
    pts = np.stack(segs, axis=1)  # (k, 3 sides, 2): two of the three are crossings
    ok = ~np.isnan(pts[:, :, 0])
    first = np.argmax(ok, axis=1)
    last = 2 - np.argmax(ok[:, ::-1], axis=1)
    rows = np.arange(len(pts))
    keep = ok.sum(axis=1) >= 2
    return np.stack([pts[rows, first], pts[rows, last]], axis=1)[keep]


def plane_cuts(scene: "Scene", grid: PlanarGrid) -> np.ndarray:
    """(s, 2, 2) float64: segments where the scene's triangles cut the grid's plane, in
    the plane's local ``(u, v)`` [m]."""
    local = grid.to_local(scene.vertices[scene.triangles].reshape(-1, 3)).reshape(-1, 3, 3)
    return _cuts(local, scene.length_tolerance(scene.tolerances.plane_distance))


def mesh_height(grid: MeshGrid, cell_centers: np.ndarray) -> float | None:
    """The one height [m] of a mesh grid's receivers, when they all lie within a tenth of the
    median face edge of it (a flat, horizontal measurement mesh); else ``None``."""
    z = np.asarray(cell_centers, dtype=float).reshape(-1, 3)[:, 2]
    tri = grid.vertices[grid.faces]
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)
    return float(np.median(z)) if np.ptp(z) <= 0.1 * float(np.median(edges)) else None


def horizontal_cuts(scene: "Scene", z: float) -> np.ndarray:
    """(s, 2, 2) float64: segments where the scene's triangles cut the plane at height ``z``,
    in world ``(x, y)`` [m]."""
    local = scene.vertices[scene.triangles].astype(np.float64) - np.array([0.0, 0.0, z])
    return _cuts(local, scene.length_tolerance(scene.tolerances.plane_distance))


def _ghz(frequency_hz: float) -> str:
    return f"{frequency_hz / 1e9:.4g} GHz"


def _metres(x: float) -> str:
    return f"{x:.4g} m"


def _grid_text(cmap: "CoverageMap") -> str:
    g = cmap.grid
    if isinstance(g, PlanarGrid):
        cu, cv = (float(c) for c in g.cell_size)
        cells = f"{cu:.4g} m cells" if cu == cv else f"{cu:.4g} x {cv:.4g} m cells"
        normal = _axis_name(g.rotation[:, 2])
        if normal is None:
            where = f"plane through ({', '.join(f'{c:.4g}' for c in g.center)}) m"
        elif normal[0] == "z":
            where = f"height {_metres(g.center[2])}"
        else:
            where = f"plane {normal[0]} = {_metres(g.center[normal[1]])}"
        return f"{where}, {cells}"
    z = mesh_height(g, cmap.cell_centers)
    tri = g.vertices[g.faces]
    edge = float(np.median(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)))
    if z is not None:
        where = f"height {_metres(z)}"
    else:
        heights = np.asarray(cmap.cell_centers, dtype=float).reshape(-1, 3)[:, 2]
        where = f"heights {heights.min():.4g} to {heights.max():.4g} m"
    return f"mesh of {g.num_cells} faces, {where}, median edge {edge:.3g} m"


def describe(cmap: "CoverageMap", quantity: str, tx: int | None = None) -> str:
    """One line of what a map's picture shows besides its quantity: frequency, transmit power
    (when the quantity depends on it), how paths add up, grid and transmitters."""
    return ", ".join(_details(cmap, quantity, tx))


def _details(cmap: "CoverageMap", quantity: str, tx: int | None = None) -> list[str]:
    parts = [_ghz(cmap.frequency_hz)]
    if quantity in TX_POWER_QUANTITIES:
        parts.append(f"tx power {cmap.tx_power_dbm:.4g} dBm")
    if quantity in KINDS:
        parts.append("power sum")
    else:
        parts.append("coherent sum" if cmap.coherent else "power sum (incoherent)")
    parts.append(_grid_text(cmap))
    if cmap.num_tx > 1 and tx is None:
        parts.append(f"{cmap.num_tx} transmitters, best server")
    else:
        i = 0 if tx is None else tx % cmap.num_tx
        which = "tx" if cmap.num_tx == 1 else f"tx {i} of {cmap.num_tx}"
        parts.append(f"{which} at ({', '.join(f'{c:.10g}' for c in cmap.tx_positions[i])}) m")
    return [_minus(p) for p in parts]


def _wrap(parts: list[str], width: int) -> str:
    """``parts`` joined by ", " into lines of at most ``width`` characters (a longer part alone)."""
    lines: list[str] = []
    for part in parts:
        if lines and len(lines[-1]) + 2 + len(part) <= width:
            lines[-1] += ", " + part
        else:
            if lines:
                lines[-1] += ","
            lines.append(part)
    return "\n".join(lines)


def _minus(text: str) -> str:
    """Minus signs as matplotlib's tick labels write them."""
    return re.sub(r"(?<![\w])-(?=[\d.i])", "\u2212", text)


def default_title(cmap: "CoverageMap", quantity: str) -> str:
    """The quantity in words with its unit and the scene."""
    label = LABELS.get(quantity, quantity)
    scene = cmap.metadata.get("scene")
    return f"{label}, {os.path.basename(str(scene))}" if scene else label


def _figsize(grid) -> tuple[float, float]:
    """A new figure's size [in] that fits a map drawn at equal scales, with its colour bar,
    two title lines, axis labels and legend, without wide empty margins."""
    if isinstance(grid, PlanarGrid):
        ny, nx = grid.shape
        w, h = nx * grid.cell_size[0], ny * grid.cell_size[1]
    else:
        w, h = np.ptp(grid.vertices[np.unique(grid.faces)][:, :2], axis=0)
    ratio = float(h / w) if w > 0 and h > 0 else 0.7
    map_w, map_h = 6.2, 7.5  # the largest map [in]; the rest: colour bar, labels, titles, legend
    if ratio * map_w <= map_h:
        return 8.0, max(4.0, ratio * map_w + 2.0)
    return max(4.5, map_h / ratio + 2.3), map_h + 2.3


def _patch(color: str, label: str):
    from matplotlib.patches import Patch

    return Patch(facecolor=color, edgecolor="0.35", linewidth=0.6, label=label)


def _cells(n: int) -> str:
    return f"{n} cell" if n == 1 else f"{n} cells"


def plot_coverage(
    cmap: "CoverageMap",
    quantity: str = "path_gain_db",
    tx: int | None = None,
    *,
    ax=None,
    scene: "Scene | None" = None,
    vmin: float | None = None,
    vmax: float | None = None,
    dynamic_range_db: float = 80.0,
    colormap: str = "viridis",
    title: str | None = None,
    colorbar: bool = True,
    aspect: str | float = "equal",
    legend: bool = True,
    details: bool = True,
    below_color: str = BELOW_COLOR,
) -> "matplotlib.artist.Artist":
    """Draw one quantity of a coverage map; returns the matplotlib ``AxesImage`` or collection.

    Parameters
    ----------
    cmap : CoverageMap
    quantity : str
        See :meth:`CoverageMap.quantity`.
    tx : int, optional
        A transmitter; default the best server.
    ax : matplotlib Axes, optional
        Where to draw; a new figure (without pyplot) when omitted: ``ax.figure.savefig``.
    scene : Scene, optional
        Draws where the scene cuts the map's plane (for a mesh grid: the horizontal plane
        at its receivers' height, when they share one).
    vmin, vmax : float, optional
        Colour range; default the finite values, at most ``dynamic_range_db`` wide. Values
        below it are drawn in ``below_color`` (and the colour bar gets a lower triangle of
        that colour), values above it in its top colour (an upper triangle). Cells that no
        path reaches (from ``tx``, or from any transmitter) are dark grey, cells reached
        only by paths the quantity leaves out (``-inf`` dB of a mechanism) mid grey, cells
        inside objects light grey.
    title : str, optional
        Default: the quantity in words with its unit, and the scene. A quantity's
        identifier in a given title (``path_gain_db``) is written in words too.
    aspect : "equal", "auto" or float
        As matplotlib's ``imshow``.
    legend : bool
        A legend under the map naming the special colours present, with their cell counts,
        and the transmitter marker.
    details : bool
        A second title line: frequency, transmit power (received power, field strength),
        coherent or power sum, grid height and cell size, transmitters.
    below_color : matplotlib colour
        Cells below the colour range.
    """
    import matplotlib
    import matplotlib.font_manager
    from matplotlib import patheffects
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import LineCollection
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.layout_engine import ConstrainedLayoutEngine
    from matplotlib.lines import Line2D
    from matplotlib.transforms import ScaledTranslation

    values = cmap.quantity(quantity, tx)
    no_path = cmap.without_paths(tx)
    inside = np.asarray(cmap.inside, dtype=bool)
    # reached, but the quantity is zero there (no path of its mechanism): its own colour
    absent = np.isneginf(values) & ~no_path & ~inside
    lo, hi = color_range(values, dynamic_range_db)
    vmin = lo if vmin is None else float(vmin)
    vmax = hi if vmax is None else float(vmax)
    finite = np.isfinite(values)
    below = finite & (values < vmin) & ~no_path & ~inside
    above = finite & (values > vmax)
    if ax is None:
        fig = Figure(figsize=_figsize(cmap.grid) if aspect == "equal" else (8, 5.5), layout="constrained")
        ax = fig.add_subplot()
    colors = matplotlib.colormaps[colormap].with_extremes(bad=INSIDE_COLOR, under=NO_PATH_COLOR)
    label = LABELS.get(quantity, quantity)
    # the image's data: no path under the range (dark grey), values below it at its bottom
    # (drawn over in below_color), absent cells NaN (drawn over in ABSENT_COLOR)
    shown = np.where(no_path, vmin - 1.0, np.maximum(values, vmin))
    shown = np.where(absent | inside, np.nan, shown)  # inside: NaN already in a traced map
    codes = np.where(absent, 0.0, np.where(below, 1.0, np.nan))  # the overlay: 0 absent, 1 below
    overlay = np.ma.masked_invalid(codes)
    overlay_colors = ListedColormap([ABSENT_COLOR, below_color])
    tx_local = None
    outlines = None
    if isinstance(cmap.grid, PlanarGrid):
        g = cmap.grid
        u, v = g.local_coordinates()
        (ou, su, lu), (ov, sv, lv) = plane_axes(g)
        hu, hv = 0.5 * g.cell_size
        extent = [ou + su * (u[0] - hu), ou + su * (u[-1] + hu), ov + sv * (v[0] - hv), ov + sv * (v[-1] + hv)]
        art = ax.imshow(shown, origin="lower", extent=extent, cmap=colors, vmin=vmin, vmax=vmax,
                        interpolation="nearest", aspect=aspect)
        if (absent | below).any():
            ax.imshow(overlay, origin="lower", extent=extent, cmap=overlay_colors, vmin=-0.5, vmax=1.5,
                      interpolation="nearest", aspect=aspect)
        if scene is not None:
            cuts = plane_cuts(scene, g)
            if len(cuts):
                outlines = np.stack([ou + su * cuts[..., 0], ov + sv * cuts[..., 1]], axis=-1)
        loc = g.to_local(cmap.tx_positions)
        tx_local = np.stack([ou + su * loc[:, 0], ov + sv * loc[:, 1]], axis=1)
        ax.set_xlabel(lu)
        ax.set_ylabel(lv)
        ax.set_xlim(sorted(extent[:2]))
        ax.set_ylim(sorted(extent[2:]))
    elif isinstance(cmap.grid, MeshGrid):
        m = cmap.grid
        art = ax.tripcolor(m.vertices[:, 0], m.vertices[:, 1], m.faces, facecolors=shown, cmap=colors,
                           vmin=vmin, vmax=vmax)
        special = absent | below
        if special.any():
            ax.tripcolor(m.vertices[:, 0], m.vertices[:, 1], m.faces[special], facecolors=codes[special],
                         cmap=overlay_colors, vmin=-0.5, vmax=1.5)
        if scene is not None:
            z = mesh_height(m, cmap.cell_centers)
            if z is not None:
                cuts = horizontal_cuts(scene, z)
                if len(cuts):
                    outlines = cuts
        used = m.vertices[np.unique(m.faces)]
        ax.set_xlim(used[:, 0].min(), used[:, 0].max())  # no margins: as a planar map
        ax.set_ylim(used[:, 1].min(), used[:, 1].max())
        ax.set_aspect(aspect)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        tx_local = cmap.tx_positions[:, :2]
    if outlines is not None:
        xlim, ylim = ax.get_xlim(), ax.get_ylim()
        halo = [patheffects.withStroke(linewidth=1.8, foreground="0.1")]  # seen on white and light grey too
        ax.add_collection(LineCollection(outlines, colors=OUTLINE_COLOR, linewidths=0.8, path_effects=halo))
        ax.set_xlim(xlim)  # the outlines may reach beyond the map: keep its extent
        ax.set_ylim(ylim)
    if tx_local is not None:
        ax.plot(tx_local[:, 0], tx_local[:, 1], "r*", markersize=12, markeredgecolor="k", label="transmitter")
        if cmap.num_tx > 1:
            for i, (x, y) in enumerate(tx_local):
                ax.annotate(f"tx {i}", (x, y), textcoords="offset points", xytext=(6, 6), color="r")
    if colorbar:
        # the triangles mean what they usually do: values beyond the range, in the colours drawn
        bar_colors = matplotlib.colormaps[colormap].with_extremes(under=below_color)
        extend = {(False, False): "neither", (True, False): "min", (False, True): "max", (True, True): "both"}[
            (bool(below.any()), bool(above.any()))]
        mappable = ScalarMappable(norm=art.norm, cmap=bar_colors)
        if isinstance(ax.figure.get_layout_engine(), ConstrainedLayoutEngine):
            # beside the map as drawn (equal scales shrink it inside its box), no taller than it
            cax = ax.inset_axes([1.03, 0.0, 0.035, 1.0])
            bar = ax.figure.colorbar(mappable, cax=cax, label=label, extend=extend)
        else:  # no layout engine to make room for an inset: take the room from the map's axes
            bar = ax.figure.colorbar(mappable, ax=ax, label=label, extend=extend)
        bar.outline.set_linewidth(0.6)
    if legend:
        unit = UNITS.get(quantity, "")
        entries = []
        if tx_local is not None:
            entries.append(Line2D([], [], linestyle="none", marker="*", color="r", markeredgecolor="k", markersize=10,
                                  label="transmitter" if cmap.num_tx == 1 else "transmitters"))
        if no_path.any():
            entries.append(_patch(NO_PATH_COLOR, f"no path reached the cell ({_cells(int(no_path.sum()))})"))
        if inside.any():
            entries.append(_patch(INSIDE_COLOR, f"inside an object, masked ({_cells(int(inside.sum()))})"))
        if absent.any():
            kind = KINDS.get(quantity, "counted")
            entries.append(_patch(ABSENT_COLOR, f"reached, but by no {kind} path, \u2212inf dB "
                                                f"({_cells(int(absent.sum()))})"))
        if below.any():
            entries.append(_patch(below_color, _minus(f"below the colour scale's {vmax - vmin:.4g} dB window, "
                                                      f"< {vmin:.1f} {unit} ({_cells(int(below.sum()))})")))
        if entries:
            # under the x label: ticks, tick labels and the label take about 3 lines of text
            below_axis = ScaledTranslation(0, -(3 * matplotlib.rcParams["font.size"] + 12) / 72,
                                           ax.figure.dpi_scale_trans)
            ax.legend(handles=entries, loc="upper center", bbox_to_anchor=(0.5, 0.0),
                      bbox_transform=ax.transAxes + below_axis, ncols=2, fontsize="small", frameon=False,
                      borderaxespad=0.0, handlelength=1.5, columnspacing=1.5)
    if title is None:
        heading = default_title(cmap, quantity)
    else:
        heading = title
        for name, words in LABELS.items():  # an identifier is no title: write it in words
            heading = heading.replace(name, words)
    if details:
        size = matplotlib.font_manager.FontProperties(size="medium").get_size_in_points()
        width_in = ax.get_position().width * ax.figure.get_figwidth() + 0.5  # the title may overhang a little
        heading = f"{heading}\n{_wrap(_details(cmap, quantity, tx), max(30, int(width_in * 72 / (0.5 * size))))}"
    ax.set_title(heading, fontsize="medium")
    return art


def save_png(cmap: "CoverageMap", path: str, quantity: str = "path_gain_db", scene: "Scene | None" = None,
             dpi: int = 150, **kwargs) -> str:
    """Plot one quantity to a PNG file; returns the path written."""
    art = plot_coverage(cmap, quantity, scene=scene, **kwargs)
    art.axes.figure.savefig(path, dpi=dpi)
    return path
