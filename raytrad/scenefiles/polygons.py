"""Polygon faces to triangles, right for non-convex polygons too.

A fan from the first corner is right only for polygons that are convex (or star-shaped
from that corner); an L-shaped floor written as one 6-corner face comes out covering
its notch. Here triangles and quads are split in numpy (a quad along the diagonal that
lies inside it), and larger polygons by ear clipping (mapbox-earcut, imported lazily)
in the plane of their Newell normal. Every triangle keeps the polygon's winding.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from raytrad.arrays import unique


def triangulate_polygons(
    positions: np.ndarray, polygons: Sequence[np.ndarray] | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Triangles covering each polygon exactly, in face order.

    Parameters
    ----------
    positions : (n, 3) float
        Vertex positions [any length unit].
    polygons : (F, k) int array, or sequence of F int arrays
        Vertex indices of each face, in winding order. Faces with fewer than 3 corners
        give no triangle.

    Returns
    -------
    triangles : (T, 3) int64
        Vertex indices; each triangle winds as its polygon (its normal points along the
        polygon's Newell normal).
    source_face : (T,) int64
        The face each triangle came from, non-decreasing.

    Notes
    -----
    A polygon of k corners gives k - 2 triangles. A degenerate polygon (no area, or
    self-intersecting so that ear clipping fails) falls back to a fan, whose slivers the
    scene repair then drops. Indices are not checked against ``positions``; the caller
    does that first.
    """
    positions = np.asarray(positions, dtype=np.float64)
    groups = _by_length(polygons)
    triangles, sources = [np.empty((0, 3), np.int64)], [np.empty(0, np.int64)]
    for k, (faces, corners) in groups.items():
        if k == 3:
            triangles.append(corners)
            sources.append(faces)
        elif k == 4:
            triangles.append(_split_quads(positions, corners).reshape(-1, 3))
            sources.append(np.repeat(faces, 2))
        elif k > 4:
            for face, polygon in zip(faces.tolist(), corners, strict=True):
                triangles.append(_ear_clip(positions, polygon))
                sources.append(np.full(k - 2, face, dtype=np.int64))
    triangle_array, source = np.concatenate(triangles), np.concatenate(sources)
    order = np.argsort(source, kind="stable")
    return triangle_array[order], source[order]


def _by_length(
    polygons: Sequence[np.ndarray] | np.ndarray,
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Faces grouped by corner count: ``{k: ((m,) face indices, (m, k) corners)}``."""
    array = polygons if isinstance(polygons, np.ndarray) else None
    if array is not None and array.dtype != object and array.ndim == 2:
        return {array.shape[1]: (np.arange(len(array)), array.astype(np.int64))}
    lengths = np.array([len(p) for p in polygons], dtype=np.int64)
    groups = {}
    for k in unique(lengths[lengths >= 3]).tolist():
        faces = np.flatnonzero(lengths == k)
        corners = [np.asarray(polygons[int(i)]) for i in faces]
        groups[k] = (faces, np.stack(corners).astype(np.int64))
    return groups


def _newell_normals(points: np.ndarray) -> np.ndarray:
    """(m, 3) Newell normals (twice the vector area) of (m, k, 3) polygon corners."""
    following = np.roll(points, -1, axis=1)
    return np.cross(points, following).sum(axis=1)


def _orientation(normal: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Signed doubled area of triangles (a, b, c) along ``normal``; all (m, 3)."""
    return np.einsum("ij,ij->i", normal, np.cross(b - a, c - a))


def _split_quads(positions: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(m, 2, 3) triangles of (m, 4) quads, split along the diagonal inside each.

    The diagonal 0-2 lies inside a simple quad when both of its triangles wind with the
    quad; otherwise corner 0 or 2 is the reflex one and the diagonal 1-3 is used.
    """
    p = positions[quads]
    normal = _newell_normals(p)
    inside = (_orientation(normal, p[:, 0], p[:, 1], p[:, 2]) >= 0) & (
        _orientation(normal, p[:, 0], p[:, 2], p[:, 3]) >= 0
    )
    first = np.stack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1)
    second = np.stack([quads[:, [1, 2, 3]], quads[:, [1, 3, 0]]], axis=1)
    return np.where(inside[:, None, None], first, second)


def _ear_clip(positions: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """(k - 2, 3) triangles of one polygon of k > 4 corners, by ear clipping in its plane."""
    import mapbox_earcut

    points = positions[polygon]
    normal = _newell_normals(points[None])[0]
    k = len(polygon)
    fan = np.stack([np.zeros(k - 2, np.int64), np.arange(1, k - 1), np.arange(2, k)], axis=1)
    length = float(np.linalg.norm(normal))
    if not np.isfinite(length) or length == 0.0:
        return polygon[fan]
    normal = normal / length
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    centred = points - points.mean(axis=0)
    plane = np.column_stack([centred @ u, centred @ v])
    clipped = mapbox_earcut.triangulate_float64(plane, np.array([k], dtype=np.uint32))
    local = np.asarray(clipped, dtype=np.int64).reshape(-1, 3)
    if len(local) != k - 2:
        local = fan
    a, b, c = (points[local[:, i]] for i in range(3))
    flip = _orientation(np.broadcast_to(normal, a.shape), a, b, c) < 0
    local[flip] = local[flip][:, ::-1]
    return polygon[local]
