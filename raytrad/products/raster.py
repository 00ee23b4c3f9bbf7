"""Conservative rasterisation of per-corner values into a texture, and chart growing.

Used by the lightmap bake (:mod:`raytrad.products.lightmap`). Texel ``(i, j)`` (column
``i``, row ``j``) covers ``[i, i + 1] x [j, j + 1]``; its centre is ``(i + 0.5, j + 0.5)``.
Every texel a triangle touches gets a value, so thin triangles are not lost.
"""

from __future__ import annotations

import math

import numpy as np

from raytrad.constants import tol

#: Most (triangle, texel) candidates held in memory at once by :func:`rasterize`.
RASTER_BUDGET = 1 << 21

#: Triangle bounding boxes up to this many texels wide are grouped by exact width.
_EXACT_BUCKET = 8
#: Wider boxes are grouped by widths growing by this factor (at most 25 % wasted tests).
_BUCKET_GROWTH = 1.25


def rasterize(
    uv_corners: np.ndarray,
    values_at_corners: np.ndarray,
    size: tuple[int, int],
    priority: np.ndarray | None = None,
    centre_count: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Interpolate per-corner values over triangles into an image, conservatively.

    A texel whose centre lies in a triangle takes the barycentric interpolation of the
    triangle's corner values at the centre. A texel that a triangle only touches (its
    square overlaps the triangle but not its centre, e.g. along a thin sliver) takes the
    interpolation at the point of the triangle nearest the centre. Where several
    triangles claim a texel the nearest wins (a centre inside is at distance 0), then the
    lower ``priority``.

    Triangles are processed in groups of equal bounding-box size (rounded up), each group
    testing all texels of all its boxes at once by broadcasting, so no Python loop runs
    per triangle or texel.

    Parameters
    ----------
    uv_corners : (T, 3, 2) float [texels]
        Corner positions in texel space (texel ``(i, j)`` covers ``[i, i+1] x [j, j+1]``).
    values_at_corners : (T, 3, C) float
        Value at each corner (radiosity [W m-2] for a lightmap).
    size : (int, int)
        Image width and height [texels].
    priority : (T,) int or None
        Tie-break between triangles at the same distance (lower wins), e.g. the front of a
        double-sided face over its back copy when both share UVs.
    centre_count : (H * W,) int64 or None
        If given, incremented for each triangle of priority 0 whose interior (not an
        edge) holds the texel's centre: more than 1 where UV charts overlap.

    Returns
    -------
    pixels : (H, W, C) float32
        Interpolated values; 0 where uncovered.
    coverage : (H, W) bool
        True where some triangle touches the texel.
    """
    uv = np.asarray(uv_corners, dtype=np.float64)
    values = np.asarray(values_at_corners, dtype=np.float64)
    width, height = int(size[0]), int(size[1])
    if uv.ndim != 3 or uv.shape[1:] != (3, 2):
        raise ValueError(f"uv_corners must be (T, 3, 2), not {uv.shape}")
    if values.ndim != 3 or values.shape[:2] != uv.shape[:2]:
        raise ValueError(f"values_at_corners must be (T, 3, C), not {values.shape}")
    channels = values.shape[2]
    rank = np.zeros(len(uv), dtype=np.int64) if priority is None else np.asarray(priority)

    best_distance = np.full(width * height, np.inf)
    best_rank = np.zeros(width * height, dtype=np.int64)
    pixels = np.zeros((width * height, channels), dtype=np.float32)

    limit = np.array([width - 1, height - 1])
    finite = np.asarray(np.isfinite(uv).all(axis=(1, 2)))
    safe = np.where(finite[:, None, None], uv, 0.0)
    lo = np.floor(safe.min(axis=1)).astype(np.int64)
    hi = np.maximum(np.ceil(safe.max(axis=1)).astype(np.int64) - 1, lo)
    visible = finite & (hi >= 0).all(axis=1) & (lo <= limit).all(axis=1)
    lo, hi = np.clip(lo, 0, limit), np.clip(hi, 0, limit)
    extent = hi - lo + 1
    box = np.stack([_bucket(extent[:, 0]), _bucket(extent[:, 1])], axis=1)
    todo = np.nonzero(visible)[0]
    shapes, group = np.unique(box[todo], axis=0, return_inverse=True)
    group = group.reshape(-1)
    order = np.argsort(group, kind="stable")
    bounds = np.searchsorted(group[order], np.arange(len(shapes) + 1))
    for g, (box_w, box_h) in enumerate(shapes):
        members = todo[order[bounds[g] : bounds[g + 1]]]
        dx, dy = (a.reshape(-1) for a in np.meshgrid(np.arange(box_w), np.arange(box_h)))
        step = max(1, RASTER_BUDGET // int(box_w * box_h))
        for start in range(0, len(members), step):
            tri = members[start : start + step]
            k, j, weights, distance = _cover_boxes(uv[tri] - lo[tri, None, :], dx, dy)
            inside_box = (dx[j] <= hi[tri[k], 0] - lo[tri[k], 0]) & (
                dy[j] <= hi[tri[k], 1] - lo[tri[k], 1]
            )
            k, j, weights, distance = (
                k[inside_box],
                j[inside_box],
                weights[inside_box],
                distance[inside_box],
            )
            t = tri[k]
            x, y = lo[t, 0] + dx[j], lo[t, 1] + dy[j]
            if centre_count is not None:
                # strictly inside: a centre on an edge (xatlas puts vertices on texel
                # centres) belongs to two neighbours, not to an overlap
                inside = (distance == 0.0) & (rank[t] == 0) & (weights.min(axis=1) > 1e-9)
                np.add.at(centre_count, (y * width + x)[inside], 1)
            _keep_nearest(
                y * width + x,
                distance,
                rank[t],
                np.einsum("nk,nkc->nc", weights, values[t]),
                best_distance,
                best_rank,
                pixels,
            )
    coverage = np.isfinite(best_distance).reshape(height, width)
    return pixels.reshape(height, width, channels), coverage


def _cover_boxes(
    corners: np.ndarray, dx: np.ndarray, dy: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Texels of a common box grid that each triangle touches, with their weights.

    Parameters
    ----------
    corners : (N, 3, 2) float [texels]
        Triangles relative to the corner of their bounding box's first texel.
    dx, dy : (B,) int
        Texel offsets of the box grid.

    Returns
    -------
    triangle : (M,) int64
        Index into ``corners`` of each touched (triangle, texel) pair.
    texel : (M,) int64
        Index into ``dx`` / ``dy``.
    weights : (M, 3) float64
        Barycentric coordinates of the texel centre if it lies in the triangle, else of
        the triangle's point nearest the centre (non-negative, summing to 1).
    distance : (M,) float64 [texels]
        From the centre to the triangle (0 inside).
    """
    edge = np.roll(corners, -1, axis=1) - corners  # edge i runs from corner i to i + 1
    # cross(edge_i, centre - corner_i) = ex * cy - ey * cx + (ey * px - ex * py)
    offset = edge[..., 1] * corners[..., 0] - edge[..., 0] * corners[..., 1]  # (N, 3)
    # cross(p1 - p0, p2 - p0), with p2 - p0 = -edge 2
    twice_area = edge[:, 0, 1] * edge[:, 2, 0] - edge[:, 0, 0] * edge[:, 2, 1]
    # a sliver whose area is lost in the rounding of its edges has no orientation
    longest = np.sqrt((edge * edge).sum(axis=2).max(axis=1))
    flat = np.abs(twice_area) <= 2.0 * tol.degenerate * longest * longest
    orientation = np.where(flat, 0.0, np.sign(twice_area))
    # the texel square (half-size 1/2) reaches past edge i when the edge's function at the
    # centre, signed positive inside, exceeds -(|ex| + |ey|) / 2
    reach = 0.5 * np.abs(edge).sum(axis=2)
    cx, cy = dx + 0.5, dy + 0.5
    touched = np.ones((len(corners), len(dx)), dtype=bool)
    inside = ~flat[:, None] & touched
    for i in range(3):
        cross = (
            edge[:, i, 0, None] * cy[None, :]
            - edge[:, i, 1, None] * cx[None, :]
            + offset[:, i, None]
        )
        signed = np.where(flat[:, None], -np.abs(cross), orientation[:, None] * cross)
        inside &= signed >= 0.0
        touched &= signed + reach[:, i, None] >= -1e-12 * (1.0 + reach[:, i, None])
    triangle, texel = np.nonzero(touched | inside)
    centre = np.stack([cx[texel], cy[texel]], axis=1)
    crosses = edge[triangle, :, 0] * centre[:, None, 1] - edge[triangle, :, 1] * centre[:, None, 0]
    crosses += offset[triangle]
    weights = np.roll(crosses, 2, axis=1) / np.where(flat, 1.0, twice_area)[triangle, None]
    distance = np.zeros(len(triangle))
    outside = np.nonzero(~inside[triangle, texel])[0]
    if len(outside):
        w, d = _nearest_on_edges(corners[triangle[outside]], centre[outside])
        weights[outside], distance[outside] = w, d
    return triangle, texel, weights, distance


def _nearest_on_edges(corners: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric weights of, and distance to, the nearest point on each triangle's edges.

    Parameters
    ----------
    corners : (N, 3, 2) float
    centre : (N, 2) float

    Returns
    -------
    weights : (N, 3) float64
    distance : (N,) float64
    """
    edge = np.roll(corners, -1, axis=1) - corners
    rel = centre[:, None, :] - corners
    length2 = (edge * edge).sum(axis=2)
    along = np.divide(
        (rel * edge).sum(axis=2), length2, out=np.zeros_like(length2), where=length2 > 0
    )
    along = np.clip(along, 0.0, 1.0)
    gap2 = ((rel - along[..., None] * edge) ** 2).sum(axis=2)
    nearest = np.argmin(gap2, axis=1)
    row = np.arange(len(corners))
    t = along[row, nearest]
    weights = np.zeros((len(corners), 3))
    weights[row, nearest] = 1.0 - t
    weights[row, (nearest + 1) % 3] = t
    return weights, np.sqrt(gap2[row, nearest])


def _keep_nearest(
    texel: np.ndarray,
    distance: np.ndarray,
    rank: np.ndarray,
    value: np.ndarray,
    best_distance: np.ndarray,
    best_rank: np.ndarray,
    pixels: np.ndarray,
) -> None:
    """Write candidates that beat what the texels hold (nearest, then lowest rank)."""
    if len(texel) == 0:
        return
    order = np.lexsort((rank, distance, texel))
    texel, distance, rank = texel[order], distance[order], rank[order]
    first = np.ones(len(texel), dtype=bool)
    first[1:] = texel[1:] != texel[:-1]
    chosen = order[first]
    texel, distance, rank = texel[first], distance[first], rank[first]
    held_distance, held_rank = best_distance[texel], best_rank[texel]
    better = (distance < held_distance) | ((distance == held_distance) & (rank < held_rank))
    texel = texel[better]
    best_distance[texel] = distance[better]
    best_rank[texel] = rank[better]
    pixels[texel] = value[chosen[better]]


def grow_charts(
    pixels: np.ndarray, coverage: np.ndarray, rings: int
) -> tuple[np.ndarray, np.ndarray]:
    """Extend charts outwards by ``rings`` texels before the push-pull fill.

    Each ring gives every uncovered texel next to a covered one (of its 8 neighbours) the
    mean of those neighbours. The padding around a chart thus repeats the chart's own edge
    instead of a push-pull blend that may include a bright neighbouring chart (a lamp),
    which bilinear filtering and mipmaps would bleed into the chart.

    Parameters
    ----------
    pixels : (H, W, C) float
    coverage : (H, W) bool
    rings : int

    Returns
    -------
    pixels : (H, W, C) float32
        Uncovered texels beyond the rings are 0.
    coverage : (H, W) bool
        Covered texels and the rings.
    """
    value = np.where(coverage[..., None], np.asarray(pixels, dtype=np.float64), 0.0)
    covered = np.asarray(coverage, dtype=bool).copy()
    height, width = covered.shape
    shifts = [(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)]
    for _ in range(rings):
        padded_value = np.pad(value, ((1, 1), (1, 1), (0, 0)))
        padded_count = np.pad(covered.astype(np.float64), 1)
        total = np.zeros_like(value)
        count = np.zeros(covered.shape)
        for a, b in shifts:
            rows, cols = slice(1 + a, 1 + a + height), slice(1 + b, 1 + b + width)
            total += padded_value[rows, cols]
            count += padded_count[rows, cols]
        ring = ~covered & (count > 0)
        if not ring.any():
            break
        value[ring] = total[ring] / count[ring, None]
        covered |= ring
    return value.astype(np.float32), covered


def _bucket(extent: np.ndarray) -> np.ndarray:
    """Box sizes rounded up: exact to 8 texels, then in steps of 25 %."""
    extent = np.asarray(extent, dtype=np.int64)
    big = extent > _EXACT_BUCKET
    steps = np.ceil(np.log(np.maximum(extent, 1) / _EXACT_BUCKET) / math.log(_BUCKET_GROWTH) - 1e-9)
    rounded = np.ceil(_EXACT_BUCKET * _BUCKET_GROWTH ** np.maximum(steps, 0)).astype(np.int64)
    return np.where(big, np.maximum(rounded, extent), extent)
