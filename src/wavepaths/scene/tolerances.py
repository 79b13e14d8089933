"""Geometric tolerances, scaled to the scene.

Every tolerance the engine uses is a named field here, with the reason beside it, and
is expressed relative to the scene's size (``Scene.diagonal``: twice the largest distance of
a vertex from the vertices' mean, the bounding box's diagonal for a box-shaped scene and,
unlike that diagonal, unchanged by a rotation) so
that a 10 m room and a 2 km city behave alike. A :class:`SceneTolerances` travels with its
:class:`~wavepaths.scene.model.Scene`; none is a module global.

Beside them, a few fixed numerical constants live next to the code that uses them, each
documented there. They are not settings, because they are margins of a computation rather
than a judgement about the scene: each is relative to the scene's size or to a length the
code has just computed, or an angle, and none should change with the scene:
``search.through_vertices.CHORD`` and ``HEIGHT`` (the chord that tests a leg through a
reflection's vertex, in scene diagonals), ``search.visibility.MIRROR_STEP`` (where a hint
ray starts, in leg lengths), ``search.reach.REACH_SLACK`` (a margin in the cosine domain),
``topology.sectors.FACE_ANGLE_TOL`` (FindDihedron's resolution [rad]),
``search.launch.END_INSET`` (in sample spacings), ``search.images.SEGMENT_EPS`` and
``scene.polygon_query.POLYGON_MARGIN`` (a segment's parameter and barycentric
coordinates), ``em.utd_terms.SIN_BETA_0_FLOOR``, ``fields.chain.BOUNDARY_EPS`` and
``BOUNDARY_NUDGE`` (angles [rad]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from ..errors import WavepathsError


@dataclass(frozen=True)
class SceneTolerances:
    """Relative tolerances, multiplied by the scene diagonal to give metres.

    Attributes
    ----------
    weld : float
        Vertices of different triangles closer than ``weld * diagonal`` are one vertex.
        Meshes exported in float32 (PLY files written by Blender for Sionna RT) carry
        coordinates rounded to about 6e-8 of their magnitude; 1e-6 covers that with a
        margin while staying far below any feature of a real scene (1 mm in 1 km).
    coplanar_angle : float
        Two triangles are coplanar when their normals differ by less than this angle
        [rad]. Normals computed from float32 vertices of a long thin triangle can deviate
        by ~1e-6 rad; 1e-5 rad keeps distinct facets of curved objects apart.
    coplanar_distance : float
        Two adjacent triangles are also coplanar when the corners of the smaller lie within
        ``coplanar_distance * diagonal`` of the larger's plane. Float32 rounding (about 6e-8 of
        the coordinates) turns a thin triangle's normal beyond ``coplanar_angle`` (a wall's
        diagonal triangles, 0.1 m thin, by up to 5e-4 rad) but moves its corners off the plane
        by no more than itself: 1e-7 covers it (0.2 mm in a 2 km scene), and a curved ground's
        regions stay within it of their planes.
    flat_angle : float
        The largest fold [rad] that the distance tests (``plane_distance`` for flat edges,
        ``coplanar_distance`` for polygons) may call flat. A narrow facet's corner lies close to
        its neighbour's plane whatever the fold: the 1-5 cm facets of munich's church, creased
        by 6-8 degrees, were flat by distance and lost the diffraction that fills the gap
        between their reflection boundaries. Rounding turns faces by at most 0.39 degrees in
        munich's float32 mesh; 1e-2 rad (0.57 degrees) keeps both apart.
    plane_distance : float
        A point lies in a plane when within ``plane_distance * diagonal`` of it (used to
        find edges lying inside another object's face, and to call an edge flat when its
        faces' corners lie that close to its tallest face's plane: float32 rounding turns
        a thin triangle's normal by more than ``coplanar_angle``, not its corner off the plane).
    ray_offset : float
        The float32 uncertainty budget of the ray casts, relative to the diagonal. Embree
        works in float32 on recentred coordinates, whose resolution is about 6e-8 of the
        scene half-size; 1e-6 is 30 times that. Casts are no longer shortened (every hit is
        decided in float64, :mod:`wavepaths.raycast`); the value sets how close to an edge
        a geometrical-optics ray counts as grazing: within ``4 ray_offset`` its (tx, rx)
        pair is re-cast in float64. (The UTD boundary side follows the search's decision
        within the much smaller :func:`wavepaths.scene.polygon_query.polygon_margin_length`.)
    """

    weld: float = 1e-6
    coplanar_angle: float = 1e-5
    coplanar_distance: float = 1e-7
    flat_angle: float = 1e-2
    plane_distance: float = 1e-6
    ray_offset: float = 1e-6

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            angle = f.name.endswith("_angle")
            top, unit = (math.pi, "rad") if angle else (1.0, "of the scene's diagonal")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 <= v <= top):
                raise WavepathsError(f"`{f.name}` must be a finite number in [0, {top:.4g}] {unit}, got {v!r}")

