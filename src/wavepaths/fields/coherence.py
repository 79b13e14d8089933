"""Partially polarised and unpolarised sources: coherence matrices along paths (seed §2.1).

The seed carries a ray's polarisation state as a 2x2 coherence matrix
``J = <E E^H>`` and propagates it through an interaction with matrix ``M`` as
``J_out = M J_in M^H``; for a diagonal, real ``M = diag(D_par, D_perp)`` this is its
formula ``[[J_xx D_par^2, J_xy D_par D_perp], [J_yx D_par D_perp, J_yy D_perp^2]]``
(:func:`wavepaths.em.polarization.seed_diffracted_coherence`). Here ``M`` is a whole
path's transfer matrix (:func:`wavepaths.fields.chain.transfer_matrices`), from the
(theta_hat, phi_hat) basis of the departure direction to that of the arrival direction.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..em.antennas import Antenna, antenna_field
from ..em.polarization import spherical_unit_vectors
from .chain import transfer_matrices
from .config import FieldConfig

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from ..search.paths import Paths


def received_coherence(scene: "Scene", paths: "Paths", config: FieldConfig, source: np.ndarray) -> np.ndarray:
    """Coherence matrix of each path's field at the receiver.

    Parameters
    ----------
    source : (2, 2) or (N, 2, 2) complex
        The transmitted wave's coherence matrix in the (theta_hat, phi_hat) basis of the
        departure direction (e.g. ``unpolarized_coherence()``), unit trace = unit power
        gain of an isotropic source.

    Returns
    -------
    (N, 2, 2) complex128
        ``T J T^H`` in the (theta_hat, phi_hat) basis of the arrival direction, in the
        normalisation of ``|a|^2`` (path gain).
    """
    t = transfer_matrices(scene, paths, config)
    j = np.broadcast_to(np.asarray(source, dtype=complex), (len(paths), 2, 2))
    return t @ j @ np.conj(np.swapaxes(t, 1, 2))


def received_power_gain(scene: "Scene", paths: "Paths", config: FieldConfig, source: np.ndarray,
                        rx_antenna: Antenna | None = None) -> np.ndarray:
    """(N,) path gain seen by a receive antenna (first port): ``c^H J_out c``.

    ``c`` holds the receive pattern's components on the arrival basis; the antenna defaults to
    ``config.rx_antenna``.
    """
    j_out = received_coherence(scene, paths, config, source)
    ant = rx_antenna or config.rx_antenna
    toward = -paths.arrival_directions
    c_rx = antenna_field(ant, toward)[:, 0]  # (N, 2) on theta_hat(-k), phi_hat(-k)
    b_to = spherical_unit_vectors(toward)
    b_arr = spherical_unit_vectors(paths.arrival_directions)
    vec = c_rx[:, 0:1] * b_to.theta_hat + c_rx[:, 1:2] * b_to.phi_hat  # (N, 3)
    c = np.stack([np.einsum("ij,ij->i", vec, b_arr.theta_hat), np.einsum("ij,ij->i", vec, b_arr.phi_hat)], axis=1)
    return np.real(np.einsum("ni,nij,nj->n", np.conj(c), j_out, c))
