"""Where surfaces pass through each other (raytrad/core/intersections.py).

The truths are geometric and computed by hand or by brute force: the line where a
vertical quad crosses a horizontal one, the pairs of overlapping boxes found by testing
every pair.
"""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core.intersections import box_pairs, intersection_segments


def _two_quads(drop: float, tilt: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 1 m floor quad (surface 0) and a vertical quad over x in [0.2, 0.7] at z = 0.4
    from y = -drop to 0.5 (surface 1), leaning by ``tilt`` in z per metre of height."""
    floor = [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)]
    wall = [(0.2, -drop, 0.4 - tilt * drop), (0.7, -drop, 0.4 - tilt * drop)]
    wall += [(0.7, 0.5, 0.4 + 0.5 * tilt), (0.2, 0.5, 0.4 + 0.5 * tilt)]
    positions = np.array(floor + wall, dtype=np.float64)
    triangles = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]])
    return positions, triangles, np.array([0, 0, 1, 1])


@pytest.mark.parametrize("tilt", [0.0, 0.3])
def test_a_quad_through_a_floor_meets_it_along_one_line(tilt: float) -> None:
    positions, triangles, surface = _two_quads(0.1, tilt)
    out = intersection_segments(positions, triangles, surface, 1e-6)
    # the line y = 0, z = 0.4, x in [0.2, 0.7], cut where the triangles' diagonals cross it:
    # on each side once (labelled with the other side's surface and normal)
    on_floor = out.surface == 1
    assert on_floor.sum() == (~on_floor).sum() >= 1
    for label in (0, 1):
        ends = out.points[out.surface == label].reshape(-1, 3)
        np.testing.assert_allclose(ends[:, 1], 0.0, atol=1e-12)
        np.testing.assert_allclose(ends[:, 2], 0.4, atol=1e-12)
        xs = np.sort(ends[:, 0])
        assert xs[0] == pytest.approx(0.2, abs=1e-12)
        assert xs[-1] == pytest.approx(0.7, abs=1e-12)
        # the pieces tile [0.2, 0.7]: their lengths add up to 0.5
        lengths = np.linalg.norm(
            out.points[out.surface == label, 1] - out.points[out.surface == label, 0], axis=1
        )
        assert lengths.sum() == pytest.approx(0.5, abs=1e-12)
    wall_normal = out.normal[on_floor]  # the wall's: across x and its leaning height
    np.testing.assert_allclose(wall_normal @ [1.0, 0.0, 0.0], 0.0, atol=1e-12)
    np.testing.assert_allclose(wall_normal @ [0.0, 1.0, tilt], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(out.normal[~on_floor][:, 1]), 1.0, atol=1e-12)


@pytest.mark.parametrize("drop", [0.0, 5e-7])
def test_touching_surfaces_do_not_cross(drop: float) -> None:
    # standing on the floor (or sunk less than the band): the outline does that job
    positions, triangles, surface = _two_quads(drop)
    out = intersection_segments(positions, triangles, surface, 1e-6)
    assert len(out.points) == 0


def test_one_surface_and_coplanar_overlaps_give_nothing() -> None:
    positions, triangles, _ = _two_quads(0.1)
    same = intersection_segments(positions, triangles, np.zeros(4, np.int64), 1e-6)
    assert len(same.points) == 0  # a surface crossing itself is not a contact line
    flat = positions.copy()
    flat[4:, 1] = 0.0  # the second quad laid flat on the floor
    flat[4:, 2] = [0.1, 0.1, 0.9, 0.9]
    out = intersection_segments(flat, triangles, np.array([0, 0, 1, 1]), 1e-6)
    assert len(out.points) == 0


def test_box_pairs_are_the_overlapping_pairs() -> None:
    rng = np.random.default_rng(4)
    lo = rng.random((400, 3)) * 10.0
    size = rng.random((400, 3)) ** 4 * 3.0  # mostly small, a few long
    size[:3] = [9.0, 0.0, 9.0]  # a few floor-like slabs
    hi = lo + size
    pairs = [(i, j) for part in box_pairs(lo, hi, 0.01) for i, j in zip(*part, strict=True)]
    got = {(int(i), int(j)) for i, j in pairs}
    assert len(pairs) == len(got)  # each pair once
    a, b = np.triu_indices(len(lo), 1)
    overlap = np.all((lo[a] - 0.01 <= hi[b] + 0.01) & (lo[b] - 0.01 <= hi[a] + 0.01), axis=1)
    want = set(zip(a[overlap].tolist(), b[overlap].tolist(), strict=True))
    assert got == want
    assert len(want) > 100


def test_labelled_box_pairs_are_the_overlapping_pairs_across_labels() -> None:
    rng = np.random.default_rng(6)
    lo = rng.random((300, 3)) * 5.0
    hi = lo + rng.random((300, 3)) ** 3 * 2.0
    label = rng.integers(0, 4, 300)
    got = {
        (int(i), int(j))
        for part in box_pairs(lo, hi, 0.0, label)
        for i, j in zip(*part, strict=True)
    }
    a, b = np.triu_indices(len(lo), 1)
    overlap = np.all((lo[a] <= hi[b]) & (lo[b] <= hi[a]), axis=1) & (label[a] != label[b])
    assert got == set(zip(a[overlap].tolist(), b[overlap].tolist(), strict=True))
    assert len(got) > 100
