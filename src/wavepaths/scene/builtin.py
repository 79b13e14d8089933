"""Built-in example scenes, addressable by name (``wavepaths info wedge``).

Each scene is a few hand-placed polygons in metres, chosen so that its physics has a
closed form or a clear expectation, and each can be written out as Mitsuba XML + PLY
(:func:`wavepaths.scene.mitsuba_writer.write_mitsuba_xml`) so that Sionna RT loads the very
same geometry.

=================  ==========================================================================
name               what it is
=================  ==========================================================================
half_plane         a 100 m x 50 m metal screen in the plane y = 0, its top edge on the x axis
wedge              a 90 degree metal wedge (exterior angle 270 degrees, n = 1.5), edge on x
wedge_awning       the wedge with a metal awning, another object, hinged on its edge 210 degrees
                   from its 0-face: three faces of two objects on one edge, whose sectors are
                   wedges of n = 7/6 and n = 1/3 (the exact arbiter of ``three_face_edge``)
box_on_ground      a 10 m concrete cube standing on a 60 m ground plane (its foot must not diffract)
slit_shutter       a concrete wall with a window closed by tilted wooden slats, a wall behind it
                   (the seed's figures 8-9 made radio)
street_canyon      two rows of concrete buildings along a street, on a ground plane
three_face_edge    a box with a metal awning hinged on its roof edge: one edge, three faces
                   (the seed's figure 4)
touching_blocks    two blocks touching along one vertical edge only: four faces on one edge,
                   whose air sectors are both 90 degrees (a naive wedge model diffracts there)
=================  ==========================================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..em.materials import PEC, Material, itu_material


@dataclass
class SceneBuilder:
    """Accumulates named objects made of quads and boxes (triangulated on the fly)."""

    vertices: list = field(default_factory=list)
    triangles: list = field(default_factory=list)
    objects: list = field(default_factory=list)
    materials: list = field(default_factory=list)
    tri_object: list = field(default_factory=list)
    tri_material: list = field(default_factory=list)

    def _ids(self, obj: str, material: Material) -> tuple[int, int]:
        if obj not in self.objects:
            self.objects.append(obj)
        if material not in self.materials:
            self.materials.append(material)
        return self.objects.index(obj), self.materials.index(material)

    def add_mesh(self, obj: str, material: Material, vertices, triangles) -> None:
        o, m = self._ids(obj, material)
        base = sum(len(v) for v in self.vertices)
        self.vertices.append(np.asarray(vertices, dtype=np.float64))
        t = np.asarray(triangles, dtype=np.int64) + base
        self.triangles.append(t)
        self.tri_object.append(np.full(len(t), o))
        self.tri_material.append(np.full(len(t), m))

    def add_quad(self, obj: str, material: Material, corners) -> None:
        """A planar quad given by its 4 corners in order."""
        self.add_mesh(obj, material, corners, [[0, 1, 2], [0, 2, 3]])

    def add_grid(self, obj: str, material: Material, origin, u, v, us, vs, holes=()) -> None:
        """A planar conforming grid ``origin + u*us[i] + v*vs[j]``, with cells in ``holes`` left out."""
        origin, u, v = (np.asarray(x, dtype=np.float64) for x in (origin, u, v))
        verts = [origin + u * a + v * b for b in vs for a in us]
        nu = len(us)
        tris = []
        for j in range(len(vs) - 1):
            for i in range(nu - 1):
                if (i, j) in holes:
                    continue
                p0, p1, p2, p3 = j * nu + i, j * nu + i + 1, (j + 1) * nu + i + 1, (j + 1) * nu + i
                tris += [[p0, p1, p2], [p0, p2, p3]]
        self.add_mesh(obj, material, verts, tris)

    def add_prism(self, obj: str, material: Material, polygon, height: float) -> None:
        """A closed vertical prism from ``z = 0`` to ``height`` over a counter-clockwise convex
        ``polygon`` [(x, y), ...] (fan-triangulated floor and roof, outward normals)."""
        m = len(polygon)
        v = [[x, y, 0.0] for x, y in polygon] + [[x, y, height] for x, y in polygon]
        t = [[0, i + 1, i] for i in range(1, m - 1)] + [[m, m + i, m + i + 1] for i in range(1, m - 1)]
        for i in range(m):
            j = (i + 1) % m
            t += [[i, j, m + j], [i, m + j, m + i]]
        self.add_mesh(obj, material, v, t)

    def add_box(self, obj: str, material: Material, lo, hi, bottom: bool = True) -> None:
        """An axis-aligned box; ``bottom=False`` leaves its floor open."""
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        v = [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0], [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]
        quads = [(4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
        if bottom:
            quads.append((0, 3, 2, 1))
        tris = []
        for a, b, c, d in quads:
            tris += [[a, b, c], [a, c, d]]
        self.add_mesh(obj, material, v, tris)

    def arrays(self):
        return (
            np.concatenate(self.vertices),
            np.concatenate(self.triangles),
            np.concatenate(self.tri_object),
            np.concatenate(self.tri_material),
            tuple(self.objects),
            tuple(self.materials),
        )


def _half_plane(b: SceneBuilder) -> None:
    b.add_quad("screen", PEC, [[-50, 0, -50], [50, 0, -50], [50, 0, 0], [-50, 0, 0]])


def _wedge(b: SceneBuilder) -> None:
    # 0-face: the half-plane z = 0, y < 0; n-face: the half-plane y = 0, z < 0.
    b.add_quad("wedge", PEC, [[-50, 0, 0], [50, 0, 0], [50, -50, 0], [-50, -50, 0]])
    b.add_quad("wedge", PEC, [[-50, 0, 0], [-50, 0, -50], [50, 0, -50], [50, 0, 0]])


AWNING_DEG = 210.0  # the awning's angle from the wedge's 0-face (the half-plane y = 0, z < 0)


def _wedge_awning(b: SceneBuilder) -> None:
    # the awning points along (0, sin a, -cos a) from the edge, as the boundary lines measure phi
    _wedge(b)
    a = np.deg2rad(AWNING_DEG)
    y, z = 50 * np.sin(a), -50 * np.cos(a)
    b.add_quad("awning", PEC, [[-50, 0, 0], [50, 0, 0], [50, y, z], [-50, y, z]])


def _box_on_ground(b: SceneBuilder) -> None:
    b.add_quad("ground", itu_material("medium_dry_ground"), [[-30, -30, 0], [30, -30, 0], [30, 30, 0], [-30, 30, 0]])
    b.add_box("box", itu_material("concrete", thickness_m=0.3), (-5, -5, 0), (5, 5, 10))


def _slit_shutter(b: SceneBuilder) -> None:
    wall = itu_material("concrete", thickness_m=0.2)
    # wall in y = 0 with a 2 m x 1 m window (x in [-1, 1], z in [1, 2])
    b.add_grid("wall", wall, [0, 0, 0], [1, 0, 0], [0, 0, 1], [-6, -1, 1, 6], [0, 1, 2, 4], holes={(1, 1)})
    wood = itu_material("wood", thickness_m=0.02)
    half = 0.09  # slat half-width [m]; slats tilted 45 degrees, 0.2 m apart, leaving slits
    for i, zc in enumerate(np.arange(1.1, 2.0, 0.2)):
        c = half * np.cos(np.pi / 4)
        b.add_quad(f"slat_{i}", wood, [[-1, -c, zc - c], [1, -c, zc - c], [1, c, zc + c], [-1, c, zc + c]])
    b.add_quad("back_wall", wall, [[-6, 4, 0], [6, 4, 0], [6, 4, 4], [-6, 4, 4]])


def _street_canyon(b: SceneBuilder) -> None:
    b.add_quad("ground", itu_material("medium_dry_ground"), [[-100, -40, 0], [100, -40, 0], [100, 40, 0], [-100, 40, 0]])
    concrete = itu_material("concrete", thickness_m=0.3)
    spans = [(-90, -50), (-45, -5), (0, 40), (45, 85)]
    for side, (y0, y1), heights in (("north", (10, 25), (15, 25, 20, 30)), ("south", (-25, -10), (20, 12, 28, 18))):
        for i, ((x0, x1), h) in enumerate(zip(spans, heights)):
            b.add_box(f"building_{side}_{i}", concrete, (x0, y0, 0), (x1, y1, h))


def _three_face_edge(b: SceneBuilder) -> None:
    b.add_box("block", itu_material("concrete", thickness_m=0.3), (0, 0, 0), (4, 4, 4))
    c, s = 3 * np.cos(np.pi / 6), 3 * np.sin(np.pi / 6)
    b.add_quad("awning", PEC, [[4, 0, 4], [4, 4, 4], [4 + c, 4, 4 - s], [4 + c, 0, 4 - s]])


def _touching_blocks(b: SceneBuilder) -> None:
    concrete = itu_material("concrete", thickness_m=0.3)
    b.add_box("block_a", concrete, (0, 0, 0), (4, 4, 6))
    b.add_box("block_b", concrete, (4, 4, 0), (8, 8, 6))


BUILTIN_SCENES = {
    "half_plane": _half_plane,
    "wedge": _wedge,
    "wedge_awning": _wedge_awning,
    "box_on_ground": _box_on_ground,
    "slit_shutter": _slit_shutter,
    "street_canyon": _street_canyon,
    "three_face_edge": _three_face_edge,
    "touching_blocks": _touching_blocks,
}


def builtin_arrays(name: str):
    """Raw arrays of a built-in scene: vertices, triangles, object ids, material ids, names, materials."""
    b = SceneBuilder()
    BUILTIN_SCENES[name](b)
    return b.arrays()
