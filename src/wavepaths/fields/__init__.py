"""Fields: complex path coefficients from path geometry, materials, antennas."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

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

    Raises
    ------
    WavepathsError
        Arguments of the wrong type, or paths traced in another scene (their
        ``scene_fingerprint``, or primitives that are no polygons or dihedra of ``scene``).
    """
    cfg = FieldConfig() if config is None else config
    check_field_arguments(scene, paths, cfg)
    a, e = coefficients_and_fields(scene, paths, cfg)
    _warn_near_field(paths, cfg)
    _warn_gtd_on_boundaries(paths, a, cfg)
    return FieldResult(paths, a, cfg.frequency_hz, cfg.tx_power_dbm, incident_field=e)


def check_field_arguments(scene: "Scene", paths: "Paths", cfg: FieldConfig) -> None:
    """The checks of :func:`compute_fields`: the types, and that ``paths`` belong to ``scene``
    (fields of paths traced in another scene are numbers without meaning, and a review got
    one 0.7 dB off with no error)."""
    from ..errors import WavepathsError
    from ..scene.model import Scene
    from ..search.paths import InteractionType, Paths

    for name, value, kind in (("scene", scene, Scene), ("paths", paths, Paths), ("config", cfg, FieldConfig)):
        if not isinstance(value, kind):
            raise WavepathsError(f"`{name}` must be a {kind.__name__}, got {type(value).__name__}")
    if paths.scene_fingerprint and paths.scene_fingerprint != scene.geometry_fingerprint:
        raise WavepathsError("`paths` were traced in another scene (or another version of this one) than `scene`")
    if not len(paths):
        return
    refl = paths.interactions == InteractionType.REFLECTION
    diff = paths.interactions == InteractionType.DIFFRACTION
    bad = bool((refl & (paths.primitive >= scene.num_polygons)).any())
    if not bad and diff.any():  # (the dihedra are built only for paths that diffract)
        dih = scene.dihedra
        bad = bool((diff & (paths.primitive >= len(dih.direction))).any() or
                   (paths.wedge_faces >= len(dih.face_direction)).any())
    if bad:
        raise WavepathsError("`paths` name polygons or dihedra that `scene` does not have: they were traced in "
                             "another scene")


GTD_EXCESS_DB = 60.0  # a GTD path this far above free space at its length lies on a boundary


def _warn_gtd_on_boundaries(paths: "Paths", a, cfg: FieldConfig) -> None:
    """A :class:`~wavepaths.scene.WavepathsWarning` when Keller's GTD (``model="gtd"``) gives a
    diffracted path more than :data:`GTD_EXCESS_DB` above free space at its length: its
    coefficient diverges on the shadow and reflection boundaries (:func:`wavepaths.em.gtd.keller_coefficients`
    floors the denominator), where such a receiver lies. A review found the README's receiver
    (exactly on a reflection boundary) reported at +57 dB without a word."""
    import warnings

    from ..scene.model import WavepathsWarning, external_stacklevel

    if cfg.model != "gtd" or len(paths) == 0:
        return
    gain = np.abs(np.asarray(a)).reshape(len(paths), -1).max(axis=1)
    free_space = cfg.wavelength / (4 * np.pi * paths.lengths)
    wild = gain > free_space * 10 ** (GTD_EXCESS_DB / 20)
    if wild.any():
        warnings.warn(
            f"{int(wild.sum())} diffracted path(s) lie on a shadow or reflection boundary, where Keller's GTD "
            f"diverges: their gain is over {GTD_EXCESS_DB:g} dB above free space (up to "
            f"{20 * np.log10(gain[wild].max()):+.1f} dB) and not physical; the UTD (the default model) is finite there",
            WavepathsWarning, stacklevel=external_stacklevel(),
        )


def _warn_near_field(paths: "Paths", cfg: FieldConfig) -> None:
    """A :class:`~wavepaths.scene.WavepathsWarning` for paths shorter than a wavelength: ray
    optics (geometrical optics, UTD) is a far-field method, and there the path gain can
    exceed 0 dB (a receiver 1 mm from its transmitter at 3.5 GHz: +16.7 dB)."""
    import warnings

    from ..scene.model import WavepathsWarning, external_stacklevel

    if len(paths) == 0:
        return
    short = paths.lengths < cfg.wavelength
    if short.any():
        warnings.warn(
            f"{int(short.sum())} of {len(paths)} paths are shorter than a wavelength ({cfg.wavelength:.3g} m at "
            f"{cfg.frequency_hz:.4g} Hz; the shortest {paths.lengths[short].min():.3g} m): ray optics is a far-field "
            "method, and their coefficients (gains possibly above 0 dB) are not physical there",
            WavepathsWarning, stacklevel=external_stacklevel(),
        )


__all__ = ["FieldConfig", "FieldResult", "compute_fields", "path_coefficients", "transfer_matrices"]
