"""Camera renders and the glTF export, checked against what the solution must look like."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from raytrad import api
from raytrad.cli import main
from raytrad.core.mesh import MeshSettings, RadiosityMesh
from raytrad.core.pipeline import Prepared, prepare
from raytrad.core.shading import twin_triangles
from raytrad.core.solver import SolveResult
from raytrad.formats.images import read_image
from raytrad.products.framing import automatic_camera, framing_camera
from raytrad.products.image import render_radiance
from raytrad.scene import Camera, Scene, make_scene
from raytrad.scene.builtin import cornell_box, furnace_box
from raytrad.settings import RenderSettings
from tests.conftest import REPOSITORY

CORNELL_CAMERA = Camera((0.278, 0.273, -0.8), (0.278, 0.273, 0.0), (0.0, 1.0, 0.0), 39.3)


@pytest.fixture(scope="module")
def cornell_solved() -> tuple[Prepared, SolveResult]:
    """The Cornell box at 4000 receivers, solved and refined."""
    return api.solve_scene(
        cornell_box(), RenderSettings(mesh=MeshSettings(receivers=4000, patches=200))
    )


@pytest.fixture(scope="module")
def cornell_image(cornell_solved: tuple[Prepared, SolveResult]) -> np.ndarray:
    prepared, result = cornell_solved
    return render_radiance(prepared.mesh, result.radiosity, CORNELL_CAMERA, 96, 96, 4)


def test_furnace_renders_to_uniform_radiance() -> None:
    rho, exitance = 0.5, 1.0
    prepared, result = api.solve_scene(
        furnace_box(rho, exitance), RenderSettings(mesh=MeshSettings(receivers=1500))
    )
    camera = Camera((0.5, 0.5, 0.5), (0.5, 0.5, 1.0), (0.0, 1.0, 0.0), 70.0)
    image = render_radiance(prepared.mesh, result.radiosity, camera, 48, 32, 4)
    expected = exitance / (math.pi * (1.0 - rho))
    np.testing.assert_allclose(image, expected, rtol=1e-2)


def test_cornell_left_wall_is_redder_than_the_right(cornell_image: np.ndarray) -> None:
    # the red wall (x = 0.55 m) is on the image's left, the green one on its right
    rows = slice(30, 66)
    left, right = (
        cornell_image[rows, 2:9].mean(axis=(0, 1)),
        cornell_image[rows, -9:-2].mean(axis=(0, 1)),
    )
    assert left[0] / left[1] > 3.0 * right[0] / right[1]
    assert right[1] > right[0]


def test_region_under_the_light_is_the_brightest_receiving_area(
    cornell_solved: tuple[Prepared, SolveResult],
) -> None:
    prepared, result = cornell_solved
    mesh = prepared.mesh
    emitting = (mesh.receiver_emitted_exitance > 0).any(axis=1)
    lum = result.radiosity @ np.array([0.2126, 0.7152, 0.0722])
    lum[emitting] = -np.inf
    brightest = np.argsort(lum)[-20:]
    x, y, z = mesh.receiver_position[brightest].T
    # the lamp spans x 0.213..0.343, z 0.227..0.332 m at the ceiling, facing down
    assert (np.abs(x - 0.278) < 0.12).all() and (np.abs(z - 0.28) < 0.12).all()
    assert (y < 0.35).all() and (mesh.receiver_normal[brightest][:, 1] > 0.99).all()


def test_back_of_a_one_sided_face_is_black_and_two_sided_twins_pair_up() -> None:
    triangles = np.array([[0, 1, 2], [2, 1, 0], [0, 2, 3]])
    np.testing.assert_array_equal(twin_triangles(triangles), [1, 0, -1])


def test_framing_camera_sees_the_whole_box() -> None:
    positions = cornell_box().positions
    camera = framing_camera(positions)
    _, up, forward = camera.basis()
    rel = positions - np.asarray(camera.position)
    depth = rel @ forward
    assert (depth > 0).all()
    tan = math.tan(math.radians(camera.vertical_fov_deg) / 2.0)
    assert (np.abs(rel @ up) / depth <= tan * 1.001).all()


def _glb_json(path: Path) -> dict[str, object]:
    data = path.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    return dict(json.loads(data[20 : 20 + length]))


def test_render_writes_image_lightmap_and_gltf_that_load_back(tmp_path: Path) -> None:
    import trimesh

    out = tmp_path / "out"
    status = main(
        [
            "render",
            str(REPOSITORY / "scenes" / "furnace.obj"),
            "-o",
            str(out),
            "--receivers",
            "800",
            "--patches",
            "60",
            "-q",
            "--image",
            "--width",
            "40",
            "--height",
            "30",
            "--camera",
            "0.5,0.5,0.1:0.5,0.5,1",
            "--lightmap",
            "--lightmap-resolution",
            "128",
            "--gltf",
        ]
    )
    assert status == 0
    image = read_image(out / "furnace.exr")
    np.testing.assert_allclose(image[..., :3], 2.0 / math.pi, rtol=1e-2)
    lightmap = read_image(out / "furnace.lightmap.exr")
    covered = lightmap[..., :3] > 0
    np.testing.assert_allclose(lightmap[..., :3][covered], 2.0, rtol=1e-2)
    assert (out / "furnace.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    header = _glb_json(out / "furnace.glb")
    primitive = header["meshes"][0]["primitives"][0]  # type: ignore[index]
    assert {"POSITION", "NORMAL", "COLOR_0", "TEXCOORD_1"} <= set(primitive["attributes"])
    assert header["materials"][0]["emissiveTexture"]["texCoord"] == 1  # type: ignore[index]
    assert header["images"][0]["mimeType"] == "image/png"  # type: ignore[index]
    scene = trimesh.load(out / "furnace.glb", process=False)
    (loaded,) = scene.geometry.values()
    # with a texture, trimesh keeps COLOR_0 as a vertex attribute, the lightmap as the
    # material's emissive texture
    colours = np.asarray(loaded.visual.vertex_attributes["color"])[:, :3]
    assert loaded.visual.material.emissiveTexture.size == (128, 128)
    exposure = header["extras"]["raytrad"]["exposure"]  # type: ignore[index]
    # the solve's tolerance 1e-3 leaves up to about 2.3e-3 at the box's edges
    np.testing.assert_allclose(colours, min(1.0, 2.0 / math.pi * exposure), rtol=3e-3)
    view = header["bufferViews"][header["images"][0]["bufferView"]]  # type: ignore[index]
    data = (out / "furnace.glb").read_bytes()
    json_length = struct.unpack_from("<I", data, 12)[0]
    start = 20 + json_length + 8 + view["byteOffset"]
    png = data[start : start + view["byteLength"]]
    (tmp_path / "lightmap.png").write_bytes(png)
    assert read_image(tmp_path / "lightmap.png").shape[:2] == (128, 128)


def _prepared_mesh(scene: Scene) -> RadiosityMesh:
    prepared = prepare(scene, MeshSettings(receivers=600))
    prepared.close()
    return prepared.mesh


def test_automatic_camera_keeps_the_front_view_of_an_open_box() -> None:
    mesh = _prepared_mesh(cornell_box())
    camera = automatic_camera(mesh)
    assert camera == framing_camera(mesh.positions)


def test_automatic_camera_goes_inside_a_closed_room() -> None:
    # from outside, a closed room shows only the black backs of its walls
    mesh = _prepared_mesh(furnace_box(0.5, 1.0))
    camera = automatic_camera(mesh)
    lo, hi = mesh.positions.min(axis=0), mesh.positions.max(axis=0)
    assert (np.asarray(camera.position) > lo).all() and (np.asarray(camera.position) < hi).all()
    image = render_radiance(mesh, np.ones((mesh.receiver_count, 3)), camera, 32, 24, 1)
    assert (image > 0).all()  # every pixel sees the lit inside of a wall


def test_automatic_camera_of_a_flat_scene_sees_its_lit_side() -> None:
    # one upright quad facing -z: a flat bounding box, no inside to stand in
    quad = np.array([[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]], dtype=float)
    scene = make_scene(quad, [[0, 1, 2], [0, 2, 3]], [0, 0], ["m"], [[0.5] * 3], [[1.0] * 3])
    mesh = _prepared_mesh(scene)
    camera = automatic_camera(mesh)
    assert camera.position[2] < 0.0  # in front of the lit side
    image = render_radiance(mesh, np.ones((mesh.receiver_count, 3)), camera, 32, 24, 1)
    assert (image > 0).any()
