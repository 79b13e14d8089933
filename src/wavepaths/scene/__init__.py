"""Scenes: loading, welding, polygons, built-in examples, Mitsuba XML."""

from .builtin import BUILTIN_SCENES
from .loaders import load_scene
from .mitsuba_writer import write_mitsuba_xml
from .model import Scene, WavepathsWarning, build_scene, transformed, with_materials
from .tolerances import SceneTolerances

__all__ = [
    "BUILTIN_SCENES",
    "Scene",
    "SceneTolerances",
    "WavepathsWarning",
    "build_scene",
    "load_scene",
    "transformed",
    "with_materials",
    "write_mitsuba_xml",
]
