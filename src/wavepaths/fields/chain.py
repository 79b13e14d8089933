"""The field carried by each path: Jones matrices chained along the path.

The field is carried as a complex 3-vector transverse to the current propagation
direction, which avoids any basis bookkeeping between interactions:

* transmitter: ``E = C_theta theta_hat + C_phi phi_hat`` of the departure direction
  (the antenna pattern, one vector per port);
* reflection (seed §2.1's coherence form applies the same matrices): with
  ``e_s = unit(k_i x n)``, ``p = e_s x k``: ``E -> r_te (E.e_s) e_s + r_tm (E.p_i) p_r``
  (ITU-R P.2040 coefficients, conventions in :mod:`wavepaths.em.fresnel`);
* diffraction: in KP's edge-fixed bases ``phi' = unit(s' x e)``, ``b0' = s' x phi'``,
  ``phi = unit(e x s)``, ``b0 = s x phi`` the 2x2 matrix of
  :func:`wavepaths.em.utd.diffraction_jones_matrices` (UTD or GTD, Luebbers' face
  coefficients as the faces' reflections in these bases,
  :func:`wavepaths.em.utd.wedge_reflection_matrices`) or of
  :func:`wavepaths.em.utd.diffraction_jones` (Sionna RT's form) maps ``(E.b0', E.phi')`` to
  the ``b0``, ``phi`` components of the diffracted field;
* receiver: ``V = C_rx^* . E`` with ``C_rx`` the receive pattern toward the arriving
  wave (seen from the receiver).

Spreading: ``1/l`` for a path without diffraction (``l`` its unfolded length); with a
diffraction, ``1/sqrt(s s' (s + s'))`` with ``s'`` and ``s`` the unfolded lengths before
and after it (spherical-wave UTD, KP 1974 Table I). The distance parameter is
``L = s s' sin^2(beta_0) / (s + s')``.

The path coefficient is normalised like Sionna RT's ``Paths.a`` for unit transmit
power: ``a = (lambda / 4 pi) * spreading * V``, *without* the propagation phase
``exp(-j 2 pi f tau)`` (apply it with :attr:`FieldResult.a_phased`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._vec import unit as _unit

from .._vec import unit_cross as _perp_unit
from ..em.antennas import antenna_field_vectors
from ..em.fresnel import reflection_coefficients
from ..em.polarization import spherical_unit_vectors
from ..em.sionna_compat import sionna_face_coefficients
from ..em.utd_terms import SIN_BETA_0_FLOOR
from ..em.utd import (
    diffraction_jones,
    diffraction_jones_matrices,
    luebbers_face_coefficients,
    wedge_reflection_matrices,
)
from ..scene.polygon_query import polygon_margin_length
from ..search.paths import InteractionType, Paths
from . import compiled as _compiled
from .config import FieldConfig

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...j,...j->...", a, b)



def _apply_reflection(scene: "Scene", cfg: FieldConfig, E: np.ndarray, k_in, k_out, polygon) -> np.ndarray:
    """Reflect field vectors ``E`` (k, p, 3) on ``polygon`` (k,)."""
    n = scene.polygon_normal[polygon]
    if _compiled.use_compiled(cfg):
        from . import _numba

        mats = scene.polygon_material[polygon]
        out = np.ascontiguousarray(E, dtype=np.complex128)
        _numba.reflect(out, np.ascontiguousarray(k_in), np.ascontiguousarray(k_out), np.ascontiguousarray(n),
                       mats, *_compiled.material_tables(scene, cfg, mats), cfg.reflection_model == "slab")
        return out
    cos_t = np.abs(_dot(k_in, n))
    e_s = _perp_unit(k_in, n, _perp_unit(n, np.array([0.0, 0.0, 1.0]) + 0 * n, np.array([1.0, 0.0, 0.0])))
    p_i = np.cross(e_s, k_in)
    p_r = np.cross(e_s, k_out)
    r_te = np.empty(len(polygon), complex)
    r_tm = np.empty(len(polygon), complex)
    mats = scene.polygon_material[polygon]
    for m in np.unique(mats):
        sel = mats == m
        r = reflection_coefficients(scene.materials[m], cfg.frequency_hz, cos_t[sel], cfg.reflection_model)
        r_te[sel], r_tm[sel] = r.r_te, r.r_tm
    es = _dot(E, e_s[:, None, :])
    ep = _dot(E, p_i[:, None, :])
    return (r_te[:, None] * es)[..., None] * e_s[:, None, :] + (r_tm[:, None] * ep)[..., None] * p_r[:, None, :]


def wedge_geometry(scene: "Scene", paths: Paths, rows: np.ndarray, j: int, compiled: bool = False):
    """UTD angles of the diffraction at interaction ``j`` of paths ``rows``.

    ``compiled``: in :func:`wavepaths.fields._numba.wedge_geometry` (the same formulas; this
    numpy code is its reference), if the compiled kernels are available.

    Returns
    -------
    dict with ``e`` (k, 3) edge unit vector, ``phi``, ``phi_prime``, ``beta_0``, ``n``
    (k,), ``s_in`` and ``s_out`` (k, 3) propagation directions, ``face_0`` and ``face_n``
    (k,) indices into the dihedra's face arrays.
    """
    dih = scene.dihedra
    d = paths.primitive[rows, j]
    f0 = paths.wedge_faces[rows, 0]
    fn = paths.wedge_faces[rows, 1]
    if compiled and _compiled.available():
        from . import _numba

        keys = ("e", "s_in", "s_out", "phi", "phi_prime", "beta_0", "n")
        c = np.ascontiguousarray
        out = _numba.wedge_geometry(c(paths.vertices, dtype=float), c(rows, dtype=np.int64), j, c(d, dtype=np.int64),
                                    c(f0, dtype=np.int64), c(fn, dtype=np.int64), dih.direction, dih.face_direction)
        return dict(zip(keys, out), face_0=f0, face_n=fn)
    e = dih.direction[d]
    v = paths.vertices[rows]
    prev, p, nxt = v[:, j], v[:, j + 1], v[:, j + 2]
    s_in = _unit(p - prev)
    s_out = _unit(nxt - p)
    x = dih.face_direction[f0]
    y = np.cross(e, x)

    def angle(vec):
        return np.mod(np.arctan2(_dot(vec, y), _dot(vec, x)), 2 * np.pi)

    wedge = angle(dih.face_direction[fn])
    wedge = np.where(wedge < 1e-9, 2 * np.pi, wedge)
    return {
        "e": e,
        "phi_prime": angle(prev - p),
        "phi": angle(nxt - p),
        "beta_0": np.arctan2(np.linalg.norm(np.cross(s_in, e), axis=1), _dot(s_in, e)),
        "n": wedge / np.pi,
        "s_in": s_in,
        "s_out": s_out,
        "face_0": f0,
        "face_n": fn,
    }


def _sionna_face_order(g: dict) -> dict:
    """Relabel the wedge as Sionna RT 2.2 does: its 0-face is the face whose normal faces
    the incoming ray (``phi' < pi``). Swapping faces maps ``phi -> n pi - phi``,
    ``phi' -> n pi - phi'`` and reverses the edge vector (docs/sionna-diffraction.md §1)."""
    return _swap_faces(g, g["phi_prime"] > np.pi)


def _reciprocal_face_order(g: dict) -> dict:
    """Relabel the wedge so that the source lies nearer the 0-face than the observer does
    (``phi' <= phi``), for Luebbers' face coefficients (docs/conventions.md).

    Luebbers takes ``R0`` at the source's angle ``phi'`` and ``Rn`` at the observer's
    ``n pi - phi``: with the faces labelled by the edge alone, swapping transmitter and
    receiver changes the coefficient of a lossy wedge (by up to 15 dB on the street
    canyon). Mirroring the labels maps ``(phi, phi')`` to ``(n pi - phi, n pi - phi')``,
    which evaluates Luebbers' formula as ``D(phi', phi)`` of the first labelling: the
    coefficient becomes ``D(min(phi, phi'), max(phi, phi'))``, symmetric in the two ends
    (reciprocal), continuous where they meet (``phi = phi'``: both labellings agree), and
    unchanged at every shadow and reflection boundary, where both evaluate each face's
    reflection at its geometrical-optics angle. A PEC wedge gives KP either way.
    """
    return _swap_faces(g, g["phi_prime"] > g["phi"])


def _swap_faces(g: dict, swap: np.ndarray) -> dict:
    """``g`` with the 0- and n-faces exchanged where ``swap``: ``phi -> n pi - phi``,
    ``phi' -> n pi - phi'``, ``beta_0 -> pi - beta_0`` and the edge vector reversed."""
    if not swap.any():
        return g
    g = dict(g)
    npi = g["n"] * np.pi
    g["phi"] = np.where(swap, npi - g["phi"], g["phi"])
    g["phi_prime"] = np.where(swap, npi - g["phi_prime"], g["phi_prime"])
    g["e"] = np.where(swap[:, None], -g["e"], g["e"])
    g["beta_0"] = np.where(swap, np.pi - g["beta_0"], g["beta_0"])
    g["face_0"], g["face_n"] = np.where(swap, g["face_n"], g["face_0"]), np.where(swap, g["face_0"], g["face_n"])
    return g


BOUNDARY_EPS = 1e-12  # [rad] an observer this close to a shadow/reflection boundary is on it
BOUNDARY_NUDGE = 1e-9  # [rad] the side it is moved to, matching the geometrical-optics decision


def _path_keys(paths: Paths, pairs: np.ndarray) -> set:
    """(tx, rx, interaction sequence) of the paths between the (tx, rx) ``pairs`` (k, 2) only:
    the few pairs with a path near a boundary, not every path of the batch."""
    n_rx = len(paths.rx_positions)
    sel = np.nonzero(np.isin(paths.tx_index * n_rx + paths.rx_index, pairs[:, 0] * n_rx + pairs[:, 1]))[0]
    return {
        (int(paths.tx_index[i]), int(paths.rx_index[i]),
         tuple(zip(paths.interactions[i, : paths.depth[i]].tolist(), paths.primitive[i, : paths.depth[i]].tolist())))
        for i in sel
    }


def _on_boundary_sides(scene: "Scene", paths: Paths, rows: np.ndarray, j: int, g: dict, legs: np.ndarray) -> None:
    """Observers on, or within the search's margin of, a shadow or reflection boundary:
    put them on the side the geometrical-optics path is on.

    The UTD term of a boundary switches sign across it, by the float64 angles; the
    geometrical-optics (GO) path is kept or dropped by the search, whose decisions within
    :func:`~wavepaths.scene.polygon_query.polygon_margin_length` of the edge may fall on the
    other side. Exactly on a boundary the UTD singular term is the mean of its one-sided
    limits and needs a GO weight of 1/2 that the search cannot give. So when the GO ray
    passes within that margin of the edge, the diffraction term takes the
    one-sided limit of the side the search chose: the lit side when the GO path (the line
    of sight for the incident shadow boundary, the reflection on the 0- or n-face for a
    reflection boundary) is among the paths, else the shadow side. The total field is
    then continuous, and exact on the boundary (a grazing perfectly conducting screen with
    both ends 1,000 wavelengths away: 6.06 dB below free space soft, 5.98 dB hard; 6.02 dB
    is the absorbing screen's).

    The margin: the search decides each GO path in float64, occlusion exactly (to 1e-12 of
    the size) and a reflection point inside its face up to the barycentric
    :data:`~wavepaths.scene.polygon_query.POLYGON_MARGIN`, at most 4e-9 of the size in metres.
    Beyond it the float64 angles and the search agree, and the angles are left alone: a GO
    path missing for another reason (another object blocking the line of sight) is no sign
    that the observer is on the shadow side. (It was ``4 ray_offset``, a float32 budget a
    thousand times larger: an object blocking the line of sight 0.05 rad inside it moved the
    diffraction onto the boundary and flipped its sign; docs/stress.md, S21.)
    """
    phi, pp, n = g["phi"], g["phi_prime"], g["n"]
    margin = np.maximum(polygon_margin_length(scene) / np.maximum(legs, 1e-300), BOUNDARY_EPS)
    sb = np.abs(phi - pp) - np.pi
    rb0 = phi + pp - np.pi
    rbn = phi + pp - (2 * n - 1) * np.pi
    near = (np.abs(sb) < margin) | (np.abs(rb0) < margin) | (np.abs(rbn) < margin)
    if not near.any():
        return
    nr = rows[np.nonzero(near)[0]]
    keys = _path_keys(paths, np.stack([paths.tx_index[nr], paths.rx_index[nr]], axis=1))
    dih = scene.dihedra
    for k in np.nonzero(near)[0]:
        i = rows[k]
        seq = list(zip(paths.interactions[i, : paths.depth[i]].tolist(), paths.primitive[i, : paths.depth[i]].tolist()))
        t, r = int(paths.tx_index[i]), int(paths.rx_index[i])
        # the nudge moves phi and phi' by half each, so that the pair's difference (a shadow
        # boundary) or sum (a reflection boundary) takes its side: symmetric in phi <-> phi', the
        # path's coefficient is the transpose of its reverse's there too (moving phi alone gave
        # 5e-9 apart). A shadow and a reflection boundary both within the margin (a source
        # grazing a face) are each given their side: the difference and the sum move apart
        if abs(sb[k]) < margin[k]:
            lit = (t, r, tuple(seq[:j] + seq[j + 1 :])) in keys
            if lit != (sb[k] < 0) or sb[k] == 0:
                side = 1.0 if phi[k] >= pp[k] else -1.0
                _nudge(g, k, side * (np.pi - BOUNDARY_NUDGE if lit else np.pi + BOUNDARY_NUDGE) - (phi[k] - pp[k]), -1.0)
        if abs(rb0[k]) < margin[k]:
            lit = (t, r, tuple(seq[:j] + [(1, int(dih.face_polygon[g["face_0"][k]]))] + seq[j + 1 :])) in keys
            if lit != (rb0[k] < 0) or rb0[k] == 0:
                _nudge(g, k, np.pi + (-BOUNDARY_NUDGE if lit else BOUNDARY_NUDGE) - (phi[k] + pp[k]), 1.0)
        elif abs(rbn[k]) < margin[k]:
            lit = (t, r, tuple(seq[:j] + [(1, int(dih.face_polygon[g["face_n"][k]]))] + seq[j + 1 :])) in keys
            if lit != (rbn[k] > 0) or rbn[k] == 0:
                _nudge(g, k, (2 * n[k] - 1) * np.pi + (BOUNDARY_NUDGE if lit else -BOUNDARY_NUDGE) - (phi[k] + pp[k]), 1.0)


def _nudge(g: dict, k: int, change: float, prime_sign: float) -> None:
    """Add ``change`` to ``phi - phi'`` (``prime_sign = -1``) or ``phi + phi'`` (``+1``) of row
    ``k``, half on each angle, both kept in ``[0, n pi]``."""
    top = g["n"][k] * np.pi
    g["phi"][k] = min(max(g["phi"][k] + 0.5 * change, 0.0), top)
    g["phi_prime"][k] = min(max(g["phi_prime"][k] + prime_sign * 0.5 * change, 0.0), top)


def _apply_diffraction(scene: "Scene", cfg: FieldConfig, E, paths: Paths, rows, j, s_before, s_after) -> np.ndarray:
    g = wedge_geometry(scene, paths, rows, j, compiled=_compiled.use_compiled(cfg))
    _on_boundary_sides(scene, paths, rows, j, g, np.minimum(s_before, s_after))
    g = _sionna_face_order(g) if cfg.compat == "sionna" else _reciprocal_face_order(g)
    e, s_in, s_out = g["e"], g["s_in"], g["s_out"]
    k = cfg.wavenumber
    # the coefficients floor |sin beta_0| at SIN_BETA_0_FLOOR; L takes the same floored sine, so
    # that D (1/sin beta_0 times F(k L a) ~ sqrt(L)) tends to its finite grazing limit instead of 0
    sin_b = np.maximum(np.abs(np.sin(g["beta_0"])), SIN_BETA_0_FLOOR)
    L = s_before * s_after / (s_before + s_after) * sin_b**2
    dih = scene.dihedra
    mat0 = scene.triangle_material[dih.face_triangle[g["face_0"]]]
    matn = scene.triangle_material[dih.face_triangle[g["face_n"]]]
    if cfg.model == "utd" and cfg.compat == "none" and _compiled.use_compiled(cfg):
        return _diffract_compiled(scene, cfg, E, g, L, mat0, matn)
    jones = np.empty((len(rows), 2, 2), complex)
    x_fallback = dih.face_direction[g["face_0"]]
    if cfg.compat != "sionna":
        # the faces' normals (any sign: a reflection does not depend on it)
        normal_0 = _perp_unit(e, x_fallback, x_fallback)
        normal_n = _perp_unit(e, dih.face_direction[g["face_n"]], x_fallback)
    for m0, mn in set(zip(mat0.tolist(), matn.tolist())):
        sel = (mat0 == m0) & (matn == mn)
        args = (g["phi"][sel], g["phi_prime"][sel], g["beta_0"][sel], g["n"][sel])
        if cfg.compat == "sionna":
            r = sionna_face_coefficients(scene.materials[m0], cfg.frequency_hz, args[1], args[2], args[3])
            jones[sel] = diffraction_jones(*args, k, L[sel], "sionna", *r)
        else:
            # Luebbers' face coefficients as reflections in the edge-fixed bases (full 2x2 at
            # oblique incidence: the total field stays continuous at the reflection boundaries)
            r = luebbers_face_coefficients(scene.materials[m0], scene.materials[mn], cfg.frequency_hz, args[0],
                                           args[1], args[3], cfg.reflection_model, beta_0=args[2])
            g0, gn = wedge_reflection_matrices(*r, e[sel], s_in[sel], s_out[sel], normal_0[sel], normal_n[sel],
                                               x_fallback[sel])
            jones[sel] = diffraction_jones_matrices(*args, k, L[sel], cfg.model, g0, gn)
    phi_in = _perp_unit(s_in, e, x_fallback)
    b_in = np.cross(s_in, phi_in)
    phi_out = _perp_unit(e, s_out, x_fallback)
    b_out = np.cross(s_out, phi_out)
    cb = _dot(E, b_in[:, None, :])
    cp = _dot(E, phi_in[:, None, :])
    ob = jones[:, None, 0, 0] * cb + jones[:, None, 0, 1] * cp
    op = jones[:, None, 1, 0] * cb + jones[:, None, 1, 1] * cp
    return ob[..., None] * b_out[:, None, :] + op[..., None] * phi_out[:, None, :]


def _diffract_compiled(scene: "Scene", cfg: FieldConfig, E, g: dict, L, mat0, matn) -> np.ndarray:
    """The tail of :func:`_apply_diffraction` (model ``"utd"``) in :func:`wavepaths.fields._numba.diffract`."""
    from ..em.utd_terms import _prepare
    from . import _numba

    # the reference's input checks (finite angles, 1 < n <= 2, L >= 0), with its messages
    _prepare(g["phi"], g["phi_prime"], g["beta_0"], g["n"], cfg.wavenumber, L)
    c = np.ascontiguousarray
    out = c(E, dtype=np.complex128)
    tables = _compiled.material_tables(scene, cfg, np.concatenate([mat0, matn]))
    kernel = _numba.diffract_parallel if _compiled.parallel(len(out)) else _numba.diffract
    kernel(np.uint64(_compiled.erfcx_address()), out, c(g["e"]), c(g["s_in"]), c(g["s_out"]),
           c(scene.dihedra.face_direction[g["face_0"]]), c(scene.dihedra.face_direction[g["face_n"]]), c(g["phi"], dtype=float), c(g["phi_prime"], dtype=float),
           c(g["beta_0"], dtype=float), c(g["n"], dtype=float), c(L, dtype=float), float(cfg.wavenumber),
           SIN_BETA_0_FLOOR, mat0, matn, *tables, cfg.reflection_model == "slab")
    return out


def path_field_vectors(scene: "Scene", paths: Paths, cfg: FieldConfig) -> tuple[np.ndarray, np.ndarray]:
    """Field vectors at the receiver and the spreading factor of each path.

    With the compiled kernels, model ``"utd"`` and no compat mode, the chain runs as one
    compiled pass per path (:func:`_path_field_vectors_compiled`); this function's numpy
    loop over the interactions is its reference.

    Returns
    -------
    E : (N, Pt, 3) complex128
        Field at the receiver per transmit port, for unit pattern amplitude normalisation
        (before spreading and the lambda / 4 pi factor).
    spreading : (N,) float64 [1/m]
    """
    # (the kernel adds a path's segment lengths left to right, as numpy's sum does below 8
    # columns; max_reflections <= 6 keeps paths within 7 segments)
    if (len(paths) and cfg.model == "utd" and cfg.compat == "none" and paths.max_depth < 7
            and _compiled.use_compiled(cfg)):
        return _path_field_vectors_compiled(scene, paths, cfg)
    return _path_field_vectors_numpy(scene, paths, cfg)


def _path_field_vectors_compiled(scene: "Scene", paths: Paths, cfg: FieldConfig) -> tuple[np.ndarray, np.ndarray]:
    """:func:`path_field_vectors` with each path's chain in one compiled pass
    (:func:`wavepaths.fields._numba.chain_fields`: the kernels of the reflections, the wedge
    geometry and the diffraction, in path order, instead of a gather, a kernel call and a
    scatter per interaction). A diffraction near a shadow or reflection boundary needs the
    other paths of its (transmitter, receiver) pair (:func:`_on_boundary_sides`): the kernel
    leaves such paths, and the numpy chain computes them among those pairs' paths."""
    from . import _numba

    E = np.ascontiguousarray(antenna_field_vectors(cfg.tx_antenna, paths.departure_directions, compiled=cfg.compiled), dtype=np.complex128)
    seg = np.ascontiguousarray(paths.segment_lengths)
    n = len(paths)
    spreading = np.empty(n)
    deferred = np.zeros(n, dtype=bool)
    dih = scene.dihedra
    kinds = paths.interactions
    refl = kinds == InteractionType.REFLECTION
    diffracted = (kinds == InteractionType.DIFFRACTION).any(axis=1)
    face_material = scene.triangle_material[dih.face_triangle]
    used = np.concatenate([scene.polygon_material[paths.primitive[refl]],
                           face_material[paths.wedge_faces[diffracted]].ravel()])
    tables = _compiled.material_tables(scene, cfg, used)
    kernel = _numba.chain_fields_parallel if _compiled.parallel(int(diffracted.sum())) else _numba.chain_fields
    kernel(np.uint64(_compiled.erfcx_address()), E, spreading, deferred, np.ascontiguousarray(paths.vertices, dtype=float),
           seg, np.ascontiguousarray(kinds), np.ascontiguousarray(paths.primitive, dtype=np.int64),
           np.ascontiguousarray(paths.wedge_faces, dtype=np.int64), scene.polygon_normal, scene.polygon_material,
           dih.direction, dih.face_direction, face_material, *tables, cfg.reflection_model == "slab",
           float(cfg.wavenumber), SIN_BETA_0_FLOOR, polygon_margin_length(scene), BOUNDARY_EPS)
    if deferred.any():
        # the numpy chain for the paths of the pairs concerned (it looks for their
        # geometrical-optics paths among them), then the deferred rows taken from it
        n_rx = len(paths.rx_positions)
        pair = paths.tx_index * n_rx + paths.rx_index
        among = np.isin(pair, pair[deferred])
        E_sub, s_sub = _path_field_vectors_numpy(scene, paths.select(among), cfg)
        rows = np.nonzero(among)[0]
        take = deferred[rows]
        E[rows[take]] = E_sub[take]
        spreading[rows[take]] = s_sub[take]
    return E, spreading


def _path_field_vectors_numpy(scene: "Scene", paths: Paths, cfg: FieldConfig) -> tuple[np.ndarray, np.ndarray]:
    """:func:`path_field_vectors` interaction by interaction over all paths (the reference)."""
    seg = paths.segment_lengths  # (N, D + 1)
    dirs = np.diff(paths.vertices, axis=1)
    dirs = dirs / np.where(seg > 0, seg, 1.0)[..., None]
    E = antenna_field_vectors(cfg.tx_antenna, paths.departure_directions, compiled=cfg.compiled)  # (N, Pt, 3)
    total = seg.sum(axis=1)
    spreading = 1.0 / total
    before = np.cumsum(seg, axis=1)  # length up to the end of segment i
    for j in range(paths.max_depth):
        kind = paths.interactions[:, j]
        refl = np.nonzero(kind == InteractionType.REFLECTION)[0]
        if len(refl):
            E[refl] = _apply_reflection(scene, cfg, E[refl], dirs[refl, j], dirs[refl, j + 1], paths.primitive[refl, j])
        diff = np.nonzero(kind == InteractionType.DIFFRACTION)[0]
        if len(diff):
            s_before = before[diff, j]
            s_after = seg[diff, j + 1 :].sum(axis=1)  # summed, not total - s_before: no cancellation
            E[diff] = _apply_diffraction(scene, cfg, E[diff], paths, diff, j, s_before, s_after)
            spreading[diff] = 1.0 / np.sqrt(s_before * s_after * (s_before + s_after))
    return E, spreading


def path_coefficients(scene: "Scene", paths: Paths, cfg: FieldConfig) -> np.ndarray:
    """Complex path coefficients ``a`` (N, Pr, Pt), normalised like Sionna RT's ``Paths.a``.

    ``a = (lambda / 4 pi) * spreading * C_rx^H E``; no ``exp(-j 2 pi f tau)`` phase.
    """
    return coefficients_and_fields(scene, paths, cfg)[0]


def coefficients_and_fields(scene: "Scene", paths: Paths, cfg: FieldConfig) -> tuple[np.ndarray, np.ndarray]:
    """:func:`path_coefficients` and the field each path brings to the receiver, from one chain.

    Returns
    -------
    a : (N, Pr, Pt) complex128
        ``(lambda / 4 pi) * spreading * C_rx^H E``.
    e : (N, Pt, 3) complex128
        ``(lambda / 4 pi) * spreading * E``: the field 3-vector at the receiver per transmit
        port, before the receive antenna, normalised like ``a`` (``a = C_rx^H e``; free space,
        isotropic transmitter: ``|e| = lambda / 4 pi d``); no ``exp(-j 2 pi f tau)`` phase.
    """
    E, spreading = path_field_vectors(scene, paths, cfg)
    e = E * ((cfg.wavelength / (4 * np.pi)) * spreading)[:, None, None]
    C = antenna_field_vectors(cfg.rx_antenna, -paths.arrival_directions, compiled=cfg.compiled)  # (N, Pr, 3)
    return np.einsum("nrj,ntj->nrt", np.conj(C), e), e


def transfer_matrices(scene: "Scene", paths: Paths, cfg: FieldConfig) -> np.ndarray:
    """Path transfer matrices T (N, 2, 2) from (theta_hat, phi_hat) at departure to
    (theta_hat, phi_hat) of the arrival direction, including spreading and lambda/4 pi.

    With them a source's coherence matrix J propagates as ``T J T^H`` (seed §2.1).
    """
    from ..em.antennas import Antenna

    vcfg = FieldConfig(cfg.frequency_hz, cfg.model, cfg.compat, cfg.reflection_model,
                       Antenna("iso", "VH"), Antenna("iso", "VH"), cfg.tx_power_dbm, cfg.compiled)
    E, spreading = path_field_vectors(scene, paths, vcfg)  # ports: theta, phi unit fields
    basis = spherical_unit_vectors(paths.arrival_directions)
    out = np.empty((len(paths), 2, 2), complex)
    out[:, 0, :] = _dot(E, basis.theta_hat[:, None, :])
    out[:, 1, :] = _dot(E, basis.phi_hat[:, None, :])
    return (cfg.wavelength / (4 * np.pi)) * spreading[:, None, None] * out
