"""Tolerances relative to the scene's size, and signs taken with a band scaled to the data."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.constants import scene_diagonal, scene_extent, sign_with_band, tol


def test_scene_size_measures() -> None:
    points = np.array([[1.0, 2.0, 3.0], [4.0, 6.0, 3.0], [2.0, 2.0, 3.0]])
    assert scene_extent(points) == 4.0  # y spans 2..6
    assert scene_diagonal(points) == 5.0  # (3, 4, 0)


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
def test_sizes_scale_with_the_scene(scale: float) -> None:
    points = np.random.default_rng(0).random((20, 3))
    assert scene_extent(points * scale) == pytest.approx(scene_extent(points) * scale)
    assert scene_diagonal(points * scale) == pytest.approx(scene_diagonal(points) * scale)


def test_sign_with_band_calls_noise_zero() -> None:
    values = np.array([-1.0, -1e-17, 0.0, 1e-17, 1.0])
    assert sign_with_band(values, 1e-12).tolist() == [-1, 0, 0, 0, 1]
    assert sign_with_band(values, 0.0).tolist() == [-1, -1, 0, 1, 1]
    assert sign_with_band(-3.0, np.array([1.0, 5.0])).tolist() == [-1, 0]  # broadcasts


def test_tolerances_are_small_and_ordered() -> None:
    # merging must not reach the T-junction test, which must not reach the ray offset
    assert 0 < tol.merge < tol.on_edge <= tol.plane < tol.ray_offset < 1e-3
    assert tol.ray_margin < tol.ray_offset
    assert all(0 < getattr(tol, name) < 1e-3 for name in tol.__dataclass_fields__)
