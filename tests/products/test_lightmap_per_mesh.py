"""Per-mesh lightmaps, model lightmap UVs, the baked glTF per object, and the display fill of
hidden receivers, each checked against an independent computation."""

from __future__ import annotations

import dataclasses
import json
import logging
import struct
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

from raytrad import api
from raytrad.core.hidden import fill_hidden
from raytrad.core.mesh import MeshSettings, RadiosityMesh, build_mesh
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolveResult
from raytrad.errors import SceneError, SettingsError
from raytrad.formats.images import read_attributes, read_image
from raytrad.outputs.gltf import BakedPart, write_baked_glb
from raytrad.products.lightmap import (
    Lightmap,
    LightmapSettings,
    bake_lightmap,
    bake_lightmaps,
    choose_lightmap_uvs,
    lightmap_vertices,
)
from raytrad.scene import Scene
from raytrad.scene.builtin import cornell_box
from raytrad.scenefiles import load_scene
from raytrad.settings import RenderSettings
from tests.conftest import CORNELL_OBJECTS, REPOSITORY, SCENES, one_quad_scene, run_cli

MESH = MeshSettings(receivers=600, patches=60)
CORNELL_UV = SCENES / "cornell-box-uv.glb"
SCHEMA_PATH = REPOSITORY / "docs" / "report.schema.json"
Solved = tuple[Prepared, SolveResult]


# --------------------------------------------------------------------------------------
# Independent reference computations
# --------------------------------------------------------------------------------------


def _barycentrics_2d(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, T, 3) barycentric coordinates of N 2-D points in each of T 2-D triangles
    (Cramer's rule on the edge vectors)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    e1, e2 = b - a, c - a
    rel = points[:, None, :] - a[None]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    l1 = (rel[..., 0] * e2[:, 1] - rel[..., 1] * e2[:, 0]) / det
    l2 = (e1[:, 0] * rel[..., 1] - e1[:, 1] * rel[..., 0]) / det
    return np.stack([1.0 - l1 - l2, l1, l2], axis=-1)


def _object_rows(prepared: Prepared) -> dict[str, np.ndarray]:
    """Object name -> sorted refined triangles whose scene triangle belongs to it."""
    scene, mesh = prepared.scene, prepared.mesh
    owner = scene.object_index[mesh.triangle_source]
    return {
        name: np.flatnonzero(owner == k)
        for k, name in enumerate(scene.object_names)
        if (owner == k).any()
    }


def _model_uv_at_corners(prepared: Prepared) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3, 2) model UV at each refined corner, by least squares in 3-D, and the (T, 3, 3)
    barycentric coordinates of the corners in their scene triangles."""
    scene, mesh = prepared.scene, prepared.mesh
    source_corners = scene.triangle_vertices()[mesh.triangle_source]  # (T, 3, 3)
    source_uv = scene.lightmap_uv[mesh.triangle_source]  # (T, 3, 2)
    edges = np.stack(
        [source_corners[:, 1] - source_corners[:, 0], source_corners[:, 2] - source_corners[:, 0]],
        axis=2,
    )  # (T, 3, 2): columns are the two edges
    points = mesh.positions[mesh.triangles]  # (T, 3 corners, 3)
    rel = points - source_corners[:, :1]
    coefficients = np.einsum("tij,tkj->tki", np.linalg.pinv(edges), rel)  # (T, 3, 2)
    # the refined corners lie in the plane of their scene triangle
    back = np.einsum("tij,tkj->tki", edges, coefficients)
    np.testing.assert_allclose(back, rel, atol=1e-9)
    weights = np.concatenate([1.0 - coefficients.sum(axis=2, keepdims=True), coefficients], 2)
    uv = np.einsum("tkj,tjc->tkc", weights, source_uv)
    return uv, weights


def _edge_neighbours(mesh: RadiosityMesh) -> list[set[int]]:
    """The receivers joined to each receiver by a refined triangle edge."""
    neighbours: list[set[int]] = [set() for _ in range(mesh.receiver_count)]
    for a, b, c in mesh.triangle_receivers.tolist():
        for p, q in ((a, b), (b, c), (c, a)):
            neighbours[p].add(q)
            neighbours[q].add(p)
    return neighbours


def _fill_reference(
    neighbours: list[set[int]], visible: np.ndarray, radiosity: np.ndarray, rings: int = 64
) -> np.ndarray:
    """Ring by ring: each still-unknown receiver next to known ones takes their plain mean."""
    out = np.array(radiosity, dtype=np.float64)
    known = visible.copy()
    for _ in range(rings):
        ring = {
            r: [n for n in neighbours[r] if known[n]]
            for r in np.flatnonzero(~known).tolist()
            if any(known[n] for n in neighbours[r])
        }
        if not ring:
            break
        values = {r: out[sources].mean(axis=0) for r, sources in ring.items()}
        for r, value in values.items():
            out[r] = value
            known[r] = True
    return out


def _glb_json(path: Path) -> dict[str, Any]:
    data = path.read_bytes()
    assert data[:4] == b"glTF"
    length = struct.unpack_from("<I", data, 12)[0]
    return dict(json.loads(data[20 : 20 + length]))


# --------------------------------------------------------------------------------------
# Fixtures
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cornell_solved() -> Solved:
    """The built-in Cornell box (8 objects) at about 600 receivers, solved."""
    return api.solve_scene(cornell_box(), RenderSettings(mesh=MESH))


@pytest.fixture(scope="module")
def uv_solved() -> Solved:
    """scenes/cornell-box-uv.glb with its TEXCOORD_1, at about 600 receivers, solved."""
    scene = load_scene(CORNELL_UV, uv_set=1)
    return api.solve_scene(scene, RenderSettings(mesh=MESH))


@pytest.fixture(scope="module")
def per_mesh_generated(cornell_solved: Solved) -> list[Lightmap]:
    prepared, result = cornell_solved
    settings = LightmapSettings(resolution=64, per_mesh=True)
    return bake_lightmaps(prepared.scene, prepared.mesh, result.radiosity, settings)


@pytest.fixture(scope="module")
def per_mesh_model_uv(uv_solved: Solved) -> list[Lightmap]:
    prepared, result = uv_solved
    settings = LightmapSettings(resolution=128, per_mesh=True)
    return bake_lightmaps(prepared.scene, prepared.mesh, result.radiosity, settings)


@pytest.fixture(params=["generated", "model-uvs"])
def per_mesh(
    request: pytest.FixtureRequest,
    cornell_solved: Solved,
    uv_solved: Solved,
    per_mesh_generated: list[Lightmap],
    per_mesh_model_uv: list[Lightmap],
) -> tuple[Prepared, np.ndarray, list[Lightmap]]:
    """(prepared, receiver radiosity, per-mesh lightmaps) for both ways of getting UVs."""
    if request.param == "generated":
        prepared, result = cornell_solved
        return prepared, result.radiosity, per_mesh_generated
    prepared, result = uv_solved
    return prepared, result.radiosity, per_mesh_model_uv


@pytest.fixture(scope="module")
def per_mesh_render(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, api.RenderOutcome]:
    """api.render of cornell-box-uv.glb with per-mesh 64 x 64 lightmaps and a glTF."""
    out = tmp_path_factory.mktemp("per-mesh")
    settings = RenderSettings(
        mesh=MESH, lightmap=LightmapSettings(resolution=64, per_mesh=True), gltf=True
    )
    return out, api.render(CORNELL_UV, out, settings)


# --------------------------------------------------------------------------------------
# Per-mesh baking
# --------------------------------------------------------------------------------------


def test_one_lightmap_per_object_covering_exactly_its_triangles(
    per_mesh: tuple[Prepared, np.ndarray, list[Lightmap]],
) -> None:
    prepared, _, lightmaps = per_mesh
    rows = _object_rows(prepared)
    assert sorted(rows) == sorted(CORNELL_OBJECTS)
    assert [m.name for m in lightmaps] == list(rows)  # the scene's object order
    for lightmap in lightmaps:
        assert lightmap.triangles is not None
        np.testing.assert_array_equal(lightmap.triangles, rows[lightmap.name])
        assert len(lightmap.uv) == len(lightmap.triangles)
    union = np.concatenate([m.triangles for m in lightmaps if m.triangles is not None])
    np.testing.assert_array_equal(np.sort(union), np.arange(len(prepared.mesh.triangles)))
    assert len(np.unique(union)) == len(union)  # every triangle exactly once


def test_per_mesh_texel_centres_are_the_barycentric_interpolation(
    per_mesh: tuple[Prepared, np.ndarray, list[Lightmap]],
) -> None:
    prepared, radiosity, lightmaps = per_mesh
    mesh = prepared.mesh
    rng = np.random.default_rng(11)
    checked = 0
    for lightmap in lightmaps:
        assert lightmap.triangles is not None
        uv = lightmap.uv * np.asarray(lightmap.size, dtype=np.float64)
        rows, cols = np.nonzero(lightmap.coverage)
        assert len(rows) > 0, lightmap.name
        pick = rng.choice(len(rows), min(150, len(rows)), replace=False)
        centres = np.stack([cols[pick] + 0.5, rows[pick] + 0.5], axis=1)
        weights = _barycentrics_2d(uv, centres)  # (N, t, 3)
        strictly = np.asarray((weights > 1e-9).all(axis=2))
        found = np.flatnonzero(strictly.any(axis=1))
        assert len(found) > 0, lightmap.name
        local = np.argmax(strictly[found], axis=1)
        w = weights[found, local]
        corners = radiosity[mesh.triangle_receivers[lightmap.triangles[local]]]
        expected = np.einsum("nk,nkc->nc", w, corners)
        got = lightmap.pixels[rows[pick][found], cols[pick][found]]
        np.testing.assert_allclose(
            got, expected, rtol=1e-5, atol=1e-7 * radiosity.max(), err_msg=lightmap.name
        )
        checked += len(found)
    assert checked > 400


def test_per_mesh_generated_atlases_meet_the_texel_density(cornell_solved: Solved) -> None:
    prepared, result = cornell_solved
    density = 150.0
    settings = LightmapSettings(texel_density=density, per_mesh=True)
    lightmaps = bake_lightmaps(prepared.scene, prepared.mesh, result.radiosity, settings)
    assert len(lightmaps) == len(CORNELL_OBJECTS)
    mesh = prepared.mesh
    for lightmap in lightmaps:
        assert lightmap.triangles is not None
        uv = lightmap.uv * np.asarray(lightmap.size, dtype=np.float64)
        e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        texels = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        area = mesh.triangle_area[lightmap.triangles]
        # area-weighted mean texel area per m2 is the squared density
        achieved = np.sqrt(texels.sum() / area.sum())
        assert achieved == pytest.approx(density, rel=0.05), lightmap.name
        assert lightmap.stats["texel_density_median"] == pytest.approx(density, rel=0.05)
        # the atlas is sized to the object, not to the scene
        side = np.sqrt(area.sum()) * density
        assert max(lightmap.size) < 3.0 * side + 20, lightmap.name


def test_per_mesh_model_uv_atlases_meet_the_texel_density(uv_solved: Solved) -> None:
    """With model UVs the atlas is square, ceil(density / median UV density) texels wide."""
    prepared, result = uv_solved
    density = 120.0
    settings = LightmapSettings(texel_density=density, per_mesh=True, uv_set=1)
    lightmaps = bake_lightmaps(prepared.scene, prepared.mesh, result.radiosity, settings)
    for lightmap in lightmaps:
        side = lightmap.size[0]
        assert lightmap.size == (side, side)
        median = lightmap.stats["texel_density_median"]
        assert density <= median * (1 + 1e-9), lightmap.name
        assert median <= density * (1.0 + 1.0 / (side - 1)), lightmap.name


def test_bake_lightmap_sorts_the_triangles_and_keeps_the_name(cornell_solved: Solved) -> None:
    prepared, result = cornell_solved
    rows = _object_rows(prepared)["tall-block"]
    shuffled = np.random.default_rng(3).permutation(rows)
    lightmap = bake_lightmap(
        prepared.mesh,
        result.radiosity,
        LightmapSettings(resolution=32),
        triangles=shuffled,
        name="tall-block",
    )
    assert lightmap.name == "tall-block"
    assert lightmap.triangles is not None
    np.testing.assert_array_equal(lightmap.triangles, rows)
    assert lightmap.size == (32, 32)
    whole = bake_lightmap(prepared.mesh, result.radiosity, LightmapSettings(resolution=32))
    assert whole.triangles is None and whole.name == ""
    assert len(whole.uv) == len(prepared.mesh.triangles)


def test_lightmap_vertices_of_one_object(
    per_mesh: tuple[Prepared, np.ndarray, list[Lightmap]],
) -> None:
    prepared, _, lightmaps = per_mesh
    mesh = prepared.mesh
    for lightmap in lightmaps:
        assert lightmap.triangles is not None
        receiver, triangles, uv = lightmap_vertices(mesh, lightmap, lightmap.triangles)
        np.testing.assert_array_equal(
            receiver[triangles], mesh.triangle_receivers[lightmap.triangles]
        )
        np.testing.assert_allclose(uv[triangles], lightmap.uv, atol=1e-7)
        # a subset in another order keeps that order
        subset = lightmap.triangles[::-2]
        receiver, triangles, uv = lightmap_vertices(mesh, lightmap, subset)
        np.testing.assert_array_equal(receiver[triangles], mesh.triangle_receivers[subset])
        # only receivers of this object
        assert set(receiver.tolist()) <= set(mesh.triangle_receivers[lightmap.triangles].ravel())
    first, second = lightmaps[0], lightmaps[1]
    assert second.triangles is not None
    with pytest.raises(ValueError, match="does not cover"):
        lightmap_vertices(mesh, first, second.triangles[:3])


# --------------------------------------------------------------------------------------
# Model UVs
# --------------------------------------------------------------------------------------


def test_model_uvs_are_interpolated_at_each_refined_corner(uv_solved: Solved) -> None:
    prepared, result = uv_solved
    scene, mesh = prepared.scene, prepared.mesh
    assert scene.lightmap_uv is not None
    expected, weights = _model_uv_at_corners(prepared)
    # every refined corner lies inside (or on the edge of) its scene triangle
    assert weights.min() >= -1e-9 and weights.max() <= 1.0 + 1e-9
    assert len(mesh.triangles) > 3 * scene.triangle_count  # the mesh really is refined
    settings = LightmapSettings(resolution=64, uv_set=1)
    lightmap = bake_lightmap(
        mesh, result.radiosity, settings, scene.lightmap_uv, scene.triangle_vertices()
    )
    assert lightmap.size == (64, 64)
    np.testing.assert_allclose(lightmap.uv, expected, atol=1e-9)
    # the same UVs per mesh, row for row
    for name, rows in _object_rows(prepared).items():
        one = bake_lightmap(
            mesh,
            result.radiosity,
            settings,
            scene.lightmap_uv,
            scene.triangle_vertices(),
            rows,
            name,
        )
        np.testing.assert_allclose(one.uv, expected[rows], atol=1e-9, err_msg=name)


def test_model_uvs_reach_the_per_mesh_lightmaps(
    uv_solved: Solved, per_mesh_model_uv: list[Lightmap]
) -> None:
    prepared, _ = uv_solved
    expected, _ = _model_uv_at_corners(prepared)
    for lightmap in per_mesh_model_uv:
        assert lightmap.triangles is not None and lightmap.size == (128, 128)
        np.testing.assert_allclose(lightmap.uv, expected[lightmap.triangles], atol=1e-9)


def test_explicit_uv_set_without_uvs_is_refused(cornell_solved: Solved) -> None:
    prepared, result = cornell_solved
    with pytest.raises(SettingsError, match="uv set 1"):
        bake_lightmap(prepared.mesh, result.radiosity, LightmapSettings(uv_set=1))


@pytest.mark.parametrize("uv_set", [-1, "banana", True, 1.0, "1"])
def test_bad_uv_set_settings_are_refused(uv_set: Any) -> None:
    with pytest.raises(SettingsError, match="uv set"):
        LightmapSettings(uv_set=uv_set)


@pytest.mark.parametrize(("uv_set", "read"), [("auto", 1), ("atlas", None), (0, 0), (3, 3)])
def test_uv_set_to_read(uv_set: int | str, read: int | None) -> None:
    assert LightmapSettings(uv_set=uv_set).uv_set_to_read == read


# --------------------------------------------------------------------------------------
# choose_lightmap_uvs
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def uv_scene() -> Scene:
    """cornell-box-uv.glb with its TEXCOORD_1 (every face has it)."""
    scene = load_scene(CORNELL_UV, uv_set=1)
    assert scene.lightmap_uv is not None and np.isfinite(scene.lightmap_uv).all()
    return scene


def _without_uvs_on(scene: Scene, name: str) -> Scene:
    assert scene.lightmap_uv is not None
    uv = scene.lightmap_uv.copy()
    uv[scene.object_index == scene.object_names.index(name)] = np.nan
    return dataclasses.replace(scene, lightmap_uv=uv)


@pytest.mark.parametrize("uv_set", ["auto", 1])
def test_checked_uvs_are_kept_when_every_face_has_them(uv_scene: Scene, uv_set: int | str) -> None:
    kept = choose_lightmap_uvs(uv_scene, LightmapSettings(uv_set=uv_set))
    assert kept.lightmap_uv is not None
    np.testing.assert_array_equal(kept.lightmap_uv, uv_scene.lightmap_uv)


def test_checked_uvs_partial_auto_drops_with_a_warning(
    uv_scene: Scene, caplog: pytest.LogCaptureFixture
) -> None:
    partial = _without_uvs_on(uv_scene, "light")
    missing = int((partial.object_index == partial.object_names.index("light")).sum())
    with caplog.at_level(logging.WARNING, logger="raytrad.api"):
        checked = choose_lightmap_uvs(partial, LightmapSettings())
    assert checked.lightmap_uv is None
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert f"{missing} of {partial.triangle_count}" in warnings[0]
    assert "'light'" in warnings[0] and "cornell-box-uv.glb" in warnings[0]


def test_checked_uvs_absent_everywhere_auto_drops_quietly(
    caplog: pytest.LogCaptureFixture,
) -> None:
    scene = load_scene(SCENES / "cornell-box.obj", uv_set=1)  # OBJ has no set 1
    with caplog.at_level(logging.WARNING, logger="raytrad.api"):
        checked = choose_lightmap_uvs(scene, LightmapSettings())
    assert checked.lightmap_uv is None
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


@pytest.mark.parametrize("uv_set", [1, 0])
def test_checked_uvs_explicit_set_missing_names_the_file(uv_scene: Scene, uv_set: int) -> None:
    partial = _without_uvs_on(uv_scene, "short-block")
    with pytest.raises(SceneError) as caught:
        choose_lightmap_uvs(partial, LightmapSettings(uv_set=uv_set))
    assert caught.value.path == CORNELL_UV
    message = str(caught.value)
    assert str(CORNELL_UV) in message
    assert f"UV set {uv_set}" in message and "'short-block'" in message


def test_checked_uvs_explicit_set_the_file_lacks(tmp_path: Path) -> None:
    scene = load_scene(CORNELL_UV, uv_set=2)
    with pytest.raises(SceneError, match=r"cornell-box-uv\.glb.*UV set 2"):
        choose_lightmap_uvs(scene, LightmapSettings(uv_set=2))
    # through render: refused at load, before anything is written
    out = tmp_path / "out"
    settings = RenderSettings(mesh=MESH, lightmap=LightmapSettings(uv_set=2))
    with pytest.raises(SceneError, match="UV set 2"):
        api.render(CORNELL_UV, out, settings)
    assert not out.exists() or not any(out.iterdir())


def test_checked_uvs_atlas_or_no_lightmap_drops(uv_scene: Scene) -> None:
    assert choose_lightmap_uvs(uv_scene, LightmapSettings(uv_set="atlas")).lightmap_uv is None
    assert choose_lightmap_uvs(uv_scene, None).lightmap_uv is None
    assert uv_scene.lightmap_uv is not None  # the input is not changed


# --------------------------------------------------------------------------------------
# The per-mesh render: files, report, glTF
# --------------------------------------------------------------------------------------


def test_per_mesh_render_writes_one_lightmap_file_per_object(
    per_mesh_render: tuple[Path, api.RenderOutcome],
) -> None:
    out, outcome = per_mesh_render
    names = set(outcome.prepared.scene.object_names)
    assert names == set(CORNELL_OBJECTS)
    assert "lightmap" not in outcome.outputs
    for name in names:
        exr = out / f"cornell-box-uv.{name}.lightmap.exr"
        png = out / f"cornell-box-uv.{name}.lightmap.png"
        assert outcome.outputs[f"lightmap:{name}"] == exr
        assert outcome.outputs[f"lightmap_preview:{name}"] == png
        pixels = read_image(exr)
        assert pixels.shape[:2] == (64, 64)
        assert np.isfinite(pixels).all() and (pixels[..., :3] >= 0).all()
        assert pixels[..., :3].max() > 0
        attributes = read_attributes(exr)
        assert attributes["raytrad:object"] == name
        assert attributes["raytrad:lightmap_per_mesh"] == 1
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    lightmap_files = sorted(p.name for p in out.glob("*.lightmap.*"))
    assert len(lightmap_files) == 2 * len(names)
    detail = outcome.report["outputs_detail"]["lightmaps"]
    assert set(detail) == names
    assert all(d["size"] == [64, 64] for d in detail.values())


def test_per_mesh_report_matches_the_schema(
    per_mesh_render: tuple[Path, api.RenderOutcome],
) -> None:
    out, _ = per_mesh_render
    report = json.loads((out / "report.json").read_text())
    schema = json.loads(SCHEMA_PATH.read_text())
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(report), key=lambda e: list(e.absolute_path))
    assert not errors, "\n".join(f"{list(e.absolute_path)}: {e.message}" for e in errors[:10])
    keys = {k for k in report["outputs"] if k.startswith("lightmap:")}
    assert keys == {f"lightmap:{name}" for name in CORNELL_OBJECTS}
    assert report["settings"]["lightmap"]["per_mesh"] is True
    assert report["settings"]["lightmap"]["uv_set"] == "auto"
    # an unknown key is still refused: the pattern does not open the object up
    report["outputs"]["lightmapfoo"] = "x"
    assert not validator.is_valid(report)


def test_per_mesh_gltf_has_one_textured_node_per_object(
    per_mesh_render: tuple[Path, api.RenderOutcome],
) -> None:
    import trimesh

    out, outcome = per_mesh_render
    path = out / "cornell-box-uv.glb"
    assert outcome.outputs["gltf"] == path
    loaded = trimesh.load(path, process=False)
    assert set(loaded.graph.nodes_geometry) == set(CORNELL_OBJECTS)
    for node in loaded.graph.nodes_geometry:
        _, geometry_name = loaded.graph[node]
        geometry = loaded.geometry[geometry_name]
        assert geometry.visual.material.emissiveTexture.size == (64, 64), node
        colours = np.asarray(geometry.visual.vertex_attributes["color"])
        assert len(colours) == len(geometry.vertices)

    header = _glb_json(path)
    nodes = header["nodes"]
    assert [n["name"] for n in nodes] == list(outcome.prepared.scene.object_names)
    assert len(header["images"]) == len(CORNELL_OBJECTS)
    textures = set()
    triangles = 0
    for node in nodes:
        mesh = header["meshes"][node["mesh"]]
        (primitive,) = mesh["primitives"]
        assert {"POSITION", "NORMAL", "COLOR_0", "TEXCOORD_1"} <= set(primitive["attributes"])
        material = header["materials"][primitive["material"]]
        assert material["emissiveTexture"]["texCoord"] == 1
        textures.add(material["emissiveTexture"]["index"])
        triangles += header["accessors"][primitive["indices"]]["count"] // 3
    assert len(textures) == len(CORNELL_OBJECTS)  # each object shows its own lightmap
    assert triangles == outcome.report["statistics"]["triangles"]


def test_scene_lightmap_gltf_shares_one_image(tmp_path: Path) -> None:
    settings = RenderSettings(mesh=MESH, lightmap=LightmapSettings(resolution=64), gltf=True)
    outcome = api.render(CORNELL_UV, tmp_path, settings)
    assert outcome.outputs["lightmap"] == tmp_path / "cornell-box-uv.lightmap.exr"
    assert not [k for k in outcome.outputs if k.startswith("lightmap:")]
    header = _glb_json(tmp_path / "cornell-box-uv.glb")
    assert [n["name"] for n in header["nodes"]] == list(outcome.prepared.scene.object_names)
    assert len(header["images"]) == 1
    indices = {m["emissiveTexture"]["index"] for m in header["materials"]}
    assert indices == {0}


# --------------------------------------------------------------------------------------
# write_baked_glb
# --------------------------------------------------------------------------------------


def _part(name: str, shift: float, uv: bool, png: bytes | None) -> BakedPart:
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float) + shift
    return BakedPart(
        name,
        positions,
        np.tile([0.0, 0.0, 1.0], (3, 1)),
        np.array([[0, 1, 2]]),
        np.full((3, 3), 0.5),
        np.array([[0.1, 0.1], [0.9, 0.1], [0.1, 0.9]]) if uv else None,
        png,
    )


def test_write_baked_glb_nodes_images_and_materials(tmp_path: Path) -> None:
    from raytrad.formats.images import encode_png

    shared = encode_png(np.zeros((4, 4, 3), dtype=np.uint8))
    own = encode_png(np.full((8, 8, 3), 200, dtype=np.uint8))
    parts = [
        _part("a", 0.0, True, shared),
        _part("b", 1.0, True, shared),  # the same bytes object: one image
        _part("c", 2.0, True, own),
        _part("plain", 3.0, False, None),
        _part("plain-2", 4.0, False, None),
    ]
    path = tmp_path / "baked.glb"
    write_baked_glb(path, parts, 2.5, {"note": "test"})
    header = _glb_json(path)
    assert [n["name"] for n in header["nodes"]] == ["a", "b", "c", "plain", "plain-2"]
    assert header["scenes"][0]["nodes"] == [0, 1, 2, 3, 4]
    assert len(header["images"]) == 2
    extras = header["extras"]["raytrad"]
    assert extras["exposure"] == 2.5 and extras["note"] == "test"
    assert extras["version"] and "radiance" in extras["colour"]
    primitives = [header["meshes"][n["mesh"]]["primitives"][0] for n in header["nodes"]]
    texture = [
        header["materials"][p["material"]].get("emissiveTexture", {}).get("index")
        for p in primitives
    ]
    assert texture[0] == texture[1] != texture[2]
    assert texture[3] is None and texture[4] is None
    assert primitives[3]["material"] == primitives[4]["material"]  # one shared unlit material
    assert "TEXCOORD_1" in primitives[0]["attributes"]
    assert "TEXCOORD_1" not in primitives[3]["attributes"]
    assert header["extensionsUsed"] == ["KHR_materials_unlit"]

    import trimesh

    loaded = trimesh.load(path, process=False)
    assert set(loaded.graph.nodes_geometry) == {"a", "b", "c", "plain", "plain-2"}
    bounds = {
        node: loaded.geometry[loaded.graph[node][1]].bounds for node in loaded.graph.nodes_geometry
    }
    np.testing.assert_allclose(bounds["c"], [[2, 2, 2], [3, 3, 2]])


# --------------------------------------------------------------------------------------
# fill_hidden
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def hidden_cornell(cornell_solved: Solved) -> tuple[RadiosityMesh, np.ndarray]:
    """The Cornell box mesh (the lamp covers ceiling receivers) and its solved radiosity."""
    prepared, result = cornell_solved
    mesh = prepared.mesh
    assert mesh.receiver_visible is not None
    hidden = ~mesh.receiver_visible
    assert hidden.sum() >= 5
    # ceiling receivers behind the lamp; the floor under the blocks is left out with its
    # triangles (enclosed), and the floor receivers on the blocks' contact lines, which
    # imprinting puts there, see the blocks' fronts
    height = mesh.receiver_position[hidden, 1]
    assert (height > 0.5).all()
    return mesh, result.radiosity


def test_fill_hidden_first_ring_is_the_mean_of_visible_neighbours(
    hidden_cornell: tuple[RadiosityMesh, np.ndarray],
) -> None:
    mesh, radiosity = hidden_cornell
    assert mesh.receiver_visible is not None
    visible = mesh.receiver_visible
    filled = fill_hidden(mesh, radiosity)
    np.testing.assert_array_equal(filled[visible], radiosity[visible])
    neighbours = _edge_neighbours(mesh)
    first_ring = 0
    for r in np.flatnonzero(~visible):
        seen = [n for n in neighbours[r] if visible[n]]
        if seen:
            first_ring += 1
            np.testing.assert_allclose(filled[r], radiosity[seen].mean(axis=0), rtol=1e-12)
    assert first_ring > 0
    np.testing.assert_allclose(filled, _fill_reference(neighbours, visible, radiosity), rtol=1e-12)


def _hidden_disc(
    centre: tuple[float, float], radius: float
) -> tuple[RadiosityMesh, np.ndarray, np.ndarray]:
    """A unit quad's mesh with the receivers within ``radius`` of ``centre`` hidden, and a
    radiosity that differs at every receiver."""
    mesh = build_mesh(
        one_quad_scene([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
        MeshSettings(receivers=400, patches=10),
    )
    p = mesh.receiver_position
    visible = np.hypot(p[:, 0] - centre[0], p[:, 1] - centre[1]) > radius
    radiosity = np.stack([1 + p[:, 0], 2 + p[:, 1] ** 2, 1 + p[:, 0] * p[:, 1]], axis=1)
    radiosity[~visible] = -5.0  # what the solve left there: must not leak into the fill
    return dataclasses.replace(mesh, receiver_visible=visible), radiosity, visible


def test_fill_hidden_fills_ring_by_ring_inward() -> None:
    mesh, radiosity, visible = _hidden_disc((0.5, 0.5), 0.3)
    neighbours = _edge_neighbours(mesh)
    filled = fill_hidden(mesh, radiosity)
    np.testing.assert_array_equal(filled[visible], radiosity[visible])
    expected = _fill_reference(neighbours, visible, radiosity)
    np.testing.assert_allclose(filled, expected, rtol=1e-12)
    # more than one ring, and every hidden receiver reached: no -5 left
    first = [r for r in np.flatnonzero(~visible) if any(visible[n] for n in neighbours[r])]
    assert len(first) < (~visible).sum()
    assert filled.min() > 0
    # filled values stay within the range of the visible ones (means of means)
    assert (filled >= radiosity[visible].min(axis=0) - 1e-12).all()
    assert (filled <= radiosity[visible].max(axis=0) + 1e-12).all()


def test_fill_hidden_rings_limit_the_depth() -> None:
    mesh, radiosity, visible = _hidden_disc((0.5, 0.5), 0.3)
    neighbours = _edge_neighbours(mesh)
    one = fill_hidden(mesh, radiosity, rings=1)
    np.testing.assert_allclose(one, _fill_reference(neighbours, visible, radiosity, 1), rtol=1e-12)
    assert (one == -5.0).all(axis=1).any()  # the inner receivers are not reached
    assert np.array_equal(fill_hidden(mesh, radiosity, rings=0), radiosity)


def test_fill_hidden_without_visibility_returns_the_input() -> None:
    mesh, radiosity, _ = _hidden_disc((0.5, 0.5), 0.3)
    plain = dataclasses.replace(mesh, receiver_visible=None)
    filled = fill_hidden(plain, radiosity)
    np.testing.assert_array_equal(filled, radiosity)
    assert filled is not radiosity  # a copy: the caller's array is not aliased
    everything = dataclasses.replace(mesh, receiver_visible=np.ones(mesh.receiver_count, bool))
    np.testing.assert_array_equal(fill_hidden(everything, radiosity), radiosity)


def test_fill_hidden_on_the_mesh_border_is_the_plain_mean() -> None:
    # hidden receivers along the quad's left edge, x = 0: a border receiver's visible
    # neighbours are joined by a border edge (one triangle) and by inner edges (two)
    mesh, radiosity, visible = _hidden_disc((0.0, 0.0), 0.2)
    neighbours = _edge_neighbours(mesh)
    filled = fill_hidden(mesh, radiosity)
    for r in np.flatnonzero(~visible):
        seen = [n for n in neighbours[r] if visible[n]]
        if seen:
            np.testing.assert_allclose(filled[r], radiosity[seen].mean(axis=0), rtol=1e-12)


# --------------------------------------------------------------------------------------
# The command line
# --------------------------------------------------------------------------------------

SMALL = ["--receivers", "500", "--patches", "60", "-q"]


@pytest.mark.parametrize(
    "options",
    [["--uv-set", "1"], ["--uv-set", "atlas"], ["--lightmap-per-mesh"]],
)
def test_lightmap_options_need_lightmap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], options: list[str]
) -> None:
    out = tmp_path / "out"
    status, stdout, err = run_cli(
        ["render", str(CORNELL_UV), "-o", str(out), *options, *SMALL], capsys
    )
    assert status != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "--lightmap" in lines[0] and "Traceback" not in err
    assert stdout == ""
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("value", ["banana", "-1", "1.5", ""])
def test_bad_uv_set_values_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], value: str
) -> None:
    out = tmp_path / "out"
    status, _, err = run_cli(
        ["render", str(CORNELL_UV), "-o", str(out), "--lightmap", "--uv-set", value, *SMALL],
        capsys,
    )
    assert status != 0
    assert "uv-set" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    assert not out.exists() or not any(out.iterdir())


def test_superscript_uv_set_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    status, _, err = run_cli(
        ["render", str(CORNELL_UV), "-o", str(out), "--lightmap", "--uv-set", "²", *SMALL],
        capsys,
    )
    assert status == 1
    assert "uv-set" in err


def test_cli_per_mesh_with_model_uvs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    status, _, err = run_cli(
        [
            "render",
            str(CORNELL_UV),
            "-o",
            str(out),
            "--lightmap",
            "--lightmap-resolution",
            "32",
            "--lightmap-per-mesh",
            "--uv-set",
            "1",
            *SMALL,
        ],
        capsys,
    )
    assert status == 0, err
    report = json.loads((out / "report.json").read_text())
    assert report["settings"]["lightmap"]["uv_set"] == 1
    assert report["settings"]["lightmap"]["per_mesh"] is True
    for name in CORNELL_OBJECTS:
        assert read_image(out / f"cornell-box-uv.{name}.lightmap.exr").shape[:2] == (32, 32)


def test_cli_explicit_uv_set_missing_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    obj = SCENES / "cornell-box.obj"
    status, _, err = run_cli(
        ["render", str(obj), "-o", str(out), "--lightmap", "--uv-set", "1", *SMALL], capsys
    )
    assert status == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert str(obj) in lines[0] and "UV set 1" in lines[0]
