"""The wedge_awning boundary line: an edge of three faces from two objects, judged by an exact
solution (no Sionna RT needed).

A metal awning, another object, is hinged on the wedge's edge 210 degrees from its lit face.
The receivers lie in the sector between that face and the awning: a wedge of n = 7/6, whose
exact field is the eigenfunction series again. This is the arbiter of the three_face_edge
case's diffracted paths on its awning edge, which Sionna RT models with one object's wedge.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.exact import wedge_geometrical_optics, wedge_plane_wave
from wavepaths.scene import load_scene
from wavepaths.topology.sectors import sector_table
from wavepaths.validation.lines import DIFFRACTED, boundary_line, diffracted_errors, line_errors


@pytest.fixture(scope="module")
def awning_line(tmp_path_factory):
    return boundary_line("wedge_awning", str(tmp_path_factory.mktemp("awning")), with_sionna=False)


def test_the_awning_edge_is_one_dihedron_of_three_faces_from_two_objects():
    s = load_scene("wedge_awning")
    d = s.dihedra
    hinge = np.nonzero(d.face_count == 3)[0]
    assert len(hinge) == 1 and d.diffracting[hinge[0]]
    objects = s.triangle_object[d.face_triangle[d.faces(hinge[0])]]
    assert {s.object_names[o] for o in objects} == {"wedge", "awning"}
    # its sectors: the lit face to the awning (210 degrees, n = 7/6), the awning to the other face
    # (60), and between the wedge's two plates (90: open plates, not a solid)
    t = sector_table(d)
    np.testing.assert_allclose(np.sort(np.rad2deg(t.width[hinge[0]][: t.count[hinge[0]]])), [60, 90, 210], atol=1e-9)


def test_wavepaths_matches_the_exact_sector_on_the_awning_line(awning_line):
    line = awning_line
    n_rx = len(line.phi_deg)
    # both faces lit (the wedge's and the awning): no shadow boundary in the sector
    assert line.boundaries_deg == {"0-face reflection boundary": 120.0, "n-face reflection boundary": 180.0}
    for field in ("soft", "hard"):
        assert line.path_counts["wavepaths"][field]["D"] == n_rx  # one diffraction by the hinge each
    total, diffracted = line_errors(line), diffracted_errors(line)
    for field in ("soft", "hard"):
        # the validation report's tolerances (verdict.EXACT_TOLERANCES); measured 0.08-0.32 dB, 0.0054
        t = total[f"wavepaths UTD ({field})"]
        assert t["max_db"] < 0.5 and t["max_complex_error"] < 0.02, (field, t)
        # the diffracted paths alone against the series minus its geometrical optics: the
        # coefficient of the n = 7/6 sector (measured 0.0034-0.0045 dB, 3e-4)
        d = diffracted[f"wavepaths UTD ({field})"]
        assert d["receivers"] == n_rx and d["max_db"] < 0.05 and d["max_complex_error"] < 2e-3, (field, d)


def test_the_awning_line_tells_the_sector_from_one_objects_wedge(awning_line):
    """Not vacuous: the wedge of the block alone (n = 1.5, the awning ignored) diffracts
    differently in the same sector, by more than the tolerance, at most receivers."""
    line = awning_line
    phi, pp = np.deg2rad(line.phi_deg), np.deg2rad(line.phi_prime_deg)
    for pol, field in (("H", "soft"), ("V", "hard")):
        sector = line.curves[("exact" + DIFFRACTED, pol)]
        block = wedge_plane_wave(line.k_rho, phi, pp, 1.5, field) - wedge_geometrical_optics(line.k_rho, phi, pp, 1.5, field)
        apart = np.abs(20 * np.log10(np.abs(block) / np.abs(sector)))
        assert np.mean(apart > 1.0) > 0.5 and apart.max() > 6.0, (field, np.median(apart), apart.max())
