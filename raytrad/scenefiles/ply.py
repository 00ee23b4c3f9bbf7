"""PLY scene files: polygons with per-face materials.

Face properties ``reflectance_r/g/b`` [1] and ``emitted_exitance_r/g/b`` [W m-2] give the
materials, else ``red/green/blue`` uchar colours decoded from sRGB, else one grey default
material. UV set 0 is the vertex properties ``s, t``, ``u, v`` or ``texture_u, texture_v``.
The radiosity PLY raytrad writes is :mod:`raytrad.formats.ply`.
"""

from __future__ import annotations

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

_REFLECTANCE_PROPERTIES = ("reflectance_r", "reflectance_g", "reflectance_b")
_EMISSION_PROPERTIES = ("emitted_exitance_r", "emitted_exitance_g", "emitted_exitance_b")
_COLOUR_PROPERTIES = ("red", "green", "blue")


def read_ply(path: Path, options: ReadOptions) -> Collected:
    """PLY polygons (fan-triangulated) with per-face materials.

    Face properties ``reflectance_r/g/b`` [1] and ``emitted_exitance_r/g/b`` [W m-2], else
    ``red/green/blue`` uchar colours decoded from sRGB, else one grey default material.
    UV set 0 is the vertex properties ``s, t``, ``u, v`` or ``texture_u, texture_v`` (v up,
    as MeshLab and Blender write them).
    """
    raw = trimesh_adapter.read_ply_elements(path)
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
    triangles, source_face = _fan_triangulate(indices)
    if triangles.size and (triangles.min() < 0 or triangles.max() >= len(positions)):
        raise SceneError(path, f"a face refers to a vertex outside 0..{len(positions) - 1}")
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


def _fan_triangulate(polygons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles of PLY polygons, in face order.

    Parameters
    ----------
    polygons : (F, k) int or (F,) object array of int arrays
        Vertex indices per face; faces with fewer than 3 corners are dropped.

    Returns
    -------
    triangles : (T, 3) int64
    source_face : (T,) int64
        The face each triangle came from.
    """
    if polygons.dtype != object and polygons.ndim == 2:
        groups = {polygons.shape[1]: (np.arange(len(polygons)), polygons.astype(np.int64))}
    else:
        lengths = np.array([len(p) for p in polygons], dtype=np.int64)
        groups = {}
        for k in np.unique(lengths[lengths >= 3]).tolist():
            faces = np.flatnonzero(lengths == k)
            groups[k] = (faces, np.stack([polygons[i] for i in faces]).astype(np.int64))
    triangles, sources = [np.empty((0, 3), np.int64)], [np.empty(0, np.int64)]
    for k, (faces, corners) in groups.items():
        if k < 3:
            continue
        fan = np.stack([corners[:, [0, j, j + 1]] for j in range(1, k - 1)], axis=1)
        triangles.append(fan.reshape(-1, 3))
        sources.append(np.repeat(faces, k - 2))
    triangle_array, source = np.concatenate(triangles), np.concatenate(sources)
    order = np.argsort(source, kind="stable")
    return triangle_array[order], source[order]


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
