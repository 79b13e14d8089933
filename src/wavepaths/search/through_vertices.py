"""Paths that pass through a face at one of their reflection points.

A reflection point ``P`` may lie exactly on another face's boundary: a ground reflection on
the foot line of a wall, a facade reflection on a building's corner edge. Each leg then
starts or ends on that face, and by the casters' rule (:mod:`wavepaths.raycast`) an end on a
surface does not hit it, so neither leg is blocked, even when the two legs lie on opposite
sides of the face: the path crosses the wall at its foot, into or out of a closed building
(a review found 31 cells of a street-canyon map lit from a transmitter inside a building).
Coverage grids with round coordinates meet such alignments systematically.

:func:`crossed_at_reflections` casts, for every reflection point, the chord between the two
points at distance ``delta`` from ``P`` on its legs: both lie on legs already cast clear, so
the chord is blocked only by a face that separates the legs within ``delta`` of ``P``. The
chord runs parallel to the mirror (a specular reflection's legs make equal angles with it)
at height ``delta |cos(theta)|``; ``delta`` is :data:`CHORD` of the scene diagonal, raised
for grazing reflections until that height is :data:`HEIGHT` of the diagonal (far above the
casters' plane tolerance, 1e-12 of it), and at most a quarter of the shorter leg. A
reflection too grazing for both is not tested (kept). Diffraction points are not tested:
the chord between a diffracted path's legs crosses the wedge itself, and the dihedron
holds every face along the edge (seed §3.2-3.3).

What is taken as blocked beyond the closed-triangle rule: a face that comes within
``delta`` (1e-6 of the diagonal, 0.25 mm on the street canyon) of a reflection point
between its legs without touching them.
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING

import numpy as np

from .paths import InteractionType

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .paths import Paths

CHORD = 1e-6
"""The chord's distance from the reflection point along each leg, in scene diagonals."""
HEIGHT = 1e-9
"""The least height of the chord above the mirror's plane, in scene diagonals."""


def crossed_at_reflections(scene: "Scene", paths: "Paths", stats: Counter | None = None,
                           compiled: bool | None = None) -> np.ndarray:
    """(N,) bool: the paths whose legs at some reflection point lie on opposite sides of a face
    through it (see the module docstring), by one cast per reflection point.

    Parameters
    ----------
    scene : Scene
    paths : Paths
    stats : Counter, optional
        ``rays_cast_reflection_chords`` is added to it.
    compiled : bool, optional
        The chords in :func:`wavepaths.search._numba_chords.reflection_chords` (default when
        numba is installed); ``False``: :func:`reflection_chords_numpy`, its reference.
    """
    out = np.zeros(len(paths), dtype=bool)
    if len(paths) == 0 or paths.max_depth == 0:
        return out
    from . import kernels

    args = (np.ascontiguousarray(paths.vertices, dtype=np.float64), np.ascontiguousarray(paths.interactions),
            np.ascontiguousarray(paths.primitive, dtype=np.int64), scene.polygon_normal,
            CHORD * scene.diagonal, HEIGHT * scene.diagonal)
    if compiled is not False and kernels.available():
        from ._numba_chords import reflection_chords

        A, B, row = reflection_chords(*args)
    else:
        A, B, row = reflection_chords_numpy(*args)
    if len(row) == 0:
        return out
    hit = scene.raycaster.occluded(A, B)
    if stats is not None:
        stats["rays_cast_reflection_chords"] += len(row)
    out[row[hit]] = True
    return out


def drop_crossed(scene: "Scene", paths: "Paths", stats: Counter, compiled: bool | None = None) -> "Paths":
    """``paths`` without those :func:`crossed_at_reflections` finds, counted in
    ``stats["paths_dropped_through_a_face"]`` (set, for this set of paths)."""
    crossed = crossed_at_reflections(scene, paths, stats, compiled)
    stats["paths_dropped_through_a_face"] = int(crossed.sum())
    return paths.select(~crossed) if crossed.any() else paths


def reflection_chords_numpy(V: np.ndarray, kinds: np.ndarray, prim: np.ndarray, normal: np.ndarray, chord: float,
                            height: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The chords of :func:`crossed_at_reflections`: ends ``A``, ``B`` (m, 3) [m] and the path
    of each (m,), one per reflection point whose chord stands at least ``height`` [m] above its
    mirror; ``V`` (N, D + 2, 3) the paths' vertices, ``kinds`` and ``prim`` (N, D) their
    interactions and primitives, ``normal`` (p, 3) the polygons' unit normals, ``chord`` [m]
    the distance from the reflection point along each leg (raised for grazing reflections)."""
    rows, j = np.nonzero(kinds == InteractionType.REFLECTION)
    P, prev, nxt = V[rows, j + 1], V[rows, j], V[rows, j + 2]
    a, b = prev - P, nxt - P
    la, lb = np.sqrt(np.einsum("ij,ij->i", a, a)), np.sqrt(np.einsum("ij,ij->i", b, b))
    ok = (la > 0) & (lb > 0)
    ua = a / np.where(ok, la, 1.0)[:, None]
    ub = b / np.where(ok, lb, 1.0)[:, None]
    cos_t = np.abs(np.einsum("ij,ij->i", ua, normal[prim[rows, j]]))
    cap = 0.25 * np.minimum(la, lb)
    ok &= cap * cos_t >= height  # decided before dividing: no rounding skips a chord
    delta = np.minimum(np.maximum(chord, height / np.where(ok, cos_t, 1.0)), cap)
    sel = np.nonzero(ok)[0]
    return P[sel] + delta[sel, None] * ua[sel], P[sel] + delta[sel, None] * ub[sel], rows[sel]
