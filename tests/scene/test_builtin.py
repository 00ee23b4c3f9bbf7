"""Built-in scenes against hand-computed geometry."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest

from raytrad.errors import SceneError, SettingsError
from raytrad.scene import Scene, triangle_areas_normals
from raytrad.scene.builtin import BUILTIN_SCENES, cornell_box, furnace_box, shadow_scene
from tests.conftest import areas_by_material

# REFERENCE.md section 4, retyped here in millimetres so the test does not share the table.
FLOOR = [(552.8, 0, 0), (0, 0, 0), (0, 0, 559.2), (549.6, 0, 559.2)]
CEILING = [(556, 548.8, 0), (556, 548.8, 559.2), (0, 548.8, 559.2), (0, 548.8, 0)]
BACK = [(549.6, 0, 559.2), (0, 0, 559.2), (0, 548.8, 559.2), (556, 548.8, 559.2)]
RIGHT_GREEN = [(0, 0, 559.2), (0, 0, 0), (0, 548.8, 0), (0, 548.8, 559.2)]
LEFT_RED = [(552.8, 0, 0), (549.6, 0, 559.2), (556, 548.8, 559.2), (556, 548.8, 0)]
LIGHT_XZ = [(343, 227), (343, 332), (213, 332), (213, 227)]
SHORT_XZ, SHORT_H = [(130, 65), (82, 225), (240, 272), (290, 114)], 165.0
TALL_XZ, TALL_H = [(423, 247), (265, 296), (314, 456), (472, 406)], 330.0
MM2 = 1e-6  # square metres per square millimetre


def _shoelace(points: Sequence[tuple[float, float]]) -> float:
    """Area of a simple planar polygon from 2-D coordinates in its plane."""
    total = 0.0
    corners = list(points)
    for (x0, y0), (x1, y1) in zip(corners, corners[1:] + corners[:1], strict=True):
        total += x0 * y1 - x1 * y0
    return abs(total) / 2


def _heron(a: tuple[float, ...], b: tuple[float, ...], c: tuple[float, ...]) -> float:
    """Triangle area from its side lengths."""
    la, lb, lc = math.dist(b, c), math.dist(a, c), math.dist(a, b)
    s = (la + lb + lc) / 2
    return math.sqrt(s * (s - la) * (s - lb) * (s - lc))


def _block_area(top_xz: Sequence[tuple[float, float]], height: float) -> float:
    corners = list(top_xz)
    perimeter = sum(
        math.dist(p, q) for p, q in zip(corners, corners[1:] + corners[:1], strict=True)
    )
    return _shoelace(top_xz) + perimeter * height


# --------------------------------------------------------------------------- Cornell box


def test_cornell_box_areas_per_material_match_the_reference_table() -> None:
    expected = {
        "white": (
            _shoelace([(x, z) for x, _, z in FLOOR])
            + _shoelace([(x, z) for x, _, z in CEILING])
            + _shoelace([(x, y) for x, y, _ in BACK])
            + _block_area(SHORT_XZ, SHORT_H)
            + _block_area(TALL_XZ, TALL_H)
        ),
        # The left wall is not planar: its area depends on the split, here along 0-2.
        "red": _heron(LEFT_RED[0], LEFT_RED[1], LEFT_RED[2])
        + _heron(LEFT_RED[0], LEFT_RED[2], LEFT_RED[3]),
        "green": 559.2 * 548.8,
        "light": 130.0 * 105.0,
    }
    got = areas_by_material(cornell_box())
    assert set(got) == set(expected)
    for name, area_mm2 in expected.items():
        assert got[name] == pytest.approx(area_mm2 * MM2, rel=1e-9), name


def test_cornell_box_materials() -> None:
    scene = cornell_box()
    values = {
        name: (scene.material_reflectance[i].tolist(), scene.material_emitted_exitance[i])
        for i, name in enumerate(scene.material_names)
    }
    assert values["white"][0] == [0.725, 0.71, 0.68]
    assert values["red"][0] == [0.63, 0.065, 0.05]
    assert values["green"][0] == [0.14, 0.45, 0.091]
    assert values["light"][0] == [0.78, 0.78, 0.78]
    np.testing.assert_allclose(
        values["light"][1], [17 * math.pi, 12 * math.pi, 4 * math.pi], rtol=1e-15
    )
    for name in ("white", "red", "green"):
        assert values[name][1].tolist() == [0.0, 0.0, 0.0]
    assert not scene.material_double_sided.any()
    assert scene.triangle_count == 2 * (6 + 5 + 5)


def _expected_normal(corners: np.ndarray, material: str) -> np.ndarray | None:
    """The direction a Cornell-box triangle must face, from where it is (None: a block side)."""
    y, z = corners[:, 1], corners[:, 2]
    if material == "light":
        return np.array([0.0, -1.0, 0.0])
    if material == "green":
        return np.array([1.0, 0.0, 0.0])
    if np.all(y == 0.0) or np.all(y == SHORT_H / 1000) or np.all(y == TALL_H / 1000):
        return np.array([0.0, 1.0, 0.0])  # floor and block tops
    if np.all(y == 0.5488):
        return np.array([0.0, -1.0, 0.0])
    if np.all(z == 0.5592):
        return np.array([0.0, 0.0, -1.0])
    return None


def test_cornell_box_normals_face_the_lit_side() -> None:
    scene = cornell_box()
    corners = scene.triangle_vertices()
    _, normals = triangle_areas_normals(corners)
    centroids = corners.mean(axis=1)
    names = [scene.material_names[i] for i in scene.material_index]
    sides = 0
    for k, material in enumerate(names):
        if material == "red":  # left wall, x = 0.55, slightly non-planar
            assert normals[k] @ [-1.0, 0.0, 0.0] > 0.999
            continue
        expected = _expected_normal(corners[k], material)
        if expected is not None:
            np.testing.assert_allclose(normals[k], expected, atol=1e-12, err_msg=str(k))
            continue
        # A block side: vertical, facing away from its block's centre.
        sides += 1
        tall = corners[k, :, 1].max() == TALL_H / 1000
        centre_xz = np.mean(TALL_XZ if tall else SHORT_XZ, axis=0) / 1000
        outward = centroids[k, [0, 2]] - centre_xz
        assert abs(normals[k, 1]) < 1e-12
        assert normals[k, [0, 2]] @ outward / np.linalg.norm(outward) > 0.5
    assert sides == 16


def test_cornell_box_room_normals_point_inside_the_room() -> None:
    scene = cornell_box()
    corners = scene.triangle_vertices()
    _, normals = triangle_areas_normals(corners)
    probe = corners.mean(axis=1) + 0.01 * normals
    inside = (probe > [0.0, 0.0, 0.0]).all(axis=1) & (probe < [0.556, 0.5488, 0.5592]).all(axis=1)
    assert inside.all()


def test_cornell_light_is_half_a_millimetre_below_the_ceiling() -> None:
    scene = cornell_box()
    light = scene.material_names.index("light")
    corners = scene.triangle_vertices()[scene.material_index == light]
    np.testing.assert_allclose(corners[:, :, 1], 0.5483, rtol=1e-15)
    np.testing.assert_allclose(corners[:, :, [0, 2]].min(axis=(0, 1)), [0.213, 0.227])
    np.testing.assert_allclose(corners[:, :, [0, 2]].max(axis=(0, 1)), [0.343, 0.332])


# --------------------------------------------------------------------------- furnace


def _directed_edges(scene: Scene) -> list[tuple[tuple[float, ...], tuple[float, ...]]]:
    corners = scene.triangle_vertices()
    return [(tuple(t[i]), tuple(t[(i + 1) % 3])) for t in corners.tolist() for i in range(3)]


def test_furnace_box_is_closed_consistently_wound_and_faces_inward() -> None:
    scene = furnace_box()
    edges = _directed_edges(scene)
    # Closed and consistently oriented: every directed edge appears once, and its reverse too.
    assert len(set(edges)) == len(edges) == 36
    assert all((b, a) in set(edges) for a, b in edges)
    corners = scene.triangle_vertices()
    areas, normals = triangle_areas_normals(corners)
    assert areas.sum() == pytest.approx(6.0, rel=1e-15)
    to_centre = 0.5 - corners.mean(axis=1)
    assert (np.einsum("ti,ti->t", normals, to_centre) > 0).all()
    # Each of the six inward axis directions covers one unit square.
    for direction in np.vstack([np.eye(3), -np.eye(3)]):
        facing = np.isclose(normals @ direction, 1.0)
        assert areas[facing].sum() == pytest.approx(1.0)


def test_furnace_box_default_and_rgb_materials() -> None:
    scene = furnace_box()
    assert scene.material_reflectance.tolist() == [[0.5, 0.5, 0.5]]
    assert scene.material_emitted_exitance.tolist() == [[1.0, 1.0, 1.0]]
    coloured = furnace_box(reflectance=(0.1, 0.2, 0.3), emitted_exitance=(1.0, 2.0, 3.0), size=2.0)
    assert coloured.material_reflectance.tolist() == [[0.1, 0.2, 0.3]]
    assert coloured.material_emitted_exitance.tolist() == [[1.0, 2.0, 3.0]]
    assert sum(areas_by_material(coloured).values()) == pytest.approx(24.0, rel=1e-15)


def test_furnace_box_rejects_bad_arguments() -> None:
    for size in (0.0, -1.0, math.nan):
        with pytest.raises(SettingsError, match="size"):
            furnace_box(size=size)
    with pytest.raises(SceneError, match="outside"):
        furnace_box(reflectance=1.5)
    with pytest.raises(SceneError, match=">= 0"):
        furnace_box(emitted_exitance=(-1.0, 0.0, 0.0))


# --------------------------------------------------------------------------- shadow scene


def test_shadow_scene_geometry_and_materials() -> None:
    scene = shadow_scene()
    assert areas_by_material(scene) == pytest.approx(
        {"floor": 4.0, "light": 0.25, "occluder": 0.36}, rel=1e-15
    )
    corners = scene.triangle_vertices()
    _, normals = triangle_areas_normals(corners)
    expected = {  # name: (height [m], normal, reflectance, exitance, double-sided)
        "floor": (0.0, [0, 1, 0], 0.6, 0.0, False),
        "light": (1.5, [0, -1, 0], 0.0, 10.0, False),
        "occluder": (0.75, [0, 1, 0], 0.5, 0.0, True),
    }
    for i, name in enumerate(scene.material_names):
        height, normal, rho, emitted, double = expected[name]
        mine = scene.material_index == i
        assert (corners[mine][:, :, 1] == height).all(), name
        np.testing.assert_array_equal(normals[mine], [normal] * int(mine.sum()))
        assert scene.material_reflectance[i].tolist() == [rho] * 3
        assert scene.material_emitted_exitance[i].tolist() == [emitted] * 3
        assert bool(scene.material_double_sided[i]) is double
    # The occluder is centred under the light and wider than it: the floor centre is umbra.
    occluder = corners[scene.material_index == scene.material_names.index("occluder")]
    assert occluder[:, :, [0, 2]].min() == -0.3 and occluder[:, :, [0, 2]].max() == 0.3


def test_builtin_scene_registry() -> None:
    assert set(BUILTIN_SCENES) == {"cornell-box", "furnace", "shadow", "blocks-room", "ball-box"}
    for name, build in BUILTIN_SCENES.items():
        scene = build()
        assert isinstance(scene, Scene) and scene.triangle_count > 0, name


def test_ball_box_is_the_cornell_box_and_a_ball_clear_of_everything() -> None:
    """The Cornell box's 32 triangles as they are, and 1 280 more on a sphere of 80 mm
    about (450, 80.1, 120) mm, wound outward, with the area of its inscribed icosphere
    (just under the sphere's 4 pi r^2), clear of the floor, the blocks and the walls."""
    from raytrad.scene.builtin import ball_box

    scene, box = ball_box(), cornell_box()
    assert scene.triangle_count == 32 + 1280
    corners = scene.positions[scene.triangles]
    np.testing.assert_array_equal(corners[:32], box.positions[box.triangles])
    ball = scene.object_index == scene.object_names.index("ball")
    assert np.flatnonzero(ball).tolist() == list(range(32, 1312))
    centre, radius = np.array([0.45, 0.0801, 0.12]), 0.08
    points = corners[ball].reshape(-1, 3)
    np.testing.assert_allclose(np.linalg.norm(points - centre, axis=1), radius, rtol=1e-12)
    area, normal = triangle_areas_normals(corners[ball])
    outward = corners[ball].mean(axis=1) - centre
    assert (np.einsum("tj,tj->t", normal, outward) > 0).all()
    assert 0.99 * 4 * np.pi * radius**2 < area.sum() < 4 * np.pi * radius**2
    assert points[:, 1].min() > 0.0  # above the floor
    assert points[:, 0].max() < box.positions[:, 0].max() - 0.01  # off the red wall
    for block in ("short-block", "tall-block"):  # off each block's box, in x or z
        mine = box.positions[box.triangles[box.object_index == box.object_names.index(block)]]
        lo, hi = mine.reshape(-1, 3).min(axis=0), mine.reshape(-1, 3).max(axis=0)
        apart = (points[:, [0, 2]].min(axis=0) > hi[[0, 2]]) | (
            points[:, [0, 2]].max(axis=0) < lo[[0, 2]]
        )
        assert apart.any(), block


def test_blocks_room_counts_bounds_power_and_footprints() -> None:
    """36 blocks of five quads in a closed 4 x 3 x 4 m room, each standing on the floor
    inside its own cell of the floor's 6 x 6 grid (so no two touch); the light is 1 m2
    of 10 W m-2."""
    from raytrad.scene.builtin import blocks_room

    scene = blocks_room()
    assert scene.triangle_count == 2 * (7 + 5 * 36)
    np.testing.assert_array_equal(scene.positions.min(axis=0), [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(scene.positions.max(axis=0), [4.0, 3.0, 4.0])
    corners = scene.positions[scene.triangles]
    area, _ = triangle_areas_normals(corners)
    light = scene.material_index == scene.material_names.index("light")
    emitted = area[light] @ scene.material_emitted_exitance[scene.material_index[light]]
    np.testing.assert_allclose(emitted, [10.0, 10.0, 10.0], rtol=1e-12)
    names = [n for n in scene.object_names if n.startswith("block-")]
    assert len(names) == 36
    for name in names:
        i, j = (int(k) for k in name.split("-")[1:])
        mine = corners[scene.object_index == scene.object_names.index(name)].reshape(-1, 3)
        assert len(mine) == 30  # 10 triangles
        assert mine[:, 1].min() == 0.0 and 0.2 <= mine[:, 1].max() <= 1.0
        cell = np.array([4.0, 4.0]) / 6
        lo, hi = mine[:, [0, 2]].min(axis=0), mine[:, [0, 2]].max(axis=0)
        assert (lo > np.array([i, j]) * cell).all() and (hi < np.array([i + 1, j + 1]) * cell).all()
    same, other = blocks_room(seed=1), blocks_room(seed=2)
    np.testing.assert_array_equal(same.positions, scene.positions)
    assert not np.array_equal(other.positions, scene.positions)
    with pytest.raises(SettingsError):
        blocks_room(0)
