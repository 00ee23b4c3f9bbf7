"""Tests of :mod:`raytrad.core.segment_search`: the points near segments, against every
pair measured one by one."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.parametrize("kernels", ["compiled", "numpy"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_items_near_segments_are_every_item_within_reach(
    seed: int, kernels: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every (item, segment) pair whose point lies within the item's reach of the
    segment, and no other, whatever the spread of reaches (a few long wall edges among
    many short ones): measured pair by pair, by the compiled search (finer cells, hashed)
    and by its numpy reference."""
    from raytrad.core import segment_search

    monkeypatch.setenv("RAYTRAD_KERNELS", kernels)
    monkeypatch.setattr(segment_search, "COMPILED_SEGMENTS", 0)  # 60 segments: compiled too
    rng = np.random.default_rng(seed)
    points = rng.uniform(0.0, 4.0, (3000, 3))
    reach = np.exp(rng.uniform(np.log(1e-3), np.log(0.5), len(points)))
    start = rng.uniform(0.0, 4.0, (60, 3))
    segments = np.stack([start, start + rng.normal(0.0, 0.3, (60, 3))], axis=1)
    segments[:5, 1] = segments[:5, 0]  # points, as the outlines' ends are passed
    p, d = segments[:, 0], segments[:, 1] - segments[:, 0]
    square = np.maximum((d * d).sum(axis=1), 1e-300)
    rel = points[:, None, :] - p[None]  # (N, S, 3)
    t = np.clip((rel * d[None]).sum(axis=2) / square[None], 0.0, 1.0)
    distance = np.linalg.norm(rel - t[..., None] * d[None], axis=2)
    item, segment = np.nonzero(distance <= reach[:, None])
    got_item, got_segment = segment_search.items_near_segments(points, segments, reach)
    np.testing.assert_array_equal(got_item, item)
    np.testing.assert_array_equal(got_segment, segment)
    one_item, one_segment = segment_search.items_near_segments(points, segments, 0.2)
    expected = np.nonzero(distance <= 0.2)
    np.testing.assert_array_equal(one_item, expected[0])
    np.testing.assert_array_equal(one_segment, expected[1])
    far_item, far_segment = segment_search.items_near_segments(points, segments + 100.0, reach)
    assert len(far_item) == 0 and len(far_segment) == 0  # none near: none, not an error


@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_the_compiled_search_finds_the_numpy_pairs_on_adversarial_input(
    offset: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Points on cell boundaries (a lattice of the cell size), repeated points, segments
    of zero length and along the lattice, far from the origin: the compiled search and
    its numpy reference give the same pairs, and both give every pair within reach."""
    from raytrad.core import compiled, segment_search

    if compiled.get() is None:
        pytest.skip("numba is not installed")
    lattice = np.stack(np.meshgrid(*[np.arange(6) * 0.25] * 3, indexing="ij"), -1).reshape(-1, 3)
    points = np.concatenate([lattice, lattice[:20], lattice[::7] + 1e-12]) + offset
    reach = np.full(len(points), 0.25)
    reach[::5] = 0.0625  # two classes of reach
    segments = (
        np.array(
            [
                [[0.0, 0.0, 0.0], [1.25, 0.0, 0.0]],  # along lattice lines
                [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]],  # a point
                [[0.25, 0.25, 0.0], [0.25, 0.25, 1.25]],
                [[0.0, 1.25, 0.0], [1.25, 0.0, 1.25]],  # a diagonal
            ]
        )
        + offset
    )
    monkeypatch.setattr(segment_search, "COMPILED_SEGMENTS", 0)
    found = segment_search.items_near_segments(points, segments, reach)
    monkeypatch.setenv("RAYTRAD_KERNELS", "numpy")
    reference = segment_search.items_near_segments(points, segments, reach)
    np.testing.assert_array_equal(found[0], reference[0])
    np.testing.assert_array_equal(found[1], reference[1])
    # every pair within reach (a hair of slack for the offset's rounding) is there
    p, d = segments[:, 0] - offset, segments[:, 1] - segments[:, 0]
    rel = (points - offset)[:, None, :] - p[None]
    t = np.clip((rel * d[None]).sum(2) / np.maximum((d * d).sum(1), 1e-300)[None], 0, 1)
    distance = np.linalg.norm(rel - t[..., None] * d[None], axis=2)
    inside = set(zip(*np.nonzero(distance <= reach[:, None] * (1 - 1e-9)), strict=True))
    assert inside <= set(zip(found[0].tolist(), found[1].tolist(), strict=True))
    assert len(inside) > 40


@pytest.mark.parametrize("kernels", ["compiled", "numpy"])
def test_zero_reach_of_point_segments_finds_the_points_on_them(
    kernels: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every segment a point and every reach 0 (no length to size the cells by): the
    items at a segment's point are found, the others not, without dividing by zero."""
    from raytrad.core import segment_search

    monkeypatch.setenv("RAYTRAD_KERNELS", kernels)
    monkeypatch.setattr(segment_search, "COMPILED_SEGMENTS", 0)
    points = np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 3.5], [4.0, 5.0, 6.0]])
    segments = np.array([[[1.0, 2.0, 3.0]] * 2, [[4.0, 5.0, 6.0]] * 2])
    item, segment = segment_search.items_near_segments(points, segments, 0.0)
    assert item.tolist() == [0, 2] and segment.tolist() == [0, 1]
