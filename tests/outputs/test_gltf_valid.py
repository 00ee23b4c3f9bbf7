"""Every ``.glb`` raytrad writes passes the Khronos glTF validator with no error or warning.

The validator (npm ``gltf-validator``, pinned in ``tools/gltf_validator``) runs on
Node.js; it is installed there by npm on first use. Without node or npm, or without the
npm registry, these tests skip and say so.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from raytrad.scene import NamedCamera
from raytrad.scene.camera import Camera
from raytrad.scenefiles import load_scene, write_glb
from tests.conftest import REPOSITORY, SCENES, npm_package, run_cli

VALIDATOR = REPOSITORY / "tools" / "gltf_validator"
SMALL = ["--receivers", "600", "--patches", "40", "--refine-threshold", "0", "-q"]


@pytest.fixture(scope="module")
def validate() -> object:
    """``validate(path) -> report dict``, or a skip naming what is missing."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is needed to run the Khronos glTF validator (not installed)")
    npm_package(VALIDATOR, "gltf-validator")

    def run(path: Path) -> dict[str, object]:
        out = subprocess.run(
            [node, str(VALIDATOR / "validate.mjs"), str(path)],
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )
        report: dict[str, object] = json.loads(out.stdout)
        return report

    return run


RENDERS = {
    "vertex colours": ("cornell-box.obj", ["--gltf"]),
    "lightmap in the model's UV set": ("cornell-box-uv.glb", ["--gltf", "--lightmap"]),
    "lightmap in a generated atlas": ("cornell-box.obj", ["--gltf", "--lightmap"]),
    "one lightmap per mesh": ("cornell-box.obj", ["--gltf", "--lightmap", "--lightmap-per-mesh"]),
}


@pytest.mark.parametrize("case", sorted(RENDERS))
def test_baked_glb_is_valid(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], validate: object, case: str
) -> None:
    scene, options = RENDERS[case]
    status, _, err = run_cli(
        ["render", str(SCENES / scene), "-o", str(tmp_path), *SMALL, *options], capsys
    )
    assert status == 0, err
    (glb,) = tmp_path.glob("*.glb")
    report = validate(glb)  # type: ignore[operator]
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]


def test_written_scene_with_uvs_and_cameras_is_valid(tmp_path: Path, validate: object) -> None:
    scene = load_scene(SCENES / "cornell-box-uv.glb", uv_set=1)
    camera = NamedCamera("front", Camera((0.28, 0.27, -0.8), (0.28, 0.27, 0.28)))
    write_glb(scene, tmp_path / "scene.glb", [camera])
    report = validate(tmp_path / "scene.glb")  # type: ignore[operator]
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]
