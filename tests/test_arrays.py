"""raytrad.arrays: the sort-based unique and the corner reductions against numpy's own;
Morton order against a bit-by-bit reference."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.arrays import (
    column_max,
    corner_max,
    corner_mean,
    corner_min,
    longest_side,
    morton_order,
    spatially_ordered,
    unique,
    unique_inverse,
)


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


def _morton_code_bitwise(cell: tuple[int, int, int], bits: int) -> int:
    """Reference: interleave bit k of x, y, z into bits 3k+2, 3k+1, 3k, one at a time."""
    code = 0
    for k in range(bits):
        for axis in range(3):
            code |= ((cell[axis] >> k) & 1) << (3 * k + 2 - axis)
    return code


def test_morton_order_of_a_2x2x2_grid_is_the_z_curve() -> None:
    cells = np.array([(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    order = morton_order(cells)
    codes = [_morton_code_bitwise(tuple(int(c) for c in cells[i] * (2**21 - 1)), 21) for i in order]
    assert codes == sorted(codes)
    # x is the most significant axis within a level: (0,0,0), (0,0,1), (0,1,0), ...
    np.testing.assert_array_equal(cells[order][:4], [(0, 0, 0), (0, 0, 1), (0, 1, 0), (0, 1, 1)])


def test_morton_order_matches_bitwise_codes_and_is_a_stable_permutation() -> None:
    rng = np.random.default_rng(5)
    cells = rng.integers(0, 16, (500, 3))  # many ties
    order = morton_order(cells.astype(float) * (2**21 - 1) / 15, bits=21)
    assert sorted(order.tolist()) == list(range(500))
    scaled = np.rint(cells * (2**21 - 1) / 15).astype(int)
    codes = np.array([_morton_code_bitwise(tuple(c), 21) for c in scaled])
    expected = np.argsort(codes, kind="stable")
    np.testing.assert_array_equal(order, expected)


def test_morton_order_ignores_translation_and_units() -> None:
    points = np.random.default_rng(6).uniform(-1, 1, (1000, 3))
    order = morton_order(points)
    np.testing.assert_array_equal(morton_order(points * 1e-3 + 1e3), order)
    assert len(morton_order(np.zeros((0, 3)))) == 0
    np.testing.assert_array_equal(morton_order(np.ones((4, 3))), np.arange(4))


def test_spatially_ordered_keeps_every_triangle() -> None:
    rng = np.random.default_rng(7)
    points = rng.uniform(0, 1, (50, 3))
    triangles = rng.integers(0, 50, (80, 3))
    new_points, new_triangles = spatially_ordered(points, triangles)
    np.testing.assert_array_equal(new_points[new_triangles], points[triangles])
    np.testing.assert_array_equal(new_points, points[morton_order(points)])


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e4])
def test_corner_reductions_are_numpys_to_the_bit(scale: float) -> None:
    """Triangles of random corners, far from the origin and near it, with repeated
    corners (degenerate): the three-row reductions equal numpy's over the corner axis."""
    rng = np.random.default_rng(int(scale * 1000) % 97)
    corners = (rng.random((5000, 3, 3)) - 0.5) * scale + rng.random((5000, 1, 1)) * 100 * scale
    corners[:50, 1] = corners[:50, 0]  # two corners alike: a zero side
    np.testing.assert_array_equal(corner_mean(corners), corners.mean(axis=1))
    np.testing.assert_array_equal(corner_min(corners), corners.min(axis=1))
    np.testing.assert_array_equal(corner_max(corners), corners.max(axis=1))
    reference = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    np.testing.assert_array_equal(longest_side(corners), reference)
    values = corners[:, :, 1]  # (N, 3): a value per corner, as refinement ranks them
    np.testing.assert_array_equal(corner_mean(values), values.mean(axis=1))
    np.testing.assert_array_equal(corner_max(values) - corner_min(values), np.ptp(values, axis=1))
    right = np.array([[[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 4.0, 0.0]]])
    assert longest_side(right)[0] == 5.0


def test_column_max_is_numpys_axis_zero_max() -> None:
    """Each column's largest value, NaN where a column holds one, as ``max(axis=0)``
    gives it, for the error log's (N, 3) arrays and a single row."""
    rng = np.random.default_rng(5)
    values = rng.normal(size=(1000, 3))
    values[17, 1] = np.nan
    values[3, 2] = np.inf
    for case in (values, np.abs(values), values[:1], rng.normal(size=(50, 5))):
        np.testing.assert_array_equal(column_max(case), case.max(axis=0))


@pytest.mark.parametrize("span", [1, 40, 10**4, 10**12])
def test_unique_inverse_is_numpys(span: int) -> None:
    """The sorted distinct keys and each key's index, as ``np.unique(return_inverse=True)``
    gives them, dtypes included: marked in a table for narrow keys (a refined mesh's corner
    keys), sorted by numpy for wide ones."""
    rng = np.random.default_rng(span)
    for count in (0, 1, 7, 5000):
        keys = rng.integers(0, span, (count, 3)).astype(np.int64)
        distinct, inverse = unique_inverse(keys)
        want, want_inverse = np.unique(keys, return_inverse=True)
        np.testing.assert_array_equal(distinct, want)
        np.testing.assert_array_equal(inverse, want_inverse.reshape(-1))
        assert distinct.dtype == want.dtype and inverse.dtype == want_inverse.dtype
