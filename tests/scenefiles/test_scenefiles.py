"""Scene loaders: exact material values, transforms, and one-line errors naming the file."""

from __future__ import annotations

import base64
import importlib.util
import json
import logging
import math
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from raytrad.errors import SceneError, SettingsError
from raytrad.formats.ply import write_radiosity_ply
from raytrad.scene import Scene, triangle_areas_normals
from raytrad.scene.builtin import cornell_box, furnace_box, shadow_scene
from raytrad.scenefiles import READERS, load_scene, trimesh_adapter
from tests.conftest import REPOSITORY

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"


def _write(directory: Path, name: str, content: str | bytes) -> Path:
    path = directory / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


def _per_material(scene: Scene) -> dict[str, dict[str, Any]]:
    """Area [m2], vector area (sum of area x normal) [m2] and values, by material name."""
    areas, normals = triangle_areas_normals(scene.triangle_vertices())
    result = {}
    for i, name in enumerate(scene.material_names):
        mine = scene.material_index == i
        result[name] = {
            "area": areas[mine].sum(),
            "vector_area": (areas[mine, None] * normals[mine]).sum(axis=0),
            "reflectance": scene.material_reflectance[i],
            "emitted_exitance": scene.material_emitted_exitance[i],
            "double_sided": bool(scene.material_double_sided[i]),
        }
    return result


# --------------------------------------------------------------------------- registry


def test_registry_lists_exactly_the_supported_suffixes() -> None:
    assert set(READERS) == {".obj", ".gltf", ".glb", ".ply", ".toml"}


def test_trimesh_is_imported_lazily() -> None:
    assert "trimesh" not in vars(trimesh_adapter)


# --------------------------------------------------------------------------- OBJ


def test_obj_kd_and_ke_are_read_exactly(tmp_path: Path) -> None:
    _write(
        tmp_path,
        "box.mtl",
        "newmtl white\nKd 0.725 0.71 0.68\n"
        "newmtl lamp\nKd 0.78 0.78 0.78\nKe 53.40707511102649 37.69911184307752 12.5\n",
    )
    path = _write(
        tmp_path,
        "box.obj",
        "mtllib box.mtl\n" + TRIANGLE + "v 0 0 1\nusemtl white\nf 1 2 3\nusemtl lamp\nf 1 4 2\n",
    )
    scene = load_scene(path)
    values = _per_material(scene)
    assert set(values) == {"white", "lamp"}
    assert values["white"]["reflectance"].tolist() == [0.725, 0.71, 0.68]  # not 185/255 etc.
    assert values["white"]["emitted_exitance"].tolist() == [0.0, 0.0, 0.0]
    assert values["lamp"]["reflectance"].tolist() == [0.78, 0.78, 0.78]
    assert values["lamp"]["emitted_exitance"].tolist() == [
        53.40707511102649,
        37.69911184307752,
        12.5,
    ]
    assert not scene.material_double_sided.any()
    assert scene.source == path


def test_obj_single_number_kd_and_ke_mean_grey(tmp_path: Path) -> None:
    _write(tmp_path, "g.mtl", "newmtl a\nKd 0.25\nKe 2\nnewmtl b\nKd 0.1 0.2 0.3\n")
    path = _write(
        tmp_path,
        "g.obj",
        "mtllib g.mtl\n" + TRIANGLE + "v 0 0 1\nusemtl a\nf 1 2 3\nusemtl b\nf 1 4 2\n",
    )
    values = _per_material(load_scene(path))
    assert values["a"]["reflectance"].tolist() == [0.25] * 3
    assert values["a"]["emitted_exitance"].tolist() == [2.0] * 3
    assert values["b"]["reflectance"].tolist() == [0.1, 0.2, 0.3]


def test_obj_quad_is_split_keeping_its_winding(tmp_path: Path) -> None:
    path = _write(tmp_path, "q.obj", "v 0 0 0\nv 2 0 0\nv 2 3 0\nv 0 3 0\nf 1 2 3 4\n")
    scene = load_scene(path)
    areas, normals = triangle_areas_normals(scene.triangle_vertices())
    assert scene.triangle_count == 2
    assert areas.sum() == pytest.approx(6.0, rel=1e-15)
    np.testing.assert_array_equal(normals, [[0, 0, 1], [0, 0, 1]])


def test_obj_without_material_gets_grey_default_and_one_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = _write(tmp_path, "plain.obj", TRIANGLE + "v 0 0 1\no a\nf 1 2 3\no b\nf 1 4 2\n")
    with caplog.at_level(logging.WARNING, logger="raytrad"):
        scene = load_scene(path)
    assert scene.material_names == ("default",)
    assert scene.material_reflectance.tolist() == [[0.5, 0.5, 0.5]]
    assert scene.material_emitted_exitance.tolist() == [[0.0, 0.0, 0.0]]
    assert scene.triangle_count == 2
    warnings = [r for r in caplog.records if "without an MTL material" in r.getMessage()]
    assert len(warnings) == 1 and "plain.obj" in warnings[0].getMessage()


def test_obj_with_missing_mtl_file_warns(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = _write(tmp_path, "lost.obj", "mtllib gone.mtl\n" + TRIANGLE + "usemtl m\nf 1 2 3\n")
    with caplog.at_level(logging.WARNING, logger="raytrad"):
        scene = load_scene(path)
    assert scene.material_reflectance.tolist() == [[0.5, 0.5, 0.5]]
    assert any("mtllib" in r.getMessage() for r in caplog.records)


def test_file_material_named_default_is_kept_apart_from_the_fallback(tmp_path: Path) -> None:
    _write(tmp_path, "d.mtl", "newmtl default\nKd 0.125 0.125 0.125\n")
    path = _write(
        tmp_path,
        "d.obj",
        "mtllib d.mtl\n" + TRIANGLE + "v 0 0 1\nf 1 4 2\nusemtl default\nf 1 2 3\n",
    )
    scene = load_scene(path)
    reflectance = dict(zip(scene.material_names, scene.material_reflectance[:, 0], strict=True))
    assert sorted(reflectance.values()) == [0.125, 0.5]
    assert set(reflectance) == {"default", "default_1"}


def test_scale_converts_file_units_to_metres(tmp_path: Path) -> None:
    path = _write(tmp_path, "mm.obj", "v 0 0 0\nv 1000 0 0\nv 0 500 0\nf 1 2 3\n")
    scene = load_scene(path, scale=0.001)
    np.testing.assert_allclose(
        scene.triangle_vertices()[0], np.array([[0, 0, 0], [1, 0, 0], [0, 0.5, 0]]), rtol=1e-15
    )
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(SettingsError, match="scale"):
            load_scene(path, scale=bad)


def test_suffix_is_matched_case_insensitively(tmp_path: Path) -> None:
    path = _write(tmp_path, "UPPER.OBJ", TRIANGLE + "f 1 2 3\n")
    assert load_scene(path).triangle_count == 1


def test_zero_area_triangles_are_dropped_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = _write(tmp_path, "thin.obj", TRIANGLE + "v 2 0 0\nf 1 2 3\nf 1 2 4\n")
    with caplog.at_level(logging.WARNING, logger="raytrad"):
        scene = load_scene(path)
    assert scene.triangle_count == 1
    areas, _ = triangle_areas_normals(scene.triangle_vertices())
    assert areas.tolist() == [0.5]
    assert any(
        "zero-area" in r.getMessage() and "thin.obj" in r.getMessage() for r in caplog.records
    )


# --------------------------------------------------------------------------- bundled scenes


@pytest.mark.parametrize(
    ("file_name", "builder"),
    [
        ("cornell-box.obj", cornell_box),
        ("furnace.obj", lambda: furnace_box(reflectance=0.5, emitted_exitance=1.0)),
        ("shadow.glb", shadow_scene),
    ],
)
def test_bundled_scene_files_match_the_builders(file_name: str, builder: Any) -> None:
    loaded = _per_material(load_scene(REPOSITORY / "scenes" / file_name))
    built = _per_material(builder())
    # OBJ keeps float64 positions (repr); glTF stores float32 (0.3 m is off by ~1e-8 m).
    tolerance = 1e-12 if file_name.endswith(".obj") else 1e-6
    assert set(loaded) == set(built)
    for name, expected in built.items():
        got = loaded[name]
        assert got["area"] == pytest.approx(expected["area"], rel=tolerance), name
        # Same vector area: every triangle still faces the same way.
        np.testing.assert_allclose(got["vector_area"], expected["vector_area"], atol=tolerance)
        np.testing.assert_array_equal(got["reflectance"], expected["reflectance"])
        np.testing.assert_allclose(
            got["emitted_exitance"], expected["emitted_exitance"], rtol=1e-14
        )
        assert got["double_sided"] == expected["double_sided"], name


def test_bundled_scene_files_are_up_to_date(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location(
        "make_scenes", REPOSITORY / "tools" / "make_scenes.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--out", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [
        "ball-box.mtl",
        "ball-box.obj",
        "blocks-room.mtl",
        "blocks-room.obj",
        "cornell-box-uv.glb",
        "cornell-box.mtl",
        "cornell-box.obj",
        "furnace.mtl",
        "furnace.obj",
        "shadow.glb",
    ]
    for name in names:
        assert (tmp_path / name).read_bytes() == (REPOSITORY / "scenes" / name).read_bytes(), name


# --------------------------------------------------------------------------- glTF


def _buffer(positions: np.ndarray, indices: np.ndarray) -> tuple[dict[str, Any], bytes]:
    """glTF accessors/bufferViews for one triangle list, and the binary blob."""
    pos, idx = positions.astype("<f4"), indices.astype("<u4")
    blob = pos.tobytes() + idx.tobytes()
    layout = {
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": len(pos),
                "type": "VEC3",
                "min": pos.min(axis=0).tolist(),
                "max": pos.max(axis=0).tolist(),
            },
            {"bufferView": 1, "componentType": 5125, "count": idx.size, "type": "SCALAR"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": pos.nbytes},
            {"buffer": 0, "byteOffset": pos.nbytes, "byteLength": idx.nbytes},
        ],
    }
    return layout, blob


def _gltf_file(directory: Path, name: str, document: dict[str, Any], blob: bytes) -> Path:
    """Write ``document`` as .gltf (data URI buffer) or .glb (hand-packed container)."""
    document = {"asset": {"version": "2.0"}, **document}
    if name.endswith(".gltf"):
        uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        document["buffers"] = [{"byteLength": len(blob), "uri": uri}]
        return _write(directory, name, json.dumps(document))
    document["buffers"] = [{"byteLength": len(blob)}]
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    chunks = (
        struct.pack("<I4s", len(text), b"JSON")
        + text
        + struct.pack("<I4s", len(blob), b"BIN\0")
        + blob
    )
    return _write(directory, name, struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)


# One triangle in the plane y = 0 whose front faces +y: (1,0,0) x (0,0,-1) = (0,1,0).
UP_TRIANGLE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _two_material_document() -> tuple[dict[str, Any], bytes]:
    layout, blob = _buffer(UP_TRIANGLE, np.arange(3))
    document = {
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0}, {"mesh": 1, "translation": [0, 1, 0]}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]},
            {"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 1}]},
        ],
        "materials": [
            {
                "name": "panel",
                "doubleSided": True,
                "pbrMetallicRoughness": {"baseColorFactor": [0.725, 0.71, 0.68, 0.5]},
                "emissiveFactor": [1.0, 0.5, 0.25],
                "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}},
            },
            {"emissiveFactor": [0.5, 0.5, 0.5]},
        ],
        **layout,
    }
    return document, blob


@pytest.mark.parametrize("name", ["two.gltf", "two.glb"])
def test_gltf_material_values(tmp_path: Path, name: str) -> None:
    document, blob = _two_material_document()
    values = _per_material(load_scene(_gltf_file(tmp_path, name, document, blob)))
    assert set(values) == {"panel", "material_1"}
    panel, plain = values["panel"], values["material_1"]
    assert panel["reflectance"].tolist() == [0.725, 0.71, 0.68]
    np.testing.assert_allclose(
        panel["emitted_exitance"], [4 * math.pi, 2 * math.pi, math.pi], rtol=1e-15
    )
    assert panel["double_sided"] is True
    # Defaults: baseColorFactor 1, emissive strength 1, single-sided.
    assert plain["reflectance"].tolist() == [1.0, 1.0, 1.0]
    np.testing.assert_allclose(plain["emitted_exitance"], [0.5 * math.pi] * 3, rtol=1e-15)
    assert plain["double_sided"] is False


def test_gltf_mirroring_node_keeps_the_mirrored_front_side(tmp_path: Path) -> None:
    layout, blob = _buffer(UP_TRIANGLE, np.arange(3))
    mirror_y = [1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 0, 0, 2, 0, 1]  # column-major, det = -1
    document = {
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"mesh": 0, "name": "plain"},
            {"mesh": 0, "name": "mirrored", "matrix": mirror_y},
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [
            {"name": "m", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}}
        ],
        **layout,
    }
    scene = load_scene(_gltf_file(tmp_path, "mirror.gltf", document, blob))
    corners = scene.triangle_vertices()
    _, normals = triangle_areas_normals(corners)
    mirrored = corners[:, 0, 1] == 2.0  # the copy moved to y = 2 by the mirroring node
    assert mirrored.tolist().count(True) == 1
    np.testing.assert_array_equal(normals[~mirrored], [[0.0, 1.0, 0.0]])
    # The mirror image of a surface facing +y faces -y; without re-winding it would face +y.
    np.testing.assert_array_equal(normals[mirrored], [[0.0, -1.0, 0.0]])
    np.testing.assert_array_equal(
        np.sort(corners[mirrored][0], axis=0), np.sort(UP_TRIANGLE * [1, -1, 1] + [0, 2, 0], axis=0)
    )


def test_gltf_primitive_without_material_uses_reflectance_one_and_warns(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    layout, blob = _buffer(UP_TRIANGLE, np.arange(3))
    document = {
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        **layout,
    }
    with caplog.at_level(logging.WARNING, logger="raytrad"):
        scene = load_scene(_gltf_file(tmp_path, "bare.glb", document, blob))
    assert scene.material_reflectance.tolist() == [[1.0, 1.0, 1.0]]
    assert scene.material_emitted_exitance.tolist() == [[0.0, 0.0, 0.0]]
    assert any("reflectance 1" in r.getMessage() for r in caplog.records)


def test_gltf_texture_is_ignored_with_one_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    document, blob = _two_material_document()
    for material in document["materials"]:
        material.setdefault("pbrMetallicRoughness", {})["baseColorTexture"] = {"index": 0}
    document["textures"] = [{"source": 0}]
    document["images"] = [{"uri": "missing.png"}]
    with caplog.at_level(logging.WARNING, logger="raytrad"):
        scene = load_scene(_gltf_file(tmp_path, "tex.gltf", document, blob))
    assert _per_material(scene)["panel"]["reflectance"].tolist() == [0.725, 0.71, 0.68]
    assert sum("textures are ignored" in r.getMessage() for r in caplog.records) == 1


def test_gltf_points_are_ignored(tmp_path: Path) -> None:
    document, blob = _two_material_document()
    document["meshes"][1]["primitives"][0]["mode"] = 0  # POINTS
    scene = load_scene(_gltf_file(tmp_path, "points.glb", document, blob))
    assert scene.triangle_count == 1 and scene.material_names == ("panel",)
    document["meshes"][0]["primitives"][0]["mode"] = 0
    with pytest.raises(SceneError, match="no triangle faces"):
        load_scene(_gltf_file(tmp_path, "only-points.glb", document, blob))


# --------------------------------------------------------------------------- PLY

PLY_ASCII = """ply
format ascii 1.0
element vertex 6
property float x
property float y
property float z
element face 3
property list uchar int vertex_indices
{properties}end_header
0 0 0
1 0 0
1 1 0
0 1 0
0 0 1
0 0 2
4 0 1 2 3 {a}
3 0 1 4 {b}
3 0 5 1 {c}
"""


def test_ply_face_reflectance_and_emission_properties(tmp_path: Path) -> None:
    properties = "".join(
        f"property float {p}_{c}\n" for p in ("reflectance", "emitted_exitance") for c in "rgb"
    )
    path = _write(
        tmp_path,
        "props.ply",
        PLY_ASCII.format(
            properties=properties,
            a="0.5 0.25 0.125 0 0 0",
            b="0.75 0.75 0.75 5 6 7",
            c="0.5 0.25 0.125 0 0 0",
        ),
    )
    scene = load_scene(path)
    assert scene.triangle_count == 4
    by_values = {
        (tuple(r), tuple(e)): i
        for i, (r, e) in enumerate(
            zip(
                scene.material_reflectance.tolist(),
                scene.material_emitted_exitance.tolist(),
                strict=True,
            )
        )
    }
    assert set(by_values) == {
        ((0.5, 0.25, 0.125), (0.0, 0.0, 0.0)),
        ((0.75, 0.75, 0.75), (5.0, 6.0, 7.0)),
    }
    areas, normals = triangle_areas_normals(scene.triangle_vertices())
    lamp = scene.material_index == by_values[((0.75, 0.75, 0.75), (5.0, 6.0, 7.0))]
    assert areas[lamp].tolist() == [0.5]  # the triangle 0 1 4
    assert areas[~lamp].sum() == pytest.approx(1.0 + 1.0)  # the unit quad + triangle 0 5 1
    np.testing.assert_array_equal(normals[lamp], [[0.0, -1.0, 0.0]])


def test_ply_uchar_colours_are_srgb_decoded(tmp_path: Path) -> None:
    properties = "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    path = _write(
        tmp_path,
        "colours.ply",
        PLY_ASCII.format(properties=properties, a="255 128 0", b="10 10 10", c="255 128 0"),
    )
    reflectance = sorted(map(tuple, load_scene(path).material_reflectance.tolist()))
    c128 = ((128 / 255 + 0.055) / 1.055) ** 2.4  # IEC 61966-2-1
    assert reflectance[0] == pytest.approx((10 / 255 / 12.92,) * 3, rel=1e-15)
    assert reflectance[1] == pytest.approx((1.0, c128, 0.0), rel=1e-15)
    assert c128 == pytest.approx(0.2158605, rel=1e-6)


def test_ply_without_material_properties_is_grey(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = _write(tmp_path, "bare.ply", PLY_ASCII.format(properties="", a="", b="", c=""))
    with caplog.at_level(logging.WARNING, logger="raytrad"):
        scene = load_scene(path)
    assert scene.material_names == ("default",)
    assert scene.material_reflectance.tolist() == [[0.5, 0.5, 0.5]]
    assert scene.triangle_count == 4
    assert any("bare.ply" in r.getMessage() for r in caplog.records)


def test_binary_ply_with_face_properties(tmp_path: Path) -> None:
    face = np.dtype(
        [
            ("n", "u1"),
            ("v", "<i4", (3,)),
            ("reflectance_r", "<f4"),
            ("reflectance_g", "<f4"),
            ("reflectance_b", "<f4"),
        ]
    )
    faces = np.zeros(2, dtype=face)
    faces["n"], faces["v"] = 3, [[0, 1, 2], [0, 2, 3]]
    faces["reflectance_r"], faces["reflectance_g"], faces["reflectance_b"] = [0.5, 0.25], 0.5, 0.5
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 0, -1], [0, 0, -1]], dtype="<f4")
    header = (
        "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
        "property float y\nproperty float z\nelement face 2\n"
        "property list uchar int vertex_indices\nproperty float reflectance_r\n"
        "property float reflectance_g\nproperty float reflectance_b\nend_header\n"
    )
    path = _write(tmp_path, "bin.ply", header.encode() + vertices.tobytes() + faces.tobytes())
    scene = load_scene(path)
    assert sorted(scene.material_reflectance[:, 0].tolist()) == [0.25, 0.5]
    _, normals = triangle_areas_normals(scene.triangle_vertices())
    np.testing.assert_array_equal(normals, [[0.0, 1.0, 0.0]] * 2)


def test_radiosity_ply_loads_as_a_scene(tmp_path: Path) -> None:
    path = tmp_path / "out.ply"
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float64)
    write_radiosity_ply(
        path, positions, np.array([[0, 1, 2]]), np.ones((3, 3)), np.zeros((3, 3), int)
    )
    scene = load_scene(path)
    np.testing.assert_array_equal(scene.triangle_vertices()[0], positions)


# --------------------------------------------------------------------------- errors

BAD_INPUTS: list[tuple[str, str | bytes | None, str]] = [
    ("absent.obj", None, "file not found"),
    ("model.stl", "solid x\nendsolid x\n", "unsupported file type '.stl'"),
    ("cloud.xyz", "0 0 0\n", "unsupported file type '.xyz'"),
    ("noise.obj", bytes(range(256)) * 8, "cannot parse as OBJ"),
    ("noise.glb", bytes(range(256)) * 8, "cannot parse as GLB"),
    ("noise.gltf", "{ this is not json", "cannot parse as glTF"),
    ("short.glb", struct.pack("<4sII", b"glTF", 2, 4000) + b"\0" * 8, "truncated"),
    ("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "NaN"),
    ("inf.obj", "v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n", "infinite"),
    ("vertices.obj", TRIANGLE, "no triangle faces"),
    ("empty.obj", "", "no triangle faces"),
    (
        "vertices.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
        "property float y\nproperty float z\nend_header\n0 0 0\n",
        "no triangle faces",
    ),
]


@pytest.mark.parametrize(("name", "content", "problem"), BAD_INPUTS, ids=[b[0] for b in BAD_INPUTS])
def test_bad_input_raises_scene_error_naming_the_file(
    tmp_path: Path, name: str, content: str | bytes | None, problem: str
) -> None:
    path = tmp_path / name if content is None else _write(tmp_path, name, content)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert name in message and problem in message
    assert "\n" not in message
    assert info.value.path == path


def test_unsupported_suffix_lists_the_registry(tmp_path: Path) -> None:
    with pytest.raises(SceneError) as info:
        load_scene(_write(tmp_path, "a.stl", "solid"))
    assert all(suffix in str(info.value) for suffix in READERS)


@pytest.mark.parametrize(
    ("mtl", "problem"),
    [
        ("newmtl m\nKd 1.5 0.5 0.5\n", "reflectance [1.5, 0.5, 0.5] is outside [0, 1]"),
        ("newmtl m\nKd 0.5 0.5 0.5\nKe -1 0 0\n", "emission [-1.0, 0.0, 0.0]"),
    ],
)
def test_bad_mtl_values_name_the_file_and_material(tmp_path: Path, mtl: str, problem: str) -> None:
    _write(tmp_path, "bad.mtl", mtl)
    path = _write(tmp_path, "bad.obj", "mtllib bad.mtl\n" + TRIANGLE + "usemtl m\nf 1 2 3\n")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert "bad.obj" in str(info.value) and problem in str(info.value)
    assert "'m'" in str(info.value)


def test_directory_is_not_a_scene(tmp_path: Path) -> None:
    os.mkdir(tmp_path / "dir.obj")
    with pytest.raises(SceneError, match="not a regular file"):
        load_scene(tmp_path / "dir.obj")
