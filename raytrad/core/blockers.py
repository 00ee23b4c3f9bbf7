"""Convex blockers: the (receiver, patch) pairs that one occluder hides wholly, found
before tracing.

Shaft culling (:mod:`raytrad.core.shafts`) finds the pairs nothing can block; this finds
the opposite kind. A pair is *blocked* when every segment from the receiver's ray origin
to any ray target on the patch passes through one convex occluder. Such a pair's traced
samples would all be blocked, so its factor is 0 and it needs no ray and no sample.

The occluders are the blocking triangles' connected components that are convex:

* a *solid*: a convex closed surface (a box), or a convex surface open along one planar
  loop (a box standing on the floor without its bottom face). The open face counts as a
  *hole*: a segment that enters the solid through a face (never through the hole, as
  the origin is on the inner side of the hole's plane) hits that face;
* a *sheet*: a planar component whose triangles cover their convex hull (a one-sided
  quad).

The test rests on convexity twice. If the segments from a point ``o`` to each corner
``v_i`` of a point set meet a convex set ``C``, at ``q_i``, then the segment from ``o``
to any ``p`` in the set's convex hull meets it too: with ``p = sum l_i v_i`` and
``q_i = o + t_i (v_i - o)``, the point ``o + (p - o) / S``, ``S = sum l_i / t_i >= 1``,
is the convex combination of the ``q_i`` with weights ``l_i / (t_i S)``, so it lies in
``C`` and on the segment. The corners are those of a hull of the patch's ray targets (its
vertices' convex hull, lifted both ways off its plane by twice the targets' own lift), so
every target is covered; and ``C`` is the occluder shrunk by a margin (a few ray offsets),
so the float32 rays Embree traces cross it with room to spare. A pair is called blocked
only when also

* the origin is outside the solid by twice the margin (through a face, not the hole),
  and on the inner side of the hole's plane by half a ray offset, or on one side of a
  sheet's plane by the margin with every corner on the other side by the margin; and
* for a solid, the blocking point is further than twice the ray offset from the ray's
  end (rays stop half an offset short of their target), bounded below from the corners'
  parameters and the patch's distance.

Half a ray offset on the hole's side is enough: along a segment from such an origin to
a point of the shrunk solid, the depth below the hole's plane never falls under the
origin's, so the segment enters the solid through a face at least that far from the
hole's rim (a ray offset is 1e-5 of the scene's diagonal, float32 rounding 6e-8 of it).
That admits the receivers on the surface a box stands on (a ray offset above the hole's
plane), the ones a box hides most (2026-12-02, Cornell box: 46 % fewer rays in
refinement, 19 % fewer in the pass, the same factors to the bit).

The test is conservative: a blocked pair is one whose samples the unculled pass traces
as all blocked, so its factors and gather weights are the unculled pass's exactly (zero);
``tests/core/test_blockers.py`` checks both, and that partly visible pairs never count.
Convex components are common in modelled scenes (boxes, slabs, table tops, partitions);
a non-convex component (an L-shaped wall, a chair modelled as one mesh) blocks nothing
here, and its pairs are traced as before.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import tol
from raytrad.core import compiled
from raytrad.core.refine import connected_labels
from raytrad.core.shafts import plane_hull, prism
from raytrad.scene.model import triangle_areas_normals

log = logging.getLogger(__name__)

#: Plane kinds: a solid's face, a solid's hole (its open planar loop), a sheet's plane,
#: and a sheet's edge (perpendicular to its plane, outward).
FACE, HOLE, SHEET, EDGE = 0, 1, 2, 3
#: Scenes of more blocking triangles than this are not searched for blockers (welding
#: their corners and labelling their components costs about a second per million).
MAX_TRIANGLES = 200_000
#: Convex components of more planes than this are not considered: every pair in doubt
#: tests each plane, and a tessellated ball (1 280 planes) cost more than its rays
#: (2026-12-03: a box with such a ball took 1.92 times the pass without blockers).
MAX_PLANES = 64
#: Origins per group of the blocker test (:meth:`Blockers.blocked`): a group shares one
#: list of candidate blockers and, probed, is tested whole only when an end is hidden.
#: Probing in the pass (2026-12-05): in a cluttered room 14 % of the origins tested are
#: hidden, two thirds of the groups have none, and probing leaves 0.30 of the tests for
#: 0.82 of the hidden pairs; in the Cornell box (49 % hidden) 0.65 of the tests for 0.98.
PROBE_GROUP = 16


@dataclass(frozen=True)
class Blockers:
    """Convex occluders, each a list of planes (CSR).

    Attributes
    ----------
    normal : (K, 3) float64
        Unit plane normals, outward (for a sheet's plane: either side) [1].
    offset : (K,) float64
        ``normal . p = offset`` on the plane [m].
    kind : (K,) int64
        :data:`FACE`, :data:`HOLE`, :data:`SHEET` or :data:`EDGE`.
    plane_ptr : (B + 1,) int64
        Each blocker's planes.
    center : (B, 3) float64, radius : (B,) float64
        Bounding spheres [m].
    margin : float
        The shrink margin [m]: the test's occluder lies this far inside the real one.
    lift : float
        The ray offset [m]: targets lie within it of their patch; rays stop half of it
        short of their target.
    """

    normal: np.ndarray
    offset: np.ndarray
    kind: np.ndarray
    plane_ptr: np.ndarray
    center: np.ndarray
    radius: np.ndarray
    margin: float
    lift: float

    @property
    def count(self) -> int:
        return len(self.radius)

    def blocked(
        self,
        origins: np.ndarray,
        corners: np.ndarray,
        patch_center: np.ndarray,
        reach: float,
        probe: bool = False,
    ) -> np.ndarray:
        """(N,) bool: the ray origins from which one blocker hides every ray target of a
        patch.

        Parameters
        ----------
        origins : (N, 3) float64
            Ray origins [m].
        corners : (V, 3) float64
            Corners of a convex set holding every ray target of the patch
            (:func:`target_corners`) [m].
        patch_center : (3,) float64, reach : float
            A ball holding those corners [m].
        probe : bool
            Test each group of :data:`PROBE_GROUP` consecutive origins (nearby ones, in
            Morton order) only when its first or last origin is hidden: the others of a
            group whose two ends are seen are called not hidden untested (False where the
            full test may say True; a pair called so is traced, to the same factor).
        """
        args = (origins, corners, patch_center, reach, self, probe)
        fast = compiled.get()
        if fast is None or len(origins) == 0:
            return numpy_blocked(*args)
        return np.asarray(
            fast.blocked_pairs(
                np.ascontiguousarray(origins, dtype=np.float64),
                np.ascontiguousarray(corners, dtype=np.float64),
                np.ascontiguousarray(patch_center, dtype=np.float64),
                float(reach),
                self.normal,
                self.offset,
                self.kind,
                self.plane_ptr,
                self.center,
                self.radius,
                self.margin,
                self.lift,
                bool(probe),
            ),
            dtype=bool,
        )


def numpy_blocked(
    origins: np.ndarray,
    corners: np.ndarray,
    patch_center: np.ndarray,
    reach: float,
    blockers: Blockers,
    probe: bool = False,
) -> np.ndarray:
    """The numpy reference of :meth:`Blockers.blocked` (same arguments, same result)."""
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(corners, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(o), dtype=bool)
    gap = np.linalg.norm(o - patch_center, axis=1) - reach  # nearest target, at least
    m, lift = blockers.margin, blockers.lift
    for b in range(blockers.count):
        todo = ~out & _segment_meets_ball(
            o, patch_center, blockers.center[b], blockers.radius[b] + reach
        )
        if not todo.any():
            continue
        planes = slice(blockers.plane_ptr[b], blockers.plane_ptr[b + 1])
        n, d, kind = blockers.normal[planes], blockers.offset[planes], blockers.kind[planes]
        h_o = o[todo] @ n.T - d  # (C, K)
        h_v = v @ n.T - d  # (V, K)
        if (kind == SHEET).any():
            s = int(np.flatnonzero(kind == SHEET)[0])
            above = (h_o[:, s] >= m) & (h_v[:, s] <= -m).all()
            below = (h_o[:, s] <= -m) & (h_v[:, s] >= m).all()
            ok = above | below
            edges = kind == EDGE
            # where each segment crosses the sheet's plane: o + t (v - o), t = h_o / (h_o - h_v)
            t = h_o[:, s][:, None] / np.where(
                ok[:, None], h_o[:, s][:, None] - h_v[None, :, s], 1.0
            )
            crossing = h_o[:, None, edges] + t[:, :, None] * (
                h_v[None, :, edges] - h_o[:, None, edges]
            )
            ok &= (crossing <= -m).all(axis=(1, 2))
        else:
            faces, holes = kind == FACE, kind == HOLE
            ok = (h_o[:, faces] >= 2.0 * m).any(axis=1) & (h_o[:, holes] <= -0.5 * lift).all(axis=1)
            # Cyrus-Beck: each segment's parameters inside the shrunk planes
            start = h_o + m  # (C, K): o against the shrunk planes
            slope = (h_v + m)[None, :, :] - start[:, None, :]  # (C, V, K)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = -start[:, None, :] / slope
            enter = np.where(slope < 0, t, 0.0).max(axis=2).clip(0.0, None)
            leave = np.where(slope > 0, t, 1.0).min(axis=2).clip(None, 1.0)
            parallel_out = ((slope == 0) & (start[:, None, :] > 0)).any(axis=2)
            ok &= ((enter <= leave) & ~parallel_out).all(axis=1)
            ok &= (1.0 - enter.max(axis=1, initial=0.0)) * gap[todo] >= 2.0 * lift
        out[np.flatnonzero(todo)[ok]] = True
    return probed(out) if probe else out


def probed(hidden: np.ndarray) -> np.ndarray:
    """(N,) bool: ``hidden`` with every group of :data:`PROBE_GROUP` consecutive origins
    (more than two) whose first and last are not hidden cleared: what
    :meth:`Blockers.blocked` finds with ``probe``."""
    out = np.array(hidden, dtype=bool)
    first = np.arange(0, len(out), PROBE_GROUP)
    last = np.minimum(first + PROBE_GROUP, len(out)) - 1
    skipped = ~(out[first] | out[last]) & (last - first > 1)
    for a, b in zip(first[skipped], last[skipped], strict=True):
        out[a : b + 1] = False
    return out


def _segment_meets_ball(
    o: np.ndarray, p: np.ndarray, center: np.ndarray, radius: float
) -> np.ndarray:
    """(N,) bool: the segments from ``o`` (N, 3) to ``p`` (3,) pass within ``radius`` of
    ``center``."""
    d = p - o
    length2 = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", center - o, d) / np.where(length2 > 0, length2, 1.0), 0, 1)
    nearest = o + t[:, None] * d
    return np.linalg.norm(nearest - center, axis=1) <= radius


def blockers(positions: np.ndarray, triangles: np.ndarray, diagonal: float) -> Blockers | None:
    """The convex components of the blocking triangles as :class:`Blockers` (None: none).

    Corners within ``tol.horizon`` x ``diagonal`` of each other are one vertex; a
    component is convex when every vertex is within that of the back of each of its
    triangles' planes (oriented outward), closed or open along one planar loop, and no
    edge joins more than two triangles; a planar component is a sheet when its triangles'
    areas sum to its convex hull's.

    Parameters
    ----------
    positions : (V, 3) float64 [m]
    triangles : (T, 3) int
    diagonal : float
        The scene's diagonal [m].
    """
    corners = np.asarray(positions, dtype=np.float64)[np.asarray(triangles)]
    flat = tol.horizon * diagonal
    corners = corners[triangle_areas_normals(corners)[0] > 0]
    if not 0 < len(corners) <= MAX_TRIANGLES:
        return None
    _, index = np.unique(np.round(corners.reshape(-1, 3) / flat), axis=0, return_inverse=True)
    welded = index.reshape(-1, 3)
    points = np.zeros((int(welded.max()) + 1, 3))
    points[welded.reshape(-1)] = corners.reshape(-1, 3)
    # a sliver whose corners weld together blocks nothing (and has no normal)
    welded = welded[triangle_areas_normals(points[welded])[0] > 0]
    if not len(welded):
        return None
    planes: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    spheres: list[tuple[np.ndarray, float]] = []
    for part in _components(welded, len(points)):
        found = _convex(points, welded[part], flat)
        if found is not None:
            planes.append(found)
            used = points[unique(welded[part])]
            center = 0.5 * (used.min(axis=0) + used.max(axis=0))
            spheres.append((center, float(np.linalg.norm(used - center, axis=1).max()) + flat))
    if not planes:
        return None
    log.debug("%d convex blockers", len(planes))
    return Blockers(
        np.concatenate([p[0] for p in planes]),
        np.concatenate([p[1] for p in planes]),
        np.concatenate([p[2] for p in planes]).astype(np.int64),
        np.concatenate([[0], np.cumsum([len(p[1]) for p in planes])]).astype(np.int64),
        np.array([s[0] for s in spheres]),
        np.array([s[1] for s in spheres]),
        MARGIN * tol.ray_offset * diagonal,
        tol.ray_offset * diagonal,
    )


#: The shrink margin in ray offsets (:attr:`Blockers.margin`).
MARGIN = 2.0


def _distinct_planes(normal: np.ndarray, offset: np.ndarray, flat: float) -> np.ndarray:
    """Indices of one plane of each set equal within 1e-9 in normal and ``flat`` in offset
    [m] (in the order of their keys, as :func:`numpy.unique` gives them)."""
    key = np.round(np.concatenate([normal / 1e-9, (offset / flat)[:, None]], axis=1))
    return np.unique(key, axis=0, return_index=True)[1]


def _components(triangles: np.ndarray, vertex_count: int) -> list[np.ndarray]:
    """Triangle indices of each connected component (sharing a vertex), in order of
    their lowest vertex."""
    joined = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]]])
    vertex_label = connected_labels(vertex_count, joined)
    lowest = np.full(int(vertex_label.max(initial=-1)) + 1, vertex_count)
    np.minimum.at(lowest, vertex_label, np.arange(vertex_count))
    label = lowest[vertex_label[triangles[:, 0]]]
    order = np.argsort(label, kind="stable")
    cuts = np.flatnonzero(np.diff(label[order])) + 1
    return np.split(order, cuts)


def _convex(
    points: np.ndarray, triangles: np.ndarray, flat: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A component's planes (normals, offsets, kinds) if it is a convex blocker."""
    edges = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    distinct, count = np.unique(edges, axis=0, return_counts=True)
    if (count > 2).any():
        return None
    used = unique(triangles)
    corners = points[triangles]
    area, normal = triangle_areas_normals(corners)
    offset = np.einsum("tj,tj->t", normal, corners[:, 0])
    first = _distinct_planes(normal, offset, flat)  # a face's coplanar triangles: once
    if len(first) > MAX_PLANES:
        return None
    normal, offset = normal[first], offset[first]
    height = points[used] @ normal.T - offset  # (U, planes)
    if (np.abs(height) <= flat).all():
        return _sheet(points[used], normal[0], float(offset[0]), float(area.sum()), flat)
    sign = np.where(
        height.max(axis=0) <= flat, 1.0, np.where(height.min(axis=0) >= -flat, -1.0, 0.0)
    )
    if (sign == 0).any():
        return None
    normal, offset = normal * sign[:, None], offset * sign
    first = _distinct_planes(normal, offset, flat)  # a face wound both ways: once
    normal, offset = normal[first], offset[first]
    kind = np.full(len(offset), FACE)
    rim = distinct[count == 1]
    if len(rim):
        hole = _hole(points[unique(rim)], points[used], flat)
        if hole is None:
            return None
        normal = np.vstack([normal, hole[0]])
        offset = np.append(offset, hole[1])
        kind = np.append(kind, HOLE)
    return normal, offset, kind


def _hole(rim: np.ndarray, points: np.ndarray, flat: float) -> tuple[np.ndarray, float] | None:
    """The outward plane of a convex surface's open loop, if the loop is planar and the
    surface lies on one side of it."""
    mean = rim.mean(axis=0)
    normal = np.linalg.svd(rim - mean)[2][-1]
    offset = float(normal @ mean)
    if np.abs(rim @ normal - offset).max() > flat:
        return None
    height = points @ normal - offset
    if height.max() <= flat and height.min() < -flat:
        return normal, offset
    if height.min() >= -flat and height.max() > flat:
        return -normal, -offset
    return None


def _sheet(
    points: np.ndarray, normal: np.ndarray, offset: float, area: float, flat: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A planar component's sheet plane and outward edge planes, if its triangles cover
    their convex hull."""
    hull = plane_hull(points, normal)
    following = np.roll(hull, -1, axis=0)
    hull_area = 0.5 * float(
        np.linalg.norm(np.cross(hull - hull[0], following - hull[0]).sum(axis=0))
    )
    if abs(hull_area - area) > 1e-9 * max(area, 1e-300) + flat * np.sqrt(area):
        return None
    # plane_hull winds counter-clockwise about ``normal``: edge x normal points outward
    edge = following - hull
    outward = np.cross(edge, normal)
    outward /= np.linalg.norm(outward, axis=1)[:, None]
    return (
        np.vstack([normal, outward]),
        np.concatenate([[offset], np.einsum("kj,kj->k", outward, hull)]),
        np.concatenate([[SHEET], np.full(len(hull), EDGE)]),
    )


def target_corners(vertices: np.ndarray, normal: np.ndarray | None, lift: float) -> np.ndarray:
    """(V', 3) corners of a convex set that holds every ray target of a patch: the convex
    hull of its vertices moved ``2 lift`` (plus their own height range along the normal: a
    patch counts as planar by its normals alone) both ways along its normal (``normal``
    None, a folded patch: each vertex moved ``2 lift`` along each axis both ways, and of
    those the corners of their hull, :func:`hull_corners`, to a tenth of the lift)."""
    if normal is not None:
        heights = np.asarray(vertices, dtype=np.float64) @ normal
        thick = float(heights.max() - heights.min())
        return prism(plane_hull(vertices, normal), normal, 2.0 * lift + thick)
    cube = 2.0 * lift * np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    points = (np.unique(vertices, axis=0)[:, None, :] + cube[None, :, :]).reshape(-1, 3)
    return hull_corners(points, 0.1 * lift)


def hull_corners(points: np.ndarray, tolerance: float) -> np.ndarray:
    """(V', 3) the corners of the convex hull of ``points`` (V, 3) [m], in their order:
    every point lies in their hull or within ``tolerance`` [m] of it. Every point where
    Qhull cannot build the hull (points in a plane or a line) or leaves one further out
    (it merges nearly coplanar facets, to its own rounding).

    The blocker and shaft tests hold for a convex set when they hold at its corners, so
    the other points are never needed: a folded patch of a ball of 5 120 triangles keeps
    355 of 2 291 points on average, and the blocker test, whose time goes as the
    corners, took 0.32 of its time in such a scene (the same answers)."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) <= 8:
        return points
    from scipy.spatial import ConvexHull, QhullError  # Qhull, only for folded patches

    centred = points - points.mean(axis=0)  # Qhull's rounding goes as the coordinates
    try:
        hull = ConvexHull(centred)
    except (QhullError, ValueError):
        return points
    planes = hull.equations  # (F, 4), unit normals: n . p + d <= 0 inside
    outside = centred @ planes[:, :3].T + planes[:, 3]
    if not outside.max() <= tolerance:
        return points
    return points[np.sort(hull.vertices)]


__all__ = ["Blockers", "blockers", "hull_corners", "numpy_blocked", "target_corners"]
