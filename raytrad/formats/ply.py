"""Per-vertex radiosity as a binary little-endian PLY file.

Layout written by :func:`write_radiosity_ply` (and the only one :func:`read_radiosity_ply`
reads)::

    element vertex V: float x, y, z [m]; float radiosity_r, radiosity_g, radiosity_b
                      [W m-2]; uchar red, green, blue (display colour)
    element face T:   list uchar int vertex_indices (always 3 indices)
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from raytrad.errors import SceneError
from raytrad.formats.atomic import atomic_write

log = logging.getLogger(__name__)

RADIOSITY_PROPERTIES = ("radiosity_r", "radiosity_g", "radiosity_b")

VERTEX_DTYPE = np.dtype(
    [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("radiosity_r", "<f4"),
        ("radiosity_g", "<f4"),
        ("radiosity_b", "<f4"),
        ("red", "u1"),
        ("green", "u1"),
        ("blue", "u1"),
    ]
)
_COUNT = "_count"  # record field holding a list property's length
FACE_DTYPE = np.dtype([(_COUNT, "u1"), ("vertex_indices", "<i4", (3,))])

# PLY scalar type names (both spellings of the standard) -> little-endian numpy codes.
_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "<i2",
    "int16": "<i2",
    "ushort": "<u2",
    "uint16": "<u2",
    "int": "<i4",
    "int32": "<i4",
    "uint": "<u4",
    "uint32": "<u4",
    "float": "<f4",
    "float32": "<f4",
    "double": "<f8",
    "float64": "<f8",
}
_PLY_NAMES = {
    "i1": "char",
    "u1": "uchar",
    "i2": "short",
    "u2": "ushort",
    "i4": "int",
    "u4": "uint",
    "f4": "float",
    "f8": "double",
}


def write_radiosity_ply(
    path: str | os.PathLike[str],
    positions: np.ndarray,
    triangles: np.ndarray,
    radiosity: np.ndarray,
    display_rgb: np.ndarray,
) -> None:
    """Write vertex positions, radiosity and display colours as a binary PLY (atomically).

    Parameters
    ----------
    path : path-like
        Output file; its directory is created if missing.
    positions : (V, 3) float
        Vertex positions [m], stored as float32.
    triangles : (T, 3) int
        Vertex indices per triangle (front side counter-clockwise), stored as int32.
    radiosity : (V, 3) float
        Radiosity per vertex and linear RGB channel [W m-2], stored as float32.
    display_rgb : (V, 3) integer
        Display colour per vertex, 0..255 (for example tone-mapped sRGB), stored as uchar.
    """
    vertices = _vertex_records(positions, radiosity, display_rgb)
    faces = _face_records(triangles, vertices.shape[0])
    header = _header(vertices.shape[0], faces.shape[0])
    with atomic_write(path, "wb") as f:
        f.write(header)
        f.write(vertices.tobytes())
        f.write(faces.tobytes())
    log.debug("wrote %s: %d vertices, %d triangles", path, vertices.shape[0], faces.shape[0])


def _vertex_records(
    positions: np.ndarray, radiosity: np.ndarray, display_rgb: np.ndarray
) -> np.ndarray:
    """(V,) VERTEX_DTYPE records from the per-vertex arrays (checked for shape and range)."""
    positions = np.asarray(positions, dtype=np.float64)
    radiosity = np.asarray(radiosity, dtype=np.float64)
    rgb = np.asarray(display_rgb)
    v = positions.shape[0]
    for name, array in (("positions", positions), ("radiosity", radiosity), ("display_rgb", rgb)):
        if array.shape != (v, 3):
            raise ValueError(f"{name} must have shape ({v}, 3), not {array.shape}")
    if not np.issubdtype(rgb.dtype, np.integer):
        raise TypeError(f"display_rgb must be integers 0..255, not {rgb.dtype}")
    if rgb.size and (rgb.min() < 0 or rgb.max() > 255):
        raise ValueError("display_rgb values must be in 0..255")
    records = np.empty(v, dtype=VERTEX_DTYPE)
    for i, axis in enumerate("xyz"):
        records[axis] = positions[:, i]
    for i, name in enumerate(RADIOSITY_PROPERTIES):
        records[name] = radiosity[:, i]
    for i, name in enumerate(("red", "green", "blue")):
        records[name] = rgb[:, i]
    return records


def _face_records(triangles: np.ndarray, vertex_count: int) -> np.ndarray:
    """(T,) FACE_DTYPE records (count 3 and three int32 indices)."""
    triangles = np.asarray(triangles)
    if triangles.ndim != 2 or triangles.shape[1] != 3:
        raise ValueError(f"triangles must have shape (T, 3), not {triangles.shape}")
    if triangles.size and (triangles.min() < 0 or triangles.max() >= vertex_count):
        raise ValueError(f"triangle indices must be in 0..{vertex_count - 1}")
    records = np.empty(triangles.shape[0], dtype=FACE_DTYPE)
    records[_COUNT] = 3
    records["vertex_indices"] = triangles
    return records


def _header(vertex_count: int, face_count: int) -> bytes:
    """The ASCII header of the layout, ending with ``end_header\\n``."""
    lines = [
        "ply",
        "format binary_little_endian 1.0",
        "comment raytrad radiosity: positions [m], radiosity_* [W m-2] linear RGB",
        f"element vertex {vertex_count}",
    ]
    for name in VERTEX_DTYPE.names or ():
        code = VERTEX_DTYPE.fields[name][0].str.lstrip("<|")  # type: ignore[index]
        lines.append(f"property {_PLY_NAMES[code]} {name}")
    lines += [f"element face {face_count}", "property list uchar int vertex_indices", "end_header"]
    return ("\n".join(lines) + "\n").encode("ascii")


def read_radiosity_ply(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a radiosity PLY written by :func:`write_radiosity_ply`.

    Any binary little-endian PLY with scalar vertex properties ``x, y, z`` and
    ``radiosity_r, radiosity_g, radiosity_b`` (in any order, among others) and triangle
    faces ``list uchar int|uint vertex_indices`` is accepted.

    Parameters
    ----------
    path : path-like
        The PLY file.

    Returns
    -------
    positions : (V, 3) float64
        Vertex positions [m].
    triangles : (T, 3) int64
        Vertex indices per triangle.
    radiosity : (V, 3) float64
        Radiosity per vertex and channel [W m-2].

    Raises
    ------
    SceneError
        Naming the file, when it is missing, not this layout, truncated, or has no
        radiosity properties.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise SceneError(path, "file not found") from None
    elements, body_start = _parse_header(path, data)
    vertex_dtype, vertex_count = elements.get("vertex", (None, 0))
    face_dtype, face_count = elements.get("face", (None, 0))
    if vertex_dtype is None or face_dtype is None or list(elements) != ["vertex", "face"]:
        raise SceneError(path, "expected exactly the elements 'vertex' then 'face'")
    names = vertex_dtype.names or ()
    missing = [n for n in ("x", "y", "z", *RADIOSITY_PROPERTIES) if n not in names]
    if missing:
        raise SceneError(path, f"no vertex properties {', '.join(missing)} (not a radiosity PLY)")
    vertex_end = body_start + vertex_dtype.itemsize * vertex_count
    face_end = vertex_end + face_dtype.itemsize * face_count
    if len(data) < face_end:
        raise SceneError(path, f"file is truncated ({len(data)} bytes, expected {face_end})")
    vertices = np.frombuffer(data, dtype=vertex_dtype, count=vertex_count, offset=body_start)
    faces = np.frombuffer(data, dtype=face_dtype, count=face_count, offset=vertex_end)
    if face_dtype.names != (_COUNT, "vertex_indices"):
        raise SceneError(path, "faces must be exactly 'property list uchar int vertex_indices'")
    if (faces[_COUNT] != 3).any():
        raise SceneError(path, "every face must have exactly 3 vertex indices")
    positions = np.stack([vertices[a] for a in "xyz"], axis=1).astype(np.float64)
    radiosity = np.stack([vertices[n] for n in RADIOSITY_PROPERTIES], axis=1).astype(np.float64)
    triangles = faces["vertex_indices"].astype(np.int64)
    if triangles.size and (triangles.min() < 0 or triangles.max() >= vertex_count):
        raise SceneError(path, f"a face refers to a vertex outside 0..{vertex_count - 1}")
    return positions, triangles, radiosity


def _parse_header(path: Path, data: bytes) -> tuple[dict[str, tuple[np.dtype, int]], int]:
    """Element record dtypes and counts, and the byte offset where the body starts."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise SceneError(path, "not a PLY file (no 'ply' ... 'end_header' header)")
    body_start = data.index(b"\n", end) + 1
    lines = data[:end].decode("ascii", errors="replace").splitlines()
    if "format binary_little_endian 1.0" not in (line.strip() for line in lines):
        raise SceneError(path, "only 'format binary_little_endian 1.0' PLY is supported")
    fields: dict[str, list[tuple[str, str, tuple[int, ...]]]] = {}
    counts: dict[str, int] = {}
    current = ""
    for line in lines:
        words = line.split()
        if not words or words[0] in ("ply", "format", "comment", "obj_info"):
            continue
        if words[0] == "element" and len(words) == 3:
            current = words[1]
            fields[current], counts[current] = [], int(words[2])
        elif words[0] == "property" and current:
            fields[current].extend(_property_fields(path, words))
        else:
            raise SceneError(path, f"cannot read PLY header line {line.strip()!r}")
    elements = {name: (np.dtype(fields[name]), counts[name]) for name in fields}
    return elements, body_start


def _property_fields(path: Path, words: list[str]) -> list[tuple[str, str, tuple[int, ...]]]:
    """Numpy record fields ``(name, code, shape)`` for one ``property`` header line.

    Records must have a fixed size, so the only list accepted is a triangle index list
    (``list uchar int|uint <name>``), read as a ``_count`` field and three indices.
    """
    try:
        if words[1] != "list" and len(words) == 3:
            return [(words[2], _PLY_TYPES[words[1]], ())]
        if (
            words[1] == "list"
            and len(words) == 5
            and _PLY_TYPES[words[2]] == "u1"
            and _PLY_TYPES[words[3]] in ("<i4", "<u4")
        ):
            return [(_COUNT, "u1", ()), (words[4], _PLY_TYPES[words[3]], (3,))]
    except KeyError:
        pass
    raise SceneError(path, f"unsupported PLY property {' '.join(words[1:])!r}")
