"""Lightmap baking: UVs, conservative rasterisation, dilation, seams and the EXR file."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from raytrad import api
from raytrad.core.mesh import MeshSettings, RadiosityMesh, build_mesh
from raytrad.core.pipeline import Prepared
from raytrad.core.refine import connected_labels
from raytrad.core.solver import SolveResult
from raytrad.formats.images import read_attributes, read_image
from raytrad.outputs.lightmaps import write_lightmap
from raytrad.products.lightmap import (
    Lightmap,
    LightmapSettings,
    bake_lightmap,
    lightmap_vertices,
    texel_density_stats,
)
from raytrad.products.raster import rasterize
from raytrad.scene import make_scene, triangle_areas_normals
from raytrad.scene.builtin import cornell_box, furnace_box
from raytrad.settings import RefineSettings, RenderSettings

SMALL_MESH = MeshSettings(receivers=1500, patches=100)
SIZE = 256
ISLAND_MARGIN = 6.0
"""Texels kept empty around each island of the model-UV layout [texels]."""


# --------------------------------------------------------------------------------------
# Reference implementations: slow, obvious, per triangle
# --------------------------------------------------------------------------------------


def _barycentrics(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, T, 3) barycentric coordinates of N points in each of T 2-D triangles."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    v0, v1 = b - a, c - a
    v2 = points[:, None, :] - a[None]
    denom = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    l1 = (v2[..., 0] * v1[:, 1] - v1[:, 0] * v2[..., 1]) / denom
    l2 = (v0[:, 0] * v2[..., 1] - v2[..., 0] * v0[:, 1]) / denom
    return np.stack([1.0 - l1 - l2, l1, l2], axis=-1)


def _centres_inside(uv: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: texels whose centre lies in some triangle, one triangle at a time."""
    width, height = size
    inside = np.zeros((height, width), dtype=bool)
    for corners in uv:
        x0, y0 = np.floor(corners.min(axis=0)).astype(int)
        x1, y1 = np.ceil(corners.max(axis=0)).astype(int)
        grid_x, grid_y = np.meshgrid(np.arange(max(x0, 0), min(x1, width)), np.arange(y0, y1))
        xs, ys = grid_x.reshape(-1), grid_y.reshape(-1)
        ys_ok = (ys >= 0) & (ys < height)
        xs, ys = xs[ys_ok], ys[ys_ok]
        weights = _barycentrics(corners[None], np.stack([xs + 0.5, ys + 0.5], axis=1))[:, 0]
        hit = (weights >= 0.0).all(axis=1)
        inside[ys[hit], xs[hit]] = True
    return inside


def _distance_to_triangles(uv: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) distance from each point to the nearest of the triangles [texels]."""
    best = np.full(len(points), np.inf)
    weights = _barycentrics(uv, points)
    best[np.asarray((weights >= 0.0).all(axis=2)).any(axis=1)] = 0.0
    for k in range(3):
        a, b = uv[:, k], uv[:, (k + 1) % 3]
        edge = b - a
        rel = points[:, None, :] - a[None]
        t = np.clip((rel * edge).sum(axis=2) / (edge * edge).sum(axis=1), 0.0, 1.0)
        gap = np.linalg.norm(rel - t[..., None] * edge, axis=2).min(axis=1)
        best = np.minimum(best, gap)
    return best


def _texel_uv(lightmap: Lightmap) -> np.ndarray:
    return lightmap.uv * np.asarray(lightmap.size, dtype=np.float64)


def _island_uvs(
    scene_corners: np.ndarray, cells: int, margin: float, points: np.ndarray, source: np.ndarray
) -> np.ndarray:
    """(N, 2) normalised UVs of ``points`` in a layout putting each scene triangle alone in
    a grid cell, each keeping its shape (one common scale), so every edge shared by two
    scene triangles is a UV seam.

    Parameters
    ----------
    scene_corners : (S, 3, 3) float [m]
    points : (N, 3) float [m], each in scene triangle ``source`` ((N,) int)
    """
    p0 = scene_corners[:, 0]
    e1 = scene_corners[:, 1] - p0
    _, normal = triangle_areas_normals(scene_corners)
    axis_u = e1 / np.linalg.norm(e1, axis=1)[:, None]
    axis_v = np.cross(normal, axis_u)

    def flatten(p: np.ndarray, s: np.ndarray) -> np.ndarray:
        rel = p - p0[s]
        return np.stack([(rel * axis_u[s]).sum(-1), (rel * axis_v[s]).sum(-1)], axis=-1)

    index = np.arange(len(scene_corners))
    flat = flatten(scene_corners.reshape(-1, 3), np.repeat(index, 3)).reshape(-1, 3, 2)
    low = flat.min(axis=1)
    scale = (1.0 - 2.0 * margin) / (flat - low[:, None]).max()
    cell = np.stack([index % cells, index // cells], axis=1)
    return (cell[source] + margin + (flatten(points, source) - low[source]) * scale) / cells


def _surfaces(mesh: RadiosityMesh) -> np.ndarray:
    """(T,) label of the receiver-connected surface of each refined triangle."""
    corners = mesh.triangle_receivers
    pairs = np.concatenate([corners[:, [0, 1]], corners[:, [1, 2]]])
    return connected_labels(mesh.receiver_count, pairs)[corners[:, 0]]


# --------------------------------------------------------------------------------------
# Fixtures
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cornell_solved() -> tuple[Prepared, SolveResult]:
    """The Cornell box at about 1500 receivers, solved to the default tolerance.

    Not refined: refinement resolves contact shadows below a texel of these small
    lightmaps, and the sampling checks below compare texels with the vertex field at texel
    scale (refined meshes are baked in tests/products/test_image.py)."""
    settings = RenderSettings(mesh=SMALL_MESH, refine=RefineSettings(threshold=0.0))
    return api.solve_scene(cornell_box(), settings)


@pytest.fixture(scope="module")
def cornell_lightmap(cornell_solved: tuple[Prepared, SolveResult]) -> Lightmap:
    """A generated (xatlas) 256 x 256 atlas of the Cornell box."""
    prepared, result = cornell_solved
    return bake_lightmap(prepared.mesh, result.radiosity, LightmapSettings(resolution=SIZE))


@pytest.fixture(scope="module")
def cornell_islands(cornell_solved: tuple[Prepared, SolveResult]) -> Lightmap:
    """The Cornell box baked through a model UV set that puts each scene triangle alone."""
    prepared, result = cornell_solved
    corners = prepared.scene.triangle_vertices()
    cells = math.ceil(math.sqrt(len(corners)))
    source = np.repeat(np.arange(len(corners)), 3)
    uv = _island_uvs(
        corners, cells, ISLAND_MARGIN * cells / (2 * SIZE), corners.reshape(-1, 3), source
    )
    uv = uv.reshape(-1, 3, 2)
    settings = LightmapSettings(resolution=2 * SIZE, uv_set=1)
    return bake_lightmap(prepared.mesh, result.radiosity, settings, uv, corners)


@pytest.fixture(params=["generated", "model-uvs"])
def baked(
    request: pytest.FixtureRequest,
    cornell_solved: tuple[Prepared, SolveResult],
    cornell_lightmap: Lightmap,
    cornell_islands: Lightmap,
) -> Iterator[tuple[RadiosityMesh, np.ndarray, Lightmap]]:
    """(mesh, receiver radiosity, lightmap) for both ways of getting UVs."""
    prepared, result = cornell_solved
    lightmap = cornell_lightmap if request.param == "generated" else cornell_islands
    yield prepared.mesh, result.radiosity, lightmap


# --------------------------------------------------------------------------------------
# Interpolation and coverage
# --------------------------------------------------------------------------------------


def test_texel_inside_a_triangle_is_the_barycentric_interpolation(
    baked: tuple[RadiosityMesh, np.ndarray, Lightmap],
) -> None:
    mesh, radiosity, lightmap = baked
    uv = _texel_uv(lightmap)
    rows, cols = np.nonzero(lightmap.coverage)
    pick = np.random.default_rng(1).choice(len(rows), 300, replace=False)
    centres = np.stack([cols[pick] + 0.5, rows[pick] + 0.5], axis=1)
    weights = _barycentrics(uv, centres)  # (N, T, 3)
    strictly = np.asarray((weights > 1e-9).all(axis=2))
    found = strictly.any(axis=1)
    assert found.sum() > 200  # most covered texels have their centre inside a triangle
    tri = np.argmax(strictly, axis=1)[found]
    w = weights[np.nonzero(found)[0], tri]
    expected = np.einsum("nk,nkc->nc", w, radiosity[mesh.triangle_receivers[tri]])
    got = lightmap.pixels[rows[pick][found], cols[pick][found]]
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-7 * radiosity.max())


def test_every_texel_whose_centre_is_in_a_triangle_is_covered(
    baked: tuple[RadiosityMesh, np.ndarray, Lightmap],
) -> None:
    _, _, lightmap = baked
    uv = _texel_uv(lightmap)
    inside = _centres_inside(uv, lightmap.size)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    chart_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    assert inside.sum() == pytest.approx(chart_area, rel=0.05)
    assert lightmap.coverage[inside].all()


def test_covered_texels_touch_a_triangle(cornell_lightmap: Lightmap) -> None:
    # conservative, not generous: a texel square touching a triangle has its centre
    # within half a diagonal of it
    uv = _texel_uv(cornell_lightmap)
    rows, cols = np.nonzero(cornell_lightmap.coverage & ~_centres_inside(uv, (SIZE, SIZE)))
    assert len(rows) > 0
    centres = np.stack([cols + 0.5, rows + 0.5], axis=1)
    distance = np.concatenate(
        [_distance_to_triangles(uv, chunk) for chunk in np.array_split(centres, 20)]
    )
    assert distance.max() <= math.sqrt(0.5) + 1e-9


def test_bilinear_footprint_inside_charts_is_filled(
    baked: tuple[RadiosityMesh, np.ndarray, Lightmap],
) -> None:
    mesh, radiosity, lightmap = baked
    uv = _texel_uv(lightmap)
    rng = np.random.default_rng(2)
    tri = rng.integers(0, len(uv), 20000)
    a, b = rng.random(len(tri)), rng.random(len(tri))
    flip = a + b > 1.0
    a, b = np.where(flip, 1.0 - a, a), np.where(flip, 1.0 - b, b)
    weights = np.stack([1.0 - a - b, a, b], axis=1)
    point = np.einsum("nk,nkc->nc", weights, uv[tri])
    x0 = np.floor(point[:, 0] - 0.5).astype(int)
    y0 = np.floor(point[:, 1] - 0.5).astype(int)
    lit = (radiosity[mesh.triangle_receivers[tri]] > 0).all(axis=(1, 2))
    width, height = lightmap.size
    for dx in (0, 1):
        for dy in (0, 1):
            x, y = x0 + dx, y0 + dy
            assert ((x >= 0) & (x < width) & (y >= 0) & (y < height)).all()
            texel = lightmap.pixels[y, x]
            assert np.isfinite(texel).all()
            assert (texel[lit] > 0).all()


def test_bilinear_footprint_holds_only_its_own_surface(
    baked: tuple[RadiosityMesh, np.ndarray, Lightmap],
) -> None:
    """No leaks: the texels bilinear filtering reads anywhere on a surface hold values
    within that surface's range (the padding repeats the chart, not a bright neighbour)."""
    mesh, radiosity, lightmap = baked
    uv = _texel_uv(lightmap)
    surface = _surfaces(mesh)
    labels = int(surface.max()) + 1
    low = np.full((labels, 3), np.inf)
    high = np.full((labels, 3), -np.inf)
    corner_values = radiosity[mesh.triangle_receivers]
    np.minimum.at(low, surface, corner_values.min(axis=1))
    np.maximum.at(high, surface, corner_values.max(axis=1))
    rng = np.random.default_rng(5)
    tri = rng.integers(0, len(uv), 50000)
    a, b = rng.random(len(tri)), rng.random(len(tri))
    flip = a + b > 1.0
    a, b = np.where(flip, 1.0 - a, a), np.where(flip, 1.0 - b, b)
    point = np.einsum("nk,nkc->nc", np.stack([1.0 - a - b, a, b], axis=1), uv[tri]) - 0.5
    x0, y0 = np.floor(point).astype(int).T
    slack = 1e-5 * radiosity.max()
    for dx in (0, 1):
        for dy in (0, 1):
            texel = lightmap.pixels[y0 + dy, x0 + dx]
            assert (texel >= low[surface[tri]] - slack).all()
            assert (texel <= high[surface[tri]] + slack).all()


def test_model_uvs_are_carried_to_the_refined_corners(
    cornell_solved: tuple[Prepared, SolveResult], cornell_islands: Lightmap
) -> None:
    """Each refined corner gets the model's UV at its position in its scene triangle."""
    prepared, _ = cornell_solved
    mesh = prepared.mesh
    corners = prepared.scene.triangle_vertices()
    cells = math.ceil(math.sqrt(len(corners)))
    expected = _island_uvs(
        corners,
        cells,
        ISLAND_MARGIN * cells / (2 * SIZE),
        mesh.positions[mesh.triangles].reshape(-1, 3),
        np.repeat(mesh.triangle_source, 3),
    )
    np.testing.assert_allclose(cornell_islands.uv.reshape(-1, 2), expected, atol=1e-9)


def test_bilinear_lookup_matches_the_vertex_interpolation(
    cornell_solved: tuple[Prepared, SolveResult], cornell_lightmap: Lightmap
) -> None:
    """What a renderer samples: within 1 % of the peak for 99 % of points (the rest are at
    contact shadows, where the radiosity changes fully within a texel)."""
    prepared, result = cornell_solved
    mesh, radiosity, lightmap = prepared.mesh, result.radiosity, cornell_lightmap
    uv = _texel_uv(lightmap)
    rng = np.random.default_rng(3)
    tri = rng.integers(0, len(uv), 20000)
    a, b = rng.random(len(tri)), rng.random(len(tri))
    flip = a + b > 1.0
    a, b = np.where(flip, 1.0 - a, a), np.where(flip, 1.0 - b, b)
    weights = np.stack([1.0 - a - b, a, b], axis=1)
    point = np.einsum("nk,nkc->nc", weights, uv[tri]) - 0.5
    exact = np.einsum("nk,nkc->nc", weights, radiosity[mesh.triangle_receivers[tri]])
    x0, y0 = np.floor(point).astype(int).T
    fx, fy = (point - np.floor(point)).T
    px = lightmap.pixels
    sampled = (
        px[y0, x0] * ((1 - fx) * (1 - fy))[:, None]
        + px[y0, x0 + 1] * (fx * (1 - fy))[:, None]
        + px[y0 + 1, x0] * ((1 - fx) * fy)[:, None]
        + px[y0 + 1, x0 + 1] * (fx * fy)[:, None]
    )
    emitting = (mesh.receiver_emitted_exitance > 0).any(axis=1)
    peak = radiosity[~emitting].max()
    error = np.abs(sampled - exact).max(axis=1) / peak
    assert np.percentile(error, 99) < 0.01


def test_sliver_a_third_of_a_texel_wide_still_gets_texels() -> None:
    # a strip 0.3 texels high between two rows of texel centres: no centre is inside
    strip = np.array(
        [
            [[2.2, 10.6], [50.7, 10.6], [50.7, 10.9]],
            [[2.2, 10.6], [50.7, 10.9], [2.2, 10.9]],
        ]
    )
    values = strip[..., :1]  # the value is the texel-space x coordinate
    pixels, coverage = rasterize(strip, values, (64, 32))
    assert not _centres_inside(strip, (64, 32)).any()
    assert coverage[10, 2:51].all()
    assert coverage.sum() == 49
    np.testing.assert_allclose(pixels[10, 3:50, 0], np.arange(3, 50) + 0.5, atol=1e-6)
    np.testing.assert_allclose(pixels[10, [2, 50], 0], [2.5, 50.5], atol=1e-6)


def test_diagonal_sliver_covers_every_texel_it_crosses() -> None:
    start, end = np.array([3.3, 4.1]), np.array([57.2, 40.6])
    across = np.array([-(end - start)[1], (end - start)[0]])
    across *= 0.15 / np.linalg.norm(across)  # 0.3 texels wide in all
    sliver = np.array([[start - across, end - across, end + across]])
    _, coverage = rasterize(sliver, np.ones((1, 3, 1)), (64, 64))
    t = np.linspace(0.0, 1.0, 20001)[1:-1, None]
    along = (1 - t) * (start - across) + t * (end + across)  # the triangle's diagonal
    crossed = np.unique(np.floor(along).astype(int), axis=0)
    assert coverage[crossed[:, 1], crossed[:, 0]].all()
    rows, cols = np.nonzero(coverage)
    gaps = _distance_to_triangles(sliver, np.stack([cols + 0.5, rows + 0.5], axis=1))
    assert gaps.max() <= math.sqrt(0.5) + 1e-9


def test_priority_breaks_ties_between_coincident_triangles() -> None:
    triangle = np.array([[1.0, 1.0], [9.0, 1.5], [2.0, 8.0]])
    uv = np.stack([triangle, triangle])
    values = np.stack([np.full((3, 1), 1.0), np.full((3, 1), 2.0)])
    pixels, coverage = rasterize(uv, values, (10, 10), priority=np.array([1, 0]))
    assert (pixels[coverage] == 2.0).all()


# --------------------------------------------------------------------------------------
# Seams, analytic furnace, texel density
# --------------------------------------------------------------------------------------


def _seam_texels(
    mesh: RadiosityMesh, radiosity: np.ndarray, lightmap: Lightmap, chart: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The texels holding the midpoint of each UV-seam edge on its two charts.

    A seam edge is a refined edge (a pair of receivers) whose two triangles put its
    midpoint at different UVs. Either texel's value is that of a point within sqrt(2)
    texels of the midpoint on its own chart (the centre if it lies inside, else the
    chart's point nearest the centre), so it differs from the midpoint's value by at most
    sqrt(2) times the chart's largest gradient: that is the bound returned.

    Parameters
    ----------
    chart : (T,) int
        A label per triangle whose groups are convex in UV (for the gradient bound).

    Returns
    -------
    first, second : (E, 3) float64
        The texel values on either side.
    midpoint : (E, 3) float64
        The vertex radiosity interpolated at the edge midpoint.
    bound : (E, 1) float64
        sqrt(2) times the sum of the two charts' largest gradients [value per texel].
    """
    uv = _texel_uv(lightmap)
    corners = mesh.triangle_receivers
    key = np.sort(np.stack([corners, np.roll(corners, -1, axis=1)], axis=2), axis=2)
    key = key.reshape(-1, 2)
    owner = np.repeat(np.arange(len(corners)), 3)
    slot = np.tile(np.arange(3), len(corners))
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, owner, slot = key[order], owner[order], slot[order]
    same = (key[1:] == key[:-1]).all(axis=1)
    t1, t2 = owner[:-1][same], owner[1:][same]
    s1, s2 = slot[:-1][same], slot[1:][same]

    def midpoint_uv(tri: np.ndarray, edge_slot: np.ndarray) -> np.ndarray:
        return np.asarray(0.5 * (uv[tri, edge_slot] + uv[tri, (edge_slot + 1) % 3]))

    seam = np.linalg.norm(midpoint_uv(t1, s1) - midpoint_uv(t2, s2), axis=1) > 1e-6
    t1, t2, s1, s2 = t1[seam], t2[seam], s1[seam], s2[seam]

    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    values = radiosity[corners]
    differences = np.stack([values[:, 1] - values[:, 0], values[:, 2] - values[:, 0]], axis=1)
    # rows of the matrix are the texel-space edges: edges @ gradient = differences
    gradient = np.einsum("tij,tjc->tic", np.linalg.inv(np.stack([e1, e2], axis=1)), differences)
    per_chart = np.zeros(int(chart.max()) + 1)
    np.maximum.at(per_chart, chart, np.linalg.norm(gradient, axis=1).max(axis=1))

    def texel_value(tri: np.ndarray, edge_slot: np.ndarray) -> np.ndarray:
        x, y = np.floor(midpoint_uv(tri, edge_slot)).astype(int).T
        assert lightmap.coverage[y, x].all()
        return np.asarray(lightmap.pixels[y, x], dtype=np.float64)

    midpoint = 0.5 * (radiosity[corners[t1, s1]] + radiosity[corners[t1, (s1 + 1) % 3]])
    bound = math.sqrt(2.0) * (per_chart[chart[t1]] + per_chart[chart[t2]])[:, None]
    return texel_value(t1, s1), texel_value(t2, s2), midpoint, bound


def test_values_match_across_model_uv_seams(
    cornell_solved: tuple[Prepared, SolveResult], cornell_islands: Lightmap
) -> None:
    """Every scene edge is a seam of the island layout; each island is one (convex)
    scene triangle."""
    prepared, result = cornell_solved
    mesh = prepared.mesh
    first, second, midpoint, bound = _seam_texels(
        mesh, result.radiosity, cornell_islands, mesh.triangle_source
    )
    assert len(first) > 50
    slack = 1e-6 * result.radiosity.max()
    assert (np.abs(first - second) <= bound + slack).all()
    assert (np.abs(first - midpoint) <= bound / 2 + slack).all()
    # in practice the two sides agree far better than the bound
    assert np.median(np.abs(first - second) / bound) < 0.25


def test_values_match_across_generated_seams() -> None:
    """xatlas must cut a tube open; a radiosity linear in position is continuous across
    the cut, and so must the texels on both sides be."""
    segments, radius = 24, 0.3
    angle = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([radius * np.cos(angle), np.zeros(segments), radius * np.sin(angle)], axis=1)
    positions = np.concatenate([ring, ring + np.array([0.0, 1.0, 0.0])])
    i = np.arange(segments)
    j = (i + 1) % segments
    triangles = np.concatenate(
        [np.stack([i, segments + j, j], axis=1), np.stack([i, segments + i, segments + j], axis=1)]
    )
    tube = make_scene(
        positions, triangles, np.zeros(len(triangles), int), ["grey"], [[0.5] * 3], [[0.0] * 3]
    )
    mesh = build_mesh(tube, MeshSettings(receivers=1500, patches=20))
    p = mesh.receiver_position
    radiosity = np.stack([1.0 + p[:, 1], 1.0 + p[:, 0] + 0.5, 2.0 + p[:, 2] * p[:, 1]], axis=1)
    lightmap = bake_lightmap(mesh, radiosity, LightmapSettings(resolution=SIZE))
    first, second, midpoint, bound = _seam_texels(
        mesh, radiosity, lightmap, np.zeros(len(mesh.triangles), dtype=np.int64)
    )
    assert len(first) >= 10  # at least one cut along the tube
    assert (np.abs(first - second) <= bound + 1e-6).all()
    assert (np.abs(first - midpoint) <= bound / 2 + 1e-6).all()


@pytest.mark.parametrize("uvs", ["generated", "model-uvs"])
def test_indexed_mesh_splits_receivers_only_on_seams(
    cornell_solved: tuple[Prepared, SolveResult],
    cornell_lightmap: Lightmap,
    cornell_islands: Lightmap,
    uvs: str,
) -> None:
    mesh = cornell_solved[0].mesh
    lightmap = cornell_lightmap if uvs == "generated" else cornell_islands
    receiver, triangles, uv = lightmap_vertices(mesh, lightmap)
    np.testing.assert_array_equal(receiver[triangles], mesh.triangle_receivers)
    np.testing.assert_allclose(uv[triangles], lightmap.uv, atol=1e-7)
    assert mesh.receiver_count <= len(receiver)
    if uvs == "generated":  # Cornell surfaces are flat: one chart each, no seams
        assert len(receiver) == mesh.receiver_count
    else:  # only receivers on scene edges are split
        assert len(receiver) < 1.2 * mesh.receiver_count


def test_furnace_every_covered_texel_is_e_over_one_minus_rho() -> None:
    prepared, result = api.solve_scene(furnace_box(0.5, 1.0), RenderSettings(mesh=SMALL_MESH))
    lightmap = bake_lightmap(prepared.mesh, result.radiosity, LightmapSettings(resolution=128))
    assert lightmap.coverage.mean() > 0.4
    np.testing.assert_allclose(lightmap.pixels[lightmap.coverage], 2.0, rtol=0.01)
    np.testing.assert_allclose(lightmap.pixels, 2.0, rtol=0.01)  # the padding too


@pytest.mark.parametrize("uvs", ["generated", "model-uvs"])
def test_texel_density_setting_is_met(uvs: str) -> None:
    scene = furnace_box(0.5, 1.0)
    mesh = build_mesh(scene, SMALL_MESH)
    corners = scene.triangle_vertices()
    model_uv = None
    if uvs == "model-uvs":
        source = np.repeat(np.arange(len(corners)), 3)
        model_uv = _island_uvs(corners, 4, 0.05, corners.reshape(-1, 3), source).reshape(-1, 3, 2)
    lightmap = bake_lightmap(
        mesh,
        np.ones((mesh.receiver_count, 3)),
        LightmapSettings(texel_density=100.0),
        model_uv,
        corners,
    )
    stats = lightmap.stats
    assert stats["texel_density_median"] == pytest.approx(100.0, rel=0.15)
    assert stats["texel_density_min"] <= stats["texel_density_median"]
    assert stats["texel_density_median"] <= stats["texel_density_max"]
    # 6 m2 of walls at 100 texels m-1 cover 60 000 texels (and a rim, conservatively)
    assert 60_000 <= lightmap.coverage.sum() <= 1.2 * 60_000


def test_texel_density_stats_of_a_known_layout() -> None:
    # a 2 m x 1 m rectangle at 10 texels m-1 and a 1 m2 triangle at 40 texels m-1
    uv = np.array(
        [
            [[0, 0], [20, 0], [20, 10]],
            [[0, 0], [20, 10], [0, 10]],
            [[0, 0], [40 * math.sqrt(2), 0], [0, 40 * math.sqrt(2)]],
        ],
        dtype=float,
    )
    stats = texel_density_stats(uv, np.array([1.0, 1.0, 1.0]))
    assert stats["texel_density_min"] == pytest.approx(10.0)
    assert stats["texel_density_median"] == pytest.approx(10.0)  # 2 of the 3 m2
    assert stats["texel_density_max"] == pytest.approx(40.0)


# --------------------------------------------------------------------------------------
# The EXR file
# --------------------------------------------------------------------------------------


def _leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if ".tmp" in p.name)


@pytest.mark.parametrize(("half", "rtol"), [(True, 1e-3), (False, 0.0)])
def test_exr_round_trip(
    tmp_path: Path, cornell_lightmap: Lightmap, half: bool, rtol: float
) -> None:
    settings = LightmapSettings(resolution=SIZE, half=half)
    lightmap = Lightmap(
        cornell_lightmap.pixels,
        cornell_lightmap.coverage,
        cornell_lightmap.uv,
        cornell_lightmap.stats,
        settings,
    )
    path = tmp_path / "cornell.exr"
    write_lightmap(path, lightmap, {"scene": "cornell-box", "solve:method": "progressive"})
    pixels, attributes = read_image(path), read_attributes(path)
    assert pixels.shape == lightmap.pixels.shape
    expected = lightmap.pixels
    atol = 1e-6 * float(expected.max()) if half else 0.0  # half keeps no denormal detail
    np.testing.assert_allclose(pixels, expected, rtol=rtol, atol=atol)
    assert attributes["raytrad:units"] == "W m-2"
    assert attributes["raytrad:quantity"] == "radiosity"
    assert attributes["raytrad:scene"] == "cornell-box"
    assert attributes["solve:method"] == "progressive"
    assert attributes["raytrad:version"]
    assert attributes["raytrad:lightmap_resolution"] == SIZE
    assert attributes["raytrad:texel_density_median"] == pytest.approx(
        lightmap.stats["texel_density_median"]
    )
    assert _leftovers(tmp_path) == []
    assert [p.name for p in tmp_path.iterdir()] == ["cornell.exr"]


# --------------------------------------------------------------------------------------
# Overlapping model UVs
# --------------------------------------------------------------------------------------


def test_non_overlapping_layouts_report_no_overlap(
    baked: tuple[RadiosityMesh, np.ndarray, Lightmap],
) -> None:
    _, _, lightmap = baked
    assert lightmap.stats["overlap_fraction"] < 1e-3


def test_overlapping_model_uvs_are_measured_and_warned(
    cornell_solved: tuple[Prepared, SolveResult], caplog: pytest.LogCaptureFixture
) -> None:
    # every scene triangle mapped onto the same UV triangle: all charts stack up
    prepared, result = cornell_solved
    corners = prepared.scene.triangle_vertices()
    uv = np.broadcast_to([[0.1, 0.1], [0.9, 0.1], [0.1, 0.9]], (len(corners), 3, 2))
    settings = LightmapSettings(resolution=64, uv_set=1)
    with caplog.at_level("WARNING"):
        lightmap = bake_lightmap(prepared.mesh, result.radiosity, settings, uv.copy(), corners)
    # the refined triangles of each scene triangle tile the UV triangle once, so every
    # texel centre inside it is covered once per front-facing scene triangle
    assert lightmap.stats["overlap_fraction"] > 0.95
    assert "overlap" in caplog.text and "--uv-set atlas" in caplog.text
