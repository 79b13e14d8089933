"""``trace()``: every path between transmitters and receivers, exactly and completely.

Cost model (what grows with what):

* once per scene: welding, polygons, dihedra, the Embree BVH — O(triangles);
* once per transmitter: the image tree, O(P^k) for reflection order k before pruning
  (P reflecting polygons), and the (image source, dihedron) sector test,
  O(images x dihedra);
* per receiver tile: reflection candidates O(receivers x images of each order),
  diffraction candidates O(receivers x receiver images x diffracting dihedra) joined
  to the transmitter-side pairs in the same sector, each a handful of vectorised
  dot products; then the surviving segments are ray-cast in one batch per stage
  (Embree, ~10^7 rays/s).

The dominant term in practice is the diffraction join with reflections (it multiplies
transmitter images, receiver images and dihedra); ``stats`` on the result counts every
stage so that this can be checked per scene.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike

from ..errors import WavepathsError
from ..scene.model import Scene
from . import kernels
from .context import TxContext, build_tx_context
from .launched import prepare_launched
from .on_faces import legs_into_solids, points_near_edges, points_on_faces, points_on_surfaces, solid_surface_cones
from .through_vertices import drop_crossed
from .options import TraceOptions, check_trace_arguments
from .paths import Paths, assemble
from .tile import trace_tile


MAX_COORDINATE = 1e9  # [m] positions beyond this lose the float64 precision the engine needs


def check_positions(name: str, value, allow_empty: bool = False) -> np.ndarray:
    """Positions as a finite (k, 3) float64 array within +-``MAX_COORDINATE`` metres,
    or a :class:`WavepathsError` that says why."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WavepathsError(f"`{name}` must be numbers of shape (n, 3) [m]: {exc}") from None
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise WavepathsError(f"`{name}` must have shape (n, 3), got {arr.shape}")
    if not allow_empty and len(arr) == 0:
        raise WavepathsError(f"`{name}` is empty")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise WavepathsError(f"`{name}` has NaN or infinite coordinates at row(s) {np.nonzero(bad)[0][:10].tolist()}")
    far = (np.abs(arr) > MAX_COORDINATE).any(axis=1)
    if far.any():
        raise WavepathsError(
            f"`{name}` has coordinates beyond {MAX_COORDINATE:g} m at row(s) {np.nonzero(far)[0][:10].tolist()} "
            "(float64 cannot resolve wavelengths there)"
        )
    return arr


INSIDE_CHECK_BUDGET = 50_000_000  # (points x triangles of closed objects) tested for the warning


def _warn_inside(scene: Scene, tx: np.ndarray, rx: np.ndarray, tx_face: np.ndarray, rx_face: np.ndarray) -> None:
    """Warn when a transmitter or receiver lies inside a closed object (paths are still traced).

    Points lying on a face (``tx_face``, ``rx_face`` >= 0, :func:`points_on_faces`) are left to
    :func:`_warn_on_faces`: on the surface the parity rule may answer either way, and did, face
    by face (8 of the street canyon's 24 wall faces).
    """
    import warnings

    from ..scene.closed import closed_objects, points_inside_closed
    from ..scene.model import WavepathsWarning

    closed = closed_objects(scene)
    if not closed.any():
        return
    tris = int(np.isin(scene.triangle_object, np.nonzero(closed)[0]).sum())
    for name, pts, face in (("transmitter", tx, tx_face), ("receiver", rx, rx_face)):
        if len(pts) * tris > INSIDE_CHECK_BUDGET:
            continue
        inside = points_inside_closed(scene, pts)
        if (face >= 0).any():  # on a face of an object is not inside it (the search's rule too)
            inside &= ~points_on_surfaces(scene, pts)
        rows = np.nonzero(inside.any(axis=1))[0]
        if len(rows):
            objs = sorted({scene.object_names[o] for o in np.nonzero(inside[rows].any(axis=0))[0]})
            warnings.warn(
                f"{len(rows)} {name}(s) inside closed object(s) {', '.join(objs)} (first: row {rows[0]}); "
                "only the paths that exist from there are returned",
                WavepathsWarning,
                stacklevel=3,
            )


def _warn_on_faces(scene: Scene, tx: np.ndarray, rx: np.ndarray, tx_face: np.ndarray | None = None,
                   rx_face: np.ndarray | None = None, edges: bool = True) -> None:
    """Report transmitters and receivers lying exactly on a face (see :func:`points_on_faces`,
    whose results ``tx_face``, ``rx_face`` may be passed in), and, with ``edges`` (a search
    with diffraction), those off the faces but within the point-in-polygon margin of an edge
    (:func:`points_near_edges`: there the diffraction follows a reflection the margin may
    accept; without diffraction the geometrical-optics field jumps at an edge anyway)."""
    import warnings

    from ..scene.model import WavepathsWarning
    from ..scene.polygon_query import polygon_margin_length

    for name, pts, face in (("transmitter", tx, tx_face), ("receiver", rx, rx_face)):
        if face is None:
            face = points_on_faces(scene, pts)
        rows = np.nonzero(face >= 0)[0]
        if len(rows):
            obj = scene.object_names[scene.polygon_object[face[rows[0]]]]
            warnings.warn(
                f"{len(rows)} {name}(s) lie exactly on a face (first: row {rows[0]}, object {obj}): they take "
                "part in no reflection or diffraction there, and the field there is the limit from neither "
                "side of the face; move them off it (any distance above the plane tolerance is exact)",
                WavepathsWarning,
                stacklevel=3,
            )
        if not edges:
            continue
        edge, dist = points_near_edges(scene, pts)
        rows = np.nonzero((edge >= 0) & (face < 0))[0]
        if len(rows):
            r = rows[0]
            obj = scene.object_names[scene.triangle_object[scene.dihedra.face_triangle[scene.dihedra.face_ptr[edge[r]]]]]
            warnings.warn(
                f"{len(rows)} {name}(s) lie within {polygon_margin_length(scene):.2g} m of an edge, off its faces "
                f"(first: row {r}, {dist[r]:.2g} m from an edge of object {obj}): there the search's point-in-polygon "
                "margin may accept a reflection on the edge's faces just beyond the edge, and the fields may be off "
                f"by several dB; move them at least {polygon_margin_length(scene):.2g} m from the edge, or onto it",
                WavepathsWarning,
                stacklevel=3,
            )


def _check_context(context, scene: Scene, tx: np.ndarray, opts: TraceOptions) -> None:
    """A :class:`TxContext` given to :func:`trace` must be for its scene, transmitters and
    options: one built for others gives paths from the wrong sources, with no error (a review
    traced 76 paths from a context of another transmitter, where there are 78)."""
    if not isinstance(context, TxContext):
        raise WavepathsError(f"`context` must be a TxContext from build_tx_context, got {type(context).__name__}")
    if context.scene_fingerprint and context.scene_fingerprint != scene.fingerprint:
        raise WavepathsError("`context` was built for another scene (or another version of this one)")
    if context.tx.shape != tx.shape or not np.array_equal(context.tx, tx):
        raise WavepathsError(f"`context` was built for the transmitters {context.tx.tolist()}, not {tx.tolist()}")
    if context.options != opts:
        diff = [f.name for f in dataclasses.fields(opts) if getattr(opts, f.name) != getattr(context.options, f.name)]
        raise WavepathsError(f"`context` was built with other options (they differ in {diff}): build it with "
                             f"these options, or pass no context")


THREADS_MIN_WORK = 1 << 22
"""Receivers x image chains from which :func:`trace` runs tiles on threads by default: the
street canyon's 100-receiver query (70 k) ran 1.4x slower on two threads, ``etoile_crop``'s
(67 M) 1.3x faster."""


def trace(
    scene: Scene,
    tx: ArrayLike,
    rx: ArrayLike,
    options: TraceOptions | None = None,
    *,
    context: TxContext | None = None,
    progress: Callable[[int], None] | None = None,
    threads: int | None = None,
) -> Paths:
    """Find every propagation path from each transmitter to each receiver.

    Parameters
    ----------
    scene : Scene
    tx : (m, 3) array_like
        Transmitter positions [m].
    rx : (n, 3) array_like
        Receiver positions [m].
    options : TraceOptions, optional
        What to trace (default: line of sight, reflections to order 2, first-order
        diffraction with one reflection before or after it).
    context : TxContext, optional
        Transmitter-side work built earlier by
        :func:`~wavepaths.search.context.build_tx_context` for this scene, these ``tx`` and
        these options (one built for others is refused).
    progress : callable, optional
        Called with the number of receivers finished after each tile.
    threads : int, optional
        Receiver tiles traced at once, on threads of this process (the compiled kernels and
        numpy's array work release the GIL). Default: the compiled kernels' thread count
        (:func:`wavepaths.search.kernels.threads`, the cores numba uses; 1 without numba)
        when the query is large (receivers x the transmitters' image chains at least
        ``THREADS_MIN_WORK``), else 1: small queries run faster on one thread. With more
        than one, the receivers are cut into at least two tiles per thread (tiles of at most
        ``options.rx_batch``), and the paths are the same as with ``threads=1``.

    Returns
    -------
    Paths
        Flat struct of arrays, sorted by (tx, rx, depth, length); ``stats`` counts
        candidates and rejections per stage and rays cast.

    Raises
    ------
    WavepathsError
        Positions that are not (n, 3) or not finite, a transmitter that coincides
        with a receiver, ``options.tolerance_db`` (coverage maps only), or a ``context``
        built for another scene, other transmitters or other options.

    Notes
    -----
    Defined edge cases: a transmitter or receiver lying exactly on a face or an edge
    takes part in no reflection or diffraction on that face or edge (its direction
    relative to them is undefined); other paths are found as usual.
    """
    opts = check_trace_arguments(scene, options)
    if opts.tolerance_db is not None:
        raise WavepathsError("`tolerance_db` applies to coverage maps only (it needs the fields of the other paths); "
                             "use `prune_db` with `prune_frequency_hz` for a path query")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1):
        raise WavepathsError(f"`threads` must be a positive integer, got {threads!r}")
    tx = check_positions("tx", tx)
    rx = check_positions("rx", rx)
    diff = np.linalg.norm(tx[:, None, :] - rx[None, :, :], axis=2)
    if (diff <= scene.length_tolerance(scene.tolerances.weld)).any():
        i, j = np.argwhere(diff <= scene.length_tolerance(scene.tolerances.weld))[0]
        raise WavepathsError(f"transmitter {i} and receiver {j} are at the same position {tx[i].tolist()}")
    tx_face, rx_face = points_on_faces(scene, tx), points_on_faces(scene, rx)
    _warn_inside(scene, tx, rx, tx_face, rx_face)
    _warn_on_faces(scene, tx, rx, tx_face, rx_face, edges=opts.diffraction)
    if context is not None:
        _check_context(context, scene, tx, opts)
    ctx = context if context is not None else build_tx_context(scene, tx, opts)
    prepare_launched(scene, ctx, rx)  # launched candidates: the fans traced once for every tile
    stats: Counter = Counter(ctx.stats)
    batches = []
    n_threads = int(threads) if threads is not None else (
        kernels.threads() if len(rx) * sum(len(lv) for lv in ctx.levels) >= THREADS_MIN_WORK else 1)
    if opts.launched:
        # the launched tiles' tube kernels run on numba's threads themselves and must not be
        # entered from two threads at once (numba's workqueue layer aborts the process)
        n_threads = 1
    size = opts.rx_batch
    if n_threads > 1 and len(rx) >= 4 * n_threads:
        # two tiles per thread at least, so that the threads stay busy to the end
        size = min(size, -(-len(rx) // (2 * n_threads)))
    else:
        n_threads = 1
    starts = list(range(0, len(rx), size))
    if n_threads > 1:
        _ = scene.raycaster, scene.exact_raycaster  # the casters built once here, not by two tiles at once

    def tile(s: int):
        return trace_tile(scene, ctx, rx[s : s + size], s)

    for s, (b, st) in zip(starts, kernels.in_threads(tile, starts, n_threads)):
        batches += b
        stats.update(st)
        if progress is not None:
            progress(min(len(rx), s + size))
    paths = assemble(tx, rx, batches, dict(stats), merge_tol=scene.length_tolerance(scene.tolerances.weld))
    paths = drop_crossed(scene, paths, stats, None if opts.compiled else False)  # through a face at a reflection
    paths.stats.update(stats)
    if (tx_face >= 0).any() or (rx_face >= 0).any():  # ends on faces: legs through a solid they lie on
        inward = legs_into_solids(paths, _cones_of(scene, tx, tx_face), _cones_of(scene, rx, rx_face))
        if inward.any():
            stats["paths_dropped_into_solid"] = int(inward.sum())
            paths = paths.select(~inward)
            paths.stats.update(stats)
    return dataclasses.replace(paths, scene_fingerprint=scene.geometry_fingerprint)


def _cones_of(scene: Scene, points: np.ndarray, face: np.ndarray) -> dict:
    """:func:`~wavepaths.search.on_faces.solid_surface_cones` of the points on a face, by their rows."""
    rows = np.nonzero(face >= 0)[0]
    found = solid_surface_cones(scene, points[rows])
    return {int(rows[i]): c for i, c in found.items()}
