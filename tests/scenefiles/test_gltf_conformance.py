"""glTF 2.0 conformance: accessors, primitives, scene graph and containers, each against
hand-computed area, counts, bounds and emitted power; malformed files refused by name.

The feature list follows the Khronos glTF sample models (SimpleSparseAccessor,
TriangleWithoutIndices, SimpleMeshes, MultipleScenes, the quantized models).
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from raytrad.errors import SceneError
from raytrad.scenefiles import load_scene
from tests.scenefiles.conformance import FLOOR, LAMP, measure
from tests.scenefiles.gltf_builder import Gltf

LAMP_POWER = math.pi * 0.04  # radiance 1 over 0.2 m x 0.2 m


def _floor_and_lamp(index_type: str = "u2") -> Gltf:
    gltf = Gltf()
    gltf.node(mesh=gltf.mesh(gltf.quad(FLOOR, 0, index_type)), name="floor")
    gltf.node(mesh=gltf.mesh(gltf.quad(LAMP, 1, index_type)), name="lamp")
    return gltf


def _check_floor_and_lamp(path: Path, copies: int = 1) -> None:
    measured = measure(load_scene(path))
    assert measured.triangles == 4 * copies
    assert measured.area_of("floor") == pytest.approx(copies * 1.0, rel=1e-6)
    assert measured.emitted_power == pytest.approx(copies * LAMP_POWER, rel=1e-6)
    assert (measured.normals[:, 1] > 0.999).sum() == 2 * copies  # floor up, lamp down
    assert (measured.normals[:, 1] < -0.999).sum() == 2 * copies


@pytest.mark.parametrize("index_type", ["u1", "u2", "u4"])
def test_8_16_and_32_bit_indices(tmp_path: Path, index_type: str) -> None:
    _check_floor_and_lamp(_floor_and_lamp(index_type).write_gltf(tmp_path / "a.gltf"))


@pytest.mark.parametrize("container", ["data URI", "file beside it", "GLB with BIN chunk"])
def test_containers(tmp_path: Path, container: str) -> None:
    gltf = _floor_and_lamp()
    if container == "data URI":
        path = gltf.write_gltf(tmp_path / "a.gltf")
    elif container == "file beside it":
        path = gltf.write_gltf(tmp_path / "a.gltf", buffer_file="a b.bin")
    else:
        path = gltf.write_glb(tmp_path / "a.glb")
    _check_floor_and_lamp(path)


def test_glb_without_bin_chunk_and_a_data_uri_buffer(tmp_path: Path) -> None:
    gltf = _floor_and_lamp()
    data_uri = gltf.write_gltf(tmp_path / "a.gltf")
    import json
    import struct

    text = data_uri.read_bytes()
    text += b" " * (-len(text) % 4)
    chunk = struct.pack("<I4s", len(text), b"JSON") + text
    glb = tmp_path / "b.glb"
    glb.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunk)) + chunk)
    assert json.loads(text)["buffers"][0]["uri"].startswith("data:")
    _check_floor_and_lamp(glb)


def test_non_indexed_primitive(tmp_path: Path) -> None:
    gltf = Gltf()
    corners = np.array(FLOOR)[[0, 1, 2, 0, 2, 3]]
    lamp = np.array(LAMP)[[0, 1, 2, 0, 2, 3]]
    for points, material in ((corners, 0), (lamp, 1)):
        primitive = {"attributes": {"POSITION": gltf.accessor(points, "f4")}, "material": material}
        gltf.node(mesh=gltf.mesh(primitive))
    _check_floor_and_lamp(gltf.write_gltf(tmp_path / "a.gltf"))


@pytest.mark.parametrize("mode", ["strip", "fan"])
def test_triangle_strips_and_fans(tmp_path: Path, mode: str) -> None:
    gltf = Gltf()
    for quad, material in ((FLOOR, 0), (LAMP, 1)):
        # strip 0 1 3 2 and fan 0 1 2 3 both cover the quad, wound as the quad
        order = [0, 1, 3, 2] if mode == "strip" else [0, 1, 2, 3]
        primitive = {
            "attributes": {"POSITION": gltf.accessor(quad, "f4")},
            "indices": gltf.accessor(order, "u2"),
            "mode": 5 if mode == "strip" else 6,
            "material": material,
        }
        gltf.node(mesh=gltf.mesh(primitive))
    _check_floor_and_lamp(gltf.write_gltf(tmp_path / "a.gltf"))


def test_interleaved_view_with_byte_stride(tmp_path: Path) -> None:
    gltf = _floor_and_lamp()
    # rewrite the floor's positions as POSITION + NORMAL interleaved (stride 24)
    interleaved = np.hstack([np.array(FLOOR, "<f4"), np.tile([0, 1, 0], (4, 1)).astype("<f4")])
    view = gltf.view(interleaved.tobytes(), stride=24)
    accessors = gltf.doc["accessors"]
    accessors.append({"bufferView": view, "componentType": 5126, "count": 4, "type": "VEC3"})
    accessors.append(
        {"bufferView": view, "byteOffset": 12, "componentType": 5126, "count": 4, "type": "VEC3"}
    )
    floor = gltf.doc["meshes"][0]["primitives"][0]
    floor["attributes"] = {"POSITION": len(accessors) - 2, "NORMAL": len(accessors) - 1}
    _check_floor_and_lamp(gltf.write_gltf(tmp_path / "a.gltf"))


def test_sparse_accessor_moves_the_lamp_up(tmp_path: Path) -> None:
    gltf = _floor_and_lamp()
    lamp_positions = gltf.doc["meshes"][1]["primitives"][0]["attributes"]["POSITION"]
    on_floor = np.array(LAMP, "<f4") * [1, 0, 1]
    dense = gltf.view(on_floor.tobytes())
    indices = gltf.view(np.array([0, 1, 2, 3], "<u2").tobytes())
    values = gltf.view(np.array(LAMP, "<f4").tobytes())
    gltf.doc["accessors"][lamp_positions].update(
        bufferView=dense,
        sparse={
            "count": 4,
            "indices": {"bufferView": indices, "componentType": 5123},
            "values": {"bufferView": values},
        },
    )
    path = gltf.write_gltf(tmp_path / "a.gltf")
    _check_floor_and_lamp(path)
    assert measure(load_scene(path)).upper[1] == pytest.approx(1.0)


@pytest.mark.parametrize(("dtype", "scale"), [("i2", 32767.0), ("u1", 255.0), ("i1", 127.0)])
def test_normalized_integers_with_mesh_quantization(
    tmp_path: Path, dtype: str, scale: float
) -> None:
    # the floor's corners (0 or 1) stored as the integers 0 and the type's maximum
    gltf = _floor_and_lamp()
    gltf.doc["extensionsUsed"] = gltf.doc["extensionsRequired"] = ["KHR_mesh_quantization"]
    floor = gltf.doc["meshes"][0]["primitives"][0]
    floor["attributes"]["POSITION"] = gltf.accessor(np.array(FLOOR) * scale, dtype, normalized=True)
    _check_floor_and_lamp(gltf.write_gltf(tmp_path / "a.gltf"))


def test_quantized_integers_scaled_by_the_node(tmp_path: Path) -> None:
    gltf = _floor_and_lamp()
    gltf.doc["extensionsUsed"] = gltf.doc["extensionsRequired"] = ["KHR_mesh_quantization"]
    floor = gltf.doc["meshes"][0]["primitives"][0]
    floor["attributes"]["POSITION"] = gltf.accessor(np.array(FLOOR) * 1000, "u2")
    gltf.doc["nodes"][0]["scale"] = [0.001, 0.001, 0.001]
    _check_floor_and_lamp(gltf.write_gltf(tmp_path / "a.gltf"))


def test_node_matrix_trs_and_instanced_meshes(tmp_path: Path) -> None:
    gltf = _floor_and_lamp()
    # the same two meshes again, moved 5 m along x by a matrix and by a translation
    gltf.node(mesh=0, matrix=[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 5, 0, 0, 1])
    gltf.node(mesh=1, translation=[5, 0, 0], rotation=[0, 0, 0, 1])
    path = gltf.write_gltf(tmp_path / "a.gltf")
    _check_floor_and_lamp(path, copies=2)
    measured = measure(load_scene(path))
    np.testing.assert_allclose(measured.upper, [6, 1, 1], atol=1e-6)


def test_children_inherit_their_parents_transform(tmp_path: Path) -> None:
    gltf = Gltf()
    lamp = gltf.node(root=False, mesh=gltf.mesh(gltf.quad(LAMP, 1)), translation=[0, 1, 0])
    gltf.node(mesh=gltf.mesh(gltf.quad(FLOOR, 0)), children=[lamp], translation=[0, 2, 0])
    measured = measure(load_scene(gltf.write_gltf(tmp_path / "a.gltf")))
    np.testing.assert_allclose(measured.lower, [0, 2, 0], atol=1e-6)
    np.testing.assert_allclose(measured.upper, [1, 4, 1], atol=1e-6)


def test_the_default_scene_of_several(tmp_path: Path) -> None:
    gltf = _floor_and_lamp()
    gltf.doc["scenes"] = [{"nodes": [0]}, {"nodes": [0, 1]}]
    gltf.doc["scene"] = 1
    _check_floor_and_lamp(gltf.write_gltf(tmp_path / "a.gltf"))


def test_supported_required_extension_is_accepted(tmp_path: Path) -> None:
    gltf = _floor_and_lamp()
    gltf.doc["extensionsUsed"] = ["KHR_materials_emissive_strength"]
    gltf.doc["extensionsRequired"] = ["KHR_materials_emissive_strength"]
    gltf.doc["materials"][1]["extensions"] = {
        "KHR_materials_emissive_strength": {"emissiveStrength": 2.0}
    }
    measured = measure(load_scene(gltf.write_gltf(tmp_path / "a.gltf")))
    assert measured.emitted_power == pytest.approx(2 * LAMP_POWER, rel=1e-6)


def test_points_and_lines_are_left_out_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    gltf = _floor_and_lamp()
    line = {"attributes": {"POSITION": gltf.accessor([[0, 0, 0], [1, 1, 1]], "f4")}, "mode": 1}
    gltf.node(mesh=gltf.mesh(line))
    with caplog.at_level(logging.WARNING):
        _check_floor_and_lamp(gltf.write_gltf(tmp_path / "a.gltf"))
    assert "points or lines carry no area" in caplog.text


def _broken(gltf: Gltf, case: str) -> None:
    doc: dict[str, Any] = gltf.doc
    if case == "index past the vertices":
        gltf.doc["meshes"][0]["primitives"][0]["indices"] = gltf.accessor([0, 1, 1000], "u2")
    elif case == "byteStride 1":
        doc["bufferViews"][0]["byteStride"] = 1
    elif case == "node refers to a missing mesh":
        doc["nodes"][0]["mesh"] = 55
    elif case == "bogus mode":
        doc["meshes"][0]["primitives"][0]["mode"] = 99
    elif case == "unsupported required extension":
        doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    elif case == "node cycle":
        doc["nodes"][0]["children"] = [1]
        doc["nodes"][1]["children"] = [0]
    elif case == "sparse values in a missing view":
        doc["accessors"][0]["sparse"] = {
            "count": 1,
            "indices": {"bufferView": 0, "componentType": 5123},
            "values": {"bufferView": 99},
        }
    elif case == "accessor count 0":
        doc["accessors"][0]["count"] = 0
    elif case == "accessor past its view":
        doc["accessors"][0]["count"] = 400
    elif case == "missing default scene":
        doc["scene"] = 3
    elif case == "primitive refers to a missing material":
        doc["meshes"][0]["primitives"][0]["material"] = 99
    elif case == "children not a list":
        doc["nodes"][0]["children"] = 5
    elif case == "index count not a multiple of 3":
        doc["meshes"][0]["primitives"][0]["indices"] = gltf.accessor([0, 1, 2, 3], "u2")


BROKEN = {
    "index past the vertices": "index 1000 is outside the vertices 0..3",
    "byteStride 1": "byteStride 1 must be a multiple of 4",
    "node refers to a missing mesh": "node 0 refers to meshes 55, which does not exist",
    "bogus mode": "mode 99 is not a glTF primitive mode",
    "unsupported required extension": "KHR_draco_mesh_compression",
    "node cycle": "node",
    "sparse values in a missing view": "refers to bufferViews 99",
    "accessor count 0": "count 0 must be a whole number >= 1",
    "accessor past its view": "accessor 0 needs 4800 bytes of its bufferView",
    "missing default scene": "the default scene refers to scenes 3",
    "index count not a multiple of 3": "4 indices do not make whole triangles",
    "primitive refers to a missing material": "refers to materials 99, which does not exist",
    "children not a list": "node 0: children is not a list",
}


@pytest.mark.parametrize("case", sorted(BROKEN))
@pytest.mark.parametrize("container", ["gltf", "glb"])
def test_malformed_files_are_refused_by_name(tmp_path: Path, case: str, container: str) -> None:
    gltf = _floor_and_lamp()
    _broken(gltf, case)
    if container == "gltf":
        path = gltf.write_gltf(tmp_path / "a.gltf")
    else:
        path = gltf.write_glb(tmp_path / "a.glb")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert message.startswith(str(path)) and BROKEN[case] in message and "\n" not in message


def test_buffer_outside_the_folder_missing_or_a_fifo(tmp_path: Path) -> None:
    (tmp_path / "scene").mkdir()
    gltf = _floor_and_lamp()
    path = gltf.write_gltf(tmp_path / "scene" / "a.gltf", buffer_file="../a.bin")
    with pytest.raises(SceneError, match="outside the scene folder"):
        load_scene(path)
    assert measure(load_scene(path, allow_outside=True)).triangles == 4
    (tmp_path / "a.bin").unlink()
    with pytest.raises(SceneError, match=r"buffer 0 '\.\./a\.bin' not found"):
        load_scene(path, allow_outside=True)
    if hasattr(os, "mkfifo"):
        path = gltf.write_gltf(tmp_path / "scene" / "b.gltf", buffer_file="pipe.bin")
        (tmp_path / "scene" / "pipe.bin").unlink()
        os.mkfifo(tmp_path / "scene" / "pipe.bin")
        with pytest.raises(SceneError, match=r"'pipe\.bin' is not a regular file"):
            load_scene(path)
