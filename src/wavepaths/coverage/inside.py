"""The inside-a-solid rule, kept importable here for code written against earlier versions:
it lives in :mod:`wavepaths.scene.solids` (the scene, the search and the ray casters all use
it, so it belongs to the first stage of the data flow, not the last)."""

from ..scene.solids import (
    PAIR_BUDGET,
    RAY_DIRECTIONS,
    SolidObjects,
    inside_solid_objects,
    inside_solids,
    solid_objects,
)

__all__ = ["PAIR_BUDGET", "RAY_DIRECTIONS", "SolidObjects", "inside_solid_objects", "inside_solids", "solid_objects"]
