"""Clusters of triangles inside each sub-area: a binary tree, so that the near field's
work per (receiver, sub-area) pair does not grow with the triangles a sub-area holds.

A receiver near a sub-area (within :data:`~raytrad.core.pairs.NEAR_FACTOR` of its sizes)
samples its visibility triangle by triangle, and one within
:data:`~raytrad.core.gather.MIDPOINT_SIZES` spreads its gather weight over every
triangle's corners. A sub-area is a fixed share of a patch (:class:`MeshSettings`
``samples``), so the triangles it holds grow with the receiver count, and with them that
work per pair: the near field as a whole grew as receivers squared. Here each sub-area of
more than :data:`CLUSTER_TRIANGLES` triangles is split in two at the median of its
triangles' centroids along its longest axis, and each half again, down to clusters of at
most that many. The near field then walks the tree and takes a cluster as one element
where the receiver is as far from it, in the cluster's own sizes, as the sub-area rule
asks of a sub-area: one disk-approximation sample and one ray for visibility, one
gather source (the cluster's mean, :class:`~raytrad.core.gather.SubareaMeans`) for the
spread. A receiver at distance ``d`` from a sub-area of size ``S > d`` then meets about
``2 pi k^2 ln(S / d)`` clusters at reach ``k``, not ``(S / h)^2`` triangles of size ``h``.

Sub-areas of at most :data:`CLUSTER_TRIANGLES` triangles are not split, so a mesh whose
sub-areas are all that small is sampled exactly as before (node ``s`` is sub-area ``s``).

References
----------
Hanrahan, P., Salzman, D., Aupperle, L. (1991). A rapid hierarchical radiosity
algorithm. SIGGRAPH '91, 197-206 (the same refinement criterion, an element's size
against its distance, on a tree of the receiving surface's elements).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from raytrad.arrays import corner_max, corner_mean, corner_min
from raytrad.core.kernels import disk_form_factor
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.refine import longest_edge

#: A sub-area (or cluster) of more triangles than this is split in two.
CLUSTER_TRIANGLES = 8


@dataclass(frozen=True)
class Clusters:
    """The cluster tree of every sub-area of a mesh.

    Nodes are grouped by patch (``patch_ptr``), and within a patch by sub-area; a
    sub-area that is not split is one node, and when none is, node ``s`` is sub-area
    ``s``. A node's triangles are the slots ``start:stop`` of ``sub_tri``.

    Attributes
    ----------
    sub_tri : (T,) int64
        The triangles grouped by sub-area (``sub_ptr``), each node's a contiguous run.
    sub_ptr : (SA + 1,) int64
        CSR pointers of the sub-areas into ``sub_tri``.
    root : (SA,) int64
        Each sub-area's node.
    start, stop : (N,) int64
        Each node's slots in ``sub_tri``.
    left, right : (N,) int64
        Its two halves, -1 for a leaf (at most :data:`CLUSTER_TRIANGLES` triangles).
    patch_ptr : (P + 1,) int64
        CSR pointers of the patches into the nodes.
    point : (N, 3) float64
        Sample point [m]: the sub-area's own for a root, else the centroid of the node's
        triangle nearest its area centroid.
    normal : (N, 3) float64
        The unit normal at ``point``.
    area : (N,) float64
        Area [m2].
    size : (N,) float64
        Bounding-box diagonal of the node's triangles [m].
    """

    sub_tri: np.ndarray
    sub_ptr: np.ndarray
    root: np.ndarray
    start: np.ndarray
    stop: np.ndarray
    left: np.ndarray
    right: np.ndarray
    patch_ptr: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    size: np.ndarray

    @property
    def count(self) -> int:
        """The number of nodes."""
        return len(self.start)

    @property
    def arrays(self) -> tuple[np.ndarray, ...]:
        """(sub_tri, start, stop, left, right, point, normal, area): the tree as the
        compiled walks take it (:mod:`raytrad.core._compiled_near`)."""
        return (
            self.sub_tri,
            self.start,
            self.stop,
            self.left,
            self.right,
            self.point,
            self.normal,
            self.area,
        )

    def cuts(
        self, nodes: np.ndarray, points: np.ndarray, scale: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """:func:`numpy_cuts` through this tree."""
        return numpy_cuts(
            nodes, points, scale, self.left, self.right, self.point, self.size, self.start
        )


def build_clusters(
    mesh: RadiosityMesh,
    sub_tri: np.ndarray,
    sub_ptr: np.ndarray,
    corners: np.ndarray | None = None,
) -> Clusters:
    """The cluster trees of ``mesh``'s sub-areas.

    Parameters
    ----------
    mesh : RadiosityMesh
    sub_tri, sub_ptr : (T,), (SA + 1,) int64
        The triangles grouped by sub-area (:func:`~raytrad.core.gather.subarea_triangles`);
        only runs of sub-areas that are split are reordered (a copy).
    corners : (T, 3, 3) float64 or None
        ``mesh.positions[mesh.triangles]`` when the caller has it [m].

    Returns
    -------
    Clusters
    """
    sub_tri = np.array(sub_tri, dtype=np.int64)
    if corners is None:
        corners = mesh.positions[mesh.triangles]
    centroid = corner_mean(corners)
    count = len(sub_ptr) - 1
    starts, stops, owners = [sub_ptr[:-1].astype(np.int64)], [sub_ptr[1:].astype(np.int64)], []
    owners.append(np.arange(count))
    levels = [np.zeros(count, np.int64)]
    parents = [np.full(count, -1, np.int64)]
    first = 0  # id of the first node of the current level (ids in creation order)
    level_start, level_stop, level_owner = starts[0], stops[0], owners[0]
    while True:
        split = np.flatnonzero(level_stop - level_start > CLUSTER_TRIANGLES)
        if not len(split):
            break
        lo, hi = level_start[split], level_stop[split]
        owner, slots = runs(lo, hi)
        points = centroid[sub_tri[slots]]
        offsets = np.concatenate([[0], np.cumsum(hi - lo)[:-1]])
        extent = np.maximum.reduceat(points, offsets) - np.minimum.reduceat(points, offsets)
        axis = longest_edge(extent)  # ties to the first axis, whatever the rounding
        key = points[np.arange(len(slots)), axis[owner]]
        order = np.lexsort((sub_tri[slots], key, owner))
        sub_tri[slots] = sub_tri[slots][order]
        middle = lo + (hi - lo) // 2
        ids = first + split
        # halves side by side: a left one's id is its right sibling's less one
        level_start = np.stack([lo, middle], axis=1).reshape(-1)
        level_stop = np.stack([middle, hi], axis=1).reshape(-1)
        level_owner = np.repeat(level_owner[split], 2)
        parents.append(np.repeat(ids, 2))
        first += len(starts[-1])
        starts.append(level_start)
        stops.append(level_stop)
        owners.append(level_owner)
        levels.append(np.full(len(level_start), len(levels)))
    start, stop = np.concatenate(starts), np.concatenate(stops)
    owner_sub, parent = np.concatenate(owners), np.concatenate(parents)
    level = np.concatenate(levels)
    # number the nodes by (sub-area, creation): sub-areas follow their patches
    order = np.lexsort((np.arange(len(start)), owner_sub))
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    start, stop, owner_sub = start[order], stop[order], owner_sub[order]
    parent, level = parent[order], level[order]
    left, right = _children(np.where(parent >= 0, rank[np.maximum(parent, 0)], -1))
    node_patch = mesh.subarea_patch[owner_sub]
    root = rank[:count]
    point, normal, area, size = _geometry(
        mesh, sub_tri, (start, stop, left, right, level), centroid, corners
    )
    point[root], normal[root] = mesh.subarea_point, mesh.subarea_normal
    size[root] = mesh.subarea_size
    return Clusters(
        sub_tri=sub_tri,
        sub_ptr=np.asarray(sub_ptr, np.int64),
        root=root,
        start=start,
        stop=stop,
        left=left,
        right=right,
        patch_ptr=np.searchsorted(node_patch, np.arange(mesh.patch_count + 1)).astype(np.int64),
        point=point,
        normal=normal,
        area=area,
        size=size,
    )


def runs(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For (K,) runs ``lo:hi``: the run of each of their slots and the slot, both
    (sum of lengths,) int64, run by run."""
    counts = hi - lo
    owner = np.repeat(np.arange(len(lo)), counts)
    slots = np.arange(len(owner)) + np.repeat(lo - np.cumsum(counts) + counts, counts)
    return owner, slots


def _children(parent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) left and right child of each node (-1: none), from each node's parent (the
    earlier-numbered of two siblings is the left one)."""
    left = np.full(len(parent), -1, np.int64)
    right = np.full(len(parent), -1, np.int64)
    child = np.flatnonzero(parent >= 0)  # ascending: the left child comes first
    is_left = np.ones(len(child), bool)
    is_left[1:] = parent[child[1:]] != parent[child[:-1]]
    left[parent[child[is_left]]] = child[is_left]
    right[parent[child[~is_left]]] = child[~is_left]
    return left, right


def _geometry(
    mesh: RadiosityMesh,
    sub_tri: np.ndarray,
    clusters: tuple[np.ndarray, ...],
    centroid: np.ndarray,
    corners: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each node's sample point, normal, area and size (:class:`Clusters`), leaves from
    their triangles and the others from their halves, deepest first: one pass over the
    triangles, whatever the depth (``centroid`` (T, 3) and ``corners`` (T, 3, 3) the
    triangles')."""
    start, stop, left, right, level = clusters
    tri_area = mesh.triangle_area[sub_tri]
    cum_area = np.concatenate([[0.0], np.cumsum(tri_area)])
    moment = np.cumsum(tri_area[:, None] * centroid[sub_tri], axis=0)
    cum_moment = np.concatenate([np.zeros((1, 3)), moment])
    area = cum_area[stop] - cum_area[start]
    middle = (cum_moment[stop] - cum_moment[start]) / np.maximum(area, 1e-300)[:, None]
    leaf = np.flatnonzero(left < 0)
    leaf = leaf[np.argsort(start[leaf])]  # the leaves cover the slots once, in order
    offsets = start[leaf]
    lo, hi = np.empty((len(start), 3)), np.empty((len(start), 3))
    lo[leaf] = np.minimum.reduceat(corner_min(corners)[sub_tri], offsets)
    hi[leaf] = np.maximum.reduceat(corner_max(corners)[sub_tri], offsets)
    owner = np.repeat(np.arange(len(leaf)), stop[leaf] - start[leaf])
    distance = np.linalg.norm(centroid[sub_tri] - middle[leaf][owner], axis=1)
    nearest = _first_nearest(distance, owner, offsets)
    point = np.empty((len(start), 3))
    chosen = np.empty(len(start), np.int64)
    chosen[leaf] = sub_tri[nearest]
    point[leaf] = centroid[chosen[leaf]]
    for depth in range(int(level.max(initial=0)), -1, -1):
        inner = np.flatnonzero((level == depth) & (left >= 0))
        a, b = left[inner], right[inner]
        lo[inner] = np.minimum(lo[a], lo[b])
        hi[inner] = np.maximum(hi[a], hi[b])
        # of the halves' points, the one nearer the node's area centroid
        pick = np.where(
            np.linalg.norm(point[a] - middle[inner], axis=1)
            <= np.linalg.norm(point[b] - middle[inner], axis=1),
            a,
            b,
        )
        chosen[inner] = chosen[pick]
        point[inner] = point[pick]
    return point, mesh.triangle_normal[chosen], area, np.linalg.norm(hi - lo, axis=1)


def _first_nearest(distance: np.ndarray, owner: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """For runs of slots (``owner`` (N,) ascending, each run non-empty and starting at
    ``offsets``), the slot of each run's smallest ``distance``, the first on ties: what
    ``np.lexsort((np.arange(N), distance, owner))[offsets]`` gives, without sorting."""
    hit = np.flatnonzero(distance == np.minimum.reduceat(distance, offsets)[owner])
    first = np.ones(len(hit), dtype=bool)
    first[1:] = owner[hit[1:]] != owner[hit[:-1]]
    return hit[first]


def numpy_cuts(
    nodes: np.ndarray,
    points: np.ndarray,
    scale: float,
    left: np.ndarray,
    right: np.ndarray,
    node_point: np.ndarray,
    node_size: np.ndarray,
    node_start: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The clusters a point takes whole below a node, and the leaves it takes triangle by
    triangle (compiled in the near-field loops; this is their reference).

    Below element ``k``'s node, a node with halves is taken whole where ``points[k]`` is
    farther than ``scale`` of its sizes from its sample point, else split; a leaf is
    taken as its triangles. The element's own node is never taken whole.

    Parameters
    ----------
    nodes : (K,) int64
        Each element's node.
    points : (K, 3) float64
        Each element's receiver [m].
    scale : float
        Distance in node sizes beyond which a node is taken whole.
    left, right, node_point, node_size, node_start : arrays of :class:`Clusters`

    Returns
    -------
    element : (M,) int64
        Ascending; within one, the items in the order of their triangles' slots.
    item : (M,) int64
        A node taken whole (>= 0), or ``-1 - leaf`` for a leaf's triangles.
    """
    element, node = np.arange(len(nodes)), np.asarray(nodes, np.int64)
    found_element, found_item, found_slot = [], [], []
    own = True
    while len(node):
        inner = left[node] >= 0
        whole = np.zeros(len(node), bool)
        if not own:
            d = points[element] - node_point[node]
            whole = inner & (np.sqrt(np.einsum("kj,kj->k", d, d)) > scale * node_size[node])
        found_element += [element[whole], element[~inner]]
        found_item += [node[whole], -1 - node[~inner]]
        found_slot += [node_start[node[whole]], node_start[node[~inner]]]
        split = inner & ~whole
        element = np.repeat(element[split], 2)
        node = np.stack([left[node[split]], right[node[split]]], axis=1).reshape(-1)
        own = False
    element = np.concatenate([np.zeros(0, np.int64), *found_element])
    item = np.concatenate([np.zeros(0, np.int64), *found_item])
    order = np.lexsort((np.concatenate([np.zeros(0, np.int64), *found_slot]), element))
    return element[order], item[order]


def disk_factors(
    points: np.ndarray,
    normals: np.ndarray,
    node_point: np.ndarray,
    node_normal: np.ndarray,
    node_area: np.ndarray,
) -> np.ndarray:
    """(K,) disk-approximation factors ``cos cos A / (pi r^2 + A)`` of (K,) nodes seen
    from (K, 3) ``points`` with unit ``normals``, 0 where either side faces away (as the
    sub-area samples of :func:`~raytrad.core.kernels.sample_weights`)."""
    d = node_point - points
    r2 = np.einsum("kj,kj->k", d, d)
    r = np.sqrt(r2)
    inv_r = 1.0 / np.where(r > 0, r, 1.0)
    cos_r = np.einsum("kj,kj->k", d, normals) * inv_r
    cos_s = -np.einsum("kj,kj->k", d, node_normal) * inv_r
    facing = (cos_r > 0) & (cos_s > 0)
    return np.where(facing, disk_form_factor(cos_r, cos_s, r2, node_area), 0.0)
