"""The outline of each patch: its distinct vertices and its boundary edges, for the exact
(contour-integral) unoccluded form factor of :mod:`raytrad.core.formfactor`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import tol
from raytrad.core.mesh import RadiosityMesh


def group(labels: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Items sorted by label, and CSR pointers ((count + 1,) int64) into them."""
    order = np.argsort(labels, kind="stable")
    return order, np.searchsorted(labels[order], np.arange(count + 1))


def patch_vertices(mesh: RadiosityMesh) -> tuple[np.ndarray, np.ndarray]:
    """The distinct vertices of each patch's triangles, grouped by patch (CSR)."""
    stride = np.int64(len(mesh.positions))
    key = unique(
        np.repeat(mesh.triangle_patch, 3).astype(np.int64) * stride + mesh.triangles.reshape(-1)
    )
    patch = key // stride  # sorted by patch, then vertex
    return key % stride, np.searchsorted(patch, np.arange(mesh.patch_count + 1))


def boundary_edges(
    mesh: RadiosityMesh, labels: np.ndarray | None = None, count: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Oriented boundary edges of each patch: edges used by one of its triangles only.

    Consecutive collinear boundary edges are merged (Lambert's sum is additive along a
    straight edge), so a refined rectangular patch has 4 edges however fine its triangles.

    Parameters
    ----------
    mesh : RadiosityMesh
    labels, count : (T,) int64 and int, optional
        Other groups of triangles to outline instead of the patches (label -1: none), and
        their count (default: the largest label + 1).

    Returns
    -------
    start, end : (E, 3) float64, edge endpoints [m], in the winding of their triangle
    pointer : (P + 1,) int64, CSR pointers by patch (by label)
    """
    if labels is None:
        labels, count = mesh.triangle_patch, mesh.patch_count
    elif count is None:
        count = int(labels.max(initial=-1)) + 1
    tri = mesh.triangles[labels >= 0]
    a = tri.reshape(-1)
    b = np.roll(tri, -1, axis=1).reshape(-1)
    patch = np.repeat(labels[labels >= 0], 3)
    single = _row_counts(patch, np.minimum(a, b), np.maximum(a, b)) == 1
    order = np.argsort(patch[single], kind="stable")
    a, b, patch = a[single][order], b[single][order], patch[single][order]
    a, b, patch = _merge_collinear(mesh.positions, a, b, patch)
    pointer = np.searchsorted(patch, np.arange(count + 1))
    return mesh.positions[a], mesh.positions[b], pointer


def _row_counts(*columns: np.ndarray) -> np.ndarray:
    """(N,) int64: how many rows of the integer ``columns`` equal each row (a row-wise
    ``np.unique(..., return_counts=True)`` read back per row, by one lexicographic sort)."""
    order = np.lexsort(columns[::-1])
    change = np.zeros(len(order), dtype=bool)
    change[:1] = True
    for column in columns:
        ranked = column[order]
        change[1:] |= ranked[1:] != ranked[:-1]
    run = np.cumsum(change) - 1
    out = np.empty(len(order), dtype=np.int64)
    out[order] = np.bincount(run)[run]
    return out


@dataclass(frozen=True)
class Pieces:
    """The planar pieces of folded patches (a warped quad's two triangles), each outlined.

    Attributes
    ----------
    start, end : (E, 3) float64
        Pieces' oriented boundary edges [m].
    edge_ptr : (K + 1,) int64
        CSR pointers into the edges by piece.
    point, normal : (K, 3) float64
        A corner of each piece [m] and its unit normal.
    patch_ptr : (P + 1,) int64
        CSR pointers into the pieces by patch (none for planar patches).
    twin_piece : (E,) int64
        For each edge, the piece of the same patch that has the same edge the other way
        (its neighbour across it), or -1: the patch's outline, or a neighbour whose
        edges run there in other pieces.
    """

    start: np.ndarray
    end: np.ndarray
    edge_ptr: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    patch_ptr: np.ndarray
    twin_piece: np.ndarray


def folded_pieces(mesh: RadiosityMesh) -> Pieces:
    """Each folded patch's triangles grouped by the scene triangle they refine (one plane
    each), with the pieces' outlines (:func:`boundary_edges`)."""
    folded = ~np.asarray(mesh.patch_planar, bool)[mesh.triangle_patch]
    key = mesh.triangle_patch * (int(mesh.triangle_source.max(initial=0)) + 1)
    key = key + mesh.triangle_source
    distinct, first, inverse = np.unique(key[folded], return_index=True, return_inverse=True)
    labels = np.full(len(key), -1, np.int64)
    labels[folded] = inverse.reshape(-1)
    start, end, edge_ptr = boundary_edges(mesh, labels, len(distinct))
    own = np.flatnonzero(folded)[first]  # a triangle of each piece
    piece_patch = mesh.triangle_patch[own]
    edge_piece = np.repeat(np.arange(len(distinct)), np.diff(edge_ptr))
    return Pieces(
        start,
        end,
        edge_ptr,
        mesh.positions[mesh.triangles[own, 0]],
        mesh.triangle_normal[own],
        np.searchsorted(piece_patch, np.arange(mesh.patch_count + 1)),
        _twin_pieces(start, end, edge_piece, piece_patch[edge_piece]),
    )


def _twin_pieces(
    start: np.ndarray, end: np.ndarray, piece: np.ndarray, patch: np.ndarray
) -> np.ndarray:
    """(E,) for each edge the piece whose edge of the same patch runs exactly the other way
    (the same two points, bit for bit), or -1. Only pairs that match one to one count: an
    edge three pieces meet at (a non-manifold fold) gets no twin, so that the region sum
    skips only edges whose two ways both drop out."""
    forward = np.concatenate([patch[:, None], start, end], axis=1)
    backward = np.concatenate([patch[:, None], end, start], axis=1)
    both = np.concatenate([forward, backward])
    order = np.lexsort(both.T[::-1])
    ranked = both[order]
    same = np.zeros(len(both), dtype=bool)
    same[1:] = (ranked[1:] == ranked[:-1]).all(axis=1)
    group = np.cumsum(~same) - 1
    label = np.empty(len(both), dtype=np.int64)
    label[order] = group
    count = len(start)
    groups = int(group[-1]) + 1 if count else 0
    # an edge's backward key meets another edge's forward key: that edge is its twin,
    # when it is the only edge with that forward key
    owner = np.full(groups, -1, dtype=np.int64)
    owner[label[:count]] = np.arange(count)
    forwards = np.bincount(label[:count], minlength=groups)
    owner[forwards != 1] = -1
    twin = owner[label[count:]]
    mutual = twin >= 0
    mutual[mutual] = twin[twin[mutual]] == np.flatnonzero(mutual)
    out = np.full(count, -1, dtype=np.int64)
    out[mutual] = piece[twin[mutual]]
    return out


def _merge_collinear(
    positions: np.ndarray, a: np.ndarray, b: np.ndarray, patch: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Join boundary edges (a -> b) whose shared vertex is straight (collinear neighbours).

    Only vertices with exactly one incoming and one outgoing boundary edge of the same
    patch are candidates, so non-manifold boundaries are left as they are.
    """
    n = len(a)
    start_key = patch * (positions.shape[0] + 1) + a
    end_key = patch * (positions.shape[0] + 1) + b
    sorted_start = np.argsort(start_key, kind="stable")
    pos = np.searchsorted(start_key[sorted_start], end_key)
    pos_c = np.minimum(pos, n - 1)
    found = start_key[sorted_start[pos_c]] == end_key
    # a vertex with two outgoing edges is ambiguous: no merging there
    dup_start = np.zeros(n, dtype=bool)
    ks = start_key[sorted_start]
    twice = np.zeros(n, dtype=bool)
    twice[1:] |= ks[1:] == ks[:-1]
    twice[:-1] |= ks[1:] == ks[:-1]
    dup_start[sorted_start] = twice
    nxt = np.where(found, sorted_start[pos_c], -1)
    ok = (nxt >= 0) & ~dup_start[np.maximum(nxt, 0)]
    d0 = positions[b] - positions[a]
    d1 = np.where(ok[:, None], d0[np.maximum(nxt, 0)], 0.0)
    cross = np.linalg.norm(np.cross(d0, d1), axis=1)
    scale = np.linalg.norm(d0, axis=1) * np.linalg.norm(d1, axis=1)
    straight = ok & (cross <= tol.collinear * scale) & (np.einsum("ij,ij->i", d0, d1) > 0)
    if not straight.any():
        return a, b, patch
    # the end of each edge's chain: follow straight joints (pointer jumping)
    jump = np.where(straight, nxt, np.arange(n))
    for _ in range(64):
        jumped = jump[jump]
        if np.array_equal(jumped, jump):
            break
        jump = jumped
    removed_start = np.zeros(n, dtype=bool)
    removed_start[nxt[straight]] = True
    keep = ~removed_start
    if not keep.any():  # a closed straight loop cannot happen for a real polygon
        return a, b, patch
    return a[keep], b[jump[keep]], patch[keep]


__all__ = ["Pieces", "boundary_edges", "folded_pieces", "group", "patch_vertices"]
