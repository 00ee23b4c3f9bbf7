"""Scene-file cameras: written by write_glb and read back, chosen by name for a render
(api.render, ``--view``), and the image size taken from the camera's aspect ratio."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from raytrad import api
from raytrad.core.hidden import fill_hidden
from raytrad.core.mesh import MeshSettings, build_mesh
from raytrad.errors import SettingsError
from raytrad.formats.images import read_attributes, read_image
from raytrad.products.framing import file_camera, framing_camera, image_view
from raytrad.products.image import render_radiance
from raytrad.scene import Camera, NamedCamera, Scene
from raytrad.scene.builtin import CORNELL_CAMERA, cornell_box
from raytrad.scenefiles import gltf as gltf_reader
from raytrad.scenefiles import load_scene, read_gltf_cameras, write_glb
from raytrad.settings import ImageSettings, RenderSettings
from tests.conftest import CORNELL_OBJECTS, REPOSITORY, SCENES, run_cli

MESH = MeshSettings(receivers=500, patches=60)
CORNELL_UV = SCENES / "cornell-box-uv.glb"
COLOUR_ROOM = SCENES / "colour-room.toml"
CORNELL_OBJ = SCENES / "cornell-box.obj"
SCHEMA_PATH = REPOSITORY / "docs" / "report.schema.json"
SMALL = ["--receivers", "500", "--patches", "60", "-q"]
#: The "corner" camera of cornell-box-uv.glb (tools/make_scenes.py).
CORNER = Camera((0.5, 0.45, 0.05), (0.1, 0.1, 0.5), vertical_fov_deg=50.0)


def _assert_same_camera(got: Camera, expected: Camera, atol: float = 1e-6) -> None:
    """Same position, frame (right, up, forward) and vertical field of view."""
    np.testing.assert_allclose(got.position, expected.position, rtol=0, atol=atol)
    for a, b, axis in zip(got.basis(), expected.basis(), ("right", "up", "forward"), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=atol, err_msg=axis)
    assert got.vertical_fov_deg == pytest.approx(expected.vertical_fov_deg, abs=atol)


def _sorted_rows(corners: np.ndarray) -> np.ndarray:
    """(T, 3) triangle centroids in lexicographic order (rounded to 1e-5 m for the sort)."""
    centroids = corners.mean(axis=1)
    key = np.round(centroids, 5)
    return centroids[np.lexsort(key.T[::-1])]


def _render(
    out: Path, image: ImageSettings, scene: Path = CORNELL_UV, **extra: object
) -> api.RenderOutcome:
    return api.render(scene, out, RenderSettings(mesh=MESH, image=image, **extra))


# --------------------------------------------------------------------------------------
# The built-in scene and the bundled file
# --------------------------------------------------------------------------------------


def test_cornell_box_has_eight_named_objects() -> None:
    scene = cornell_box()
    assert tuple(scene.object_names) == CORNELL_OBJECTS
    counts = np.bincount(scene.object_index, minlength=len(CORNELL_OBJECTS))
    # six quads (two triangles) and two blocks of five quads
    np.testing.assert_array_equal(counts, [2, 2, 2, 2, 2, 2, 10, 10])
    emitting = (scene.emitted_exitance > 0).any(axis=1)
    np.testing.assert_array_equal(emitting, scene.object_index == CORNELL_OBJECTS.index("light"))
    # the blocks stand on the floor (y = 0) and reach up to their tops
    for block, top in (("short-block", 0.165), ("tall-block", 0.33)):
        corners = scene.triangle_vertices()[scene.object_index == CORNELL_OBJECTS.index(block)]
        assert corners[..., 1].min() == pytest.approx(0.0, abs=1e-9)
        assert corners[..., 1].max() == pytest.approx(top, abs=1e-9)


def test_bundled_uv_scene_is_the_cornell_box_with_two_cameras() -> None:
    scene = load_scene(CORNELL_UV, uv_set=1)
    box = cornell_box()
    assert set(scene.object_names) == set(CORNELL_OBJECTS)
    for name in CORNELL_OBJECTS:
        mine = scene.triangle_vertices()[scene.object_index == scene.object_names.index(name)]
        theirs = box.triangle_vertices()[box.object_index == box.object_names.index(name)]
        assert len(mine) == len(theirs), name
        np.testing.assert_allclose(_sorted_rows(mine), _sorted_rows(theirs), atol=1e-6)
    assert scene.lightmap_uv is not None
    assert np.isfinite(scene.lightmap_uv).all()
    assert scene.lightmap_uv.min() >= 0 and scene.lightmap_uv.max() <= 1

    front, corner = read_gltf_cameras(CORNELL_UV)
    assert (front.name, corner.name) == ("front", "corner")
    _assert_same_camera(front.camera, CORNELL_CAMERA)
    _assert_same_camera(corner.camera, CORNER)
    assert front.aspect_ratio == pytest.approx(1.0)
    assert corner.aspect_ratio == pytest.approx(16 / 9)


# --------------------------------------------------------------------------------------
# write_glb cameras round trip
# --------------------------------------------------------------------------------------

ORIENTATIONS = {
    # (position, look_at, up)
    "arbitrary": ((0.3, -1.2, 2.5), (1.1, 0.4, -0.7), (0.2, 0.9, -0.3)),
    "identity": ((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
    "half-turn-about-y": ((1.0, 2.0, 3.0), (1.0, 2.0, 4.0), (0.0, 1.0, 0.0)),  # looks +z
    "half-turn-about-x": ((0.0, 0.5, 0.0), (0.0, 0.5, 5.0), (0.0, -1.0, 0.0)),
    "half-turn-about-z": ((0.2, 0.0, 0.0), (0.2, 0.0, -2.0), (0.0, -1.0, 0.0)),
    "almost-half-turn": ((0.0, 0.0, 0.0), (1e-7, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "looking-down": ((0.0, 3.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, -1.0)),
    "looking-up": ((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), (1.0, 0.0, 1.0)),
}


@pytest.mark.parametrize("orientation", list(ORIENTATIONS))
def test_write_glb_camera_round_trip(tmp_path: Path, orientation: str) -> None:
    position, look_at, up = ORIENTATIONS[orientation]
    camera = Camera(position, look_at, up, 27.5)
    path = tmp_path / "scene.glb"
    write_glb(cornell_box(), path, [NamedCamera("view", camera, 1.5)])
    (named,) = read_gltf_cameras(path)
    assert named.name == "view"
    assert named.aspect_ratio == pytest.approx(1.5)
    _assert_same_camera(named.camera, camera)
    # a glTF camera looks along its local -Z: the read look_at is one metre ahead
    forward = np.subtract(look_at, position)
    np.testing.assert_allclose(
        np.subtract(named.camera.look_at, named.camera.position),
        forward / np.linalg.norm(forward),
        atol=1e-6,
    )


def test_write_glb_keeps_several_cameras_and_the_geometry(tmp_path: Path) -> None:
    cameras = [
        NamedCamera("a", CORNELL_CAMERA, None),
        NamedCamera("b", CORNER, 16 / 9),
        NamedCamera("c", Camera((1, 1, 1), (0, 0, 0), (0, 0, 1), 80.0), 0.5),
    ]
    path = tmp_path / "scene.glb"
    box = cornell_box()
    write_glb(box, path, cameras)
    read = read_gltf_cameras(path)
    assert [c.name for c in read] == ["a", "b", "c"]
    assert [c.aspect_ratio for c in read] == [None, pytest.approx(16 / 9), pytest.approx(0.5)]
    for got, expected in zip(read, cameras, strict=True):
        _assert_same_camera(got.camera, expected.camera)
    # scale multiplies positions only
    for got, expected in zip(read_gltf_cameras(path, 2.0), cameras, strict=True):
        np.testing.assert_allclose(got.camera.position, 2.0 * np.array(expected.camera.position))
        np.testing.assert_allclose(got.camera.basis()[2], expected.camera.basis()[2], atol=1e-6)
    # camera nodes add no geometry; each object is one node
    scene = load_scene(path)
    assert scene.triangle_count == box.triangle_count
    assert set(scene.object_names) == set(CORNELL_OBJECTS)
    assert np.allclose(np.sort(scene.positions.ravel()), np.sort(box.positions.ravel()), atol=1e-6)


def test_write_glb_without_cameras_has_none(tmp_path: Path) -> None:
    path = tmp_path / "scene.glb"
    write_glb(cornell_box(), path)
    assert read_gltf_cameras(path) == []
    header = path.read_bytes()
    assert b'"cameras"' not in header


# --------------------------------------------------------------------------------------
# Choosing the camera: file_camera, image_view
# --------------------------------------------------------------------------------------


def _load_camera(path: Path, settings: RenderSettings) -> tuple[Scene, NamedCamera | None]:
    """The scene and the file camera a render with ``settings`` would use."""
    loaded = api.load(path, settings)
    image = settings.image
    if image is None:
        return loaded.scene, None
    return loaded.scene, file_camera(loaded.cameras, image.view, Path(path), loaded.kind)


@pytest.fixture
def no_camera_reading(monkeypatch: pytest.MonkeyPatch) -> list[Path]:
    """Record every reading of a glTF document's cameras (still reading)."""
    calls: list[Path] = []
    real = gltf_reader.cameras_from_document

    def recording(path: Path, document: dict[str, object], scale: float = 1.0) -> object:
        calls.append(Path(path))
        return real(path, document, scale)

    monkeypatch.setattr(gltf_reader, "cameras_from_document", recording)
    return calls


def test_gltf_cameras_are_read_only_for_an_image(no_camera_reading: list[Path]) -> None:
    scene, camera = _load_camera(CORNELL_UV, RenderSettings())
    assert camera is None and scene.triangle_count == 32
    assert no_camera_reading == []
    _, camera = _load_camera(CORNELL_UV, RenderSettings(image=ImageSettings()))
    assert camera is not None and camera.name == "front"
    assert no_camera_reading == [CORNELL_UV]


def test_gltf_file_is_parsed_once_for_geometry_and_cameras(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    parsed: list[str] = []
    real = gltf_reader.parse_json

    def counting(path: Path, data: bytes, label: str) -> object:
        parsed.append(label)
        return real(path, data, label)

    monkeypatch.setattr(gltf_reader, "parse_json", counting)
    _, camera = _load_camera(CORNELL_UV, RenderSettings(image=ImageSettings(view="corner")))
    assert camera is not None and camera.name == "corner"
    assert parsed == ["GLB"]


@pytest.mark.parametrize(
    ("view", "expected"), [(None, "front"), ("front", "front"), ("corner", "corner")]
)
def test_load_picks_the_camera_by_name(view: str | None, expected: str) -> None:
    settings = RenderSettings(image=ImageSettings(view=view))
    _, camera = _load_camera(CORNELL_UV, settings)
    assert camera is not None and camera.name == expected
    _assert_same_camera(camera.camera, CORNELL_CAMERA if expected == "front" else CORNER)


def test_load_scale_moves_the_camera() -> None:
    settings = RenderSettings(scale=10.0, image=ImageSettings(view="corner"))
    scene, camera = _load_camera(CORNELL_UV, settings)
    assert camera is not None
    np.testing.assert_allclose(camera.camera.position, 10.0 * np.array(CORNER.position))
    assert scene.positions.max() == pytest.approx(10.0 * cornell_box().positions.max(), rel=1e-6)


def test_unknown_view_lists_the_cameras() -> None:
    settings = RenderSettings(image=ImageSettings(view="side"))
    with pytest.raises(SettingsError) as caught:
        _load_camera(CORNELL_UV, settings)
    message = str(caught.value)
    assert "'side'" in message and "'front'" in message and "'corner'" in message
    assert "cornell-box-uv.glb" in message


def test_view_of_a_file_without_cameras(tmp_path: Path) -> None:
    path = tmp_path / "bare.glb"
    write_glb(cornell_box(), path)
    _, camera = _load_camera(path, RenderSettings(image=ImageSettings()))
    assert camera is None
    with pytest.raises(SettingsError, match="none"):
        _load_camera(path, RenderSettings(image=ImageSettings(view="front")))


def test_toml_camera_and_its_name() -> None:
    _, camera = _load_camera(COLOUR_ROOM, RenderSettings(image=ImageSettings()))
    assert camera is not None and camera.name == "camera" and camera.aspect_ratio is None
    _assert_same_camera(camera.camera, CORNELL_CAMERA)
    _, named = _load_camera(COLOUR_ROOM, RenderSettings(image=ImageSettings(view="camera")))
    assert named == camera
    with pytest.raises(SettingsError, match="'front'"):
        _load_camera(COLOUR_ROOM, RenderSettings(image=ImageSettings(view="front")))


def test_view_for_an_obj_is_refused() -> None:
    _, camera = _load_camera(CORNELL_OBJ, RenderSettings(image=ImageSettings()))
    assert camera is None
    with pytest.raises(SettingsError, match="cameras"):
        _load_camera(CORNELL_OBJ, RenderSettings(image=ImageSettings(view="front")))


@pytest.fixture(scope="module")
def small_mesh() -> object:
    return build_mesh(cornell_box(), MeshSettings(receivers=300, patches=20))


@pytest.mark.parametrize(
    ("aspect", "width", "height", "expected"),
    [
        (16 / 9, None, 48, 85),  # round(85.33)
        (16 / 9, None, 24, 43),  # round(42.67)
        (1.0, None, 48, 48),
        (0.5, None, 31, 16),  # round(15.5) = 16 (half to even)
        (0.01, None, 10, 1),  # never below one pixel
        (None, None, 48, 640),
        (16 / 9, 100, 48, 100),  # a given width wins
    ],
)
def test_image_view_width_from_the_aspect_ratio(
    small_mesh: object, aspect: float | None, width: int | None, height: int, expected: int
) -> None:
    named = NamedCamera("corner", CORNER, aspect)
    camera, got, origin = image_view(small_mesh, None, named, width, height)  # type: ignore[arg-type]
    assert camera == CORNER and origin == "corner"
    assert got == expected


def test_image_view_without_a_file_camera(small_mesh: object) -> None:
    camera, width, origin = image_view(small_mesh, None, None, None, 48)  # type: ignore[arg-type]
    assert width == 640 and origin == "automatic framing"
    assert camera == framing_camera(small_mesh.positions)  # type: ignore[attr-defined]
    given = Camera((0, 0, -1), (0, 0, 0))
    named = NamedCamera("c", CORNER, 2.0)
    camera, width, origin = image_view(small_mesh, given, named, None, 48)  # type: ignore[arg-type]
    assert camera == given and width == 640  # the settings' camera beats the file's
    assert origin == "settings"


# --------------------------------------------------------------------------------------
# Renders
# --------------------------------------------------------------------------------------


def test_render_from_the_corner_camera(tmp_path: Path) -> None:
    image = ImageSettings(height=48, samples=1, view="corner")
    outcome = _render(tmp_path, image)
    camera = outcome.report["outputs_detail"]["camera"]
    assert camera["name"] == "corner"
    np.testing.assert_allclose(camera["position"], CORNER.position, atol=1e-6)
    assert camera["vertical_fov_deg"] == pytest.approx(50.0)
    pixels = read_image(tmp_path / "cornell-box-uv.exr")
    assert pixels.shape[:2] == (48, 85)
    assert read_image(tmp_path / "cornell-box-uv.png").shape[:2] == (48, 85)
    assert read_attributes(tmp_path / "cornell-box-uv.exr")["raytrad:quantity"] == "radiance"
    # the pixels are those of the solution seen from that camera
    prepared, result = outcome.prepared, outcome.result
    shown = fill_hidden(prepared.mesh, result.radiosity)
    named = read_gltf_cameras(CORNELL_UV)[1]
    expected = render_radiance(prepared.mesh, shown, named.camera, 85, 48, 1)
    np.testing.assert_allclose(pixels[..., :3], expected, rtol=1e-6, atol=1e-9)
    assert (expected > 0).mean() > 0.5  # it sees the room
    # the report on disk says the same, and matches its schema
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["outputs_detail"]["camera"]["name"] == "corner"
    assert report["settings"]["image"]["view"] == "corner"
    schema = json.loads(SCHEMA_PATH.read_text())
    jsonschema.Draft202012Validator(schema).validate(report)


def test_render_from_the_first_camera_by_default(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.INFO, logger="raytrad.products.framing"):
        outcome = _render(tmp_path, ImageSettings(height=20, samples=1))
    assert outcome.report["outputs_detail"]["camera"]["name"] == "front"
    assert read_image(tmp_path / "cornell-box-uv.exr").shape[:2] == (20, 20)  # aspect 1
    said = [r.getMessage() for r in caplog.records if "cameras" in r.getMessage()]
    assert said and "'corner'" in said[0] and "--view" in said[0]


def test_render_unknown_view_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(SettingsError) as caught:
        _render(out, ImageSettings(height=20, view="nope"))
    assert "'front'" in str(caught.value) and "'corner'" in str(caught.value)
    assert not out.exists()


def test_render_toml_camera(tmp_path: Path) -> None:
    image = ImageSettings(width=24, height=16, samples=1)
    outcome = _render(tmp_path, image, COLOUR_ROOM)
    camera = outcome.report["outputs_detail"]["camera"]
    assert camera["name"] == "camera"
    np.testing.assert_allclose(camera["position"], CORNELL_CAMERA.position, atol=1e-9)
    np.testing.assert_allclose(camera["look_at"], CORNELL_CAMERA.look_at, atol=1e-9)
    assert read_image(tmp_path / "colour-room.exr").shape[:2] == (16, 24)


def test_render_obj_view_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(SettingsError):
        _render(out, ImageSettings(height=20, view="front"), CORNELL_OBJ)
    assert not out.exists()
    outcome = _render(out, ImageSettings(height=12, width=16, samples=1), CORNELL_OBJ)
    assert outcome.report["outputs_detail"]["camera"]["name"] == "automatic framing"


def test_render_settings_camera_is_named_settings(tmp_path: Path) -> None:
    image = ImageSettings(height=12, samples=1, camera=CORNELL_CAMERA, view="corner")
    outcome = _render(tmp_path, image)
    camera = outcome.report["outputs_detail"]["camera"]
    assert camera["name"] == "settings"
    np.testing.assert_allclose(camera["position"], CORNELL_CAMERA.position)
    assert read_image(tmp_path / "cornell-box-uv.exr").shape[:2] == (12, 640)


# --------------------------------------------------------------------------------------
# The command line
# --------------------------------------------------------------------------------------


def test_view_without_image_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    status, stdout, err = run_cli(
        ["render", str(CORNELL_UV), "-o", str(out), "--view", "x", *SMALL], capsys
    )
    assert status != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "--view" in lines[0] and "--image" in lines[0], err
    assert stdout == "" and not out.exists()


@pytest.mark.parametrize(
    ("scene", "view", "words"),
    [
        (CORNELL_UV, "nope", ["'nope'", "'front'", "'corner'"]),
        (CORNELL_OBJ, "front", ["cornell-box.obj", "cameras"]),
        (COLOUR_ROOM, "front", ["colour-room.toml", "'camera'"]),
    ],
)
def test_bad_view_is_one_line(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    scene: Path,
    view: str,
    words: list[str],
) -> None:
    out = tmp_path / "out"
    status, _, err = run_cli(
        ["render", str(scene), "-o", str(out), "--image", "--view", view, *SMALL], capsys
    )
    assert status == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("raytrad: error: "), err
    for word in words:
        assert word in lines[0]
    assert not out.exists() or not any(out.iterdir())


def test_cli_view_sets_camera_and_width(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    status, _, err = run_cli(
        [
            "render",
            str(CORNELL_UV),
            "-o",
            str(out),
            "--image",
            "--height",
            "24",
            "--spp",
            "1",
            "--view",
            "corner",
            *SMALL,
        ],
        capsys,
    )
    assert status == 0, err
    assert read_image(out / "cornell-box-uv.exr").shape[:2] == (24, round(24 * 16 / 9))
    report = json.loads((out / "report.json").read_text())
    assert report["outputs_detail"]["camera"]["name"] == "corner"
    assert report["settings"]["image"]["width"] is None
    assert math.isclose(report["outputs_detail"]["camera"]["vertical_fov_deg"], 50.0)
