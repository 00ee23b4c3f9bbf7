"""Fixing what CAD export and hand modelling get wrong, with a warning for each fix.

* **T-junctions**: a vertex lying inside another triangle's edge splits that triangle, so
  surfaces conform (no light or shadow leaks along the seam, and winding can be compared).
* **Duplicate faces**: the same triangle twice, or a coplanar face lying on an earlier one
  facing the same way (the same quad triangulated twice), would receive and shoot twice,
  doubling the light it sends. One copy is kept. A copy with the opposite winding is the
  other side of a two-sided surface and stays.
* **Inverted faces**: in a connected, edge-sharing surface (a closed room, a block), every
  shared edge is walked in opposite directions by its two faces. Faces whose winding
  disagrees with the larger part (by area) of their surface were modelled inside out: a room
  wall facing outside would swallow all the light reaching its back. They are flipped.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import scene_extent, tol
from raytrad.core.refine import merge_vertices, unique_edges
from raytrad.scene import Scene, triangle_areas_normals

log = logging.getLogger(__name__)


def repair_scene(scene: Scene) -> Scene:
    """The scene without duplicate faces and with consistent winding (see module doc)."""
    extent = scene_extent(scene.positions[unique(scene.triangles)])
    where = scene.source or "<scene>"
    scene = _split_t_junctions(scene, extent, where)
    _, merged = merge_vertices(scene.positions, scene.triangles, extent * tol.merge)
    keep = _first_of_duplicates(merged) & ~_covered_by_earlier(scene, extent)
    if not keep.all():
        log.warning(
            "%s: dropped %d duplicate faces (the same triangle twice would double its light)",
            where,
            int((~keep).sum()),
        )
        scene = scene.select(keep)
        merged = merged[keep]
    areas, _ = triangle_areas_normals(scene.triangle_vertices())
    flip = inverted_faces(merged, areas)
    if flip.any():
        log.warning(
            "%s: flipped %d faces whose winding disagrees with the rest of their surface "
            "(inside-out faces would swallow the light reaching their back)",
            where,
            int(flip.sum()),
        )
        scene = scene.flipped(flip)
    return scene


def _first_of_duplicates(triangles: np.ndarray) -> np.ndarray:
    """(T,) bool: True for the first face of each set with the same corners and winding."""
    # the same cyclic order starting from the smallest vertex identifies a winding
    start = np.argmin(triangles, axis=1)
    order = (start[:, None] + np.arange(3)[None, :]) % 3
    canonical = np.take_along_axis(triangles, order, axis=1)
    _, first = np.unique(canonical, axis=0, return_index=True)
    keep = np.zeros(len(triangles), dtype=bool)
    keep[first] = True
    return keep


def inverted_faces(triangles: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """(T,) bool: faces to flip so each edge-connected surface has one winding.

    Two faces sharing an edge (and only two: non-manifold edges carry no constraint) agree
    when they walk it in opposite directions. Orientation parity is propagated over the
    agreement graph; within each connected part the parity class with less area flips.

    Parameters
    ----------
    triangles : (T, 3) int64
        Faces over merged vertices.
    areas : (T,) float64
        Face areas [m2].
    """
    count = len(triangles)
    a = triangles.reshape(-1)
    b = np.roll(triangles, -1, axis=1).reshape(-1)
    key = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    forward = a < b
    face = np.repeat(np.arange(count), 3)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    manifold = counts[inverse] == 2
    order = np.argsort(inverse[manifold], kind="stable")
    f = face[manifold][order].reshape(-1, 2)
    d = forward[manifold][order].reshape(-1, 2)
    # same direction along the shared edge means the two windings disagree
    disagree = d[:, 0] == d[:, 1]
    label, parity = _parity_components(count, f, disagree)
    flip = np.zeros(count, dtype=bool)
    for part in unique(label[parity == 1]):
        members = label == part
        odd = members & (parity == 1)
        if areas[odd].sum() < areas[members & (parity == 0)].sum():
            flip |= odd
        else:
            flip |= members & (parity == 0)
    return flip


def _parity_components(
    count: int, pairs: np.ndarray, odd: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Connected components of faces, and each face's parity relative to its root.

    Breadth-first over the pair graph, vectorised by frontier; parity(b) = parity(a) xor odd.
    """
    label = np.full(count, -1, dtype=np.int64)
    parity = np.zeros(count, dtype=np.int8)
    if len(pairs) == 0:
        return np.arange(count), parity
    both = np.concatenate([pairs, pairs[:, ::-1]])
    both_odd = np.concatenate([odd, odd]).astype(np.int8)
    order = np.argsort(both[:, 0], kind="stable")
    src, dst, rel = both[order, 0], both[order, 1], both_odd[order]
    ptr = np.searchsorted(src, np.arange(count + 1))
    isolated = ptr[1:] == ptr[:-1]
    label[isolated] = np.nonzero(isolated)[0]
    for root in np.nonzero(~isolated)[0]:
        if label[root] >= 0:
            continue
        label[root] = root
        frontier = np.array([root])
        while len(frontier):
            starts, stops = ptr[frontier], ptr[frontier + 1]
            n = stops - starts
            idx = np.repeat(starts, n) + (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n))
            nxt, p = dst[idx], parity[src[idx]] ^ rel[idx]
            new = label[nxt] < 0
            nxt, p = nxt[new], p[new]
            nxt, first = np.unique(nxt, return_index=True)
            label[nxt] = root
            parity[nxt] = p[first]
            frontier = nxt
    return label, parity


#: Largest vertex x edge (and coplanar-group) work done to find T-junctions and overlaps.
_REPAIR_WORK_LIMIT = 50_000_000


def _split_t_junctions(scene: Scene, extent: float, where: object) -> Scene:
    """Split triangles whose edges pass through another vertex (to ``tol.on_edge`` x extent).

    Each half keeps its parent's material and object; lightmap UVs of the new corner are
    interpolated along the split edge.
    """
    positions, triangles = merge_vertices(scene.positions, scene.triangles, extent * tol.merge)
    parent = np.arange(len(triangles))  # scene triangle of each current triangle
    uv = scene.lightmap_uv
    total = 0
    for _ in range(32):
        edges, tri_edges = unique_edges(triangles)
        if len(positions) * len(edges) > _REPAIR_WORK_LIMIT:
            log.info("%s: too large to look for T-junctions", where)
            break
        split_vertex = _vertex_inside_edges(positions, edges, tol.on_edge * extent)
        split_vertex = _same_surface_only(positions, triangles, edges, tri_edges, split_vertex)
        if not (split_vertex >= 0).any():
            break
        # split each triangle at the first of its edges that has a vertex inside
        has = split_vertex[tri_edges] >= 0
        which = np.argmax(has, axis=1)
        todo = np.nonzero(has.any(axis=1))[0]
        k = which[todo]
        t = triangles[todo]
        a, b, c = (
            t[np.arange(len(t)), k],
            t[np.arange(len(t)), (k + 1) % 3],
            t[np.arange(len(t)), (k + 2) % 3],
        )
        v = split_vertex[tri_edges[todo, k]]
        keep = np.ones(len(triangles), dtype=bool)
        keep[todo] = False
        triangles = np.concatenate(
            [triangles[keep], np.stack([a, v, c], 1), np.stack([v, b, c], 1)]
        )
        parent = np.concatenate([parent[keep], parent[todo], parent[todo]])
        if uv is not None:
            uv = np.concatenate([uv[keep], *_split_uvs(uv[todo], k, positions, a, b, v)])
        total += len(todo)
    if total == 0:
        return scene
    log.warning(
        "%s: split %d faces at T-junctions (vertices inside other faces' edges)", where, total
    )
    return replace(scene.select(parent), positions=positions, triangles=triangles, lightmap_uv=uv)


def _split_uvs(
    uv: np.ndarray,
    k: np.ndarray,
    positions: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    v: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Corner UVs of the halves (a, v, c) and (v, b, c) of triangles split on edge k.

    Parameters
    ----------
    uv : (N, 3, 2) float
        Corner UVs of the split triangles, in their corner order.
    k : (N,) int
        The split edge runs from corner ``k`` (``a``) to corner ``k + 1`` (``b``).
    positions : (V, 3) float [m]
    a, b, v : (N,) int
        Vertex indices of the edge ends and of the vertex on the edge.

    Returns
    -------
    two (N, 3, 2) float64
    """
    rows = np.arange(len(uv))
    ua, ub, uc = uv[rows, k], uv[rows, (k + 1) % 3], uv[rows, (k + 2) % 3]
    edge = positions[b] - positions[a]
    t = np.einsum("ij,ij->i", positions[v] - positions[a], edge) / np.einsum("ij,ij->i", edge, edge)
    uv_v = ua + t[:, None] * (ub - ua)
    return np.stack([ua, uv_v, uc], 1), np.stack([uv_v, ub, uc], 1)


def _same_surface_only(
    positions: np.ndarray,
    triangles: np.ndarray,
    edges: np.ndarray,
    tri_edges: np.ndarray,
    split_vertex: np.ndarray,
) -> np.ndarray:
    """Keep a T-vertex only if a face using it lies in the plane of a face using the edge.

    A block's corner touching the floor's diagonal is not a T-junction of the floor.
    """
    _, normal = triangle_areas_normals(positions[triangles])
    edge_faces = np.repeat(np.arange(len(triangles)), 3)
    out = split_vertex.copy()
    for e in np.nonzero(split_vertex >= 0)[0]:
        faces = edge_faces[tri_edges.reshape(-1) == e]
        users = np.nonzero((triangles == split_vertex[e]).any(axis=1))[0]
        # v lies on the edge, so a user face parallel to an edge face shares its plane
        if not (np.abs(normal[faces] @ normal[users].T) > 1.0 - tol.parallel).any():
            out[e] = -1
    return out


def _vertex_inside_edges(positions: np.ndarray, edges: np.ndarray, tolerance: float) -> np.ndarray:
    """(E,) index of a vertex strictly inside each edge (closest to its middle), else -1."""
    used = unique(edges)
    points = positions[used]
    out = np.full(len(edges), -1, dtype=np.int64)
    chunk = max(1, 2_000_000 // max(len(points), 1))
    for start in range(0, len(edges), chunk):
        e = edges[start : start + chunk]
        a, b = positions[e[:, 0]], positions[e[:, 1]]
        d = b - a
        length2 = np.einsum("ij,ij->i", d, d)
        t = np.einsum("pj,ej->ep", points, d) - np.einsum("ej,ej->e", a, d)[:, None]
        t = t / np.maximum(length2, 1e-300)[:, None]
        closest = a[:, None, :] + t[..., None] * d[:, None, :]
        distance = np.linalg.norm(points[None, :, :] - closest, axis=2)
        length = np.sqrt(length2)[:, None]
        inside = (distance < tolerance) & (t * length > tolerance) & ((1 - t) * length > tolerance)
        score = np.where(inside, np.abs(t - 0.5), np.inf)
        best = np.argmin(score, axis=1)
        found = np.isfinite(score[np.arange(len(e)), best])
        out[start : start + chunk] = np.where(found, used[best], -1)
    return out


def _covered_by_earlier(scene: Scene, extent: float) -> np.ndarray:
    """(T,) bool: faces whose centroid lies on an earlier coplanar face facing the same way."""
    corners = scene.triangle_vertices()
    _, normal = triangle_areas_normals(corners)
    offset = np.einsum("ij,ij->i", normal, corners[:, 0])
    key = np.column_stack(
        [np.round(normal * 1e6), np.round(offset / max(extent, 1e-300) * 1e7)]
    ).astype(np.int64)
    _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.reshape(-1)
    covered = np.zeros(len(corners), dtype=bool)
    counts = np.bincount(group)
    for g in np.nonzero(counts > 1)[0]:
        members = np.nonzero(group == g)[0]
        if len(members) ** 2 > _REPAIR_WORK_LIMIT:
            continue
        centroid = corners[members].mean(axis=1)
        inside = _points_in_triangles(centroid, corners[members], normal[members[0]])
        earlier = np.tril(inside, k=-1)  # point i inside an earlier triangle j < i
        covered[members[earlier.any(axis=1)]] = True
    return covered


def _points_in_triangles(
    points: np.ndarray, triangles: np.ndarray, normal: np.ndarray
) -> np.ndarray:
    """(N, M) bool: point i inside or on triangle j (all coplanar, unit normal given).

    On the boundary counts: the centroid of one diagonal's half of a quad lies on the
    other diagonal, the shared edge of the earlier copy's two halves.
    """
    inside = np.ones((len(points), len(triangles)), dtype=bool)
    for k in range(3):
        a, b = triangles[:, k], triangles[:, (k + 1) % 3]
        edge = np.cross(b - a, normal)  # points outward for counter-clockwise triangles
        side = np.einsum("pj,tj->pt", points, edge) - np.einsum("tj,tj->t", a, edge)[None, :]
        scale = np.linalg.norm(edge, axis=1)[None, :]
        inside &= side <= tol.parallel * scale * np.linalg.norm(b - a, axis=1)[None, :]
    return inside
