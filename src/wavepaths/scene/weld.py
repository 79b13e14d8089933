"""Welding coincident vertices and dropping degenerate triangles."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


def weld_vertices(vertices: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices closer than ``tolerance``.

    Parameters
    ----------
    vertices : (v, 3) float64
        Vertex positions [m].
    tolerance : float
        Merge distance [m]. Pairs closer than this are merged, and merging is
        transitive (connected components of the "closer than" graph).

    Returns
    -------
    welded : (w, 3) float64
        One position per component: the mean of its members.
    index : (v,) int64
        ``welded[index[i]]`` replaces ``vertices[i]``.
    """
    n = len(vertices)
    if n == 0:
        return vertices.reshape(0, 3), np.zeros(0, dtype=np.int64)
    pairs = cKDTree(vertices).query_pairs(r=tolerance, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    sums = np.zeros((count, 3))
    np.add.at(sums, labels, vertices)
    welded = sums / np.bincount(labels, minlength=count)[:, None]
    return welded, labels.astype(np.int64)


def degenerate_triangles(vertices: np.ndarray, triangles: np.ndarray, area_tolerance: float) -> np.ndarray:
    """Mask of triangles whose area is below ``area_tolerance`` [m^2] or that repeat a vertex.

    Parameters
    ----------
    vertices : (v, 3) float64
    triangles : (f, 3) int64
    area_tolerance : float

    Returns
    -------
    (f,) bool
    """
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    repeated = (
        (triangles[:, 0] == triangles[:, 1])
        | (triangles[:, 1] == triangles[:, 2])
        | (triangles[:, 0] == triangles[:, 2])
    )
    return repeated | (area <= area_tolerance)
