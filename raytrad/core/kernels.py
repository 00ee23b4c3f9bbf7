"""Form-factor kernels: closed-form point-to-area factors, vectorised over pairs.

* :func:`disk_form_factor`: the Wallace et al. (1989) disk approximation of a
  differential-to-area factor;
* :func:`polygon_form_factor`: the exact unoccluded point-to-polygon factor (Lambert's
  formula; Baum, Rushmeier and Winget 1989), clipped to the receiver's horizon;
* :func:`edge_sum`: Lambert's formula over given edges (the outline sums of
  :mod:`raytrad.core.contour` build on it).

Clipping at the horizon needs no tolerance: Lambert's formula is continuous as a corner
crosses the receiver's plane, so a corner at +-1e-17 m gives the same factor either way.
Choosing a ray *target* is not continuous (the centroid of the whole triangle or of its
clipped part), so :func:`visible_centroid` counts heights within ``tol.horizon`` of the
pair's size as on the horizon (:func:`horizon_heights`).

:func:`polygon_form_factor` and :func:`linear_corner_shares` run compiled
(:mod:`raytrad.core.compiled`, numba) when it is available; their ``numpy_`` twins here
are the reference the tests compare them with.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from raytrad.constants import tol
from raytrad.core import compiled


def _f64(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=np.float64)


def disk_form_factor(
    cos_receiver: np.ndarray, cos_source: np.ndarray, distance_sq: np.ndarray, area: np.ndarray
) -> np.ndarray:
    """Wallace et al. disk approximation of a differential-to-area form factor.

    Parameters
    ----------
    cos_receiver, cos_source : array_like
        Cosines between the connecting line and each normal [1].
    distance_sq : array_like
        Squared distance [m2].
    area : array_like
        Sub-area [m2].

    Returns
    -------
    ndarray, cos_r cos_s dA / (pi r^2 + dA) [1]; exact for a coaxial disk of area dA.
    """
    return cos_receiver * cos_source * area / (math.pi * distance_sq + area)


def horizon_heights(polygons: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Heights of polygon corners above each receiver's tangent plane [m], snapped to 0
    within ``tol.horizon`` x the largest corner distance of their pair (the corner lies on
    the horizon up to rounding).

    Parameters
    ----------
    polygons : (N, K, 3) float64
        Corners [m].
    points : (N, 3) float64
        Receiver positions [m].
    normals : (N, 3) float64
        Receiver unit normals.

    Returns
    -------
    (N, K) float64
    """
    offsets = polygons - points[:, None, :]
    height = np.einsum("nkj,nj->nk", offsets, normals)
    reach = np.sqrt(np.einsum("nkj,nkj->nk", offsets, offsets).max(axis=1))
    return np.where(np.abs(height) <= tol.horizon * reach[:, None], 0.0, height)


def clip_to_horizon(
    polygons: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Clip triangles to the half-space in front of each receiver (Sutherland-Hodgman).

    Parameters
    ----------
    polygons : (N, 3, 3) float64
        Triangle corners [m].
    points : (N, 3) float64
        Receiver positions [m].
    normals : (N, 3) float64
        Receiver unit normals.

    Returns
    -------
    clipped : (N, 4, 3) float64
        Polygon corners in order; shorter polygons repeat their last corner.
    count : (N,) int64
        Corner count (0 when nothing is above the horizon).
    """
    n = len(polygons)
    h = np.einsum("nkj,nj->nk", polygons - points[:, None, :], normals)
    candidates = np.zeros((n, 6, 3))
    valid = np.zeros((n, 6), dtype=bool)
    for k in range(3):
        a, b = polygons[:, k], polygons[:, (k + 1) % 3]
        ha, hb = h[:, k], h[:, (k + 1) % 3]
        candidates[:, 2 * k] = a
        valid[:, 2 * k] = ha >= 0
        crosses = (ha >= 0) != (hb >= 0)
        t = np.where(crosses, ha / np.where(crosses, ha - hb, 1.0), 0.0)
        candidates[:, 2 * k + 1] = a + t[:, None] * (b - a)
        valid[:, 2 * k + 1] = crosses
    order = np.argsort(~valid, axis=1, kind="stable")[:, :4]
    count = valid.sum(axis=1)
    clipped = np.take_along_axis(candidates, order[:, :, None], axis=1)
    last = np.maximum(count - 1, 0)
    pad = np.arange(4)[None, :] >= count[:, None]
    clipped = np.where(pad[:, :, None], clipped[np.arange(n), last][:, None, :], clipped)
    return clipped, np.minimum(count, 4)


def polygon_form_factor(
    polygons: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """Exact unoccluded point-to-polygon form factor, compiled when available (see
    :func:`numpy_polygon_form_factor`, the reference, for the formula and shapes)."""
    fast = compiled.get()
    if fast is None:
        return numpy_polygon_form_factor(polygons, points, normals)
    return fast.polygon_form_factor(_f64(polygons), _f64(points), _f64(normals))


def numpy_polygon_form_factor(
    polygons: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """Exact unoccluded point-to-polygon form factor (Lambert's formula).

    ``F = |sum_k gamma_k n . (u_k x u_k+1) / |u_k x u_k+1|| / (2 pi)`` with u_k the unit
    vectors to the corners (Baum et al. 1989). The polygons are first clipped to each
    receiver's horizon, so the formula's precondition holds.

    Parameters
    ----------
    polygons : (N, 3, 3) float64
        Triangle corners [m] (any winding).
    points : (N, 3) float64
        Receiver positions [m].
    normals : (N, 3) float64
        Receiver unit normals.

    Returns
    -------
    (N,) float64 form factors [1].
    """
    height = np.einsum("nkj,nj->nk", polygons - points[:, None, :], normals)
    whole = (height >= 0).all(axis=1)
    out = np.zeros(len(polygons))
    if whole.any():
        out[whole] = _lambert(polygons[whole], points[whole], normals[whole])
    part = ~whole & (height > 0).any(axis=1)
    if part.any():
        clipped, count = clip_to_horizon(polygons[part], points[part], normals[part])
        out[part] = np.where(count >= 3, _lambert(clipped, points[part], normals[part]), 0.0)
    return out


@functools.lru_cache(maxsize=8)
def _sub_triangles(levels: int) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric corners (4^levels, 3, 3) and centroids (4^levels, 3) of the midpoint
    subdivision of a triangle, ``levels`` times (cached, read-only)."""
    tris = np.eye(3)[None, :, :]
    for _ in range(levels):
        a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
        ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
        tris = np.concatenate(
            [np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))]
        )
    centroids = tris.mean(axis=1)
    tris.flags.writeable = False
    centroids.flags.writeable = False
    return tris, centroids


@functools.lru_cache(maxsize=8)
def sub_grid(levels: int) -> tuple[np.ndarray, ...]:
    """:func:`_sub_triangles` as shared corners and edges, for the compiled corner shares
    (cached, read-only).

    Returns
    -------
    vertex_bary : (V, 3) float64, each distinct corner's barycentric coordinates (bitwise
        the rows of :func:`_sub_triangles`' corners: ``vertex_bary[tri_vertex]`` equals them)
    tri_vertex : (S, 3) int64, each part's corners
    edge_of : (S, 3) int64, the edge from each part's corner k to corner k + 1
    edge_sign : (S, 3) float64, +1 where that edge runs as ``edge_ends`` has it, else -1
    edge_ends : (E, 2) int64, each distinct edge's corners
    centroids : (S, 3) float64, as :func:`_sub_triangles`'
    """
    corners, centroids = _sub_triangles(levels)
    vertex_bary, inverse = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    tri_vertex = inverse.reshape(-1, 3).astype(np.int64)
    start, end = tri_vertex.reshape(-1), np.roll(tri_vertex, -1, axis=1).reshape(-1)
    low, high = np.minimum(start, end), np.maximum(start, end)
    keys, edge_of = np.unique(low * len(vertex_bary) + high, return_inverse=True)
    edge_ends = np.stack(np.divmod(keys, len(vertex_bary)), axis=1).astype(np.int64)
    edge_sign = np.where(start == low, 1.0, -1.0).reshape(-1, 3)
    out = (vertex_bary, tri_vertex, edge_of.reshape(-1, 3).astype(np.int64), edge_sign)
    tables = (*out, edge_ends, np.ascontiguousarray(centroids))
    for table in tables:
        table.flags.writeable = False
    return tables


def linear_corner_shares(
    triangles: np.ndarray, points: np.ndarray, normals: np.ndarray, levels: int = 2
) -> np.ndarray:
    """Corner shares, compiled when available (see :func:`numpy_linear_corner_shares`, the
    reference, for the method and shapes)."""
    fast = compiled.get()
    if fast is None:
        return numpy_linear_corner_shares(triangles, points, normals, levels)
    return fast.linear_corner_shares(_f64(triangles), _f64(points), _f64(normals), sub_grid(levels))


def numpy_linear_corner_shares(
    triangles: np.ndarray, points: np.ndarray, normals: np.ndarray, levels: int = 2
) -> np.ndarray:
    """(N, 3) share of each corner in what a receiver sees of a linearly varying triangle.

    A receiver close to a triangle sees mostly its nearest part: the radiosity it gathers
    from a triangle with corner values ``B_k`` is ``sum_k s_k B_k``, with ``s_k`` the
    factor-weighted mean barycentric coordinate of corner k over the triangle. Computed by
    splitting each triangle ``levels`` times at its edge midpoints (``4**levels`` exact
    factors, :func:`polygon_form_factor`) and weighting each part's centroid coordinates
    by its factor. Triangles the receiver does not see get equal shares.

    Parameters
    ----------
    triangles : (N, 3, 3) float64
        Corners [m].
    points, normals : (N, 3) float64
        Receiver positions [m] and unit normals.
    levels : int
        Midpoint subdivisions.

    Returns
    -------
    (N, 3) float64, rows summing to 1.
    """
    corners, centroids = _sub_triangles(levels)
    count = len(corners)
    parts = np.einsum("skc,ncj->nskj", corners, triangles).reshape(-1, 3, 3)
    factor = numpy_polygon_form_factor(
        parts, np.repeat(points, count, axis=0), np.repeat(normals, count, axis=0)
    ).reshape(-1, count)
    total = factor.sum(axis=1)
    shares = factor @ centroids
    seen = total > 0
    out = np.full((len(triangles), 3), 1.0 / 3.0)
    out[seen] = shares[seen] / total[seen, None]
    return out


def visible_centroid(polygons: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, 3) mean corner of each triangle's part above the receiver's horizon [m].

    A triangle straddling the horizon (the floor running under a block, seen from the
    block's side) is aimed at in its visible part, not at a centroid behind the block.
    """
    height = horizon_heights(polygons, points, normals)
    target = polygons.mean(axis=1)
    part = ~(height >= 0).all(axis=1)
    if part.any():
        clipped, count = clip_to_horizon(polygons[part], points[part], normals[part])
        valid = np.arange(4)[None, :] < count[:, None]
        total = (clipped * valid[:, :, None]).sum(axis=1)
        target[part] = total / np.maximum(count, 1)[:, None]
    return target


def _lambert(polygons: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Lambert's formula for (N, k, 3) polygons wholly above each receiver's horizon."""
    d = polygons - points[:, None, :]
    return edge_sum(d, np.roll(d, -1, axis=1), normals)


def edge_terms(u: np.ndarray, v: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, E) signed terms ``gamma n.(u x v) / |u x v|`` of Lambert's formula, one per edge.

    Parameters
    ----------
    u, v : (N, E, 3) float64
        Vectors from each receiver to the start and end of each edge [m].
    normals : (N, 3) float64
        Receiver unit normals.

    Returns
    -------
    (N, E) float64 [rad]; 0 for an edge through the receiver. For points on one straight
    line that misses the receiver the terms add up: ``term(a, b) + term(b, c) =
    term(a, c)`` (a signed angle).
    """
    u = u / np.maximum(np.linalg.norm(u, axis=2), 1e-300)[:, :, None]
    v = v / np.maximum(np.linalg.norm(v, axis=2), 1e-300)[:, :, None]
    cross = np.cross(u, v)
    sin = np.linalg.norm(cross, axis=2)
    gamma = np.arctan2(sin, np.einsum("nej,nej->ne", u, v))
    projected = np.einsum("nej,nj->ne", cross, normals) / np.where(sin > 0, sin, 1.0)
    return np.where(sin > 0, gamma * projected, 0.0)


def edge_sum(u: np.ndarray, v: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """|sum over edges of gamma n.(u x v)/|u x v|| / (2 pi): Lambert's formula.

    Parameters
    ----------
    u, v : (N, E, 3) float64
        Vectors from each receiver to the start and end of each edge [m].
    normals : (N, 3) float64
        Receiver unit normals.

    Returns
    -------
    (N,) float64 form factors [1]; an edge through the receiver contributes nothing.
    """
    return np.abs(edge_terms(u, v, normals).sum(axis=1)) / (2.0 * math.pi)


def numpy_facing_triangle_sums(
    points: np.ndarray,
    normals: np.ndarray,
    corners: np.ndarray,
    triangle_normals: np.ndarray,
    margin: float,
) -> np.ndarray:
    """Sum over triangles of the exact horizon-clipped factor from each receiver: the
    triangle-by-triangle truth the outline sums of :mod:`raytrad.core.contour` are
    tested against (the pass no longer computes it: its cost grew with refinement).

    A triangle counts only where its lit side faces the receiver by more than ``margin``
    (a one-sided triangle seen from behind gives nothing).

    Parameters
    ----------
    points, normals : (C, 3) float64
        Receiver positions [m] and unit normals.
    corners : (T, 3, 3) float64
        Triangle corners [m].
    triangle_normals : (T, 3) float64
        Their unit normals (lit side).
    margin : float
        Height in front of a triangle's plane below which it is not seen [m].

    Returns
    -------
    (C,) float64 form factors [1].
    """
    c, t = len(points), len(corners)
    rc = np.repeat(np.arange(c), t)
    rt = np.tile(np.arange(t), c)
    x, nx, tri = points[rc], normals[rc], corners[rt]
    in_front = np.einsum("kj,kj->k", x - tri[:, 0], triangle_normals[rt]) > margin
    f = np.zeros(len(rc))
    if in_front.any():
        f[in_front] = numpy_polygon_form_factor(tri[in_front], x[in_front], nx[in_front])
    return np.bincount(rc, weights=f, minlength=c)


def sample_weights(
    points: np.ndarray,
    normals: np.ndarray,
    sees: np.ndarray,
    samples: np.ndarray,
    sample_normals: np.ndarray,
    near_reach: np.ndarray,
    area: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Disk weights of far sample pairs and the near mask, compiled when available (see
    :func:`numpy_sample_weights`, the reference)."""
    args = (points, normals, sees, samples, sample_normals, near_reach, area)
    fast = compiled.get()
    if fast is None:
        return numpy_sample_weights(*args)
    return fast.sample_weights(
        _f64(points),
        _f64(normals),
        np.ascontiguousarray(sees, dtype=np.bool_),
        _f64(samples),
        _f64(sample_normals),
        _f64(near_reach),
        _f64(area),
    )


def numpy_sample_weights(
    points: np.ndarray,
    normals: np.ndarray,
    sees: np.ndarray,
    samples: np.ndarray,
    sample_normals: np.ndarray,
    near_reach: np.ndarray,
    area: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every (receiver, sub-area sample) pair of the receivers that see the patch: far
    and facing, or near. A receiver that sees the patch but is neither near nor facing
    any of its samples is near all of them (it is then handled triangle by triangle).

    Parameters
    ----------
    points, normals : (C, 3) float64
        Receiver positions [m] and unit normals.
    sees : (C,) bool
        The receivers that see part of the patch; the others get no sample.
    samples, sample_normals : (S, 3) float64
        Sub-area sample points [m] and unit normals.
    near_reach : (S,) float64
        A receiver nearer than this to a sample is near it [m].
    area : (S,) float64
        Sub-areas [m2].

    Returns
    -------
    weight : (C, S) float64, :func:`disk_form_factor` of far pairs, 0 elsewhere [1]
    far : (C, S) bool, not near, and each in front of the other
    near : (C, S) bool
    """
    d = samples[None, :, :] - points[:, None, :]
    r2 = np.einsum("csj,csj->cs", d, d)
    r = np.sqrt(r2)
    inv_r = 1.0 / np.where(r > 0, r, 1.0)
    cos_r = np.einsum("csj,cj->cs", d, normals) * inv_r
    cos_s = -np.einsum("csj,sj->cs", d, sample_normals) * inv_r
    near = r < near_reach[None, :]
    far = ~near & (cos_r > 0) & (cos_s > 0)
    near |= (~far.any(axis=1) & ~near.any(axis=1))[:, None]
    sees = np.asarray(sees, dtype=bool)[:, None]
    far &= sees
    near &= sees
    weight = np.where(far, disk_form_factor(cos_r, cos_s, r2, area[None, :]), 0.0)
    return weight, far, near


def visibility_rays(
    origins: np.ndarray,
    far: np.ndarray,
    sub_targets: np.ndarray,
    near_receivers: np.ndarray,
    near_targets: np.ndarray,
    shift: np.ndarray,
    shorten: float,
) -> tuple[np.ndarray, ...]:
    """A chunk's occlusion rays, compiled when available (see
    :func:`numpy_visibility_rays`, the reference)."""
    fast = compiled.get()
    if fast is None:
        return numpy_visibility_rays(
            origins, far, sub_targets, near_receivers, near_targets, shift, shorten
        )
    return tuple(
        fast.visibility_rays(
            _f64(origins),
            np.ascontiguousarray(far, dtype=np.bool_),
            _f64(sub_targets),
            np.ascontiguousarray(near_receivers, dtype=np.int64),
            _f64(near_targets),
            _f64(shift),
            float(shorten),
        )
    )


def numpy_visibility_rays(
    origins: np.ndarray,
    far: np.ndarray,
    sub_targets: np.ndarray,
    near_receivers: np.ndarray,
    near_targets: np.ndarray,
    shift: np.ndarray,
    shorten: float,
) -> tuple[np.ndarray, ...]:
    """The occlusion rays of a chunk: from each receiver's ray origin to each far sample
    point it sees (row-major in ``far``), then to each near triangle's target.

    Parameters
    ----------
    origins : (C, 3) float64
        Ray origins of the chunk's receivers [m].
    far : (C, S) bool
        Far (receiver, sub-area sample) pairs.
    sub_targets : (S, 3) float64
        Sample ray targets [m].
    near_receivers : (B,) int64
        Chunk receiver of each near ray.
    near_targets : (B, 3) float64
        Its target [m].
    shift : (3,) float64
        Subtracted from the origins (to the ray tracer's local frame) [m].
    shorten : float
        Each ray stops this short of its target [m].

    Returns
    -------
    origin : (A + B, 3) float32 [m]
    direction : (A + B, 3) float32, unit
    reach : (A + B,) float32 [m]
    far_c, far_s : (A,) int64, receiver and sample of each far ray
    """
    far_c, far_s = np.nonzero(far)
    start = origins[np.concatenate([far_c, near_receivers])]
    delta = np.concatenate([sub_targets[far_s], near_targets]) - start
    length = np.sqrt(np.einsum("ij,ij->i", delta, delta))
    direction = delta / np.where(length > 0, length, 1.0)[:, None]
    reach = np.maximum(length - shorten, 0.0)
    return (
        (start - shift).astype(np.float32),
        direction.astype(np.float32),
        reach.astype(np.float32),
        far_c,
        far_s,
    )
