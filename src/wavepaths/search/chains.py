"""Candidate chains of a tile: the budget that bounds them, the casts that decide their
occlusion, and the triangles they touch (shared by the line-of-sight, reflection and
diffraction searches of :mod:`wavepaths.search.tile` and :mod:`wavepaths.search.diffraction`).
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene

CANDIDATE_BUDGET = 1 << 21  # candidates held at once (bounds temporaries to ~100 MB)


def leg_order(legs: int) -> list[int]:
    """Legs of a chain in casting order: from the receiver back to the transmitter.

    The legs nearest the receiver are the most often blocked (street-canyon R2+D2 map: 40 %,
    34 %, 16 % and 15 % of four-leg chains, from the last leg to the first), so the chains
    still clear after them, the only ones cast again, are the fewest: 2.39 casts per four-leg
    chain and 2.00 per three-leg chain, against 2.55 and 2.10 in the order last, first, inner.
    """
    return list(range(legs - 1, -1, -1))


def occluded_chains(scene: "Scene", vertices: np.ndarray, stats: Counter, exact: np.ndarray | None = None) -> np.ndarray:
    """(k,) bool: whether any segment of the chains ``vertices`` (k, s, 3) is blocked.

    A chain with a degenerate segment (shorter than the weld tolerance: two interactions
    at one point, e.g. a reflection on a face exactly at the edge it then diffracts on)
    counts as blocked: its geometry is undefined.
    """
    k, s, _ = vertices.shape
    from ..raycast import plane_tolerance
    from . import kernels

    # only segments joining two interactions can be degenerate; a transmitter or receiver may
    # sit as close to a surface as it likes, but one exactly on the face or edge it would
    # interact with (within the casters' plane tolerance, i.e. rounding) takes part in no
    # interaction there (docs/search.md)
    weld, plane = scene.length_tolerance(scene.tolerances.weld), plane_tolerance(scene)
    if kernels.available():
        from . import _numba

        degenerate = _numba.degenerate_chains(np.ascontiguousarray(vertices, dtype=np.float64), weld, plane)
    else:
        d = np.diff(vertices, axis=1)
        seg = np.sqrt(np.einsum("ksj,ksj->ks", d, d))
        inner = seg[:, 1:-1] if s > 3 else np.zeros((k, 0))
        degenerate = (inner <= weld).any(axis=1)
        if s > 2:
            degenerate |= (seg[:, [0, -1]] <= plane).any(axis=1)
    # the true vertices: by the casters' rule (wavepaths.raycast) an end on a surface does not
    # hit it, and a face next to it still blocks (no lifted or shortened copies)
    # one leg at a time, each cast only for the chains still clear (compaction), from the
    # receiver back (leg_order)
    blocked = np.zeros(k, dtype=bool)
    alive = np.nonzero(~degenerate)[0]
    for j in leg_order(s - 1):
        if len(alive) == 0:
            break
        hit = scene.raycaster.occluded_legs(vertices, alive, j, j + 1)
        stats["rays_cast"] += len(alive)
        blocked[alive[hit]] = True
        alive = alive[~hit]
    if exact is not None and exact.any():
        # chains of (tx, rx) pairs that sit on a shadow or reflection boundary: float64 casts
        sel = np.nonzero(exact)[0]
        blocked[sel] = scene.exact_raycaster.occluded(
            vertices[sel, :-1].reshape(-1, 3), vertices[sel, 1:].reshape(-1, 3)
        ).reshape(len(sel), s - 1).any(axis=1)
        stats["rays_cast_float64"] += len(sel) * (s - 1)
    return blocked | degenerate


def triangle_of(scene: "Scene", polygons: np.ndarray) -> np.ndarray:
    return scene.polygon_tris[scene.polygon_tri_ptr[polygons]]
