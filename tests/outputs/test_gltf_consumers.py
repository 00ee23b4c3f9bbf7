"""The baked lightmap shows in real glTF consumers: Blender's importer (pip ``bpy``) and
three.js in headless Chromium, each seeing from raytrad's camera what raytrad's own image
shows.

Optional: the Blender test runs where ``bpy`` imports in this Python or in the Python
named by ``RAYTRAD_BPY_PYTHON`` (bpy pins its own Python version); the web test needs
Chromium (Debian ``chromium``) and npm, which installs three.js into
``tools/gltf_viewer``. Without them the tests skip and say what is missing.
"""

from __future__ import annotations

import functools
import http.server
import importlib.util
import os
import shutil
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from raytrad import api
from raytrad.core.mesh import MeshSettings
from raytrad.formats.images import read_image
from raytrad.settings import ImageSettings, LightmapSettings, RenderSettings
from tests.conftest import REPOSITORY, SCENES, npm_package

WIDTH, HEIGHT = 160, 120
VIEWER = REPOSITORY / "tools" / "gltf_viewer"


@pytest.fixture(scope="module")
def baked(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, object]]:
    """The Cornell box baked with a lightmap, its glb and image from the 'front' camera."""
    out = tmp_path_factory.mktemp("baked")
    settings = RenderSettings(
        mesh=MeshSettings(receivers=1500, patches=80),
        lightmap=LightmapSettings(resolution=512),
        image=ImageSettings(width=WIDTH, height=HEIGHT, samples=4, view="front"),
        gltf=True,
    )
    outcome = api.render(SCENES / "cornell-box-uv.glb", out, settings)
    camera: dict[str, object] = outcome.report["outputs_detail"]["camera"]
    return out, camera


def _agrees_with_raytrad(picture: Path, out: Path) -> None:
    """The consumer's picture shows what raytrad's image shows (not black, same layout)."""
    theirs = read_image(picture)[..., :3].astype(np.float64).mean(axis=2)
    ours = read_image(out / "cornell-box-uv.png")[..., :3].astype(np.float64).mean(axis=2)
    assert theirs.shape == ours.shape
    assert theirs.mean() > 0.15, "the lightmap does not show"
    assert np.corrcoef(theirs.ravel(), ours.ravel())[0, 1] > 0.9


def _triple(values: object) -> str:
    return ",".join(f"{float(v):.6g}" for v in values)  # type: ignore[attr-defined]


def _bpy_python() -> str | None:
    if importlib.util.find_spec("bpy") is not None:
        return sys.executable
    return os.environ.get("RAYTRAD_BPY_PYTHON")


def test_blender_imports_the_lightmap_and_shows_it(
    baked: tuple[Path, dict[str, object]],
) -> None:
    python = _bpy_python()
    if python is None:
        pytest.skip(
            "Blender's bpy is not installed (pip install --no-deps 'bpy>=4.2' requests "
            "zstandard, or RAYTRAD_BPY_PYTHON)"
        )
    out, camera = baked
    picture = out / "blender.png"
    done = subprocess.run(
        [
            python,
            str(REPOSITORY / "tools" / "blender_view.py"),
            str(out / "cornell-box-uv.glb"),
            str(picture),
            _triple(camera["position"]),
            _triple(camera["look_at"]),
            str(camera["vertical_fov_deg"]),
            str(WIDTH),
            str(HEIGHT),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "uv layers floor ['UVMap', 'UVMap.001']" in done.stdout  # TEXCOORD_0 and _1
    _agrees_with_raytrad(picture, out)


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if shutil.which(name):
            return shutil.which(name)
    return None


@pytest.fixture(scope="module")
def served(baked: tuple[Path, dict[str, object]]) -> Iterator[str]:
    """The viewer page, three.js and the baked glb over http on localhost; the base URL."""
    if _chromium() is None:
        pytest.skip("Chromium is needed for the web viewer test (not installed)")
    npm_package(VIEWER, "three")
    out, _ = baked
    site = out / "site"
    site.mkdir(exist_ok=True)
    shutil.copy(VIEWER / "viewer.html", site / "viewer.html")
    shutil.copy(out / "cornell-box-uv.glb", site / "model.glb")
    if not (site / "node_modules").exists():
        (site / "node_modules").symlink_to(VIEWER / "node_modules")
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(site), **{})
    handler.log_message = lambda *args: None  # type: ignore[attr-defined]
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()


def test_three_js_in_chromium_shows_the_lightmap(
    baked: tuple[Path, dict[str, object]], served: str
) -> None:
    out, camera = baked
    picture = out / "web.png"
    url = (
        f"{served}/viewer.html?model=model.glb&position={_triple(camera['position'])}"
        f"&target={_triple(camera['look_at'])}&fov={camera['vertical_fov_deg']}"
        f"&width={WIDTH}&height={HEIGHT}"
    )
    done = subprocess.run(
        [
            str(_chromium()),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--hide-scrollbars",
            f"--window-size={WIDTH},{HEIGHT}",
            "--virtual-time-budget=15000",
            f"--screenshot={picture}",
            url,
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0 and picture.is_file(), done.stderr[-2000:]
    _agrees_with_raytrad(picture, out)
