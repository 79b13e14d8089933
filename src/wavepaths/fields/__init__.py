"""Fields: complex path coefficients from path geometry, materials, antennas."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .chain import coefficients_and_fields, path_coefficients, transfer_matrices
from .config import FieldConfig
from .result import FieldResult

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from ..search.paths import Paths


def compute_fields(scene: "Scene", paths: "Paths", config: FieldConfig | None = None) -> FieldResult:
    """Complex coefficient of every path (see :mod:`wavepaths.fields.chain`).

    Parameters
    ----------
    scene : Scene
    paths : Paths
        From :func:`wavepaths.trace` on the same scene.
    config : FieldConfig, optional
        Frequency, diffraction model, antennas, transmit power (defaults: 3.5 GHz, UTD,
        isotropic vertically polarised antennas, 0 dBm).

    Returns
    -------
    FieldResult
    """
    cfg = config or FieldConfig()
    a, e = coefficients_and_fields(scene, paths, cfg)
    return FieldResult(paths, a, cfg.frequency_hz, cfg.tx_power_dbm, incident_field=e)


__all__ = ["FieldConfig", "FieldResult", "compute_fields", "path_coefficients", "transfer_matrices"]
