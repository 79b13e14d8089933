"""Known disagreement 'sionna-free-edge-collapses-to-flat' (validation/known.py): who matches the exact solution.

A metal screen with the corners of etoile_crop's element_015 wall (top edge at z = 15 m, vertices
tens of metres from the origin). Sionna RT 2.2 orients a wedge's normals by the side of the other
face's centroid with a float32 margin; on a free edge the other face is the triangle itself, and
float32 rounding flips one normal: its wedge becomes flat (n = 1) and the diffracted field
vanishes. Sommerfeld's exact half-plane solution decides: wavepaths matches it, Sionna's |a| is
zero to float32 precision.

The exact reference takes nothing from the engine: its angles phi, phi', beta_0, the diffraction
point and the distances s', s come from the screen's construction (edge P0 -> P1, face below the
edge, normal N) and the explicit TX and RX positions (:func:`reference_geometry`), not from
``wedge_geometry`` or the traced path, so an error in the engine's angles or path vertices cannot
enter both sides of the comparison.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.em.antennas import Antenna
from wavepaths.em.materials import itu_material
from wavepaths.em.utd import kp_coefficients
from wavepaths.exact import halfplane_plane_wave, utd_wedge_total_field
from wavepaths.fields import FieldConfig, compute_fields
from wavepaths.fields.chain import wedge_geometry
from wavepaths.scene import build_scene, load_scene, write_mitsuba_xml
from wavepaths.scene.builtin import SceneBuilder
from wavepaths.search import TraceOptions, trace
from wavepaths.validation.compare import compare_paths
from wavepaths.validation.known import KNOWN_DISAGREEMENTS
from wavepaths.validation.disagreements import _sionna_collapsed_free_edge

pytestmark = pytest.mark.sionna

FREQ = 3.5e9
K = 2 * np.pi * FREQ / 299_792_458.0
P0, P1 = np.array([11.606341, -68.425201, 15.0]), np.array([35.922268, -80.158165, 15.0])  # element_015's wall top
T = (P1 - P0) / np.linalg.norm(P1 - P0)
N = np.cross([0.0, 0.0, 1.0], T)
M = 0.5 * (P0 + P1)
TX = (M + 30 * N + [0, 0, 12.0])[None]
# in the plane perpendicular to the edge through its midpoint (beta_0 = 90 deg), in front of the
# screen below the edge, on the transmitter's side (behind the screen Sionna's flat wedge finds no
# path at all: those receivers are only in wavepaths' output)
RX = np.stack([M + 20 * N + [0, 0, -10.0], M + 35 * N + [0, 0, -5.0], M + 12 * N + [0, 0, -13.0]])


def reference_geometry(tx: np.ndarray, rx: np.ndarray) -> dict:
    """The diffraction at the screen's top edge from the scene's construction alone.

    Edge unit vector e = T (P0 -> P1). The screen hangs below the edge: from the edge into the
    face is t0 = -z, and its normal on the transmitter's side is n0 = N = z x T; (t0, n0, e) is
    right-handed ((-z) x (z x T) = T), so this face is the 0-face of docs/conventions.md and
    angles are measured about e from t0 toward n0, in the plane perpendicular to the edge. (For a
    half-plane the other labelling maps (phi, phi') to (2 pi - phi, 2 pi - phi'), which leaves
    Sommerfeld's solution unchanged.) The diffraction point Q is the point of the edge's line where
    the unfolded path TX -> Q -> RX is straight (Keller's law).
    """
    e, t0, n0 = T, np.array([0.0, 0.0, -1.0]), N

    def along_and_radial(p):
        t = float((p - P0) @ e)
        return t, float(np.linalg.norm(p - P0 - t * e))

    (t_tx, r_tx), (t_rx, r_rx) = along_and_radial(tx), along_and_radial(rx)
    q = P0 + (t_tx * r_rx + t_rx * r_tx) / (r_tx + r_rx) * e

    def angle(p):
        v = p - q
        return float(np.mod(np.arctan2(v @ n0, v @ t0), 2 * np.pi))

    s_in, s_out = float(np.linalg.norm(q - tx)), float(np.linalg.norm(rx - q))
    beta_0 = float(np.arccos(np.clip((q - tx) @ e / s_in, -1.0, 1.0)))
    return {"q": q, "phi_prime": angle(tx), "phi": angle(rx), "beta_0": beta_0, "s_in": s_in, "s_out": s_out}


def exact_soft_halfplane(k_l: float, phi: float, phi_prime: float) -> complex:
    """Sommerfeld's exact diffraction coefficient (soft, broadside, units 1/k): exact total field
    minus geometrical optics, times sqrt(L) exp(jkL), at k rho = k L."""
    u = halfplane_plane_wave(k_l, phi, phi_prime, "soft")
    d_kp = kp_coefficients(phi, phi_prime, np.pi / 2, 2.0, 1.0, k_l).d_s
    go = utd_wedge_total_field(k_l, phi, phi_prime, 2.0, "soft") - d_kp * np.exp(-1j * k_l) / np.sqrt(k_l)
    return complex((u - go) * np.sqrt(k_l) * np.exp(1j * k_l))


def test_known_disagreement_is_listed():
    ids = {k["id"]: k for k in KNOWN_DISAGREEMENTS}
    assert ids["sionna-free-edge-collapses-to-flat"]["who_matches_exact"].startswith("wavepaths")


def test_sionna_diffraction_vanishes_on_a_free_edge_where_sommerfeld_does_not(tmp_path):
    from wavepaths.errors import DependencyError
    from wavepaths.validation.sionna_env import ensure_sionna
    from wavepaths.validation.sionna_runner import run_sionna_paths

    try:
        ensure_sionna()
    except DependencyError as exc:  # pragma: no cover - CI installs Sionna RT
        pytest.skip(f"Sionna RT is not usable here: {exc}")

    b = SceneBuilder()
    b.add_quad("screen", itu_material("metal"), [P0, P1, P1 - [0, 0, 15.0], P0 - [0, 0, 15.0]])
    xml = str(tmp_path / "screen.xml")
    write_mitsuba_xml(build_scene(*b.arrays(), source="element_015 wall as a screen"), xml)
    scene = load_scene(xml)

    ant = Antenna("iso", "H")  # E horizontal, along the edge: the soft polarisation
    paths = trace(scene, TX, RX, TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0))
    a_compat = compute_fields(scene, paths, FieldConfig(FREQ, "utd", "sionna", tx_antenna=ant, rx_antenna=ant)).a
    a_utd = compute_fields(scene, paths, FieldConfig(FREQ, "utd", tx_antenna=ant, rx_antenna=ant)).a
    sn = run_sionna_paths(xml, TX, RX, frequency_hz=FREQ, max_depth=1, diffraction=True, edge_diffraction=True,
                          tx_antenna=("iso", "H"), rx_antenna=("iso", "H"))
    comp = compare_paths(paths, a_compat, sn)
    top = [m for m in comp.matches if m.kinds == "D"
           and abs(paths.vertices[m.wp_index, 1, 2] - 15.0) < 1e-6]  # diffracted on the top edge
    assert sorted(m.rx for m in top) == [0, 1, 2]
    lam = 299_792_458.0 / FREQ

    def db(x):
        return 20 * np.log10(max(abs(x), 1e-300))

    for m in top:
        i, j = m.wp_index, m.sn_index
        # the reference's geometry, from the scene's construction (not from the engine)
        ref = reference_geometry(TX[0], RX[m.rx])
        assert abs(ref["beta_0"] - np.pi / 2) < 1e-9  # TX and RX lie in the plane through M normal to the edge
        assert 0.0 < ref["phi"] < 2 * np.pi and 0.0 < ref["phi_prime"] < 2 * np.pi
        s_in, s_out = ref["s_in"], ref["s_out"]
        k_l = K * s_in * s_out / (s_in + s_out) * np.sin(ref["beta_0"]) ** 2
        d = exact_soft_halfplane(k_l, ref["phi"], ref["phi_prime"]) / np.sqrt(K)
        a_exact = lam / (4 * np.pi) * abs(d) / np.sqrt(s_in * s_out * (s_in + s_out))
        # wavepaths matches Sommerfeld (UTD is exact for the half-plane; ITU metal, Luebbers): 0.1 dB
        assert abs(db(a_utd[i]) - db(a_exact)) < 0.1
        # (separately) the engine's wedge is the screen's half-plane, diffracting at Q
        g = wedge_geometry(scene, paths, np.array([i]), 0)
        assert abs(g["n"][0] - 2.0) < 1e-12 and abs(g["beta_0"][0] - np.pi / 2) < 1e-6
        assert np.linalg.norm(paths.vertices[i, 1] - ref["q"]) < 1e-6
        # Sionna's coefficient is zero to float32 precision: at least 60 dB below the exact one
        assert db(sn.a[j]) < db(a_exact) - 60.0
        # and the validation report counts the pair as this known disagreement, not as a violation
        assert _sionna_collapsed_free_edge(scene, paths, m, sn, a_compat)
