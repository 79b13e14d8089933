"""Receiver lines across shadow and reflection boundaries, against exact solutions.

A transmitter far away (``S_PRIME`` metres) approximates a plane wave at a half-plane or
a 90-degree wedge whose edge lies on the x axis; receivers sit on a circle of radius
``rho`` around the edge. The normalised total field ``u`` (incident field at the edge = 1)
of each engine is compared with Sommerfeld's half-plane solution and the wedge
eigenfunction series.

Both engines' antennas are Sionna's isotropic "V" / "H"; the physical soft and hard
fields are recovered from the path coefficients with the geometric signs of the
antenna bases (all rays travel in the y-z plane, perpendicular to the edge):

* soft (E along the edge): ``u = sum a_HH (x.phi_hat(k_dep)) (x.phi_hat(-k_arr)) e^{-jkl}``;
* hard (H along the edge): ``u = -sum a_VV (x.phi_hat(k_dep)) (x.phi_hat(-k_arr)) e^{-jkl}``;

both divided by ``lambda / (4 pi s') e^{-jks'}``, the incident field at the edge.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..em.antennas import Antenna
from ..em.polarization import spherical_unit_vectors
from ..exact.halfplane import halfplane_plane_wave
from ..exact.wedge import wedge_geometrical_optics, wedge_plane_wave
from ..fields import FieldConfig, compute_fields
from ..scene import load_scene, write_mitsuba_xml
from ..scene.builtin import AWNING_DEG
from ..search import TraceOptions, trace
from ..em.constants import SPEED_OF_LIGHT  # noqa: F401 (re-exported)

S_PRIME = 10_000.0  # plane-wave approximation: curvature error k rho^2 / 2 s' ~ 4e-3
LINE_SAMPLES = 1_000_000  # Sionna's samples per source on the lines
# the full report's: from 10 km Sionna's samples barely reach the wedges' faces; with 1e6 it keeps
# none of the wedge line's 133 diffracted paths, with 1e7 all of them (about 80 s per polarisation)
LINE_SAMPLES_FULL = {"half_plane": 1_000_000, "wedge": 10_000_000, "wedge_awning": 10_000_000}
# the lines of the report, each with an exact solution
LINES = ("half_plane", "wedge", "wedge_awning")
# suffix of a curve label for the field of an engine's diffracted paths alone, and of the exact
# solution minus its geometrical optics (:func:`~wavepaths.exact.wedge.wedge_geometrical_optics`)
DIFFRACTED = " diffracted"


@dataclass
class BoundaryLine:
    """|u| in dB along the circle, per engine and polarisation."""

    name: str
    phi_deg: np.ndarray
    phi_prime_deg: float
    k_rho: float
    curves: dict  # (label, polarization) -> (k,) complex u
    boundaries_deg: dict
    # engine -> field ("soft"/"hard") -> {"LOS", "R", "D"} paths kept on the line: an engine
    # that misses a mechanism's paths is off the exact solution for that reason
    path_counts: dict = field(default_factory=dict)
    # field -> {"rms_rad", "max_rad", "paths"}: k (c tau - l) of Sionna's kept paths, its float32
    # delay against the float64 length of its own polyline (10 km of path: a phase floor), and
    # "utd_with_these_delays": {"max_db", "max_complex_error"} of wavepaths' UTD against the exact
    # solution with its own delays rounded to float32 (the floor's effect on a correct model)
    sionna_delay_phase: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)  # what a reader needs to recompute the line


def _u(geometry_dirs, a, lengths, rx_index, n_rx, k, polarization, s_prime):
    """Normalised soft/hard field from single-port coefficients (see module docstring)."""
    x = np.array([1.0, 0.0, 0.0])
    out = np.zeros(n_rx, complex)
    dep, arr = geometry_dirs
    s_tx = spherical_unit_vectors(dep).phi_hat @ x
    s_rx = spherical_unit_vectors(-arr).phi_hat @ x
    sign = 1.0 if polarization == "H" else -1.0
    np.add.at(out, rx_index, sign * a * s_tx * s_rx * np.exp(-1j * k * lengths))
    lam = 2 * np.pi / k
    return out / (lam / (4 * np.pi * s_prime) * np.exp(-1j * k * s_prime))


def _mechanism_counts(depth: np.ndarray, interactions: np.ndarray) -> dict:
    """``{"LOS", "R", "D"}``: how many of the kept paths (depth <= 1) are of each kind."""
    first = np.where(depth > 0, interactions[:, 0], 0)
    return {"LOS": int((depth == 0).sum()), "R": int(((depth > 0) & (first == 1)).sum()),
            "D": int(((depth > 0) & (first == 2)).sum())}


def _diffracted(depth: np.ndarray, interactions: np.ndarray) -> np.ndarray:
    """(N,) bool: the kept paths that are one diffraction by the edge (the line keeps no other)."""
    return (depth == 1) & (interactions[:, 0] == 2)


def _polyline_lengths(v: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(N,) float64 length of each path's polyline ``v`` (N, D + 2, 3), its ``depth + 1`` segments."""
    seg = np.linalg.norm(np.diff(v, axis=1), axis=2)
    used = np.arange(seg.shape[1])[None, :] <= depth[:, None]
    return np.where(used, np.nan_to_num(seg), 0.0).sum(axis=1)


def _geometry(scene_name: str):
    if scene_name == "half_plane":
        # face direction -z from the edge; angles from -z toward +y
        to_xyz = lambda phi: np.stack([np.zeros_like(phi), np.sin(phi), -np.cos(phi)], axis=-1)
        return to_xyz, 2.0, 60.0
    # wavepaths' wedge: 0-face along -z, n-face along -y, exterior from -z through +y, +z to -y
    to_xyz = lambda phi: np.stack([np.zeros_like(phi), np.sin(phi), -np.cos(phi)], axis=-1)
    if scene_name == "wedge_awning":
        # the sector from the 0-face to the awning (another object on the same edge), n = 7/6; the
        # source lights both, as three_face_edge's transmitter lights the roof and the awning
        return to_xyz, AWNING_DEG / 180.0, 60.0
    return to_xyz, 1.5, 100.0


def _keep_edge(vertices, depth, interactions, edge_is_diff):
    """Paths that are LOS, reflections, or diffracted on the x-axis edge."""
    keep = np.ones(len(depth), dtype=bool)
    for i in range(len(depth)):
        for j in range(depth[i]):
            if interactions[i, j] == 2:
                v = vertices[i, j + 1]
                keep[i] &= edge_is_diff(v)
    return keep


def boundary_line(scene_name: str, out_dir: str, frequency_hz: float = 3.5e9, rho: float = 1.0,
                  with_sionna: bool = True, samples: int = LINE_SAMPLES) -> BoundaryLine:
    """Compute the normalised total field along the circle for every engine available.

    ``scene_name`` is one of :data:`LINES`; ``samples`` is Sionna's number of samples per source.
    Besides each engine's total field, the curves hold the field of its diffracted paths alone
    (label + :data:`DIFFRACTED`) and the exact solution minus its geometrical optics
    (:func:`diffracted_errors`).
    """
    import os

    scene = load_scene(scene_name)
    xml = os.path.join(out_dir, "scenes", scene_name, f"{scene_name}.xml")
    os.makedirs(os.path.dirname(xml), exist_ok=True)
    write_mitsuba_xml(scene, xml)
    to_xyz, n, phi_p_deg = _geometry(scene_name)
    k = 2 * np.pi * frequency_hz / SPEED_OF_LIGHT
    phi_deg = np.arange(1.0, n * 180 - 0.5, 2.0)  # odd degrees: never exactly on a boundary
    phi_deg = phi_deg[np.abs(phi_deg - phi_p_deg) > 1]
    tx = S_PRIME * to_xyz(np.deg2rad(np.array([phi_p_deg])))
    rx = rho * to_xyz(np.deg2rad(phi_deg))
    on_edge = lambda v: abs(v[1]) < 1e-3 and abs(v[2]) < 1e-3
    curves = {}
    p = trace(scene, tx, rx, TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=0))
    p = p.select(_keep_edge(p.vertices, p.depth, p.interactions, on_edge))
    counts: dict = {}
    delay_phase: dict = {}
    float32_delays: dict = {}
    for pol in ("V", "H"):
        ant = Antenna("iso", pol)
        counts.setdefault("wavepaths", {})[FIELD_OF_POLARIZATION[pol]] = _mechanism_counts(p.depth, p.interactions)
        for label, cfg in (("wavepaths UTD", FieldConfig(frequency_hz, "utd", tx_antenna=ant, rx_antenna=ant)),
                           ("wavepaths GTD", FieldConfig(frequency_hz, "gtd", tx_antenna=ant, rx_antenna=ant)),
                           ("wavepaths compat=sionna", FieldConfig(frequency_hz, "utd", "sionna", tx_antenna=ant, rx_antenna=ant))):
            r = compute_fields(scene, p, cfg)
            curves[(label, pol)] = _u((p.departure_directions, p.arrival_directions), r.a, p.lengths,
                                      p.rx_index, len(rx), k, pol, S_PRIME)
            d = _diffracted(p.depth, p.interactions)
            curves[(label + DIFFRACTED, pol)] = _u((p.departure_directions[d], p.arrival_directions[d]),
                                                   r.a[d], p.lengths[d], p.rx_index[d], len(rx), k, pol, S_PRIME)
            if label == "wavepaths UTD":  # the same UTD with its delays rounded as Sionna's are (float32)
                rounded = np.float32(p.lengths / SPEED_OF_LIGHT).astype(np.float64) * SPEED_OF_LIGHT
                float32_delays[pol] = _u((p.departure_directions, p.arrival_directions), r.a, rounded,
                                         p.rx_index, len(rx), k, pol, S_PRIME)
        if with_sionna:
            from .sionna_runner import run_sionna_paths

            sn = run_sionna_paths(xml, tx, rx, frequency_hz=frequency_hz, max_depth=1, diffraction=True,
                                  edge_diffraction=True, samples_per_src=samples, tx_antenna=("iso", pol),
                                  rx_antenna=("iso", pol))
            depth = sn.num_interactions
            keep = _keep_edge(sn.vertices, depth, sn.interactions, on_edge)
            v = sn.vertices[keep]
            d = depth[keep]
            rows = np.arange(len(v))
            dep = v[:, 1] - v[:, 0]
            arr = v[rows, d + 1] - v[rows, d]
            dep /= np.linalg.norm(dep, axis=1, keepdims=True)
            arr /= np.linalg.norm(arr, axis=1, keepdims=True)
            curves[("Sionna RT", pol)] = _u((dep, arr), sn.a[keep], sn.tau[keep] * SPEED_OF_LIGHT,
                                            sn.rx_index[keep], len(rx), k, pol, S_PRIME)
            dd = _diffracted(d, sn.interactions[keep])
            curves[("Sionna RT" + DIFFRACTED, pol)] = _u((dep[dd], arr[dd]), sn.a[keep][dd],
                                                         sn.tau[keep][dd] * SPEED_OF_LIGHT, sn.rx_index[keep][dd],
                                                         len(rx), k, pol, S_PRIME)
            counts.setdefault("Sionna RT", {})[FIELD_OF_POLARIZATION[pol]] = _mechanism_counts(
                d, sn.interactions[keep])
            err = k * (sn.tau[keep] * SPEED_OF_LIGHT - _polyline_lengths(v, d))
            delay_phase.setdefault(FIELD_OF_POLARIZATION[pol], {}).update({
                "rms_rad": float(np.sqrt(np.mean(err**2))) if len(err) else None,
                "max_rad": float(np.max(np.abs(err))) if len(err) else None, "paths": int(len(err))})
        soft_hard = "soft" if pol == "H" else "hard"
        phi = np.deg2rad(phi_deg)
        if n == 2.0:
            curves[("exact", pol)] = halfplane_plane_wave(k * rho, phi, np.deg2rad(phi_p_deg), soft_hard)
        else:
            curves[("exact", pol)] = wedge_plane_wave(k * rho, phi, np.deg2rad(phi_p_deg), n, soft_hard)
        ref = curves[("exact", pol)]
        curves[("exact" + DIFFRACTED, pol)] = ref - wedge_geometrical_optics(k * rho, phi, np.deg2rad(phi_p_deg), n,
                                                                            soft_hard)
        u32 = float32_delays[pol]
        d32 = 20 * np.log10(np.maximum(np.abs(u32), 1e-12) / np.maximum(np.abs(ref), 1e-12))
        delay_phase.setdefault(soft_hard, {})["utd_with_these_delays"] = {
            "max_db": float(np.max(np.abs(d32[np.abs(ref) > 0.05]))), "max_complex_error": float(np.max(np.abs(u32 - ref)))}
    candidates = {"shadow boundary": phi_p_deg + 180.0 if phi_p_deg < 180 else phi_p_deg - 180.0,
                  "0-face reflection boundary": 180.0 - phi_p_deg,
                  "n-face reflection boundary": (2 * n - 1) * 180 - phi_p_deg}
    bounds = {k: round(v, 9) for k, v in candidates.items() if 0 < v < n * 180}
    settings = {"scene": scene_name, "material": ", ".join(sorted({m.name for m in scene.materials})),
                "frequency_hz": frequency_hz, "rho_m": rho,
                "source_distance_m": S_PRIME, "phi_prime_deg": phi_p_deg, "phi_step_deg": 2.0,
                "tx": tx[0].tolist(), "sionna_max_depth": 1, "sionna_samples_per_src": samples,
                "kept": "line of sight, one reflection and the diffraction by the edge on the x axis",
                "antennas": "isotropic, both ends: H gives the soft field, V the hard one"}
    return BoundaryLine(scene_name, phi_deg, phi_p_deg, k * rho, curves, bounds, counts, delay_phase, settings)


# the antenna polarisation of a line's curves and the physical field it gives (module docstring)
FIELD_OF_POLARIZATION = {"H": "soft", "V": "hard"}


def curve_key(label: str, polarization: str) -> str:
    """The report's name of one curve: ``"wavepaths UTD (soft)"`` for ``("wavepaths UTD", "H")``."""
    return f"{label} ({FIELD_OF_POLARIZATION[polarization]})"


def line_errors(line: BoundaryLine) -> dict:
    """Largest and median |u| difference in dB from the exact solution, per engine and polarisation."""
    out = {}
    for (label, pol), u in line.curves.items():
        if label == "exact" or label.endswith(DIFFRACTED):
            continue
        ref = line.curves[("exact", pol)]
        d = 20 * np.log10(np.maximum(np.abs(u), 1e-12) / np.maximum(np.abs(ref), 1e-12))
        lit = np.abs(ref) > 0.05  # skip the deep nulls of the exact field
        out[curve_key(label, pol)] = {
            "max_db": float(np.max(np.abs(d[lit]))), "median_db": float(np.median(np.abs(d[lit]))),
            "max_complex_error": float(np.max(np.abs(u - ref))),
        }
    return out


def diffracted_errors(line: BoundaryLine) -> dict:
    """Each engine's diffracted paths alone against the exact solution minus its geometrical optics.

    The total field mixes every mechanism: an engine that misses reflections, or whose delays
    carry a phase floor, is off the exact solution whatever its diffraction coefficient. The
    exact diffracted field ``u_d = u_exact - u_GO`` (:func:`~wavepaths.exact.wedge.wedge_geometrical_optics`;
    discontinuous on the shadow and reflection boundaries, which no receiver touches) is
    compared with the sum of the engine's diffracted paths, at the receivers where it has one
    (``receivers``; ``receivers_without`` are left out, a missing path being a search matter).

    Returns
    -------
    dict
        :func:`curve_key` of the engine's label -> ``{"max_db", "median_db"}`` (|u_d| ratio in dB
        where ``|u_d| > 0.05``, or over all its receivers if none is), ``"max_complex_error"``
        (``|u_d - u_d,exact|``, incident field at the edge = 1), ``"receivers"``,
        ``"receivers_without"``; the errors are ``None`` when the engine has no diffracted path.
    """
    out = {}
    for (label, pol), u in line.curves.items():
        if not label.endswith(DIFFRACTED) or label == "exact" + DIFFRACTED:
            continue
        ref = line.curves[("exact" + DIFFRACTED, pol)]
        has = u != 0
        entry = {"receivers": int(has.sum()), "receivers_without": int((~has).sum()),
                 "max_db": None, "median_db": None, "max_complex_error": None}
        if has.any():
            d = np.abs(20 * np.log10(np.abs(u[has]) / np.maximum(np.abs(ref[has]), 1e-12)))
            strong = np.abs(ref[has]) > 0.05
            d = d[strong] if strong.any() else d
            entry.update(max_db=float(d.max()), median_db=float(np.median(d)),
                         max_complex_error=float(np.max(np.abs(u[has] - ref[has]))))
        out[curve_key(label[:-len(DIFFRACTED)], pol)] = entry
    return out


def line_summary(line: BoundaryLine) -> dict:
    """The JSON entry of one line: its errors (:func:`line_errors`) and everything its figure needs.

    ``curves`` maps :func:`curve_key` (``"exact (soft)"``, ``"Sionna RT (hard)"``, ...) to the
    complex ``u`` along the circle as two lists, ``{"re": (k,), "im": (k,)}``, one value per
    ``phi_deg``; :func:`curves_from_summary` reads them back.
    """
    return {"errors": line_errors(line), "diffracted_errors": diffracted_errors(line),
            "phi_deg": line.phi_deg.tolist(), "phi_prime_deg": float(line.phi_prime_deg),
            "boundaries_deg": {k: float(v) for k, v in line.boundaries_deg.items()}, "k_rho": float(line.k_rho),
            "path_counts": line.path_counts, "sionna_delay_phase_rad": line.sionna_delay_phase,
            "settings": line.settings,
            "curves": {curve_key(label, pol): {"re": np.real(u).tolist(), "im": np.imag(u).tolist()}
                       for (label, pol), u in line.curves.items()}}


def curves_from_summary(entry: dict) -> dict:
    """``(label, polarization) -> (k,) complex u`` from a :func:`line_summary` entry (as read from JSON).

    A ``null`` (a non-finite value, ``validation/json_io.py``) comes back as NaN.
    """
    out = {}
    for key, c in entry["curves"].items():
        label, field = key.rsplit(" (", 1)
        pol = {v: k for k, v in FIELD_OF_POLARIZATION.items()}[field.rstrip(")")]
        out[(label, pol)] = np.asarray(c["re"], dtype=float) + 1j * np.asarray(c["im"], dtype=float)
    return out
