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
