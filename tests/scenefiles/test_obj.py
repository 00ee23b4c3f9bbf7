"""OBJ objects (``o``, else ``g``) read as the scene's objects, materials untouched."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from raytrad.scene import Scene
from raytrad.scenefiles import load_scene

MTL = "newmtl red\nKd 0.8 0.1 0.1\n\nnewmtl blue\nKd 0.1 0.1 0.8\nKe 2 3 4\n"

# four unit triangles side by side along x, each with its own three vertices
VERTICES = "".join(f"v {x} 0 0\nv {x + 1} 0 0\nv {x} 1 0\n" for x in (0, 2, 4, 6))


def _face(k: int) -> str:
    return f"f {3 * k + 1} {3 * k + 2} {3 * k + 3}\n"


def _write(tmp_path: Path, body: str, newline: str = "\n") -> Path:
    (tmp_path / "m.mtl").write_text(MTL)
    path = tmp_path / "objects.obj"
    path.write_bytes(("mtllib m.mtl\n" + VERTICES + body).replace("\n", newline).encode())
    return path


def _by_x(scene: Scene) -> tuple[list[str], list[str]]:
    """Object and material name of each triangle, ordered by its position along x."""
    order = np.argsort(scene.triangle_vertices()[:, :, 0].min(axis=1))
    objects = [scene.object_names[i] for i in scene.object_index[order]]
    materials = [scene.material_names[i] for i in scene.material_index[order]]
    return objects, materials


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_objects_and_materials_of_each_face(tmp_path: Path, newline: str) -> None:
    body = (
        "o chair\nusemtl red\n"
        + _face(0)
        + "usemtl blue\n"
        + _face(1)
        # no usemtl: the material in force (blue) carries over into the next object
        + "o table top\n"
        + _face(2)
        + "usemtl red\n"
        + _face(3)
    )
    scene = load_scene(_write(tmp_path, body, newline))
    objects, materials = _by_x(scene)
    assert objects == ["chair", "chair", "table top", "table top"]
    assert materials == ["red", "blue", "blue", "red"]
    assert scene.object_names == ("chair", "table top")
    assert sorted(scene.material_names) == ["blue", "red"]
    red = scene.material_names.index("red")
    blue = scene.material_names.index("blue")
    np.testing.assert_array_equal(scene.material_reflectance[red], [0.8, 0.1, 0.1])
    np.testing.assert_array_equal(scene.material_emitted_exitance[blue], [2.0, 3.0, 4.0])


def test_a_repeated_object_name_is_one_object(tmp_path: Path) -> None:
    body = "usemtl red\no a\n" + _face(0) + "o b\n" + _face(1) + "o a\n" + _face(2) + _face(3)
    objects, materials = _by_x(load_scene(_write(tmp_path, body)))
    assert objects == ["a", "b", "a", "a"] and set(materials) == {"red"}


def test_groups_are_objects_when_there_is_no_o(tmp_path: Path) -> None:
    body = "g left\nusemtl red\n" + _face(0) + _face(1) + "g right\n" + _face(2) + _face(3)
    objects, _ = _by_x(load_scene(_write(tmp_path, body)))
    assert objects == ["left", "left", "right", "right"]


def test_o_wins_over_g(tmp_path: Path) -> None:
    body = "o whole\ng part1\nusemtl red\n" + _face(0) + "g part2\n" + _face(1) + _face(2)
    body += _face(3)
    objects, _ = _by_x(load_scene(_write(tmp_path, body)))
    assert objects == ["whole"] * 4


def test_faces_before_the_first_object_belong_to_the_file(tmp_path: Path) -> None:
    body = "usemtl red\n" + _face(0) + "o lamp\nusemtl blue\n" + _face(1) + _face(2) + _face(3)
    objects, materials = _by_x(load_scene(_write(tmp_path, body)))
    assert objects == ["objects", "lamp", "lamp", "lamp"]
    assert materials == ["red", "blue", "blue", "blue"]


def test_objects_without_any_material_get_the_default(tmp_path: Path) -> None:
    (tmp_path / "bare.obj").write_text(VERTICES + "o a\n" + _face(0) + "o b\n" + _face(1))
    scene = load_scene(tmp_path / "bare.obj")
    objects, materials = _by_x(scene)
    assert objects == ["a", "b"] and materials == ["default", "default"]
    np.testing.assert_array_equal(scene.material_reflectance, [[0.5, 0.5, 0.5]])


def test_objects_keep_their_uv_seams(tmp_path: Path) -> None:
    # one quad over two objects, sharing vertices, with different vt on the shared ones
    text = (
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
        "vt 0.1 0.1\nvt 0.4 0.1\nvt 0.4 0.4\nvt 0.6 0.6\nvt 0.9 0.9\nvt 0.6 0.9\n"
        "o lower\nf 1/1 2/2 3/3\no upper\nf 1/4 3/5 4/6\n"
    )
    (tmp_path / "seam.obj").write_text(text)
    scene = load_scene(tmp_path / "seam.obj", uv_set=0)
    assert scene.lightmap_uv is not None
    expected = {
        ("lower", (0, 0)): (0.1, 0.9),
        ("lower", (1, 0)): (0.4, 0.9),
        ("lower", (1, 1)): (0.4, 0.6),
        ("upper", (0, 0)): (0.6, 0.4),
        ("upper", (1, 1)): (0.9, 0.1),
        ("upper", (0, 1)): (0.6, 0.1),
    }
    corners = scene.triangle_vertices()
    for t in range(scene.triangle_count):
        name = scene.object_names[scene.object_index[t]]
        for k in range(3):
            key = (name, (int(corners[t, k, 0]), int(corners[t, k, 1])))
            np.testing.assert_allclose(scene.lightmap_uv[t, k], expected[key], atol=1e-12)
