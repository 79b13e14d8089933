"""The scenes, transmitters and receivers the benchmarks run on.

Both engines read the same Mitsuba XML file:

* ``simple_street_canyon``: Sionna RT's built-in scene (74 triangles), with the set-up of
  ``docs/sionna-notes.md`` §8: transmitter at (-45, 0, 10), 100 receivers on the line
  x = 23.5 m, y from -55 to 55 m, z = 1.5 m (line of sight and shadowed).
* ``etoile_crop``: the buildings of Sionna RT's ``etoile`` scene that lie entirely inside
  a square around a centre, plus its ground (whole objects are kept, so closed buildings
  stay closed), written out as XML + PLY. The 300 m square around the origin holds
  948 triangles, 350 polygons and 657 diffracting dihedra (653 before edges were cut at coplanar polygons' borders); the full scene (13,098
  triangles) is beyond the image tree's limit at reflection order 2.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..scene import Scene, build_scene, load_scene, write_mitsuba_xml

STREET_CANYON_TX = np.array([[-45.0, 0.0, 10.0]])


@dataclass(frozen=True)
class BenchScene:
    """A scene file with its transmitter and receivers.

    Attributes
    ----------
    name : str
    xml : str
        Mitsuba XML file both engines load.
    tx : (1, 3) float64 [m]
    rx : (n, 3) float64 [m]
    note : str
    """

    name: str
    xml: str
    tx: np.ndarray
    rx: np.ndarray
    note: str = ""


def street_canyon_receivers(n: int = 100) -> np.ndarray:
    """(n, 3) receivers of ``docs/sionna-notes.md`` §8: x = 23.5, y in [-55, 55], z = 1.5 [m]."""
    return np.stack([np.full(n, 23.5), np.linspace(-55.0, 55.0, n), np.full(n, 1.5)], axis=1)


def sionna_scene_xml(name: str) -> str:
    """Path of a Sionna RT built-in scene (needs sionna-rt)."""
    from ..validation.sionna_runner import builtin_scene_path

    return builtin_scene_path(name)


def street_canyon(n_rx: int = 100) -> BenchScene:
    """Sionna's ``simple_street_canyon`` with the receivers of the Sionna notes."""
    return BenchScene("simple_street_canyon", sionna_scene_xml("simple_street_canyon"), STREET_CANYON_TX.copy(),
                      street_canyon_receivers(n_rx), "Sionna RT built-in scene, 74 triangles")


def crop_objects(scene: Scene, center, half_width: float, keep_names: tuple[str, ...] = ("Plane",)) -> Scene:
    """The objects of ``scene`` lying entirely inside the square ``center +- half_width`` in x, y.

    Objects named in ``keep_names`` (the ground) are kept whole.
    """
    nobj = len(scene.object_names)
    corners = scene.vertices[scene.triangles]
    lo = np.full((nobj, 3), np.inf)
    hi = np.full((nobj, 3), -np.inf)
    np.minimum.at(lo, scene.triangle_object, corners.min(axis=1))
    np.maximum.at(hi, scene.triangle_object, corners.max(axis=1))
    cx, cy = float(center[0]), float(center[1])
    sel = (lo[:, 0] >= cx - half_width) & (hi[:, 0] <= cx + half_width) \
        & (lo[:, 1] >= cy - half_width) & (hi[:, 1] <= cy + half_width)
    for name in keep_names:
        if name in scene.object_names:
            sel[scene.object_names.index(name)] = True
    keep = sel[scene.triangle_object]
    return build_scene(scene.vertices, scene.triangles[keep], scene.triangle_object[keep],
                       scene.triangle_material[keep], scene.object_names, scene.materials,
                       source=f"{scene.source} (objects within {2 * half_width:g} m of {cx:g}, {cy:g})")


def outdoor_points(scene: Scene, points: np.ndarray) -> np.ndarray:
    """(k,) bool: which of ``points`` (k, 3) lie outside every solid object (building)."""
    from ..coverage import inside_solid_objects, solid_objects

    return ~inside_solid_objects(scene, points, solid_objects(scene))


def etoile_crop(out_dir: str, n_rx: int = 100, half_width: float = 150.0, seed: int = 0) -> BenchScene:
    """A square of Sionna's ``etoile`` written to ``out_dir/scenes/etoile_crop``.

    The transmitter stands at (3, 1, 25) m, above the street; the receivers are the first
    ``n_rx`` of uniform random points at 1.5 m height in the square that lie outside the
    buildings (seeded, so every run uses the same ones).
    """
    full = load_scene(sionna_scene_xml("etoile"))
    crop = crop_objects(full, (0.0, 0.0), half_width)
    path = os.path.join(out_dir, "scenes", "etoile_crop", "etoile_crop.xml")
    if not os.path.exists(path):
        write_mitsuba_xml(crop, path)
    rng = np.random.default_rng(seed)
    pts = np.column_stack([rng.uniform(-half_width, half_width, 8 * n_rx),
                           rng.uniform(-half_width, half_width, 8 * n_rx), np.full(8 * n_rx, 1.5)])
    rx = pts[outdoor_points(crop, pts)][:n_rx]
    info = crop.summary()
    return BenchScene("etoile_crop", path, np.array([[3.0, 1.0, 25.0]]), rx,
                      f"Sionna RT's etoile, objects within a {2 * half_width:g} m square: {info['triangles']} "
                      f"triangles, {info['polygons']} polygons, {info['diffracting_dihedra']} diffracting dihedra")
