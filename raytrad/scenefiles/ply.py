"""PLY scene files: polygons with per-face materials.

Face properties ``reflectance_r/g/b`` [1] and ``emitted_exitance_r/g/b`` [W m-2] give the
materials, else ``red/green/blue`` uchar colours decoded from sRGB, else one grey default
material. UV set 0 is the vertex properties ``s, t``, ``u, v`` or ``texture_u, texture_v``.
The radiosity PLY raytrad writes is :mod:`raytrad.formats.ply`.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.errors import SceneError
from raytrad.scene.colorimetry import srgb_decode
from raytrad.scenefiles import trimesh_adapter
from raytrad.scenefiles.common import (
    DEFAULT_REFLECTANCE,
    Collected,
    Material,
    ReadOptions,
    reason,
    used_vertices,
)
from raytrad.scenefiles.polygons import triangulate_polygons

_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
_HEADER_LIMIT = 1 << 20
_TYPE_SIZES = {
    **dict.fromkeys(("char", "uchar", "int8", "uint8"), 1),
    **dict.fromkeys(("short", "ushort", "int16", "uint16"), 2),
    **dict.fromkeys(("int", "uint", "float", "int32", "uint32", "float32"), 4),
    **dict.fromkeys(("double", "float64"), 8),
}

_REFLECTANCE_PROPERTIES = ("reflectance_r", "reflectance_g", "reflectance_b")
_EMISSION_PROPERTIES = ("emitted_exitance_r", "emitted_exitance_g", "emitted_exitance_b")
_COLOUR_PROPERTIES = ("red", "green", "blue")


def read_ply(path: Path, options: ReadOptions) -> Collected:
    """PLY polygons (convex or not) with per-face materials.

    Face properties ``reflectance_r/g/b`` [1] and ``emitted_exitance_r/g/b`` [W m-2], else
    ``red/green/blue`` uchar colours decoded from sRGB, else one grey default material.
    UV set 0 is the vertex properties ``s, t``, ``u, v`` or ``texture_u, texture_v`` (v up,
    as MeshLab and Blender write them).
    """
    raw = read_ply_elements(path)
    try:
        positions = np.column_stack([raw["vertex"]["data"][a] for a in "xyz"])
    except Exception as exc:  # a vertex element without x, y, z
        raise SceneError(path, f"cannot parse as PLY: {reason(exc)}") from exc
    collected = Collected(path, options)
    uv = _ply_uv(raw["vertex"]["data"]) if options.uv_set == 0 else None
    face = raw.get("face") or {}
    if not face.get("length"):
        return collected
    columns = _ply_face_columns(face["data"])
    indices = columns.get("vertex_indices", columns.get("vertex_index"))
    if indices is None:
        raise SceneError(path, "PLY faces have no 'vertex_indices' list")
    corners = [np.asarray(c, dtype=np.int64).ravel() for c in indices]
    flat = np.concatenate(corners) if corners else np.empty(0, np.int64)
    if flat.size and (flat.min() < 0 or flat.max() >= len(positions)):
        raise SceneError(path, f"a face refers to a vertex outside 0..{len(positions) - 1}")
    with np.errstate(all="ignore"):  # non-finite coordinates are reported later
        triangles, source_face = triangulate_polygons(
            positions, indices if indices.dtype != object else corners
        )
    face_materials, materials = _ply_face_materials(collected, columns, len(indices))
    triangle_material = face_materials[source_face]
    for m, material in enumerate(materials):
        selected = triangles[triangle_material == m]
        if len(selected):
            used, local = used_vertices(selected)
            collected.add(positions[used], local, material, None, None if uv is None else uv[used])
    return collected


def _ply_uv(vertex: Any) -> np.ndarray | None:
    """(n, 2) vertex UVs with v down from PLY vertex data, or None without UV properties."""
    names = set(getattr(getattr(vertex, "dtype", None), "names", None) or vertex)
    for u, v in (("s", "t"), ("u", "v"), ("texture_u", "texture_v")):
        if u in names and v in names:
            return np.column_stack(
                [np.asarray(vertex[u], dtype=np.float64), 1.0 - np.asarray(vertex[v], np.float64)]
            )
    return None


def _ply_face_columns(data: Any) -> dict[str, np.ndarray]:
    """Per-face arrays by property name from trimesh's raw PLY face data.

    trimesh gives a dict of arrays (ASCII, or binary with mixed polygon sizes) or one
    structured array whose list properties are ``(count, values)`` records.
    """
    if isinstance(data, dict):
        return {str(k): np.asarray(v) for k, v in data.items()}
    columns: dict[str, np.ndarray] = {}
    for name in data.dtype.names or ():
        column = data[name]
        if column.dtype.names and "f1" in column.dtype.names:
            column = column["f1"]
        columns[name] = np.asarray(column)
    return columns


def _ply_face_materials(
    collected: Collected, columns: dict[str, np.ndarray], face_count: int
) -> tuple[np.ndarray, list[Material]]:
    """(F,) material index per PLY face and the distinct materials."""
    reflectance: np.ndarray | None = None
    if all(p in columns for p in _REFLECTANCE_PROPERTIES):
        reflectance = np.column_stack([columns[p] for p in _REFLECTANCE_PROPERTIES])
    elif all(columns.get(p, np.empty(0)).dtype == np.uint8 for p in _COLOUR_PROPERTIES):
        reflectance = srgb_decode(np.column_stack([columns[p] for p in _COLOUR_PROPERTIES]) / 255)
    emission = np.zeros((face_count, 3))
    if all(p in columns for p in _EMISSION_PROPERTIES):
        emission = np.column_stack([columns[p] for p in _EMISSION_PROPERTIES])
    defaulted = reflectance is None
    if reflectance is None:
        collected.warn_once(
            "default",
            "PLY faces have no reflectance or colour properties; using reflectance %s grey",
            DEFAULT_REFLECTANCE,
        )
        reflectance = np.full((face_count, 3), DEFAULT_REFLECTANCE)
    values = np.column_stack([reflectance, emission]).astype(np.float64)
    distinct, inverse = np.unique(values, axis=0, return_inverse=True)
    names = [f"ply_material_{i}" for i in range(len(distinct))]
    if defaulted and len(distinct) == 1:
        names = ["default"]
    materials = [
        Material(name, (v[0], v[1], v[2]), (v[3], v[4], v[5]))
        for name, v in zip(names, distinct.tolist(), strict=True)
    ]
    return inverse.reshape(-1), materials


def read_ply_elements(path: Path) -> dict[str, Any]:
    """The file's elements as ``{"vertex": {"data": ..., "length": n}, "face": {...}}``.

    The header's ``format`` must be one of the three the PLY format defines, version 1.0
    (trimesh would read any other as little endian). Binary files are read by trimesh,
    which is fast; ASCII files, and binary ones trimesh fails on (mixed polygon sizes
    before other face properties, say), by plyfile, which checks every record's length
    (trimesh silently reads past a short line or a wrong element count).

    Raises
    ------
    SceneError
        ``cannot parse as PLY`` with the reason, naming the header line or the element
        and row at fault.
    """
    binary = _check_header(path)
    if binary:
        try:
            return trimesh_adapter.read_ply_elements(path)
        except SceneError:
            pass  # plyfile reads it, or says which record is at fault
    import plyfile

    try:
        with path.open("rb") as f, warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy's loadtxt notes are noise to a user
            data = plyfile.PlyData.read(f)
    except Exception as exc:  # plyfile raises several types for malformed input
        raise SceneError(path, f"cannot parse as PLY: {reason(exc)}") from None
    return {e.name: {"data": e.data, "length": e.count} for e in data.elements}


def _check_header(path: Path) -> bool:
    """Whether the PLY file is binary; SceneError for a ``format`` line the spec lacks, or
    element counts the file is too short to hold (a flipped byte can make a count of 4e9,
    which a reader would try to allocate)."""
    with path.open("rb") as f:
        head = f.read(_HEADER_LIMIT)
    end = head.find(b"end_header")
    header = head[: end if end >= 0 else len(head)].decode("ascii", errors="replace")
    binary = False
    elements: list[tuple[str, int, int, int]] = []  # name, count, properties, least bytes
    for number, line in enumerate(header.splitlines(), start=1):
        words = line.split()
        if words[:1] == ["format"]:
            if len(words) != 3 or words[1] not in _FORMATS or words[2] != "1.0":
                raise SceneError(
                    path, f"cannot parse as PLY: header line {number}: unknown {line!r}"
                )
            binary = words[1] != "ascii"
        elif words[:1] == ["element"] and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), 0, 0))
        elif words[:1] == ["property"] and elements and len(words) >= 3:
            size = _TYPE_SIZES.get(words[2] if words[1] == "list" else words[1], 1)
            name, count, properties, least = elements[-1]
            elements[-1] = (name, count, properties + 1, least + size)
    if end >= 0:
        body = path.stat().st_size - (end + len(b"end_header") + 1)
        for name, count, properties, least in elements:
            need = count * (least if binary else 2 * properties)
            if need > body:
                raise SceneError(
                    path,
                    f"cannot parse as PLY: the header declares {count} {name} elements, "
                    f"more than the file's {max(body, 0)} bytes of data can hold",
                )
    return binary
