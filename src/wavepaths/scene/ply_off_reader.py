"""Reading PLY and OFF files as polygons: vertices and faces of any number of vertices.

trimesh splits a PLY or OFF face of four or more vertices into a fan from its first vertex,
which covers area outside a concave face (an L-shaped hexagon of 300 m^2 loaded as
400 m^2), and it refuses binary PLY files that mix triangles and larger faces. These
readers return the faces as the file gives them; :func:`wavepaths.scene.obj_reader.split_polygons`
then triangulates them as OBJ faces are (a fan where it stays inside, ear clipping in the
face's plane where it would not).

* PLY (``ascii 1.0``, ``binary_little_endian 1.0``, ``binary_big_endian 1.0``; the format
  of Greg Turk's specification): the ``vertex`` element's ``x``, ``y``, ``z`` (any scalar
  type, an ASCII value rounded to its declared type as a binary file stores it) and the
  ``face`` element's ``vertex_indices`` (or ``vertex_index``) list; other properties and
  elements are read past. Binary faces whose lists all have the same
  length are read in one pass; mixed lengths face by face.
* OFF (``OFF``, ``COFF``, ``NOFF``, ``CNOFF``; ``#`` comments): the counts line, the
  vertices' first three numbers, then each face's count and indices (colours after them
  ignored).

A face that names a vertex outside the file's vertices, a truncated file or a malformed
header raises :class:`~wavepaths.errors.SceneError` naming the place.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError

# PLY scalar types (the specification's names and their sized aliases) as numpy codes
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FACE_LISTS = ("vertex_indices", "vertex_index")


@dataclass(frozen=True)
class PolygonFile:
    """The polygons of a mesh file.

    Attributes
    ----------
    vertices : (v, 3) float64
        Positions [file units].
    counts : (f,) int64
        Vertices per face, each at least 3.
    indices : (sum(counts),) int64
        The faces' vertex indices, face after face, each in ``[0, v)``.
    places : (f,) int64
        Where each face is in the file: its line (1-based) in a text file, its index
        (1-based) in a binary PLY file.
    unit : str
        ``"line"`` or ``"face"``: what ``places`` count.
    """

    vertices: np.ndarray
    counts: np.ndarray
    indices: np.ndarray
    places: np.ndarray
    unit: str

    def faces(self) -> list[list[int]]:
        """Each face's vertex indices, as lists."""
        ends = np.cumsum(self.counts)
        flat = self.indices.tolist()
        return [flat[e - c : e] for c, e in zip(self.counts.tolist(), ends.tolist())]


def _checked(path: str, vertices: np.ndarray, counts: np.ndarray, indices: np.ndarray, places: np.ndarray,
             unit: str) -> PolygonFile:
    if len(counts) == 0:
        raise SceneError(f"{path}: the mesh has no faces")
    small = np.flatnonzero(counts < 3)
    if len(small):
        raise SceneError(f"{path}, {unit} {int(places[small[0]])}: a face needs at least 3 vertices, "
                         f"got {int(counts[small[0]])}")
    bad = np.flatnonzero((indices < 0) | (indices >= len(vertices)))
    if len(bad):
        face = int(np.searchsorted(np.cumsum(counts), bad[0], side="right"))
        raise SceneError(f"{path}, {unit} {int(places[face])}: face names vertex {int(indices[bad[0]])}; "
                         f"the file has {len(vertices)} vertices (numbered from 0)")
    return PolygonFile(np.ascontiguousarray(vertices, np.float64), counts.astype(np.int64),
                       indices.astype(np.int64), places.astype(np.int64), unit)


# ---------------------------------------------------------------------------------------- OFF
def read_off(path: str) -> PolygonFile:
    """The polygons of the OFF file ``path``."""
    with open(path, "rb") as fh:
        text = fh.read().decode("utf-8-sig", errors="replace")  # (a byte-order mark first: dropped)
    rows = []  # (line number, tokens) of the non-empty lines, comments removed
    for number, line in enumerate(text.splitlines(), start=1):
        tokens = line.split("#", 1)[0].split()
        if tokens:
            rows.append((number, tokens))
    if not rows or rows[0][1][0].upper() not in ("OFF", "COFF", "NOFF", "CNOFF"):
        raise SceneError(f"{path}: not an OFF file (its first word is not OFF, COFF, NOFF or CNOFF)")
    head = rows[0][1][1:]  # the counts may follow the keyword on its line
    at = 1
    if not head:
        if len(rows) < 2:
            raise SceneError(f"{path}: the OFF file has no counts line")
        number, head = rows[1]
        at = 2
    try:
        nv, nf = int(head[0]), int(head[1])
    except (ValueError, IndexError):
        raise SceneError(f"{path}, line {rows[at - 1][0]}: malformed counts {' '.join(head)!r} "
                         "(vertices, faces, edges)") from None
    if nv < 0 or nf < 0 or len(rows) < at + nv + nf:
        raise SceneError(f"{path}: the file ends before its {nv} vertices and {nf} faces")
    try:
        vertices = np.array([[float(t) for t in tokens[:3]] for _, tokens in rows[at : at + nv]], np.float64)
    except ValueError:
        raise SceneError(f"{path}: a malformed vertex between lines {rows[at][0]} and {rows[at + nv - 1][0]}") from None
    if nv and vertices.shape != (nv, 3):
        raise SceneError(f"{path}: a vertex with fewer than 3 coordinates between lines {rows[at][0]} and "
                         f"{rows[at + nv - 1][0]}")
    counts, indices, places = [], [], []
    for number, tokens in rows[at + nv : at + nv + nf]:
        try:
            k = int(tokens[0])
            refs = [int(t) for t in tokens[1 : k + 1]]
        except ValueError:
            raise SceneError(f"{path}, line {number}: malformed face {' '.join(tokens)!r}") from None
        if len(refs) != k:
            raise SceneError(f"{path}, line {number}: the face announces {k} vertices and gives {len(refs)}")
        counts.append(k)
        indices.extend(refs)
        places.append(number)
    return _checked(path, vertices.reshape(-1, 3), np.asarray(counts, np.int64), np.asarray(indices, np.int64),
                    np.asarray(places, np.int64), "line")


# ---------------------------------------------------------------------------------------- PLY
@dataclass
class _Property:
    name: str
    dtype: str  # numpy code of the value (of the items for a list)
    count_dtype: str | None = None  # numpy code of a list's count, None for a scalar


@dataclass
class _Element:
    name: str
    count: int
    properties: list[_Property]


def _ply_header(path: str, data: bytes) -> tuple[str, list[_Element], int]:
    """``(format, elements, offset of the body)`` of a PLY file's bytes."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise SceneError(f"{path}: not a PLY file (no 'ply' first line or no 'end_header')")
    body = data.index(b"\n", end) + 1 if b"\n" in data[end:] else len(data)
    fmt = None
    elements: list[_Element] = []
    for number, raw in enumerate(data[:end].decode("ascii", errors="replace").splitlines()[1:], start=2):
        tokens = raw.split()
        if not tokens or tokens[0] in ("comment", "obj_info"):
            continue
        try:
            if tokens[0] == "format":
                fmt = tokens[1]
            elif tokens[0] == "element":
                elements.append(_Element(tokens[1], int(tokens[2]), []))
            elif tokens[0] == "property" and tokens[1] == "list":
                elements[-1].properties.append(_Property(tokens[4], _PLY_TYPES[tokens[3]], _PLY_TYPES[tokens[2]]))
            elif tokens[0] == "property":
                elements[-1].properties.append(_Property(tokens[2], _PLY_TYPES[tokens[1]]))
            else:
                raise ValueError
        except (IndexError, KeyError, ValueError):
            raise SceneError(f"{path}, line {number}: malformed PLY header line {raw.strip()!r}") from None
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise SceneError(f"{path}: unknown PLY format {fmt!r} (ascii, binary_little_endian, binary_big_endian)")
    return fmt, elements, body


def _face_list(path: str, element: _Element) -> int:
    lists = [i for i, p in enumerate(element.properties) if p.count_dtype is not None and p.name in _FACE_LISTS]
    if not lists:
        raise SceneError(f"{path}: the PLY 'face' element has no vertex_indices list")
    return lists[0]


def _ply_binary_element(path: str, data: bytes, at: int, element: _Element, order: str):
    """``(columns, offset after it)``: each property's values, a list property's as ``(counts,
    flat items)``."""
    props = element.properties
    n = element.count
    if all(p.count_dtype is None for p in props):
        dt = np.dtype([(f"p{i}", order + p.dtype) for i, p in enumerate(props)])
        if at + dt.itemsize * n > len(data):
            raise SceneError(f"{path}: the file ends inside its '{element.name}' element")
        rec = np.frombuffer(data, dt, count=n, offset=at)
        return [rec[f"p{i}"] for i in range(len(props))], at + dt.itemsize * n
    if n == 0:
        return [np.zeros(0, p.dtype) if p.count_dtype is None else (np.zeros(0, np.int64), np.zeros(0, p.dtype))
                for p in props], at
    # lists: first as if every record's lists had the first record's lengths, checked after
    lengths, pos = [], at
    for p in props:
        if p.count_dtype is None:
            pos += np.dtype(p.dtype).itemsize
        else:
            c = np.dtype(order + p.count_dtype)
            if pos + c.itemsize > len(data):
                raise SceneError(f"{path}: the file ends inside its '{element.name}' element")
            k = int(np.frombuffer(data, c, count=1, offset=pos)[0])
            lengths.append(k)
            pos += c.itemsize + k * np.dtype(p.dtype).itemsize
    fields, li = [], 0
    for i, p in enumerate(props):
        if p.count_dtype is None:
            fields.append((f"p{i}", order + p.dtype))
        else:
            fields.append((f"c{i}", order + p.count_dtype))
            fields.append((f"p{i}", order + p.dtype, (lengths[li],)))
            li += 1
    dt = np.dtype(fields)
    if n and at + dt.itemsize * n <= len(data):
        rec = np.frombuffer(data, dt, count=n, offset=at)
        li, same = 0, True
        for i, p in enumerate(props):
            if p.count_dtype is not None:
                same = same and bool(np.all(rec[f"c{i}"] == lengths[li]))
                li += 1
        if same:
            cols = []
            for i, p in enumerate(props):
                if p.count_dtype is None:
                    cols.append(rec[f"p{i}"])
                else:
                    items = rec[f"p{i}"]
                    cols.append((np.full(n, items.shape[1], np.int64), items.reshape(-1)))
            return cols, at + dt.itemsize * n
    # mixed lengths: record by record
    values: list[list] = [[] for _ in props]
    pos = at
    try:
        for _ in range(n):
            for i, p in enumerate(props):
                if p.count_dtype is None:
                    v = np.frombuffer(data, order + p.dtype, count=1, offset=pos)
                    values[i].append(v[0])
                    pos += v.itemsize
                else:
                    c = np.frombuffer(data, order + p.count_dtype, count=1, offset=pos)
                    pos += c.itemsize
                    v = np.frombuffer(data, order + p.dtype, count=int(c[0]), offset=pos)
                    values[i].append(v)
                    pos += v.nbytes
    except ValueError:
        raise SceneError(f"{path}: the file ends inside its '{element.name}' element") from None
    cols = []
    for i, p in enumerate(props):
        if p.count_dtype is None:
            cols.append(np.asarray(values[i]))
        else:
            cols.append((np.array([len(v) for v in values[i]], np.int64),
                         np.concatenate(values[i]) if values[i] else np.zeros(0, p.dtype)))
    return cols, pos


def _ply_ascii_element(path: str, lines: list[tuple[int, list[str]]], at: int, element: _Element):
    """``(columns, next line, line numbers of the records)``, as :func:`_ply_binary_element`."""
    props = element.properties
    if at + element.count > len(lines):
        raise SceneError(f"{path}: the file ends inside its '{element.name}' element")
    values: list[list] = [[] for _ in props]
    numbers = []
    for number, tokens in lines[at : at + element.count]:
        numbers.append(number)
        j = 0
        try:
            for i, p in enumerate(props):
                if p.count_dtype is None:
                    values[i].append(float(tokens[j]))
                    j += 1
                else:
                    k = int(tokens[j])
                    values[i].append([int(float(t)) for t in tokens[j + 1 : j + 1 + k]])
                    if len(values[i][-1]) != k:
                        raise IndexError
                    j += 1 + k
        except (ValueError, IndexError):
            raise SceneError(f"{path}, line {number}: malformed '{element.name}' record "
                             f"{' '.join(tokens)[:60]!r}") from None
    cols = []
    for i, p in enumerate(props):
        if p.count_dtype is None:
            # as declared (a ``float`` property is a float32, as in a binary file of the same values)
            cols.append(np.asarray(values[i], np.float64).astype(p.dtype))
        else:
            cols.append((np.array([len(v) for v in values[i]], np.int64),
                         np.array([x for v in values[i] for x in v], np.int64)))
    return cols, at + element.count, np.asarray(numbers, np.int64)


def read_ply(path: str) -> PolygonFile:
    """The polygons of the PLY file ``path``."""
    with open(path, "rb") as fh:
        data = fh.read()
    if data.startswith(b"\xef\xbb\xbf"):  # a UTF-8 byte-order mark before the header
        data = data[3:]
    fmt, elements, body = _ply_header(path, data)
    names = [e.name for e in elements]
    if "vertex" not in names or "face" not in names:
        raise SceneError(f"{path}: the PLY file needs a 'vertex' and a 'face' element (it has {', '.join(names)})")
    vertex = elements[names.index("vertex")]
    xyz = [next((i for i, p in enumerate(vertex.properties) if p.name == a and p.count_dtype is None), None)
           for a in "xyz"]
    if None in xyz:
        raise SceneError(f"{path}: the PLY 'vertex' element needs x, y and z properties")
    columns: dict[str, list] = {}
    places = None
    if fmt == "ascii":
        lines = [(n, line.split()) for n, line in
                 enumerate(data[body:].decode("ascii", errors="replace").splitlines(), start=1)]
        header_lines = data[:body].count(b"\n")
        lines = [(n + header_lines, t) for n, t in lines if t]
        at = 0
        for e in elements:
            cols, at, numbers = _ply_ascii_element(path, lines, at, e)
            columns[e.name] = cols
            if e.name == "face":
                places = numbers
        unit = "line"
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        at = body
        for e in elements:
            columns[e.name], at = _ply_binary_element(path, data, at, e, order)
        unit = "face"
    v = np.column_stack([np.asarray(columns["vertex"][i], np.float64) for i in xyz]) if vertex.count else np.zeros((0, 3))
    face = elements[names.index("face")]
    counts, indices = columns["face"][_face_list(path, face)]
    if places is None:
        places = np.arange(1, len(counts) + 1)
    return _checked(path, v, np.asarray(counts, np.int64), np.asarray(indices, np.int64), places, unit)


__all__ = ["PolygonFile", "read_off", "read_ply"]
