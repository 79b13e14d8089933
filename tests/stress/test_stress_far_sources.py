"""A small scene seen from very far: the culling tests' angles at the rounding limit.

A 1 m PEC wedge and a transmitter 1e8 m away subtend caps of directions of about 1e-8 rad;
``arccos`` of a normalised dot product is only good to about 1.5e-8 rad near 0, and the
beam tests (the image tree's, the chains' beams, the Keller cone's reach) rejected valid
reflections there: 6 to 14 of 14 receivers lost their reflection from 1e8 m on (found by a
review). The angles are ``atan2(|u x v|, u . v)`` now (``search.spheres.vector_angle``).
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, trace
from wavepaths.em.materials import PEC
from wavepaths.scene.builtin import SceneBuilder
from wavepaths.scene.model import build_scene
from wavepaths.search.options import CULLING_TESTS


def _small_wedge():
    """A closed right-angled PEC prism, 1 m faces, its edge on the z axis (|z| <= 1): the
    0-face y = 0 (x in [0, 1]) and the n-face x = 0 (y in [-1, 0]); free space spans 270 deg
    from +x counter-clockwise."""
    b = SceneBuilder()
    v = [[0, 0, -1], [1, 0, -1], [0, -1, -1], [0, 0, 1], [1, 0, 1], [0, -1, 1]]
    tris = [[0, 1, 4], [0, 4, 3], [0, 3, 5], [0, 5, 2], [1, 2, 5], [1, 5, 4], [0, 2, 1], [3, 4, 5]]
    b.add_mesh("wedge", PEC, v, tris)
    return build_scene(*b.arrays())


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("distance", [1e6, 1e8, 3e8, 9e8])
@pytest.mark.parametrize("rho", [0.0159, 0.3])
def test_a_far_transmitter_keeps_every_reflection_of_a_small_scene(distance, rho, compiled):
    scene = _small_wedge()
    pp = np.radians(30.0)
    phi = np.linspace(0.03, 1.5 * np.pi - 0.03, 25)
    rx = np.stack([rho * np.cos(phi), rho * np.sin(phi), np.zeros_like(phi)], axis=1)
    tx = np.array([[distance * np.cos(pp), distance * np.sin(pp), 0.0]])
    opts = TraceOptions(max_reflections=1, diffraction=False, compiled=compiled)
    p = trace(scene, tx, rx, opts)
    # the 0-face mirrors the transmitter for the receivers below its reflection boundary
    # phi = pi - phi', and the reflection point (x = x_r + y_r / tan phi') lies on the face
    want = phi < np.pi - pp
    got = np.array([((p.rx_index == r) & (p.depth == 1)).sum() for r in range(len(rx))])
    assert np.array_equal(got, want.astype(int)), (got, want.astype(int))
    # and the same paths with every culling test off
    off = trace(scene, tx, rx, TraceOptions(max_reflections=1, diffraction=False, compiled=compiled,
                                            disable_culling=frozenset(CULLING_TESTS)))
    assert len(off) == len(p)
