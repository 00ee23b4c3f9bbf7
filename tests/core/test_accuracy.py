"""The total error estimate (raytrad.core.accuracy) against known errors."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from raytrad.core.accuracy import ErrorParts, discretisation_error, total_error_column
from raytrad.core.convergence import counted_receivers
from raytrad.core.pipeline import Prepared


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
