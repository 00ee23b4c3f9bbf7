"""Lightmap UV sets read from glTF, OBJ, PLY and TOML scenes: every triangle corner gets the
UV the file gives for it (v down), checked against the numbers written into the file."""

from __future__ import annotations

import base64
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from raytrad.errors import SceneError
from raytrad.formats.glb import TRIANGLES, GltfBuffers, glb_container
from raytrad.scene import Scene, triangle_areas_normals
from raytrad.scene.builtin import cornell_box
from raytrad.scenefiles import load_scene, load_scene_file, write_glb
from tests.conftest import SCENES

#: float32 UVs: trimesh flips v on load and the loader flips it back, one rounding each.
F32_ATOL = 2.0**-22

# --------------------------------------------------------------------------- matching

#: Corner permutations; the first three keep the winding, the last three reverse it.
PERMUTATIONS = [(0, 1, 2), (1, 2, 0), (2, 0, 1), (0, 2, 1), (2, 1, 0), (1, 0, 2)]


def _match(corners: np.ndarray, expected: np.ndarray, atol: float) -> tuple[np.ndarray, ...]:
    """Which expected triangle each triangle is, and how its corners map onto it.

    Parameters
    ----------
    corners : (T, 3, 3) float
        Corner positions of the loaded triangles [m].
    expected : (N, 3, 3) float
        Corner positions of the triangles written to the file [m].

    Returns
    -------
    index : (T,) int
        ``corners[i]`` has the corners of ``expected[index[i]]`` ...
    perm : (T, 3) int
        ... with ``corners[i, c] == expected[index[i], perm[i, c]]``.
    """
    corners, expected = np.asarray(corners), np.asarray(expected)
    index = np.full(len(corners), -1)
    perm = np.zeros((len(corners), 3), dtype=np.int64)
    for p in PERMUTATIONS:
        moved = expected[:, list(p)]  # (N, 3, 3)
        distance = np.abs(corners[:, None] - moved[None]).max(axis=(2, 3))  # (T, N)
        hit = distance <= atol
        assert (hit.sum(axis=1) <= 1).all(), "ambiguous expected triangles"
        rows = np.nonzero(hit.any(axis=1))[0]
        assert (index[rows] == -1).all()
        index[rows] = hit[rows].argmax(axis=1)
        perm[rows] = p
    assert (index >= 0).all(), f"{int((index < 0).sum())} triangles match no expected triangle"
    return index, perm


def _expected_uv(index: np.ndarray, perm: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(T, 3, 2) expected UVs of matched triangles, in the loaded corner order."""
    return np.asarray(uv)[index[:, None], perm]


def _keeps_winding(perm: np.ndarray) -> np.ndarray:
    """(T,) bool: the corner map is a rotation (same winding)."""
    return np.array([tuple(p) in PERMUTATIONS[:3] for p in perm.tolist()])


def _object_of(scene: Scene) -> list[str]:
    return [scene.object_names[i] for i in scene.object_index]


# --------------------------------------------------------------------------- glTF

# A unit quad (two triangles) in the plane z = 0 facing +z; the node moves it to z = 2.
QUAD = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
QUAD_INDICES = np.array([[0, 1, 2], [0, 2, 3]])
QUAD_UV1 = np.array([[0.125, 0.875], [0.3333333333, 0.9], [0.7, 0.1234567891], [0.05, 0.01]])
QUAD_UV0 = np.array([[0.6, 0.2], [0.8, 0.2], [0.8, 0.4], [0.6, 0.4]])
# Two single triangles: one with only TEXCOORD_0, one with only TEXCOORD_1 and no material.
LEDGE = np.array([[0, 0, 5], [1, 0, 5], [0, 1, 5]], dtype=np.float64)
LEDGE_UV0 = np.array([[0.11, 0.22], [0.33, 0.44], [0.55, 0.66]])
BARE = np.array([[3, 0, 0], [4, 0, 0], [3, 1, 0]], dtype=np.float64)
BARE_UV1 = np.array([[0.91, 0.02], [0.97, 0.03], [0.93, 0.51]])
QUAD_TRANSLATION = np.array([0.0, 0.0, 2.0])


def _f32(values: np.ndarray) -> np.ndarray:
    """The float64 values of ``values`` stored as float32."""
    return np.asarray(values, dtype=np.float32).astype(np.float64)


def _write_gltf(path: Path, meshes: list[dict[str, Any]], nodes: list[dict[str, Any]]) -> Path:
    """A .gltf (data URI) or .glb file of ``meshes``, each ``{"name", "primitives"}`` whose
    primitives give float arrays by attribute name, ``"indices"`` and maybe ``"material"``.
    """
    buffers = GltfBuffers()
    json_meshes = []
    for mesh in meshes:
        primitives = []
        for primitive in mesh["primitives"]:
            attributes = {
                name: buffers.add(np.asarray(values, dtype="<f4"), f"VEC{np.shape(values)[1]}")
                for name, values in primitive["attributes"].items()
            }
            entry: dict[str, Any] = {
                "attributes": attributes,
                "indices": buffers.add(
                    np.asarray(primitive["indices"], dtype="<u4").reshape(-1), "SCALAR", True
                ),
                "mode": TRIANGLES,
            }
            if "material" in primitive:
                entry["material"] = primitive["material"]
            primitives.append(entry)
        json_meshes.append({"name": mesh["name"], "primitives": primitives})
    blob = buffers.binary()
    document: dict[str, Any] = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": json_meshes,
        "materials": [
            {"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}}
        ],
        "accessors": buffers.accessors,
        "bufferViews": buffers.views,
    }
    if path.suffix == ".gltf":
        uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        document["buffers"] = [{"byteLength": len(blob), "uri": uri}]
        path.write_text(json.dumps(document))
    else:
        document["buffers"] = [{"byteLength": len(blob)}]
        path.write_bytes(glb_container(json.dumps(document).encode(), blob))
    return path


def _three_node_file(path: Path) -> Path:
    """Nodes ``panel`` (quad, sets 0 and 1), ``ledge`` (set 0 only), ``bare`` (set 1 only,
    no material)."""
    meshes = [
        {
            "name": "quad",
            "primitives": [
                {
                    "attributes": {
                        "POSITION": QUAD,
                        "TEXCOORD_0": QUAD_UV0,
                        "TEXCOORD_1": QUAD_UV1,
                    },
                    "indices": QUAD_INDICES,
                    "material": 0,
                }
            ],
        },
        {
            "name": "ledge",
            "primitives": [
                {
                    "attributes": {"POSITION": LEDGE, "TEXCOORD_0": LEDGE_UV0},
                    "indices": [0, 1, 2],
                    "material": 0,
                }
            ],
        },
        {
            "name": "bare",
            "primitives": [
                {"attributes": {"POSITION": BARE, "TEXCOORD_1": BARE_UV1}, "indices": [0, 1, 2]}
            ],
        },
    ]
    nodes = [
        {"name": "panel", "mesh": 0, "translation": QUAD_TRANSLATION.tolist()},
        {"name": "ledge", "mesh": 1},
        {"name": "bare", "mesh": 2},
    ]
    return _write_gltf(path, meshes, nodes)


def _three_node_expected(uv_set: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Corners (4, 3, 3) [m], UVs (4, 3, 2) (NaN where the set is missing), node names."""
    nan3 = np.full((3, 2), np.nan)
    quad_uv = _f32(QUAD_UV1 if uv_set == 1 else QUAD_UV0)[QUAD_INDICES]
    corners = np.concatenate([(QUAD + QUAD_TRANSLATION)[QUAD_INDICES], LEDGE[None], BARE[None]])
    uv = np.concatenate(
        [
            quad_uv,
            (nan3 if uv_set == 1 else _f32(LEDGE_UV0))[None],
            (_f32(BARE_UV1) if uv_set == 1 else nan3)[None],
        ]
    )
    return corners, uv, ["panel", "panel", "ledge", "bare"]


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
@pytest.mark.parametrize("uv_set", [1, 0])
def test_gltf_texcoord_set_goes_to_the_right_corners(
    tmp_path: Path, suffix: str, uv_set: int
) -> None:
    scene = load_scene(_three_node_file(tmp_path / f"model{suffix}"), uv_set=uv_set)
    corners, uv, objects = _three_node_expected(uv_set)
    assert scene.triangle_count == 4
    assert scene.lightmap_uv is not None
    assert scene.lightmap_uv.shape == (4, 3, 2)
    assert scene.lightmap_uv.dtype == np.float64
    index, perm = _match(scene.triangle_vertices(), corners, 1e-6)
    assert sorted(index.tolist()) == [0, 1, 2, 3]
    assert _keeps_winding(perm).all()
    # v is top-down in glTF and stays so: the loaded numbers are the file's numbers.
    np.testing.assert_allclose(
        scene.lightmap_uv, _expected_uv(index, perm, uv), rtol=0, atol=F32_ATOL
    )
    assert _object_of(scene) == [objects[i] for i in index]


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_gltf_missing_set_gives_nan_rows_only_there(tmp_path: Path, suffix: str) -> None:
    scene = load_scene(_three_node_file(tmp_path / f"model{suffix}"), uv_set=1)
    assert scene.lightmap_uv is not None
    names = _object_of(scene)
    nan_rows = np.isnan(scene.lightmap_uv).all(axis=(1, 2))
    finite_rows = np.isfinite(scene.lightmap_uv).all(axis=(1, 2))
    assert [n for n, bad in zip(names, nan_rows, strict=True) if bad] == ["ledge"]
    assert finite_rows.sum() == 3
    # TEXCOORD_2 is in no primitive: every row is NaN, none is dropped.
    scene2 = load_scene(tmp_path / f"model{suffix}", uv_set=2)
    assert scene2.triangle_count == 4
    assert scene2.lightmap_uv is not None and np.isnan(scene2.lightmap_uv).all()


def test_gltf_primitive_without_material_keeps_uvs_and_default_material(tmp_path: Path) -> None:
    scene = load_scene(_three_node_file(tmp_path / "model.glb"), uv_set=1)
    assert scene.lightmap_uv is not None
    bare = np.array(_object_of(scene)) == "bare"
    assert bare.sum() == 1
    index, perm = _match(scene.triangle_vertices()[bare], BARE[None], 1e-6)
    np.testing.assert_allclose(
        scene.lightmap_uv[bare], _expected_uv(index, perm, _f32(BARE_UV1)[None]), atol=F32_ATOL
    )
    # glTF's default material (reflectance 1), not the file's "grey".
    np.testing.assert_array_equal(scene.reflectance[bare], [[1.0, 1.0, 1.0]])
    np.testing.assert_array_equal(scene.reflectance[~bare], 0.5)


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_gltf_without_uv_set_has_no_lightmap_uv(tmp_path: Path, suffix: str) -> None:
    scene = load_scene(_three_node_file(tmp_path / f"model{suffix}"))
    assert scene.lightmap_uv is None
    assert set(scene.object_names) == {"panel", "ledge", "bare"}
    assert scene.triangle_count == 4
    # Without a UV set the primitive without a material still uses glTF's default.
    assert sorted(scene.reflectance[:, 0].tolist()) == [0.5, 0.5, 0.5, 1.0]


def test_gltf_object_names_are_the_node_names(tmp_path: Path) -> None:
    scene = load_scene(_three_node_file(tmp_path / "model.glb"), uv_set=0)
    assert sorted(scene.object_names) == ["bare", "ledge", "panel"]
    assert np.bincount(scene.object_index).tolist() == [
        {"panel": 2, "ledge": 1, "bare": 1}[n] for n in scene.object_names
    ]


def test_gltf_node_with_two_primitives_is_one_object(tmp_path: Path) -> None:
    second = {"attributes": {"POSITION": BARE, "TEXCOORD_1": BARE_UV1}, "indices": [0, 1, 2]}
    first = {
        "attributes": {"POSITION": QUAD, "TEXCOORD_1": QUAD_UV1},
        "indices": QUAD_INDICES,
        "material": 0,
    }
    path = _write_gltf(
        tmp_path / "two.glb",
        [{"name": "mesh", "primitives": [first, second]}],
        [{"name": "panel", "mesh": 0}],
    )
    scene = load_scene(path, uv_set=1)
    assert scene.triangle_count == 3
    assert scene.object_names == ("panel",)


def test_gltf_mirroring_node_keeps_uvs_on_their_corners(tmp_path: Path) -> None:
    quad = {
        "attributes": {"POSITION": QUAD, "TEXCOORD_1": QUAD_UV1},
        "indices": QUAD_INDICES,
        "material": 0,
    }
    path = _write_gltf(
        tmp_path / "mirror.glb",
        [{"name": "quad", "primitives": [quad]}],
        [{"name": "panel", "mesh": 0, "scale": [-1.0, 1.0, 1.0]}],
    )
    scene = load_scene(path, uv_set=1)
    mirrored = (QUAD * [-1.0, 1.0, 1.0])[QUAD_INDICES]
    index, perm = _match(scene.triangle_vertices(), mirrored, 1e-6)
    assert sorted(index.tolist()) == [0, 1]
    assert not _keeps_winding(perm).any()  # reversed: the front still faces +z
    _, normals = triangle_areas_normals(scene.triangle_vertices())
    np.testing.assert_allclose(normals, [[0.0, 0.0, 1.0]] * 2, atol=1e-6)
    assert scene.lightmap_uv is not None
    np.testing.assert_allclose(
        scene.lightmap_uv, _expected_uv(index, perm, _f32(QUAD_UV1)[QUAD_INDICES]), atol=F32_ATOL
    )


# --------------------------------------------------------------------------- round trip


def test_write_glb_round_trip_keeps_every_corner_uv(tmp_path: Path) -> None:
    box = cornell_box()
    rng = np.random.default_rng(7)
    uv = rng.uniform(0.0, 1.0, size=(box.triangle_count, 3, 2))
    box = replace(box, lightmap_uv=uv)
    write_glb(box, tmp_path / "box.glb")
    loaded = load_scene(tmp_path / "box.glb", uv_set=1)
    assert loaded.triangle_count == box.triangle_count
    assert set(loaded.object_names) == set(box.object_names)
    index, perm = _match(loaded.triangle_vertices(), box.triangle_vertices(), 1e-6)
    assert sorted(index.tolist()) == list(range(box.triangle_count))
    assert _keeps_winding(perm).all()
    assert loaded.lightmap_uv is not None
    np.testing.assert_allclose(loaded.lightmap_uv, _expected_uv(index, perm, uv), atol=1e-6)
    assert _object_of(loaded) == [_object_of(box)[i] for i in index]
    # The same file without a UV set reads no UVs.
    assert load_scene(tmp_path / "box.glb").lightmap_uv is None


def test_write_glb_without_uvs_reads_back_nan(tmp_path: Path) -> None:
    box = cornell_box()
    assert box.lightmap_uv is None
    write_glb(box, tmp_path / "box.glb")
    loaded = load_scene(tmp_path / "box.glb", uv_set=1)
    assert loaded.triangle_count == box.triangle_count
    assert loaded.lightmap_uv is not None and np.isnan(loaded.lightmap_uv).all()


# --------------------------------------------------------------------------- OBJ

# A unit quad in z = 0 facing +z, its two triangles on separate UV islands: vertices 1 and
# 3 (the shared diagonal) have different vt on each face.
SEAM_POSITIONS = QUAD
SEAM_VT = np.array([[0.1, 0.2], [0.4, 0.2], [0.4, 0.6], [0.6, 0.2], [0.9, 0.6], [0.6, 0.6]])
SEAM_FACES = [[(1, 1), (2, 2), (3, 3)], [(1, 4), (3, 5), (4, 6)]]  # (v, vt), 1-based
SEAM_OBJ = (
    "mtllib seam.mtl\n"
    + "".join(f"v {x:g} {y:g} {z:g}\n" for x, y, z in SEAM_POSITIONS)
    + "".join(f"vt {u!r} {v!r}\n" for u, v in SEAM_VT.tolist())
    + "usemtl white\n"
    + "".join("f " + " ".join(f"{v}/{t}" for v, t in face) + "\n" for face in SEAM_FACES)
)
SEAM_MTL = "newmtl white\nKd 0.5 0.5 0.5\n"


def _seam_expected() -> tuple[np.ndarray, np.ndarray]:
    """Corners (2, 3, 3) [m] and UVs (2, 3, 2), v flipped to top-down."""
    corners = np.array([[SEAM_POSITIONS[v - 1] for v, _ in face] for face in SEAM_FACES])
    uv = np.array([[SEAM_VT[t - 1] for _, t in face] for face in SEAM_FACES])
    uv[..., 1] = 1.0 - uv[..., 1]
    return corners, uv


def _seam_obj(directory: Path, stem: str = "seam") -> Path:
    (directory / "seam.mtl").write_text(SEAM_MTL)
    path = directory / f"{stem}.obj"
    path.write_text(SEAM_OBJ)
    return path


def test_obj_seam_keeps_per_corner_uvs(tmp_path: Path) -> None:
    scene = load_scene(_seam_obj(tmp_path), uv_set=0)
    corners, uv = _seam_expected()
    assert scene.triangle_count == 2
    index, perm = _match(scene.triangle_vertices(), corners, 1e-12)
    assert sorted(index.tolist()) == [0, 1]
    assert _keeps_winding(perm).all()
    assert scene.lightmap_uv is not None
    np.testing.assert_allclose(scene.lightmap_uv, _expected_uv(index, perm, uv), atol=1e-12)
    # The diagonal's ends carry two different UVs, one per face.
    assert not np.allclose(uv[0, 0], uv[1, 0])
    assert scene.object_names == ("seam",)
    assert scene.material_names == ("white",)


def test_obj_without_uv_set_has_no_lightmap_uv(tmp_path: Path) -> None:
    scene = load_scene(_seam_obj(tmp_path))
    assert scene.lightmap_uv is None
    assert scene.triangle_count == 2


def test_obj_higher_uv_set_is_all_nan(tmp_path: Path) -> None:
    scene = load_scene(_seam_obj(tmp_path), uv_set=1)
    assert scene.triangle_count == 2
    assert scene.lightmap_uv is not None
    assert np.isnan(scene.lightmap_uv).all()


def test_obj_without_vt_gives_nan_rows(tmp_path: Path) -> None:
    path = tmp_path / "plain.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = load_scene(path, uv_set=0)
    assert scene.lightmap_uv is not None
    assert scene.lightmap_uv.shape == (1, 3, 2)
    assert np.isnan(scene.lightmap_uv).all()


# --------------------------------------------------------------------------- PLY

PLY_POSITIONS = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [3, 0, 0]], dtype=float)
PLY_ST = np.array([[0.1, 0.15], [0.3, 0.25], [0.35, 0.75], [0.05, 0.8], [0.9, 0.45]])
PLY_FACES = [[0, 1, 2, 3], [1, 4, 2]]  # a quad (fanned 0-1-2, 0-2-3) and a triangle


def _ply(directory: Path, u: str, v: str) -> Path:
    header = [
        "ply",
        "format ascii 1.0",
        f"element vertex {len(PLY_POSITIONS)}",
        *(f"property double {name}" for name in ("x", "y", "z", u, v)),
        f"element face {len(PLY_FACES)}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    rows = [
        " ".join(repr(float(x)) for x in (*p, *st))
        for p, st in zip(PLY_POSITIONS, PLY_ST, strict=True)
    ]
    faces = [" ".join(str(i) for i in (len(face), *face)) for face in PLY_FACES]
    path = directory / "model.ply"
    path.write_text("\n".join(header + rows + faces) + "\n")
    return path


@pytest.mark.parametrize(("u", "v"), [("s", "t"), ("u", "v"), ("texture_u", "texture_v")])
def test_ply_vertex_uvs_are_set_zero_with_v_flipped(tmp_path: Path, u: str, v: str) -> None:
    scene = load_scene(_ply(tmp_path, u, v), uv_set=0)
    fans = [(0, 1, 2), (0, 2, 3), (1, 4, 2)]
    corners = PLY_POSITIONS[fans]
    uv = np.column_stack([PLY_ST[:, 0], 1.0 - PLY_ST[:, 1]])[fans]
    assert scene.triangle_count == 3
    index, perm = _match(scene.triangle_vertices(), corners, 1e-12)
    assert sorted(index.tolist()) == [0, 1, 2]
    assert _keeps_winding(perm).all()
    assert scene.lightmap_uv is not None
    np.testing.assert_allclose(scene.lightmap_uv, _expected_uv(index, perm, uv), atol=1e-12)


def test_ply_other_uv_sets_are_nan_or_absent(tmp_path: Path) -> None:
    path = _ply(tmp_path, "s", "t")
    one = load_scene(path, uv_set=1)
    assert one.lightmap_uv is not None and one.lightmap_uv.shape == (3, 3, 2)
    assert np.isnan(one.lightmap_uv).all()
    assert load_scene(path).lightmap_uv is None


# --------------------------------------------------------------------------- TOML


def _toml(directory: Path, body: str) -> Path:
    path = directory / "scene.toml"
    path.write_text(body)
    return path


def test_toml_default_names_are_the_stem_then_numbered(tmp_path: Path) -> None:
    _seam_obj(tmp_path)
    body = '[[mesh]]\nfile = "seam.obj"\n\n[[mesh]]\nfile = "seam.obj"\ntranslate = [0, 0, 1]\n'
    scene = load_scene(_toml(tmp_path, body), uv_set=0)
    assert scene.object_names == ("seam", "seam_1")
    z = scene.triangle_vertices()[:, :, 2]
    names = np.array(_object_of(scene))
    np.testing.assert_array_equal(z[names == "seam"], 0.0)
    np.testing.assert_array_equal(z[names == "seam_1"], 1.0)
    # Both copies carry the file's UVs.
    corners, uv = _seam_expected()
    for name, shift in (("seam", 0.0), ("seam_1", 1.0)):
        mine = names == name
        index, perm = _match(
            scene.triangle_vertices()[mine], corners + np.array([0.0, 0.0, shift]), 1e-12
        )
        assert scene.lightmap_uv is not None
        np.testing.assert_allclose(
            scene.lightmap_uv[mine], _expected_uv(index, perm, uv), atol=1e-12
        )


def test_toml_explicit_name_and_numbering_after_it(tmp_path: Path) -> None:
    _seam_obj(tmp_path)
    body = (
        '[[mesh]]\nfile = "seam.obj"\nname = "wall"\n\n'
        '[[mesh]]\nfile = "seam.obj"\n\n'
        '[[mesh]]\nfile = "seam.obj"\n'
    )
    scene = load_scene(_toml(tmp_path, body))
    assert scene.object_names == ("wall", "seam", "seam_1")
    assert np.bincount(scene.object_index).tolist() == [2, 2, 2]
    assert scene.lightmap_uv is None


def test_toml_duplicate_explicit_name_is_an_error(tmp_path: Path) -> None:
    _seam_obj(tmp_path)
    body = (
        '[[mesh]]\nfile = "seam.obj"\nname = "wall"\n\n[[mesh]]\nfile = "seam.obj"\nname = "wall"\n'
    )
    path = _toml(tmp_path, body)
    with pytest.raises(SceneError, match=r"mesh\[1\]\.name") as info:
        load_scene(path)
    assert info.value.path == path
    assert "wall" in str(info.value)


def test_toml_mesh_file_with_several_objects_gives_slash_names(tmp_path: Path) -> None:
    _three_node_file(tmp_path / "model.glb")
    body = '[[mesh]]\nfile = "model.glb"\nname = "kit"\n'
    scene = load_scene(_toml(tmp_path, body), uv_set=1)
    assert sorted(scene.object_names) == ["kit/bare", "kit/ledge", "kit/panel"]
    corners, uv, objects = _three_node_expected(1)
    index, perm = _match(scene.triangle_vertices(), corners, 1e-6)
    assert _object_of(scene) == [f"kit/{objects[i]}" for i in index]
    assert scene.lightmap_uv is not None
    np.testing.assert_allclose(scene.lightmap_uv, _expected_uv(index, perm, uv), atol=F32_ATOL)


@pytest.mark.parametrize("how", ["load_scene", "description"])
def test_toml_mirror_keeps_uvs_on_their_mirrored_corners(tmp_path: Path, how: str) -> None:
    _seam_obj(tmp_path)
    path = _toml(tmp_path, '[[mesh]]\nfile = "seam.obj"\nscale = [-1, 1, 1]\n')
    if how == "load_scene":
        scene = load_scene(path, uv_set=0)
    else:
        scene = load_scene_file(path, uv_set=0).scene
    corners, uv = _seam_expected()
    mirrored = corners * [-1.0, 1.0, 1.0]
    index, perm = _match(scene.triangle_vertices(), mirrored, 1e-12)
    assert sorted(index.tolist()) == [0, 1]
    # The winding is reversed so the lit side still faces +z (the mirror of +z) ...
    assert not _keeps_winding(perm).any()
    _, normals = triangle_areas_normals(scene.triangle_vertices())
    np.testing.assert_allclose(normals, [[0.0, 0.0, 1.0]] * 2, atol=1e-12)
    # ... and every UV stays on its (mirrored) corner.
    assert scene.lightmap_uv is not None
    np.testing.assert_allclose(scene.lightmap_uv, _expected_uv(index, perm, uv), atol=1e-12)


def test_toml_scene_description_passes_the_uv_set(tmp_path: Path) -> None:
    _three_node_file(tmp_path / "model.gltf")
    path = _toml(tmp_path, '[[mesh]]\nfile = "model.gltf"\n')
    corners, uv, _ = _three_node_expected(0)
    scene = load_scene_file(path, uv_set=0).scene
    index, perm = _match(scene.triangle_vertices(), corners, 1e-6)
    assert scene.lightmap_uv is not None
    np.testing.assert_allclose(scene.lightmap_uv, _expected_uv(index, perm, uv), atol=F32_ATOL)
    assert load_scene_file(path).scene.lightmap_uv is None


def test_gltf_objects_come_in_file_node_order() -> None:
    path = SCENES / "cornell-box-uv.glb"
    data = path.read_bytes()
    length = int.from_bytes(data[12:16], "little")
    document = json.loads(data[20 : 20 + length])
    meshes = [n["name"] for n in document["nodes"] if "mesh" in n]
    assert list(load_scene(path).object_names) == meshes
