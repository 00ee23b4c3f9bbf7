"""Scene repair: T-junctions split, duplicate faces dropped, inside-out faces flipped, with
lightmap UVs and object indices following every change (each corner keeps the UV of its
position, checked against affine UV maps and recorded corner UVs)."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core.repair import repair_scene
from raytrad.scene import triangle_areas_normals
from raytrad.scene.builtin import furnace_box
from tests.conftest import triangle_soup, uv_at_corner


def _affine(matrix: np.ndarray, offset: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(..., 2) UVs ``matrix @ position + offset`` of (..., 3) positions."""
    return np.asarray(corners) @ np.asarray(matrix).T + np.asarray(offset)


# --------------------------------------------------------------------------- T-junctions

# In the plane z = 0, facing +z: a big triangle over the x axis from 0 to 2, and below it
# two small ones meeting at (0.7, 0, 0), a vertex inside the big triangle's bottom edge.
BIG = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
SMALL = np.array(
    [
        [[0.0, 0.0, 0.0], [0.7, -1.0, 0.0], [0.7, 0.0, 0.0]],
        [[0.7, 0.0, 0.0], [0.7, -1.0, 0.0], [2.0, 0.0, 0.0]],
    ]
)
# A different affine UV map per original triangle (a UV seam along the split edge).
MAPS = [
    (np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), np.array([0.0, 0.0])),  # u = x, v = y
    (np.array([[0.2, -0.1, 0.0], [0.05, 0.25, 0.0]]), np.array([0.3, 0.5])),
    (np.array([[-0.3, 0.15, 0.0], [0.1, -0.4, 0.0]]), np.array([0.9, 0.1])),
]


@pytest.mark.parametrize("roll", [0, 1, 2])
def test_t_junction_split_interpolates_uvs_linearly(roll: int) -> None:
    # ``roll`` moves the split edge to corners (k, k + 1) for every k.
    corners = np.stack([np.roll(BIG, roll, axis=0), SMALL[0], SMALL[1]])
    uv = np.stack([_affine(*MAPS[i], corners[i]) for i in range(3)])
    scene = triangle_soup(corners, uv)
    repaired = repair_scene(scene)
    assert repaired.triangle_count == 4
    # The big triangle (object t0) is now two halves meeting at (0.7, 0, 0).
    assert np.bincount(repaired.object_index).tolist() == [2, 1, 1]
    halves = repaired.triangle_vertices()[repaired.object_index == 0]
    assert (np.abs(halves - [0.7, 0.0, 0.0]).max(axis=2) < 1e-12).any(axis=1).all()
    areas, normals = triangle_areas_normals(repaired.triangle_vertices())
    np.testing.assert_allclose(areas[repaired.object_index == 0].sum(), 1.0, rtol=1e-12)
    np.testing.assert_allclose(normals, [[0.0, 0.0, 1.0]] * 4, atol=1e-12)
    # Every corner's UV is its own triangle's affine map of its position.
    assert repaired.lightmap_uv is not None
    after = repaired.triangle_vertices()
    expected = np.stack(
        [_affine(*MAPS[o], c) for o, c in zip(repaired.object_index, after, strict=True)]
    )
    np.testing.assert_allclose(repaired.lightmap_uv, expected, rtol=0, atol=1e-12)


def test_t_junction_split_with_nan_uvs_stays_nan_and_others_stay_exact() -> None:
    corners = np.stack([BIG, SMALL[0], SMALL[1]])
    uv = np.stack([np.full((3, 2), np.nan), *(_affine(*MAPS[i], corners[i]) for i in (1, 2))])
    repaired = repair_scene(triangle_soup(corners, uv))
    assert repaired.lightmap_uv is not None
    big = repaired.object_index == 0
    assert big.sum() == 2
    assert np.isnan(repaired.lightmap_uv[big]).all()
    for o in (1, 2):
        mine = repaired.object_index == o
        np.testing.assert_array_equal(
            repaired.lightmap_uv[mine], _affine(*MAPS[o], repaired.triangle_vertices()[mine])
        )


def test_t_junction_split_without_uvs_keeps_none() -> None:
    repaired = repair_scene(triangle_soup(np.stack([BIG, SMALL[0], SMALL[1]]), None))
    assert repaired.triangle_count == 4
    assert repaired.lightmap_uv is None


# --------------------------------------------------------------------------- inverted faces


@pytest.mark.parametrize("bad", [0, 5, 11])
def test_flipped_inside_out_face_keeps_uvs_on_their_corners(bad: int) -> None:
    box = furnace_box()
    good = box.triangle_vertices()
    rng = np.random.default_rng(bad)
    uv = rng.uniform(0.0, 1.0, size=(box.triangle_count, 3, 2))
    corners, flipped_uv = good.copy(), uv.copy()
    corners[bad] = corners[bad][::-1]  # inside out, each UV still on its corner
    flipped_uv[bad] = flipped_uv[bad][::-1]
    scene = triangle_soup(corners, flipped_uv, np.zeros(box.triangle_count, dtype=int), ["box"])
    repaired = repair_scene(scene)
    assert repaired.triangle_count == box.triangle_count
    # The winding is the good one again ...
    _, normals = triangle_areas_normals(repaired.triangle_vertices())
    _, good_normals = triangle_areas_normals(good)
    np.testing.assert_allclose(normals, good_normals, atol=1e-12)
    # ... and each corner carries the UV recorded for its position in that triangle.
    assert repaired.lightmap_uv is not None
    after = repaired.triangle_vertices()
    for t in range(box.triangle_count):
        for c in range(3):
            np.testing.assert_array_equal(
                repaired.lightmap_uv[t, c], uv_at_corner(good[t], uv[t], after[t, c])
            )
    np.testing.assert_array_equal(repaired.lightmap_uv[bad], uv[bad])


# --------------------------------------------------------------------------- duplicates


def test_duplicate_removal_keeps_the_uv_rows_of_kept_faces() -> None:
    quad = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    apart = np.array([[5.0, 0.0, 0.0], [6.0, 0.0, 0.0], [5.0, 1.0, 0.0]])
    corners = np.stack(
        [
            apart,  # 0: kept
            quad[[0, 1, 2]],  # 1: kept
            quad[[0, 2, 3]],  # 2: kept
            quad[[1, 2, 0]],  # 3: triangle 1 again (same winding, rotated): dropped
            quad[[0, 1, 3]],  # 4, 5: the quad split along the other diagonal: dropped
            quad[[1, 2, 3]],
        ]
    )
    uv = np.random.default_rng(3).uniform(size=(6, 3, 2))
    scene = triangle_soup(corners, uv)
    repaired = repair_scene(scene)
    assert repaired.triangle_count == 3
    assert repaired.object_names[repaired.object_index[0]] == "t0"
    assert [repaired.object_names[i] for i in repaired.object_index] == ["t0", "t1", "t2"]
    assert repaired.lightmap_uv is not None
    np.testing.assert_array_equal(repaired.lightmap_uv, uv[:3])
    np.testing.assert_array_equal(repaired.triangle_vertices(), corners[:3])


def test_back_to_back_copy_is_not_a_duplicate_and_keeps_its_uvs() -> None:
    triangle = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    corners = np.stack([triangle, triangle[::-1]])
    uv = np.random.default_rng(4).uniform(size=(2, 3, 2))
    repaired = repair_scene(triangle_soup(corners, uv))
    assert repaired.triangle_count == 2
    assert repaired.lightmap_uv is not None
    np.testing.assert_array_equal(repaired.lightmap_uv, uv)
