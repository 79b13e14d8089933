"""Shared fixtures: small scenes built from arrays."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wavepaths.em.materials import PEC
from wavepaths.scene import build_scene


def strict_json(text: str):
    """json.loads that refuses NaN, Infinity and -Infinity (which JSON does not have)."""
    def refuse(name):
        raise ValueError(f"not JSON: {name}")

    return json.loads(text, parse_constant=refuse)


def quads_scene(quads, objects=None, source="test"):
    """A scene from a list of quads (4 corners each), one object per quad unless given."""
    verts, tris, obj = [], [], []
    for i, q in enumerate(quads):
        base = 4 * i
        verts += list(q)
        tris += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
        o = i if objects is None else objects[i]
        obj += [o, o]
    names = [f"o{i}" for i in range(max(obj) + 1)]
    return build_scene(np.array(verts, float), np.array(tris), np.array(obj), np.zeros(len(tris), int), names, [PEC], source=source)


def box_arrays(lo, hi, bottom=True):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0], [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    quads = [(4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)] + ([(0, 3, 2, 1)] if bottom else [])
    t = []
    for a, b, c, d in quads:
        t += [[a, b, c], [a, c, d]]
    return v, np.array(t)


def boxes_scene(boxes, ground=None, source="boxes"):
    """Axis-aligned boxes (lo, hi), optionally on a ground square of half-size ``ground`` at z = 0."""
    verts, tris, obj = [], [], []
    n = 0
    for i, (lo, hi) in enumerate(boxes):
        v, t = box_arrays(lo, hi)
        verts.append(v)
        tris.append(t + n)
        obj.append(np.full(len(t), i))
        n += len(v)
    if ground is not None:
        g = ground
        verts.append(np.array([[-g, -g, 0], [g, -g, 0], [g, g, 0], [-g, g, 0]], float))
        tris.append(np.array([[0, 1, 2], [0, 2, 3]]) + n)
        obj.append(np.full(2, len(boxes)))
    tri = np.concatenate(tris)
    names = [f"o{i}" for i in range(len(boxes) + (ground is not None))]
    return build_scene(np.concatenate(verts), tri, np.concatenate(obj), np.zeros(len(tri), int), names, [PEC], source=source)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
