"""What a surface shows where a ray lands on the (refined) mesh: the radiosity of the side
facing the ray, interpolated over the triangle's receivers.

Shared by everything that reads a solution along rays: camera images, surface probes and
the Monte Carlo check of a bake's discretisation (:mod:`raytrad.core.accuracy`).
"""

from __future__ import annotations

import numpy as np

from raytrad.core.mesh import RadiosityMesh


def twin_triangles(triangles: np.ndarray) -> np.ndarray:
    """(T,) int64: the reversed copy of each triangle (other side of a two-sided surface),
    or -1."""
    key = np.sort(triangles, axis=1).astype(np.int64)
    count = int(key.max(initial=0)) + 1
    if count < 1 << 21:  # one int64 a triangle, ordered as the rows: sorted 4x as fast
        key = (key[:, 0] * count + key[:, 1]) * count + key[:, 2]
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    twin = np.full(len(triangles), -1, dtype=np.int64)
    pairs = counts[inverse] == 2
    order = np.argsort(inverse[pairs], kind="stable")
    members = np.nonzero(pairs)[0][order].reshape(-1, 2)
    twin[members[:, 0]] = members[:, 1]
    twin[members[:, 1]] = members[:, 0]
    return twin


def triangle_normals(mesh: RadiosityMesh) -> tuple[np.ndarray, np.ndarray]:
    """(T,) doubled areas [m2] and (T, 3) unit normals of the mesh's triangles."""
    corners = mesh.positions[mesh.triangles]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(cross, axis=1)
    return length, cross / np.maximum(length, 1e-300)[:, None]


def shade(
    hit: np.ndarray,
    weights: np.ndarray,
    direction: np.ndarray,
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    normal: np.ndarray,
    twin: np.ndarray,
) -> np.ndarray:
    """(N, 3) radiosity seen along each ray: the side of the surface facing the camera.

    A hit on the back of a single-sided surface is black (no light leaves its back); on a
    two-sided surface it takes the reversed copy, whose corners come in reverse order.
    """
    out = np.zeros((len(hit), 3))
    ok = hit >= 0
    tri = hit[ok]
    w = weights[ok]
    facing = np.einsum("ij,ij->i", normal[tri], direction[ok]) < 0
    back = ~facing & (twin[tri] >= 0)
    tri = np.where(back, twin[tri], tri)
    if back.any():  # only the rays that see a two-sided surface's back (w is a copy)
        w[back] = _reversed_weights(mesh.triangles, hit[ok][back], tri[back], w[back])
    visible = facing | back
    tri = tri[visible]
    values = np.einsum("nk,nkc->nc", w[visible], radiosity[mesh.triangle_receivers[tri]])
    out[np.nonzero(ok)[0][visible]] = values
    return out


def _reversed_weights(
    triangles: np.ndarray, hit: np.ndarray, twin: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """Barycentric weights of the same point in the twin triangle (corners permuted)."""
    out = np.zeros_like(weights)
    for k in range(3):
        match = triangles[twin] == triangles[hit][:, k : k + 1]
        out += match * weights[:, k : k + 1]
    return out


__all__ = ["shade", "triangle_normals", "twin_triangles"]
