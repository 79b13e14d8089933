"""``wavepaths validate``: the validation report against Sionna RT and exact solutions.

For each case (:mod:`wavepaths.validation.cases`) both engines load the same Mitsuba XML
file and trace the same transmitters, receivers, antennas and path types. wavepaths runs
twice on the same geometry: with the textbook diffraction model and with
``compat="sionna"``; matched paths are compared like for like (compat), and the textbook
model's diffraction differences are reported beside them. Receiver lines across the
shadow and reflection boundaries show who agrees with the exact solutions.

Tolerances held (Sionna computes in float32, wavepaths in float64):

* delays: 1e-6 relative;
* |a| of line-of-sight and reflected paths: 0.1 dB;
* |a| of diffracted paths, compat mode: 0.5 dB;
* no path may be found by Sionna and not by wavepaths;
* against the exact solutions (the arbiter; Sionna RT is a peer): wavepaths' UTD within
  0.5 dB in |u| and 0.02 in complex u on every boundary line and polarisation
  (:mod:`wavepaths.validation.verdict`, which also says which engine matches where the two
  disagree).

The report passes when every case and the exact-solution comparison pass.

``validation.json`` is strict JSON: a non-finite number (-inf dB where no path reaches a
receiver, NaN where a coverage cell is not compared) is written ``null``
(:mod:`wavepaths.validation.json_io`). It holds everything the figures are drawn from (the
boundary lines' complex fields, the coverage maps), and ``report.html`` is written from the
file as read back (:func:`write_report`), so the report can be rebuilt from the JSON alone.
"""

from __future__ import annotations

import html
import json
import os
import platform
import sys
import time

import numpy as np

from ..fields import FieldConfig, compute_fields
from ..scene import load_scene, write_mitsuba_xml
from ..search import TraceOptions, trace
from .cases import Case, default_cases
from .compare import compare_paths, total_gain_db
from .figures import report_figures
from .json_io import write_json
from .known import KNOWN_DISAGREEMENTS
from .verdict import EXACT_TOLERANCES, HELD_ENGINE, exact_comparison, known_disagreement_verdicts

TOLERANCES = {"delay_rel": 1e-6, "gain_db_los_reflection": 0.1, "gain_db_diffraction_compat": 0.5,
              **EXACT_TOLERANCES}


def _scene_file(case: Case, out_dir: str) -> str:
    if case.scene.startswith("sionna:"):
        from .sionna_runner import builtin_scene_path

        return builtin_scene_path(case.scene.split(":", 1)[1])
    path = os.path.join(out_dir, "scenes", case.scene, f"{case.scene}.xml")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    write_mitsuba_xml(load_scene(case.scene), path)
    return path


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


def _diffraction_dihedron(paths, i: int) -> int:
    kinds = paths.interactions[i, : paths.depth[i]].tolist()
    return int(paths.primitive[i, kinds.index(2)]) if 2 in kinds else -1


def _explain_sionna_only(scene, sn, j: int, sectors=None) -> str:
    """Why a Sionna path has no wavepaths match: a topology rule wavepaths enforces, an edge that
    is not a wedge, a reflection off the diffracting wedge's own face, or a failure. ``sectors``: the scene's
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


def run_case(case: Case, out_dir: str) -> dict:
    """Run one case on both engines; return its JSON-ready result."""
    from .sionna_runner import run_sionna_paths

    xml = _scene_file(case, out_dir)
    scene = load_scene(xml)
    opts = TraceOptions(max_reflections=case.max_depth, diffraction=True,
                        diffraction_reflections=max(case.max_depth - 1, 0))
    t0 = time.perf_counter()
    paths = trace(scene, case.tx, case.rx, opts)
    wp_time = time.perf_counter() - t0
    result = {"name": case.name, "scene": case.scene, "scene_file": xml, "note": case.note,
              "tx": case.tx.tolist(), "num_rx": len(case.rx), "max_depth": case.max_depth,
              "edge_diffraction": case.edge_diffraction, "frequency_hz": case.frequency_hz,
              "wavepaths_paths": len(paths), "wavepaths_time_s": wp_time, "polarizations": {}}
    from ..em.antennas import Antenna

    for pol in case.polarizations:
        ant = Antenna("iso", pol)
        t0 = time.perf_counter()
        compat = compute_fields(scene, paths, FieldConfig(case.frequency_hz, "utd", "sionna", tx_antenna=ant, rx_antenna=ant))
        fields_time = time.perf_counter() - t0
        textbook = compute_fields(scene, paths, FieldConfig(case.frequency_hz, "utd", tx_antenna=ant, rx_antenna=ant))
        sn = run_sionna_paths(xml, case.tx, case.rx, frequency_hz=case.frequency_hz, max_depth=case.max_depth,
                              diffraction=True, edge_diffraction=case.edge_diffraction,
                              samples_per_src=case.samples_per_src,
                              tx_antenna=("iso", pol), rx_antenna=("iso", pol))
        explain = _explainer(scene, paths, sn, case)
        comp = compare_paths(paths, compat.a, sn, explain=explain)
        comp_tb = compare_paths(paths, textbook.a, sn, explain=explain)
        m, n = len(case.tx), len(case.rx)
        matched_w = np.array([x.wp_index for x in comp.matches], dtype=int)
        g_sn = total_gain_db(sn.tx_index, sn.rx_index, sn.a, sn.tau, case.frequency_hz, m, n)
        g_wp_matched = total_gain_db(paths.tx_index[matched_w], paths.rx_index[matched_w], compat.a[matched_w],
                                     paths.delays[matched_w], case.frequency_hz, m, n)
        g_wp_all = textbook.path_gain_db()
        summary = comp.summary()
        violations = []
        topo = _multi_object_dihedra(scene)
        non_manifold = _non_manifold_dihedra(scene)
        different_wedge = 0
        non_manifold_wedge = 0
        collapsed_free_edge = 0
        known_dr = 0
        for mm in comp.matches:
            if mm.kinds == "D-R" and case.max_depth >= 3:
                known_dr += 1  # known disagreement 'sionna-dr-depends-on-max-depth'
                continue
            wedge = (_matched_wedge_difference(paths, mm.wp_index, topo, non_manifold)
                     if "D" in mm.kinds else None)
            if wedge == MATCHED_MULTI_OBJECT_EDGE:
                # wavepaths' true dihedron takes another object's face on this edge; Sionna's wedge is
                # its mesh's own two faces: a different exterior angle, a known topology difference
                different_wedge += 1
                continue
            if abs(mm.delay_rel_error) > TOLERANCES["delay_rel"]:
                violations.append(f"delay {mm.kinds} rx {mm.rx}: {mm.delay_rel_error:.2e}")
            tol = TOLERANCES["gain_db_diffraction_compat"] if "D" in mm.kinds else TOLERANCES["gain_db_los_reflection"]
            if np.isfinite(mm.gain_diff_db) and abs(mm.gain_diff_db) > tol:
                if wedge == MATCHED_NON_MANIFOLD_EDGE:
                    # three or more faces of one mesh on the edge; Sionna's wedge is one pair of them
                    # (known disagreement 'non-manifold-edge-wedge')
                    non_manifold_wedge += 1
                elif "D" in mm.kinds and _sionna_collapsed_free_edge(scene, paths, mm, sn, compat.a):
                    # Sionna's screen became a flat wedge (n = 1) in float32: its coefficient vanishes
                    # (known disagreement 'sionna-free-edge-collapses-to-flat')
                    collapsed_free_edge += 1
                else:
                    violations.append(f"|a| {mm.kinds} rx {mm.rx}: {mm.gain_diff_db:+.3f} dB")
        failures = [x for x in comp.only_sionna if x["reason"] == SIONNA_ONLY_FAILURE]
        if failures:
            violations.append(f"{len(failures)} path(s) found by Sionna only")
        textbook_d = comp_tb.summary()["by_kind"]
        result["polarizations"][pol] = {
            "comparison_compat": summary,
            "matched_on_multi_object_edges": different_wedge,
            "matched_on_non_manifold_edges": non_manifold_wedge,
            "matched_on_collapsed_free_edges": collapsed_free_edge,
            "matched_d_r_at_depth_3_not_held": known_dr,
            "textbook_diffraction_gain_diff_db": {k: v["gain_diff_db"] for k, v in textbook_d.items() if "D" in k},
            "only_wavepaths": comp.only_wavepaths[:200],
            "only_sionna": comp.only_sionna[:200],
            "total_gain_db": {"sionna": g_sn.tolist(), "wavepaths_matched_compat": g_wp_matched.tolist(),
                              "wavepaths_all_textbook": g_wp_all.tolist()},
            "total_gain_diff_db_matched": _finite_max(_finite_diff(g_wp_matched, g_sn)),
            "sionna_paths": int(len(sn.tx_index)),
            "sionna_time_s": sn.elapsed_s,
            "sionna_warmup_s": sn.warmup_s,
            "wavepaths_fields_time_s": fields_time,
            "violations": violations,
            "passed": not violations,
        }
    result["passed"] = all(v["passed"] for v in result["polarizations"].values())
    return result


def _finite_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    both = np.isfinite(a) & np.isfinite(b)
    return np.abs(a[both] - b[both])


def _finite_max(x: np.ndarray):
    x = np.asarray(x)
    x = x[np.isfinite(x)]
    return float(x.max()) if len(x) else None


def _versions() -> dict:
    import numpy
    import scipy

    from .. import __version__

    out = {"wavepaths": __version__, "python": sys.version.split()[0], "numpy": numpy.__version__,
           "scipy": scipy.__version__, "platform": platform.platform(), "machine": platform.machine(),
           "cpus": os.cpu_count()}
    try:
        from .sionna_env import sionna_version

        out["sionna-rt"] = sionna_version()
        import drjit
        import mitsuba

        out["mitsuba"] = mitsuba.__version__
        out["drjit"] = drjit.__version__
    except Exception:  # pragma: no cover - reported as missing
        pass
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    out["cpu"] = line.split(":", 1)[1].strip()
                    break
    except OSError:  # pragma: no cover
        pass
    return out


def _fmt(x, spec=".3g"):
    return "-" if x is None else format(x, spec)


def _verdict_text(summary: dict) -> str:
    exact = summary["exact_comparison"]
    cases = "pass" if summary["cases_passed"] else "FAIL"
    held = "pass" if exact["passed"] else "FAIL: " + "; ".join(exact["violations"][:3])
    return (f"path-by-path comparison with Sionna RT: {cases}; {HELD_ENGINE} against the exact solutions: "
            f"{html.escape(held)}")


def _within_text(exact: dict, line: str, key: str) -> str:
    """'yes' / 'no' for an engine the exact comparison measures, '-' (not judged) for the others."""
    engine, field = key.rsplit(" (", 1)
    v = exact["lines"].get(line, {}).get(field.rstrip(")"), {}).get("engines", {}).get(engine)
    return "-" if v is None else ("yes" if v["within_tolerance"] else "no")


def _known_verdict_html(k: dict, exact: dict) -> str:
    v = exact["known_disagreements"].get(k["id"])
    if v is None or v["matches_exact"] is None:
        return f"not measured here; documented: {html.escape(k['who_matches_exact'])}"
    return f"<b>{html.escape(v['matches_exact'])}</b> <span class=small>({html.escape(v['detail'])})</span>"


def write_html(summary: dict, figures: dict, path: str) -> None:
    """The HTML report: versions, tolerances, per-case tables and plots, known disagreements."""
    e = html.escape
    rows = []
    for c in summary["cases"]:
        for pol, r in c["polarizations"].items():
            s = r["comparison_compat"]
            rows.append(
                f"<tr class={'ok' if r['passed'] else 'bad'}><td>{e(c['name'])}</td><td>{pol}</td><td>{s['matched']}</td>"
                f"<td>{s['only_wavepaths']}</td><td>{s['only_sionna']}</td>"
                f"<td>{_fmt(s['delay_rel_error']['max'])}</td><td>{_fmt(s['gain_diff_db']['median'])}</td>"
                f"<td>{_fmt(s['gain_diff_db']['max'])}</td><td>{_fmt(r['total_gain_diff_db_matched'])}</td>"
                f"<td>{_fmt(c['wavepaths_time_s'])}</td><td>{_fmt(r['sionna_time_s'])}</td>"
                f"<td>{'pass' if r['passed'] else 'FAIL: ' + e('; '.join(r['violations'][:3]))}</td></tr>")
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>wavepaths validation</title><style>",
        "body{font-family:system-ui,sans-serif;max-width:1250px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;font-size:13px;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 7px;text-align:right}"
        "th{background:#f0f0f0}td:first-child{text-align:left}tr.bad{background:#fdd}tr.ok td:last-child{color:#070}"
        "code{background:#f4f4f4;padding:1px 3px}img{max-width:100%}.small{font-size:12px;color:#555}",
        "</style></head><body>",
        "<h1>wavepaths validation against Sionna RT and exact solutions</h1>",
        f"<p>Generated {e(summary['generated'])} by <code>wavepaths validate{' --quick' if summary['quick'] else ''}</code>. "
        f"Overall: <b>{'PASS' if summary['passed'] else 'FAIL'}</b> ({_verdict_text(summary)}).</p>",
        "<h2>Versions and machine</h2><table>" + "".join(
            f"<tr><th>{e(k)}</th><td>{e(str(v))}</td></tr>" for k, v in summary["versions"].items()) + "</table>",
        "<h2>Tolerances</h2><p>Sionna RT computes in float32, wavepaths in float64. Matched paths must agree within "
        f"{TOLERANCES['delay_rel']:g} relative in delay, {TOLERANCES['gain_db_los_reflection']} dB in |a| for line of sight "
        f"and reflections, {TOLERANCES['gain_db_diffraction_compat']} dB for diffraction when wavepaths reproduces Sionna's "
        "diffraction combination (<code>compat='sionna'</code>); every path Sionna finds must be found by wavepaths. "
        "Paths are matched by interaction sequence and vertex positions (within 2 cm), not by order.</p>"
        "<p>The exact solutions are the arbiter, Sionna RT is a peer: on every boundary line and polarisation "
        f"wavepaths' UTD must stay within {summary['tolerances']['exact_max_db']} dB of the exact |u| where it is lit "
        f"(|u| &gt; 0.05) and within {summary['tolerances']['exact_max_complex_error']} of the exact complex u "
        "(a point source 10 km away stands in for the plane wave; UTD is asymptotic in 1/(k rho), k rho ~ 73). "
        "An engine within both bounds matches the exact solution. Non-finite numbers are <code>null</code> in "
        "<code>validation.json</code>.</p>",
        "<h2>Path-by-path comparison (compat mode)</h2><table><tr><th>case</th><th>pol</th><th>matched</th>"
        "<th>only wavepaths</th><th>only Sionna</th><th>max delay rel. diff</th><th>median |a| diff [dB]</th>"
        "<th>max |a| diff [dB]</th><th>max total gain diff, matched [dB]</th><th>wavepaths trace [s]</th>"
        "<th>Sionna [s]</th><th>verdict</th></tr>" + "".join(rows) + "</table>",
    ]
    parts.append("<h2>Across shadow and reflection boundaries: who matches the exact solution</h2>"
                 "<p>A transmitter 10 km away lights the edge (a plane wave); receivers on a circle around it. "
                 "|u| is the total field (line of sight, reflection, diffraction by this edge) relative to the "
                 "incident field at the edge. Black: the exact solution (Sommerfeld's half-plane; the wedge "
                 "eigenfunction series).</p>")
    exact = summary["exact_comparison"]
    for name, line in summary.get("lines", {}).items():
        parts.append(f"<h3>{e(name)}</h3><img src='data:image/png;base64,{figures['line_' + name]}'>")
        verdicts = exact["lines"].get(name, {})
        parts.append("<p>Matches the exact solution: " + "; ".join(
            f"{field}: <b>{e(v['matches_exact'])}</b>" for field, v in verdicts.items()) + "</p>")
        parts.append("<table><tr><th>engine (polarisation)</th><th>max |u| error [dB]</th><th>median [dB]</th>"
                     "<th>max complex error</th><th>within tolerance</th></tr>" + "".join(
                         f"<tr><td>{e(k)}</td><td>{_fmt(v['max_db'])}</td><td>{_fmt(v['median_db'])}</td>"
                         f"<td>{_fmt(v['max_complex_error'])}</td><td>{_within_text(exact, name, k)}</td></tr>"
                         for k, v in line["errors"].items()) + "</table>")
    cov = summary.get("coverage")
    if cov:
        parts.append("<h2>Coverage maps</h2><p>Sionna RT's <code>RadioMapSolver</code> (ray shooting, cell-averaged, "
                     "power sum) and wavepaths' exact paths at the cell centres (power sum), same scene "
                     f"(<code>{e(str(cov['scene']))}</code>), transmitter {cov['tx']}, {cov['cell_m']} m cells at "
                     f"z = {cov['center'][2]} m, depth {cov['max_depth']}. Statistics over cells outside buildings "
                     f"where both maps exceed {cov['noise_floor_db']} dB.</p>")
        parts.append(f"<img src='data:image/png;base64,{figures['coverage']}'>")
        parts.append("<table><tr><th>run</th><th>cells compared</th><th>median diff [dB]</th><th>mean [dB]</th>"
                     "<th>std [dB]</th><th>95% |diff| [dB]</th><th>cells only wavepaths reaches</th>"
                     "<th>wavepaths [s]</th><th>Sionna [s] (after warm-up)</th></tr>" + "".join(
                         f"<tr><td>{e(k)}</td><td>{r['cells_compared']}</td><td>{_fmt(r['median_db'])}</td>"
                         f"<td>{_fmt(r['mean_db'])}</td><td>{_fmt(r['std_db'])}</td><td>{_fmt(r['p95_abs_db'])}</td>"
                         f"<td>{r['cells_only_wavepaths']}</td><td>{_fmt(r['wavepaths_time_s'])}</td>"
                         f"<td>{_fmt(r['sionna_time_s'])}</td></tr>" for k, r in cov["runs"].items()) + "</table>")
    parts.append("<h2>Known disagreements</h2><p>Which engine matches the exact solution is computed from the "
                 "boundary lines' errors above (within the tolerances on every line the disagreement shows on); "
                 "where no line of this report measures it, the documented answer is given with the test that "
                 "checks it.</p><table><tr><th>what</th><th>why</th><th>matches the exact solution</th></tr>"
                 + "".join(f"<tr><td style='text-align:left'>{e(k['what'])}</td><td style='text-align:left'>{e(k['reason'])}</td>"
                           f"<td style='text-align:left'>{_known_verdict_html(k, exact)}</td></tr>"
                           for k in summary["known_disagreements"]) + "</table>")
    parts.append("<h2>Cases</h2>")
    for c in summary["cases"]:
        parts.append(f"<h3>{e(c['name'])}</h3><p class=small>{e(c['note'])}. Scene file <code>{e(c['scene_file'])}</code>; "
                     f"{c['num_rx']} receivers; depth {c['max_depth']}; edge diffraction in Sionna: {c['edge_diffraction']}.</p>")
        if "gain_" + c["name"] in figures:
            parts.append(f"<img src='data:image/png;base64,{figures['gain_' + c['name']]}'>")
        for pol, r in c["polarizations"].items():
            bk = r["comparison_compat"]["by_kind"]
            parts.append(f"<p><b>{pol}</b>: by interaction sequence (compat): " + ", ".join(
                f"{e(k)}: {v['matched']} matched, max |a| diff {_fmt(v['gain_diff_db']['max'])} dB" for k, v in bk.items()) + "</p>")
            if r["textbook_diffraction_gain_diff_db"]:
                parts.append("<p class=small>Textbook UTD vs Sionna for the same diffracted paths: " + ", ".join(
                    f"{e(k)} max {_fmt(v['max'])} dB, median {_fmt(v['median'])} dB"
                    for k, v in r["textbook_diffraction_gain_diff_db"].items()) + "</p>")
            if r.get("matched_on_multi_object_edges"):
                parts.append(f"<p class=small>{r['matched_on_multi_object_edges']} matched diffracted path(s) lie on edges "
                             "shared by several objects: wavepaths' true dihedron (seed §3.3) differs from Sionna's "
                             "single-mesh wedge, so their coefficients are not held to the tolerance.</p>")
            if r.get("matched_on_non_manifold_edges"):
                parts.append(f"<p class=small>{r['matched_on_non_manifold_edges']} matched diffracted path(s) lie on edges "
                             "where three or more faces of one mesh meet: Sionna's wedge is one pair of them (one block's "
                             "own corner), wavepaths' the free-space sector of all of them, so their coefficients are not "
                             "held to the tolerance (known disagreement 'non-manifold-edge-wedge').</p>")
            if r.get("matched_on_collapsed_free_edges"):
                parts.append(f"<p class=small>{r['matched_on_collapsed_free_edges']} matched diffracted path(s) lie on free "
                             "edges whose Sionna wedge collapsed to a flat one (n = 1) in float32: Sionna's coefficient "
                             "vanishes where the exact half-plane solution does not (known disagreement "
                             "'sionna-free-edge-collapses-to-flat').</p>")
            reasons = r["comparison_compat"]["only_wavepaths_reasons"]
            if reasons:
                parts.append("<p class=small>Only in wavepaths: " + "; ".join(f"{v} x {e(k)}" for k, v in reasons.items()) + "</p>")
            if r["only_sionna"]:
                parts.append("<p class=small style='color:#a00'>Only in Sionna: " + "; ".join(
                    f"{e(x['kinds'])} rx {x['rx']} ({_fmt(x['length_m'], '.3f')} m)" for x in r["only_sionna"][:20]) + "</p>")
    parts.append("</body></html>")
    with open(path, "w") as f:
        f.write("\n".join(parts))


def write_report(json_path: str, html_path: str) -> dict:
    """Write ``report.html`` from ``validation.json`` alone (figures included); return the summary read."""
    with open(json_path) as f:
        summary = json.load(f)
    write_html(summary, report_figures(summary), html_path)
    return summary


def run_validation(out_dir: str, quick: bool = False, progress=None) -> dict:
    """Run the cases, the boundary lines and the coverage maps; write ``validation.json`` and,
    from it, ``report.html``. Return the summary as written to the JSON."""
    from .lines import boundary_line, line_summary

    os.makedirs(out_dir, exist_ok=True)
    cases = [c for c in default_cases() if c.quick or not quick]
    results = []
    steps = len(cases) + 3
    for i, case in enumerate(cases):
        if progress:
            progress(i, steps, case.name)
        results.append(run_case(case, out_dir))
    lines = {}
    for j, name in enumerate(("half_plane", "wedge")):
        if progress:
            progress(len(cases) + j, steps, f"boundary line {name}")
        lines[name] = line_summary(boundary_line(name, out_dir))
    if progress:
        progress(steps, steps, "coverage maps")
    from .coverage_compare import compare_coverage
    from .sionna_runner import builtin_scene_path

    # the maps (wavepaths_db, sionna_db, difference_db) stay: the coverage figure is drawn from them
    coverage_summary = compare_coverage(builtin_scene_path("simple_street_canyon"), [-40.0, 0.0, 10.0],
                                        (0.0, 0.0, 1.5), (160.0, 80.0), 4.0 if quick else 2.0, 2)
    if progress:
        progress(steps, steps, "report")
    exact = exact_comparison(lines, EXACT_TOLERANCES)
    exact["known_disagreements"] = known_disagreement_verdicts(KNOWN_DISAGREEMENTS, exact)
    cases_passed = all(r["passed"] for r in results)
    summary = {
        "generated": time.strftime("%Y-%m-%d %H:%M:%S"),
        "quick": quick,
        "versions": _versions(),
        "tolerances": TOLERANCES,
        "cases": results,
        "lines": lines,
        "coverage": coverage_summary,
        "known_disagreements": KNOWN_DISAGREEMENTS,
        "exact_comparison": exact,
        "cases_passed": cases_passed,
        "passed": cases_passed and exact["passed"],
    }
    json_path = os.path.join(out_dir, "validation.json")
    write_json(summary, json_path)
    return write_report(json_path, os.path.join(out_dir, "report.html"))
