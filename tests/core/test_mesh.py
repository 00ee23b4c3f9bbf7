"""Refinement and the radiosity mesh: exact geometric invariants, creases, patches, seeds."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from raytrad.core.mesh import MeshSettings, build_mesh
from raytrad.core.refine import surface_labels
from raytrad.scene import triangle_areas_normals
from raytrad.scene.builtin import cornell_box, furnace_box, shadow_scene
from tests.conftest import FURNACE_MESH

# --------------------------------------------------------------------------------------
# Surfaces and receivers
# --------------------------------------------------------------------------------------


def test_box_faces_are_separate_surfaces(closed_box: tuple) -> None:
    positions, triangles = closed_box
    labels = surface_labels(positions, triangles, np.zeros(12, dtype=np.int64), 30.0)
    assert len(np.unique(labels)) == 6
    _, normals = triangle_areas_normals(positions[triangles])
    for label in np.unique(labels):  # each surface is one face: two triangles, one normal
        mine = labels == label
        assert mine.sum() == 2
        np.testing.assert_allclose(normals[mine][0], normals[mine][1], atol=1e-15)


def test_box_corners_have_one_receiver_per_face() -> None:
    mesh = build_mesh(furnace_box(), FURNACE_MESH)
    for corner in itertools.product([0.0, 1.0], repeat=3):
        at = np.nonzero((mesh.receiver_position == corner).all(axis=1))[0]
        assert len(at) == 3
        # the three inward face normals: +e_k on the face x_k = 0, -e_k on x_k = 1
        expected = np.diag([1.0 if c == 0.0 else -1.0 for c in corner])
        got = mesh.receiver_normal[at]
        np.testing.assert_array_equal(got[np.argsort(np.abs(got).argmax(axis=1))], expected)
    # edge points have 2 receivers, face interiors 1
    _, count = np.unique(mesh.receiver_position, axis=0, return_counts=True)
    assert set(count.tolist()) == {1, 2, 3}
    assert (count == 3).sum() == 8


def test_double_sided_surfaces_get_receivers_on_both_sides() -> None:
    scene = shadow_scene()
    mesh = build_mesh(scene, MeshSettings(receivers=600, patches=30))
    at_occluder = np.isclose(mesh.receiver_position[:, 1], 0.75)
    up = at_occluder & np.isclose(mesh.receiver_normal[:, 1], 1.0)
    down = at_occluder & np.isclose(mesh.receiver_normal[:, 1], -1.0)
    assert up.sum() > 0 and up.sum() == down.sum() == at_occluder.sum() // 2
    np.testing.assert_array_equal(
        np.unique(mesh.receiver_position[up], axis=0),
        np.unique(mesh.receiver_position[down], axis=0),
    )
    # the occluder's area is counted once per side
    np.testing.assert_allclose(mesh.receiver_area[up].sum(), 0.36, rtol=1e-12)
    np.testing.assert_allclose(mesh.receiver_area[down].sum(), 0.36, rtol=1e-12)


@pytest.mark.parametrize(
    ("build", "area"),
    [(furnace_box, 6.0), (cornell_box, None)],
    ids=["furnace", "cornell"],
)
def test_areas_add_up(build, area: float | None) -> None:
    scene = build()
    total = area or float(triangle_areas_normals(scene.triangle_vertices())[0].sum())
    mesh = build_mesh(scene, MeshSettings(receivers=1500, patches=100))
    assert mesh.receiver_area.sum() == pytest.approx(total, rel=1e-12)
    assert mesh.patch_area.sum() == pytest.approx(total, rel=1e-12)
    assert mesh.subarea_area.sum() == pytest.approx(total, rel=1e-12)
    assert mesh.triangle_area.sum() == pytest.approx(total, rel=1e-12)
    # each receiver's area is a third of its triangles' areas
    expected = np.bincount(
        mesh.triangle_receivers.reshape(-1),
        weights=np.repeat(mesh.triangle_area / 3.0, 3),
        minlength=mesh.receiver_count,
    )
    np.testing.assert_allclose(mesh.receiver_area, expected, rtol=1e-12)


def test_patches_are_one_material_and_one_surface(cornell_mesh: tuple) -> None:
    scene, mesh = cornell_mesh
    material = scene.material_index[mesh.triangle_source]
    for patch in range(mesh.patch_count):
        mine = mesh.triangle_patch == patch
        assert len(np.unique(material[mine])) == 1
        # every triangle of a patch faces within the crease angle of the patch normal
        assert (mesh.triangle_normal[mine] @ mesh.patch_normal[patch]).min() > np.cos(
            np.radians(30.0)
        )
    np.testing.assert_array_equal(
        mesh.patch_reflectance,
        scene.material_reflectance[
            [material[mesh.triangle_patch == p][0] for p in range(mesh.patch_count)]
        ],
    )


def test_patch_extent_respects_patch_size() -> None:
    mesh = build_mesh(furnace_box(), MeshSettings(max_edge=0.05, patch_size=0.25))
    corners = mesh.positions[mesh.triangles]
    for patch in range(mesh.patch_count):
        centroids = corners[mesh.triangle_patch == patch].mean(axis=1)
        assert np.ptp(centroids, axis=0).max() <= 0.25
    # 6 faces of 1 m split into pieces no wider than 0.25 m: at least 16 per face
    assert mesh.patch_count >= 6 * 16


def test_sample_points_lie_on_their_subarea(cornell_mesh: tuple) -> None:
    _, mesh = cornell_mesh
    corners = mesh.positions[mesh.triangles]
    for s in range(mesh.subarea_count):
        mine = corners[mesh.triangle_subarea == s]
        p = mesh.subarea_point[s]
        a, b, c = mine[:, 0], mine[:, 1], mine[:, 2]
        total = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        parts = (
            np.linalg.norm(np.cross(b - p, c - p), axis=1)
            + np.linalg.norm(np.cross(c - p, a - p), axis=1)
            + np.linalg.norm(np.cross(a - p, b - p), axis=1)
        )
        assert np.isclose(parts, total, rtol=1e-9).any()
    assert (np.diff(mesh.subarea_patch) >= 0).all()


def test_same_seed_same_samples_other_seed_other_samples() -> None:
    scene = cornell_box()
    first = build_mesh(scene, MeshSettings(receivers=1000, patches=50, seed=3))
    again = build_mesh(scene, MeshSettings(receivers=1000, patches=50, seed=3))
    other = build_mesh(scene, MeshSettings(receivers=1000, patches=50, seed=4))
    np.testing.assert_array_equal(first.subarea_point, again.subarea_point)
    assert first.subarea_point.shape == other.subarea_point.shape
    # the seed moves the sample points only, and moves all of them
    np.testing.assert_array_equal(first.triangle_subarea, other.triangle_subarea)
    assert (np.linalg.norm(first.subarea_point - other.subarea_point, axis=1) > 0).all()
