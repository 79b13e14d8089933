"""The validation cases: the same scene file, positions, antennas and path types for both engines."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def ring(radius: float, degrees: np.ndarray, z: float, centre=(0.0, 0.0)) -> np.ndarray:
    a = np.deg2rad(np.asarray(degrees, dtype=float))
    return np.stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a), np.full(len(a), z)], axis=1)


@dataclass(frozen=True)
class Case:
    """One comparison.

    Attributes
    ----------
    name : str
    scene : str
        ``"sionna:<name>"`` for a Sionna RT built-in scene, or a wavepaths built-in scene
        name, written out as Mitsuba XML + PLY so that both engines read the same file.
    tx, rx : (m, 3), (n, 3) float [m]
    max_depth : int
        Sionna's ``max_depth``; wavepaths traces reflections to this order and diffraction
        with up to ``max_depth - 1`` reflections.
    edge_diffraction : bool
        Let Sionna diffract on free edges too (screens, plates).
    quick : bool
        Part of ``--quick`` (and of CI).
    polarizations : tuple of str
    """

    name: str
    scene: str
    tx: np.ndarray
    rx: np.ndarray
    max_depth: int = 2
    edge_diffraction: bool = False
    quick: bool = False
    frequency_hz: float = 3.5e9
    polarizations: tuple = ("V", "H")
    note: str = ""
    samples_per_src: int = 1_000_000


def default_cases() -> list[Case]:
    line = lambda x0, x1, n, y, z: np.stack([np.linspace(x0, x1, n), np.full(n, y), np.full(n, z)], axis=1)
    return [
        Case("simple_wedge", "sionna:simple_wedge",
             np.array([[10.0, 17.320508, 2.0]]), ring(10.0, np.arange(5, 270, 10), 1.0), max_depth=2, quick=True,
             note="Sionna's 90-degree concrete wedge (n = 1.5), receivers on a circle around the edge"),
        Case("box", "sionna:box", np.array([[9.0, 3.0, 1.5]]), ring(9.0, np.arange(7.5, 360, 15), 0.3),
             max_depth=2, quick=True, note="Sionna's metal box; receivers around it"),
        Case("simple_reflector", "sionna:simple_reflector", np.array([[-2.0, 0.3, 3.0]]),
             line(-3, 3, 13, -0.23, 2.0), max_depth=1, edge_diffraction=True,
             note="a 1 m metal plate: specular reflection and its rim's diffraction (the receiver line avoids "
                  "lying exactly on a reflection boundary, where Sionna takes one side and wavepaths the side of "
                  "its geometrical-optics decision)"),
        Case("simple_street_canyon", "sionna:simple_street_canyon", np.array([[-40.0, 0.0, 10.0]]),
             line(-70, 70, 30, 2.0, 1.5), max_depth=3,
             note="the street canyon, depth 3 with diffraction"),
        Case("half_plane", "half_plane", np.array([[0.0, -40.0, -10.0]]),
             np.stack([np.zeros(12), np.full(12, 6.0), np.linspace(-9, 4, 12)], axis=1), max_depth=1,
             edge_diffraction=True, quick=True, note="wavepaths' metal screen (edge on the x axis)"),
        Case("wedge", "wedge", np.array([[0.0, 30.0, -10.0]]), ring_yz(5.0, np.arange(-85, 180, 12)), max_depth=2,
             edge_diffraction=True, note="wavepaths' 90-degree metal wedge"),
        Case("slit_shutter", "slit_shutter", np.array([[0.3, -6.0, 2.8]]),
             np.stack([np.linspace(-2, 2, 9), np.full(9, 2.5), np.full(9, 1.4)], axis=1), max_depth=2,
             edge_diffraction=True, note="a wall with a window closed by slats, a wall behind"),
        Case("box_on_ground", "box_on_ground", np.array([[-15.0, -12.0, 3.0]]),
             ring(14.0, np.arange(0, 360, 30), 1.5), max_depth=2, note="a box standing on the ground"),
        Case("three_face_edge", "three_face_edge", np.array([[9.0, 2.0, 7.0]]),
             np.concatenate([np.stack([np.linspace(-3, 10, 10), np.full(10, 2.5), np.full(10, 6.5)], axis=1),
                             np.array([[4.6, 2.5, 3.2], [5.0, 1.5, 3.0], [5.3, 2.0, 2.6], [4.4, 3.0, 2.0]])]),
             max_depth=2, edge_diffraction=True, quick=True,
             note="a box with an awning on its roof edge; the last four receivers sit in the pocket under the "
                  "awning, which no diffracted path from above the roof can reach around that edge"),
    ]


def ring_yz(radius: float, degrees) -> np.ndarray:
    """Points around the x axis (the wedge's edge), angle from +y toward +z."""
    a = np.deg2rad(np.asarray(degrees, dtype=float))
    return np.stack([np.full(len(a), 1.0), radius * np.cos(a), radius * np.sin(a)], axis=1)
