"""The facets that shaft culling tests: planar groups of the blocking triangles, and in scenes
of many small ones, volumes that stand for them (:mod:`raytrad.core.shafts` tests them).

A curved or finely tessellated surface (a ball, a statue, a cylinder's side) makes a facet
of every triangle, and the tests per (receiver, patch) pair grow with the facets while
the rays they save do not. Past :data:`MAX_FACETS`, the large facets (walls, table tops,
the faces of boxes), whose side bits settle most pairs at once, stay facets, and the
small ones are gathered by bisection into a few volumes: a bounding sphere and box
without a plane. A pair whose shaft misses a volume's sphere, or lies beyond a plane
that separates the volume's box from it, is clear of everything in the volume.
"""

from __future__ import annotations

import itertools
import logging

import numpy as np

from raytrad.constants import tol
from raytrad.core.refine import cluster_bounds
from raytrad.core.shafts import Facets, plane_hull

log = logging.getLogger(__name__)

#: At most this many facets are culled against (4 words of bits per receiver). The tests
#: per pair grow with the facets, the rays they save do not: in rooms of turned blocks at
#: 5 000 receivers the culled pass (with the convex blockers) took 0.68 of the unculled
#: pass's time at 87 facets, 0.84 at 187, 1.08 at 327 and 1.21 at 507; at 15 000
#: receivers 0.93 at 327 and 1.05 at 507 (2026-12-03, after the shaft test's bit index
#: lost its ``log2``; 128 before that). A scene with more keeps its large facets and
#: gathers the others into volumes (:func:`facets`).
MAX_FACETS = 256
#: In a scene of more than :data:`MAX_FACETS` facets, a facet whose bounding sphere
#: reaches this share of the scene's diagonal stays a facet [1] ...
LARGE_FACET = 0.05
#: ... if there are at most this many (else the scene is not culled; in rooms of 8 x 8
#: and 10 x 10 turned blocks at 5 000 receivers, 128 of their faces kept and the rest
#: in volumes took 1.12-1.24 times the unculled pass) ...
KEPT_FACETS = 128
#: ... and the others are gathered into at most this many volumes. A volume has no side
#: bits, so every pair tests it: few volumes keep the tests per pair few.
VOLUMES = 16
#: The two limits above where rays go through Embree's packets
#: (:mod:`raytrad.core.embree`), whose rays cost about half as much, so culling pays in
#: fewer scenes. Culled over unculled pass time with packets (2026-12-05,
#: ``tools/bench_performance.py --receivers 10000``, one run each): the Cornell box (17
#: facets) 0.73 (at 20 000), rooms of 2 x 2, 3 x 3, 4 x 4 and 6 x 6 turned blocks (27, 52,
#: 87 and 187 facets) 0.88, 1.01, 1.07 and 1.23; past the facets, with volumes, a ball in
#: a box (17 large facets) 0.97 and the cluttered room (72 large facets) 1.17.
PACKET_FACETS = 48
#: ... and past :data:`PACKET_FACETS`, the most large facets kept (see :data:`KEPT_FACETS`).
PACKET_KEPT = 32
#: Normals within this of each other [1] and plane offsets within this x the scene
#: diagonal fall in one coplanar group before the exact planarity check.
_NORMAL_GRID = 1e-6


def facets(
    positions: np.ndarray,
    triangles: np.ndarray,
    diagonal: float,
    most: int = MAX_FACETS,
    most_large: int = KEPT_FACETS,
) -> Facets | None:
    """The planar facets of the blocking triangles, and in a scene of more than ``most``
    (:data:`MAX_FACETS`) of them, volumes that stand for the small ones.

    Triangles are grouped by their plane (normal and offset on a fine grid); a triangle
    whose corners are not all within ``tol.horizon`` x ``diagonal`` of its group's plane
    becomes a facet of its own, so every facet is flat to that tolerance. Triangles without
    area block nothing and are left out.

    A curved or finely tessellated surface makes a facet of every triangle. Past
    ``most``, the facets whose bounding sphere reaches :data:`LARGE_FACET` of the
    diagonal (walls, table tops, the faces of boxes) stay facets, and the others are
    gathered by bisection into at most :data:`VOLUMES` *volumes* (:func:`_volumes`);
    with more than ``most_large`` (:data:`KEPT_FACETS`) large facets (a room of many boxes)
    the tests would cost more than the rays they save, and the scene is not culled
    (None). Rays in Embree's packets take :data:`PACKET_FACETS` and :data:`PACKET_KEPT`.

    A volume has no plane (its normal is 0, so no side bit is ever set for it, and the
    pyramid test, which needs a plane, never runs), a bounding sphere holding its
    triangles, and as its hull the corners of its bounding box: the capsule test and the
    planes that separate a facet from the shaft hold for any set inside the convex hull
    of those points.

    Parameters
    ----------
    positions : (V, 3) float64 [m]
    triangles : (T, 3) int
    diagonal : float
        The scene's diagonal [m].
    most, most_large : int
        The limits above; ``most`` at most :data:`MAX_FACETS` (the side bits' words).

    Returns
    -------
    Facets, or None: no triangle has area, or too many large facets.
    """
    corners = np.asarray(positions, dtype=np.float64)[np.asarray(triangles)]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1)
    keep = length > 0
    corners, normal = corners[keep], normal[keep] / length[keep, None]
    if not len(corners):
        return None
    group, n, d = _planar_groups(corners, normal, diagonal)
    count = len(d)
    flat = tol.horizon * diagonal
    lo, hi = _corner_bounds(corners, group, count)
    center = 0.5 * (lo + hi)
    radius = _group_radius(corners, group, center, count)
    planar = np.ones(count, dtype=bool)
    volume = np.full(count, -1, dtype=np.int64)
    if count > min(most, MAX_FACETS):
        if np.count_nonzero(radius >= LARGE_FACET * diagonal) > most_large:
            log.debug("%d facets, more than %d large: no shaft culling", count, most_large)
            return None
        planar, volume = _split(radius, lo, hi, diagonal)
        log.debug(
            "%d facets > %d: %d kept, the rest in %d volumes",
            count,
            most,
            int(planar.sum()),
            volume.max(initial=-1) + 1,
        )
    kept = np.flatnonzero(planar)
    hulls = _plane_hulls(corners, group, n, kept)
    normals, offsets, centers, radii = [n[kept]], [d[kept]], [center[kept]], [radius[kept]]
    volumes = int(volume[~planar].max(initial=-1)) + 1
    if volumes:
        # a triangle's volume: its facet's; the triangles of kept facets have none (-1)
        of_triangle = np.where(planar[group], -1, volume[group])
        inside = of_triangle >= 0
        v_lo, v_hi = _corner_bounds(corners[inside], of_triangle[inside], volumes)
        v_center = 0.5 * (v_lo + v_hi)
        normals.append(np.zeros((volumes, 3)))
        offsets.append(np.zeros(volumes))
        centers.append(v_center)
        radii.append(_group_radius(corners[inside], of_triangle[inside], v_center, volumes))
        box = np.stack([v_lo - flat, v_hi + flat], axis=1)  # (volumes, 2, 3)
        pick = np.array(list(itertools.product((0, 1), repeat=3)))  # (8, 3) corner choices
        hulls += list(box[:, pick, [0, 1, 2]])  # each (8, 3)
    hull_ptr = np.concatenate([[0], np.cumsum([len(h) for h in hulls])]).astype(np.int64)
    return Facets(
        np.concatenate(normals),
        np.concatenate(offsets),
        np.concatenate(centers),
        np.concatenate(radii) + flat,
        np.concatenate(hulls) if hulls else np.zeros((0, 3)),
        hull_ptr,
        flat,
        0.25 * tol.ray_offset * diagonal,
    )


def _planar_groups(
    corners: np.ndarray, normal: np.ndarray, diagonal: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each triangle's facet (its plane's group), and the facets' planes: (T,) int64,
    (Q, 3) unit normals (largest component positive) and (Q,) offsets [m]."""
    normal = (
        normal * np.sign(normal[np.arange(len(normal)), np.abs(normal).argmax(axis=1)])[:, None]
    )
    offset = np.einsum("tj,tj->t", normal, corners.mean(axis=1))
    flat = tol.horizon * diagonal
    key = np.concatenate(
        [np.round(normal / _NORMAL_GRID), np.round(offset / (_NORMAL_GRID * diagonal))[:, None]],
        axis=1,
    ).astype(np.int64)
    _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.reshape(-1)
    lead_tri = np.full(group.max(initial=-1) + 1, -1)
    lead_tri[group[::-1]] = np.arange(len(group))[::-1]  # first triangle of each group
    plane_n, plane_d = normal[lead_tri[group]], offset[lead_tri[group]]
    off_plane = np.abs(np.einsum("tkj,tj->tk", corners, plane_n) - plane_d[:, None]).max(axis=1)
    alone = off_plane > flat
    group = np.where(alone, group.max(initial=-1) + 1 + np.arange(len(group)), group)
    _, group = np.unique(group, return_inverse=True)
    group = group.reshape(-1)
    first = np.full(int(group.max()) + 1, -1)
    first[group[::-1]] = np.arange(len(group))[::-1]
    return group, normal[first], offset[first]


def _corner_bounds(
    corners: np.ndarray, group: np.ndarray, count: int
) -> tuple[np.ndarray, np.ndarray]:
    """(count, 3) lower and upper corners of each group's triangles' bounding box [m]
    (:func:`~raytrad.core.refine.cluster_bounds` of the triangles' corners)."""
    lo, hi = cluster_bounds(corners.reshape(-1, 3), np.repeat(group, 3), count)
    return lo, hi


def _group_radius(
    corners: np.ndarray, group: np.ndarray, center: np.ndarray, count: int
) -> np.ndarray:
    """(count,) the radius about ``center`` of a ball holding each group's triangles [m]."""
    reach = np.linalg.norm(corners - center[group][:, None, :], axis=2).max(axis=1)
    radius = np.zeros(count)
    np.maximum.at(radius, group, reach)
    return radius


def _plane_hulls(
    corners: np.ndarray, group: np.ndarray, normal: np.ndarray, kept: np.ndarray
) -> list[np.ndarray]:
    """The convex hull in its plane (:func:`plane_hull`) of each ``kept`` facet."""
    order = np.argsort(group, kind="stable")
    bounds = np.searchsorted(group[order], np.stack([kept, kept + 1]))
    return [
        plane_hull(corners[order[a:b]].reshape(-1, 3), normal[q])
        for q, a, b in zip(kept, bounds[0], bounds[1], strict=True)
    ]


def _split(
    radius: np.ndarray, lo: np.ndarray, hi: np.ndarray, diagonal: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which facets stay facets in a scene of more facets than the limit (see
    :func:`facets`), and the volume of each of the others.

    Returns
    -------
    planar : (Q,) bool
    volume : (Q,) int64, consecutive from 0 over the facets not kept (-1 for kept ones)
    """
    planar = radius >= LARGE_FACET * diagonal
    rest = np.flatnonzero(~planar)
    volume = np.full(len(radius), -1, dtype=np.int64)
    volume[rest] = _volumes(lo[rest], hi[rest], VOLUMES)
    # a volume of one facet is that facet: exact, and its side bits cull
    sizes = np.bincount(volume[rest], minlength=VOLUMES)
    alone = rest[sizes[volume[rest]] == 1]
    planar[alone] = True
    volume[alone] = -1
    rest = np.flatnonzero(~planar)
    volume[rest] = np.unique(volume[rest], return_inverse=True)[1].reshape(-1)
    return planar, volume


def _volumes(lo: np.ndarray, hi: np.ndarray, limit: int) -> np.ndarray:
    """(M,) labels of at most ``limit`` groups of boxes ((M, 3) corners): the group of
    the largest extent is halved at the median of its boxes' centres along its longest
    axis until there are ``limit`` groups, or none of more than one box is left to split."""
    middle = 0.5 * (lo + hi)
    groups = [np.arange(len(lo))]
    extent = [_extent(lo, hi, groups[0])]
    while len(groups) < limit:
        size = np.array([e if len(g) > 1 else -1.0 for g, e in zip(groups, extent, strict=True)])
        pick = int(np.argmax(size))
        if size[pick] < 0:
            break
        members = groups[pick]
        spread = middle[members].max(axis=0) - middle[members].min(axis=0)
        axis = int(np.argmax(spread))
        order = members[np.argsort(middle[members, axis], kind="stable")]
        half = len(order) // 2
        groups[pick : pick + 1] = [order[:half], order[half:]]
        extent[pick : pick + 1] = [_extent(lo, hi, order[:half]), _extent(lo, hi, order[half:])]
    labels = np.empty(len(lo), dtype=np.int64)
    for label, members in enumerate(groups):
        labels[members] = label
    return labels


def _extent(lo: np.ndarray, hi: np.ndarray, members: np.ndarray) -> float:
    """The diagonal of the bounding box of boxes ``members`` [m]."""
    return float(np.linalg.norm(hi[members].max(axis=0) - lo[members].min(axis=0)))


__all__ = [
    "KEPT_FACETS",
    "LARGE_FACET",
    "MAX_FACETS",
    "PACKET_FACETS",
    "PACKET_KEPT",
    "VOLUMES",
    "facets",
]
