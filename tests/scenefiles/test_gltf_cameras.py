"""glTF cameras: node transforms composed by hand, pinhole frames, and errors naming the file."""

from __future__ import annotations

import json
import logging
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from raytrad.errors import SceneError, SettingsError
from raytrad.scene import NamedCamera
from raytrad.scenefiles import read_gltf_cameras

YFOV = 0.7  # [rad]
S = math.sqrt(0.5)  # sin 45 deg = cos 45 deg
#: Quaternions (x, y, z, w) of +90 degrees about Y and about X.
Y90 = [0.0, S, 0.0, S]
X90 = [S, 0.0, 0.0, S]
PERSPECTIVE = {"type": "perspective", "perspective": {"yfov": YFOV, "znear": 0.1}}


def _write(directory: Path, nodes: list[Any], **document: Any) -> Path:
    """A .gltf file with these nodes, one perspective camera unless given, and one scene."""
    document.setdefault("cameras", [PERSPECTIVE])
    document.setdefault("scenes", [{"nodes": [0]}])
    path = directory / "cameras.gltf"
    path.write_text(json.dumps({"asset": {"version": "2.0"}, "nodes": nodes, **document}))
    return path


def _only(path: Path, scale: float = 1.0) -> NamedCamera:
    [named] = read_gltf_cameras(path, scale)
    return named


def _frame(named: NamedCamera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position [m], unit forward and unit up as read from the Camera fields."""
    camera = named.camera
    forward = np.subtract(camera.look_at, camera.position)
    return np.array(camera.position), forward / np.linalg.norm(forward), np.array(camera.up)


def _translate(t: list[float]) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = t
    return m


# Rotation matrices written out by hand (columns = images of the x, y, z axes).
ROT_Y90 = np.array([[0, 0, 1, 0], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]], dtype=float)
ROT_X90 = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], dtype=float)


# --------------------------------------------------------------------------- transforms


def test_translated_camera_looks_down_minus_z_with_y_up(tmp_path: Path) -> None:
    named = _only(_write(tmp_path, [{"camera": 0, "translation": [1, 2, 3]}]))
    position, forward, up = _frame(named)
    np.testing.assert_allclose(position, [1, 2, 3])
    np.testing.assert_allclose(forward, [0, 0, -1])
    np.testing.assert_allclose(up, [0, 1, 0])
    assert named.camera.vertical_fov_deg == pytest.approx(YFOV * 180 / math.pi)
    assert named.aspect_ratio is None
    _, basis_up, basis_forward = named.camera.basis()
    np.testing.assert_allclose(basis_forward, [0, 0, -1])
    np.testing.assert_allclose(basis_up, [0, 1, 0])


def test_quarter_turn_about_y_faces_minus_x(tmp_path: Path) -> None:
    named = _only(_write(tmp_path, [{"camera": 0, "rotation": Y90}]))
    _, forward, up = _frame(named)
    np.testing.assert_allclose(forward, [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(up, [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(named.camera.basis()[2], [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(named.camera.position, [0, 0, 0], atol=1e-12)


def test_nested_nodes_compose_parent_then_child(tmp_path: Path) -> None:
    nodes = [
        {"translation": [10, 0, 0], "rotation": Y90, "children": [1]},
        {"camera": 0, "translation": [0, 0, -2], "rotation": X90},
    ]
    position, forward, up = _frame(_only(_write(tmp_path, nodes)))
    world = _translate([10, 0, 0]) @ ROT_Y90 @ _translate([0, 0, -2]) @ ROT_X90
    np.testing.assert_allclose(position, world[:3, 3], atol=1e-12)
    np.testing.assert_allclose(forward, world[:3, :3] @ [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(up, world[:3, :3] @ [0, 1, 0], atol=1e-12)
    # The same worked by hand: R_y(90) takes (0, 0, -2) to (-2, 0, 0); R_x(90) turns
    # -Z into +Y (kept by R_y) and +Y into +Z, which R_y(90) turns into +X.
    np.testing.assert_allclose(position, [8, 0, 0], atol=1e-12)
    np.testing.assert_allclose(forward, [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(up, [1, 0, 0], atol=1e-12)


def test_matrix_form_equals_trs_form(tmp_path: Path) -> None:
    trs = {"translation": [1, -2, 3], "rotation": X90, "scale": [2, 3, 4]}
    matrix = _translate([1, -2, 3]) @ ROT_X90 @ np.diag([2.0, 3.0, 4.0, 1.0])
    column_major = matrix.flatten(order="F").tolist()
    from_trs = _only(_write(tmp_path, [{"camera": 0, **trs}]))
    from_matrix = _only(_write(tmp_path, [{"camera": 0, "matrix": column_major}]))
    for a, b in zip(_frame(from_trs), _frame(from_matrix), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(_frame(from_matrix)[0], [1, -2, 3])


def test_non_uniform_parent_scale_tilts_the_view_like_geometry(tmp_path: Path) -> None:
    nodes = [
        {"scale": [2, 1, 1], "children": [1]},
        {"camera": 0, "rotation": [0.0, math.sin(math.pi / 8), 0.0, math.cos(math.pi / 8)]},
    ]
    _, forward, up = _frame(_only(_write(tmp_path, nodes)))
    # R_y(45) takes -Z to (-s, 0, -s); stretching x by 2 gives (-2, 0, -1) / sqrt(5).
    np.testing.assert_allclose(forward, np.array([-2, 0, -1]) / math.sqrt(5), atol=1e-12)
    np.testing.assert_allclose(up, [0, 1, 0], atol=1e-12)


def test_scale_multiplies_position_only(tmp_path: Path) -> None:
    path = _write(tmp_path, [{"camera": 0, "translation": [1000, 2000, -500], "rotation": Y90}])
    metres = _only(path, scale=0.001)
    units = _only(path)
    np.testing.assert_allclose(metres.camera.position, [1, 2, -0.5])
    np.testing.assert_allclose(_frame(metres)[1], _frame(units)[1], atol=1e-12)
    np.testing.assert_allclose(_frame(metres)[1], [-1, 0, 0], atol=1e-12)
    assert metres.camera.vertical_fov_deg == units.camera.vertical_fov_deg
    with pytest.raises(SettingsError, match="scale"):
        read_gltf_cameras(path, scale=0.0)


# --------------------------------------------------------------------------- files and scenes


def test_glb_file_and_aspect_ratio(tmp_path: Path) -> None:
    camera = {"type": "perspective", "perspective": {"yfov": 0.5, "aspectRatio": 1.5}}
    document = {
        "asset": {"version": "2.0"},
        "cameras": [camera],
        "nodes": [{"camera": 0, "translation": [0, 1, 2], "name": "Main"}],
        "scenes": [{"nodes": [0]}],
    }
    chunk = json.dumps(document).encode()
    chunk += b" " * (-len(chunk) % 4)
    binary = struct.pack("<II", 4, 0x004E4942) + b"\0" * 4  # a BIN chunk after the JSON one
    glb = (
        struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(chunk) + len(binary))
        + struct.pack("<II", len(chunk), 0x4E4F534A)
        + chunk
        + binary
    )
    path = tmp_path / "camera.glb"
    path.write_bytes(glb)
    named = _only(path)
    assert named.name == "Main"
    assert named.aspect_ratio == 1.5
    assert named.camera.vertical_fov_deg == pytest.approx(math.degrees(0.5))
    np.testing.assert_allclose(named.camera.position, [0, 1, 2])


def test_names_fall_back_from_node_to_camera_to_index(tmp_path: Path) -> None:
    cameras = [{**PERSPECTIVE, "name": "lens"}, PERSPECTIVE]
    nodes = [{"children": [1, 2, 3]}, {"camera": 0, "name": "node"}, {"camera": 0}, {"camera": 1}]
    names = [n.name for n in read_gltf_cameras(_write(tmp_path, nodes, cameras=cameras))]
    assert names == ["node", "lens", "camera 1"]


def test_only_the_selected_scene_is_read(tmp_path: Path) -> None:
    nodes = [{"camera": 0, "name": "A"}, {"camera": 0, "name": "B"}]
    scenes = [{"nodes": [0]}, {"nodes": [1]}]
    selected = read_gltf_cameras(_write(tmp_path, nodes, scenes=scenes, scene=1))
    assert [n.name for n in selected] == ["B"]
    default = read_gltf_cameras(_write(tmp_path, nodes, scenes=scenes))
    assert [n.name for n in default] == ["A"]


def test_without_scenes_every_root_node_is_read(tmp_path: Path) -> None:
    nodes = [
        {"camera": 0, "name": "root"},
        {"translation": [0, 0, 1], "children": [2]},
        {"camera": 0, "name": "child", "translation": [0, 0, 1]},
    ]
    path = tmp_path / "cameras.gltf"
    document = {"asset": {"version": "2.0"}, "cameras": [PERSPECTIVE], "nodes": nodes}
    path.write_text(json.dumps(document))
    found = {n.name: n.camera.position for n in read_gltf_cameras(path)}
    assert found == {"root": (0.0, 0.0, 0.0), "child": (0.0, 0.0, 2.0)}


def test_file_without_cameras_gives_none(tmp_path: Path) -> None:
    assert read_gltf_cameras(_write(tmp_path, [{"mesh": 0}], cameras=[])) == []
    assert read_gltf_cameras(_write(tmp_path, [])) == []


def test_orthographic_camera_is_skipped_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    ortho = {"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0, "zfar": 9}}
    nodes = [{"children": [1, 2]}, {"camera": 0, "name": "plan"}, {"camera": 1, "name": "eye"}]
    path = _write(tmp_path, nodes, cameras=[ortho, PERSPECTIVE])
    with caplog.at_level(logging.WARNING, logger="raytrad.scenefiles.gltf_cameras"):
        found = read_gltf_cameras(path)
    assert [n.name for n in found] == ["eye"]
    [record] = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert "cameras.gltf" in record.getMessage()
    assert "'plan'" in record.getMessage()
    assert "orthographic" in record.getMessage()


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize("yfov", [0, -0.5, math.pi, 4.0, None, "wide", True])
def test_bad_yfov_names_the_file(tmp_path: Path, yfov: object) -> None:
    perspective = {} if yfov is None else {"yfov": yfov}
    cameras = [{"type": "perspective", "perspective": perspective}]
    with pytest.raises(SceneError, match="yfov") as caught:
        read_gltf_cameras(_write(tmp_path, [{"camera": 0}], cameras=cameras))
    assert "cameras.gltf" in str(caught.value)


@pytest.mark.parametrize(
    ("node", "cameras", "message"),
    [
        ({"camera": 1}, [PERSPECTIVE], "camera is 1"),
        ({"camera": 0}, [], "camera is 0"),
        ({"camera": 0, "rotation": [0, 0, 0, 0]}, [PERSPECTIVE], "zero quaternion"),
        ({"camera": 0, "rotation": [0, 0, 1]}, [PERSPECTIVE], "rotation must be"),
        ({"camera": 0, "translation": [0, float("nan"), 0]}, [PERSPECTIVE], "non-finite"),
        ({"camera": 0, "matrix": [1.0] * 15 + [float("inf")]}, [PERSPECTIVE], "non-finite"),
        ({"camera": 0, "matrix": [1, 0, 0, 0] * 4}, [PERSPECTIVE], "not affine"),
        ({"camera": 0, "scale": [1, 0, 1]}, [PERSPECTIVE], "degenerate"),
        ({"camera": 0, "scale": [1, 1, 0]}, [PERSPECTIVE], "degenerate"),
        ({"camera": 0}, [{"type": "fisheye"}], "neither a perspective"),
        ({"camera": 0}, [{**PERSPECTIVE, "perspective": {"yfov": 1, "aspectRatio": 0}}], "aspect"),
        ({"camera": 0, "children": [0]}, [PERSPECTIVE], "cycle"),
        ({"camera": 0, "children": [5]}, [PERSPECTIVE], "children has 5"),
    ],
)
def test_malformed_camera_data_names_the_file_and_problem(
    tmp_path: Path, node: dict[str, Any], cameras: list[Any], message: str
) -> None:
    with pytest.raises(SceneError, match=message) as caught:
        read_gltf_cameras(_write(tmp_path, [node], cameras=cameras))
    assert caught.value.path == tmp_path / "cameras.gltf"


def test_sheared_matrix_with_view_along_up_is_degenerate(tmp_path: Path) -> None:
    matrix = np.eye(4)
    matrix[:3, 2] = [0, -1, 0]  # local -Z goes to +Y, the image of local +Y
    nodes = [{"camera": 0, "matrix": matrix.flatten(order="F").tolist()}]
    with pytest.raises(SceneError, match="parallel"):
        read_gltf_cameras(_write(tmp_path, nodes))


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("broken.gltf", b"{not json", "cannot parse as glTF"),
        ("list.gltf", b"[1, 2]", "not a glTF file"),
        ("no-asset.gltf", b'{"nodes": []}', "not a glTF file"),
        ("old.gltf", b'{"asset": {"version": "1.0"}}', "version '1.0'"),
        ("text.glb", b'{"asset": {"version": "2.0"}} padding', "bad magic"),
        ("v1.glb", struct.pack("<4sIIII", b"glTF", 1, 20, 0, 0x4E4F534A), "version 1"),
        ("short.glb", struct.pack("<4sIIII", b"glTF", 2, 99, 0, 0x4E4F534A), "truncated"),
    ],
)
def test_not_a_gltf_file(tmp_path: Path, name: str, content: bytes, message: str) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(SceneError, match=message) as caught:
        read_gltf_cameras(path)
    assert name in str(caught.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match="not found"):
        read_gltf_cameras(tmp_path / "absent.gltf")
