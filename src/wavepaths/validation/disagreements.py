"""Why the two engines disagree on a path: the classes of the validation report.

A path one engine finds and the other does not, or a matched pair whose coefficients differ,
gets a reason here: a topology rule wavepaths enforces (seed §3.1-3.3), an edge that is not
a wedge, Sionna RT's wedge being two of a dihedron's faces, its collapsed screens, a
reflection off the diffracting wedge's own face, a mirror Sionna exchanged for a nearly
coplanar one after placing the diffraction point, a leg crossing a face exactly at its edge,
or a failure. :mod:`wavepaths.validation.report` and benchmark 2
(:mod:`wavepaths.bench.sionna_paths`) use them; ``validation/known.py`` documents each
known disagreement and the test that checks it.
"""

from __future__ import annotations

import numpy as np

from .cases import Case


def _explainer(scene, paths, sn, case: Case):
    from ..topology.sectors import sector_table

    dih = scene.dihedra
    sectors = sector_table(dih)

    def explain(side: str, i: int) -> str:
        if side == "sionna":
            return _explain_sionna_only(scene, sn, i, sectors)
        kinds = paths.interactions[i, : paths.depth[i]]
        if (kinds == 2).any():
            d = int(paths.primitive[i][kinds.tolist().index(2)])
            faces = dih.face_triangle[dih.faces(d)]
            objects = set(scene.triangle_object[faces].tolist())
            if dih.face_count[d] == 1 and not case.edge_diffraction:
                return "free edge: Sionna diffracts on free edges only with edge_diffraction=True"
            if len(objects) > 1:
                return "edge between different objects: Sionna 2.2 diffracts only on wedges inside one mesh"
            if dih.face_count[d] >= 3:
                return "edge with three or more faces: Sionna has no such dihedron"
        return "Sionna's ray sampling (or its path cap) missed it"

    return explain


SIONNA_ONLY_TOPOLOGY = "topology rule: Sionna ignores another object's face on this edge; the path leaves its topological volume (seed §3.1, figure 4)"
SIONNA_ONLY_FAILURE = "found by Sionna only: not found by wavepaths (a failure)"
SIONNA_ONLY_NOT_A_WEDGE = ("not a wedge: Sionna diffracts on an edge whose free-space angle around E and R is at most "
                           "pi (flat or concave, n <= 1: no shadow boundary, UTD's D vanishes at n = 1 and is not "
                           "defined below); wavepaths diffracts only into sectors wider than pi (seed §3.2)")
SIONNA_ONLY_THROUGH_EDGE = ("through an edge: a leg of Sionna's path crosses a face exactly at that face's edge "
                            "(a receiver on the shadow boundary of a window's jamb, say): wavepaths' occlusion rule "
                            "blocks a segment that crosses a closed triangle through its edge or vertex (no leak "
                            "between the two triangles of a wall; docs/stress.md, 'What blocks a segment'), Sionna's "
                            "ray passes; 1e-4 m to the open side both engines keep the path")
SIONNA_ONLY_MIRROR_SUBSTITUTION = ("mirror substitution: Sionna placed the diffraction point with one mirror's plane "
                                   "and recorded the reflection on another, nearly coplanar face (a neighbouring "
                                   "facade), without placing the point again: the point obeys Keller's law only for "
                                   "the first mirror, the path for neither (known disagreement "
                                   "'sionna-near-coplanar-mirror-substitution')")
SIONNA_ONLY_OWN_FACE = ("own face: Sionna reflects the diffracted ray off a face of the wedge it diffracts on (the "
                        "ray runs along that face, at grazing incidence: a ray into the wedge's exterior never meets "
                        "the wedge's own faces, seed §3.2; such a path carries no field)")


def _multi_object_dihedra(scene) -> set:
    """Dihedra whose faces belong to more than one object (Sionna sees only its own mesh's wedge)."""
    dih = scene.dihedra
    out = set()
    for d in np.nonzero(dih.face_count >= 2)[0]:
        if len(set(scene.triangle_object[dih.face_triangle[dih.faces(d)]].tolist())) > 1:
            out.add(int(d))
    return out


def _non_manifold_dihedra(scene) -> set:
    """Dihedra with three or more distinct face polygons, all of one object: a non-manifold
    edge of one mesh.

    Typically two blocks of one building mesh that share a party wall (each block's wall is a
    face on the edge) and whose facades continue each other (etoile_crop's element_015).
    Sionna RT 2.2 builds a wedge from one pair of the mesh's half-edges (Mitsuba's
    ``opposite_dedge``), i.e. one block's own two faces, and ignores the others; wavepaths'
    dihedron takes every face on the edge and diffracts into the free-space sector (seed §3.2).
    Where the facades are nearly coplanar the two wedges differ completely: Sionna's is a
    right-angled corner (n = 1.5), wavepaths' a nearly flat wall (n -> 1, D -> 0, as the exact
    wedge solution). Dihedra whose faces span several objects are
    :func:`_multi_object_dihedra`, not these.
    """
    dih = scene.dihedra
    out = set()
    for d in np.nonzero(dih.face_count >= 3)[0]:
        if len(set(scene.triangle_object[dih.face_triangle[dih.faces(d)]].tolist())) == 1:
            out.add(int(d))
    return out


MATCHED_MULTI_OBJECT_EDGE = "multi-object edge"
MATCHED_NON_MANIFOLD_EDGE = "non-manifold edge"


def _matched_wedge_difference(paths, i: int, multi_object: set, non_manifold: set) -> str | None:
    """Why a matched diffracted path's coefficient is not held to the tolerance, or None.

    :data:`MATCHED_MULTI_OBJECT_EDGE` when wavepaths' dihedron takes another object's face on
    the edge (:func:`_multi_object_dihedra`), :data:`MATCHED_NON_MANIFOLD_EDGE` when it has
    three or more faces of one mesh (:func:`_non_manifold_dihedra`): in both cases Sionna's
    wedge is two of the faces, a different exterior angle (known disagreements
    'diffraction-between-objects' and 'non-manifold-edge-wedge', validation/known.py).
    """
    d = _diffraction_dihedron(paths, i)
    if d in multi_object:
        return MATCHED_MULTI_OBJECT_EDGE
    if d in non_manifold:
        return MATCHED_NON_MANIFOLD_EDGE
    return None


COLLAPSED_FREE_EDGE_DB = 60.0  # Sionna's |a| at least this far below wavepaths' compat value


def _sionna_object_index(scene, sn, o: int) -> int:
    """wavepaths' object index of Sionna's object ``o`` (by name; Sionna strips ``mesh-``), or -1."""
    if o < 0:
        return -1
    name = sn.object_names[o]
    for cand in (name, "mesh-" + name):
        if cand in scene.object_names:
            return scene.object_names.index(cand)
    return -1


def _sionna_collapsed_free_edge(scene, paths, match, sn, a_compat) -> bool:
    """Whether a matched diffracted pair is Sionna's collapsed screen.

    True when Sionna's |a| is at least :data:`COLLAPSED_FREE_EDGE_DB` below wavepaths' compat
    value and the triangle Sionna diffracts on has a free edge along the diffraction edge (no
    other triangle of its object on that edge: Sionna's wedge is a screen, n = 2). Sionna RT 2.2
    (``utils/wedges.py::wedge_geometry``) orients the two normals of a wedge by the side of the
    other face's centroid, with a float32 margin of 6e-6; on a screen the "other face" is the
    same triangle, whose centroid lies in its own plane, so float32 rounding (vertex coordinates
    of tens of metres) can flip one normal: n0 = nn, interior angle pi, n = 1, and every UTD
    term cancels (to float32). Known disagreement 'sionna-free-edge-collapses-to-flat'.
    """
    i, j = match.wp_index, match.sn_index
    if not abs(sn.a[j]) <= abs(a_compat[i]) * 10 ** (-COLLAPSED_FREE_EDGE_DB / 20):
        return False
    kinds = sn.interactions[j, : sn.num_interactions[j]].tolist()
    if 2 not in kinds:
        return False
    tri = _sionna_triangle(scene, sn, j, kinds.index(2))
    if tri < 0:
        return False
    d = _diffraction_dihedron(paths, i)
    e, origin = scene.dihedra.direction[d], scene.dihedra.origin[d]
    corners = scene.triangles[tri]
    rel = scene.vertices[corners] - origin
    dist = np.linalg.norm(rel - np.outer(rel @ e, e), axis=1)
    on = corners[dist < 1e-3]
    if len(on) != 2:
        return False
    tris = np.nonzero(scene.triangle_object == scene.triangle_object[tri])[0]
    others = scene.triangles[tris[tris != tri]]
    return not bool(np.any(np.isin(others, on).sum(axis=1) == 2))


def _sionna_triangle(scene, sn, j: int, k: int) -> int:
    """The scene triangle of Sionna path ``j``'s interaction ``k`` (its object and primitive), or -1."""
    o = _sionna_object_index(scene, sn, int(sn.objects[j, k]))
    prim = int(sn.primitives[j, k])
    if o < 0 or prim < 0:
        return -1
    tris = np.nonzero(scene.triangle_object == o)[0]
    return int(tris[prim]) if prim < len(tris) else -1


def _sionna_own_face(scene, sn, j: int, k: int, tol: float) -> bool:
    """Whether a reflection next to Sionna path ``j``'s diffraction ``k`` is off a triangle that
    has the diffraction point on one of its sides (within ``tol`` [m]): a face of the wedge itself.

    From a point of an edge, a ray that meets a face through that edge lies in the face's plane:
    it leaves along the face (grazing, the boundary of the exterior sector) and its reflection
    has no field. Sionna's float32 points can still land such a ray a centimetre along the face.
    """
    p = sn.vertices[j, k + 1]
    for m in (k - 1, k + 1):
        if not (0 <= m < sn.num_interactions[j]) or sn.interactions[j, m] != 1:
            continue
        tri = _sionna_triangle(scene, sn, j, m)
        if tri < 0:
            continue
        V = scene.vertices[scene.triangles[tri]]
        for a, b in ((0, 1), (1, 2), (2, 0)):
            e = V[b] - V[a]
            t = np.clip((p - V[a]) @ e / (e @ e), 0.0, 1.0)
            if np.linalg.norm(p - V[a] - t * e) < tol:
                return True
    return False


KELLER_IMAGE_TOL = 1e-5
"""Keller residual |e.u_in - e.u_out| of a Sionna diffraction point, its rays aimed at the
end points' images in the path's mirrors, above which the point is not on the law for those
mirrors. Sionna's float32 vertices give at most 2.6e-6 on etoile_crop's 5,462 diffracted
paths (benchmark 2's run); the one substituted mirror seen there leaves 1.65e-3, and a
smaller substitution (two facades 0.09 mrad apart) 7.9e-5."""
NEAR_MIRROR_ANGLE = 1e-2
"""[rad] The largest angle between a recorded mirror's plane and a substitute's."""
NEAR_MIRROR_DISTANCE = 2e-2
"""[m] The largest distance from Sionna's reflection point to a substitute's plane. A proxy,
looser than Sionna's own rule (it accepts another triangle when the two mirror images differ
by less than 1 cm), which needs the image of the path's far end: on etoile_crop the planes
lie 2 mm apart at the point and the images 7.8 mm."""
RESTORED_FACTOR = 100.0
"""How much closer to Keller's law the substitute must bring the point, besides within
:data:`KELLER_IMAGE_TOL`: a point off the law by float32 noise alone is not put on it by a
nearby plane (etoile_crop: 1.65e-3 -> 6.4e-8; a D-R-R 0.09 mrad apart: 7.9e-5 -> 1.9e-8)."""


def _image_keller_residual(scene, v: np.ndarray, k: int, mirrors: list, edges: np.ndarray) -> float:
    """min over the dihedra ``edges`` of |e.u_in - e.u_out| at the diffraction point ``v[k + 1]``
    of a path with vertices ``v`` (transmitter, interactions, receiver) whose interaction ``k``
    is the diffraction and the others reflections on the polygons ``mirrors`` (one per
    interaction, -1 at ``k``): the incoming ray aimed from the transmitter's image in the
    mirrors before the point (seed §2.3, unfolded), the outgoing one at the receiver's image in
    the mirrors after it. The images, unlike the neighbouring vertices, carry no float32
    rounding of a reflection point next to the edge."""
    from ..search.geometry import mirror_points

    n, off = scene.polygon_normal, scene.polygon_offset
    src, tgt = v[0], v[-1]
    for m in range(k):
        src = mirror_points(src, n[mirrors[m]], off[mirrors[m]])
    for m in range(len(mirrors) - 1, k, -1):
        tgt = mirror_points(tgt, n[mirrors[m]], off[mirrors[m]])
    p = v[k + 1]
    u_in, u_out = (p - src) / np.linalg.norm(p - src), (tgt - p) / np.linalg.norm(tgt - p)
    e = scene.dihedra.direction[edges]
    return float(np.min(np.abs(e @ u_in - e @ u_out)))


def _sionna_mirror_substitution(scene, sn, j: int, k: int, edges: np.ndarray) -> bool:
    """Whether Sionna path ``j`` (diffraction at interaction ``k``, on one of the dihedra
    ``edges``, the rest reflections) has its diffraction point off Keller's law for its recorded
    mirrors (by more than :data:`KELLER_IMAGE_TOL`) and on it (within that tolerance, and
    :data:`RESTORED_FACTOR` times closer) once one mirror is exchanged for another polygon
    whose plane lies within :data:`NEAR_MIRROR_ANGLE` of the mirror's and
    :data:`NEAR_MIRROR_DISTANCE` of the reflection point. The polygon need not hold the point
    (on etoile_crop it does not: Sionna's candidate ray hit it elsewhere). The tolerance was
    set on etoile_crop's float32 points (300 m); on a scene many kilometres wide a point's
    float32 noise over short legs may exceed it, but no nearby plane then restores the law.

    Sionna RT 2.2 places the point with the mirror its candidate ray hit, then, tracing back
    from the receiver, accepts another triangle whose image lies within 1 cm and records that
    one and its hit point, without placing the point again (etoile_crop, receiver 80: element_233's
    facade, then element_022's, 1.13 mrad apart; the point 12 cm from the path on the recorded
    facade, which wavepaths finds). Known disagreement
    ``sionna-near-coplanar-mirror-substitution``.
    """
    count = int(sn.num_interactions[j])
    kinds = sn.interactions[j, :count]
    if len(edges) == 0 or count < 2 or not np.all((kinds == 1) | (np.arange(count) == k)):
        return False
    mirrors = [-1] * count
    for m in range(count):
        if m != k:
            tri = _sionna_triangle(scene, sn, j, m)
            if tri < 0:
                return False
            mirrors[m] = int(scene.triangle_polygon[tri])
    v = sn.vertices[j, : count + 2].astype(np.float64)
    r0 = _image_keller_residual(scene, v, k, mirrors, edges)
    if not r0 > KELLER_IMAGE_TOL:
        return False  # on the law for its own mirrors: not this case
    normal, off = scene.polygon_normal, scene.polygon_offset
    for m in range(count):
        if m == k:
            continue
        p = mirrors[m]
        near = np.nonzero((np.abs(normal @ normal[p]) >= np.cos(NEAR_MIRROR_ANGLE))
                          & (np.abs(normal @ v[m + 1] - off) <= NEAR_MIRROR_DISTANCE))[0]
        for q in near[near != p]:
            swapped = mirrors[:m] + [int(q)] + mirrors[m + 1:]
            if _image_keller_residual(scene, v, k, swapped, edges) <= min(KELLER_IMAGE_TOL, r0 / RESTORED_FACTOR):
                return True
    return False


def _diffraction_dihedron(paths, i: int) -> int:
    kinds = paths.interactions[i, : paths.depth[i]].tolist()
    return int(paths.primitive[i, kinds.index(2)]) if 2 in kinds else -1


def _explain_sionna_only(scene, sn, j: int, sectors=None) -> str:
    """Why a Sionna path has no wavepaths match: a topology rule wavepaths enforces, an edge that
    is not a wedge, a reflection off the diffracting wedge's own face, a mirror Sionna exchanged
    after placing the diffraction point, a leg through a face's edge, or a failure. ``sectors``: the scene's
    :func:`~wavepaths.topology.sectors.sector_table`, built here when not given (callers that
    explain many paths build it once)."""
    from ..topology.find_dihedron import find_dihedron

    kinds = sn.interactions[j, : sn.num_interactions[j]]
    if not (kinds == 2).any():
        return SIONNA_ONLY_FAILURE
    k = kinds.tolist().index(2)
    v = sn.vertices[j]
    p, e, r = v[k + 1], v[k], v[k + 2]
    dih = scene.dihedra
    rel = p - dih.origin
    t = np.einsum("ij,ij->i", rel, dih.direction)
    dist = np.linalg.norm(rel - t[:, None] * dih.direction, axis=1)
    # Sionna's vertices are float32: within 1 cm of an edge (the path matching's tolerance is 2 cm)
    tol = 1e-2
    on = np.nonzero((dist < tol) & (t > -tol) & (t < dih.length + tol))[0]
    near_edges = on
    for d in on:
        if dih.face_count[d] >= 3:
            res = find_dihedron(dih, np.array([d]), p[None], e[None], r[None])
            if not res.valid[0]:
                return SIONNA_ONLY_TOPOLOGY
    # the edges on which the point obeys Keller's law (float32 vertices: 2e-3 in the cosines);
    # a point at a corner lies on other edges too, where it does not
    u_in, u_out = (p - e) / np.linalg.norm(p - e), (r - p) / np.linalg.norm(r - p)
    on = on[np.abs(dih.direction[on] @ u_in - dih.direction[on] @ u_out) < 2e-3]
    if len(on) and not dih.diffracting[on].any():
        from ..topology.sectors import sector_of, sector_table

        tab = sector_table(dih) if sectors is None else sectors
        dd = np.concatenate([on, on])
        sec, width = sector_of(tab, dd, np.concatenate([np.repeat(e[None], len(on), 0), np.repeat(r[None], len(on), 0)]),
                               dih.origin[dd])
        if np.all(width <= np.pi + scene.tolerances.coplanar_angle):
            return SIONNA_ONLY_NOT_A_WEDGE
    # Sionna's float32 points lie within about 1e-5 m of the sides they are on at these scales
    if _sionna_own_face(scene, sn, j, k, 1e-3):
        return SIONNA_ONLY_OWN_FACE
    if _sionna_mirror_substitution(scene, sn, j, k, near_edges):
        return SIONNA_ONLY_MIRROR_SUBSTITUTION
    if _crosses_faces_only_at_edges(scene, sn.vertices[j, : sn.num_interactions[j] + 2], 1e-4):
        return SIONNA_ONLY_THROUGH_EDGE
    return SIONNA_ONLY_FAILURE


def _crosses_faces_only_at_edges(scene, vertices: np.ndarray, tol: float) -> bool:
    """Whether a path's legs cross some face, and every face they cross, within ``tol`` [m] of
    that face's boundary (the legs' own end points on their faces do not count: a leg's
    crossings are taken at least ``tol`` from its ends).

    The occlusion rule blocks a segment crossing a closed triangle, at its edge too; Sionna's
    ray at exactly that edge passes. Within ``tol`` of an edge the two verdicts are a
    convention on the boundary of the edge's shadow, not a missed path.
    """
    V = scene.vertices[scene.triangles]
    e1, e2 = V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]
    n = np.cross(e1, e2)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    at_edge = 0
    for a, b in zip(vertices[:-1], vertices[1:]):
        length = float(np.linalg.norm(b - a))
        if length <= 2 * tol:
            continue
        da = np.einsum("ij,ij->i", a - V[:, 0], n)
        db = np.einsum("ij,ij->i", b - V[:, 0], n)
        t = np.where(da != db, da / np.where(da != db, da - db, 1.0), -1.0)
        hit = (t * length > tol) & ((1.0 - t) * length > tol)
        for i in np.nonzero(hit)[0]:
            x = a + t[i] * (b - a)
            # the distance from x to the triangle (0 inside) and to its boundary
            dist_in, dist_edge = _triangle_distances(V[i], x)
            if dist_in > tol:
                continue  # passes beside the triangle
            if dist_edge > tol:
                return False  # through its interior: a real blocker
            at_edge += 1
    return at_edge > 0


def _triangle_distances(tri: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """(distance from ``x`` to the closed triangle's region in its plane (0 inside), distance
    to its boundary) [m], for ``x`` in the triangle's plane."""
    edges = []
    for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
        e = b - a
        s = np.clip((x - a) @ e / (e @ e), 0.0, 1.0)
        edges.append(float(np.linalg.norm(x - a - s * e)))
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    inside = all(np.cross(b - a, x - a) @ n >= 0 for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])))
    return (0.0 if inside else min(edges)), min(edges)
