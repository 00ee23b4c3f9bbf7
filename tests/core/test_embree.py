"""Embree's packet queries (raytrad.core.embree, raytrad.core._compiled_rays) against
embreex's single-ray queries, the independent answer: the same library traces the same
float32 rays one at a time there.
"""

from __future__ import annotations

import multiprocessing

import numpy as np
import pytest

from raytrad.constants import tol
from raytrad.core import embree
from raytrad.core.pipeline import Prepared
from raytrad.core.visibility import Occluder
from raytrad.scene.builtin import cornell_box


def _occluders(positions: np.ndarray, triangles: np.ndarray, monkeypatch: pytest.MonkeyPatch):
    """(packets, embreex) occluders of the same triangles."""
    packets = Occluder(positions, triangles)
    with monkeypatch.context() as patch:
        patch.setenv(embree.RAYS_VARIABLE, "embreex")
        single = Occluder(positions, triangles)
    assert packets.packets and not single.packets
    return packets, single


def _clutter(rng: np.random.Generator, count: int = 300) -> tuple[np.ndarray, np.ndarray]:
    """``count`` random triangles in the unit box, and a floor quad."""
    corners = rng.random((count, 3, 3))
    corners = corners[:, :1] + 0.2 * (corners - corners[:, :1])
    floor = np.array([[[0, 0, 0], [1, 0, 0], [1, 0, 1]], [[0, 0, 0], [1, 0, 1], [0, 0, 1]]])
    corners = np.concatenate([corners, floor.astype(float)])
    return corners.reshape(-1, 3), np.arange(3 * len(corners)).reshape(-1, 3)


def _segments(rng: np.random.Generator, positions: np.ndarray, triangles: np.ndarray):
    """Random segments and adversarial ones: ending on vertices, on edge midpoints, in
    the floor's plane (grazing), of zero length, and reaching exactly a triangle's plane."""
    n = 20_000
    starts = rng.random((n, 3))
    ends = rng.random((n, 3))
    corner = positions[triangles]
    on_vertex = corner[rng.integers(0, len(triangles), n), rng.integers(0, 3, n)]
    pick = rng.integers(0, len(triangles), n)
    on_edge = 0.5 * (corner[pick, 0] + corner[pick, 1])
    grazing = np.stack([rng.random(n), np.zeros(n), rng.random(n)], axis=1)
    centroid = corner.mean(axis=1)[rng.integers(0, len(triangles), n)]
    starts = np.concatenate([starts, starts, starts, grazing, starts, starts])
    ends = np.concatenate([ends, on_vertex, on_edge, grazing[::-1], starts[:n], centroid])
    delta = ends - starts
    length = np.linalg.norm(delta, axis=1)
    direction = delta / np.where(length > 0, length, 1.0)[:, None]
    direction[length == 0] = [0.0, 1.0, 0.0]
    return starts, direction, length


@pytest.mark.parametrize("seed", [0, 1])
def test_packets_find_what_embreex_finds_blocked(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same answer for every segment that stops short of its end by raytrad's margin
    (``tol.ray_margin`` of the diagonal, as every query raytrad makes does). A segment
    reaching exactly onto a surface is a tie at its end, which the packet and single-ray
    arithmetic may break either way (a few in ten thousand here); none elsewhere."""
    rng = np.random.default_rng(seed)
    positions, triangles = _clutter(rng)
    packets, single = _occluders(positions, triangles, monkeypatch)
    starts, direction, length = _segments(rng, positions, triangles)
    o, o_single = packets.to_local(starts), single.to_local(starts)
    np.testing.assert_array_equal(o, o_single)
    short = np.maximum(length - tol.ray_margin * packets.diagonal, 0.0)
    blocked = packets.occluded_local(o, direction, short)
    assert 0.2 < blocked.mean() < 0.8  # both kinds of answer are tested
    np.testing.assert_array_equal(blocked, single.occluded_local(o, direction, short))
    assert packets.rays_cast == single.rays_cast == len(o)
    tie = packets.occluded_local(o, direction, length) != single.occluded_local(
        o, direction, length
    )
    group = np.arange(len(o)) // (len(o) // 6)  # random, vertex, edge, grazing, zero, centroid
    assert not tie[np.isin(group, [0, 3, 4])].any()
    assert tie.mean() < 1e-3


@pytest.mark.parametrize("seed", [0, 1])
def test_packets_find_the_closest_hits_embreex_finds(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(seed)
    positions, triangles = _clutter(rng)
    packets, single = _occluders(positions, triangles, monkeypatch)
    starts, direction, _ = _segments(rng, positions, triangles)
    o = packets.to_local(starts)
    triangle, distance, weights = packets.intersect_barycentric_local(o, direction)
    expected = single.intersect_barycentric_local(o, direction)
    hit = triangle >= 0
    assert 0.2 < hit.mean() < 0.9
    np.testing.assert_array_equal(triangle, expected[0])
    np.testing.assert_array_equal(distance, expected[1])
    np.testing.assert_array_equal(weights[hit], expected[2][hit])
    assert np.isinf(distance[~hit]).all()
    # the weights are the hit point's: its position from them is where the ray ends
    point = np.einsum("nk,nkj->nj", weights[hit], positions[triangles[triangle[hit]]])
    end = starts[hit] + distance[hit, None] * direction[hit]
    assert np.abs(point - end).max() < 2e-4  # float32, grazing hits included


def test_rays_made_in_the_tracing_loop_are_the_written_out_rays(
    cornell: Prepared, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The pass's rays made and traced in one compiled loop give the factors, the hidden
    samples and the ray count of the rays written out and traced as a batch."""
    engine = cornell.engine
    assert engine.occluder is not None and engine.occluder.packets
    rng = np.random.default_rng(3)
    pick = rng.choice(cornell.mesh.receiver_count, 400, replace=False)
    points, normals = cornell.mesh.receiver_position[pick], cornell.mesh.receiver_normal[pick]
    patches = range(0, cornell.mesh.patch_count, 15)
    before = engine.occluder.rays_cast
    fused = [engine.factors_at(points, normals, p) for p in patches]
    fused_rays = engine.occluder.rays_cast - before
    monkeypatch.setattr(Occluder, "packets", property(lambda self: False))
    before = engine.occluder.rays_cast
    written = [engine.factors_at(points, normals, p) for p in patches]
    assert engine.occluder.rays_cast - before == fused_rays > 0
    for a, b in zip(fused, written, strict=True):
        np.testing.assert_array_equal(a, b)
    assert any(0 < (f > 0).mean() < 1 for f in fused)  # some receivers see a patch partly


def test_embreex_answers_when_asked_or_when_no_library_is_found(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    scene = cornell_box()
    monkeypatch.setenv(embree.RAYS_VARIABLE, "embreex")
    assert not Occluder(scene.positions, scene.triangles).packets
    monkeypatch.delenv(embree.RAYS_VARIABLE)
    monkeypatch.setattr(embree, "usable", lambda: False)
    single = Occluder(scene.positions, scene.triangles)
    assert not single.packets
    # from the floor up through the short block, and beside it up to the ceiling
    starts = np.array([[0.185, 0.01, 0.169], [0.5, 0.01, 0.5]])
    blocked = single.occluded_local(
        single.to_local(starts), np.array([[0.0, 1.0, 0.0]] * 2), np.array([0.5, 0.5])
    )
    np.testing.assert_array_equal(blocked, [True, False])


def test_the_library_embreex_ships_is_found() -> None:
    path = embree.library_path()
    assert path is not None and "embree4" in path
    assert embree.usable()


def _blocked_in_child() -> list[bool]:
    """The segments of the fallback test, traced in a process forked from the tests."""
    scene = cornell_box()
    occluder = Occluder(scene.positions, scene.triangles)
    starts = np.array([[0.185, 0.01, 0.169], [0.5, 0.01, 0.5]])
    blocked = occluder.occluded_local(
        occluder.to_local(starts), np.array([[0.0, 1.0, 0.0]] * 2), np.array([0.5, 0.5])
    )
    return [bool(b) and occluder.packets for b in blocked] + [occluder.packets]


def test_a_forked_process_traces_with_its_own_device() -> None:
    """A script that forks after tracing (multiprocessing's default on Linux) gets the
    same answers in the child, which makes its own Embree device, and does not hang."""
    scene = cornell_box()
    Occluder(scene.positions, scene.triangles).occluded_local(
        np.zeros((8, 3)), np.tile([0.0, 1.0, 0.0], (8, 1)), np.ones(8)
    )
    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.apply_async(_blocked_in_child).get(timeout=120) == [True, False, True]
