"""Embree's packet queries behind :mod:`raytrad.core.compiled`, written for numba
(imported only there): rays filled into 8-ray packets (``RTCRay8``, ``RTCRayHit8``) and
handed to ``rtcOccluded8`` and ``rtcIntersect8`` of the library
:func:`raytrad.core.embree.library_path` finds, by name: numba links the two functions
from the library :func:`raytrad.core.compiled.link_embree` loads, so its cache keeps the
compiled loops across processes.
When no library is found, :data:`KERNELS` is empty and the rays go through embreex.

Each answers what embreex's ``EmbreeScene.run`` answers for the same float32 rays
(``tnear`` 0, every mask bit, ``tfar`` the segment's length or 1e37), which the tests
compare: ``OCCLUDED`` and ``INTERSECT`` with ``output=True``.
"""

# mypy: ignore-errors

import numpy as np

from raytrad.core import _compiled_kernels as _k
from raytrad.core import embree

#: Embree's ``rtcOccluded8`` and ``rtcIntersect8`` as numba external functions, bound by
#: :func:`raytrad.core.compiled.link_embree` before these loops are compiled.
_occluded8 = _intersect8 = None

#: Every function to compile, each after the helpers it calls (none without the library).
KERNELS: tuple[str, ...] = ()
if embree.usable():
    KERNELS = (
        "_aligned",
        "_packet",
        "_fill",
        "occluded_packets",
        "intersect_packets",
        "_lane",
        "_flush",
        "traced_samples",
    )

#: The helpers that allocate nothing (see :func:`raytrad.core.compiled._jit`).
BORROWING = ("_fill", "_lane", "_flush")

#: Packet width (``RTCRay8``).
K = 8
#: Offsets in a packet, in 4-byte words: the ray's fields, then the hit's
#: (``RTCRay8``: org xyz, tnear, dir xyz, time, tfar, mask, id, flags; ``RTCHit8``: Ng
#: xyz, u, v, primID, geomID, then instance ids). The hit's tail is given room for 16
#: rows of instance ids, whatever levels the library was built with.
_TFAR, _MASK = 8 * K, 9 * K
_U, _V, _PRIM = 15 * K, 16 * K, 17 * K
_WORDS = 35 * K
_INVALID = 0xFFFFFFFF


def _aligned(count):
    """(count,) float32 zeros at an address that is a multiple of 64 bytes (Embree reads
    a packet and its valid mask with aligned vector loads)."""
    buffer = np.zeros(count + 16, dtype=np.float32)
    skip = (64 - buffer.ctypes.data % 64) % 64 // 4
    return buffer[skip : skip + count]


def _packet(words):
    """A packet of ``words`` 4-byte words (its rays, then room for their hits), its
    words as unsigned integers and its valid mask: every lane's mask bits set, ``tnear``,
    ``time``, ``id`` and ``flags`` 0 (Embree writes none of them)."""
    ray = _aligned(words)
    bits = ray.view(np.uint32)
    for k in range(K):
        bits[_MASK + k] = _INVALID
    return ray, bits, _aligned(np.int64(K)).view(np.int32)


def _fill(ray, valid, origins, directions, start, count):
    """Rays ``start:start + count`` into the packet's first lanes (origin, direction;
    the rest of each lane as it was); the other lanes marked invalid."""
    for k in range(K):
        if k < count:
            i = start + k
            valid[k] = -1
            ray[k], ray[K + k], ray[2 * K + k] = origins[i, 0], origins[i, 1], origins[i, 2]
            ray[4 * K + k] = directions[i, 0]
            ray[5 * K + k] = directions[i, 1]
            ray[6 * K + k] = directions[i, 2]
        else:
            valid[k] = 0


def occluded_packets(scene, origins, directions, distances, out):
    """(N,) bool into ``out``: is something hit within ``distances`` along each float32
    ray (``origins``, unit ``directions``, (N, 3))? ``scene``: an ``RTCScene`` handle."""
    ray, _, valid = _packet(np.int64(12 * K))
    n = len(origins)
    for start in range(0, n, K):
        count = min(K, n - start)
        _fill(ray, valid, origins, directions, start, count)
        for k in range(count):
            ray[_TFAR + k] = distances[start + k]
        _occluded8(valid.ctypes.data, scene, ray.ctypes.data, 0)
        for k in range(count):
            out[start + k] = ray[_TFAR + k] < 0.0  # Embree marks a hit with -inf


def intersect_packets(scene, origins, directions, triangle, distance, u, v):
    """The closest hit of each float32 ray (``tfar`` 1e37): into ``triangle`` (N,)
    int64 (-1 for a miss), ``distance`` (N,) float64 [m] (inf for a miss) and the hit's
    barycentric ``u``, ``v`` (N,) float64 (0 for a miss)."""
    ray, words, valid = _packet(np.int64(_WORDS))
    n = len(origins)
    for start in range(0, n, K):
        count = min(K, n - start)
        _fill(ray, valid, origins, directions, start, count)
        for k in range(count):
            ray[_TFAR + k] = 1e37
            for w in range(_PRIM + k, _WORDS, K):  # primID, geomID, instance ids
                words[w] = _INVALID
        _intersect8(valid.ctypes.data, scene, ray.ctypes.data, 0)
        for k in range(count):
            i = start + k
            if words[_PRIM + k] == _INVALID:
                triangle[i], distance[i], u[i], v[i] = -1, np.inf, 0.0, 0.0
            else:
                triangle[i] = words[_PRIM + k]
                distance[i] = ray[_TFAR + k]
                u[i], v[i] = ray[_U + k], ray[_V + k]


def _lane(ray, k, a, b, shift, shorten, segment):
    """The ray from ``a`` towards ``b`` into lane ``k``, made by
    :func:`raytrad.core._compiled_kernels._segment` (into ``segment``: its origin,
    direction and length rows), so that it is the very ray
    :func:`~raytrad.core._compiled_kernels.visibility_rays` would write."""
    origin, direction, length = segment
    _k._segment(a, b, shift, shorten, origin, direction, length, np.int64(0))
    ray[k], ray[K + k], ray[2 * K + k] = origin[0], origin[1], origin[2]
    ray[4 * K + k], ray[5 * K + k], ray[6 * K + k] = direction[0], direction[1], direction[2]
    ray[_TFAR + k] = length[0]


def _flush(scene, ray, valid, count, lane_c, lane_s, far_hidden, near_hidden):
    """Trace the packet's first ``count`` lanes and mark what they find blocked: a far
    sample (``lane_c >= 0``: receiver, sample) in ``far_hidden``, a near item (``lane_s``)
    in ``near_hidden``."""
    for k in range(K):
        valid[k] = -1 if k < count else 0
    _occluded8(valid.ctypes.data, scene, ray.ctypes.data, 0)
    for k in range(count):
        if ray[_TFAR + k] < 0.0:
            if lane_c[k] >= 0:
                far_hidden[lane_c[k], lane_s[k]] = True
            else:
                near_hidden[lane_s[k]] = True


def traced_samples(
    scene,
    origins,
    far,
    doubt,
    sub_targets,
    near_c,
    near_targets,
    shift,
    shorten,
    far_hidden,
    near_hidden,
):
    """A chunk's visibility rays made and traced in packets, without writing them out:
    the far (receiver ``c``, sample ``s``) pairs of ``far`` (C, S) whose receiver is in
    ``doubt`` (C,), row-major, then the near items ``k`` whose receiver ``near_c[k]`` is,
    each ray as :func:`~raytrad.core._compiled_kernels.visibility_rays` makes it (shifted
    by ``shift``, ``shorten`` short of its target). The blocked ones are marked True in
    ``far_hidden`` (C, S) and ``near_hidden`` (B,) bool; returns the rays cast."""
    ray, _, valid = _packet(np.int64(12 * K))
    segment = (np.empty(3, np.float32), np.empty(3, np.float32), np.empty(1, np.float32))
    lane_c = np.empty(K, dtype=np.int64)
    lane_s = np.empty(K, dtype=np.int64)
    lanes = np.int64(0)  # counters as int64 from the start: no helper typed for a literal
    rays = np.int64(0)
    full = np.int64(K)
    for c in range(far.shape[0]):
        if not doubt[c]:
            continue
        for s in range(far.shape[1]):
            if far[c, s]:
                _lane(ray, lanes, origins[c], sub_targets[s], shift, shorten, segment)
                lane_c[lanes], lane_s[lanes] = c, s
                lanes += 1
                if lanes == K:
                    _flush(scene, ray, valid, full, lane_c, lane_s, far_hidden, near_hidden)
                    rays += full
                    lanes = np.int64(0)
    for b in range(len(near_c)):
        if doubt[near_c[b]]:
            _lane(ray, lanes, origins[near_c[b]], near_targets[b], shift, shorten, segment)
            lane_c[lanes], lane_s[lanes] = -1, b
            lanes += 1
            if lanes == K:
                _flush(scene, ray, valid, full, lane_c, lane_s, far_hidden, near_hidden)
                rays += full
                lanes = np.int64(0)
    if lanes:
        _flush(scene, ray, valid, lanes, lane_c, lane_s, far_hidden, near_hidden)
        rays += lanes
    return rays
