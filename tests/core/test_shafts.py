"""Shaft culling (raytrad.core.shafts): facets from independent geometry, the compiled test
against its numpy reference, and the culled pass against tracing every pair.

The property that matters is conservativeness: a pair called clear must have nothing in
its shaft. It is checked two ways, neither through the culling code: Embree itself finds
no blocked segment among random segments from a clear pair's receiver to its patch, and
the culled pass gives the unculled pass's factors and gather weights.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np
import pytest

from raytrad.core import compiled, pairs, shafts
from raytrad.core.blockers import target_corners
from raytrad.core.facets import KEPT_FACETS, MAX_FACETS, VOLUMES, facets
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.mesh import MeshSettings
from raytrad.core.pipeline import Prepared, prepare
from raytrad.core.shafts import ShaftEnd, shaft_end
from raytrad.core.visibility import Occluder
from raytrad.scene.builtin import blocks_room, shadow_scene

from .occluders import (
    CASES,
    DIAGONAL,
    LIFT,
    PLATE,
    SWEEP,
    ball_room,
    furniture_room,
    join,
    quad_targets,
    quad_triangles,
    trace,
)


def _unpack(packed: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    words = packed.shape[-1] // 2
    bits = np.unpackbits(packed.astype("<u8").view(np.uint8), axis=-1, bitorder="little")
    bits = bits.astype(bool)
    return bits[..., :count], bits[..., 64 * words : 64 * words + count]


def _soup(rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` small random triangles, each in its own plane, in the unit cube."""
    centre = rng.uniform(0.0, 1.0, size=(count, 1, 3))
    corners = centre + 0.08 * rng.normal(size=(count, 3, 3))
    return corners.reshape(-1, 3), np.arange(3 * count).reshape(-1, 3)


def test_side_bits_are_the_signs_of_the_heights() -> None:
    rng = np.random.default_rng(4)
    found = facets(*_soup(rng, 120), diagonal=1.7)  # 2 words of bits, the last part full
    assert found is not None and found.count == 120 and found.words == 2
    points = rng.uniform(0.0, 1.0, size=(500, 3))
    heights = points @ found.normal.T - found.offset
    front, back = _unpack(found.sides(points), found.count)
    np.testing.assert_array_equal(front, heights > found.band)
    np.testing.assert_array_equal(back, heights < -found.band)


def _quad_end(quad: np.ndarray, lift: float = 1e-5) -> ShaftEnd:
    """The shaft end of a planar quad patch (targets lifted ``lift`` along its normal)."""
    normal = np.cross(quad[1] - quad[0], quad[3] - quad[0])
    normal /= np.linalg.norm(normal)
    corners = target_corners(quad, normal, lift)
    center = quad.mean(axis=0)
    reach = float(np.linalg.norm(corners - center, axis=1).max())
    return shaft_end(quad, quad, normal, center, reach, corners, lift)


def _folded_end(points: np.ndarray, lift: float = 1e-5) -> ShaftEnd:
    corners = target_corners(points, None, lift)
    center = points.mean(axis=0)
    reach = float(np.linalg.norm(corners - center, axis=1).max())
    return shaft_end(points, points, None, center, reach, corners, lift)


def _shaft_args(found, origins: np.ndarray, patch_sides: np.ndarray, end: ShaftEnd) -> tuple:
    return (
        origins,
        found.sides(origins),
        patch_sides,
        found.normal,
        found.offset,
        found.center,
        found.radius,
        found.hull,
        found.hull_ptr,
        found.band,
        end.center,
        end.reach,
        end.targets,
        end.outline,
        end.normal,
        np.array([found.flat, end.lift, end.level, end.thick]),
    )


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
@pytest.mark.parametrize("count", [5, 64, 120, 620])
def test_compiled_shaft_test_matches_numpy(count: int) -> None:
    rng = np.random.default_rng(count)
    if count > MAX_FACETS:  # 20 large triangles, and 600 small ones about a point
        positions, triangles = _soup(rng, 20)
        small = rng.normal(0.25, 0.06, size=(count - 20, 1, 3)) + 0.01 * rng.normal(
            size=(count - 20, 3, 3)
        )
        positions = np.concatenate([positions, small.reshape(-1, 3)])
        triangles = np.arange(len(positions)).reshape(-1, 3)
    else:
        positions, triangles = _soup(rng, count)
    found = facets(positions, triangles, diagonal=1.7)
    assert found is not None
    assert (found.normal == 0).all(axis=1).any() == (count > MAX_FACETS)  # volumes
    origins = rng.uniform(-0.2, 1.2, size=(3000, 3))
    origins[:300] = found.center[rng.integers(0, found.count, 300)]  # inside their spheres
    outcomes = set()
    for trial in range(12):
        if trial % 2:  # a folded patch: no outline
            points = rng.uniform(0.0, 1.0, size=(6, 3))
            end, patch_sides = _folded_end(points), found.patch_sides(points, None, 1e-5)
        else:  # a planar quad, small or large
            a, u, v = rng.uniform(0.0, 1.0, 3), *rng.normal(scale=0.05 * (trial + 1), size=(2, 3))
            quad = np.array([a, a + u, a + u + v, a + v])
            end = _quad_end(quad)
            patch_sides = found.patch_sides(quad, end.normal, 1e-5)
        args = _shaft_args(found, origins, patch_sides, end)
        fast = shafts.shaft_clear(*args)
        np.testing.assert_array_equal(fast, shafts.numpy_shaft_clear(*args))
        outcomes |= set(fast.tolist())
    assert outcomes == {False, True}  # both outcomes are exercised


#: A sheet beside the shaft, in a plane between the receivers and the patch: its
#: bounding sphere meets every capsule and the patch's ball reaches into the pyramid
#: through it, but the patch's corners do not (the separating planes' case).
BESIDE = quad_triangles(
    np.array([[0.6, -1.0, 2.0], [3.0, -1.0, 2.0], [3.0, 3.0, 2.0], [0.6, 3.0, 2.0]])
)


@pytest.mark.parametrize("case", [*CASES, "sheet beside the shaft"])
def test_constructed_cases_are_clear_only_where_no_segment_is_blocked(case: str) -> None:
    """The blockers' constructed cases (a receiver peeking past an occluder's edge, a thin
    occluder between parallel plates, one touching the shaft's boundary, one wholly
    inside the shaft) and a sheet beside the shaft: Embree finds no blocked segment from a
    receiver called clear to 256 random targets and the corners of its patch."""
    if case == "sheet beside the shaft":
        geometry, quad, origins = BESIDE, PLATE, SWEEP * [0.5, 1, 1]
    else:  # the receivers farther out, where they look past the occluder
        geometry, quad, origins, _ = CASES[case]
        origins = origins * [3, 1, 1]
    occluder = Occluder(*join(geometry, quad_triangles(quad)))
    found = facets(*geometry, DIAGONAL)
    assert found is not None
    end = _quad_end(quad, LIFT)
    args = _shaft_args(found, origins, found.patch_sides(quad, end.normal, LIFT), end)
    clear = shafts.shaft_clear(*args)
    np.testing.assert_array_equal(clear, shafts.numpy_shaft_clear(*args))
    targets = np.concatenate(
        [quad + LIFT * end.normal, quad_targets(quad, 256, np.random.default_rng(2))]
    )
    for origin, free in zip(origins, clear, strict=True):
        if free:
            assert not trace(occluder, origin, targets).any(), (case, origin)
    if case != "touching the shaft's boundary":
        assert clear.any() and not clear.all()  # both outcomes occur
    if case == "sheet beside the shaft":
        # the patch's ball alone clears none of the middle receivers; its corners do
        ball = _shaft_args(found, origins, found.patch_sides(quad, end.normal, LIFT), end)
        ball = (*ball[:12], np.zeros((0, 3)), np.zeros((0, 3)), *ball[14:])
        middle = np.abs(origins[:, 0]) < 0.2
        assert not shafts.numpy_shaft_clear(*ball)[middle].any()
        assert clear[middle].all()


@pytest.fixture(scope="module", params=[1, 2, "blocks", "ball"])
def room(request: pytest.FixtureRequest) -> Iterator[Prepared]:
    """Rooms of furniture, the bundled room of 36 blocks (187 facets, culled since the
    limit rose past 128), and a room with a ball of 1 280 triangles (its facets in
    volumes); all culled under the limits of single-ray queries, which reach past the
    packets' (:data:`~raytrad.core.facets.PACKET_FACETS`), so that the test reaches
    those rooms."""
    with _single_ray_limits():
        prepared = _room(request.param)
    yield prepared
    prepared.close()


@contextlib.contextmanager
def _single_ray_limits() -> Iterator[None]:
    """The pass culls under the facet limits of single-ray queries meanwhile."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(pairs, "PACKET_FACETS", MAX_FACETS)
        patch.setattr(pairs, "PACKET_KEPT", KEPT_FACETS)
        yield


def _room(kind: int | str) -> Prepared:
    if kind == "blocks":
        prepared = prepare(blocks_room(6), MeshSettings(receivers=1200, patches=160))
        assert prepared.engine._pairs.facets.count > 128
    elif kind == "ball":
        prepared = prepare(ball_room(), MeshSettings(receivers=1500, patches=120))
        assert (prepared.engine._pairs.facets.normal == 0).all(axis=1).sum() == VOLUMES
    else:
        prepared = prepare(furniture_room(int(kind)), MeshSettings(receivers=1500, patches=120))
        assert prepared.engine._pairs.facets is not None
    return prepared


@pytest.mark.skipif(compiled.get() is None, reason="culling runs with compiled kernels only")
def test_clear_pairs_have_no_blocked_segment(room: Prepared) -> None:
    """Embree, not the culling code, checks 64 random segments of every clear pair."""
    with _single_ray_limits():
        engine = FormFactorEngine(room.mesh, room.occluder)
    pairs, mesh = engine._pairs, room.mesh
    assert pairs.facets is not None
    rng = np.random.default_rng(0)
    checked = 0
    for patch in range(0, mesh.patch_count, 3):
        receivers = engine._candidates(patch)
        clear = pairs.facets.clear(
            engine._origins[receivers],
            engine._sides[receivers],
            pairs._patch_sides[patch],
            pairs._ends[patch],
        )
        chosen = receivers[clear][:40]
        triangles = np.flatnonzero(mesh.triangle_patch == patch)
        for r in chosen:
            tri = rng.choice(triangles, 64)
            w = rng.dirichlet(np.ones(3), 64)
            ends = np.einsum("nk,nkj->nj", w, mesh.positions[mesh.triangles[tri]])
            starts = np.repeat(engine._origins[r][None, :], 64, axis=0)
            blocked = room.occluder.occluded(starts, ends, mesh.triangle_normal[tri])
            assert not blocked.any(), (patch, r)
        checked += len(chosen)
    assert checked > 1000


def _columns(engine: FormFactorEngine) -> list:
    return [engine.column(p) for p in range(engine.mesh.patch_count)]


@pytest.mark.skipif(compiled.get() is None, reason="culling runs with compiled kernels only")
@pytest.mark.parametrize("scene", ["room", "shadow"])
def test_culled_pass_equals_tracing_every_pair(scene: str, room: Prepared, prepare_scene) -> None:
    prepared = (
        room if scene == "room" else prepare_scene(shadow_scene(), MeshSettings(receivers=1200))
    )
    with _single_ray_limits():
        culled = FormFactorEngine(prepared.mesh, prepared.occluder)
    every = FormFactorEngine(prepared.mesh, prepared.occluder, cull=False)
    try:
        for a, b in zip(_columns(culled), _columns(every), strict=True):
            np.testing.assert_array_equal(a.receivers, b.receivers)
            np.testing.assert_allclose(a.factors, b.factors, rtol=1e-12, atol=1e-15)
            np.testing.assert_array_equal(a.gather.receivers, b.gather.receivers)
            np.testing.assert_array_equal(a.gather.pointer, b.gather.pointer)
            np.testing.assert_array_equal(a.gather.sources, b.gather.sources)
            np.testing.assert_allclose(a.gather.weights, b.gather.weights, rtol=1e-12, atol=1e-15)
        # the same naive count, and culling leaves far fewer rays
        assert culled.rays_naive == every.rays_naive > 0
        assert culled.rays_cast < 0.7 * every.rays_cast
    finally:
        culled.close()
        every.close()


def test_a_planar_shaft_end_holds_its_targets_and_a_folded_one_needs_them() -> None:
    """A planar patch's default target corners reach two lifts plus its own height
    spread (4e-4 m over 10 m, within ``tol.parallel`` of flat) above and below every
    corner; a folded patch has no outline to build them from."""
    quad = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 4e-4], [0, 10, 4e-4]])
    normal, lift = np.array([0.0, 0.0, 1.0]), 1e-4
    end = shaft_end(quad, quad, normal, quad.mean(axis=0), 8.0, None, lift)
    assert end.thick == pytest.approx(4e-4) and end.level == 0.0
    heights = end.targets @ normal
    assert heights.max() >= (quad @ normal).max() + 2 * lift
    assert heights.min() <= (quad @ normal).min() - 2 * lift
    with pytest.raises(ValueError, match="folded"):
        shaft_end(quad, np.zeros((0, 3)), None, quad.mean(axis=0), 8.0, None, lift)
