"""OBJ and MTL conformance: each spec feature read right, against hand-computed values.

The table covers what real exporters write: relative indices between interleaved ``v``
blocks (McGuire's Cornell box), tabs and other white space, ``\\`` continuations,
convex and non-convex n-gons, ``o``/``g``/``usemtl`` variants, missing or partial MTL,
MTL bytes in other encodings, ``Ke``; and the malformed files that must be refused.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np
import pytest

from raytrad.errors import SceneError
from raytrad.scenefiles import load_scene
from raytrad.scenefiles.obj_text import parse_mtl
from tests.scenefiles.conformance import (
    FLOOR,
    FLOOR_AND_LAMP_MTL,
    L_FLOOR,
    LAMP,
    inside_notch,
    measure,
)


def _v(points: tuple[tuple[float, ...], ...], sep: str = " ") -> str:
    return "".join(f"v{sep}{x}{sep}{y}{sep}{z}\n" for x, y, z in points)


def _write(tmp_path: Path, obj: str, mtl: str | bytes | None = FLOOR_AND_LAMP_MTL) -> Path:
    if mtl is not None:
        data = mtl.encode() if isinstance(mtl, str) else mtl
        (tmp_path / "scene.mtl").write_bytes(data)
    path = tmp_path / "scene.obj"
    path.write_text(("mtllib scene.mtl\n" if mtl is not None else "") + obj)
    return path


ABSOLUTE = "usemtl floor\n" + _v(FLOOR) + "f 1 2 3 4\nusemtl lamp\n" + _v(LAMP) + "f 5 6 7 8\n"

FLOOR_AND_LAMP_FILES = {
    "absolute indices": ABSOLUTE,
    "relative indices between v blocks": (
        "usemtl floor\n" + _v(FLOOR) + "f -4 -3 -2 -1\nusemtl lamp\n" + _v(LAMP) + "f -4 -3 -2 -1\n"
    ),
    "tab after v": ABSOLUTE.replace("v ", "v\t"),
    "tabs and runs of spaces everywhere": ABSOLUTE.replace(" ", " \t  "),
    "CRLF line ends": ABSOLUTE.replace("\n", "\r\n"),
    "backslash continuation": ABSOLUTE.replace("f 1 2 3 4", "f 1 2 \\\n3 4"),
    "v/vt/vn corners, relative": (
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 1 0\nusemtl floor\n"
        + _v(FLOOR)
        + "f -4/-4/-1 -3/-3/-1 -2/-2/-1 -1/-1/-1\nusemtl lamp\n"
        + _v(LAMP)
        + "f -4//1 -3//1 -2//1 -1//1\n"
    ),
    "w coordinate and vertex colours": ABSOLUTE.replace("v 0 0 0\n", "v 0 0 0 1.0\n").replace(
        "v 1 0 1\n", "v 1 0 1 0.2 0.3 0.4\n"
    ),
    "comments, blank lines, l and p statements": (
        "# a comment\n\n"
        + ABSOLUTE.replace("f 1 2 3 4", "f 1 2 3 4 # the floor")
        + "l 1 2\np 3\n# the end\n"
    ),
    "triangles instead of quads": (
        "usemtl floor\n"
        + _v(FLOOR)
        + "f 1 2 3\nf 1 3 4\nusemtl lamp\n"
        + _v(LAMP)
        + "f 5 6 7\nf 5 7 8\n"
    ),
}


@pytest.mark.parametrize("case", sorted(FLOOR_AND_LAMP_FILES))
def test_floor_and_lamp_variants_read_the_same(tmp_path: Path, case: str) -> None:
    measured = measure(load_scene(_write(tmp_path, FLOOR_AND_LAMP_FILES[case])))
    assert measured.triangles == 4
    assert measured.area_of("floor") == pytest.approx(1.0, rel=1e-12)
    assert measured.area_of("lamp") == pytest.approx(0.04, rel=1e-9)
    assert measured.emitted_power == pytest.approx(0.4, rel=1e-9)
    np.testing.assert_allclose(measured.lower, [0, 0, 0])
    np.testing.assert_allclose(measured.upper, [1, 1, 1])
    # floor faces up, lamp faces down (winding kept through every rewrite)
    assert np.allclose(np.abs(measured.normals[:, 1]), 1.0)
    assert (measured.normals[:, 1] > 0).sum() == 2


L_FLOOR_FACES = {
    "one 6-corner face": "f 1 2 3 4 5 6\n",
    "the same face from another corner": "f 4 5 6 1 2 3\n",
    "relative indices": "f -6 -5 -4 -3 -2 -1\n",
    "a reflex-corner quad and a triangle": "f 6 1 2 3\nf 3 4 5\nf 3 5 6\n",
    "two concave quads": "f 1 2 3 6\nf 6 3 4 5\n",
}


@pytest.mark.parametrize("case", sorted(L_FLOOR_FACES))
def test_non_convex_polygons_cover_exactly_their_area(tmp_path: Path, case: str) -> None:
    obj = "usemtl floor\n" + _v(L_FLOOR) + L_FLOOR_FACES[case]
    scene = load_scene(_write(tmp_path, obj))
    measured = measure(scene)
    assert measured.area == pytest.approx(3.0, rel=1e-12)
    assert inside_notch(scene) == 0.0
    assert (measured.normals[:, 1] > 0.999).all()


def test_a_star_shaped_polygon_is_clipped_into_ears(tmp_path: Path) -> None:
    # a 5-pointed star (10 corners) in the plane x + y + z = 0: area 10 x the area of the
    # triangle (centre, outer tip, inner corner)
    outer, inner = 1.0, 0.4
    angles = np.pi / 5 * np.arange(10)
    radii = np.where(np.arange(10) % 2 == 0, outer, inner)
    u = np.array([1, -1, 0]) / np.sqrt(2)
    w = np.array([1, 1, -2]) / np.sqrt(6)
    points = (radii * np.cos(angles))[:, None] * u + (radii * np.sin(angles))[:, None] * w
    obj = "usemtl floor\n" + _v(tuple(map(tuple, points))) + "f " + " ".join(map(str, range(1, 11)))
    measured = measure(load_scene(_write(tmp_path, obj + "\n")))
    expected = 10 * 0.5 * outer * inner * np.sin(np.pi / 5)
    assert measured.triangles == 8
    assert measured.area == pytest.approx(expected, rel=1e-12)
    np.testing.assert_allclose(measured.normals @ np.cross(u, w), 1.0)


def test_mcguire_style_file_with_interleaved_relative_quads(tmp_path: Path) -> None:
    # the layout of McGuire's CornellBox-Original.obj: per object a g, usemtl, four
    # tab-separated v lines and f -4 -3 -2 -1; five 1 m squares of a box and a lamp
    walls = {
        "floor": ((0, 0, 0), (0, 0, 1), (1, 0, 1), (1, 0, 0)),
        "ceiling": ((0, 1, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1)),
        "back": ((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)),
        "left": ((0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)),
        "right": ((1, 0, 0), (1, 0, 1), (1, 1, 1), (1, 1, 0)),
    }
    body = "".join(
        f"g {name}\nusemtl floor\n" + _v(quad, sep="\t") + "f -4 -3 -2 -1\n"
        for name, quad in walls.items()
    )
    lamp = tuple((x, 0.99, z) for x, _, z in LAMP)
    body += "g light\nusemtl lamp\n" + _v(lamp, sep="\t") + "f -4 -3 -2 -1\n"
    scene = load_scene(_write(tmp_path, body))
    measured = measure(scene)
    assert measured.triangles == 12
    assert measured.area_of("floor") == pytest.approx(5.0, rel=1e-12)
    assert measured.emitted_power == pytest.approx(0.4, rel=1e-9)
    assert set(scene.object_names) == {*walls, "light"}
    # every wall faces into the box
    centroids = scene.positions[scene.triangles].mean(axis=1)
    assert ((0.5 - centroids) * measured.normals).sum(axis=1).min() > 0


@pytest.mark.parametrize(
    ("faces", "problem"),
    [
        ("f 0 1 2\n", "line 7: face index 0"),
        ("f 1 2 9\n", "line 7: face refers to 'v' 9, but the file has 4"),
        ("f -5 -2 -1\n", "line 7: relative index -5 reaches before the first 'v'"),
        ("f 1 2 x\n", "line 7: bad face corner 'x'"),
        ("f 1/1 2/1 3/1\n", "face refers to 'vt' 1, but the file has 0"),
    ],
)
def test_bad_face_indices_are_refused_by_line(tmp_path: Path, faces: str, problem: str) -> None:
    path = _write(tmp_path, "usemtl floor\n" + _v(FLOOR) + faces)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert "scene.obj" in str(info.value) and problem in str(info.value)


def test_a_vertex_without_three_numbers_is_refused(tmp_path: Path) -> None:
    path = _write(tmp_path, "v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SceneError, match="line 2: a vertex needs 3 numbers"):
        load_scene(path)


def test_mtl_in_latin_1_keeps_every_material(tmp_path: Path) -> None:
    mtl = "# café \xff\xfe\n".encode("latin-1") + FLOOR_AND_LAMP_MTL.encode()
    measured = measure(load_scene(_write(tmp_path, ABSOLUTE, mtl)))
    assert measured.emitted_power == pytest.approx(0.4, rel=1e-9)
    assert set(measured.by_material) == {"floor", "lamp"}


@pytest.mark.parametrize(
    ("bad_line", "line"),
    [("Kd 0.5 0.5", 2), ("Kd 0.5 zero 0.5", 2), ("Kd nan", 2), ("Kd 0.5 0.5 0.5 0.5", 2)],
)
def test_one_bad_mtl_line_is_reported_and_the_rest_kept(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, bad_line: str, line: int
) -> None:
    mtl = FLOOR_AND_LAMP_MTL.replace("Kd 0.5 0.5 0.5", bad_line)
    with caplog.at_level(logging.WARNING):
        scene = load_scene(_write(tmp_path, ABSOLUTE, mtl))
    assert f"scene.mtl line {line}: {bad_line!r}" in caplog.text
    floor = scene.material_names.index("floor")
    np.testing.assert_array_equal(scene.material_reflectance[floor], [0.5] * 3)  # default
    assert measure(scene).emitted_power == pytest.approx(0.4, rel=1e-9)


def test_partial_and_missing_mtl(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        scene = load_scene(_write(tmp_path, ABSOLUTE, "newmtl lamp\nKe 10 10 10\nKd 0 0 0\n"))
    assert measure(scene).emitted_power == pytest.approx(0.4, rel=1e-9)
    assert "faces without an MTL material" in caplog.text
    (tmp_path / "scene.mtl").unlink()
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        scene = load_scene(tmp_path / "scene.obj")
    assert "mtllib 'scene.mtl' not found" in caplog.text
    assert measure(scene).emitted_power == 0.0


def test_several_mtllib_files_and_names_with_spaces(tmp_path: Path) -> None:
    (tmp_path / "a.mtl").write_text("newmtl floor\nKd 0.25 0.25 0.25\n")
    (tmp_path / "b c.mtl").write_text("newmtl lamp\nKe 10 10 10\n")
    path = tmp_path / "scene.obj"
    path.write_text("mtllib a.mtl\nmtllib b c.mtl\n" + ABSOLUTE)
    scene = load_scene(path)
    floor = scene.material_names.index("floor")
    np.testing.assert_array_equal(scene.material_reflectance[floor], [0.25] * 3)
    assert measure(scene).emitted_power == pytest.approx(0.4, rel=1e-9)


def test_mtllib_outside_the_scene_folder_is_refused_by_name(tmp_path: Path) -> None:
    (tmp_path / "secret").mkdir()
    (tmp_path / "secret" / "outside.mtl").write_text(FLOOR_AND_LAMP_MTL)
    (tmp_path / "scene").mkdir()
    path = tmp_path / "scene" / "scene.obj"
    path.write_text("mtllib ../secret/outside.mtl\n" + ABSOLUTE)
    with pytest.raises(SceneError, match="outside the scene folder") as info:
        load_scene(path)
    assert "missing" not in str(info.value) and "not found" not in str(info.value)
    allowed = load_scene(path, allow_outside=True)
    assert measure(allowed).emitted_power == pytest.approx(0.4, rel=1e-9)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
def test_an_mtllib_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "scene.mtl")
    path = tmp_path / "scene.obj"
    path.write_text("mtllib scene.mtl\n" + ABSOLUTE)
    with pytest.raises(SceneError, match=r"'scene\.mtl' is not a regular file"):
        load_scene(path)


def test_parse_mtl_reads_scalar_colours_and_trailing_comments() -> None:
    warnings: list[str] = []
    text = b"Kd 1 1 1\nnewmtl a b # two words\nKd 0.25 # grey\nKE 1 2 3\nnewmtl c\nKd 1 2\n"
    materials = parse_mtl("x.mtl", text, warnings.append)
    assert materials == {"a b": {"kd": (0.25,) * 3, "ke": (1.0, 2.0, 3.0)}, "c": {}}
    assert warnings == [
        "x.mtl line 1: Kd before any newmtl; line ignored",
        "x.mtl line 6: 'Kd 1 2' is not 1 or 3 numbers; line ignored",
    ]
