"""The Python API step by step: load (with what the settings need of the file), prepare,
solve, and a render that reports progress and writes its outputs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from raytrad import api
from raytrad.core.solver import solve
from raytrad.settings import (
    ImageSettings,
    LightmapSettings,
    MeshSettings,
    RenderSettings,
    SolveSettings,
)
from tests.conftest import SCENES

SMALL = MeshSettings(receivers=500, patches=40)


def test_load_reads_cameras_and_uvs_only_when_asked() -> None:
    plain = api.load(SCENES / "cornell-box-uv.glb")
    assert plain.cameras == () and plain.scene.lightmap_uv is None and plain.kind == "gltf"
    asked = api.load(
        SCENES / "cornell-box-uv.glb",
        RenderSettings(image=ImageSettings(), lightmap=LightmapSettings()),
    )
    assert [c.name for c in asked.cameras] == ["front", "corner"]
    assert asked.scene.lightmap_uv is not None and np.isfinite(asked.scene.lightmap_uv).all()


def test_load_gives_a_toml_files_output_defaults() -> None:
    loaded = api.load(SCENES / "colour-room.toml")
    assert loaded.kind == "toml" and loaded.output["lightmap_resolution"] == 512
    assert [c.name for c in loaded.cameras] == ["camera"]


def test_step_by_step_equals_solve_scene() -> None:
    settings = RenderSettings(mesh=SMALL, solve=SolveSettings(tolerance=1e-4))
    scene = api.load(SCENES / "furnace.obj").scene
    with api.prepare(scene, settings) as prepared:
        stepwise = solve(prepared.mesh, prepared.engine, settings.solve)
    _, at_once = api.solve_scene(scene, settings)
    np.testing.assert_array_equal(stepwise.radiosity, at_once.radiosity)
    np.testing.assert_allclose(at_once.radiosity, 2.0, rtol=3e-4)  # 3 x tolerance, test_solver


def test_render_reports_progress_and_applies_the_file_defaults(tmp_path: Path) -> None:
    seen: list[api.RenderProgress] = []
    settings = RenderSettings(mesh=SMALL, lightmap=LightmapSettings())
    outcome = api.render(SCENES / "colour-room.toml", tmp_path, settings, progress=seen.append)
    assert [p.shots for p in seen] == list(range(1, outcome.result.state.shots + 1))
    assert all(math.isfinite(p.residual) and p.seconds >= 0 for p in seen)
    lightmap = outcome.report["settings"]["lightmap"]
    # the file's [output]: lightmap_resolution 512 and texel_density 400 (which decides)
    assert lightmap["resolution"] == 512 and lightmap["texel_density"] == 400.0
    assert outcome.report["settings"]["exposure"] == 0.0
    stats = outcome.report["outputs_detail"]["lightmap"]
    assert abs(stats["texel_density_median"] / 400.0 - 1.0) < 0.05
    assert sorted(outcome.outputs) == sorted(
        ["ply", "lightmap", "lightmap_preview", "report", "manifest"]
    )
    assert all(path.is_file() for path in outcome.outputs.values())
