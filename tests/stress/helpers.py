"""Shared helpers of the stress suite: total fields, path keys, laws at the vertices,
independent references (image theory, the half-plane's scalar fields).

Nothing here calls the engine's internals beyond its public results (``trace``,
``compute_fields``, ``transfer_matrices``, ``Paths``), so the references stay independent.
"""

from __future__ import annotations

import warnings

import numpy as np

from wavepaths import InteractionType, TraceOptions, WavepathsError, trace
from wavepaths.em.antennas import Antenna
from wavepaths.fields import FieldConfig, compute_fields, transfer_matrices
from wavepaths.scene import WavepathsWarning

REFL, DIFF = int(InteractionType.REFLECTION), int(InteractionType.DIFFRACTION)
C0 = 299_792_458.0  # m/s, as scipy.constants.c


def config(pol: str = "V", frequency_hz: float = 3e9) -> FieldConfig:
    """Isotropic antennas of one polarisation at both ends."""
    ant = Antenna("iso", pol)
    return FieldConfig(frequency_hz=frequency_hz, tx_antenna=ant, rx_antenna=ant)


def total_field(scene, tx, rx, options: TraceOptions, pol: str = "V", frequency_hz: float = 3e9):
    """Coherent sum of ``a exp(-j 2 pi f tau)`` per receiver, the paths and their fields.

    Returns
    -------
    total : (n,) complex128
    paths : Paths
    fields : FieldResult
    """
    rx = np.atleast_2d(np.asarray(rx, float))
    p = trace(scene, np.atleast_2d(np.asarray(tx, float)), rx, options)
    f = compute_fields(scene, p, config(pol, frequency_hz))
    out = np.zeros(len(rx), complex)
    np.add.at(out, p.rx_index, f.a_phased)
    return out, p, f


def go_mask(paths) -> np.ndarray:
    """(N,) bool: paths without a diffraction (geometrical optics)."""
    if paths.max_depth == 0:
        return np.ones(len(paths), bool)
    return ~(paths.interactions == DIFF).any(axis=1)


def per_receiver(paths, values, n: int, mask=None) -> np.ndarray:
    """Sum ``values`` (N,) per receiver, optionally over ``mask`` only."""
    out = np.zeros(n, complex)
    m = np.ones(len(paths), bool) if mask is None else mask
    np.add.at(out, paths.rx_index[m], values[m])
    return out


def path_key(paths, i: int, reverse: bool = False) -> tuple:
    """(interaction kinds, primitives) of path ``i``, reversed for the reciprocal path."""
    d = int(paths.depth[i])
    kinds = paths.interactions[i, :d].tolist()
    prims = paths.primitive[i, :d].tolist()
    if reverse:
        kinds, prims = kinds[::-1], prims[::-1]
    return tuple(kinds), tuple(prims)


def path_table(paths, reverse: bool = False) -> dict:
    """{(tx, rx, kinds, primitives): row}; a path found twice is an error."""
    out = {}
    for i in range(len(paths)):
        a, b = int(paths.tx_index[i]), int(paths.rx_index[i])
        key = (b, a) + path_key(paths, i, True) if reverse else (a, b) + path_key(paths, i)
        assert key not in out, f"path found twice: {key}"
        out[key] = i
    return out


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def check_laws(scene, paths, tol: float = 1e-9) -> int:
    """Law of reflection and Keller's cone at every interaction, points on their primitives.

    ``tol`` is on unit-vector components (dimensionless) and, times the scene diagonal,
    on distances. A direction computed from a segment of length ``l`` carries a rounding
    error of ~eps * |coordinates| / l, so the angular tolerance of an interaction grows as
    ``1e-14 * scene size / (shorter adjacent segment)`` when that exceeds ``tol`` (an end
    point 1e-9 m from a face). Returns the number of interactions checked.
    """
    size = scene.diagonal + float(np.abs(scene.bounds).max())
    dih = scene.dihedra
    checked = 0
    for i in range(len(paths)):
        v = paths.vertices[i]
        for j in range(int(paths.depth[i])):
            a, p, b = v[j], v[j + 1], v[j + 2]
            din, dout = unit(p - a), unit(b - p)
            q = int(paths.primitive[i, j])
            ang_tol = max(tol, 1e-14 * size / max(min(np.linalg.norm(p - a), np.linalg.norm(b - p)), 1e-300))
            if paths.interactions[i, j] == REFL:
                n = scene.polygon_normal[q]
                assert np.abs(dout - (din - 2 * (din @ n) * n)).max() <= ang_tol, (i, j, "law of reflection")
                assert abs(n @ p - scene.polygon_offset[q]) <= tol * scene.diagonal, (i, j, "off the plane")
            else:
                w = dih.direction[q]
                assert abs(din @ w - dout @ w) <= ang_tol, (i, j, "Keller's cone", din @ w, dout @ w)
                t = (p - dih.origin[q]) @ w
                assert -tol * scene.diagonal <= t <= dih.length[q] + tol * scene.diagonal, (i, j, "off the segment")
                assert np.linalg.norm(np.cross(p - dih.origin[q], w)) <= tol * scene.diagonal, (i, j, "off the edge line")
            checked += 1
    return checked


def rotate_yz(v: np.ndarray, angle: float) -> np.ndarray:
    """Rotate a vector about the x axis by ``angle`` [rad] (the edges of the built-in
    half-plane and wedge lie on x)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([v[0], c * v[1] - s * v[2], s * v[1] + c * v[2]])


def yz(theta: float, r: float, x: float = 0.0) -> np.ndarray:
    """The point at distance ``r`` from the x axis in direction ``theta`` [rad] of the yz plane."""
    return np.array([x, r * np.cos(theta), r * np.sin(theta)])


def reported(fn, allow_on_face: bool = False):
    """Run ``fn``; return ``None`` if the engine *reported* the case (a WavepathsError or a
    WavepathsWarning, which the test configuration turns into an exception), else its value.

    Stress cases may legitimately be refused: "where a case cannot be handled, it is
    detected and reported, never silently wrong". With ``allow_on_face`` the report of an
    end point lying exactly on a face (the computation goes on, with the defined edge
    case) is let through, so that tests still check what is computed there.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", WavepathsWarning)
            if allow_on_face:
                warnings.filterwarnings("ignore", message=ON_FACE_MESSAGE, category=WavepathsWarning)
            return fn()
    except (WavepathsError, WavepathsWarning):
        return None


ON_FACE_MESSAGE = r".*lie exactly on a face"
NEAR_EDGE_MESSAGE = r".*lie within \S+ m of an edge, off its faces"


# ---- independent references -------------------------------------------------------------
def theta_phi_hat(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Spherical unit vectors of unit direction(s) ``d`` (..., 3), written out here."""
    t = np.arccos(np.clip(d[..., 2], -1, 1))
    p = np.arctan2(d[..., 1], d[..., 0])
    th = np.stack([np.cos(t) * np.cos(p), np.cos(t) * np.sin(p), -np.sin(t)], axis=-1)
    ph = np.stack([-np.sin(p), np.cos(p), np.zeros_like(p)], axis=-1)
    return th, ph


def pec_plane_two_ray(tx: np.ndarray, rx: np.ndarray, pol: str, frequency_hz: float) -> complex:
    """Image theory for isotropic antennas over the PEC plane z = 0 (an exact reference).

    The reflected field of a perfect conductor is ``E_r(x) = -S E_i(S x)`` with
    ``S = diag(1, 1, -1)`` (tangential E cancels on the plane), so the path coefficients are
    ``lambda / (4 pi r) C_rx^* . E`` for the direct ray and the image ray, phased by
    ``exp(-j k r)``; the antennas are isotropic with the ``theta_hat`` (V) or ``phi_hat`` (H)
    field.
    """
    lam = C0 / frequency_hz
    k = 2 * np.pi / lam
    S = np.diag([1.0, 1.0, -1.0])
    pick = 0 if pol == "V" else 1
    total = 0j
    # direct
    r1 = np.linalg.norm(rx - tx)
    d1 = (rx - tx) / r1
    e = theta_phi_hat(d1)[pick]
    total += lam / (4 * np.pi * r1) * (theta_phi_hat(-d1)[pick] @ e) * np.exp(-1j * k * r1)
    # image: departs toward the reflection point along S d2, arrives along d2
    img = S @ tx
    r2 = np.linalg.norm(rx - img)
    d2 = (rx - img) / r2
    e_dep = theta_phi_hat(S @ d2)[pick]
    e_arr = -S @ e_dep
    total += lam / (4 * np.pi * r2) * (theta_phi_hat(-d2)[pick] @ e_arr) * np.exp(-1j * k * r2)
    return total


def halfplane_scalar_total(scene, tx, rx_pts, pol: str, frequency_hz: float, edge: int, opts: TraceOptions):
    """Normalised scalar total field (soft: E_x, hard: H_x) of a point source, summed over
    the line of sight, reflections and the diffraction on ``edge``; for comparison with the
    exact half-plane plane-wave solution when the source is far away."""
    from wavepaths.em.polarization import spherical_unit_vectors

    p = trace(scene, tx, rx_pts, opts)
    keep = (p.depth == 0) | (p.interactions[:, 0] == REFL) | (p.primitive[:, 0] == edge)
    p = p.select(keep)
    cfg = FieldConfig(frequency_hz=frequency_hz)
    T = transfer_matrices(scene, p, cfg)
    x = np.array([1.0, 0, 0])
    k = cfg.wavenumber
    dep = spherical_unit_vectors(p.departure_directions)
    arr = spherical_unit_vectors(p.arrival_directions)
    out = np.zeros(len(rx_pts), complex)
    for i in range(len(p)):
        d = p.departure_directions[i]
        e0 = x if pol == "soft" else np.cross(x, d)  # hard: H along the edge
        c = np.array([e0 @ dep.theta_hat[i], e0 @ dep.phi_hat[i]])
        ev = T[i] @ c
        E = ev[0] * arr.theta_hat[i] + ev[1] * arr.phi_hat[i]
        u = E[0] if pol == "soft" else np.cross(p.arrival_directions[i], E)[0]
        out[p.rx_index[i]] += u * np.exp(-1j * k * p.lengths[i])
    s_prime = np.linalg.norm(tx[0])
    return out / (cfg.wavelength / (4 * np.pi * s_prime) * np.exp(-1j * k * s_prime))


def top_edge(scene) -> int:
    """The dihedron of the built-in half-plane / wedge lying on the x axis."""
    d = scene.dihedra
    score = np.abs(d.origin[:, 1]) + np.abs(d.origin[:, 2]) + np.abs(d.direction[:, 1]) + np.abs(d.direction[:, 2])
    return int(np.argmin(score))
