"""Fixtures of the core tests: small meshes shared by several modules."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core.mesh import RadiosityMesh, build_mesh
from raytrad.core.refine import merge_vertices
from raytrad.scene import Scene
from raytrad.scene.builtin import cornell_box, furnace_box
from tests.conftest import CORNELL_MESH


def directed_edges(triangles: np.ndarray) -> np.ndarray:
    """(3T, 2) directed edges (v_k, v_k+1) of every triangle."""
    return np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=2).reshape(-1, 2)


@pytest.fixture(scope="module")
def closed_box() -> tuple[np.ndarray, np.ndarray]:
    """The unit furnace cube with shared corner vertices: 8 vertices, 12 triangles."""
    scene = furnace_box()
    positions, triangles = merge_vertices(scene.positions, scene.triangles, 1e-9)
    assert positions.shape == (8, 3) and triangles.shape == (12, 3)
    return positions, triangles


@pytest.fixture(scope="module")
def cornell_mesh() -> tuple[Scene, RadiosityMesh]:
    scene = cornell_box()
    return scene, build_mesh(scene, CORNELL_MESH)
