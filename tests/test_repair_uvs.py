"""Lightmap UVs and object indices through scene repair, selection, flipping and validation:
every corner keeps the UV of its position, checked against affine UV maps and recorded
corner UVs."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest

from raytrad.errors import SceneError
from raytrad.repair import repair_scene
from raytrad.scene import Scene, make_scene, triangle_areas_normals
from raytrad.scenes import furnace_box


def _soup(
    corners: np.ndarray,
    uv: np.ndarray | None,
    object_index: Sequence[int] | None = None,
    object_names: Sequence[str] | None = None,
) -> Scene:
    """A scene of triangles with their own three vertices each, one grey material.

    Parameters
    ----------
    corners : (T, 3, 3) float
        Corner positions [m], counter-clockwise from the front side.
    uv : (T, 3, 2) float or None
        Corner lightmap UVs.
    object_index : (T,) int or None
        Object of each triangle; default one object per triangle, named ``t<i>``.
    """
    corners = np.asarray(corners, dtype=np.float64)
    count = len(corners)
    if object_index is None:
        object_index = range(count)
        object_names = [f"t{i}" for i in range(count)]
    return make_scene(
        positions=corners.reshape(-1, 3),
        triangles=np.arange(3 * count).reshape(-1, 3),
        material_index=np.zeros(count, dtype=np.int64),
        material_names=["grey"],
        material_reflectance=[[0.5, 0.5, 0.5]],
        material_emitted_exitance=[[0.0, 0.0, 0.0]],
        object_index=np.asarray(object_index),
        object_names=object_names,
        lightmap_uv=uv,
    )


def _affine(matrix: np.ndarray, offset: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(..., 2) UVs ``matrix @ position + offset`` of (..., 3) positions."""
    return np.asarray(corners) @ np.asarray(matrix).T + np.asarray(offset)


def _uv_of(corners: np.ndarray, uv: np.ndarray, point: np.ndarray) -> np.ndarray:
    """The UV recorded for ``point`` among one triangle's (3, 3) corners and (3, 2) UVs."""
    at = np.nonzero(np.abs(corners - point).max(axis=1) < 1e-12)[0]
    assert len(at) == 1
    return uv[at[0]]


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
    scene = _soup(corners, uv)
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
    repaired = repair_scene(_soup(corners, uv))
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
    repaired = repair_scene(_soup(np.stack([BIG, SMALL[0], SMALL[1]]), None))
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
    scene = _soup(corners, flipped_uv, np.zeros(box.triangle_count, dtype=int), ["box"])
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
                repaired.lightmap_uv[t, c], _uv_of(good[t], uv[t], after[t, c])
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
    scene = _soup(corners, uv)
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
    repaired = repair_scene(_soup(corners, uv))
    assert repaired.triangle_count == 2
    assert repaired.lightmap_uv is not None
    np.testing.assert_array_equal(repaired.lightmap_uv, uv)


# --------------------------------------------------------------------------- Scene methods

FAN = np.array(
    [
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],
        [[0.0, 0.0, 2.0], [1.0, 0.0, 2.0], [0.0, 1.0, 2.0]],
        [[0.0, 0.0, 3.0], [1.0, 0.0, 3.0], [0.0, 1.0, 3.0]],
    ]
)
FAN_UV = np.arange(4 * 3 * 2, dtype=np.float64).reshape(4, 3, 2) / 24.0


def _fan() -> Scene:
    return _soup(FAN, FAN_UV, [2, 0, 1, 2], ["a", "b", "c"])


@pytest.mark.parametrize(
    "rows", [np.array([3, 0, 2]), np.array([True, False, True, True]), np.array([1])]
)
def test_select_keeps_objects_and_uvs_aligned(rows: np.ndarray) -> None:
    scene = _fan()
    picked = np.arange(4)[rows]
    selected = scene.select(rows)
    assert selected.object_names == ("a", "b", "c")
    np.testing.assert_array_equal(selected.object_index, np.array([2, 0, 1, 2])[picked])
    assert selected.lightmap_uv is not None
    np.testing.assert_array_equal(selected.lightmap_uv, FAN_UV[picked])
    np.testing.assert_array_equal(selected.triangle_vertices(), FAN[picked])


def test_select_without_uvs_keeps_none() -> None:
    scene = _soup(FAN, None)
    assert scene.select(np.array([0, 2])).lightmap_uv is None
    assert scene.flipped(np.array([True, False, False, True])).lightmap_uv is None


def test_flipped_reverses_uv_corners_with_the_triangle() -> None:
    scene = _fan()
    flip = np.array([False, True, False, True])
    flipped = scene.flipped(flip)
    np.testing.assert_array_equal(flipped.object_index, scene.object_index)
    _, before = triangle_areas_normals(scene.triangle_vertices())
    _, after = triangle_areas_normals(flipped.triangle_vertices())
    np.testing.assert_allclose(after, np.where(flip[:, None], -before, before), atol=1e-15)
    assert flipped.lightmap_uv is not None
    corners = flipped.triangle_vertices()
    for t in range(4):
        for c in range(3):
            np.testing.assert_array_equal(
                flipped.lightmap_uv[t, c], _uv_of(FAN[t], FAN_UV[t], corners[t, c])
            )
    # The original scene is not modified.
    np.testing.assert_array_equal(scene.lightmap_uv, FAN_UV)
    np.testing.assert_array_equal(scene.triangle_vertices(), FAN)


# --------------------------------------------------------------------------- make_scene


def test_make_scene_keeps_uvs_as_float64_per_corner() -> None:
    scene = _soup(FAN, FAN_UV.astype(np.float32))
    assert scene.lightmap_uv is not None
    assert scene.lightmap_uv.dtype == np.float64
    np.testing.assert_array_equal(scene.lightmap_uv, FAN_UV.astype(np.float32))


def test_make_scene_drops_degenerate_faces_with_their_uv_rows() -> None:
    corners = FAN.copy()
    corners[1] = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [2.0, 0.0, 1.0]]  # collinear
    scene = _soup(corners, FAN_UV, [0, 1, 2, 0], ["a", "b", "c"])
    assert scene.triangle_count == 3
    np.testing.assert_array_equal(scene.object_index, [0, 2, 0])
    np.testing.assert_array_equal(scene.lightmap_uv, FAN_UV[[0, 2, 3]])


def test_make_scene_allows_nan_uvs() -> None:
    uv = FAN_UV.copy()
    uv[2] = np.nan
    scene = _soup(FAN, uv)
    assert scene.lightmap_uv is not None
    assert np.isnan(scene.lightmap_uv[2]).all()


@pytest.mark.parametrize(
    ("uv", "message"),
    [
        (np.zeros((5, 3, 2)), "lightmap UVs"),  # one row too many
        (np.zeros((3, 3, 2)), "lightmap UVs"),  # one row too few
        (np.zeros((4, 3, 3)), "lightmap UVs"),  # three numbers per corner
        (np.zeros((4, 3)), "lightmap UVs"),  # one number per corner
        (np.zeros((4, 5)), "lightmap UVs"),  # not whole corners
        (np.zeros((4, 6)), "lightmap UVs"),  # the right count, not per corner
        (np.full((4, 3, 2), np.inf), "infinite"),
    ],
)
def test_make_scene_rejects_bad_uvs(uv: np.ndarray, message: str) -> None:
    with pytest.raises(SceneError, match=message):
        _soup(FAN, uv)


@pytest.mark.parametrize(
    ("object_index", "names", "message"),
    [
        ([0, 1, 3, 0], ["a", "b", "c"], "object that does not exist"),
        ([0, 1, -1, 0], ["a", "b", "c"], "object that does not exist"),
        ([0, 1, 2], ["a", "b", "c"], "one entry per triangle"),
        ([0, 1, 1, 0], ["a", "a"], "unique"),
        ([0, 0, 0, 0], [], "object that does not exist"),
    ],
)
def test_make_scene_rejects_bad_objects(
    object_index: list[int], names: list[str], message: str
) -> None:
    with pytest.raises(SceneError, match=message):
        _soup(FAN, FAN_UV, object_index, names)


def test_make_scene_default_object_is_the_source_stem() -> None:
    scene = make_scene(
        positions=FAN.reshape(-1, 3),
        triangles=np.arange(12).reshape(-1, 3),
        material_index=np.zeros(4, dtype=np.int64),
        material_names=["grey"],
        material_reflectance=[[0.5] * 3],
        material_emitted_exitance=[[0.0] * 3],
        source="rooms/hall.obj",
    )
    assert scene.object_names == ("hall",)
    np.testing.assert_array_equal(scene.object_index, 0)
    assert scene.lightmap_uv is None
