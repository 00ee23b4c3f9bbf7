"""Where surfaces pass through each other: the segments two crossing triangles share.

A block sunk into a floor, a table leg through a rug, a pipe through a wall: the
intersection line is a contact line like a block's bottom edge on a floor (the surface is
hidden on one side of it and lit on the other), but it is no triangle's edge, so
:func:`~raytrad.core.imprint.outline_segments` does not find it. This module finds it as
segments in the same form (:class:`~raytrad.core.imprint.Outlines`), once on each of the
two triangles, so that :func:`~raytrad.core.imprint.imprint_outlines` puts refined edges
on it.

Two triangles cross when each has corners strictly on both sides of the other's plane
(beyond a band). Their common segment is the overlap, along the line where the planes
meet, of the two intervals each triangle cuts from it (Möller 1997). Candidate pairs come
from a uniform grid of their bounding boxes, between surfaces only, not from testing
every pair.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from raytrad.constants import sign_with_band
from raytrad.core.imprint import Outlines
from raytrad.scene import triangle_areas_normals

#: Cells of the broad phase's grid along the scene's diagonal, at the finest.
GRID_CELLS = 256

#: Most (triangle, cell) entries the broad phase makes before coarsening its grid.
MAX_ENTRIES = 1 << 22

#: Candidate pairs the broad phase hands on at a time (bounds its memory).
PAIRS_PER_CHUNK = 1 << 21


def intersection_segments(
    positions: np.ndarray, triangles: np.ndarray, surface: np.ndarray, band: float
) -> Outlines:
    """The segments where triangles of different surfaces pass through each other.

    Parameters
    ----------
    positions : (V, 3) float64 [m]
    triangles : (T, 3) int64
    surface : (T,) int64, surface label per triangle
    band : float [m]
        Corners nearer than this to the other triangle's plane count as on it: triangles
        that only touch (a block standing on a floor, two faces sharing an edge) do not
        cross; segments shorter than this are dropped.

    Returns
    -------
    Outlines
        Each segment twice: labelled with the surface and normal of the triangle that
        crosses the one it lies on (as an outline, it is imprinted on every surface but
        its label's).
    """
    corners = np.asarray(positions, dtype=np.float64)[triangles]
    area, normal = triangle_areas_normals(corners)
    usable = np.flatnonzero(area > 0)
    found: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    if len(usable) >= 2:
        box_lo, box_hi = corners[usable].min(axis=1), corners[usable].max(axis=1)
        for first, second in box_pairs(box_lo, box_hi, band, surface[usable]):
            first, second = usable[first], usable[second]
            ends, ok = _shared_segments(
                corners[first], normal[first], corners[second], normal[second], band
            )
            found.append((first[ok], second[ok], ends[ok]))
    if not found or not sum(len(f[0]) for f in found):
        return Outlines(np.zeros((0, 2, 3)), np.zeros(0, np.int64), np.zeros((0, 3)))
    first, second, ends = (np.concatenate(part) for part in zip(*found, strict=True))
    return Outlines(
        np.concatenate([ends, ends]),
        np.concatenate([surface[second], surface[first]]).astype(np.int64),
        np.concatenate([normal[second], normal[first]]),
    )


def box_pairs(
    lo: np.ndarray, hi: np.ndarray, pad: float, label: np.ndarray | None = None
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The pairs of boxes that overlap once each is grown by ``pad`` [m], in chunks.

    Each box is entered in every cell of a uniform grid it covers, and pairs are taken
    within cells: with ``label``, only between boxes of different labels (a cell holding
    many triangles of one surface and one of another makes as many pairs as the first
    has triangles, not their square). A pair is kept only in the cell holding the lowest
    corner of the two boxes' overlap, so it comes once without sorting the pairs.

    Parameters
    ----------
    lo, hi : (N, 3) float64 [m]
    pad : float [m]
    label : (N,) int or None
        None: every pair.

    Yields
    ------
    (K,) int64, (K,) int64: ``i < j``; every overlapping pair once over all chunks of at
    most about :data:`PAIRS_PER_CHUNK` candidates.
    """
    label = np.arange(len(lo)) if label is None else np.asarray(label, np.int64)
    lo, hi = lo - pad, hi + pad
    extent = float(np.linalg.norm(hi.max(axis=0) - lo.min(axis=0)))
    cell = max(float(np.median((hi - lo).max(axis=1))), extent / GRID_CELLS, 1e-300)
    origin = lo.min(axis=0)
    while True:
        first = np.floor((lo - origin) / cell).astype(np.int64)
        span = np.floor((hi - origin) / cell).astype(np.int64) - first + 1
        count = span.prod(axis=1)
        if int(count.sum()) <= MAX_ENTRIES:
            break
        cell *= 2.0
    owner = np.repeat(np.arange(len(lo)), count)
    step = _ramp(count)
    sy, sz = span[owner, 1], span[owner, 2]
    cells = first[owner] + np.stack([step // (sy * sz), (step // sz) % sy, step % sz], axis=1)
    key = np.ravel_multi_index(
        (cells - cells.min(axis=0)).T, tuple(cells.max(axis=0) - cells.min(axis=0) + 1)
    )
    order = np.lexsort((label[owner], key))
    key, owner, cells = key[order], owner[order], cells[order]
    group = key * (int(label.max()) + 1) + label[owner]  # (cell, label), sorted
    group_end = np.searchsorted(group, group, side="right")
    partners = np.searchsorted(key, key, side="right") - group_end  # larger labels, same cell
    total = np.cumsum(partners)
    if len(total) == 0 or total[-1] == 0:
        return
    bounds = np.searchsorted(total, np.arange(0, int(total[-1]), PAIRS_PER_CHUNK), side="right")
    for start, stop in zip(bounds, [*bounds[1:].tolist(), len(key)], strict=True):
        part = partners[start:stop]
        entry = np.repeat(np.arange(start, stop), part)
        a, b = owner[entry], owner[np.repeat(group_end[start:stop], part) + _ramp(part)]
        corner = np.floor((np.maximum(lo[a], lo[b]) - origin) / cell).astype(np.int64)
        keep = np.all(corner == cells[entry], axis=1)
        keep &= np.all((lo[a] <= hi[b]) & (lo[b] <= hi[a]), axis=1)
        a, b = a[keep], b[keep]
        yield np.minimum(a, b), np.maximum(a, b)


def _ramp(counts: np.ndarray) -> np.ndarray:
    """0, 1, ..., c - 1 for each c of ``counts``, concatenated."""
    return np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)


def _shared_segments(
    a: np.ndarray, na: np.ndarray, b: np.ndarray, nb: np.ndarray, band: float
) -> tuple[np.ndarray, np.ndarray]:
    """The segment triangles ``a`` and ``b`` (K, 3, 3) share, with their unit normals
    (K, 3): (K, 2, 3) end points [m] and (K,) bool, whether they cross along a segment
    longer than ``band`` (rows where they do not are zeros)."""
    db = np.einsum("kcj,kj->kc", b - a[:, :1], na)  # b's corners above a's plane
    sb = sign_with_band(db, band)
    crossing = (sb.max(axis=1) > 0) & (sb.min(axis=1) < 0)
    da = np.zeros_like(db)
    da[crossing] = np.einsum("kcj,kj->kc", a[crossing] - b[crossing, :1], nb[crossing])
    sa = sign_with_band(da, band)
    crossing &= (sa.max(axis=1) > 0) & (sa.min(axis=1) < 0)
    line = np.cross(na, nb)
    length = np.linalg.norm(line, axis=1)
    crossing &= length > 1e-12
    ends = np.zeros((len(a), 2, 3))
    rows = np.flatnonzero(crossing)
    if len(rows) == 0:
        return ends, crossing
    line = line[rows] / length[rows, None]
    pa, ta = _cut(a[rows], da[rows], sa[rows], line)
    pb, tb = _cut(b[rows], db[rows], sb[rows], line)
    low = np.where((ta[:, 0] >= tb[:, 0])[:, None], pa[:, 0], pb[:, 0])
    high = np.where((ta[:, 1] <= tb[:, 1])[:, None], pa[:, 1], pb[:, 1])
    ends[rows] = np.stack([low, high], axis=1)
    crossing[rows] = np.minimum(ta[:, 1], tb[:, 1]) - np.maximum(ta[:, 0], tb[:, 0]) > band
    return ends, crossing


def _cut(
    corners: np.ndarray, distance: np.ndarray, side: np.ndarray, line: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where triangles (K, 3, 3) cross a plane, given their corners' signed ``distance``
    to it and its banded ``side`` (K, 3): the two end points (K, 2, 3) [m] of the cut,
    ordered along ``line`` (K, 3), and their positions along it (K, 2) [m]. A corner on
    the plane is an end; so is each edge whose ends lie on opposite sides. Rows that do
    not cross are filled but meaningless."""
    nxt = np.roll(np.arange(3), -1)
    d0, d1 = distance, distance[:, nxt]
    edge = (side * side[:, nxt]) < 0
    s = np.divide(d0, d0 - d1, out=np.zeros_like(d0), where=edge)
    on_edge = corners + s[:, :, None] * (corners[:, nxt] - corners)
    points = np.concatenate([on_edge, corners], axis=1)  # (K, 6, 3)
    valid = np.concatenate([edge, side == 0], axis=1)
    t = np.einsum("kcj,kj->kc", points, line)
    t_low = np.where(valid, t, np.inf)
    t_high = np.where(valid, t, -np.inf)
    lo, hi = t_low.argmin(axis=1), t_high.argmax(axis=1)
    rows = np.arange(len(points))
    ends = np.stack([points[rows, lo], points[rows, hi]], axis=1)
    return ends, np.stack([t[rows, lo], t[rows, hi]], axis=1)


__all__ = ["box_pairs", "intersection_segments"]
