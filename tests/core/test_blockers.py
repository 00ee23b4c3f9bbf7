"""Convex blockers (raytrad.core.blockers): which components count, the compiled test
against its numpy reference, and that a pair called blocked is blocked for Embree too:
every random segment from its ray origin to its patch, in the issue's constructed cases
(a receiver peeking past an occluder's edge, a thin occluder between parallel plates, an
occluder touching the shaft's boundary, one wholly inside the shaft) and in rooms of
turned blocks. The form-factor pass with blockers gives the pass without them."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.arrays import morton_order
from raytrad.constants import tol
from raytrad.core import blockers as bl
from raytrad.core import compiled
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.mesh import MeshSettings
from raytrad.core.visibility import Occluder
from raytrad.scene.builder import icosphere
from raytrad.scene.builtin import shadow_scene

from .occluders import (
    CASES,
    DIAGONAL,
    LIFT,
    PATCH,
    box,
    furniture_room,
    join,
    quad_targets,
    quad_triangles,
    trace,
)


def test_closed_and_open_boxes_are_solids() -> None:
    closed = bl.blockers(*box(np.zeros(3), np.ones(3)), DIAGONAL)
    assert closed is not None and closed.count == 1
    assert sorted(closed.kind.tolist()) == [bl.FACE] * 6
    np.testing.assert_allclose(np.abs(closed.offset), 1.0, atol=1e-12)
    # every corner is on or behind every outward plane
    corners = box(np.zeros(3), np.ones(3))[0]
    assert (corners @ closed.normal.T - closed.offset <= 1e-12).all()
    open_box = bl.blockers(*box(np.array([0, 1, 0.0]), np.ones(3), 0.3, bottom=False), DIAGONAL)
    assert open_box is not None and open_box.count == 1
    assert sorted(open_box.kind.tolist()) == [bl.FACE] * 5 + [bl.HOLE]
    hole = open_box.kind == bl.HOLE
    np.testing.assert_allclose(open_box.normal[hole][0], [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(open_box.offset[hole], 0.0, atol=1e-12)
    two = bl.blockers(
        *join(box(np.zeros(3), np.ones(3)), box(np.full(3, 5.0), np.ones(3))), DIAGONAL
    )
    assert two is not None and two.count == 2


def test_convex_components_of_many_planes_are_left_out() -> None:
    """A ball of 80 faces (more than MAX_PLANES) blocks nothing; of 20 faces, and beside
    the large one a box, it does."""
    fine, coarse = icosphere(2), icosphere(0)
    assert len(fine[1]) > bl.MAX_PLANES >= len(coarse[1])
    assert bl.blockers(*fine, DIAGONAL) is None
    assert bl.blockers(*coarse, DIAGONAL).count == 1
    both = bl.blockers(*join(fine, box(np.array([3.0, 0, 0]), np.ones(3))), DIAGONAL)
    assert both.count == 1 and np.allclose(both.center[0], [3.0, 0, 0])


def test_a_box_beside_a_finely_tessellated_ball_is_still_a_blocker() -> None:
    """A ball of 20 480 triangles (once past the scene's cap, which left the box out
    too) leaves the box its blocker, as it is alone."""
    ball = icosphere(5)
    assert len(ball[1]) > 20_000
    solid = box(np.array([3.0, 0, 0]), np.ones(3))
    found = bl.blockers(*join(ball, solid), DIAGONAL)
    alone = bl.blockers(*solid, DIAGONAL)
    assert found is not None and found.count == 1
    np.testing.assert_array_equal(found.normal, alone.normal)
    np.testing.assert_array_equal(found.offset, alone.offset)


def test_non_convex_components_block_nothing() -> None:
    l_walls = join(
        quad_triangles([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
        quad_triangles([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]]),
    )
    # welded into one component: its open rim is not planar
    assert bl.blockers(*l_walls, DIAGONAL) is None
    tube_points, tube_triangles = box(np.zeros(3), np.ones(3), bottom=False)
    keep = ~np.isin(np.arange(len(tube_triangles)), [2, 7])  # no top either: two rims
    assert bl.blockers(tube_points, tube_triangles[keep], DIAGONAL) is None
    l_sheet = np.array([[0, 0, 0], [2, 0, 0], [2, 0, 1], [1, 0, 1], [1, 0, 2], [0, 0, 2.0]])
    assert (
        bl.blockers(l_sheet, np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]), DIAGONAL)
        is None
    )
    square = bl.blockers(*quad_triangles([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]]), DIAGONAL)
    assert square is not None and sorted(square.kind.tolist()) == [bl.SHEET] + [bl.EDGE] * 4


def classify(
    found: bl.Blockers, origins: np.ndarray, quad: np.ndarray, probe: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """(compiled or numpy, numpy) blocked flags of origins against a quad patch."""
    normal = np.cross(quad[1] - quad[0], quad[3] - quad[0])
    corners = bl.target_corners(quad, normal / np.linalg.norm(normal), LIFT)
    center = quad.mean(axis=0)
    reach = float(np.linalg.norm(corners - center, axis=1).max())
    return (
        found.blocked(origins, corners, center, reach, probe),
        bl.numpy_blocked(origins, corners, center, reach, found, probe),
    )


@pytest.mark.parametrize("case", list(CASES))
def test_constructed_cases_are_blocked_only_where_embree_blocks_every_segment(case: str) -> None:
    geometry, quad, origins, some = CASES[case]
    occluder = Occluder(*join(geometry, quad_triangles(quad)))
    found = bl.blockers(*geometry, DIAGONAL)
    assert found is not None
    fast, reference = classify(found, origins, quad)
    np.testing.assert_array_equal(fast, reference)
    rng = np.random.default_rng(1)
    corners = np.concatenate([quad + LIFT * 0, quad_targets(quad, 256, rng)])
    partly = []
    for origin, hidden in zip(origins, fast, strict=True):
        blocked = trace(occluder, origin, corners)
        if hidden:
            assert blocked.all(), (case, origin)
        partly.append(not blocked.all())
    if some:  # the test can fail: both kinds occur
        assert fast.any() and not fast.all()
    else:
        assert not fast.any()
    if some is False:
        assert all(partly)


def random_blockers(rng: np.random.Generator) -> bl.Blockers:
    parts = [
        box(rng.uniform(-2, 2, 3), rng.uniform(0.2, 1.0, 3), rng.uniform(0, np.pi), bottom=bool(b))
        for b in (0, 1)
    ]
    corner = rng.uniform(-2, 2, 3)
    u, v = rng.normal(size=(2, 3))
    parts.append(quad_triangles(np.array([corner, corner + u, corner + u + v, corner + v])))
    found = bl.blockers(*join(*parts), DIAGONAL)
    assert found is not None
    return found


@pytest.mark.skipif(compiled.get() is None, reason="needs the compiled kernels")
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("ordered", [False, True])
@pytest.mark.parametrize("probe", [False, True])
def test_compiled_test_matches_numpy(seed: int, ordered: bool, probe: bool) -> None:
    """Scattered origins, and origins in Morton order as the pass hands them: groups of
    nearby origins, whose shared candidate blockers must leave out none that hides;
    probed, the groups whose ends are seen are left untested."""
    rng = np.random.default_rng(seed)
    found = random_blockers(rng)
    hits = 0
    for _ in range(20):
        quad = PATCH + rng.uniform(-1, 1, 3) + [0, 0, rng.uniform(0, 4)]
        origins = rng.uniform(-5, 5, (400, 3)) - [0, 0, 4]
        if ordered:
            origins = origins[morton_order(origins)]
        fast, reference = classify(found, origins, quad, probe)
        np.testing.assert_array_equal(fast, reference)
        hits += int(fast.sum())
    assert hits > 0


def test_probing_skips_the_groups_whose_ends_are_seen() -> None:
    """A group of PROBE_GROUP origins keeps what the full test found when its first or
    last origin is hidden, and loses it when neither is; a group of two or fewer is never
    skipped."""
    assert bl.PROBE_GROUP == 16
    from raytrad.core._compiled_shafts import BLOCKER_GROUP

    assert BLOCKER_GROUP == bl.PROBE_GROUP  # the kernel's groups are the reference's
    hidden = np.zeros(16 * 4 + 2, dtype=bool)
    hidden[3:9] = True  # group 0: ends seen, middle hidden -> skipped
    hidden[16:20] = True  # group 1: first hidden -> kept
    hidden[40:48] = True  # group 2: last hidden -> kept
    hidden[50] = True  # group 3: ends seen -> skipped
    hidden[65] = True  # group 4: two origins -> tested whole
    out = bl.probed(hidden)
    expected = hidden.copy()
    expected[3:9] = False
    expected[50] = False
    np.testing.assert_array_equal(out, expected)
    assert not (out & ~hidden).any()  # never hides what the full test sees


@pytest.mark.skipif(compiled.get() is None, reason="needs the compiled kernels")
def test_grouped_origins_among_many_blockers_match_numpy() -> None:
    """40 small boxes between a patch and a cloud of origins in Morton order: most boxes
    are far from a group's shaft, and the groups' candidate lists must keep every box
    that hides a patch from one of their origins."""
    rng = np.random.default_rng(7)
    parts = [
        box(rng.uniform(-3, 3, 3) * [1, 1, 0.3] + [0, 0, 1.5], rng.uniform(0.2, 0.6, 3), 0.0)
        for _ in range(40)
    ]
    found = bl.blockers(*join(*parts), DIAGONAL)
    assert found is not None and found.count == 40
    origins = rng.uniform(-4, 4, (3000, 3)) * [1, 1, 0.2]
    origins = origins[morton_order(origins)]
    hits = probed_hits = 0
    for _ in range(6):
        quad = PATCH * 0.3 + rng.uniform(-2, 2, 3) * [1, 1, 0] + [0, 0, 3.5]
        fast, reference = classify(found, origins, quad)
        np.testing.assert_array_equal(fast, reference)
        hits += int(fast.sum())
        fast, reference = classify(found, origins, quad, probe=True)
        np.testing.assert_array_equal(fast, reference)
        probed_hits += int(fast.sum())
    assert 0.05 < hits / (6 * len(origins)) < 0.95  # both kinds occur
    assert 0.5 * hits < probed_hits < hits  # probing misses a few, at groups' edges


@pytest.fixture(scope="module", params=[1, 2])
def room(request: pytest.FixtureRequest):
    from raytrad.core.pipeline import prepare

    prepared = prepare(furniture_room(request.param), MeshSettings(receivers=1500, patches=120))
    yield prepared
    prepared.close()


@pytest.mark.skipif(compiled.get() is None, reason="blockers run with compiled kernels only")
def test_blocked_pairs_have_every_segment_blocked(room) -> None:
    """Embree, not the blocker code, checks 64 random segments of every blocked pair."""
    engine = FormFactorEngine(room.mesh, room.occluder)
    pairs, mesh = engine._pairs, room.mesh
    assert pairs.blockers is not None and pairs.blockers.count >= 2
    rng = np.random.default_rng(0)
    lift = tol.ray_offset * engine.diagonal
    checked = 0
    for patch in range(0, mesh.patch_count, 2):
        receivers = engine._candidates(patch)
        origins = engine._origins[receivers]
        hidden = pairs.blockers.blocked(
            origins,
            pairs._corners[pairs._corner_ptr[patch] : pairs._corner_ptr[patch + 1]],
            mesh.patch_center[patch],
            float(pairs._corner_reach[patch]),
        )
        triangles = np.flatnonzero(mesh.triangle_patch == patch)
        for o in origins[hidden][:30]:
            tri = rng.choice(triangles, 64)
            w = rng.dirichlet(np.ones(3), 64)
            ends = np.einsum("nk,nkj->nj", w, mesh.positions[mesh.triangles[tri]])
            ends += lift * mesh.triangle_normal[tri]
            d = ends - o
            length = np.linalg.norm(d, axis=1)
            starts = np.repeat((o - room.occluder.origin)[None, :], len(d), axis=0)
            blocked = room.occluder.occluded_local(starts, d / length[:, None], length - 0.5 * lift)
            assert blocked.all(), (patch, o)
            checked += 1
    assert checked > 300
    engine.close()


@pytest.mark.skipif(compiled.get() is None, reason="blockers run with compiled kernels only")
def test_pass_with_blockers_equals_pass_without(prepare_scene) -> None:
    prepared = prepare_scene(shadow_scene(), MeshSettings(receivers=1200))
    with_blockers = FormFactorEngine(prepared.mesh, prepared.occluder)
    without = FormFactorEngine(prepared.mesh, prepared.occluder)
    assert with_blockers._pairs.blockers is not None
    without._pairs.blockers = None
    try:
        for patch in range(prepared.mesh.patch_count):
            a, b = with_blockers.column(patch), without.column(patch)
            np.testing.assert_array_equal(a.receivers, b.receivers)
            np.testing.assert_array_equal(a.factors, b.factors)
            np.testing.assert_array_equal(a.gather.receivers, b.gather.receivers)
            np.testing.assert_array_equal(a.gather.weights, b.gather.weights)
        assert with_blockers.rays_naive == without.rays_naive > 0
        assert with_blockers.rays_cast < 0.5 * without.rays_cast  # a block on a floor
    finally:
        with_blockers.close()
        without.close()


@pytest.mark.parametrize(
    ("edge", "blocked"), [(0.25 + 1e-3, True), (0.25, False), (0.25 - 1e-3, False)]
)
def test_a_sheet_blocks_once_its_edge_passes_the_shaft_by_the_margin(
    edge: float, blocked: bool
) -> None:
    sheet = quad_triangles(np.array([[-2, -2, 2], [edge, -2, 2], [edge, 4, 2], [-2, 4, 2.0]]))
    quad = np.array([[-0.5, 0, 4], [-0.5, 2, 4], [0.5, 2, 4], [0.5, 0, 4.0]])
    found = bl.blockers(*sheet, DIAGONAL)
    assert found is not None
    fast, reference = classify(found, np.array([[0.0, 1.0, 0.0]]), quad)
    assert fast[0] == reference[0] == blocked


def test_a_sliver_that_welds_away_leaves_the_box_a_blocker() -> None:
    points, triangles = box(np.zeros(3), np.ones(3))
    corner = points[0]
    sliver = corner + np.array([[0, 0, 0], [1e-12, 1e-12, 1e-12], [0, 2e-12, 0]])
    found = bl.blockers(
        np.concatenate([points, sliver]),
        np.concatenate([triangles, [[8, 9, 10]]]),
        DIAGONAL,
    )
    assert found is not None and found.count == 1
    assert np.isfinite(found.normal).all()


def test_target_corners_hold_a_patch_planar_by_its_normals_alone() -> None:
    """A patch counts as planar when its normals agree within ``tol.parallel`` (about
    4.5e-5 rad), so its corners may spread in height by more than a ray's lift over a
    patch of the scene's size: the target prism reaches over that spread too."""
    normal = np.array([0.0, 0.0, 1.0])
    quad = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 4e-4], [0, 10, 4e-4]])  # 4e-5 rad
    corners = bl.target_corners(quad, normal, LIFT)
    targets = quad + LIFT * normal  # the highest targets, and the lowest ray ends below
    heights = corners @ normal
    assert heights.max() >= (targets @ normal).max() + LIFT
    assert heights.min() <= (quad @ normal).min() - LIFT
    assert 4e-4 > 2 * LIFT  # the spread is larger than the lift margin alone


def _inside_hull(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Whether each point lies in the convex hull of ``corners``, by the hull's facet
    planes (scipy's Qhull, independent of the corners' choice) to rounding."""
    from scipy.spatial import ConvexHull

    planes = ConvexHull(corners).equations  # (F, 4): n . p + d <= 0 inside
    size = np.abs(points).max() + 1.0
    return (points @ planes[:, :3].T + planes[:, 3] <= 1e-12 * size).all(axis=1)


@pytest.mark.parametrize("seed", range(3))
def test_hull_corners_are_points_whose_hull_holds_every_point(seed: int) -> None:
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(400, 3)) * [3.0, 1.0, 0.2] + rng.uniform(-1e3, 1e3, 3)
    corners = bl.hull_corners(points, 1e-9)
    assert 8 < len(corners) < len(points)
    # each corner is one of the points, in their order
    index = [int(np.flatnonzero((points == c).all(axis=1))[0]) for c in corners]
    assert index == sorted(index)
    assert _inside_hull(points, corners).all()


def test_hull_corners_keep_every_point_where_there_is_no_hull() -> None:
    flat = np.c_[np.random.default_rng(0).uniform(size=(30, 2)), np.zeros(30)]
    np.testing.assert_array_equal(bl.hull_corners(flat, 1e-9), flat)
    few = np.eye(3)
    np.testing.assert_array_equal(bl.hull_corners(few, 1e-9), few)


@pytest.mark.parametrize("lift", [1e-5, 1e-7, 1e-9])
def test_target_corners_of_a_thin_patch_far_out_hold_every_target(lift: float) -> None:
    """A nearly flat folded patch a million metres out: Qhull merges nearly coplanar
    facets to its rounding, which left points 3e-7 m outside the hull of its corners
    (lift 1e-7) before the points were centred; every target must lie within a tenth of
    the lift of the corners' hull, else every point is kept."""
    rng = np.random.default_rng(0)
    vertices = np.c_[rng.uniform(0, 1, (300, 2)), 1e-6 * rng.uniform(size=300)] + 1e6
    corners = bl.target_corners(vertices, None, lift)
    cube = 2.0 * lift * np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    targets = (vertices[:, None, :] + cube[None]).reshape(-1, 3)
    from scipy.spatial import ConvexHull

    centre = corners.mean(axis=0)
    planes = ConvexHull(corners - centre).equations
    outside = (targets - centre) @ planes[:, :3].T + planes[:, 3]
    assert outside.max() <= 0.1 * lift


def test_target_corners_of_a_folded_patch_hold_every_ray_target() -> None:
    """A cap of a fine ball (a folded patch): its corners are far fewer than its
    vertices' lifted copies, and every ray target (a vertex moved up to ``2 lift`` along
    any axis) lies in their hull."""
    positions, triangles = icosphere(4)
    cap = np.unique(triangles[(positions[triangles].mean(axis=1)[:, 2] > 0.8)])
    vertices = positions[cap]
    corners = bl.target_corners(vertices, None, LIFT)
    assert len(corners) < 8 * len(vertices) / 2
    rng = np.random.default_rng(1)
    targets = vertices[rng.integers(0, len(vertices), 2000)] + rng.uniform(
        -2 * LIFT, 2 * LIFT, (2000, 3)
    )
    assert _inside_hull(np.vstack([vertices, targets]), corners).all()
