"""Contact lines imprinted on the refined mesh (raytrad/core/imprint.py).

The truths here are geometric and computed without the module: where a footprint square
lies on a floor, whether a floor triangle has points on both sides of its outline; the
area each scene triangle had; the plane each vertex lay in.
"""

from __future__ import annotations

import numpy as np
import pytest

from raytrad import api
from raytrad.core.hidden import fill_hidden
from raytrad.core.imprint import outline_segments
from raytrad.core.mesh import MeshSettings, RadiosityMesh, build_mesh
from raytrad.core.pipeline import Prepared
from raytrad.core.refine import surface_labels
from raytrad.core.solver import SolveResult
from raytrad.products.probe import hemisphere_gather, radiosity_at
from raytrad.scene import Scene, triangle_areas_normals
from raytrad.scene.builder import SceneBuilder, box_faces, rectangle
from raytrad.settings import RenderSettings


def _block_on_floor(
    lo: tuple[float, float], hi: tuple[float, float], lift: float, two_sided: bool = False
) -> Scene:
    """A 1 m room, an open-bottom block over [lo, hi] in x and z standing ``lift`` above the
    floor (double-sided with ``two_sided``), and a lamp 0.5 mm below the ceiling over
    [0.3, 0.62] in x and z."""
    builder = SceneBuilder()
    builder.material("white", 0.7)
    builder.material("floor", 0.7, double_sided=two_sided)
    builder.material("lamp", 0.0, 5.0)
    builder.room("white", (1.0, 1.0, 1.0), face_material={"y-": "floor"})
    builder.block("white", (lo[0], lift, lo[1]), (hi[0], lift + 0.3, hi[1]))
    builder.quad(rectangle(1, 1.0 - 5e-4, (0.3, 0.3), (0.62, 0.62)), "lamp", (0, -1, 0))
    return builder.build()


def _straddling(
    mesh: RadiosityMesh,
    level: float,
    lo: tuple[float, float],
    hi: tuple[float, float],
    axis: int = 1,
) -> int:
    """Triangles lying in the plane ``axis`` = ``level`` with sample points strictly inside
    and strictly outside the rectangle [lo, hi] in the other two axes (in order)."""
    u_axis, v_axis = [k for k in range(3) if k != axis]
    corners = mesh.positions[mesh.triangles]
    flat = np.abs(corners[:, :, axis] - level).max(axis=1) < 1e-9
    corners = corners[flat]
    u, v = np.meshgrid(np.linspace(0, 1, 21), np.linspace(0, 1, 21))
    u, v = u[u + v <= 1], v[u + v <= 1]
    weights = np.stack([1 - u - v, u, v], axis=1)  # (K, 3) barycentric samples
    points = np.einsum("kc,tcd->tkd", weights, corners)
    x, z = points[..., u_axis], points[..., v_axis]
    margin = 1e-7
    inside = (x > lo[0] + margin) & (x < hi[0] - margin) & (z > lo[1] + margin)
    inside &= z < hi[1] - margin
    outside = (x < lo[0] - margin) | (x > hi[0] + margin) | (z < lo[1] - margin)
    outside |= z > hi[1] + margin
    return int((inside.any(axis=1) & outside.any(axis=1)).sum())


FOOTPRINT = ((0.213, 0.287), (0.471, 0.553))  # off the refinement grid


@pytest.mark.parametrize(
    ("lift", "two_sided"), [(0.0, False), (1e-3, False), (0.0, True)], ids=["on", "1mm", "two"]
)
def test_no_floor_triangle_straddles_a_block_footprint(lift: float, two_sided: bool) -> None:
    # A block on the floor (or 1 mm above it, inside the cover gap; or on a double-sided
    # floor, whose reversed copy shares its vertices): every refined floor triangle lies
    # wholly under the block or wholly beside it, so the floor's hidden and lit parts
    # never share a triangle. Without the imprint, dozens straddle.
    lo, hi = FOOTPRINT
    scene = _block_on_floor(lo, hi, lift, two_sided)
    for receivers in (3000, 12000):
        plain = build_mesh(scene, MeshSettings(receivers=receivers, imprint=False))
        imprinted = build_mesh(scene, MeshSettings(receivers=receivers))
        before = _straddling(plain, 0.0, lo, hi)
        after = _straddling(imprinted, 0.0, lo, hi)
        print(f"{receivers} receivers, lift {lift}: straddling {before} -> {after}")
        assert before > 10
        assert after == 0


def _sides_across(mesh: RadiosityMesh, level: float) -> int:
    """Upright triangles with corners strictly above and strictly below y = ``level``."""
    corners = mesh.positions[mesh.triangles]
    upright = np.abs(mesh.triangle_normal[:, 1]) < 1e-9
    y = corners[upright][:, :, 1]
    return int(((y.max(axis=1) > level + 1e-7) & (y.min(axis=1) < level - 1e-7)).sum())


@pytest.mark.parametrize("two_sided", [False, True], ids=["one", "two"])
def test_a_sunk_block_and_the_floor_are_imprinted_on_each_other(two_sided: bool) -> None:
    # A block sunk 2 cm into the floor (one- or double-sided, whose reversed copy crosses
    # the block too): the line where its sides pass through the floor is no triangle's
    # edge (intersections.py finds it). No floor triangle straddles the footprint and no
    # side triangle the floor's plane; without the imprint dozens do.
    lo, hi = FOOTPRINT
    scene = _block_on_floor(lo, hi, -0.02, two_sided)
    for receivers in (3000, 12000):
        plain = build_mesh(scene, MeshSettings(receivers=receivers, imprint=False))
        mesh = build_mesh(scene, MeshSettings(receivers=receivers))
        floor = (_straddling(plain, 0.0, lo, hi), _straddling(mesh, 0.0, lo, hi))
        sides = (_sides_across(plain, 0.0), _sides_across(mesh, 0.0))
        print(f"{receivers} receivers: floor {floor[0]} -> {floor[1]}, sides {sides} ")
        assert floor[0] > 10 and sides[0] > 10
        assert floor[1] == 0 and sides[1] == 0


def test_the_floor_at_a_sunk_blocks_foot_agrees_with_a_gather() -> None:
    # Floor points 2 and 5 mm from where a sunk block's sides pass through the floor, at
    # about 4000 receivers, against an independent hemisphere gather of the bake's own
    # solution. Without the intersection lines: 1.196 and 1.130 times the gather (floor
    # triangles reaching under the block interpolated toward its filled hidden floor).
    lo, hi = FOOTPRINT
    scene = _block_on_floor(lo, hi, -0.02)
    settings = RenderSettings(mesh=MeshSettings(receivers=4000))
    prepared = api.prepare(scene, settings)
    try:
        result = api.solve(prepared, settings)
        mesh = prepared.mesh
        shown = fill_hidden(mesh, result.radiosity)
        t = np.linspace(0.1, 0.9, 8)[:, None]
        ratios = []
        for gap in (0.002, 0.005):
            points = []
            for a, b, out in (
                ((lo[0], lo[1]), (hi[0], lo[1]), (0, 0, -1)),
                ((lo[0], hi[1]), (hi[0], hi[1]), (0, 0, 1)),
                ((lo[0], lo[1]), (lo[0], hi[1]), (-1, 0, 0)),
                ((hi[0], lo[1]), (hi[0], hi[1]), (1, 0, 0)),
            ):
                start, end = np.array([a[0], 1e-6, a[1]]), np.array([b[0], 1e-6, b[1]])
                points.append(start + t * (end - start) + gap * np.array(out))
            points = np.concatenate(points)
            up = np.tile([0.0, 1.0, 0.0], (len(points), 1))
            baked = radiosity_at(mesh, shown, points, up)
            irradiance, _ = hemisphere_gather(mesh, shown, points, up, rays=4096, seed=2)
            ratios.append(baked[:, 1].mean() / (0.7 * irradiance[:, 1]).mean())
    finally:
        prepared.close()
    print("floor 2 and 5 mm from the sunk block, bake / gather:", np.round(ratios, 3))
    np.testing.assert_allclose(ratios, 1.0, atol=0.04)


def test_a_parallel_cover_is_not_imprinted() -> None:
    # The lamp 0.5 mm below the ceiling covers the ceiling behind it (visibility.COVER_GAP);
    # a ceiling receiver on its outline would be half covered, darker than anything a
    # millimetre away, so its outline is left off the ceiling: the same triangles straddle.
    scene = _block_on_floor(*FOOTPRINT, 0.0)
    plain = build_mesh(scene, MeshSettings(receivers=8000, imprint=False))
    imprinted = build_mesh(scene, MeshSettings(receivers=8000))
    square = ((0.3, 0.3), (0.62, 0.62))
    assert _straddling(plain, 1.0, *square) > 4
    assert _straddling(imprinted, 1.0, *square) == _straddling(plain, 1.0, *square)


def test_a_shelf_is_imprinted_on_the_wall_it_stands_against() -> None:
    # a 2 cm thick shelf (open at the back) against the x = 0 wall: its top, bottom and
    # ends meet the wall at right angles, so its outline there is imprinted
    builder = SceneBuilder()
    builder.material("white", 0.7)
    builder.material("lamp", 0.0, 5.0)
    builder.room("white", (1.0, 1.0, 1.0))
    builder.quad(rectangle(1, 1.0 - 5e-4, (0.3, 0.3), (0.62, 0.62)), "lamp", (0, -1, 0))
    for name, corners, outward in box_faces((0.0, 0.413, 0.237), (0.25, 0.433, 0.771)):
        if name != "x-":
            builder.quad(corners, "white", outward)
    scene = builder.build()
    for imprint, expected in ((False, None), (True, 0)):
        mesh = build_mesh(scene, MeshSettings(receivers=8000, imprint=imprint))
        # on the wall x = 0 the shelf's outline is [0.413, 0.433] x [0.237, 0.771] in (y, z)
        count = _straddling(mesh, 0.0, (0.413, 0.237), (0.433, 0.771), axis=0)
        print(f"imprint {imprint}: wall triangles straddling the shelf's outline: {count}")
        if expected is None:
            assert count > 4
        else:
            assert count == expected


def test_imprinting_keeps_areas_planes_and_orientation() -> None:
    lo, hi = FOOTPRINT
    scene = _block_on_floor(lo, hi, 0.0)
    plain = build_mesh(scene, MeshSettings(receivers=6000, imprint=False))
    mesh = build_mesh(scene, MeshSettings(receivers=6000))
    # vertices on the footprint's outline: the plain mesh has those of the scene's own
    # triangles (none), the imprinted one a row along each side
    for m, least, most in ((plain, 0, 0), (mesh, 4 * 5, 4 * 40)):
        x, z = m.positions[:, 0], m.positions[:, 2]
        on_x = np.isclose(x, lo[0], atol=1e-12) | np.isclose(x, hi[0], atol=1e-12)
        on_z = np.isclose(z, lo[1], atol=1e-12) | np.isclose(z, hi[1], atol=1e-12)
        within = (x >= lo[0] - 1e-12) & (x <= hi[0] + 1e-12) & (z >= lo[1] - 1e-12)
        within &= z <= hi[1] + 1e-12
        floor = np.zeros(len(x), dtype=bool)
        _, up = triangle_areas_normals(m.positions[m.triangles])
        floor[m.triangles[(up[:, 1] > 0.99) & (m.positions[m.triangles][:, 0, 1] == 0.0)]] = True
        outline = (on_x | on_z) & within & floor
        print("floor vertices on the footprint outline:", int(outline.sum()))
        assert least <= int(outline.sum()) <= most
    # each scene triangle's area covered exactly once
    scene_area, scene_normal = triangle_areas_normals(scene.triangle_vertices())
    area, normal = triangle_areas_normals(mesh.positions[mesh.triangles])
    total = np.bincount(mesh.triangle_source, weights=area, minlength=scene.triangle_count)
    np.testing.assert_allclose(total, scene_area, rtol=1e-12)
    # no triangle turned over or a sliver, every vertex in its scene triangle's plane
    np.testing.assert_allclose(normal, scene_normal[mesh.triangle_source], atol=1e-9)
    smallest = triangle_areas_normals(plain.positions[plain.triangles])[0].min()
    assert area.min() > 0.01 * smallest
    offset = np.einsum(
        "tcd,td->tc",
        mesh.positions[mesh.triangles] - scene.triangle_vertices()[mesh.triangle_source][:, :1],
        scene_normal[mesh.triangle_source],
    )
    assert np.abs(offset).max() < 1e-12


def test_outline_segments_are_surface_boundaries() -> None:
    # a room (6 faces, 2 triangles each): 4 outline edges per face, the diagonals inside
    builder = SceneBuilder()
    builder.material("white", 0.5)
    builder.room("white", (1.0, 2.0, 3.0))
    scene = builder.build()
    surface = surface_labels(scene.positions, scene.triangles, scene.material_index, 30.0)
    outlines = outline_segments(scene.positions, scene.triangles, surface)
    segments, owner = outlines.points, outlines.surface
    assert len(segments) == 24
    np.testing.assert_array_equal(np.bincount(owner), [4] * 6)
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    np.testing.assert_allclose(np.sort(length), np.repeat([1.0, 2.0, 3.0], 8))


def test_the_floor_at_the_cornell_blocks_feet_agrees_with_a_gather(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    # Floor points 2 and 5 mm in front of each block side, at about 4000 receivers: the
    # bake must agree with an independent hemisphere gather of its own solution. Without
    # the imprint, floor triangles reaching under the blocks interpolated toward the
    # (filled) hidden corners there: 1.087 and 1.055 times the gather.
    prepared, result = cornell_fine
    scene, mesh = prepared.scene, prepared.mesh
    corners = scene.triangle_vertices()[0::2]
    _, normals = triangle_areas_normals(corners)
    # the blocks' sides: vertical quads standing on the floor, lower than the room's walls
    upright = (np.abs(normals[:, 1]) < 0.5) & (corners[:, :, 1].min(axis=1) < 1e-6)
    sides = np.nonzero(upright & (corners[:, :, 1].max(axis=1) < 0.4))[0]
    assert len(sides) == 8
    shown = fill_hidden(mesh, result.radiosity)
    ratios = []
    for gap in (0.002, 0.005):
        points = []
        for q in sides:
            quad = np.concatenate([corners[q], scene.triangle_vertices()[2 * q + 1]])
            foot = quad[quad[:, 1] < 1e-6]
            a, b = foot[0], foot[np.argmax(np.linalg.norm(foot - foot[0], axis=1))]
            t = np.linspace(0.1, 0.9, 8)[:, None]
            points.append(a + t * (b - a) + gap * normals[q])
        points = np.concatenate(points) + np.array([0.0, 1e-6, 0.0])
        up = np.tile([0.0, 1.0, 0.0], (len(points), 1))
        baked = radiosity_at(mesh, shown, points, up)
        irradiance, _ = hemisphere_gather(mesh, shown, points, up, rays=4096, seed=2)
        gathered = scene.material_reflectance[0] * irradiance  # the floor's white
        ratios.append(baked[:, 1].mean() / gathered[:, 1].mean())
    print("floor 2 and 5 mm from the blocks' feet, bake / gather:", np.round(ratios, 3))
    np.testing.assert_allclose(ratios, 1.0, atol=0.04)


def test_an_edge_shorter_than_the_gap_is_snapped_to_an_outline_above_it() -> None:
    """An outline segment may lie up to ``gap`` off a surface and still be imprinted on
    it, so the edges it crosses are searched within half their length and the gap of it.
    A 4 mm edge under a segment 9 mm up (gap 10 mm) was missed while the search reached
    only an edge's length (its midpoint is 9 mm from the segment)."""
    from raytrad.core.imprint import Outlines, _crossing_snaps

    edge = 0.004
    positions = np.array([[0.0, 0.0, 0.0], [edge, 0.0, 0.0], [0.0, edge, 0.0]])
    triangles = np.array([[0, 1, 2]])
    height = 0.009
    outline = Outlines(
        points=np.array([[[0.5 * edge, -0.5, height], [0.5 * edge, 0.5, height]]]),
        surface=np.array([1]),
        normal=np.array([[1.0, 0.0, 0.0]]),
    )
    vertex, target = _crossing_snaps(positions, triangles, np.array([0]), outline, 0.01)
    crosses = [sorted(row[:2]) for row in vertex.tolist()]
    assert [0, 1] in crosses  # the edge along x, which the segment crosses at its middle
    row = crosses.index([0, 1])
    np.testing.assert_allclose(target[row, 2], [0.5 * edge, 0.0, 0.0], atol=1e-12)
