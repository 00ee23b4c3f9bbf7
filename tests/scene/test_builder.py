"""The scene builder: faces wound to face where asked, rooms and blocks of known area,
materials and objects in the order they were given."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.scene import triangle_areas_normals
from raytrad.scene.builder import SceneBuilder, box_faces, icosphere, quads_scene, rectangle

SQUARE = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 1.0, 0.0)]


def _normals(scene: object) -> np.ndarray:
    return triangle_areas_normals(scene.triangle_vertices())[1]  # type: ignore[attr-defined]


@pytest.mark.parametrize("facing", [(0, 0, 1), (0, 0, -1), (0.3, -0.2, -5.0)])
def test_quads_face_where_asked(facing: tuple[float, float, float]) -> None:
    scene = quads_scene([SQUARE], facing=[facing])
    assert (_normals(scene) @ np.asarray(facing) > 0).all()


def test_facing_in_the_plane_is_refused() -> None:
    builder = SceneBuilder()
    builder.material("grey", 0.5)
    with pytest.raises(ValueError, match="plane"):
        builder.quad(SQUARE, "grey", facing=(1.0, 0.0, 1e-12))
    with pytest.raises(ValueError, match="plane"):
        builder.triangle(SQUARE[:3], "grey", facing=(0.0, 1.0, 0.0))


def test_room_faces_inward_and_block_outward() -> None:
    builder = SceneBuilder()
    builder.material("wall", 0.5)
    builder.material("box", (0.1, 0.2, 0.3), emitted_exitance=2.0, double_sided=True)
    builder.room("wall", size=(2.0, 3.0, 4.0), obj="room")
    builder.block("box", (0.5, 0.0, 0.5), (1.0, 1.0, 1.5), obj="box")
    scene = builder.build()
    areas, normals = triangle_areas_normals(scene.triangle_vertices())
    room = scene.object_index == 0
    assert scene.object_names == ("room", "box")
    assert areas[room].sum() == pytest.approx(2 * (2 * 3 + 3 * 4 + 2 * 4))
    # top 0.5 x 1, sides 1 x 1 (twice) and 0.5 x 1 (twice), no bottom
    assert areas[~room].sum() == pytest.approx(0.5 + 2 * 1.0 + 2 * 0.5)
    centroids = scene.triangle_vertices().mean(axis=1)
    inward = np.einsum("ij,ij->i", normals[room], np.array([1.0, 1.5, 2.0]) - centroids[room])
    outward = np.einsum("ij,ij->i", normals[~room], centroids[~room] - [0.75, 0.5, 1.0])
    assert (inward > 0).all() and (outward > 0).all()
    assert scene.material_names == ("wall", "box")
    assert scene.material_reflectance[1].tolist() == [0.1, 0.2, 0.3]
    assert scene.material_emitted_exitance[1].tolist() == [2.0, 2.0, 2.0]
    assert scene.material_double_sided.tolist() == [False, True]


def test_grid_wall_leaves_holes_and_overrides_cells() -> None:
    builder = SceneBuilder()
    builder.material("wall", 0.5)
    builder.material("lamp", 0.0, 1.0)
    cells = {(0, 0): None, (1, 1): "lamp"}
    builder.grid_wall(2, 1.0, [0.0, 1.0, 3.0], [0.0, 2.0, 3.0], "wall", (0, 0, -1), cells)
    scene = builder.build()
    areas, _ = triangle_areas_normals(scene.triangle_vertices())
    assert areas.sum() == pytest.approx(9.0 - 2.0)
    assert areas[scene.material_index == 1].sum() == pytest.approx(2.0)


def test_box_faces_and_rectangles() -> None:
    faces = box_faces((0, 0, 0), (1, 2, 3))
    assert [name for name, _, _ in faces] == ["x-", "x+", "y-", "y+", "z-", "z+"]
    corners = rectangle(1, 2.0, (0.0, 0.0), (1.0, 3.0))
    assert (corners[:, 1] == 2.0).all() and np.ptp(corners, axis=0).tolist() == [1.0, 0.0, 3.0]


def test_icosphere_is_on_the_unit_sphere_and_outward() -> None:
    points, triangles = icosphere(2)
    assert len(triangles) == 20 * 16
    np.testing.assert_allclose(np.linalg.norm(points, axis=1), 1.0, rtol=1e-15)
    corners = points[triangles]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert (np.einsum("ij,ij->i", normal, corners.mean(axis=1)) > 0).all()
