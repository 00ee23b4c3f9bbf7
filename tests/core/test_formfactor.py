"""Form factors against closed forms, brute-force quadrature and enclosure identities.

Expected values come from REFERENCE.md section 3 (closed forms, CIE 171:2006 test case 5.6)
or from a midpoint quadrature of ``cos_x cos_y / (pi r^2)`` written here, never from
raytrad itself.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable

import numpy as np
import pytest

from raytrad.core import compiled
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.mesh import MeshSettings, RadiosityMesh, build_mesh
from raytrad.core.pairs import receiver_points
from raytrad.core.pathtrace import path_traced_radiosity
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolveResult, SolveSettings, solve
from raytrad.core.visibility import Occluder, nothing_can_occlude
from raytrad.scene import Scene, triangle_areas_normals
from raytrad.scene.builtin import furnace_box, shadow_scene
from tests.conftest import FURNACE_MESH
from tests.core.analytic import UP, polygon_factor, square, two_triangles

# --------------------------------------------------------------------------------------
# The engine: unoccluded geometry
# --------------------------------------------------------------------------------------

CIE_DOWN = [26.80, 30.94, 33.98, 35.57, 35.57, 33.98, 30.94, 26.80]
CIE_SIDE = [35.901, 27.992, 21.639, 16.716, 12.967]


@pytest.fixture
def cie_floor(make_one_quad: Callable[..., Scene]) -> RadiosityMesh:
    """CIE 171 test case 5.6: the 4 x 4 m floor z = 0, as one patch."""
    floor = make_one_quad([(0, 0, 0), (4, 0, 0), (4, 4, 0), (0, 4, 0)])
    mesh = build_mesh(floor, MeshSettings(max_edge=0.5, patch_size=4.0))
    assert mesh.patch_count == 1
    return mesh


@pytest.mark.parametrize("with_rays", [False, True], ids=["no-occluder", "occluder"])
def test_cie_171_scenario_2_configuration_factors(
    cie_floor: RadiosityMesh, make_one_quad: Callable[..., Scene], with_rays: bool
) -> None:
    occluder = None
    if with_rays:  # nothing can block, so rays must not change anything
        occluder = Occluder(cie_floor.positions, cie_floor.triangles)
    engine = FormFactorEngine(cie_floor, occluder)
    try:
        y = np.arange(0.25, 4.0, 0.5)
        down = engine.factors_at(
            np.column_stack([np.full(8, 2.0), y, np.full(8, 3.0)]), np.tile(-UP, (8, 1)), 0
        )
        z = np.arange(0.75, 3.0, 0.5)
        side = engine.factors_at(
            np.column_stack([np.full(5, 2.0), np.zeros(5), z]), np.tile([0.0, 1.0, 0.0], (5, 1)), 0
        )
    finally:
        engine.close()
        if occluder is not None:
            occluder.close()
    # the published values are rounded to 4-5 digits; the engine's factors are exact
    np.testing.assert_allclose(100.0 * down, CIE_DOWN, rtol=1e-3)
    np.testing.assert_allclose(100.0 * side, CIE_SIDE, rtol=1e-3)


def test_column_gives_nothing_to_receivers_behind_a_one_sided_patch(
    make_quads: Callable[..., Scene],
) -> None:
    # Two floors facing up, one above the other: the lower one looks at the upper one's
    # back, which neither receives nor shoots.
    scene = make_quads([square(0, 1, 0, 1, 0.0), square(0, 1, 0, 1, 0.5)])
    mesh = build_mesh(scene, MeshSettings(max_edge=0.25, patch_size=2.0))
    engine = FormFactorEngine(mesh, None)
    upper = int(np.argmax(mesh.patch_center[:, 2]))
    lower = int(np.argmin(mesh.patch_center[:, 2]))
    assert len(engine.column(upper).receivers) == 0
    assert len(engine.column(lower).receivers) == 0  # the upper one is behind the lower


def test_factors_at_gives_nothing_to_a_point_behind_the_patch(cie_floor: RadiosityMesh) -> None:
    engine = FormFactorEngine(cie_floor, None)
    points = np.array([(2.0, 2.0, -1.0), (1.0, 3.0, -0.2)])
    # below the one-sided floor, facing up at its back
    assert engine.factors_at(points, np.tile(UP, (2, 1)), 0).tolist() == [0.0, 0.0]


def _exchange(prepared: Prepared, receiving: np.ndarray, shooting: np.ndarray) -> float:
    """Area-weighted F from a receiving surface to a shooting one, from engine columns.

    ``receiving`` is a (R,) bool mask of receivers, ``shooting`` a (P,) bool mask of patches.
    Integrates the point factors over the receiving surface:
    ``sum_j A_j F(j <- shooting) / sum_j A_j``.
    """
    mesh = prepared.mesh
    total = 0.0
    for patch in np.nonzero(shooting)[0]:
        column = prepared.engine.column(int(patch))
        mine = receiving[column.receivers]
        total += float(mesh.receiver_area[column.receivers[mine]] @ column.factors[mine])
    return total / float(mesh.receiver_area[receiving].sum())


UNIT_SQUARE_FLOOR = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]  # faces +z


@pytest.mark.parametrize(
    ("other", "expected"),
    [
        ([(0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1)], 0.199825),  # opposed at distance 1
        ([(0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)], 0.200044),  # perpendicular, shared edge
    ],
    ids=["opposed", "perpendicular"],
)
def test_unit_square_exchange_factors(
    make_quads: Callable[..., Scene],
    prepare_scene: Callable[..., Prepared],
    other: list,
    expected: float,
) -> None:
    prepared = prepare_scene(
        make_quads([UNIT_SQUARE_FLOOR, other]), MeshSettings(max_edge=0.05, patch_size=0.5)
    )
    mesh = prepared.mesh
    on_floor = np.isclose(mesh.receiver_normal @ UP, 1.0)
    floor_patch = np.isclose(mesh.patch_normal @ UP, 1.0)
    assert 0 < on_floor.sum() < mesh.receiver_count
    # both directions: the squares have equal areas, so reciprocity makes them equal
    assert _exchange(prepared, on_floor, ~floor_patch) == pytest.approx(expected, rel=1e-2)
    assert _exchange(prepared, ~on_floor, floor_patch) == pytest.approx(expected, rel=1e-2)


def _dense_factors(engine: FormFactorEngine) -> np.ndarray:
    """(R, P) matrix of F(receiver <- patch) assembled from the engine's columns."""
    mesh = engine.mesh
    matrix = np.zeros((mesh.receiver_count, mesh.patch_count))
    for patch in range(mesh.patch_count):
        column = engine.column(patch)
        matrix[column.receivers, patch] = column.factors
    return matrix


def _corner_count(mesh: RadiosityMesh) -> np.ndarray:
    """Per receiver of the unit furnace box: on how many of the planes x, y, z in {0, 1}."""
    on_face = np.isclose(mesh.receiver_position, 0.0) | np.isclose(mesh.receiver_position, 1.0)
    return on_face.sum(axis=1)


def test_closed_box_rows_sum_to_one(prepare_furnace: Callable[..., Prepared]) -> None:
    prepared = prepare_furnace()
    rows = _dense_factors(prepared.engine).sum(axis=1)
    where = _corner_count(prepared.mesh)
    # corner (3 planes) and edge (2 planes) receivers are included and counted
    assert (where == 3).sum() == 24 and (where == 2).sum() > 0
    np.testing.assert_allclose(rows, 1.0, atol=1e-6)


def test_closed_box_rows_sum_to_one_with_rays() -> None:
    scene = furnace_box()
    mesh = build_mesh(scene, FURNACE_MESH)
    with Occluder(scene.positions, scene.triangles) as occluder:
        engine = FormFactorEngine(mesh, occluder, cull=False)
        rows = _dense_factors(engine).sum(axis=1)
        engine.close()
        culled = FormFactorEngine(mesh, occluder)
        culled_rows = _dense_factors(culled).sum(axis=1)
        culled.close()
    assert engine.rays_cast > 0
    np.testing.assert_allclose(rows, 1.0, atol=1e-5)
    # inside a convex box no wall separates a receiver from a patch: shaft culling casts
    # no ray, and every factor is its unoccluded value
    if compiled.get() is not None:  # culling runs with the compiled shaft test only
        assert culled.rays_cast == 0
    np.testing.assert_allclose(culled_rows, 1.0, atol=1e-5)


def test_folded_patch_gives_its_own_receivers_almost_nothing(cornell: Prepared) -> None:
    """The Cornell left wall is a warped quad: its patches are not planar.

    A receiver on such a patch sees at most the part of the wall's other triangle in front
    of it (its own triangle is in its plane and gives nothing). The exact factor of those
    triangles bounds what all the wall's patches together may give it; a boundary-contour
    shortcut over a folded patch would give about 1 instead.
    """
    mesh, engine = cornell.mesh, cornell.engine
    folded = np.nonzero(~mesh.patch_planar)[0]
    assert len(folded) > 0
    wall = np.unique(mesh.triangle_source[np.isin(mesh.triangle_patch, folded)])
    corners = cornell.scene.triangle_vertices()[wall]
    wall_patches = np.unique(mesh.triangle_patch[np.isin(mesh.triangle_source, wall)])
    own = np.unique(mesh.triangle_receivers[np.isin(mesh.triangle_source, wall)])
    got = np.zeros(mesh.receiver_count)
    for patch in wall_patches:
        column = engine.column(int(patch))
        got[column.receivers] += column.factors
    _, wall_normal = triangle_areas_normals(corners)
    bound = np.zeros(len(own))
    for k, j in enumerate(own):
        x = engine._points[j]
        in_front = np.einsum("tj,tj->t", x - corners[:, 0], wall_normal) > 1e-9
        if in_front.any():
            bound[k] = polygon_factor(corners[in_front], x, mesh.receiver_normal[j])
    assert bound.max() < 0.01  # the fold is slight: the wall sees little of itself
    assert (got[own] <= bound + 1e-9).all()


# --------------------------------------------------------------------------------------
# Occlusion
# --------------------------------------------------------------------------------------


def _occlusion_setup(
    make_quads: Callable[..., Scene],
    prepare_scene: Callable[..., Prepared],
    occluder_quad: list,
) -> tuple[Prepared, int, np.ndarray, np.ndarray]:
    """A 1 x 1 patch at z = 1 facing down, a floor at z = 0, an occluder at z = 0.5.

    Returns the prepared scene, the patch index, receiver points on the floor below the
    patch centre (x = 0) and the exact unoccluded factors there.
    """
    patch = square(-0.5, 0.5, -0.5, 0.5, 1.0, up=False)
    floor = square(-1.5, 1.5, -1.5, 1.5, 0.0)
    prepared = prepare_scene(
        make_quads([patch, floor, occluder_quad]),
        MeshSettings(max_edge=0.25, patch_size=4.0, samples=64),
    )
    assert prepared.occluder is not None
    top = int(np.argmin(prepared.mesh.patch_normal[:, 2]))
    points = np.array([(0.0, -0.3, 0.0), (0.0, 0.0, 0.0), (0.0, 0.3, 0.0)])
    unoccluded = np.array([polygon_factor(two_triangles(patch), x, UP) for x in points])
    return prepared, top, points, unoccluded


def test_fully_blocked_patch_gives_nothing(
    make_quads: Callable[..., Scene], prepare_scene: Callable[..., Prepared]
) -> None:
    prepared, top, points, unoccluded = _occlusion_setup(
        make_quads, prepare_scene, square(-1.0, 1.0, -1.0, 1.0, 0.5)
    )
    assert unoccluded.min() > 0.2
    got = prepared.engine.factors_at(points, np.tile(UP, (3, 1)), top)
    np.testing.assert_allclose(got, 0.0, atol=1e-12)


def test_half_blocked_patch_gives_half(
    make_quads: Callable[..., Scene], prepare_scene: Callable[..., Prepared]
) -> None:
    # The occluder covers x < 0 at mid-height: from a point at x = 0 on the floor, the ray
    # to (x, y, 1) crosses z = 0.5 at x / 2, so exactly the half x < 0 of the patch is hidden,
    # and by symmetry that half carries half the factor.
    prepared, top, points, unoccluded = _occlusion_setup(
        make_quads, prepare_scene, square(-2.0, 0.0, -2.0, 2.0, 0.5)
    )
    got = prepared.engine.factors_at(points, np.tile(UP, (3, 1)), top)
    np.testing.assert_allclose(got / unoccluded, 0.5, atol=0.05)


def _edge_receivers(scene: Scene, mesh: RadiosityMesh) -> np.ndarray:
    """(R, T) bool: receiver j lies on scene triangle t whose normal differs from its own."""
    corners = scene.triangle_vertices()
    _, normal = triangle_areas_normals(corners)
    x = mesh.receiver_position
    height = x @ normal.T - np.einsum("tj,tj->t", corners[:, 0], normal)[None, :]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    w = x[:, None, :] - corners[None, :, 0]
    d00, d01, d11 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    d20, d21 = (w * e1).sum(2), (w * e2).sum(2)
    denominator = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / denominator
    u = (d00 * d21 - d01 * d20) / denominator
    inside = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9) & (np.abs(height) < 1e-7)
    return inside & ((mesh.receiver_normal @ normal.T) < math.cos(math.radians(30.0)))


def _cornell_triangle_kinds(scene: Scene) -> dict[str, np.ndarray]:
    """(T,) bool masks of the Cornell scene triangles: room planes, floor, block sides."""
    corners = scene.triangle_vertices()
    _, normal = triangle_areas_normals(corners)
    name = np.array(scene.material_names)[scene.material_index]
    y, z = corners[:, :, 1], corners[:, :, 2]
    floor = (np.abs(y) < 1e-9).all(axis=1) & (normal[:, 1] > 0.99)
    ceiling = (np.abs(y - 0.5488) < 1e-9).all(axis=1) & (normal[:, 1] < -0.99)
    back = (np.abs(z - 0.5592) < 1e-9).all(axis=1)
    room = floor | ceiling | back | np.isin(name, ["red", "green"])
    block = (name == "white") & ~room
    return {"room": room, "floor": floor, "block_side": block & (np.abs(normal[:, 1]) < 0.01)}


def _edge_ratios(
    prepared: Prepared, result: SolveResult, own_kind: np.ndarray, other_kind: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Radiosity of edge receivers and of their nearest interior neighbours on the same wall.

    Edge receivers: on a triangle of ``own_kind`` and lying on another scene triangle, all of
    which are of ``other_kind``. Neighbours: the 3 nearest receivers with the same normal and
    reflectance that lie on no other triangle. Radiosity is summed over channels.

    Returns
    -------
    edge : (K,) int64 receiver indices
    radiosity : (K,) float64
    neighbours : (K,) float64 mean radiosity of the neighbours
    """
    scene, mesh = prepared.scene, prepared.mesh
    on_other = _edge_receivers(scene, mesh)
    is_edge = on_other.any(axis=1)
    source = np.empty(mesh.receiver_count, dtype=np.int64)
    source[mesh.triangle_receivers.reshape(-1)] = np.repeat(mesh.triangle_source, 3)
    others_ok = ~(on_other & ~other_kind[None, :]).any(axis=1)
    edge = np.nonzero(is_edge & own_kind[source] & others_ok)[0]
    radiosity = result.radiosity.sum(axis=1)
    x, n, rho = mesh.receiver_position, mesh.receiver_normal, mesh.receiver_reflectance
    neighbours = np.empty(len(edge))
    for k, j in enumerate(edge):
        same = ~is_edge & (n @ n[j] > 0.999) & (rho == rho[j]).all(axis=1)
        distance = np.where(same, np.linalg.norm(x - x[j], axis=1), np.inf)
        neighbours[k] = radiosity[np.argsort(distance)[:3]].mean()
    return edge, radiosity[edge], neighbours


def test_no_edge_receiver_is_black_where_its_neighbours_are_lit(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    prepared, result = cornell_fine
    everything = np.ones(prepared.scene.triangle_count, dtype=bool)
    edge, radiosity, neighbours = _edge_ratios(prepared, result, everything, everything)
    assert len(edge) > 200
    lit = neighbours > 0.01 * np.median(result.radiosity.sum(axis=1))
    assert lit.mean() > 0.9
    assert (radiosity[lit] > 0).all()


def test_room_edge_receivers_are_not_dark(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    prepared, result = cornell_fine
    kinds = _cornell_triangle_kinds(prepared.scene)
    edge, radiosity, neighbours = _edge_ratios(prepared, result, kinds["room"], kinds["room"])
    assert len(edge) > 100
    ratio = radiosity / neighbours
    print(f"room edges: {len(edge)}, smallest ratio to neighbours {ratio.min():.3f}")
    # No black seam; the darkest are the room's three-way corners, which the path tracer
    # puts at about 0.4 of their neighbours (the near field resolves the dark corner).
    assert ratio.min() > 0.3
    order = np.argsort(ratio)[:4]
    points, _ = receiver_points(prepared.mesh, 1e-5 * prepared.engine.diagonal)
    darkest = edge[order]
    irradiance, _ = path_traced_radiosity(
        prepared.scene, points[darkest], prepared.mesh.receiver_normal[darkest], paths=40000, seed=3
    )
    mesh = prepared.mesh
    traced = (
        mesh.receiver_emitted_exitance[darkest] + mesh.receiver_reflectance[darkest] * irradiance
    ).sum(axis=1)
    print("darkest room-edge receivers, bake / path tracer:", radiosity[order] / traced)
    np.testing.assert_allclose(radiosity[order], traced, rtol=0.15)


def test_block_base_receivers_are_dark_as_the_path_tracer_says(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    # A receiver where a block stands on the floor lies in a real contact shadow: the path
    # tracer puts it at about a third of its neighbours 3 receivers up the side. Black
    # (a ray leak) or as bright as its neighbours (no contact shadow) are both wrong.
    prepared, result = cornell_fine
    kinds = _cornell_triangle_kinds(prepared.scene)
    edge, radiosity, neighbours = _edge_ratios(
        prepared, result, kinds["block_side"], kinds["floor"]
    )
    assert len(edge) > 20
    ratio = radiosity / neighbours
    print(f"block-base edges: {len(edge)}, smallest ratio to neighbours {ratio.min():.3f}")
    assert ratio.min() > 0.2
    darkest = edge[np.argsort(ratio)[:4]]
    points, _ = receiver_points(prepared.mesh, 1e-5 * prepared.engine.diagonal)
    normals = prepared.mesh.receiver_normal[darkest]
    irradiance, _ = path_traced_radiosity(
        prepared.scene, points[darkest], normals, paths=4000, seed=2
    )
    rho = prepared.mesh.receiver_reflectance[darkest]
    traced = (rho * irradiance).sum(axis=1)
    print("darkest base receivers, bake / path tracer:", radiosity[np.argsort(ratio)[:4]] / traced)
    np.testing.assert_array_less(0.5 * traced, radiosity[np.argsort(ratio)[:4]])
    np.testing.assert_array_less(radiosity[np.argsort(ratio)[:4]], 2.0 * traced)


def _floor_and_block(make_quads: Callable[..., Scene], offset: tuple[float, float]) -> Scene:
    """A 2 x 2 m floor (y = 0, facing up) and an open-bottom 0.5 m cube standing on it."""
    cx, cz = offset
    a, h = 0.25, 0.5
    floor = [(-1, 0, -1), (-1, 0, 1), (1, 0, 1), (1, 0, -1)]
    xz = [(cx - a, cz - a), (cx + a, cz - a), (cx + a, cz + a), (cx - a, cz + a)]
    quads = [[(x, h, z) for x, z in xz[::-1]]]  # top, facing up
    for (x0, z0), (x1, z1) in zip(xz, xz[1:] + xz[:1], strict=True):
        quads.append([(x0, 0, z0), (x0, h, z0), (x1, h, z1), (x1, 0, z1)])  # facing out
    return make_quads([floor, *quads])


@pytest.mark.parametrize(
    "offset",
    [
        (0.0, 0.0),
        (0.013, 0.007),
    ],
    ids=["block-on-grid", "block-off-grid"],
)
def test_block_base_receivers_see_the_floor_in_front(
    make_quads: Callable[..., Scene],
    prepare_scene: Callable[..., Prepared],
    offset: tuple[float, float],
) -> None:
    # Nothing stands between a block side's base and the floor in front of it, so the
    # ray-traced factor must equal the exact unoccluded factor of the floor quad (clipped
    # to the receiver's horizon, i.e. the block's side plane).
    scene = _floor_and_block(make_quads, offset)
    prepared = prepare_scene(scene, MeshSettings(max_edge=0.05, patch_size=0.5))
    mesh, engine = prepared.mesh, prepared.engine
    assert prepared.occluder is not None
    base = np.nonzero(
        (np.abs(mesh.receiver_position[:, 1]) < 1e-12) & (np.abs(mesh.receiver_normal[:, 1]) < 1e-9)
    )[0]
    assert len(base) > 40
    floor_patches = np.nonzero(mesh.patch_normal[:, 1] > 0.99)[0]
    floor_patches = floor_patches[mesh.patch_center[floor_patches, 1] < 1e-9]
    got = np.zeros(mesh.receiver_count)
    for patch in floor_patches:
        column = engine.column(int(patch))
        got[column.receivers] += column.factors
    floor = scene.triangle_vertices()[:2]
    exact = np.array(
        [polygon_factor(floor, engine._points[j], mesh.receiver_normal[j]) for j in base]
    )
    assert exact.min() > 0.49  # about half the hemisphere is floor
    np.testing.assert_allclose(got[base], exact, rtol=0.02)


#: The room's back corners from REFERENCE.md section 4, in metres.
BACK_CORNERS = [
    (0.0, 0.0, 0.5592),
    (0.5496, 0.0, 0.5592),
    (0.0, 0.5488, 0.5592),
    (0.556, 0.5488, 0.5592),
]


def test_ray_from_a_room_corner_toward_the_interior_is_free(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    # A receiver in a corner lies exactly in the planes of the two other walls there; the
    # engine's ray origin must be off all of them, so a ray into the room is not blocked.
    prepared, _ = cornell_fine
    mesh, engine, occluder = prepared.mesh, prepared.engine, prepared.occluder
    assert occluder is not None
    corner = np.nonzero(
        [np.isclose(mesh.receiver_position, c, rtol=0, atol=1e-9).all(axis=1) for c in BACK_CORNERS]
    )[1]
    assert len(corner) == 3 * len(BACK_CORNERS)  # three surfaces meet in each corner
    centre = np.array([0.278, 0.2744, 0.2796])
    x = mesh.receiver_position[corner]
    targets = x + 0.05 * (centre - x) / np.linalg.norm(centre - x, axis=1)[:, None]
    assert not occluder.occluded(engine._origins[corner], targets).any()


def test_grazing_segment_to_a_surface_is_not_blocked_by_that_surface(
    make_quads: Callable[..., Scene],
) -> None:
    # A floor and a wall standing on its far edge; nothing lies between the start points
    # (just above the floor) and the end points (on the floor).
    scene = make_quads(
        [[(0, 0, 0), (0, 0, 1), (1, 0, 1), (1, 0, 0)], [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]]
    )
    height, z = np.meshgrid([1e-5, 1e-4, 1e-3, 1e-2], np.linspace(0.05, 0.95, 19))
    starts = np.column_stack([np.full(z.size, 0.02), height.ravel(), np.full(z.size, 0.5)])
    ends = np.column_stack([np.full(z.size, 0.98), np.zeros(z.size), z.ravel()])
    with Occluder(scene.positions, scene.triangles) as occluder:
        blocked = occluder.occluded(starts, ends, end_normals=np.tile([0.0, 1.0, 0.0], (z.size, 1)))
    assert not blocked.any()


# --------------------------------------------------------------------------------------
# No rays where nothing can occlude
# --------------------------------------------------------------------------------------


def test_convex_enclosure_casts_no_rays(prepare_furnace: Callable[..., Prepared]) -> None:
    prepared = prepare_furnace()
    scene = prepared.scene
    assert nothing_can_occlude(scene.positions, scene.triangles, 1e-9)
    assert prepared.occluder is None and prepared.engine.occluder is None
    for patch in range(prepared.mesh.patch_count):
        prepared.engine.column(patch)
    assert prepared.engine.columns_computed == prepared.mesh.patch_count
    assert prepared.engine.rays_cast == 0


def test_shadow_scene_needs_rays(prepare_scene: Callable[..., Prepared]) -> None:
    scene = shadow_scene()
    assert not nothing_can_occlude(scene.positions, scene.triangles, 1e-9)
    prepared = prepare_scene(scene, MeshSettings(receivers=500, patches=20))
    assert prepared.occluder is not None
    prepared.engine.column(0)
    assert prepared.engine.rays_cast > 0


def test_columns_beyond_the_cache_are_spilled_not_retraced(cornell: Prepared) -> None:
    """With a cache too small for any column, every column goes to a spill file once, its
    near-field gather weights with it (the cache bounds both): the solve reads them back
    (no ray after the pass) and gives the cached engine's answer."""
    tiny = FormFactorEngine(cornell.mesh, cornell.occluder, cache_bytes=1)
    try:
        tiny.balance(cornell.closed_receivers)
        assert tiny._spill.bytes > 0 and not tiny._cache
        assert len(tiny._spill) == cornell.mesh.patch_count
        rays = tiny.rays_cast
        near, kept = tiny.near_field(), cornell.engine.near_field()
        assert len(near) == len(kept) > 0
        for (pa, fa, ga), (pb, fb, gb) in zip(near, kept, strict=True):
            assert pa == pb
            np.testing.assert_array_equal(fa, fb)
            np.testing.assert_array_equal(ga.sources, gb.sources)
            np.testing.assert_array_equal(ga.weights, gb.weights)
        settings = SolveSettings(max_shots=200)
        spilled = solve(cornell.mesh, tiny, settings)
        cached = solve(cornell.mesh, cornell.engine, settings)
        assert tiny.rays_cast == rays  # read back, never traced again
        np.testing.assert_array_equal(spilled.radiosity, cached.radiosity)
        folder = tiny._spill.folder
    finally:
        tiny.close()
    assert folder and not os.path.exists(folder)  # the spill files go with the engine


def test_balancing_without_a_cache_holds_the_columns_once(cornell: Prepared) -> None:
    """With no cache (``cache_bytes=0``: nothing kept, nothing spilled), balancing keeps the
    pass's columns for its sweeps instead of tracing them again each round, and balances
    them as the cached engine does."""
    bare = FormFactorEngine(cornell.mesh, cornell.occluder, cache_bytes=0)
    try:
        bare.balance(cornell.closed_receivers)
        assert bare.columns_computed == cornell.mesh.patch_count
        assert not bare._cache and not len(bare._spill)
        np.testing.assert_array_equal(bare._col_scale, cornell.engine._col_scale)
        np.testing.assert_array_equal(bare.row_sums(), cornell.engine.row_sums())
    finally:
        bare.close()


def test_released_columns_are_computed_again_alike(cornell: Prepared) -> None:
    """Once the solve is done a render drops the cache and the spill files
    (``release_columns``); a column asked for later is traced again and equals the one
    released. A pass cut short keeps its columns (its checkpoint needs them)."""
    engine = FormFactorEngine(cornell.mesh, cornell.occluder, cache_bytes=200_000)
    cut = FormFactorEngine(cornell.mesh, cornell.occluder)
    try:
        engine.balance(cornell.closed_receivers)
        assert engine._cache and len(engine._spill)
        before = [engine.column(p) for p in (0, cornell.mesh.patch_count - 1)]
        computed, folder = engine.columns_computed, engine._spill.folder
        engine.release_columns()
        assert not engine._cache and not len(engine._spill) and engine._cached_bytes == 0
        assert folder and not os.path.exists(folder)
        for patch, old in zip((0, cornell.mesh.patch_count - 1), before, strict=True):
            new = engine.column(patch)
            np.testing.assert_array_equal(new.receivers, old.receivers)
            np.testing.assert_array_equal(new.factors, old.factors)
        assert engine.columns_computed == computed + 2
        cut.balance(cornell.closed_receivers, stop=lambda: True)
        assert not cut.complete
        kept = len(cut._cache)
        cut.release_columns()
        assert kept and len(cut._cache) == kept
    finally:
        engine.close()
        cut.close()
