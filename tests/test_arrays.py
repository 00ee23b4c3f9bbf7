"""raytrad.arrays: the sort-based unique against numpy's own."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.arrays import unique


@pytest.mark.parametrize(
    "values",
    [
        np.zeros(0, dtype=np.int64),
        np.array([7]),
        np.array([[3, 1, 2], [2, 3, 3]], dtype=np.int32),
        np.random.default_rng(1).integers(0, 50, 10_000),
        np.random.default_rng(2).integers(-(2**62), 2**62, 10_000),
        np.random.default_rng(3).normal(size=(100, 3)).round(1),
    ],
)
def test_unique_is_numpys(values: np.ndarray) -> None:
    expected = np.unique(values)
    got = unique(values)
    assert got.dtype == expected.dtype
    np.testing.assert_array_equal(got, expected)


def test_unique_leaves_its_input_alone() -> None:
    values = np.array([3, 1, 3, 2])
    unique(values)
    np.testing.assert_array_equal(values, [3, 1, 3, 2])
