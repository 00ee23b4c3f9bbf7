"""Form-factor kernels against closed forms and brute-force quadrature."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raytrad.core.kernels import _sub_triangles, disk_form_factor, sub_grid
from tests.core.analytic import (
    UP,
    corner_factor,
    polygon_factor,
    quadrature_factor,
    square,
    two_triangles,
)


@pytest.mark.parametrize(("radius", "height"), [(0.7, 0.3), (1.0, 1.0), (0.01, 5.0), (3.0, 0.05)])
def test_disk_factor_is_exact_for_a_coaxial_disk(radius: float, height: float) -> None:
    got = disk_form_factor(1.0, 1.0, height**2, math.pi * radius**2)
    # dA / (pi h^2 + dA) = R^2 / (h^2 + R^2) exactly; only float rounding may differ
    assert got == pytest.approx(radius**2 / (height**2 + radius**2), rel=1e-15, abs=0)


def test_disk_factor_scales_with_both_cosines_elementwise() -> None:
    cos_r = np.array([[1.0, 0.5], [0.25, 0.0]])
    cos_s = np.array([[0.8, 1.0], [0.5, 1.0]])
    got = disk_form_factor(cos_r, cos_s, np.full((2, 2), 2.0), np.full((2, 2), 0.3))
    assert got.shape == (2, 2)
    np.testing.assert_allclose(got, cos_r * cos_s * 0.3 / (2.0 * math.pi + 0.3), rtol=1e-15)


@pytest.mark.parametrize("height", [0.01, 0.25, 1.0, 4.0])
def test_polygon_factor_centred_under_a_square(height: float) -> None:
    quad = two_triangles(square(-0.5, 0.5, -0.5, 0.5, height, up=False))
    expected = 4.0 * corner_factor(0.5, 0.5, height)  # four 0.5 x 0.5 corner rectangles
    assert polygon_factor(quad, np.zeros(3), UP) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(
    ("x", "y", "parts"),
    [
        # inside the projection: four corner rectangles add
        (0.2, 0.3, [(+1, 0.2, 0.3), (+1, 0.8, 0.3), (+1, 0.2, 0.7), (+1, 0.8, 0.7)]),
        # outside it: the rectangle to the far edge minus the one to the near edge
        (-0.3, 0.4, [(+1, 1.3, 0.4), (+1, 1.3, 0.6), (-1, 0.3, 0.4), (-1, 0.3, 0.6)]),
    ],
)
def test_polygon_factor_off_centre_by_superposition(x: float, y: float, parts: list) -> None:
    height = 0.25
    quad = two_triangles(square(0.0, 1.0, 0.0, 1.0, height))
    expected = sum(sign * corner_factor(a, b, height) for sign, a, b in parts)
    got = polygon_factor(quad, np.array([x, y, 0.0]), UP)
    assert got == pytest.approx(expected, rel=1e-12)
    # Lambert's formula does not depend on the winding
    assert polygon_factor(quad[:, ::-1], np.array([x, y, 0.0]), UP) == pytest.approx(
        expected, rel=1e-12
    )


@pytest.mark.parametrize(("height", "tilt_degrees"), [(0.25, 30.0), (0.25, 60.0), (1.0, 45.0)])
def test_polygon_factor_for_a_tilted_receiver_matches_quadrature(
    height: float, tilt_degrees: float
) -> None:
    # At 60 degrees part of the square lies below the receiver's horizon: clipping counts.
    tilt = math.radians(tilt_degrees)
    normal = np.array([math.sin(tilt), 0.0, math.cos(tilt)])
    quad = square(-0.5, 0.5, -0.5, 0.5, height, up=False)
    corner = np.array([-0.5, -0.5, height])
    expected = quadrature_factor(
        corner, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.zeros(3), normal
    )
    assert polygon_factor(two_triangles(quad), np.zeros(3), normal) == pytest.approx(
        expected, rel=1e-5
    )


@pytest.mark.parametrize(
    "corners",
    [
        [(-0.2, -0.5, 0.6), (0.8, 0.1, -0.3), (0.1, 0.7, 0.4)],  # one corner below
        [(-0.2, -0.5, -0.1), (0.8, 0.1, -0.3), (0.1, 0.7, 0.4)],  # two corners below
    ],
)
@pytest.mark.parametrize("normal", [(0.0, 0.0, 1.0), (0.3, -0.2, 0.9)])
def test_polygon_factor_clips_a_triangle_at_the_horizon(corners: list, normal: tuple) -> None:
    tri = np.array(corners, dtype=np.float64)
    n = np.array(normal) / np.linalg.norm(normal)
    expected = quadrature_factor(
        tri[0], tri[1] - tri[0], tri[2] - tri[0], np.zeros(3), n, triangle=True
    )
    assert polygon_factor(tri[None], np.zeros(3), n) == pytest.approx(expected, rel=1e-5)


def test_polygon_factor_is_zero_for_a_polygon_behind_the_receiver() -> None:
    below = two_triangles(square(-0.5, 0.5, -0.5, 0.5, -0.3))
    assert polygon_factor(below, np.zeros(3), UP) == 0.0
    # the same square in front of a receiver that faces the other way is seen
    assert polygon_factor(below, np.zeros(3), -UP) == pytest.approx(
        4.0 * corner_factor(0.5, 0.5, 0.3), rel=1e-12
    )


@pytest.mark.parametrize("levels", [1, 2, 3])
def test_the_sub_grid_shares_corners_and_edges_of_the_midpoint_split(levels: int) -> None:
    corners, centroids = _sub_triangles(levels)
    vertex_bary, tri_vertex, edge_of, edge_sign, edge_ends, grid_centroids = sub_grid(levels)
    side = 2**levels
    # a triangular grid of side s = 2^L: (s+1)(s+2)/2 corners, 3 s(s+1)/2 edges, bitwise the
    # corners each part names
    assert len(vertex_bary) == (side + 1) * (side + 2) // 2
    assert len(edge_ends) == 3 * side * (side + 1) // 2
    np.testing.assert_array_equal(vertex_bary[tri_vertex], corners)
    np.testing.assert_array_equal(grid_centroids, centroids)
    # each part's edge k runs from its corner k to corner k + 1, as its sign says
    start, end = tri_vertex, np.roll(tri_vertex, -1, axis=1)
    forward = edge_sign > 0
    np.testing.assert_array_equal(np.where(forward, start, end), edge_ends[edge_of, 0])
    np.testing.assert_array_equal(np.where(forward, end, start), edge_ends[edge_of, 1])
    # an inner edge is shared by two parts running it both ways; an outer one by one part
    uses = np.bincount(edge_of.reshape(-1), minlength=len(edge_ends))
    assert set(uses) <= {1, 2} and (uses == 1).sum() == 3 * side
    net = np.bincount(edge_of.reshape(-1), weights=edge_sign.reshape(-1))
    np.testing.assert_array_equal(np.abs(net[uses == 2]), 0.0)
