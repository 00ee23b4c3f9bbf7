"""Automatic framing sees the lit part of a scene, stands upright for z-up models, and the
image's exposure comes from what the camera sees."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from raytrad import api
from raytrad.core.mesh import MeshSettings
from raytrad.formats.images import read_image
from raytrad.products.framing import _candidate_cameras, framing_camera, up_vector
from raytrad.scene import Camera
from raytrad.scene.builtin import cornell_box
from raytrad.settings import ImageSettings, RenderSettings

# scene (x, y, z) of a y-up model -> the same model written z up: (x, -z, y)
Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _inward_quad(corners: list[tuple[float, float, float]], inside: np.ndarray) -> list[int]:
    """The quad's corner order whose normal points toward ``inside``."""
    p = np.array(corners)
    normal = np.cross(p[1] - p[0], p[2] - p[0])
    return [0, 1, 2, 3] if normal @ (inside - p.mean(axis=0)) > 0 else [3, 2, 1, 0]


def _rooms_obj(tmp_path: Path) -> Path:
    """Two closed 2 m rooms side by side (x in [0, 2] and [2.1, 4.1]), walls facing in,
    and a 0.6 m lamp under the first room's ceiling."""
    vertices: list[tuple[float, float, float]] = []
    lines = ["mtllib rooms.mtl"]

    def quad(corners: list[tuple[float, float, float]], inside: np.ndarray, material: str) -> None:
        lines.append(f"usemtl {material}")
        order = _inward_quad(corners, inside)
        start = len(vertices)
        vertices.extend(corners)
        lines.append("f " + " ".join(str(start + 1 + k) for k in order))

    for x0 in (0.0, 2.1):
        x1 = x0 + 2.0
        inside = np.array([x0 + 1.0, 1.0, 1.0])
        for axis in range(3):
            lo, hi = (x0, x1) if axis == 0 else (0.0, 2.0)
            for value in (lo, hi):
                corners = []
                for a, b in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    point = [0.0, 0.0, 0.0]
                    others = [k for k in range(3) if k != axis]
                    point[axis] = value
                    for k, t in zip(others, (a, b), strict=True):
                        point[k] = (x0, x1)[t] if k == 0 else (0.0, 2.0)[t]
                    corners.append((point[0], point[1], point[2]))
                quad(corners, inside, "wall")
    lamp = [(0.7, 1.99, 0.7), (1.3, 1.99, 0.7), (1.3, 1.99, 1.3), (0.7, 1.99, 1.3)]
    quad(lamp, np.array([1.0, 0.0, 1.0]), "lamp")
    (tmp_path / "rooms.mtl").write_text("newmtl wall\nKd 0.7 0.7 0.7\nnewmtl lamp\nKe 20 20 20\n")
    path = tmp_path / "rooms.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in vertices) + "\n".join(lines) + "\n")
    return path


def test_the_camera_stands_in_the_lit_room_and_the_image_is_not_black(tmp_path: Path) -> None:
    settings = RenderSettings(
        mesh=MeshSettings(receivers=3000, patches=80),
        image=ImageSettings(width=64, height=48, samples=1),
    )
    outcome = api.render(_rooms_obj(tmp_path), tmp_path / "out", settings)
    camera = outcome.report["outputs_detail"]["camera"]
    assert 0.0 < camera["position"][0] < 2.0  # inside the lit room
    radiance = read_image(tmp_path / "out" / "rooms.exr")
    assert (radiance.max(axis=2) > 0.01).mean() > 0.9  # nearly every pixel lit
    preview = read_image(tmp_path / "out" / "rooms.png")
    assert 0.2 < float(preview.mean()) < 0.95  # exposed for what it shows


def test_the_image_exposure_comes_from_what_the_camera_sees(tmp_path: Path) -> None:
    # the same lit room seen from inside: the dark room beside it (half the model, zero)
    # does not enter the image's exposure, so it differs from the model's
    settings = RenderSettings(
        mesh=MeshSettings(receivers=3000, patches=80),
        image=ImageSettings(width=64, height=48, samples=1),
    )
    outcome = api.render(_rooms_obj(tmp_path), tmp_path / "out", settings)
    detail = outcome.report["outputs_detail"]
    assert detail["camera"]["exposure"] > 0
    assert detail["camera"]["exposure"] != pytest.approx(detail["exposure"], rel=1e-3)


def _rotated(camera: Camera, rotation: np.ndarray) -> tuple[np.ndarray, ...]:
    _, up, forward = camera.basis()
    position = np.asarray(camera.position) @ rotation.T
    return position, up @ rotation.T, forward @ rotation.T


@pytest.mark.parametrize("which", ["front", "every candidate"])
def test_z_up_views_are_the_y_up_views_turned(which: str) -> None:
    positions = cornell_box().positions
    turned = positions @ Y_TO_Z.T
    if which == "front":
        pairs = [(framing_camera(positions), framing_camera(turned, up="z"))]
    else:
        pairs = list(
            zip(
                _candidate_cameras(positions, 45.0, "y"),
                _candidate_cameras(turned, 45.0, "z"),
                strict=True,
            )
        )
    for y_up, z_up in pairs:
        position, up, forward = _rotated(y_up, Y_TO_Z)
        np.testing.assert_allclose(z_up.position, position, atol=1e-12)
        np.testing.assert_allclose(z_up.basis()[1], up, atol=1e-12)
        np.testing.assert_allclose(z_up.basis()[2], forward, atol=1e-12)
    assert up_vector("z") == (0.0, 0.0, 1.0)
