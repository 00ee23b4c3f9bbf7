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
  the receiver to the patch's centre (as wide as the patch's bounding sphere), or a plane
  separates it from the shaft, the convex hull of the receiver and the patch's ray
  targets. The planes tried: each side plane of the pyramid from the receiver through the
  facet's convex hull, with the patch's bounding ball or every corner of a convex set
  holding its targets outside it (then no segment to the patch passes through the facet);
  and, for a planar patch, the patch's own plane and each side plane of the shaft from
  the receiver through the patch's convex outline, with the whole facet outside it. Each
  keeps a margin for the targets' lift off the surface and the facets' flatness.

A pair that no facet can block is *clear*: its visible fraction is exactly 1 and it needs
no ray. The test is conservative (a pair called clear has no occluder in its shaft), so
culling changes no factor; ``tests/core/test_shafts.py`` compares culled and unculled
passes. In a room, the walls, floor and ceiling never separate a receiver from a patch,
so only the furniture is ever tested.

The per-receiver bits are packed 64 facets to a word; per (receiver, patch) pair the
candidate facets are then a few word operations, and only those get the capsule and
plane tests (:func:`shaft_clear`, compiled). The facets come from
:func:`raytrad.core.facets.facets`: curved or finely tessellated surfaces make a facet of
every triangle, and past a few hundred facets the small ones are gathered into a few
*volumes* (a bounding sphere and box, no plane), which every pair tests, so such a scene
is culled around them instead of traced pair by pair.

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

from raytrad.core import compiled
from raytrad.core.kernels import _f64

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Facets:
    """Planar groups of the blocking triangles.

    Attributes
    ----------
    normal : (Q, 3) float64, unit plane normals (sign fixed: largest component positive);
        0 for a volume (:func:`raytrad.core.facets.facets`), never on a side of anything
    offset : (Q,) float64, plane offsets: ``normal . p = offset`` on the plane [m]; 0 for
        a volume
    center : (Q, 3) float64, bounding-sphere centres [m]
    radius : (Q,) float64, bounding-sphere radii [m]
    hull, hull_ptr : (K, 3) float64, (Q + 1,) int64: each facet's convex hull in its plane,
        counter-clockwise about ``normal``, or a volume's 8 box corners (CSR) [m]
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
        end: ShaftEnd,
    ) -> np.ndarray:
        """(N,) bool: receivers whose shaft to the patch (its ``end``) no facet can block
        (see :func:`shaft_clear`)."""
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
            end.center,
            end.reach,
            end.targets,
            end.outline,
            end.normal,
            np.array([self.flat, end.lift, end.level, end.thick]),
        )


@dataclass(frozen=True)
class ShaftEnd:
    """A patch's end of the shafts from receivers to it.

    Attributes
    ----------
    center : (3,) float64, the centre of a ball holding every ray target [m]
    reach : float, its radius [m]
    targets : (V, 3) float64, corners of a convex set holding every ray target [m]
    outline : (E, 3) float64, a planar patch's convex outline in its plane, (0, 3) for a
        folded one [m]
    normal : (3,) float64, a planar patch's unit normal (its targets' side)
    lift : float, how far the ray targets sit above the patch along ``normal`` [m]
    level : float, the patch's lowest height ``normal . p`` [m]
    thick : float, its height range along ``normal`` [m]
    """

    center: np.ndarray
    reach: float
    targets: np.ndarray
    outline: np.ndarray
    normal: np.ndarray
    lift: float
    level: float
    thick: float


def shaft_end(
    vertices: np.ndarray,
    hull: np.ndarray,
    normal: np.ndarray | None,
    center: np.ndarray,
    reach: float,
    targets: np.ndarray | None,
    lift: float,
) -> ShaftEnd:
    """The :class:`ShaftEnd` of a patch from its vertices (V, 3), its convex outline in
    order (``hull``, :func:`plane_hull` of its outline's corners), its normal (None: a
    folded patch, which gets no outline), its ball, the corners of a convex set holding
    its ray targets and their lift [m].

    ``targets`` None (a planar patch only): the hull moved ``2 lift`` plus the patch's
    height range both ways along its normal (:func:`prism`; a patch counts as planar by
    its normals alone, so its corners may spread a little in height).

    Raises
    ------
    ValueError
        A folded patch without ``targets``.
    """
    if normal is None:
        if targets is None:
            raise ValueError("a folded patch's shaft end needs the corners of its targets")
        return ShaftEnd(center, reach, targets, np.zeros((0, 3)), np.zeros(3), lift, 0.0, 0.0)
    heights = np.asarray(vertices, dtype=np.float64) @ normal
    thick = float(heights.max() - heights.min())
    hull = np.asarray(hull, dtype=np.float64)
    normal = np.asarray(normal, dtype=np.float64)
    if targets is None:
        targets = prism(hull, normal, 2.0 * lift + thick)
    return ShaftEnd(center, reach, targets, hull, normal, lift, float(heights.min()), thick)


def prism(hull: np.ndarray, normal: np.ndarray, height: float) -> np.ndarray:
    """(2 K, 3) a planar patch's convex ``hull`` (K, 3) moved ``height`` both ways along
    its ``normal`` [m]: with ``height`` twice the ray targets' lift plus the patch's own
    height range, a convex set that holds every ray target."""
    return np.concatenate([hull + height * normal, hull - height * normal])


def shaft_clear(
    origins: np.ndarray,
    sides: np.ndarray,
    patch_sides: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    centers: np.ndarray,
    radii: np.ndarray,
    hull: np.ndarray,
    hull_ptr: np.ndarray,
    band: float,
    patch_center: np.ndarray,
    patch_reach: float,
    targets: np.ndarray,
    outline: np.ndarray,
    patch_normal: np.ndarray,
    margins: np.ndarray,
) -> np.ndarray:
    """Receivers whose shaft to a patch no facet can block, compiled when available (see
    :func:`numpy_shaft_clear`, the reference)."""
    args = (origins, sides, patch_sides, normals, offsets, centers, radii, hull, hull_ptr)
    end = (targets, outline, patch_normal, margins)
    fast = compiled.get()
    if fast is None:
        return numpy_shaft_clear(*args, band, patch_center, patch_reach, *end)
    return fast.shaft_clear(
        _f64(origins),
        np.ascontiguousarray(sides, dtype=np.uint64),
        np.ascontiguousarray(patch_sides, dtype=np.uint64),
        _f64(normals),
        _f64(offsets),
        _f64(centers),
        _f64(radii),
        _f64(hull),
        np.ascontiguousarray(hull_ptr, dtype=np.int64),
        float(band),
        _f64(patch_center),
        float(patch_reach),
        _f64(targets).reshape(-1, 3),
        _f64(outline).reshape(-1, 3),
        _f64(patch_normal),
        _f64(margins),
    )


def numpy_shaft_clear(
    origins: np.ndarray,
    sides: np.ndarray,
    patch_sides: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    centers: np.ndarray,
    radii: np.ndarray,
    hull: np.ndarray,
    hull_ptr: np.ndarray,
    band: float,
    patch_center: np.ndarray,
    patch_reach: float,
    targets: np.ndarray,
    outline: np.ndarray,
    patch_normal: np.ndarray,
    margins: np.ndarray,
) -> np.ndarray:
    """Receivers whose shaft to a patch no facet can block (:mod:`raytrad.core.shafts`).

    A facet can block a ray from a receiver to the patch only if all of these hold:

    * the receiver is not strictly on one side of the facet's plane with every target on
      the patch on or beyond that same side (the packed side bits);
    * its bounding sphere meets the capsule of radius ``patch_reach`` around the segment
      from the receiver to the patch's centre;
    * neither the patch's bounding ball nor every corner of ``targets`` is wholly outside
      one side plane of the pyramid from the receiver through the facet's convex hull (a
      receiver within ``band`` of the facet's plane has no such pyramid);
    * for a planar patch (``outline`` not empty): the facet is not wholly below half a
      ray lift above the patch's lowest point with the receiver above it, nor wholly
      outside one side plane of the shaft from the receiver through the patch's outline
      (by two lifts, the patch's thickness and the margins).

    Parameters
    ----------
    origins : (N, 3) float64
        Ray origins [m].
    sides : (N, 2 W) uint64
        Their packed front and behind bits (:meth:`~raytrad.core.shafts.Facets.sides`).
    patch_sides : (2 W,) uint64
        The patch's packed on-or-in-front and on-or-behind bits
        (:meth:`~raytrad.core.shafts.Facets.patch_sides`).
    normals, offsets : (Q, 3), (Q,) float64
        Facet planes: ``normal . p = offset`` [1], [m].
    centers, radii : (Q, 3), (Q,) float64
        Facet bounding spheres [m].
    hull, hull_ptr : (K, 3) float64, (Q + 1,) int64
        Facet convex hulls, counter-clockwise about their normals (CSR) [m].
    band : float
        Plane band of the pyramid test [m].
    patch_center : (3,) float64
        The patch's bounding-sphere centre [m].
    patch_reach : float
        Its radius, ray targets' lift included [m].
    targets : (V, 3) float64
        Corners of a convex set that holds every ray target on the patch [m]
        (:func:`~raytrad.core.blockers.target_corners`).
    outline : (E, 3) float64
        A planar patch's convex outline (E >= 3), in order; (0, 3) for a folded patch [m].
    patch_normal : (3,) float64
        A planar patch's unit normal, on the side its ray targets are lifted to.
    margins : (4,) float64
        The facets' flatness, the ray targets' lift along the normal, the patch's lowest
        height along it (``patch_normal . p``) and its height range [m].

    Returns
    -------
    (N,) bool, True where no ray is needed: the visible fraction is 1.

    References
    ----------
    Haines and Wallace (1994), see :mod:`raytrad.core.shafts`.
    """
    count = len(radii)
    words = sides.shape[1] // 2
    flat, _lift, _level, _thick = (float(v) for v in margins)

    def unpack(packed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        bits = np.unpackbits(
            np.ascontiguousarray(packed, dtype="<u8").view(np.uint8), axis=-1, bitorder="little"
        ).astype(bool)
        return bits[..., :count], bits[..., 64 * words : 64 * words + count]

    front, back = unpack(sides)
    patch_front, patch_back = unpack(patch_sides[None, :])
    blocks = ~((front & patch_front) | (back & patch_back))  # (N, Q)
    delta = np.asarray(patch_center)[None, :] - origins  # (N, 3)
    length2 = np.einsum("nj,nj->n", delta, delta)
    safe = np.where(length2 > 0, length2, 1.0)
    for q in range(count):
        rel = centers[q][None, :] - origins
        t = np.where(length2 > 0, np.clip(np.einsum("nj,nj->n", rel, delta) / safe, 0, 1), 0.0)
        gap = rel - t[:, None] * delta
        blocks[:, q] &= np.einsum("nj,nj->n", gap, gap) <= (radii[q] + patch_reach) ** 2
        height = origins @ normals[q] - offsets[q]
        ring = hull[hull_ptr[q] : hull_ptr[q + 1]]
        if len(ring) < 3:
            continue
        sign = np.where(height > 0, -1.0, 1.0)
        outside = np.zeros(len(origins), dtype=bool)
        for k in range(len(ring)):
            a = ring[k][None, :] - origins
            b = ring[(k + 1) % len(ring)][None, :] - origins
            n = sign[:, None] * np.cross(a, b)
            norm = np.sqrt(np.einsum("nj,nj->n", n, n))
            outside |= np.einsum("nj,nj->n", n, delta) < -patch_reach * norm
            if len(targets):
                far = _dots(n, targets, origins) < -(flat + band) * norm[:, None]
                outside |= far.all(axis=1)
        blocks[:, q] &= ~(outside & (np.abs(height) > band))
        if len(outline) >= 3:
            blocks[:, q] &= ~_beyond_patch(origins, ring, outline, patch_normal, margins, band)
    return ~blocks.any(axis=1)


def _dots(n: np.ndarray, points: np.ndarray, origins: np.ndarray) -> np.ndarray:
    """(N, V) ``n[i] . (points[v] - origins[i])``, summed x, y, z in order."""
    d = points[None, :, :] - origins[:, None, :]
    return n[:, None, 0] * d[..., 0] + n[:, None, 1] * d[..., 1] + n[:, None, 2] * d[..., 2]


def _beyond_patch(
    origins: np.ndarray,
    ring: np.ndarray,
    outline: np.ndarray,
    normal: np.ndarray,
    margins: np.ndarray,
    band: float,
) -> np.ndarray:
    """(N,) bool: a facet (convex ``ring``) below the patch's plane with the origin above
    it, or outside a side plane of the shaft from the origin through the patch's convex
    ``outline`` (see :func:`numpy_shaft_clear`)."""
    flat, lift, level, thick = (float(v) for v in margins)
    cut = level + 0.5 * lift
    above = (
        normal[0] * origins[:, 0] + normal[1] * origins[:, 1] + normal[2] * origins[:, 2]
        > cut + flat + band
    )
    heights = normal[0] * ring[:, 0] + normal[1] * ring[:, 1] + normal[2] * ring[:, 2]
    out = above & bool((heights < cut - flat - band).all())
    middle = np.zeros(3)
    for v in range(len(outline)):  # summed as the compiled loop sums
        middle = middle + outline[v] / len(outline)
    margin = 2.0 * lift + flat + band + thick
    for k in range(len(outline)):
        a = outline[k][None, :] - origins
        b = outline[(k + 1) % len(outline)][None, :] - origins
        n = np.cross(a, b)
        norm = np.sqrt(n[:, 0] * n[:, 0] + n[:, 1] * n[:, 1] + n[:, 2] * n[:, 2])
        inner = _dots(n, middle[None, :], origins)[:, 0]
        scale = np.abs(middle - origins).sum(axis=1)
        usable = (norm > 0) & (np.abs(inner) > 1e-9 * norm * scale)
        n = np.where(inner[:, None] < 0, -n, n)
        outside = (_dots(n, ring, origins) < -margin * norm[:, None]).all(axis=1)
        out |= usable & outside
    return out


def plane_hull(points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(K, 3) the convex hull of coplanar points, counter-clockwise about ``normal``
    (Andrew's monotone chain on the plane's coordinates)."""
    u = np.cross(normal, np.eye(3)[np.abs(normal).argmin()])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    uv = np.stack([points @ u, points @ v], axis=1)
    uv = uv[np.lexsort((uv[:, 1], uv[:, 0]))]  # sorted by u, v, each point once
    first = np.ones(len(uv), dtype=bool)
    first[1:] = (uv[1:] != uv[:-1]).any(axis=1)
    uv = uv[first]
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


__all__ = [
    "Facets",
    "ShaftEnd",
    "numpy_shaft_clear",
    "plane_hull",
    "prism",
    "shaft_clear",
    "shaft_end",
]
