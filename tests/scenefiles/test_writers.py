"""The OBJ / GLB scene writers: exact round trips through the readers, and what OBJ cannot
say."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest

from raytrad.scene import make_scene
from raytrad.scene.builtin import cornell_box, furnace_box, shadow_scene
from raytrad.scenefiles import load_scene, write_glb, write_obj
from tests.conftest import areas_by_material


def test_write_obj_round_trips_exact_float64(tmp_path: Path) -> None:
    original = furnace_box(
        reflectance=(0.1, 0.2, 0.30000000000000004),
        emitted_exitance=(1 / 3, 2 / 3, math.pi),
        size=0.7,
    )
    write_obj(original, tmp_path / "f.obj")
    assert (tmp_path / "f.mtl").exists()
    loaded = load_scene(tmp_path / "f.obj")
    assert loaded.material_reflectance.tolist() == [[0.1, 0.2, 0.30000000000000004]]
    assert loaded.material_emitted_exitance.tolist() == [[1 / 3, 2 / 3, math.pi]]
    np.testing.assert_array_equal(
        np.sort(loaded.triangle_vertices().reshape(-1, 3), axis=0),
        np.sort(original.triangle_vertices().reshape(-1, 3), axis=0),
    )


def test_write_obj_text(tmp_path: Path) -> None:
    write_obj(cornell_box(), tmp_path / "box.obj")
    obj = (tmp_path / "box.obj").read_text().splitlines()
    mtl = (tmp_path / "box.mtl").read_text().splitlines()
    assert "mtllib box.mtl" in obj
    assert sum(line.startswith("f ") for line in obj) == 32
    assert {"newmtl white", "Kd 0.725 0.71 0.68", "Ke 0.0 0.0 0.0"} <= set(mtl)
    assert f"Ke {17 * math.pi!r} {12 * math.pi!r} {4 * math.pi!r}" in mtl


def test_write_obj_warns_that_double_sided_is_lost(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="raytrad"):
        write_obj(shadow_scene(), tmp_path / "s.obj")
    assert any("double-sided" in r.getMessage() for r in caplog.records)
    assert not load_scene(tmp_path / "s.obj").material_double_sided.any()


def test_write_obj_makes_material_names_safe(tmp_path: Path) -> None:
    scene = make_scene(
        positions=np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]),
        triangles=np.array([[0, 1, 2], [0, 3, 1]]),
        material_index=np.array([0, 1]),
        material_names=["white paint", "white paint"],
        material_reflectance=np.array([[0.5] * 3, [0.25] * 3]),
        material_emitted_exitance=np.zeros((2, 3)),
    )
    write_obj(scene, tmp_path / "n.obj")
    loaded = load_scene(tmp_path / "n.obj")
    assert sorted(loaded.material_names) == ["white_paint", "white_paint_1"]
    assert sorted(loaded.material_reflectance[:, 0].tolist()) == [0.25, 0.5]


def test_write_glb_keeps_double_sided_and_emission(tmp_path: Path) -> None:
    original = shadow_scene()
    write_glb(original, tmp_path / "s.glb")
    loaded = load_scene(tmp_path / "s.glb")
    by_name = {n: i for i, n in enumerate(loaded.material_names)}
    for i, name in enumerate(original.material_names):
        j = by_name[name]
        assert loaded.material_double_sided[j] == original.material_double_sided[i]
        assert loaded.material_reflectance[j].tolist() == original.material_reflectance[i].tolist()
        np.testing.assert_allclose(
            loaded.material_emitted_exitance[j], original.material_emitted_exitance[i], rtol=1e-15
        )
    # Positions are float32 in glTF: 0.3 m comes back as 0.30000001192092896 m.
    assert areas_by_material(loaded) == pytest.approx(areas_by_material(original), rel=1e-6)
    np.testing.assert_array_equal(
        np.sort(loaded.triangle_vertices().reshape(-1, 3), axis=0),
        np.sort(original.triangle_vertices().reshape(-1, 3).astype(np.float32), axis=0),
    )
