"""Embree's C API through ctypes: a scene the compiled occlusion kernel can cast into.

embreex wraps Embree for Python: a call casts a batch of float32 rays and returns numpy
arrays. The occlusion of a segment needs one or two such rays, each checked in float64
between the calls, so on the Python side a query is several passes over fresh arrays
around two calls
(:meth:`wavepaths.raycast.embree.EmbreeRayCaster._halves_core`). :class:`DirectScene`
builds the same triangles into a scene of the Embree library embreex ships, and hands its
``rtcIntersect1`` entry point and scene handle to :func:`wavepaths.raycast._numba.occluded_direct`,
which casts the half-rays, reads the hits and decides them in one compiled pass per
segment (without the GIL, like embreex's calls).

The ray-hit record is Embree 4's ``RTCRayHit`` (``rtcore_ray.h``): the ray ``org_x, org_y,
org_z, tnear, dir_x, dir_y, dir_z, time, tfar`` (float32), ``mask, id, flags`` (uint32),
then the hit ``Ng_x, Ng_y, Ng_z, u, v`` (float32), ``primID, geomID, instID[1]`` (uint32)
and, in builds with instance arrays, ``instPrimID[1]``: 96 bytes at most, 16-byte aligned.
The rays are set as embreex sets them (``tnear = 0``, ``time = 0``, every mask bit,
``flags = 0``), on the same triangles (one vertex triple per triangle) in a scene with
the same flag (``RTC_SCENE_FLAG_ROBUST``), so a hit names the same triangle: the verdicts,
ray counts and float64 fallbacks of the two paths are equal (tested). :func:`direct_scene` returns ``None`` when the library cannot be found or
refuses the scene, and the caster keeps the embreex path.
"""

from __future__ import annotations

import ctypes
import glob
import os
import threading
import weakref
from functools import lru_cache

import numpy as np

RTC_GEOMETRY_TYPE_TRIANGLE = 0
RTC_BUFFER_TYPE_INDEX = 0
RTC_BUFFER_TYPE_VERTEX = 1
RTC_FORMAT_UINT3 = 0x5003
RTC_FORMAT_FLOAT3 = 0x9003
RTC_ERROR_NONE = 0
RTC_SCENE_FLAG_ROBUST = 1 << 2


def _candidates() -> list[str]:
    """Paths of the Embree 4 library: the one embreex ships (``embreex.libs``), then the system's."""
    out = []
    try:
        import embreex

        here = os.path.dirname(os.path.abspath(embreex.__file__))
        for folder in (os.path.join(here, os.pardir, "embreex.libs"), os.path.join(here, ".dylibs"), here):
            out += sorted(glob.glob(os.path.join(folder, "libembree4*.so*")))
            out += sorted(glob.glob(os.path.join(folder, "libembree4*.dylib"))) + sorted(glob.glob(os.path.join(folder, "embree4*.dll")))
    except ImportError:  # pragma: no cover - embreex is a dependency
        pass
    import ctypes.util

    found = ctypes.util.find_library("embree4")
    if found:
        out.append(found)
    return out


@lru_cache(maxsize=1)
def library() -> ctypes.CDLL | None:
    """The Embree 4 library with the signatures used here, or ``None``."""
    for path in _candidates():
        try:
            lib = ctypes.CDLL(path)
            lib.rtcIntersect1  # noqa: B018 - the entry point the kernel calls
        except (OSError, AttributeError):
            continue
        vp, u32, sz = ctypes.c_void_p, ctypes.c_uint32, ctypes.c_size_t
        for name, res, args in (("rtcNewDevice", vp, [ctypes.c_char_p]), ("rtcReleaseDevice", None, [vp]),
                                ("rtcGetDeviceError", ctypes.c_int, [vp]), ("rtcNewScene", vp, [vp]),
                                ("rtcReleaseScene", None, [vp]), ("rtcCommitScene", None, [vp]),
                                ("rtcNewGeometry", vp, [vp, ctypes.c_int]),
                                ("rtcSetNewGeometryBuffer", vp, [vp, ctypes.c_int, u32, ctypes.c_int, sz, sz]),
                                ("rtcCommitGeometry", None, [vp]), ("rtcAttachGeometry", u32, [vp, vp]),
                                ("rtcReleaseGeometry", None, [vp]), ("rtcSetSceneFlags", None, [vp, ctypes.c_int])):
            fn = getattr(lib, name)
            fn.restype, fn.argtypes = res, args
        return lib
    return None


class DirectScene:
    """Triangles (k, 3, 3) float32 in an Embree scene of their own, for
    :func:`wavepaths.raycast._numba.occluded_direct`.

    Attributes
    ----------
    intersect : int
        The address of ``rtcIntersect1``.
    scene : int
        The ``RTCScene`` handle.
    """

    def __init__(self, lib: ctypes.CDLL, corners: np.ndarray) -> None:
        corners = np.ascontiguousarray(corners, dtype=np.float32).reshape(-1, 3, 3)
        # Embree's calls on one object are not thread-safe, and the device is shared: scenes
        # are built one at a time (casting into a committed scene is thread-safe)
        with _DEVICE_LOCK:
            self._build(lib, corners)

    def _build(self, lib: ctypes.CDLL, corners: np.ndarray) -> None:
        k = len(corners)
        self.device = _device(lib)
        self.scene = lib.rtcNewScene(self.device)
        if self.scene:
            # the scene goes with this object (also at exit, and if the build fails below);
            # the device stays for the process
            weakref.finalize(self, lib.rtcReleaseScene, self.scene)
        # robust, as embreex builds its scenes: the same hits, named alike (without it Embree's
        # faster arithmetic named other faces at float32 ties and changed the ray counts)
        lib.rtcSetSceneFlags(self.scene, RTC_SCENE_FLAG_ROBUST)
        geom = lib.rtcNewGeometry(self.device, RTC_GEOMETRY_TYPE_TRIANGLE)
        vb = lib.rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, 3 * k)
        ib = lib.rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, k)
        if not (self.scene and geom and vb and ib):
            raise RuntimeError(f"Embree refused the scene (error {lib.rtcGetDeviceError(self.device)})")
        ctypes.memmove(vb, corners.ctypes.data, corners.nbytes)
        index = np.arange(3 * k, dtype=np.uint32)
        ctypes.memmove(ib, index.ctypes.data, index.nbytes)
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(self.scene, geom)
        lib.rtcReleaseGeometry(geom)
        lib.rtcCommitScene(self.scene)
        err = lib.rtcGetDeviceError(self.device)
        if err != RTC_ERROR_NONE:
            raise RuntimeError(f"Embree error {err} while building the scene")
        self.intersect = int(ctypes.cast(lib.rtcIntersect1, ctypes.c_void_p).value)


_DEVICE: list = []
_DEVICE_LOCK = threading.RLock()


def _device(lib: ctypes.CDLL) -> int:
    """One Embree device for every :class:`DirectScene` of the process, never released
    (devices made and released scene after scene crashed the process in the tests)."""
    with _DEVICE_LOCK:
        if not _DEVICE:
            device = lib.rtcNewDevice(None)
            if not device:
                raise RuntimeError("rtcNewDevice failed")
            _DEVICE.append(device)
        return _DEVICE[0]


def direct_scene(corners: np.ndarray) -> DirectScene | None:
    """A :class:`DirectScene` of ``corners``, or ``None`` when Embree's library is not at hand
    (the caster then casts through embreex)."""
    lib = library()
    if lib is None:
        return None
    try:
        return DirectScene(lib, corners)
    except RuntimeError:
        return None
