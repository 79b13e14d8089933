"""Errors that wavepaths raises for bad input.

Every error a user can cause by a bad file, argument or position is a
:class:`WavepathsError` (or a subclass). The command line turns it into one line on
standard error and exit status 2, without a traceback.
"""

from __future__ import annotations


class WavepathsError(ValueError):
    """A user-facing error: bad input, with a message that names what was wrong."""


class SceneError(WavepathsError):
    """A scene file that cannot be loaded: missing, unknown format, bad geometry."""


class DependencyError(WavepathsError):
    """An optional dependency (Sionna RT, libLLVM, dask) that is missing or unusable."""


class ImageTreeTooLarge(WavepathsError):
    """An image tree that would hold more chains than the guard allows
    (:data:`wavepaths.search.images.MAX_IMAGES`)."""
