"""The scene model: selection, flipping and validation keep objects and lightmap UVs
aligned with their triangles; make_scene refuses what cannot give a finite answer."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.errors import SceneError
from raytrad.scene import Scene, barycentric_coordinates, make_scene, triangle_areas_normals
from tests.conftest import triangle_soup, uv_at_corner

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
    return triangle_soup(FAN, FAN_UV, [2, 0, 1, 2], ["a", "b", "c"])


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
    scene = triangle_soup(FAN, None)
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
                flipped.lightmap_uv[t, c], uv_at_corner(FAN[t], FAN_UV[t], corners[t, c])
            )
    # The original scene is not modified.
    np.testing.assert_array_equal(scene.lightmap_uv, FAN_UV)
    np.testing.assert_array_equal(scene.triangle_vertices(), FAN)


# --------------------------------------------------------------------------- make_scene


def test_make_scene_keeps_uvs_as_float64_per_corner() -> None:
    scene = triangle_soup(FAN, FAN_UV.astype(np.float32))
    assert scene.lightmap_uv is not None
    assert scene.lightmap_uv.dtype == np.float64
    np.testing.assert_array_equal(scene.lightmap_uv, FAN_UV.astype(np.float32))


def test_make_scene_drops_degenerate_faces_with_their_uv_rows() -> None:
    corners = FAN.copy()
    corners[1] = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [2.0, 0.0, 1.0]]  # collinear
    scene = triangle_soup(corners, FAN_UV, [0, 1, 2, 0], ["a", "b", "c"])
    assert scene.triangle_count == 3
    np.testing.assert_array_equal(scene.object_index, [0, 2, 0])
    np.testing.assert_array_equal(scene.lightmap_uv, FAN_UV[[0, 2, 3]])


def test_make_scene_allows_nan_uvs() -> None:
    uv = FAN_UV.copy()
    uv[2] = np.nan
    scene = triangle_soup(FAN, uv)
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
        triangle_soup(FAN, uv)


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
        triangle_soup(FAN, FAN_UV, object_index, names)


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


def test_barycentric_coordinates_recover_the_weights_a_point_was_made_with() -> None:
    rng = np.random.default_rng(4)
    corners = rng.normal(size=(50, 3, 3)) * 10.0 + 1e4  # far from the origin
    weights = rng.dirichlet([1.0, 1.0, 1.0], size=50)
    weights[0] = [1.2, -0.5, 0.3]  # outside the triangle
    points = np.einsum("nk,nkd->nd", weights, corners)
    _, normal = triangle_areas_normals(corners)
    lifted = points + 0.01 * normal  # off the plane: the same weights
    np.testing.assert_allclose(barycentric_coordinates(lifted, corners), weights, atol=1e-9)
    flat = np.array([[[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]])  # degenerate: inside nothing
    assert np.isnan(barycentric_coordinates(np.zeros((1, 3)), flat)).all()
