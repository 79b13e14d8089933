"""Optional compiled kernels (numba) for the field chain.

The numpy code of :mod:`wavepaths.fields.chain`, :mod:`wavepaths.em.fresnel` and
:mod:`wavepaths.em.utd` is the reference; the kernels in :mod:`wavepaths.fields._numba`
run the same formulas path by path, without the numpy temporaries (a UTD coefficient is
about 60 array operations per path in numpy). They cover reflections and the ``"utd"``
diffraction model without the Sionna compat mode; the other models run in numpy. They
agree with the reference to rounding (tests/fields/test_fields_compiled.py).

Used when numba is installed (the ``fast`` extra) and ``FieldConfig(compiled=True)`` (the
default). scipy's Faddeeva function is called from the compiled code through its C entry
point; :func:`available` checks it against scipy once per process and falls back to numpy
if it disagrees.
"""

from __future__ import annotations

import threading
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .config import FieldConfig


@lru_cache(maxsize=1)
def erfcx_address() -> int:
    """Address of scipy's complex ``erfcx`` (``scipy.special.cython_special``)."""
    from numba.extending import get_cython_function_address

    return int(get_cython_function_address("scipy.special.cython_special", "__pyx_fuse_0erfcx"))


@lru_cache(maxsize=1)
def available() -> bool:
    """Whether the compiled field kernels can run: numba is installed and the compiled call
    of scipy's ``erfcx`` returns scipy's values (checked once, on 64 points of the ray
    ``e^{j pi/4} sqrt(x)`` the UTD transition function uses, and off it)."""
    try:
        from . import _numba
    except ImportError:
        return False
    from scipy.special import erfcx

    x = np.geomspace(1e-10, 1e9, 48)
    z = np.concatenate([np.exp(0.25j * np.pi) * np.sqrt(x), np.linspace(-3, 3, 16) + 1j * np.linspace(2, -1, 16)])
    try:
        got = _numba.erfcx_array(np.uint64(erfcx_address()), z)
    except Exception:  # pragma: no cover - no C entry point on this build of scipy
        return False
    return bool(np.allclose(got, erfcx(z), rtol=1e-15, atol=0.0))


def use_compiled(cfg: "FieldConfig") -> bool:
    """Whether ``cfg``'s chain runs compiled (reflections always; diffraction for ``"utd"``
    without the Sionna compat mode)."""
    return cfg.compiled and available()


PARALLEL_MIN_ROWS = 1 << 11
"""Diffracted rows from which the diffraction kernel runs on numba's threads (about 2 ms of
work on one thread)."""


def parallel(rows: int) -> bool:
    """Whether a kernel call over ``rows`` paths should use numba's threads: enough rows,
    more than one thread (1 in the coverage pool's workers), and the main thread (numba's
    default threading layer must not be entered from two threads at once, see
    :func:`wavepaths.search.kernels.receiver_pairs`)."""
    if rows < PARALLEL_MIN_ROWS or threading.current_thread() is not threading.main_thread():
        return False
    import numba

    return int(numba.get_num_threads()) > 1


def material_tables(scene: "Scene", cfg: "FieldConfig", used: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per material of ``scene.materials``: kind code (int64), complex relative permittivity
    at ``cfg.frequency_hz`` and thickness in wavelengths. Only the materials ``used`` (indices)
    are evaluated (a material's permittivity raises outside its frequency range, as the
    numpy chain does when it meets it); the others keep ``eta = 1`` and are never read."""
    from ..em.materials import relative_permittivity
    from . import _numba

    codes = {"pec": _numba.KIND_PEC, "absorber": _numba.KIND_ABSORBER}
    m = len(scene.materials)
    kinds = np.zeros(m, np.int64)
    etas = np.ones(m, np.complex128)
    thick = np.zeros(m, np.float64)
    # a material's row depends on the material and the frequency only: kept on the scene (as
    # its dihedra are), keyed by the (frozen) material, so a coverage map's tiles compute it once

    def row(mat) -> tuple:
        kind = codes.get(mat.kind, _numba.KIND_DIELECTRIC)
        if kind == _numba.KIND_DIELECTRIC:
            return kind, complex(relative_permittivity(mat, cfg.frequency_hz)), float(mat.thickness_m) / cfg.wavelength
        return kind, 1.0 + 0j, 0.0

    for i in np.flatnonzero(np.bincount(used, minlength=m)).tolist():  # np.unique's materials, without its sort
        mat = scene.materials[i]
        kinds[i], etas[i], thick[i] = scene.memo(("material_row", mat, cfg.frequency_hz), lambda: row(mat))
    return kinds, etas, thick


def warm_up() -> bool:
    """Compile the field kernels now (numba caches them: once per machine), on a few paths
    of the built-in street canyon. ``scripts/setup.sh`` calls it. Returns :func:`available`."""
    if not available():
        return False
    from ..scene import load_scene
    from ..search import TraceOptions, trace
    from . import compute_fields
    from .config import FieldConfig

    scene = load_scene("street_canyon")
    rx = np.array([[20.0, 0.0, 1.5], [60.0, 5.0, 1.5], [-20.0, 30.0, 1.5]])
    paths = trace(scene, np.array([[-60.0, 0.0, 10.0]]), rx, TraceOptions(max_reflections=1, diffraction=True))
    global PARALLEL_MIN_ROWS
    saved = PARALLEL_MIN_ROWS
    try:
        for rows in (saved, 1):  # the one-pass chain serial, then on numba's threads
            PARALLEL_MIN_ROWS = rows
            for model in ("slab", "half_space"):
                compute_fields(scene, paths, FieldConfig(reflection_model=model))
    finally:
        PARALLEL_MIN_ROWS = saved
    # the threaded diffraction kernel, with the argument types _diffract_compiled passes
    from . import _numba

    z, v = np.zeros(1), np.array([[0.0, 0.0, 1.0]])
    for slab in (True, False):
        _numba.diffract_parallel(np.uint64(erfcx_address()), np.ones((1, 1, 3), np.complex128), v, v, v, v, v, z, z,
                                 z + 1.0, z + 1.5, z + 1.0, 1.0, 1e-6, np.zeros(1, np.int64), np.zeros(1, np.int64),
                                 np.ones(1, np.int64), np.ones(1, np.complex128), z, slab)
    return True
