"""The trimesh adapter's decisions taken on computed signs: a mirror is a mirror at any
scale, and a flattening transform (whose determinant's sign is rounding noise) is not."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raytrad.scenefiles.trimesh_adapter import is_mirror


def _rotation(degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
def test_rotations_are_not_mirrors_and_reflections_are(scale: float) -> None:
    rotation = scale * _rotation(37.0)
    assert not is_mirror(rotation)
    assert is_mirror(rotation @ np.diag([1.0, -1.0, 1.0]))
    assert is_mirror(-rotation)


def test_a_flattening_transform_is_no_mirror_whatever_its_rounding() -> None:
    a = np.array([0.31, 0.77, 0.13]) * 1e8
    flat = np.column_stack([a, a / 3.0, [0.2, 0.5, 0.9]])
    assert np.linalg.det(flat) < 0.0  # rounding noise of a rank-2 matrix
    assert not is_mirror(flat)
