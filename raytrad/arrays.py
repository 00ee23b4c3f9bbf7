"""Array helpers that numpy does slowly.

:func:`unique` is ``np.unique(values)`` by sorting. numpy 2.3 and later answer a plain
``np.unique`` (no ``return_*``) with a hash table, which on this project's index arrays
(vertex and triangle indices, packed pair keys) is 2 to 20 times slower than sorting:
measured with numpy 2.4 on 2 cores, 3 million indices below 500 000 took 1.22 s against
0.23 s, and a million 64-bit keys 0.84 s against 0.05 s (2026-12-03). Imprinting 100
contact outlines spent 23 s of 44 there.

:func:`corner_mean`, :func:`corner_min`, :func:`corner_max` and :func:`longest_side`
reduce a triangle's three corners as ``mean``, ``min``, ``max`` and ``np.linalg.norm``
over the corner axis do, to the bit, by adding or comparing the three rows: numpy's
reductions over a short middle axis take two to four times as long (100 000 triangles:
a mean in 6.1 ms against 10.9 with the gather, a minimum in 1.9 ms against 7.4), and
refinement makes them for the whole mesh every round.
"""

from __future__ import annotations

import numpy as np


def unique(values: np.ndarray) -> np.ndarray:
    """The sorted unique values of ``values`` (flattened), as ``np.unique(values)``.

    Parameters
    ----------
    values : array_like
        Any shape; integers, or floats without NaN (a NaN is kept once per occurrence,
        where ``np.unique`` keeps one).

    Returns
    -------
    (U,) array of ``values``' dtype, ascending.
    """
    flat = np.sort(np.asarray(values).reshape(-1))
    if len(flat) < 2:
        return flat
    keep = np.empty(len(flat), dtype=bool)
    keep[0] = True
    np.not_equal(flat[1:], flat[:-1], out=keep[1:])
    return flat[keep]


def unique_inverse(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(keys, return_inverse=True)`` for non-negative integer ``keys`` (any
    shape; the inverse flat): the sorted distinct keys and each key's index among them.
    Keys spanning no more than :data:`DENSE_SPAN` times their count are marked in a table
    instead of sorted (a refined mesh's edge and corner keys: a third to a fifth of the
    sort's time, the same arrays); wider ones go to ``np.unique``."""
    flat = np.asarray(keys).reshape(-1)
    if len(flat) == 0 or int(flat.max()) >= DENSE_SPAN * len(flat) or int(flat.min()) < 0:
        distinct, inverse = np.unique(flat, return_inverse=True)
        return distinct, inverse.reshape(-1)
    present = np.zeros(int(flat.max()) + 1, dtype=bool)
    present[flat] = True
    distinct = np.flatnonzero(present).astype(flat.dtype, copy=False)
    rank = np.cumsum(present, dtype=np.int64) - 1
    return distinct, rank[flat]


#: The widest span of keys, per key, that :func:`unique_inverse` marks in a table.
DENSE_SPAN = 8


def column_max(values: np.ndarray) -> np.ndarray:
    """(C,) the largest value of each column of ``values`` ((N, C), N >= 1), NaN where a
    column holds one: ``values.max(axis=0)``, a column at a time. numpy reduces a few
    columns across many rows with a strided loop; a contiguous copy of each column and its
    own reduction took a sixteenth of the time for (26 000, 3) (the error log's rows)."""
    return np.array([np.ascontiguousarray(values[:, c]).max() for c in range(values.shape[1])])


def morton_order(points: np.ndarray, bits: int = 21) -> np.ndarray:
    """(N,) int64 permutation that puts ``points`` ((N, 3) float) in Morton (Z-curve)
    order over their bounding box: points near each other in space come near each other
    in the permutation, wherever the points lie and whatever their units.

    Each coordinate is quantised to ``bits`` (at most 21) bits across the box and the
    bits interleaved; ties keep their input order (stable).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    lo = points.min(axis=0)
    span = float((points.max(axis=0) - lo).max())
    scale = ((1 << bits) - 1) / span if span > 0 else 0.0
    cells = np.clip((points - lo) * scale, 0, (1 << bits) - 1).astype(np.uint64)
    code = np.zeros(len(points), dtype=np.uint64)
    for axis in range(3):
        code |= _spread_bits(cells[:, axis]) << np.uint64(2 - axis)
    return np.argsort(code, kind="stable")


def _spread_bits(values: np.ndarray) -> np.ndarray:
    """Each value's low 21 bits spread two zero bits apart (bit k to bit 3k)."""
    v = values & np.uint64(0x1FFFFF)
    for shift, mask in (
        (32, 0x1F00000000FFFF),
        (16, 0x1F0000FF0000FF),
        (8, 0x100F00F00F00F00F),
        (4, 0x10C30C30C30C30C3),
        (2, 0x1249249249249249),
    ):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def spatially_ordered(points: np.ndarray, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``points`` ((N, 3)) renumbered in :func:`morton_order`, and ``indices`` (any
    shape, int, into ``points``) renumbered to match: for a mesh's vertices and
    triangles, consecutive vertices (and the receivers numbered by them) then lie in one
    part of the scene, so a chunk of consecutive receivers casts coherent rays."""
    order = morton_order(points)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return points[order], rank[indices]


def corner_mean(corners: np.ndarray) -> np.ndarray:
    """(N, D) ``corners.mean(axis=1)`` of (N, 3, D) corners, or (N,) of (N, 3) values, to
    the bit (the rows added in order, then divided by 3)."""
    return (corners[:, 0] + corners[:, 1] + corners[:, 2]) / 3.0


def corner_min(corners: np.ndarray) -> np.ndarray:
    """(N, D) ``corners.min(axis=1)`` of (N, 3, D) corners, or (N,) of (N, 3) values (no
    NaN)."""
    return np.minimum(np.minimum(corners[:, 0], corners[:, 1]), corners[:, 2])


def corner_max(corners: np.ndarray) -> np.ndarray:
    """(N, D) ``corners.max(axis=1)`` of (N, 3, D) corners, or (N,) of (N, 3) values (no
    NaN)."""
    return np.maximum(np.maximum(corners[:, 0], corners[:, 1]), corners[:, 2])


def longest_side(corners: np.ndarray) -> np.ndarray:
    """(N,) each triangle's longest side [m] from (N, 3, 3) corners, to the bit
    ``np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)``."""
    side = corners - corners[:, [2, 0, 1]]
    squared = side[..., 0] * side[..., 0] + side[..., 1] * side[..., 1]
    length = np.sqrt(squared + side[..., 2] * side[..., 2])
    return np.maximum(np.maximum(length[:, 0], length[:, 1]), length[:, 2])
