"""Conforming refinement: exact geometric invariants (areas, containment, conformity,
winding) on the closed box and the Cornell box."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core.refine import refine
from raytrad.scene import triangle_areas_normals
from tests.core.conftest import directed_edges


@pytest.mark.parametrize("max_edge", [0.3, 0.1, 0.07])
def test_refine_bounds_every_edge(closed_box: tuple, max_edge: float) -> None:
    positions, triangles, _ = refine(*closed_box, max_edge)
    edges = directed_edges(triangles)
    length = np.linalg.norm(positions[edges[:, 1]] - positions[edges[:, 0]], axis=1)
    assert length.max() <= max_edge
    # and it does not over-refine: midpoint splits halve edges, so some edge is > max_edge / 2
    assert length.max() > max_edge / 2


def test_refine_preserves_each_parents_area(cornell_mesh: tuple) -> None:
    scene, _ = cornell_mesh
    corners = scene.triangle_vertices()
    parent_area, _ = triangle_areas_normals(corners)
    positions, triangles, parent = refine(scene.positions, scene.triangles, 0.05)
    area, _ = triangle_areas_normals(positions[triangles])
    assert len(triangles) > 20 * len(parent_area)
    np.testing.assert_allclose(
        np.bincount(parent, weights=area, minlength=len(parent_area)), parent_area, rtol=1e-12
    )
    assert area.sum() == pytest.approx(parent_area.sum(), rel=1e-12)


def test_refine_keeps_each_triangle_inside_its_parent(cornell_mesh: tuple) -> None:
    scene, _ = cornell_mesh
    positions, triangles, parent = refine(scene.positions, scene.triangles, 0.05)
    corners = scene.triangle_vertices()[parent]  # (T', 3, 3)
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    total = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    for k in range(3):
        p = positions[triangles[:, k]]
        # barycentric areas of p in its parent sum to the parent's area iff p is inside
        parts = (
            np.linalg.norm(np.cross(b - p, c - p), axis=1)
            + np.linalg.norm(np.cross(c - p, a - p), axis=1)
            + np.linalg.norm(np.cross(a - p, b - p), axis=1)
        )
        np.testing.assert_allclose(parts, total, rtol=1e-9)


@pytest.mark.parametrize("max_edge", [0.3, 0.07])
def test_refined_closed_box_is_conforming(closed_box: tuple, max_edge: float) -> None:
    positions, triangles, _ = refine(*closed_box, max_edge)
    directed = directed_edges(triangles)
    _, undirected_count = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    # closed and conforming: every edge has exactly two triangles (a T-junction leaves an
    # edge with one), and consistent winding: each directed edge occurs once
    assert (undirected_count == 2).all()
    _, directed_count = np.unique(directed, axis=0, return_counts=True)
    assert (directed_count == 1).all()
    # no duplicate vertices: shared edges were split once
    assert len(np.unique(positions, axis=0)) == len(positions)
    # Euler characteristic of a sphere
    v, e, f = len(np.unique(triangles)), len(undirected_count), len(triangles)
    assert v - e + f == 2


def test_refine_preserves_winding(closed_box: tuple) -> None:
    positions, triangles = closed_box
    _, parent_normal = triangle_areas_normals(positions[triangles])
    fine_positions, fine, parent = refine(positions, triangles, 0.1)
    _, normal = triangle_areas_normals(fine_positions[fine])
    np.testing.assert_allclose(
        np.einsum("ij,ij->i", normal, parent_normal[parent]), 1.0, atol=1e-12
    )
