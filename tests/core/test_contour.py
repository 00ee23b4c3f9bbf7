"""A planar patch's unoccluded factor from its outline (raytrad.core.contour), against the
triangle-by-triangle horizon-clipped sum, a brute-force quadrature and the compiled kernels.

The outlines are the ones a per-triangle sum and a naive clip get wrong differently: a
concave L (the horizon line meets the outline four times), a square with a square hole
(two loops, the inner one wound the other way), with receivers whose horizon passes
exactly through a corner, contains a whole edge, or grazes the patch's plane.
"""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core import compiled, contour, kernels
from tests.core.analytic import quadrature_factor

#: Agreement asked of two evaluations of the same factor (rounding only).
AGREE = 1e-12


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _l_shape() -> tuple[np.ndarray, list[np.ndarray]]:
    """Outline loops and triangles of a concave L in z = 0, facing +z."""
    p = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0.0]])
    triangles = p[[[0, 1, 2], [0, 2, 3], [0, 3, 5], [3, 4, 5]]]
    return triangles, [p]


def _square_with_hole() -> tuple[np.ndarray, list[np.ndarray]]:
    """A 3 x 3 square with a 1 x 1 hole in the middle, in z = 0, facing +z."""
    outer = np.array([[0, 0, 0], [3, 0, 0], [3, 3, 0], [0, 3, 0.0]])
    inner = np.array([[1, 1, 0], [1, 2, 0], [2, 2, 0], [2, 1, 0.0]])  # clockwise: a hole
    o, i = outer, inner[[0, 3, 2, 1]]  # inner corners counter-clockwise, to triangulate
    triangles = np.array(
        [
            [o[0], o[1], i[1]],
            [o[0], i[1], i[0]],
            [o[1], o[2], i[2]],
            [o[1], i[2], i[1]],
            [o[2], o[3], i[3]],
            [o[2], i[3], i[2]],
            [o[3], o[0], i[0]],
            [o[3], i[0], i[3]],
        ]
    )
    return triangles, [outer, inner]


def _placed(triangles, loops, rng):
    """The shape turned and moved at random (a rigid motion)."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    shift = rng.normal(size=3) * 10.0
    loops = [loop @ q.T + shift for loop in loops]
    start = np.concatenate(loops)
    end = np.concatenate([np.roll(loop, -1, axis=0) for loop in loops])
    return triangles @ q.T + shift, start, end, q[:, 2]


def _receivers(start, normal, rng, count=3000):
    """Receivers in front of the plane, with straddling and adversarial normals."""
    centre = start.mean(axis=0)
    x = centre + rng.normal(size=(count, 3)) * 2.0
    height = (x - centre) @ normal
    x += (np.abs(height) + 1e-3 - height)[:, None] * normal  # all in front, >= 1 mm
    n = _unit(rng.normal(size=(count, 3)))
    k = count // 6
    # the horizon through an outline corner exactly
    corner = start[rng.integers(0, len(start), k)]
    n[:k] = _unit(np.cross(corner - x[:k], rng.normal(size=(k, 3))))
    # the horizon containing a whole outline edge: normal across the edge's plane
    e = rng.integers(0, len(start), k)
    s = slice(k, 2 * k)
    edge = np.roll(start, -1, axis=0)[e] - start[e]  # a loop's next corner, near enough
    n[s] = _unit(np.cross(start[e] - x[s], edge)) * rng.choice([-1.0, 1.0], (k, 1))
    # grazing: the receiver a hair above the plane, its normal tipped across it
    s = slice(2 * k, 3 * k)
    x[s] -= (((x[s] - centre) @ normal) - 1e-6)[:, None] * normal
    n[s] = _unit(rng.normal(size=(k, 3)) * 0.2 + normal * rng.choice([-1.0, 1.0], (k, 1)))
    return x, n


@pytest.mark.parametrize("shape", [_l_shape, _square_with_hole])
def test_clipped_outline_equals_the_triangle_sum(shape):
    rng = np.random.default_rng(7)
    triangles, start, end, normal = _placed(*shape(), rng)
    x, n = _receivers(start, normal, rng)
    tri_normals = np.tile(normal, (len(triangles), 1))
    want = kernels.numpy_facing_triangle_sums(x, n, triangles, tri_normals, 0.0)
    got = contour.numpy_clipped_contour_form_factor(start, end, x, n)
    np.testing.assert_allclose(got, want, rtol=0, atol=AGREE)
    straddles = ((start - x[:, None, :]) @ n[:, :, None]).squeeze(-1)
    straddles = (straddles.min(axis=1) < 0) & (straddles.max(axis=1) > 0)
    assert straddles.mean() > 0.5 and (want[straddles] > 0).mean() > 0.9


@pytest.mark.parametrize("shape", [_l_shape, _square_with_hole])
def test_clipped_outline_is_the_whole_contour_above_the_horizon(shape):
    rng = np.random.default_rng(8)
    _, start, end, normal = _placed(*shape(), rng)
    x = start.mean(axis=0) + normal * rng.uniform(0.5, 3.0, (500, 1))
    x += rng.normal(size=(500, 3)) * 0.3
    n = np.tile(-normal, (500, 1))  # facing it: the whole patch above every horizon
    np.testing.assert_allclose(
        contour.numpy_clipped_contour_form_factor(start, end, x, n),
        contour.numpy_contour_form_factor(start, end, x, n),
        rtol=0,
        atol=AGREE,
    )


def test_clipped_outline_against_quadrature():
    """A 2 x 2 square 1 m above a receiver whose normal is tipped 60 degrees: the horizon
    cuts the square; the midpoint rule integrates the kernel over the half-space."""
    square = np.array([[-1, -1, 1], [-1, 1, 1], [1, 1, 1], [1, -1, 1.0]])  # facing -z
    point = np.array([0.2, -0.1, 0.0])
    normal = np.array([np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3)])
    got = contour.numpy_clipped_contour_form_factor(
        square, np.roll(square, -1, axis=0), point[None], normal[None]
    )[0]
    want = quadrature_factor(
        square[0], square[3] - square[0], square[1] - square[0], point, normal, n=2000
    )
    assert got == pytest.approx(want, rel=2e-5)
    assert 0.05 < got < 0.5  # clipped, not empty and not the whole square


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
@pytest.mark.parametrize("shape", [_l_shape, _square_with_hole])
def test_compiled_outline_kernels_agree_with_numpy(shape):
    rng = np.random.default_rng(9)
    _, start, end, normal = _placed(*shape(), rng)
    x, n = _receivers(start, normal, rng)
    for fast, reference in (
        (contour.clipped_contour_form_factor, contour.numpy_clipped_contour_form_factor),
        (contour.contour_form_factor, contour.numpy_contour_form_factor),
    ):
        np.testing.assert_allclose(
            fast(start, end, x, n), reference(start, end, x, n), rtol=0, atol=AGREE
        )


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_compiled_contour_agrees_on_an_outline_from_every_side():
    rng = np.random.default_rng(2)
    # an L-shaped planar patch outline (6 boundary edges) and receivers all around it,
    # some in its plane and some on its boundary
    outline = np.array([[0, 0, 0], [2, 0, 0], [2, 0, 1], [1, 0, 1], [1, 0, 2], [0, 0, 2.0]])
    start, end = outline, np.roll(outline, -1, axis=0)
    x = rng.normal(size=(3000, 3))
    x[:300, 1] = 0.0
    x[300:400] = outline[rng.integers(0, 6, 100)]
    n = _unit(rng.normal(size=(3000, 3)))
    got = contour.contour_form_factor(start, end, x, n)
    want = contour.numpy_contour_form_factor(start, end, x, n)
    np.testing.assert_allclose(got, want, rtol=0, atol=AGREE)
