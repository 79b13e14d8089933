"""Exact reference solutions (oracles) for the diffraction engine and its tests.

* :func:`halfplane_plane_wave` -- Sommerfeld's PEC half-plane, plane-wave incidence.
* :func:`wedge_plane_wave` -- Macdonald's eigenfunction series for a PEC wedge.
* :func:`utd_wedge_total_field` -- the GO + UTD/GTD/Sionna-compat counterpart.
* :func:`wedge_geometrical_optics` -- its GO part alone (exact minus it: the diffracted field).
* :func:`knife_edge_loss_db`, :func:`knife_edge_field`, :func:`fresnel_nu` -- ITU-R P.526
  single knife edge (Fresnel-Kirchhoff, absorbing screen).
"""

from wavepaths.exact.halfplane import halfplane_plane_wave
from wavepaths.exact.knife_edge import fresnel_nu, knife_edge_field, knife_edge_loss_db
from wavepaths.exact.wedge import utd_wedge_total_field, wedge_geometrical_optics, wedge_plane_wave

__all__ = [
    "fresnel_nu",
    "halfplane_plane_wave",
    "knife_edge_field",
    "knife_edge_loss_db",
    "utd_wedge_total_field",
    "wedge_geometrical_optics",
    "wedge_plane_wave",
]
