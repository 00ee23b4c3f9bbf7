"""Contact lines put into the refined mesh: refined vertices moved onto, and edges split
at, other surfaces' outlines lying on a surface.

Where another surface's outline lies on a surface (a block's bottom edges on the floor, a
shelf's ends on a wall), radiosity on the surface changes abruptly along that line: the
floor is hidden under the block and dark at its foot. A refined triangle straddling the
line interpolates across it, so the hidden side bleeds into the lit one (the floor at a
block's foot too bright), and a receiver at the foot of the block gathers that wrong floor.

Discontinuity meshing puts mesh edges on such lines (Heckbert 1992; Lischinski, Tampieri
and Greenberg 1992). Here the refined mesh is adjusted rather than rebuilt: for every
refined edge that crosses an outline segment, the end nearer the segment moves onto it,
staying in every scene triangle it lies in (inside one triangle it moves freely, on a
shared edge or a crease it slides along it, a scene corner stays put), and no move may fold
a triangle or leave it a sliver. An edge no move can mend (the line through a triangle's
corner and across the opposite edge) is split where it crosses, and an outline's corner
inside a triangle splits it. So the scene's triangles, its surfaces and the lightmap UVs
(interpolated over scene triangles) keep their shape, and the mesh stays conforming.

Everything is flat arrays; the broad phase (:mod:`raytrad.core.segment_search`) is a grid of
cells about an item's reach wide.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import sign_with_band
from raytrad.core.refine import edge_keys, unique_edges
from raytrad.core.segment_search import items_near_segments, nearest_on_segment
from raytrad.scene import barycentric_coordinates, triangle_areas_normals

#: Outlines of surfaces meeting a surface at more than this angle are imprinted on it
#: [degrees]: a block's sides on the floor, a shelf's ends on a wall. A parallel surface
#: (a lamp just below the ceiling) covers what lies behind it instead: its outline
#: receivers would be half covered, darker than anything a millimetre away.
CONTACT_ANGLE = 30.0

#: Relative band within which a point counts as on a line (a fraction of the product of
#: the two segments' lengths, the scale of the cross products compared).
SIDE_BAND = 1e-6

#: A triangle's points lie within this fraction of its longest edge of its centroid (2/3,
#: and a margin for the points :data:`SIDE_BAND` outside it).
CORNER_REACH = 0.7

#: How far from a scene triangle's plane a target may lie, as a fraction of its longest
#: edge (a vertex on a crease moves along both planes).
PLANE_BAND = 1e-9

#: Rounds of snapping and splitting: a round re-tests the edges a neighbour's move blocked.
IMPRINT_ROUNDS = 4

#: An edge is not split nearer its end than this fraction of its length (a sliver).
MIN_SPLIT = 0.02

#: A snap is refused when it leaves an adjacent triangle with less than this fraction of
#: its area (or turns it over): a sliver is worse than an edge across the line.
MIN_AREA_KEPT = 0.1


@dataclass(frozen=True)
class Outlines:
    """Surface outlines as segments (M of them).

    Attributes
    ----------
    points : (M, 2, 3) float64 [m], end points
    surface : (M,) int64, the surface each bounds
    normal : (M, 3) float64, unit normal of the triangle each bounds
    """

    points: np.ndarray
    surface: np.ndarray
    normal: np.ndarray


def outline_segments(positions: np.ndarray, triangles: np.ndarray, surface: np.ndarray) -> Outlines:
    """The outline of each surface: edges used by exactly one triangle of that surface.

    Parameters
    ----------
    positions : (V, 3) float64 [m]
    triangles : (T, 3) int64
    surface : (T,) int64, surface label per triangle
    """
    edges, tri_edges = unique_edges(triangles)
    # (edge, surface) pairs used once: one key each, edge-major
    surfaces = int(surface.max()) + 1 if len(surface) else 1
    keyed = tri_edges.reshape(-1) * surfaces + np.repeat(surface, 3)
    _, first, count = np.unique(keyed, return_index=True, return_counts=True)
    once = first[count == 1]  # rows of tri_edges: triangle once // 3
    _, normal = triangle_areas_normals(positions[triangles])
    points = positions[edges[tri_edges.reshape(-1)[once]]]
    kept = np.linalg.norm(points[:, 1] - points[:, 0], axis=1) > 0
    kept &= np.linalg.norm(normal[once // 3], axis=1) > 0  # a degenerate triangle's edges
    return Outlines(points[kept], np.repeat(surface, 3)[once][kept], normal[once // 3][kept])


def imprint_outlines(
    positions: np.ndarray,
    triangles: np.ndarray,
    parent: np.ndarray,
    parent_source: np.ndarray,
    parent_surface: np.ndarray,
    source_corners: np.ndarray,
    outlines: Outlines,
    gap: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Put refined edges on the outline segments of other surfaces lying on a surface.

    A segment lies on a refined edge's surface when both its end points are within ``gap``
    of the plane of a triangle holding the edge; the edge crosses it when, seen along that
    plane's normal, each strictly separates the other's end points. Each round first snaps
    an end of every crossing edge onto the segment (the least move that keeps the end in
    its scene triangles and no triangle folded or flattened), then splits the edges still
    crossing at the crossing (a line through a triangle's corner and across the opposite
    edge, which no move can mend), at most one edge per triangle, and puts an outline's
    corner lying inside a triangle into it; up to :data:`IMPRINT_ROUNDS` rounds, on the
    triangles near an outline only.

    Parameters
    ----------
    positions : (V, 3) float64 [m], vertices of the refined mesh
    triangles : (T, 3) int64, refined triangles
    parent : (T,) int64, the input triangle of refinement each lies in
    parent_source : (P,) int64, per input triangle, the scene triangle (double-sided
        copies mapped to their original)
    parent_surface : (P,) int64, per input triangle, its surface label
    source_corners : (N, 3, 3) float64 [m], corners of the scene triangles
    outlines : Outlines
        From :func:`outline_segments`. Only outlines of surfaces meeting the refined one
        at more than :data:`CONTACT_ANGLE` are imprinted (a block's sides on the floor); a
        parallel one (a lamp's rim under the ceiling) covers it instead
        (:data:`~raytrad.core.visibility.COVER_GAP`).
    gap : float [m], how far from a surface an outline may lie and still be imprinted

    Returns
    -------
    positions : (V', 3) float64, a copy with snapped vertices moved and split points added
    triangles : (T', 3) int64, with split triangles replaced by their halves
    parent : (T',) int64
    changed : int, vertices moved plus vertices added
    """
    positions = np.array(positions, dtype=np.float64)
    if len(outlines.surface) == 0 or len(triangles) == 0:
        return positions, triangles, parent, 0
    # only triangles near an outline can change: the rounds work on those alone (a vertex
    # a move or a split touches, and every triangle around it, lie within two of the
    # longest refined edges of the outline), the rest keep their rows
    corners = positions[triangles]
    longest = float(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max())
    near, _ = items_near_segments(corners.mean(axis=1), outlines.points, 2.0 * longest)
    near = unique(near)
    if len(near) == 0:
        return positions, triangles, parent, 0
    positions, part, part_parent, changed = _imprint_rounds(
        positions,
        triangles[near],
        parent[near],
        parent_source,
        parent_surface,
        source_corners,
        outlines,
        gap,
    )
    triangles, parent = triangles.copy(), parent.copy()
    triangles[near], parent[near] = part[: len(near)], part_parent[: len(near)]
    triangles = np.concatenate([triangles, part[len(near) :]])
    parent = np.concatenate([parent, part_parent[len(near) :]])
    return positions, triangles, parent, changed


def _imprint_rounds(
    positions: np.ndarray,
    triangles: np.ndarray,
    parent: np.ndarray,
    parent_source: np.ndarray,
    parent_surface: np.ndarray,
    source_corners: np.ndarray,
    outlines: Outlines,
    gap: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The rounds of :func:`imprint_outlines` on ``triangles`` (those near an outline);
    ``positions`` are changed in place and extended. Splits keep each split triangle's row
    (one half) and append the rest."""
    changed = 0
    for _ in range(IMPRINT_ROUNDS):
        surface = parent_surface[parent]
        args = (outlines, gap)
        vertex, target = _crossing_snaps(positions, triangles, surface, *args)
        tri, point, _ = _outline_corners(positions, triangles, surface, *args)
        if len(vertex) == 0 and len(tri) == 0:
            break
        corner_vertex, corner_target = _corner_snaps(triangles, tri, point)
        vertex = np.concatenate([corner_vertex, vertex])
        target = np.concatenate([corner_target, target])
        source = parent_source[parent]
        sources = _vertex_sources(len(positions), triangles, source)
        valid = _inside_sources(target, vertex, sources, source_corners)
        vertex, target = _nearest_target(positions, vertex, target, valid)
        _, normal = triangle_areas_normals(positions[triangles])  # a reversed copy's own
        changed += len(_accept_moves(positions, triangles, normal, vertex, target))
        before = len(positions)
        vertex, target = _crossing_snaps(positions, triangles, surface, *args)
        positions, triangles, parent = _split_edges(
            positions, triangles, parent, vertex[:, :2], target[:, 2]
        )
        tri, point, weights = _outline_corners(positions, triangles, parent_surface[parent], *args)
        positions, triangles, parent = _insert_corners(
            positions, triangles, parent, tri, point, weights
        )
        changed += len(positions) - before
    return positions, triangles, parent, changed


def _split_edges(
    positions: np.ndarray,
    triangles: np.ndarray,
    parent: np.ndarray,
    ends: np.ndarray,
    points: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split edges ``ends`` (K, 2) at ``points`` (K, 3), each triangle holding one into two
    (its corner opposite the edge joined to the point); an edge is skipped when a triangle
    holding it already has a split edge, or when its point lies within
    :data:`MIN_SPLIT` of its length from an end."""
    if len(ends) == 0:
        return positions, triangles, parent
    count = len(positions)
    keys, first = np.unique(edge_keys(ends[:, 0], ends[:, 1], count), return_index=True)
    ends, points = ends[first], points[first]
    s = np.linalg.norm(points - positions[ends[:, 0]], axis=1) / np.linalg.norm(
        positions[ends[:, 1]] - positions[ends[:, 0]], axis=1
    )
    fair = (s > MIN_SPLIT) & (s < 1.0 - MIN_SPLIT)
    keys, points = keys[fair], points[fair]
    tri_keys = edge_keys(triangles, np.roll(triangles, -1, axis=1), count)
    slot, corner = np.nonzero(np.isin(tri_keys, keys))
    holders: dict[int, list[tuple[int, int]]] = {}
    for t, k in zip(slot.tolist(), corner.tolist(), strict=True):
        holders.setdefault(int(tri_keys[t, k]), []).append((t, k))
    busy: set[int] = set()
    rows: list[int] = []
    sides: list[int] = []
    new_index: list[int] = []
    chosen: list[int] = []
    for i, key in enumerate(keys.tolist()):
        held = holders.get(key, [])
        if not held or any(t in busy for t, _ in held):
            continue
        busy.update(t for t, _ in held)
        for t, side in held:
            rows.append(t)
            sides.append(side)
            new_index.append(count + len(chosen))
        chosen.append(i)
    if not rows:
        return positions, triangles, parent
    row, side_k, x = np.array(rows), np.array(sides), np.array(new_index)
    a = triangles[row, side_k]
    b = triangles[row, (side_k + 1) % 3]
    c = triangles[row, (side_k + 2) % 3]
    triangles = triangles.copy()
    triangles[row] = np.stack([a, x, c], axis=1)
    triangles = np.concatenate([triangles, np.stack([x, b, c], axis=1)])
    parent = np.concatenate([parent, parent[row]])
    positions = np.concatenate([positions, points[chosen]])
    return positions, triangles, parent


def _vertex_sources(
    count: int, triangles: np.ndarray, triangle_source: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The scene triangles each vertex lies in, as CSR: ``(pointer (V + 1,), source)``."""
    width = int(triangle_source.max()) + 1
    pairs = unique(triangles.reshape(-1) * width + np.repeat(triangle_source, 3))
    pointer = np.searchsorted(pairs // width, np.arange(count + 1))
    return pointer, pairs % width


def _crossing_snaps(
    positions: np.ndarray,
    triangles: np.ndarray,
    triangle_surface: np.ndarray,
    outlines: Outlines,
    gap: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Where each refined edge crosses an outline segment, the moves that would put one of
    its ends on the segment: each end to its foot on the segment (moved into the edge's
    plane; the least move) and each end along the edge to the crossing (the move that keeps
    an end lying on a scene triangle's edge or a crease on it).

    Returns (K, 4) int64 vertices and (K, 4, 3) float64 targets [m], one row per crossing.
    """
    edges, tri_edges = unique_edges(triangles)
    owner = np.empty(len(edges), dtype=np.int64)
    owner[tri_edges.reshape(-1)] = np.repeat(np.arange(len(triangles)), 3)
    a, b = positions[edges[:, 0]], positions[edges[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    # a crossing lies on the edge, within half its length of the midpoint, and the
    # segment within ``gap`` of it (its ends are within ``gap`` of the plane)
    reach = 0.5 * length + gap
    edge_index, segment_index = items_near_segments(0.5 * (a + b), outlines.points, reach)
    tri = owner[edge_index]
    keep = triangle_surface[tri] != outlines.surface[segment_index]
    edge_index, segment_index, tri = edge_index[keep], segment_index[keep], tri[keep]
    area, normal = triangle_areas_normals(positions[triangles[tri]])
    edge_index, segment_index, normal = (
        edge_index[area > 0],
        segment_index[area > 0],
        normal[area > 0],
    )
    a, b = a[edge_index], b[edge_index]
    p, q = outlines.points[segment_index, 0], outlines.points[segment_index, 1]
    on_plane = (np.abs(_dot(normal, p - a)) <= gap) & (np.abs(_dot(normal, q - a)) <= gap)
    on_plane &= _meeting(normal, outlines.normal[segment_index])
    side_a = _dot(normal, np.cross(q - p, a - p))
    side_b = _dot(normal, np.cross(q - p, b - p))
    side_p = _dot(normal, np.cross(b - a, p - a))
    side_q = _dot(normal, np.cross(b - a, q - a))
    # an end point on the other's line (a shared crease, an edge ending on the outline)
    # is not a crossing: the signs are taken with a band of SIDE_BAND of their scale
    band = SIDE_BAND * np.linalg.norm(q - p, axis=1) * np.linalg.norm(b - a, axis=1)
    crossing = (
        on_plane
        & (sign_with_band(side_a, band) * sign_with_band(side_b, band) < 0)
        & (sign_with_band(side_p, band) * sign_with_band(side_q, band) < 0)
    )
    ends = edges[edge_index[crossing]]
    a, b, p, q, normal = a[crossing], b[crossing], p[crossing], q[crossing], normal[crossing]
    side_a, side_b = side_a[crossing], side_b[crossing]
    along = a + (side_a / (side_a - side_b))[:, None] * (b - a)
    targets = [_foot(a, p, q, normal), _foot(b, p, q, normal), along, along]
    vertex = np.stack([ends[:, 0], ends[:, 1], ends[:, 0], ends[:, 1]], axis=1)
    return vertex, np.stack(targets, axis=1)


def _foot(point: np.ndarray, p: np.ndarray, q: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(N, 3) the nearest point of segment p-q to ``point``, moved along ``normal`` into the
    plane through ``point``."""
    foot = nearest_on_segment(point, p, q)
    return foot - _dot(normal, foot - point)[:, None] * normal


def _outline_corners(
    positions: np.ndarray,
    triangles: np.ndarray,
    triangle_surface: np.ndarray,
    outlines: Outlines,
    gap: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Outline end points inside a refined triangle of another surface, within ``gap`` of
    its plane and not at one of its corners (a block's corner on the floor).

    Returns (K,) int64 triangles, (K, 3) float64 points moved into their planes [m] and
    (K, 3) float64 barycentric coordinates.
    """
    ends = np.concatenate([outlines.points[:, 0], outlines.points[:, 1]])
    end_surface = np.concatenate([outlines.surface, outlines.surface])
    end_normal = np.concatenate([outlines.normal, outlines.normal])
    corners = positions[triangles]
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    # a point of a triangle lies within 2/3 of its longest edge of the centroid (a
    # median is no longer than it), the end within ``gap`` of its plane above the point
    reach = CORNER_REACH * longest + gap
    tri, end = items_near_segments(corners.mean(axis=1), np.stack([ends, ends], 1), reach)
    keep = triangle_surface[tri] != end_surface[end]
    tri, end = tri[keep], end[keep]
    area, normal = triangle_areas_normals(corners[tri])
    tri, end, normal = tri[area > 0], end[area > 0], normal[area > 0]  # slivers skipped
    corners = positions[triangles[tri]]
    height = _dot(normal, ends[end] - corners[:, 0])
    point = ends[end] - height[:, None] * normal
    weights = barycentric_coordinates(point, corners)
    inside = (np.abs(height) <= gap) & (weights.min(axis=1) >= -SIDE_BAND)
    inside &= _meeting(normal, end_normal[end])
    inside &= weights.max(axis=1) < 1.0 - SIDE_BAND
    rows = np.unique(np.stack([tri[inside], end[inside]], 1), axis=0, return_index=True)[1]
    inside = np.nonzero(inside)[0][rows]
    return tri[inside], point[inside], weights[inside]


def _corner_snaps(
    triangles: np.ndarray, tri: np.ndarray, point: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The moves putting a corner of each triangle ``tri`` on its outline corner ``point``,
    shaped as :func:`_crossing_snaps`' (K, 4) (its last column repeats its first)."""
    vertex = triangles[tri][:, [0, 1, 2, 0]]
    return vertex, np.repeat(point[:, None], 4, axis=1)


def _insert_corners(
    positions: np.ndarray,
    triangles: np.ndarray,
    parent: np.ndarray,
    tri: np.ndarray,
    point: np.ndarray,
    weights: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Put outline corners into the triangles holding them: a point inside a triangle
    splits it in three; a point within :data:`MIN_SPLIT` (barycentric) of an edge splits
    that edge at the point's foot on it (:func:`_split_edges`). One point per triangle."""
    tri, first = np.unique(tri, return_index=True)
    point, weights = point[first], weights[first]
    near = weights.min(axis=1) < MIN_SPLIT
    edge_k = (np.argmin(weights, axis=1) + 1) % 3  # the edge opposite the least weight
    a = triangles[tri, edge_k]
    b = triangles[tri, (edge_k + 1) % 3]
    foot = nearest_on_segment(point, positions[a], positions[b])
    inner = ~near
    count = len(positions)
    x = count + np.arange(int(inner.sum()))
    t = triangles[tri[inner]]
    triangles = triangles.copy()
    triangles[tri[inner]] = np.stack([t[:, 0], t[:, 1], x], axis=1)
    triangles = np.concatenate(
        [triangles, np.stack([t[:, 1], t[:, 2], x], 1), np.stack([t[:, 2], t[:, 0], x], 1)]
    )
    parent = np.concatenate([parent, parent[tri[inner]], parent[tri[inner]]])
    positions = np.concatenate([positions, point[inner]])
    ends = np.stack([a[near], b[near]], axis=1)
    return _split_edges(positions, triangles, parent, ends, foot[near])


def _nearest_target(
    positions: np.ndarray, vertex: np.ndarray, target: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One move per crossing (its least valid one), then one per vertex (its least).

    Parameters: (K, C) vertices, (K, C, 3) targets and (K, C) validity, C moves a crossing.
    """
    distance = np.linalg.norm(target - positions[vertex], axis=2)
    distance[~valid] = np.inf
    best = np.argmin(distance, axis=1)
    rows = np.arange(len(vertex))
    distance, vertex, target = distance[rows, best], vertex[rows, best], target[rows, best]
    some = np.isfinite(distance)
    distance, vertex, target = distance[some], vertex[some], target[some]
    order = np.lexsort((distance, vertex))
    vertex, target = vertex[order], target[order]
    first = np.ones(len(vertex), dtype=bool)
    first[1:] = vertex[1:] != vertex[:-1]
    return vertex[first], target[first]


def _inside_sources(
    target: np.ndarray,
    vertex: np.ndarray,
    sources: tuple[np.ndarray, np.ndarray],
    source_corners: np.ndarray,
) -> np.ndarray:
    """(K, C) bool: each target lies in every scene triangle its vertex lies in, so the
    scene triangles, creases and the lightmap UVs interpolated over them keep their shape
    (a vertex inside one triangle moves within it, one on a shared edge or crease along it,
    one on a scene corner not at all)."""
    shape = vertex.shape
    vertex, target = vertex.reshape(-1), target.reshape(-1, 3)
    if len(vertex) == 0:
        return np.zeros(shape, dtype=bool)
    pointer, source = sources
    count = pointer[vertex + 1] - pointer[vertex]
    if count.min() < 1:
        raise ValueError("a refined vertex lies in no scene triangle")
    row = np.repeat(np.arange(len(vertex)), count)
    slot = np.repeat(pointer[vertex] - (np.cumsum(count) - count), count) + np.arange(row.size)
    inside = _in_triangle(target[row], source_corners[source[slot]])
    every = np.minimum.reduceat(inside.astype(np.int8), np.cumsum(count) - count) > 0
    return every.reshape(shape)


def _in_triangle(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(N,) bool: ``points`` lie in the triangles ``corners`` (N, 3, 3), within their plane
    to :data:`PLANE_BAND` of the longest edge and to a barycentric band of 1e-9."""
    area, normal = triangle_areas_normals(corners)
    height = np.abs(_dot(points - corners[:, 0], normal))
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    longest = np.maximum(np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1))
    inside = (
        barycentric_coordinates(points, corners).min(axis=1) >= -1e-9
    )  # NaN (degenerate): False
    return inside & (height <= PLANE_BAND * longest) & (area > 0)


def _accept_moves(
    positions: np.ndarray,
    triangles: np.ndarray,
    reference_normal: np.ndarray,
    vertex: np.ndarray,
    target: np.ndarray,
) -> np.ndarray:
    """Move ``vertex`` to ``target`` in place, then, while a moved triangle is turned over
    or keeps less than :data:`MIN_AREA_KEPT` of its area, undo the longest move in each
    such triangle (two corners snapping onto one line undo one, not both). Returns the
    vertices that moved."""
    original = positions[vertex].copy()
    slot = np.full(len(positions), -1, dtype=np.int64)
    slot[vertex] = np.arange(len(vertex))
    touched = np.nonzero((slot[triangles] >= 0).any(axis=1))[0]
    corner_slot = slot[triangles[touched]]
    before, _ = triangle_areas_normals(positions[triangles[touched]])
    length = np.linalg.norm(target - original, axis=1)
    active = np.ones(len(vertex), dtype=bool)
    positions[vertex] = target
    for _ in range(len(vertex) + 1):
        area, normal = triangle_areas_normals(positions[triangles[touched]])
        bad = (area < MIN_AREA_KEPT * before) | (_dot(normal, reference_normal[touched]) <= 0.5)
        slots = corner_slot[bad]
        live = slots >= 0
        live[live] = active[slots[live]]
        if not live.any():
            break
        moves = np.where(live, length[np.maximum(slots, 0)], -1.0)
        longest = slots[np.arange(len(slots)), np.argmax(moves, axis=1)]
        undo = unique(longest[live.any(axis=1)])
        active[undo] = False
        positions[vertex[undo]] = original[undo]
    return vertex[active]


def _meeting(normal: np.ndarray, outline_normal: np.ndarray) -> np.ndarray:
    """(N,) bool: an outline's surface meets a surface at more than :data:`CONTACT_ANGLE`."""
    return np.abs(_dot(normal, outline_normal)) < math.cos(math.radians(CONTACT_ANGLE))


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", x, y)
