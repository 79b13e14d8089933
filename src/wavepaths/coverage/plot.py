"""Pictures of coverage maps with matplotlib (no pyplot state: figures are built directly).

A planar map is drawn in the grid's plane: axes that coincide with a world axis are
labelled and offset like it (a horizontal grid shows world ``x``, ``y``; the vertical
wall of the shutter example shows ``x``, ``z``). The scene is drawn as the lines where
its triangles cut the grid's plane (building walls at the receiver height), cells inside
solid objects are light grey, cells no path reaches dark grey (the colour bar's "under"
triangle; :meth:`CoverageMap.without_paths`, whatever the quantity), cells that paths reach
but where the quantity is zero (a mechanism none of them has: ``-inf`` dB) mid grey, values
merely below the colour range take its lowest colour, and each
transmitter is a red star at its projection on the plane.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .grid import MeshGrid, PlanarGrid

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .result import CoverageMap

LABELS = {
    "path_gain_db": "path gain [dB]",
    "received_power_dbm": "received power [dBm]",
    "field_strength_dbuv_m": "field strength [dBuV/m]",
    "los_gain_db": "line-of-sight gain [dB]",
    "reflection_gain_db": "reflected gain [dB]",
    "diffraction_gain_db": "diffracted gain [dB]",
}


ABSENT_COLOR = "0.5"  # cells reached only by paths the quantity leaves out


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


def plane_cuts(scene: "Scene", grid: PlanarGrid) -> np.ndarray:
    """(s, 2, 2) float64: segments where the scene's triangles cut the grid's plane, in
    the plane's local ``(u, v)`` [m]."""
    local = grid.to_local(scene.vertices[scene.triangles].reshape(-1, 3)).reshape(-1, 3, 3)
    d = local[:, :, 2]
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
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
):
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
        Draws where the scene cuts the map's plane.
    vmin, vmax : float, optional
        Colour range; default the finite values, at most ``dynamic_range_db`` wide. Values
        below it take its lowest colour; the colour bar's "under" colour (dark grey, the
        triangle) marks cells that no path reaches (from ``tx``, or from any transmitter),
        mid grey cells reached only by paths the quantity leaves out (``-inf`` dB of a
        mechanism), light grey cells inside objects.
    aspect : "equal", "auto" or float
        As matplotlib's ``imshow``.
    """
    import matplotlib
    from matplotlib.collections import LineCollection
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    values = cmap.quantity(quantity, tx)
    no_path = cmap.without_paths(tx)
    # reached, but the quantity is zero there (no path of its mechanism): its own colour
    absent = np.isneginf(values) & ~no_path & ~cmap.inside
    lo, hi = color_range(values, dynamic_range_db)
    vmin = lo if vmin is None else vmin
    vmax = hi if vmax is None else vmax
    if ax is None:
        fig = Figure(figsize=(8, 5.5), layout="constrained")
        ax = fig.add_subplot()
    colors = matplotlib.colormaps[colormap].with_extremes(bad="0.85", under="0.15")
    label = LABELS.get(quantity, quantity)
    # finite values below the range take its lowest colour; the "under" colour means no path
    shown = np.where(no_path, vmin - 1.0, np.maximum(values, vmin))
    shown = np.where(absent, np.nan, shown)  # drawn over in ABSENT_COLOR below
    absent_layer = np.ma.masked_where(~absent, np.zeros(absent.shape))
    absent_colors = ListedColormap([ABSENT_COLOR])
    tx_local = None
    if isinstance(cmap.grid, PlanarGrid):
        g = cmap.grid
        u, v = g.local_coordinates()
        (ou, su, lu), (ov, sv, lv) = plane_axes(g)
        hu, hv = 0.5 * g.cell_size
        extent = [ou + su * (u[0] - hu), ou + su * (u[-1] + hu), ov + sv * (v[0] - hv), ov + sv * (v[-1] + hv)]
        art = ax.imshow(shown, origin="lower", extent=extent, cmap=colors, vmin=vmin, vmax=vmax,
                        interpolation="nearest", aspect=aspect)
        if absent.any():
            ax.imshow(absent_layer, origin="lower", extent=extent, cmap=absent_colors, vmin=0, vmax=1,
                      interpolation="nearest", aspect=aspect)
        if scene is not None:
            cuts = plane_cuts(scene, g)
            if len(cuts):
                cuts = np.stack([ou + su * cuts[..., 0], ov + sv * cuts[..., 1]], axis=-1)
                ax.add_collection(LineCollection(cuts, colors="white", linewidths=0.8))
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
        if absent.any():
            ax.tripcolor(m.vertices[:, 0], m.vertices[:, 1], m.faces[absent], facecolors=np.zeros(int(absent.sum())),
                         cmap=absent_colors, vmin=0, vmax=1)
        ax.set_aspect(aspect)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        tx_local = cmap.tx_positions[:, :2]
    if tx_local is not None:
        ax.plot(tx_local[:, 0], tx_local[:, 1], "r*", markersize=12, markeredgecolor="k", label="transmitter")
        if cmap.num_tx > 1:
            for i, (x, y) in enumerate(tx_local):
                ax.annotate(f"tx {i}", (x, y), textcoords="offset points", xytext=(6, 6), color="r")
    if colorbar:
        extend = "min" if no_path.any() else "neither"  # the triangle: cells no path reaches
        ax.figure.colorbar(art, ax=ax, label=label, extend=extend)
    ax.set_title(title if title is not None else label)
    return art


def save_png(cmap: "CoverageMap", path: str, quantity: str = "path_gain_db", scene: "Scene | None" = None,
             dpi: int = 150, **kwargs) -> str:
    """Plot one quantity to a PNG file; returns the path written."""
    art = plot_coverage(cmap, quantity, scene=scene, **kwargs)
    art.axes.figure.savefig(path, dpi=dpi)
    return path
