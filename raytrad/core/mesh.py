"""From a :class:`~raytrad.scene.Scene` to the radiosity mesh: receivers, patches and sub-areas.

* **Receivers** are the vertices of the refined triangle mesh, one per *surface*: a vertex
  where two surfaces meet at a crease, or where materials change, is a separate receiver on
  each side, so light never blurs across a room corner.
* **Patches** shoot. A patch is a group of refined triangles of one surface, no larger than
  ``patch_size`` across.
* **Sub-areas** split each patch into a few groups of triangles; each has one fixed sample
  point, the point the visibility rays aim at (Wallace et al. 1989).

Everything is flat arrays; no Python object per element.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from raytrad.arrays import corner_mean, longest_side, spatially_ordered, unique, unique_inverse
from raytrad.constants import scene_diagonal, scene_extent, tol
from raytrad.core.imprint import Outlines, imprint_outlines, outline_segments
from raytrad.core.intersections import intersection_segments
from raytrad.core.refine import (
    bisect_clusters,
    cluster_bounds,
    group_sorted,
    max_edge_for_receivers,
    merge_vertices,
    refine,
    refined_count_bound,
    surface_labels,
)
from raytrad.core.visibility import COVER_GAP
from raytrad.errors import SceneError, SettingsError
from raytrad.scene import Scene, triangle_areas_normals

log = logging.getLogger(__name__)

#: Surfaces meeting at more than this dihedral angle are separate receivers [degrees].
CREASE_ANGLE = 30.0

MAX_RECEIVERS = 10_000_000
"""The most receivers a mesh may ask for (``--receivers``, ``--max-receivers``)."""

MAX_REFINED_TRIANGLES = 2e8
"""The largest bound (:func:`~raytrad.core.refine.refined_count_bound`) on the triangles
refinement may make; a scene whose extent would need more is refused before refining."""


@dataclass(frozen=True, eq=False)
class RadiosityMesh:
    """The discretisation the solver works on.

    Attributes (R receivers, T refined triangles, P patches, S sub-areas)
    ------------------------------------------------------------------------
    receiver_position : (R, 3) float64 [m]
    receiver_normal : (R, 3) float64, unit
    receiver_area : (R,) float64 [m2], a third of the area of each adjacent triangle
    receiver_inward : (R, 3) float64 [m], the centroid of the receiver's largest own triangle
        (a point strictly inside its surface, used to start rays off adjacent planes)
    receiver_reflectance : (R, 3) float64 [1]
    receiver_emitted_exitance : (R, 3) float64 [W m-2]
    triangle_receivers : (T, 3) int64, receiver index of each refined corner
    triangle_area : (T,) float64 [m2]
    triangle_normal : (T, 3) float64
    triangle_patch : (T,) int64
    triangle_subarea : (T,) int64
    triangle_source : (T,) int64, index of the scene triangle each refined triangle came from
    patch_area : (P,) float64 [m2]
    patch_reflectance : (P, 3) float64 [1]
    patch_center : (P, 3) float64 [m], area-weighted centroid
    patch_radius : (P,) float64 [m], bounding-sphere radius about ``patch_center``
    patch_normal : (P, 3) float64, unit area-weighted normal
    patch_planar : (P,) bool, all triangles share ``patch_normal``
    subarea_patch : (S,) int64, sorted ascending
    subarea_area : (S,) float64 [m2]
    subarea_point : (S, 3) float64 [m], the fixed sample point
    subarea_normal : (S, 3) float64, normal of the triangle holding the sample point
    subarea_size : (S,) float64 [m], bounding-box diagonal of the sub-area
    positions : (V, 3) float64 [m], vertex positions of the refined mesh
    triangles : (T, 3) int64, vertex indices of the refined mesh
    receiver_visible : (R,) bool or None, False for receivers shut in by other surfaces
        (see :func:`raytrad.core.hidden.hide_receivers`); None means all visible
    triangle_surface : (T,) int64 or None, the smooth surface of one material each refined
        triangle belongs to (receivers are split between surfaces); None when unknown
    """

    receiver_position: np.ndarray
    receiver_normal: np.ndarray
    receiver_area: np.ndarray
    receiver_inward: np.ndarray
    receiver_reflectance: np.ndarray
    receiver_emitted_exitance: np.ndarray
    triangle_receivers: np.ndarray
    triangle_area: np.ndarray
    triangle_normal: np.ndarray
    triangle_patch: np.ndarray
    triangle_subarea: np.ndarray
    triangle_source: np.ndarray
    patch_area: np.ndarray
    patch_reflectance: np.ndarray
    patch_center: np.ndarray
    patch_radius: np.ndarray
    patch_normal: np.ndarray
    patch_planar: np.ndarray
    subarea_patch: np.ndarray
    subarea_area: np.ndarray
    subarea_point: np.ndarray
    subarea_normal: np.ndarray
    subarea_size: np.ndarray
    positions: np.ndarray
    triangles: np.ndarray
    receiver_visible: np.ndarray | None = None
    triangle_surface: np.ndarray | None = None

    @property
    def receiver_count(self) -> int:
        return int(self.receiver_position.shape[0])

    @property
    def patch_count(self) -> int:
        return int(self.patch_area.shape[0])

    @property
    def subarea_count(self) -> int:
        return int(self.subarea_area.shape[0])

    def patch_emits(self) -> np.ndarray:
        """(P,) bool: patches with a triangle that has an emitting corner."""
        lit = (self.receiver_emitted_exitance[self.triangle_receivers] > 0).any(axis=(1, 2))
        return np.bincount(self.triangle_patch[lit], minlength=self.patch_count) > 0

    def patch_subareas(self, patch: int) -> slice:
        """The slice of sub-area indices belonging to ``patch``."""
        return slice(self._subarea_ptr[patch], self._subarea_ptr[patch + 1])

    @functools.cached_property
    def _subarea_ptr(self) -> list[int]:
        """Each patch's first sub-area, then their count (found once: pairs ask per chunk)."""
        counts = np.bincount(self.subarea_patch, minlength=self.patch_count)
        return np.concatenate([[0], np.cumsum(counts)]).tolist()


# --------------------------------------------------------------------------------------
# Building the mesh
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MeshSettings:
    """How finely to discretise.

    Attributes
    ----------
    max_edge : float or None
        Longest refined edge [m]; None derives it from ``receivers``.
    receivers : int
        Target receiver count when ``max_edge`` is None.
    patch_size : float or None
        Largest patch extent [m]; None derives it from ``patches``.
    patches : int
        Target patch count when ``patch_size`` is None.
    samples : int
        Sub-areas (sample points) per patch.
    emitter_samples : int
        Sub-areas per emitting patch: direct shadows are the sharpest features.
    seed : int
        Seed of the sample-point placement.
    imprint : bool
        Put contact lines into the refined mesh: vertices moved onto, and edges split at,
        other surfaces' outlines lying on a surface (a block's foot on the floor, a
        shelf's ends on a wall): :func:`~raytrad.core.imprint.imprint_outlines`.
    """

    max_edge: float | None = None
    receivers: int = 20000
    patch_size: float | None = None
    patches: int = 400
    samples: int = 16
    emitter_samples: int = 256
    seed: int = 0
    imprint: bool = True

    def __post_init__(self) -> None:
        if self.max_edge is not None and not self.max_edge > 0:
            raise SettingsError(f"max edge must be positive, got {self.max_edge}")
        if self.receivers < 1 or self.patches < 1 or self.samples < 1 or self.emitter_samples < 1:
            raise SettingsError("receivers, patches and samples must be at least 1")
        if max(self.receivers, self.patches) > MAX_RECEIVERS:
            raise SettingsError(f"receivers and patches must be at most {MAX_RECEIVERS:,}")
        if self.patch_size is not None and not self.patch_size > 0:
            raise SettingsError(f"patch size must be positive, got {self.patch_size}")


def build_mesh(
    scene: Scene,
    settings: MeshSettings | None = None,
    enclosed: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> RadiosityMesh:
    """Refine ``scene`` and build receivers, patches and sub-areas (see module docstring).

    Parameters
    ----------
    scene : Scene
    settings : MeshSettings
    enclosed : callable or None
        ``enclosed(points, normals) -> (N,) bool``: True where a surface point can neither
        see nor be seen (the floor under a block standing on it). Refined triangles whose
        centroid is enclosed are left out: otherwise a patch half under the block would
        average its lit half with the dark half and shoot too little.
    """
    settings = settings or MeshSettings()
    positions, triangles, material = _surface_triangles(scene)
    base_area, _ = triangle_areas_normals(positions[triangles])
    total_area = float(base_area.sum())
    if not (total_area > 0.0 and math.isfinite(total_area)):
        extent = scene_extent(scene.positions[unique(scene.triangles)])
        raise SceneError(
            scene.source,
            f"no surface is left once vertices closer than {extent * tol.merge:.3g} m are "
            f"merged (the scene is {extent:.3g} m across): check the units, or stray "
            "vertices far from the rest",
        )
    max_edge = settings.max_edge or max_edge_for_receivers(total_area, settings.receivers)
    surface = surface_labels(positions, triangles, material, CREASE_ANGLE)
    patch_size = settings.patch_size or math.sqrt(total_area / settings.patches)
    emissive = (scene.material_emitted_exitance[material] > 0).any(axis=1)
    limit = _edge_limits(base_area, surface, emissive, max_edge, patch_size, settings)
    _check_refinement_budget(scene, positions[triangles], limit)
    coarse = positions
    positions, fine, parent = refine(positions, triangles, limit)
    if settings.imprint:
        positions, fine, parent = _imprint(
            scene, coarse, triangles, surface, positions, fine, parent
        )
    fine_surface = surface[parent]
    area, normal = triangle_areas_normals(positions[fine])
    keep = area > 0
    if enclosed is not None:
        keep &= ~_enclosed_triangles(positions[fine], normal, enclosed)
        if not keep.any():
            raise SceneError(scene.source, "no surface can see any other (all enclosed)")
        if (~keep).any():
            log.info(
                "left out %d of %d mesh triangles, shut in where no light reaches (the "
                "floor under a block, the block's base)",
                int((~keep).sum()),
                len(keep),
            )
    fine, parent, fine_surface, area, normal = (
        fine[keep],
        parent[keep],
        fine_surface[keep],
        area[keep],
        normal[keep],
    )
    positions, fine = spatially_ordered(positions, fine)  # receivers coherent in space
    receivers = surface_receivers(positions, fine, fine_surface, area, normal)
    triangle_receivers, r_pos, r_normal, r_area, r_inward = receivers
    tri_material = material[parent]
    r_material = np.empty(len(r_pos), dtype=np.int64)
    r_material[triangle_receivers.reshape(-1)] = np.repeat(tri_material, 3)

    centroids = positions[fine].mean(axis=1)
    patch = bisect_clusters(
        centroids, fine_surface, lambda _l, extent: extent.max(axis=1) > patch_size
    )
    patch = group_sorted(patch)
    emissive = (scene.material_emitted_exitance[tri_material] > 0).any(axis=1)
    subarea = _subareas(centroids, patch, emissive, settings)

    mesh_source = _source_index(scene, parent)
    mesh = _assemble(
        scene,
        positions,
        fine,
        area,
        normal,
        tri_material,
        mesh_source,
        patch,
        subarea,
        triangle_receivers,
        r_pos,
        r_normal,
        r_area,
        r_inward,
        r_material,
        settings.seed,
    )
    return replace(mesh, triangle_surface=fine_surface)


def _imprint(
    scene: Scene,
    coarse: np.ndarray,
    triangles: np.ndarray,
    surface: np.ndarray,
    positions: np.ndarray,
    fine: np.ndarray,
    parent: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The refined mesh with edges put on other surfaces' outlines lying within
    :data:`~raytrad.core.visibility.COVER_GAP` of the diagonal from a surface, and on the
    lines where surfaces pass through each other (a block sunk into the floor)
    (:func:`~raytrad.core.imprint.imprint_outlines`,
    :func:`~raytrad.core.intersections.intersection_segments`)."""
    gap = COVER_GAP * scene_diagonal(coarse[unique(triangles)])
    positions, fine, parent, changed = imprint_outlines(
        positions,
        fine,
        parent,
        _source_index(scene, np.arange(len(triangles))),
        surface,
        coarse[triangles[: scene.triangle_count]],
        _contact_lines(coarse, triangles, surface, gap),
        gap,
    )
    if changed:
        log.info("moved or added %d mesh vertices onto contact lines", changed)
    return positions, fine, parent


def _contact_lines(
    positions: np.ndarray, triangles: np.ndarray, surface: np.ndarray, gap: float
) -> Outlines:
    """Surfaces' outlines and the lines where surfaces pass through each other."""
    outline = outline_segments(positions, triangles, surface)
    crossing = intersection_segments(positions, triangles, surface, gap)
    return Outlines(
        np.concatenate([outline.points, crossing.points]),
        np.concatenate([outline.surface, crossing.surface]),
        np.concatenate([outline.normal, crossing.normal]),
    )


def _check_refinement_budget(scene: Scene, corners: np.ndarray, limit: np.ndarray) -> None:
    """Refuse, before refining, a scene that would need more than
    :data:`MAX_REFINED_TRIANGLES` triangles (a stray vertex far away, wrong units, a
    ``max_edge`` far below the scene's size)."""
    bound = refined_count_bound(corners, limit)
    if bound <= MAX_REFINED_TRIANGLES:
        return
    lengths = longest_side(corners)
    worst = int(np.argmax(lengths / limit))
    raise SceneError(
        scene.source,
        f"refining would make up to {bound:.2g} triangles (more than {MAX_REFINED_TRIANGLES:.0e}): "
        f"a triangle {lengths[worst]:.3g} m long must be cut into edges of {limit[worst]:.3g} m; "
        "check the units, stray vertices far from the rest, or --max-edge",
    )


def _edge_limits(
    area: np.ndarray,
    surface: np.ndarray,
    emissive: np.ndarray,
    max_edge: float,
    patch_size: float,
    settings: MeshSettings,
) -> np.ndarray:
    """(T,) longest refined edge per scene triangle [m].

    Emitting surfaces are refined until each of their patches holds about
    ``emitter_samples`` triangles, since a sub-area is a group of whole triangles: direct
    shadows need more sample points than a small lamp would otherwise get.
    """
    limit = np.full(len(area), max_edge)
    if emissive.any():
        surface_area = np.bincount(surface, weights=area)[surface]
        patch_area = np.minimum(surface_area, patch_size * patch_size)
        # an equilateral triangle of edge h has area sqrt(3)/4 h^2; refinement halves edges
        fine = 1.5 * np.sqrt(patch_area / (settings.emitter_samples * math.sqrt(3.0) / 4.0))
        # ... but emitters never take more than a quarter of the receiver budget (a scene
        # where everything glows, like a furnace, keeps the ordinary resolution)
        receivers = area.sum() / (math.sqrt(3.0) / 2.0 * max_edge**2)
        budget = max_edge_for_receivers(float(area[emissive].sum()), max(1, int(receivers / 4)))
        limit = np.where(emissive, np.minimum(limit, np.maximum(fine, budget)), limit)
    return limit


def _enclosed_triangles(
    corners: np.ndarray,
    normals: np.ndarray,
    enclosed: Callable[[np.ndarray, np.ndarray], np.ndarray],
) -> np.ndarray:
    """(T,) bool: triangles whose centroid and near-corner points are all enclosed."""
    centroid = corners.mean(axis=1)
    shut = enclosed(centroid, normals)
    for k in range(3):
        todo = np.nonzero(shut)[0]
        if len(todo) == 0:
            break
        near_corner = 0.9 * corners[todo, k] + 0.1 * centroid[todo]
        shut[todo] = enclosed(near_corner, normals[todo])
    return shut


def _surface_triangles(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merged vertices and the triangle list, with a reversed copy of each double-sided one."""
    extent = scene_extent(scene.positions[unique(scene.triangles)])
    positions, triangles = merge_vertices(scene.positions, scene.triangles, extent * tol.merge)
    material = scene.material_index
    two = scene.double_sided
    if two.any():
        triangles = np.concatenate([triangles, triangles[two][:, ::-1]])
        material = np.concatenate([material, material[two]])
    return positions, triangles, material


def _source_index(scene: Scene, parent: np.ndarray) -> np.ndarray:
    """Map refined triangles to the scene triangle they came from (copies to originals)."""
    two = np.nonzero(scene.double_sided)[0]
    source = np.concatenate([np.arange(scene.triangle_count), two])
    return source[parent]


def surface_receivers(
    positions: np.ndarray,
    triangles: np.ndarray,
    surface: np.ndarray,
    area: np.ndarray,
    normal: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """One receiver per (vertex, surface) pair, with its normal, area and inward point."""
    corner_vertex = triangles.reshape(-1)
    corner_surface = np.repeat(surface, 3)
    stride = int(corner_surface.max(initial=0)) + 1
    key = corner_vertex.astype(np.int64) * stride + corner_surface  # sorts as (vertex, surface)
    distinct, inverse = unique_inverse(key)  # marked in a table: no sort
    count = len(distinct)
    triangle_third = area / 3.0
    third = np.repeat(triangle_third, 3)
    r_area = np.bincount(inverse, weights=third, minlength=count)
    r_normal = np.zeros((count, 3))
    for k in range(3):  # each corner's normal times its third: the triangle's, repeated
        weights = np.repeat(normal[:, k] * triangle_third, 3)
        r_normal[:, k] = np.bincount(inverse, weights=weights, minlength=count)
    # The inward point is the centroid of the receiver's largest own triangle, not a mean:
    # where a fin meets a wall, the mean of the triangles on both sides of the fin lies in
    # the fin's plane, and a receiver evaluated there would see half a hemisphere.
    largest = np.zeros(count)
    np.maximum.at(largest, inverse, third)
    # ties (triangles equal up to the rounding of their coordinates, which grows with
    # the distance from the origin) go to the first triangle; rounding the ratio instead
    # would flip at half-steps
    edge = np.sqrt(6.0 * np.maximum(largest[inverse], 1e-300))  # ~ the triangle's size [m]
    far = float(np.abs(positions).max(initial=0.0))
    slack = tol.tie + 16.0 * np.finfo(np.float64).eps * far / edge
    near_largest = third >= largest[inverse] * (1.0 - slack)
    # each receiver's first corner among its near-largest ones (its largest corner is
    # one), as a stable sort by (receiver, not near-largest) would put first
    big = np.flatnonzero(near_largest)
    first = np.full(count, len(inverse), dtype=np.int64)
    np.minimum.at(first, inverse[big], big)
    r_inward = corner_mean(positions[triangles[first // 3]])  # the corner's triangle's
    r_normal /= np.linalg.norm(r_normal, axis=1)[:, None]
    return inverse.reshape(-1, 3), positions[distinct // stride], r_normal, r_area, r_inward


def _subareas(
    centroids: np.ndarray, patch: np.ndarray, emissive: np.ndarray, settings: MeshSettings
) -> np.ndarray:
    """Split each patch into about ``samples`` (emitters: ``emitter_samples``) sub-areas."""
    count = int(patch.max()) + 1
    patch_emissive = np.zeros(count, dtype=bool)
    patch_emissive[patch[emissive]] = True
    target = np.where(patch_emissive, settings.emitter_samples, settings.samples)

    def split(labels: np.ndarray, extent: np.ndarray) -> np.ndarray:
        cluster_patch = np.zeros(int(labels.max()) + 1, dtype=np.int64)
        cluster_patch[labels] = patch
        have = np.bincount(cluster_patch, minlength=count)
        return np.asarray(have[cluster_patch] < target[cluster_patch])

    labels = bisect_clusters(centroids, patch, split)
    # order sub-areas by patch so each patch owns a contiguous range
    sub_patch = np.zeros(int(labels.max()) + 1, dtype=np.int64)
    sub_patch[labels] = patch
    order = np.lexsort((np.arange(len(sub_patch)), sub_patch))
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[labels]


def _assemble(
    scene: Scene,
    positions: np.ndarray,
    triangles: np.ndarray,
    area: np.ndarray,
    normal: np.ndarray,
    tri_material: np.ndarray,
    source: np.ndarray,
    patch: np.ndarray,
    subarea: np.ndarray,
    triangle_receivers: np.ndarray,
    r_pos: np.ndarray,
    r_normal: np.ndarray,
    r_area: np.ndarray,
    r_inward: np.ndarray,
    r_material: np.ndarray,
    seed: int,
) -> RadiosityMesh:
    p_count = int(patch.max()) + 1
    s_count = int(subarea.max()) + 1
    corners = positions[triangles]
    centroid = corners.mean(axis=1)
    p_area = np.bincount(patch, weights=area, minlength=p_count)
    p_center = (
        np.stack(
            [
                np.bincount(patch, weights=centroid[:, k] * area, minlength=p_count)
                for k in range(3)
            ],
            axis=1,
        )
        / p_area[:, None]
    )
    p_normal_sum = np.stack(
        [np.bincount(patch, weights=normal[:, k] * area, minlength=p_count) for k in range(3)],
        axis=1,
    )
    p_normal = p_normal_sum / np.maximum(np.linalg.norm(p_normal_sum, axis=1), 1e-300)[:, None]
    planar = np.ones(p_count, dtype=bool)
    np.logical_and.at(
        planar, patch, np.einsum("ij,ij->i", normal, p_normal[patch]) > 1.0 - tol.parallel
    )
    corner_dist = np.linalg.norm(corners - p_center[patch][:, None, :], axis=2).max(axis=1)
    p_radius = np.zeros(p_count)
    np.maximum.at(p_radius, patch, corner_dist)
    p_reflectance = scene.material_reflectance[tri_material[np.unique(patch, return_index=True)[1]]]

    s_patch = np.zeros(s_count, dtype=np.int64)
    s_patch[subarea] = patch
    s_area = np.bincount(subarea, weights=area, minlength=s_count)
    lo, hi = cluster_bounds(corners.reshape(-1, 3), np.repeat(subarea, 3), s_count)
    s_size = np.linalg.norm(hi - lo, axis=1)
    # Sample points hang on the geometry, not on the order of the file's triangles: each
    # triangle gets a canonical key from its quantised centroid, and each sub-area its
    # random numbers from a hash of its smallest key and the seed.
    key = _position_keys(centroid, positions)
    sub_key = np.full(s_count, np.iinfo(np.int64).max)
    np.minimum.at(sub_key, subarea, key)
    random = _hash_uniform(sub_key, seed, 3)
    chosen = _pick_triangles(subarea, area, s_count, random[:, 0], key)
    u, v = random[:, 1], random[:, 2]
    flip = u + v > 1.0
    u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
    c = corners[chosen]
    s_point = c[:, 0] + u[:, None] * (c[:, 1] - c[:, 0]) + v[:, None] * (c[:, 2] - c[:, 0])

    return RadiosityMesh(
        receiver_position=r_pos,
        receiver_normal=r_normal,
        receiver_area=r_area,
        receiver_inward=r_inward,
        receiver_reflectance=scene.material_reflectance[r_material],
        receiver_emitted_exitance=scene.material_emitted_exitance[r_material],
        triangle_receivers=triangle_receivers,
        triangle_area=area,
        triangle_normal=normal,
        triangle_patch=patch,
        triangle_subarea=subarea,
        triangle_source=source,
        patch_area=p_area,
        patch_reflectance=p_reflectance,
        patch_center=p_center,
        patch_radius=p_radius,
        patch_normal=p_normal,
        patch_planar=planar,
        subarea_patch=s_patch,
        subarea_area=s_area,
        subarea_point=s_point,
        subarea_normal=normal[chosen],
        subarea_size=s_size,
        positions=positions,
        triangles=triangles,
    )


def _pick_triangles(
    subarea: np.ndarray, area: np.ndarray, count: int, uniform: np.ndarray, key: np.ndarray
) -> np.ndarray:
    """One triangle per sub-area, chosen with probability proportional to its area.

    ``uniform`` (count,) in [0, 1) picks along the sub-area's triangles in ``key`` order.
    """
    order = np.lexsort((key, subarea))
    cum = np.cumsum(area[order])
    start = np.searchsorted(subarea[order], np.arange(count))
    end = np.append(start[1:], len(order))
    before = np.where(start > 0, cum[np.maximum(start - 1, 0)], 0.0)
    target = before + uniform * (cum[end - 1] - before)
    pick = np.searchsorted(cum, target, side="right")
    pick = np.clip(pick, start, end - 1)
    return order[pick]


def _position_keys(points: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(N,) int64 key of each point, quantised to 2^-20 of the scene's extent (so the
    same in any units and at any placement)."""
    lo = positions.min(axis=0)
    extent = max(float(np.ptp(positions, axis=0).max()), 1e-300)
    q = np.round((points - lo) / extent * (1 << 20)).astype(np.int64)
    return (q[:, 0] << 42) ^ (q[:, 1] << 21) ^ q[:, 2]


def _hash_uniform(keys: np.ndarray, seed: int, count: int) -> np.ndarray:
    """(N, count) uniform numbers in [0, 1) from integer keys (splitmix64 mixing)."""
    out = np.empty((len(keys), count))
    state = keys.astype(np.uint64) ^ np.uint64((seed * 0x9E3779B97F4A7C15) & (2**64 - 1))
    with np.errstate(over="ignore"):
        for k in range(count):
            state = state + np.uint64(0x9E3779B97F4A7C15)
            z = state
            z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
            z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
            z = z ^ (z >> np.uint64(31))
            out[:, k] = (z >> np.uint64(11)).astype(np.float64) / float(1 << 53)
    return out
