"""The search for points near segments behind :mod:`raytrad.core.compiled`, written for
numba (imported only there): the (item, segment) pairs of one reach class, found through
the cells around points sampled along each segment and measured at once, without the
27-fold key arrays of the numpy path. Plain Python as written here;
:func:`raytrad.core.compiled.get` compiles every function in :data:`KERNELS`. It finds
the same pairs as its numpy reference (:func:`raytrad.core.segment_search.cell_pairs`,
then :func:`raytrad.core.segment_search.distance_to_segment`); see there for shapes and
units.
"""

# mypy: ignore-errors

import math

import numpy as np

#: Every function to compile, each after the helpers it calls.
KERNELS = ("_key", "_slot", "_near_cells", "segment_candidates")

#: Hash multipliers of a cell's three integer coordinates (as ``segment_search.cell_key``).
_K0, _K1, _K2 = 73856093, 19349663, 83492791
#: 2**64 over the golden ratio: spreads the keys over the table's slots.
_FIBONACCI = 0x9E3779B97F4A7C15


def _key(x, y, z):
    """The cell key of integer cell (x, y, z), as ``segment_search.cell_key``."""
    return (
        np.uint64(x) * np.uint64(_K0)
        ^ np.uint64(y) * np.uint64(_K1)
        ^ np.uint64(z) * np.uint64(_K2)
    )


def _slot(key, shift):
    """Where ``key`` starts its probe in a table of ``2**(64 - shift)`` slots."""
    return np.int64((key * np.uint64(_FIBONACCI)) >> shift)


def _near_cells(cells, shift):
    """A bit (one hash, a Bloom filter's) for the key of every cell within one of
    ``cells`` (M, 3), in ``2**(64 - shift)`` bits: a sample whose own cell's bit is clear
    has no item in its 27 cells, and is passed over with one test instead of 27 probes; a
    set bit may be another cell's, which the probes then find empty. A bit an entry keeps
    it small: 16 bytes an item at a fill of at most 27 in 128."""
    words = np.zeros(((1 << (64 - int(shift))) + 63) // 64, dtype=np.uint64)
    for a in range(len(cells)):
        for o in range(27):  # one loop, not three: numba compiles it in a fraction
            key = _key(
                cells[a, 0] + o // 9 - 1, cells[a, 1] + o // 3 % 3 - 1, cells[a, 2] + o % 3 - 1
            )
            h = _slot(key, shift)
            words[h >> 6] |= np.uint64(1) << np.uint64(h & 63)
    return words


def segment_candidates(points, reach, samples, owner, segments, origin, cell, keys, by_key, cells):
    """(item, segment) pairs whose item point lies within its ``reach`` of the segment.

    ``points`` (M, 3) and ``reach`` (M,) are the items of one class, ``samples`` (K, 3)
    points along the (S, 2, 3) ``segments`` (``owner`` (K,) says whose), every ``cell``
    [m] apart at most; ``keys`` (M,) uint64 are the items' cell keys in ascending order
    and ``by_key`` (M,) their items, ``cells`` (M, 3) int64 their cells in the same
    order. An item in one of the 27 cells around a sample of a segment (by key: cells
    sharing a key are searched too) is measured against that segment once. Pairs come in
    no particular order, each once."""
    m = len(keys)
    # the distinct keys in an open-addressing table (Fibonacci hashing, linear probing):
    # a lookup takes a probe or two where a binary search took a dozen unpredictable steps
    bits = 4
    while (1 << bits) < 2 * m:
        bits += 1
    mask = (1 << bits) - 1
    shift = np.uint64(64 - bits)
    table_key = np.zeros(mask + 1, dtype=np.uint64)
    table_start = np.full(mask + 1, -1, dtype=np.int64)
    table_stop = np.full(mask + 1, -1, dtype=np.int64)  # empty: range(-1, -1)
    slot = 0
    while slot < m:
        stop = slot + 1
        while stop < m and keys[stop] == keys[slot]:
            stop += 1
        h = _slot(keys[slot], shift)
        while table_start[h] >= 0:
            h = (h + 1) & mask
        table_key[h], table_start[h], table_stop[h] = keys[slot], slot, stop
        slot = stop
    near_bits = 6
    while (1 << near_bits) < 128 * m:
        near_bits += 1
    near_shift = np.uint64(64 - near_bits)
    near = _near_cells(cells, near_shift)
    size = max(16, 4 * m)
    out_item = np.empty(size, dtype=np.int64)
    out_segment = np.empty(size, dtype=np.int64)
    seen = np.full(len(points), -1, dtype=np.int64)  # the last segment each item was measured for
    found = 0
    last_j, last_x, last_y, last_z = -1, 0, 0, 0
    for k in range(len(samples)):
        j = owner[k]
        px, py, pz = segments[j, 0, 0], segments[j, 0, 1], segments[j, 0, 2]
        dx, dy, dz = segments[j, 1, 0] - px, segments[j, 1, 1] - py, segments[j, 1, 2] - pz
        square = dx * dx + dy * dy + dz * dz
        cx = np.int64(math.floor((samples[k, 0] - origin[0]) / cell))
        cy = np.int64(math.floor((samples[k, 1] - origin[1]) / cell))
        cz = np.int64(math.floor((samples[k, 2] - origin[2]) / cell))
        if j == last_j and cx == last_x and cy == last_y and cz == last_z:
            continue  # the cells the segment's last sample searched
        last_j, last_x, last_y, last_z = j, cx, cy, cz
        key = _key(cx, cy, cz)
        h = _slot(key, near_shift)
        if not (near[h >> 6] >> np.uint64(h & 63)) & np.uint64(1):
            continue  # no item within a cell of this one
        for o in range(27):  # the 27 cells around the sample, in one loop
            key = _key(cx + o // 9 - 1, cy + o // 3 % 3 - 1, cz + o % 3 - 1)
            h = _slot(key, shift)
            while table_start[h] >= 0 and table_key[h] != key:
                h = (h + 1) & mask
            for slot in range(table_start[h], table_stop[h]):  # none if not found
                i = by_key[slot]
                if seen[i] == j:
                    continue
                seen[i] = j
                ex, ey, ez = points[i, 0] - px, points[i, 1] - py, points[i, 2] - pz
                t = (ex * dx + ey * dy + ez * dz) / (square if square > 0 else 1.0)
                t = min(max(t, 0.0), 1.0)
                gx = points[i, 0] - (px + t * dx)
                gy = points[i, 1] - (py + t * dy)
                gz = points[i, 2] - (pz + t * dz)
                if not math.sqrt(gx * gx + gy * gy + gz * gz) <= reach[i] * (1 + 1e-9):
                    continue
                if found == size:  # copied in a loop: numba compiles a slice copy slowly
                    size *= 2
                    grown_item = np.empty(size, dtype=np.int64)
                    grown_segment = np.empty(size, dtype=np.int64)
                    for c in range(found):
                        grown_item[c], grown_segment[c] = out_item[c], out_segment[c]
                    out_item, out_segment = grown_item, grown_segment
                out_item[found] = i
                out_segment[found] = j
                found += 1
    return out_item[:found], out_segment[:found]
