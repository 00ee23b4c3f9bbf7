"""Shaft culling: the (receiver, patch) pairs that nothing can occlude, found before tracing.

A ray from a receiver to a patch can be blocked only by a surface that the segment
crosses. raytrad groups the scene's blocking triangles into planar *facets* (coplanar
triangles, each with a bounding sphere) and keeps, per receiver and per facet, one bit for
"strictly in front of the facet's plane" and one for "strictly behind" (Haines and Wallace
1994 test shafts against the planes of their occluders' bounding volumes in the same
spirit). A facet cannot block any ray from a receiver to a patch when

* the receiver and every ray target on the patch lie on the same side of its plane (a
  segment between two points on one side never crosses it), or
* it misses the shaft: its bounding sphere is outside the capsule around the segment from
  the receiver to the patch's centre (as wide as the patch's bounding sphere), or the
  patch's bounding ball is wholly outside one side plane of the pyramid from the receiver
  through the facet's convex hull (then no segment to the patch passes through it).

A pair that no facet can block is *clear*: its visible fraction is exactly 1 and it needs
no ray. The test is conservative (a pair called clear has no occluder in its shaft), so
culling changes no factor; ``tests/core/test_shafts.py`` compares culled and unculled
passes. In a room, the walls, floor and ceiling never separate a receiver from a patch,
so only the furniture is ever tested.

The per-receiver bits are packed 64 facets to a word; per (receiver, patch) pair the
candidate facets are then a few word operations, and only those get the capsule and
pyramid tests (:func:`~raytrad.core.kernels.shaft_clear`, compiled). Scenes with more than
:data:`MAX_FACETS` facets (curved, finely tessellated surfaces) are not culled: every pair
is traced, as before.

References
----------
Haines, E. A. and Wallace, J. R. (1994). Shaft culling for efficient ray-traced radiosity.
In *Photorealistic Rendering in Computer Graphics* (Proceedings of the second Eurographics
Workshop on Rendering, 1991), Springer.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from raytrad.constants import tol
from raytrad.core.kernels import shaft_clear

log = logging.getLogger(__name__)

#: At most this many facets are culled against (4 words of bits per receiver); a scene with
#: more is traced pair by pair, unculled.
MAX_FACETS = 256
#: Normals within this of each other [1] and plane offsets within this x the scene
#: diagonal fall in one coplanar group before the exact planarity check.
_NORMAL_GRID = 1e-6


@dataclass(frozen=True)
class Facets:
    """Planar groups of the blocking triangles.

    Attributes
    ----------
    normal : (Q, 3) float64, unit plane normals (sign fixed: largest component positive)
    offset : (Q,) float64, plane offsets: ``normal . p = offset`` on the plane [m]
    center : (Q, 3) float64, bounding-sphere centres [m]
    radius : (Q,) float64, bounding-sphere radii [m]
    hull, hull_ptr : (K, 3) float64, (Q + 1,) int64: each facet's convex hull in its plane,
        counter-clockwise about ``normal`` (CSR) [m]
    flat : float
        Every facet's corners lie within ``flat`` of its plane; points within it are on
        the plane [m].
    band : float
        A ray origin counts as in front of (behind) a plane when more than ``band`` above
        (below) it [m]: a receiver's origin, ``tol.ray_offset`` x diagonal off its own
        surface, is in front of that surface's facet.
    """

    normal: np.ndarray
    offset: np.ndarray
    center: np.ndarray
    radius: np.ndarray
    hull: np.ndarray
    hull_ptr: np.ndarray
    flat: float
    band: float

    @property
    def count(self) -> int:
        return len(self.offset)

    @property
    def words(self) -> int:
        """uint64 words per receiver for one side's bits."""
        return max(1, -(-self.count // 64))

    def heights(self, points: np.ndarray) -> np.ndarray:
        """(N, Q) signed heights of ``points`` above each facet's plane [m]."""
        return np.asarray(points, dtype=np.float64) @ self.normal.T - self.offset[None, :]

    def sides(self, origins: np.ndarray) -> np.ndarray:
        """Packed side bits of ray origins.

        Parameters
        ----------
        origins : (N, 3) float64
            Ray origins [m].

        Returns
        -------
        (N, 2 W) uint64: bit ``q`` of words ``0..W-1`` says the origin is strictly in front
        of facet ``q``, of words ``W..2W-1`` strictly behind it.
        """
        out = np.empty((len(origins), 2 * self.words), dtype=np.uint64)
        for a in range(0, len(origins), 1 << 16):  # bounded temporaries
            h = self.heights(origins[a : a + (1 << 16)])
            out[a : a + len(h)] = np.concatenate(
                [_pack(h > self.band, self.words), _pack(h < -self.band, self.words)], axis=1
            )
        return out

    def patch_sides(
        self, vertices: np.ndarray, normal: np.ndarray | None, lift: float
    ) -> np.ndarray:
        """Packed side bits of a patch's ray targets: points of its triangles lifted
        ``lift`` along its normal (``normal`` None: a folded patch, lifted along any
        direction).

        Returns
        -------
        (2 W,) uint64: bit ``q`` of the first W words says every target is on or in front
        of facet ``q``, of the last W on or behind it.
        """
        h = self.heights(vertices)  # (V, Q)
        if normal is None:
            low, high = h.min(axis=0) - lift, h.max(axis=0) + lift
        else:
            shift = lift * (self.normal @ normal)
            low, high = h.min(axis=0) + shift, h.max(axis=0) + shift
        return np.concatenate(
            [
                _pack((low >= -self.flat)[None, :], self.words)[0],
                _pack((high <= self.flat)[None, :], self.words)[0],
            ]
        )

    def clear(
        self,
        origins: np.ndarray,
        sides: np.ndarray,
        patch_sides: np.ndarray,
        patch_center: np.ndarray,
        patch_reach: float,
    ) -> np.ndarray:
        """(N,) bool: receivers whose shaft to the patch no facet can block (see
        :func:`~raytrad.core.kernels.shaft_clear`)."""
        return shaft_clear(
            origins,
            sides,
            patch_sides,
            self.normal,
            self.offset,
            self.center,
            self.radius,
            self.hull,
            self.hull_ptr,
            self.band,
            patch_center,
            patch_reach,
        )


def facets(positions: np.ndarray, triangles: np.ndarray, diagonal: float) -> Facets | None:
    """The planar facets of the blocking triangles, or None when there are more than
    :data:`MAX_FACETS` (no culling).

    Triangles are grouped by their plane (normal and offset on a fine grid); a triangle
    whose corners are not all within ``tol.horizon`` x ``diagonal`` of its group's plane
    becomes a facet of its own, so every facet is flat to that tolerance. Triangles without
    area block nothing and are left out.

    Parameters
    ----------
    positions : (V, 3) float64 [m]
    triangles : (T, 3) int
    diagonal : float
        The scene's diagonal [m].
    """
    corners = np.asarray(positions, dtype=np.float64)[np.asarray(triangles)]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1)
    keep = length > 0
    corners, normal = corners[keep], normal[keep] / length[keep, None]
    lead = np.abs(normal).argmax(axis=1)
    normal *= np.sign(normal[np.arange(len(normal)), lead])[:, None]
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
    count = int(group.max(initial=-1)) + 1
    if count > MAX_FACETS:
        log.debug("%d facets > %d: no shaft culling", count, MAX_FACETS)
        return None
    first = np.full(count, -1)
    first[group[::-1]] = np.arange(len(group))[::-1]
    n, d = normal[first], offset[first]
    lo = np.full((count, 3), np.inf)
    hi = np.full((count, 3), -np.inf)
    np.minimum.at(lo, group, corners.min(axis=1))
    np.maximum.at(hi, group, corners.max(axis=1))
    center = 0.5 * (lo + hi)
    reach = np.linalg.norm(corners - center[group][:, None, :], axis=2).max(axis=1)
    radius = np.zeros(count)
    np.maximum.at(radius, group, reach)
    hulls = [_plane_hull(corners[group == q].reshape(-1, 3), n[q]) for q in range(count)]
    hull_ptr = np.concatenate([[0], np.cumsum([len(h) for h in hulls])]).astype(np.int64)
    return Facets(
        n,
        d,
        center,
        radius + flat,
        np.concatenate(hulls) if hulls else np.zeros((0, 3)),
        hull_ptr,
        flat,
        0.25 * tol.ray_offset * diagonal,
    )


def _plane_hull(points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(K, 3) the convex hull of coplanar points, counter-clockwise about ``normal``
    (Andrew's monotone chain on the plane's coordinates)."""
    u = np.cross(normal, np.eye(3)[np.abs(normal).argmin()])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    uv = np.unique(np.stack([points @ u, points @ v], axis=1), axis=0)  # sorted by u, v
    index = np.arange(len(uv))

    def chain(order: np.ndarray) -> list[int]:
        out: list[int] = []
        for i in order:
            while len(out) >= 2:
                a, b = uv[out[-2]], uv[out[-1]]
                if (b[0] - a[0]) * (uv[i][1] - a[1]) - (b[1] - a[1]) * (uv[i][0] - a[0]) > 0:
                    break
                out.pop()
            out.append(int(i))
        return out[:-1]

    ring = chain(index) + chain(index[::-1])
    if len(ring) < 3:  # a sliver: keep every point (the edge test then separates nothing)
        ring = list(index)
    # lift back: the plane point of each hull vertex in the facet's plane coordinates
    offset = float(np.mean(points @ normal))
    return uv[ring, 0:1] * u + uv[ring, 1:2] * v + offset * normal


def _pack(bits: np.ndarray, words: int) -> np.ndarray:
    """(N, Q) bool -> (N, words) uint64, bit q of word q // 64 (little-endian)."""
    padded = np.zeros((len(bits), words * 64), dtype=bool)
    padded[:, : bits.shape[1]] = bits
    return np.packbits(padded, axis=1, bitorder="little").view("<u8").astype(np.uint64)


__all__ = ["MAX_FACETS", "Facets", "facets"]
