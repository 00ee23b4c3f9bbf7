"""The total error estimate (raytrad.core.accuracy) against known errors."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from raytrad.core.accuracy import (
    ErrorParts,
    _gathered,
    discretisation_error,
    total_error_column,
)
from raytrad.core.convergence import counted_receivers
from raytrad.core.mesh import MeshSettings, build_mesh
from raytrad.core.pipeline import Prepared
from raytrad.scene.builder import SceneBuilder, rectangle


def test_exact_furnace_solution_has_no_residual(prepare_furnace: Callable[..., Prepared]) -> None:
    # B = E / (1 - rho) satisfies the radiosity equation at every point: what the check
    # reports is its Monte Carlo noise, which it subtracts.
    prepared = prepare_furnace(0.5, 1.0)
    mesh = prepared.mesh
    exact = np.full((mesh.receiver_count, 3), 2.0)
    residual = discretisation_error(
        prepared.scene, mesh, exact, counted_receivers(mesh), 1.0, samples=1024, rays=1024
    )
    assert residual.samples == 1024
    assert (residual.residual < 0.005).all()
    # what is reported is one standard error of that subtraction, amplified: the noise
    # floor of the check (every wall here is an emitter, sampled by area: noisy near
    # the box's edges), which keeps the estimate on the safe side
    assert (residual.error < 0.06).all()
    np.testing.assert_allclose(residual.gain, 2.0)


def test_a_wrong_solution_is_found_and_not_understated(
    prepare_furnace: Callable[..., Prepared],
) -> None:
    # 10% too bright everywhere: the true relative error is 0.1. The residual
    # B' - E - rho H' = 0.1 E / (1 - rho) is 1/11 of B', amplified by 1 / (1 - rho):
    # the estimate must cover the truth, within the factor 3 the targets allow.
    prepared = prepare_furnace(0.5, 1.0)
    mesh = prepared.mesh
    wrong = np.full((mesh.receiver_count, 3), 2.2)
    residual = discretisation_error(
        prepared.scene, mesh, wrong, counted_receivers(mesh), 1.0, samples=256, rays=256
    )
    np.testing.assert_allclose(residual.residual, 1 / 22, rtol=0.1)
    assert (residual.error >= 1 / 11).all() and (residual.error <= 3 / 11).all()


def test_total_error_column_adds_the_bake_error_to_each_bound() -> None:
    parts = ErrorParts(
        algebraic=np.full(3, 0.001),
        discretisation=np.array([0.02, 0.03, 0.04]),
        conservation=np.zeros(3),
    )
    np.testing.assert_allclose(parts.total, [0.02, 0.03, 0.04])
    assert parts.dominant == "discretisation"
    column = total_error_column([[np.inf] * 3, [0.5, 0.5, 0.5], [0.001] * 3], parts)
    assert len(column) == 3
    assert all(v is None or v == np.inf for v in column[0])
    np.testing.assert_allclose(column[1], [0.52, 0.53, 0.54])
    np.testing.assert_allclose(column[2], parts.total)


def test_points_no_front_sees_are_skipped() -> None:
    # A block sunk 5 cm into the floor of a closed room: its sides below the floor see the
    # floor's back and the void beneath, no surface's front; no light reaches them and
    # none leaves them for anyone in the room. The residual check skips them (they were
    # a 9.5 times overestimate of a furnished room's error: a point there gathers 0 and
    # shows the lit value of the floor line above). Points above the floor are kept.
    builder = SceneBuilder()
    builder.material("white", 0.7)
    builder.material("lamp", 0.0, 5.0)
    builder.room("white", (1.0, 1.0, 1.0))
    builder.block("white", (0.3, -0.05, 0.3), (0.6, 0.25, 0.6))
    builder.quad(rectangle(1, 1.0 - 5e-4, (0.3, 0.3), (0.62, 0.62)), "lamp", (0, -1, 0))
    scene = builder.build()
    mesh = build_mesh(scene, MeshSettings(receivers=2000))
    centroid = mesh.positions[mesh.triangles].mean(axis=1)
    side = (np.abs(mesh.triangle_normal[:, 1]) < 1e-9) & (centroid[:, 0] > 0.29)
    side &= centroid[:, 0] < 0.61
    below = np.flatnonzero(side & (centroid[:, 1] < -0.01))
    above = np.flatnonzero(side & (centroid[:, 1] > 0.01))
    assert len(below) and len(above)
    tri = np.concatenate([below, above])
    weights = np.full((len(tri), 3), 1.0 / 3.0)
    radiosity = np.ones((mesh.receiver_count, 3))
    rng = np.random.default_rng(0)
    _, _, shut = _gathered(scene, mesh, radiosity, tri, weights, 256, rng)
    assert shut[: len(below)].all()
    assert not shut[len(below) :].any()
