"""The radiosity solution against an independent Monte Carlo path tracer.

The path tracer (:func:`raytrad.core.pathtrace.path_traced_radiosity`) shares nothing with the
solver but the scene and Embree: no form factors, no patches, no receivers. It is itself
checked on the white furnace, where the answer is known in closed form.
"""

from __future__ import annotations

import numpy as np
import pytest

from raytrad import api
from raytrad.core.mesh import MeshSettings
from raytrad.core.pathtrace import path_traced_radiosity
from raytrad.core.solver import SolveSettings
from raytrad.scene.builtin import cornell_box, furnace_box
from raytrad.settings import RenderSettings

#: Cornell box points away from shadow edges: (position [m], surface).
SMOOTH_POINTS = np.array(
    [
        [0.28, 0.27, 0.5592],  # back wall
        [0.555, 0.27, 0.28],  # red wall
        [0.0, 0.27, 0.28],  # green wall
        [0.05, 0.0, 0.5],  # floor, back right
        [0.45, 0.0, 0.1],  # floor, front left
        [0.2, 0.165, 0.17],  # short block top
        [0.37, 0.33, 0.35],  # tall block top
        [0.1, 0.5488, 0.45],  # ceiling
    ]
)


def _compare(receivers: int, patches: int, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Relative differences radiosity / path traced - 1 and the tracer's relative errors."""
    scene = cornell_box()
    settings = RenderSettings(
        mesh=MeshSettings(receivers=receivers, patches=patches),
        solve=SolveSettings(tolerance=1e-5),
    )
    prepared, result = api.solve_scene(scene, settings)
    mesh = prepared.mesh
    nearest = np.array(
        [int(np.argmin(np.linalg.norm(mesh.receiver_position - p, axis=1))) for p in points]
    )
    irradiance, error = path_traced_radiosity(
        scene, mesh.receiver_position[nearest], mesh.receiver_normal[nearest], paths=50000
    )
    rho = mesh.receiver_reflectance[nearest]
    traced = mesh.receiver_emitted_exitance[nearest] + rho * irradiance
    return result.radiosity[nearest] / traced - 1.0, rho * error / traced


def test_path_tracer_reproduces_the_white_furnace() -> None:
    scene = furnace_box(reflectance=0.8, emitted_exitance=1.0)
    # the box spans [0, 1]^3 with its faces turned inward
    points = np.array([[0.5, 0.5, 0.0], [0.8, 0.0, 0.7], [1.0, 0.6, 0.5]])
    normals = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    irradiance, error = path_traced_radiosity(scene, points, normals, paths=100000)
    expected = 1.0 / (1.0 - 0.8)  # H = (B - E) / rho with B = E / (1 - rho)
    assert np.all(np.abs(irradiance - expected) < 4 * error + 1e-9)
    assert np.all(error < 0.02 * expected)


@pytest.mark.slow
def test_cornell_box_agrees_with_path_tracing() -> None:
    difference, noise = _compare(5000, 400, SMOOTH_POINTS)
    print("relative difference per point and channel:\n", np.round(difference, 4))
    assert np.all(noise < 0.01)
    # discretisation error at 5000 receivers plus 3 sigma of Monte Carlo noise
    assert np.all(np.abs(difference) < 0.025 + 3 * noise)


@pytest.mark.slow
def test_cornell_box_agrees_with_path_tracing_when_refined() -> None:
    points = np.vstack([SMOOTH_POINTS, [[0.28, 0.0, 0.28], [0.28, 0.0, 0.05]]])
    difference, noise = _compare(60000, 1600, points)
    print("relative difference per point and channel:\n", np.round(difference, 4))
    assert np.all(np.abs(difference) < 0.015 + 3 * noise)
