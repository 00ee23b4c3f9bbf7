"""Refining and partitioning triangle meshes: vertex merging, conforming refinement,
smooth surfaces and bisection clusters. Flat arrays in, flat arrays out.

Every tie is broken the same way whatever the model's units or placement
(:data:`~raytrad.constants.tol` ``.tie``), so the same scene gives the same mesh.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import tol
from raytrad.scene import triangle_areas_normals

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------
# Vertices and refinement
# --------------------------------------------------------------------------------------


def merge_vertices(
    positions: np.ndarray, triangles: np.ndarray, tolerance: float
) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices closer than about ``tolerance`` (quantised to a grid of that pitch).

    Returns
    -------
    positions : (V', 3) float64
    triangles : (T, 3) int64, re-indexed
    """
    used = unique(triangles)
    key = np.round((positions[used] - positions[used].min(axis=0)) / tolerance).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    remap = np.full(positions.shape[0], -1, dtype=np.int64)
    remap[used] = inverse.reshape(-1)
    return positions[used[first]], remap[triangles]


def edge_keys(a: np.ndarray, b: np.ndarray, count: int) -> np.ndarray:
    """One int64 per undirected edge (a, b) of vertices below ``count``: the same for (b, a),
    and sorting the keys sorts the (low, high) pairs."""
    return np.minimum(a, b) * count + np.maximum(a, b)


def unique_edges(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges and, per triangle, the index of edge k = (v_k, v_{k+1})."""
    count = int(triangles.max()) + 1 if triangles.size else 1
    keys = edge_keys(triangles, np.roll(triangles, -1, axis=1), count)  # (T, 3)
    distinct, inverse = np.unique(keys.reshape(-1), return_inverse=True)
    edges = np.stack([distinct // count, distinct % count], axis=1)
    return edges, inverse.reshape(-1, 3)


def refine(
    positions: np.ndarray,
    triangles: np.ndarray,
    max_edge: float | np.ndarray,
    max_rounds: int = 40,
    quiet: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Conforming refinement until no edge is longer than ``max_edge``.

    Edges are split at their midpoints, once per unique edge, so triangles that share an
    edge stay conforming (no T-junctions are created). Whenever a triangle has a split
    edge its longest edge is split too (longest-edge closure), which keeps the triangles
    from degrading: 1 split edge bisects, 2 give three triangles, 3 give four similar ones.

    Parameters
    ----------
    positions : (V, 3) float64 [m]
    triangles : (T, 3) int64
    max_edge : float or (T,) float [m]
        Longest edge allowed, overall or per input triangle (an edge shared by two
        triangles takes the smaller limit, so the mesh stays conforming).
    max_rounds : int
        Most rounds of splitting (each round splits every marked edge once).
    quiet : bool
        Do not warn when the rounds run out (a deliberate single round, say).

    Returns
    -------
    positions : (V', 3) float64
    triangles : (T', 3) int64, same winding as their parents
    parent : (T',) int64, the input triangle each output triangle lies in
    """
    positions = np.asarray(positions, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    parent = np.arange(triangles.shape[0])
    limit = np.broadcast_to(np.asarray(max_edge, dtype=np.float64), parent.shape)
    for _ in range(max_rounds):
        edges, tri_edges = unique_edges(triangles)
        length = np.linalg.norm(positions[edges[:, 1]] - positions[edges[:, 0]], axis=1)
        edge_limit = np.full(len(edges), np.inf)
        np.minimum.at(edge_limit, tri_edges.reshape(-1), np.repeat(limit[parent], 3))
        marked = length > edge_limit
        if not marked.any():
            break
        longest = longest_edge(length[tri_edges])
        longest_index = tri_edges[np.arange(len(triangles)), longest]
        while True:  # longest-edge closure
            needs = marked[tri_edges].any(axis=1) & ~marked[longest_index]
            if not needs.any():
                break
            marked[longest_index[needs]] = True
        midpoint_index = np.full(len(edges), -1, dtype=np.int64)
        midpoint_index[marked] = positions.shape[0] + np.arange(int(marked.sum()))
        midpoints = 0.5 * (positions[edges[marked, 0]] + positions[edges[marked, 1]])
        positions = np.concatenate([positions, midpoints])
        triangles, keep = _split_triangles(triangles, tri_edges, longest, midpoint_index)
        parent = parent[keep]
    else:
        if not quiet:
            log.warning("refinement stopped after %d rounds", max_rounds)
    return positions, triangles, parent


def refined_count_bound(corners: np.ndarray, max_edge: float | np.ndarray) -> float:
    """An upper bound on the triangles :func:`refine` makes of these triangles.

    Midpoint splitting halves every edge of a triangle each round at most, so a triangle
    whose longest edge is ``L`` needs ``k = ceil(log2(L / max_edge))`` rounds and ends as at
    most ``4**k`` triangles. For a sliver that is the count indeed (its pieces stay
    slivers), far above what its area suggests: one stray vertex 5e8 m away makes a
    triangle worth 1e11 of them.

    Parameters
    ----------
    corners : (T, 3, 3) float [m]
    max_edge : float or (T,) float [m]

    Returns
    -------
    float
        The sum of ``4**k`` over the triangles (inf when it overflows).
    """
    lengths = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        rounds = np.ceil(np.log2(np.maximum(lengths / max_edge, 1.0)))
        return float(np.sum(4.0**rounds))


def longest_edge(lengths: np.ndarray) -> np.ndarray:
    """(T,) index of each row's largest entry, ties (to ``tol.tie`` relative) to the first.

    Rounding must not decide: the two legs of an isosceles triangle are equal up to the
    last bit, and which one wins would change with the model's units or position, and the
    whole refinement with it.
    """
    relative = lengths / np.maximum(lengths.max(axis=1, keepdims=True), 1e-300)
    return np.argmax(np.round(relative / tol.tie), axis=1)


def _split_triangles(
    triangles: np.ndarray, tri_edges: np.ndarray, longest: np.ndarray, midpoint: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Split each triangle by the midpoints of its marked edges (see :func:`refine`)."""
    t = np.arange(len(triangles))
    # Rotate so that the longest edge is edge 0 = (a, b), c opposite; winding is kept.
    rot = (longest[:, None] + np.arange(3)[None, :]) % 3
    a, b, c = (triangles[t[:, None], rot][:, k] for k in range(3))
    e = tri_edges[t[:, None], rot]
    m0, m1, m2 = midpoint[e[:, 0]], midpoint[e[:, 1]], midpoint[e[:, 2]]
    s0, s1, s2 = m0 >= 0, m1 >= 0, m2 >= 0
    none = ~s0
    only0 = s0 & ~s1 & ~s2
    with1 = s0 & s1 & ~s2
    with2 = s0 & ~s1 & s2
    red = s0 & s1 & s2
    pieces = [
        (none, [(a, b, c)]),
        (only0, [(a, m0, c), (m0, b, c)]),
        (with1, [(a, m0, c), (m0, b, m1), (m0, m1, c)]),
        (with2, [(m0, b, c), (a, m0, m2), (m0, c, m2)]),
        (red, [(a, m0, m2), (m0, b, m1), (m2, m1, c), (m0, m1, m2)]),
    ]
    out, keep = [], []
    for mask, tris in pieces:
        idx = np.nonzero(mask)[0]
        for p, q, r in tris:
            out.append(np.stack([p[idx], q[idx], r[idx]], axis=1))
            keep.append(idx)
    return np.concatenate(out), np.concatenate(keep)


def max_edge_for_receivers(total_area: float, receivers: int) -> float:
    """The edge length whose near-equilateral mesh has about ``receivers`` vertices.

    A mesh of equilateral triangles of edge h has about 2 / (sqrt(3) / 4 h^2) / ... that is,
    twice as many triangles as vertices, so V ~ A / (sqrt(3) / 2 * h^2). Refinement splits
    edges at midpoints, so the realised edge lies in (h/2, h]; 1.5 compensates on average.
    """
    return math.sqrt(total_area / (receivers * math.sqrt(3.0) / 2.0)) * 1.5


# --------------------------------------------------------------------------------------
# Surfaces
# --------------------------------------------------------------------------------------


def connected_labels(count: int, pairs: np.ndarray) -> np.ndarray:
    """Connected-component labels of ``count`` nodes joined by ``pairs`` ((E, 2) int).

    Hook-and-shortcut union-find, vectorised; labels are consecutive from 0.
    """
    parent = np.arange(count)
    if len(pairs):
        while True:
            a, b = parent[pairs[:, 0]], parent[pairs[:, 1]]
            differ = a != b
            if not differ.any():
                break
            lo, hi = np.minimum(a, b)[differ], np.maximum(a, b)[differ]
            np.minimum.at(parent, hi, lo)
            while True:
                jumped = parent[parent]
                if np.array_equal(jumped, parent):
                    break
                parent = jumped
    return np.unique(parent, return_inverse=True)[1].reshape(-1)


def surface_labels(
    positions: np.ndarray, triangles: np.ndarray, material: np.ndarray, crease_angle: float
) -> np.ndarray:
    """Label triangles that form one smooth surface of one material.

    Two triangles sharing an edge belong to the same surface when their materials match and
    their normals differ by less than ``crease_angle`` degrees (opposite-facing copies of a
    double-sided face never do).

    Returns
    -------
    (T,) int64 surface label per triangle.
    """
    _, normals = triangle_areas_normals(positions[triangles])
    _edges, tri_edges = unique_edges(triangles)
    owner = np.repeat(np.arange(len(triangles)), 3)
    order = np.argsort(tri_edges.reshape(-1), kind="stable")
    sorted_edges = tri_edges.reshape(-1)[order]
    # consecutive owners of the same edge form candidate pairs (covers non-manifold edges)
    same = sorted_edges[1:] == sorted_edges[:-1]
    t0, t1 = owner[order][:-1][same], owner[order][1:][same]
    cos_limit = math.cos(math.radians(crease_angle))
    smooth = (np.einsum("ij,ij->i", normals[t0], normals[t1]) >= cos_limit) & (
        material[t0] == material[t1]
    )
    return connected_labels(len(triangles), np.stack([t0[smooth], t1[smooth]], axis=1))


# --------------------------------------------------------------------------------------
# Clustering triangles into patches and sub-areas
# --------------------------------------------------------------------------------------


def cluster_bounds(points: np.ndarray, labels: np.ndarray, count: int) -> tuple[np.ndarray, ...]:
    lo = np.full((count, 3), np.inf)
    hi = np.full((count, 3), -np.inf)
    np.minimum.at(lo, labels, points)
    np.maximum.at(hi, labels, points)
    return lo, hi


def bisect_clusters(
    centroids: np.ndarray,
    labels: np.ndarray,
    split: Callable[[np.ndarray, np.ndarray], np.ndarray],
    max_rounds: int = 64,
) -> np.ndarray:
    """Split clusters of points in half along their longest axis while ``split`` asks.

    Parameters
    ----------
    centroids : (N, 3) float64
        One point per item (triangle centroids) [m].
    labels : (N,) int64
        Initial cluster of each item.
    split : callable
        ``split(labels, extent) -> (C,) bool``: which of the C current clusters to split,
        given their bounding-box extents ((C, 3) float64).

    Returns
    -------
    (N,) int64 cluster labels, consecutive from 0.
    """
    labels = np.unique(labels, return_inverse=True)[1].reshape(-1)
    for _ in range(max_rounds):
        count = int(labels.max()) + 1
        lo, hi = cluster_bounds(centroids, labels, count)
        extent = hi - lo
        want = split(labels, extent) & (extent.max(axis=1) > 0)
        if not want.any():
            break
        axis = longest_edge(extent)  # ties between axes broken the same way
        middle = 0.5 * (lo + hi)[np.arange(count), axis]
        item_axis = axis[labels]
        # a centroid within tol.tie of the cluster size of the middle counts as below it,
        # so the split does not depend on rounding (units, far-from-origin placement)
        margin = tol.tie * extent.max(axis=1)
        upper = want[labels] & (
            centroids[np.arange(len(labels)), item_axis] > middle[labels] + margin[labels]
        )
        new_label = count + np.cumsum(want) - 1
        labels = np.where(upper, new_label[labels], labels)
        labels = np.unique(labels, return_inverse=True)[1].reshape(-1)
    return labels


def group_sorted(labels: np.ndarray) -> np.ndarray:
    """Relabel so that labels are consecutive and sorted by the first item's position."""
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[inverse.reshape(-1)]
