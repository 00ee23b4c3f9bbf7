"""Which points lie near which segments: the broad phase of the imprint's search for the
refined edges crossing an outline and the triangles holding an outline's corner.

Points (an edge's midpoint, a triangle's centroid) are hashed into a uniform grid of
cells; points are sampled along each segment at most a cell apart, and the points in the
27 cells around each sample are measured against that segment. Items whose reaches differ
widely (a few long wall edges among many short ones) are taken in classes of reach a
factor 2 apart, each with its own cell size, so the long ones do not make every item a
candidate of every segment.

Many outline segments (a room of furniture has thousands) go to the compiled loop
(``segment_candidates`` in :mod:`raytrad.core._compiled_segments`), which measures each
candidate as it finds it; few go to numpy, which is as fast there and does not wait for
numba to compile the loop the first time. Both find the same pairs.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from raytrad.arrays import unique
from raytrad.core import compiled

#: Candidate items are taken in at most this many classes of reach, each a factor 2
#: below the last (:func:`items_near_segments`); smaller items join the last class.
REACH_CLASSES = 12

#: Outlines of at least this many segments are searched by the compiled loop: below,
#: numpy takes a few hundredths of a second (64 segments of the Cornell box's blocks at
#: 54 000 edges: 0.03 s), less than numba takes to load the loop, or (the first time)
#: 2 s to compile it. A room of furniture has thousands: 23 s of numpy, 3 s compiled.
COMPILED_SEGMENTS = 256

#: The most points the compiled search samples along the segments per item and segment
#: of a class (the numpy search takes 4: it keeps 27 cell keys a sample).
_SAMPLES_PER_ITEM = 64.0

#: Candidate pairs measured together by numpy (its temporaries then stay in the cache:
#: 4.4 times faster than all at once on 5.5 million pairs).
_PAIRS_AT_ONCE = 1 << 16


def items_near_segments(
    points: np.ndarray, segments: np.ndarray, reach: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every (item, segment) pair whose item point lies within ``reach`` of the segment.

    Parameters
    ----------
    points : (N, 3) float
        The items' points [m]: an edge's midpoint, a triangle's centroid.
    segments : (S, 2, 3) float
        The segments' ends [m]; a segment may be a point (both ends equal).
    reach : float or (N,) float
        One distance for every item, or each item's own [m].

    Returns
    -------
    item, segment : (P,) int64
        The pairs, sorted by item, then segment; none (not an error) when no item is near
        or either input is empty.
    """
    reach = np.broadcast_to(np.asarray(reach, dtype=np.float64), (len(points),))
    if len(points) == 0 or len(segments) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    top = max(float(reach.max()), np.finfo(np.float64).tiny)
    length = float(np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1).sum())
    level = np.floor(np.log2(top / np.maximum(reach, top * 2.0**-REACH_CLASSES)))
    fast = compiled.get() if len(segments) >= COMPILED_SEGMENTS else None
    segments = np.ascontiguousarray(segments, dtype=np.float64)
    keys = []
    for k in unique(level.astype(np.int64)).tolist():
        rows = np.flatnonzero(level == k)
        # cells twice the class's reach: an item within reach of a segment's point X then
        # lies within a cell of the sample nearest X (half a cell away at most), so in
        # one of its 27 cells; and no finer than a few samples along the segments per
        # item of the class (the compiled loop keeps no 27 keys a sample, so it takes
        # more: finer cells, fewer far items measured)
        share = 4.0 if fast is None else _SAMPLES_PER_ITEM
        cell = max(2.0 * float(reach[rows].max()), length / (share * (len(rows) + len(segments))))
        if not cell > 0.0:  # points at zero reach of point segments: any cell finds them
            cell = 1.0
        class_points = np.ascontiguousarray(points[rows], dtype=np.float64)
        if fast is not None:  # found and measured in one loop
            item, segment = fast.segment_candidates(
                class_points,
                np.ascontiguousarray(reach[rows]),
                *_cell_grid(class_points, segments, cell),
            )
            keys.append(rows[item] * len(segments) + segment)
            continue
        item, segment = cell_pairs(class_points, segments, cell)
        for a in range(0, len(item), _PAIRS_AT_ONCE):  # a few MB at a time: in cache
            i, j = item[a : a + _PAIRS_AT_ONCE], segment[a : a + _PAIRS_AT_ONCE]
            near = distance_to_segment(class_points[i], segments[j]) <= reach[rows[i]] * (1 + 1e-9)
            keys.append(rows[i[near]] * len(segments) + j[near])
    pairs = unique(np.concatenate(keys)) if keys else np.zeros(0, dtype=np.int64)
    return pairs // len(segments), pairs % len(segments)


def nearest_on_segment(point: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N, 3) the nearest point of each segment p-q (N, 3 each; p itself when p = q) to
    each ``point`` (N, 3) [m]."""
    direction = q - p
    square = _dot(direction, direction)
    t = np.clip(_dot(point - p, direction) / np.where(square > 0, square, 1.0), 0.0, 1.0)
    return p + t[:, None] * direction


def distance_to_segment(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """(K,) distance of each point (K, 3) from its segment (K, 2, 3) [m]."""
    gap = points - nearest_on_segment(points, segments[:, 0], segments[:, 1])
    return np.sqrt(_dot(gap, gap))


def cell_pairs(
    points: np.ndarray, segments: np.ndarray, cell: float
) -> tuple[np.ndarray, np.ndarray]:
    """(item, segment) pairs (unsorted, with repeats, not yet measured) of the items in
    the 27 cells [m] around a point sampled along a segment: the reference of the
    compiled ``segment_candidates``, which measures them too."""
    samples, owner, _, origin, _, sorted_keys, by_key, _ = _cell_grid(points, segments, cell)
    sample_cells = np.floor((samples - origin) / cell).astype(np.int64)
    offsets = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)
    keys = cell_key((sample_cells[:, None, :] + offsets[None]).reshape(-1, 3))
    key_owner = np.repeat(owner, len(offsets))
    order = np.lexsort((key_owner, keys))
    keys, key_owner = keys[order], key_owner[order]
    fresh = np.ones(len(keys), dtype=bool)
    fresh[1:] = (keys[1:] != keys[:-1]) | (key_owner[1:] != key_owner[:-1])
    keys, key_owner = keys[fresh], key_owner[fresh]
    lo = np.searchsorted(sorted_keys, keys, side="left")
    hi = np.searchsorted(sorted_keys, keys, side="right")
    count = hi - lo
    pair_owner = np.repeat(key_owner, count)
    start = np.repeat(lo - (np.cumsum(count) - count), count)
    item = by_key[start + np.arange(int(count.sum()))]
    return item, pair_owner


def cell_key(cells: np.ndarray) -> np.ndarray:
    """One uint64 hash per integer cell (N, 3). Two cells may share a hash: that only adds
    candidates, which the exact tests drop."""
    with np.errstate(over="ignore"):
        c = cells.astype(np.uint64)
        return (
            c[:, 0] * np.uint64(73856093)
            ^ c[:, 1] * np.uint64(19349663)
            ^ c[:, 2] * np.uint64(83492791)
        )


def _cell_grid(points: np.ndarray, segments: np.ndarray, cell: float) -> tuple[Any, ...]:
    """What :func:`cell_pairs` and the compiled ``segment_candidates`` search: points
    sampled along the segments at most ``cell`` [m] apart ((K, 3), their segments (K,)),
    the segments, the grid's origin (3,) and cell [m], the items' cell keys in ascending
    order (M,), their items (M,) and their cells (M, 3)."""
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    steps = np.ceil(length / cell).astype(np.int64) + 1
    owner = np.repeat(np.arange(len(segments)), steps)
    first = np.repeat(np.cumsum(steps) - steps, steps)
    fraction = (np.arange(len(owner)) - first) / np.maximum(steps[owner] - 1, 1)
    samples = segments[owner, 0] + fraction[:, None] * (segments[owner, 1] - segments[owner, 0])
    origin = np.minimum(points.min(axis=0), samples.min(axis=0)) - 2.0 * cell
    cells = np.floor((points - origin) / cell).astype(np.int64)
    keys = cell_key(cells)
    by_key = np.argsort(keys, kind="stable")
    return samples, owner, segments, origin, cell, keys[by_key], by_key, cells[by_key]


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", x, y)
