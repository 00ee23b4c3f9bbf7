"""Divergence is handled during the solve, and ambient overshooting stays much faster.

Form factors that sum to less than 1 in a closed scene make the published ambient term
overshoot by far too much (REFERENCE.md section 5.1: a toy box whose factors summed to 0.99
diverged at rho = 0.999). Here the exact, balanced factors of a convex cube are scaled by a
known k, so the exact answer of the altered system is still known: B = E / (1 - k rho).
"""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core import pipeline
from raytrad.core.solver import SolveSettings, solve
from raytrad.errors import SolverError
from raytrad.scene.builtin import furnace_box

from .cases import (
    BOX_MESH,
    ScaledEngine,
    assert_finished,
    assert_within,
    case,
    prepare,
    run_case,
    solve_prepared,
)


def test_ambient_survives_form_factors_that_sum_to_099() -> None:
    # rho = 0.999, rows summing to 0.99: B = 1 / (1 - 0.98901) = 90.99. No user action:
    # default settings, and the solve must converge to the altered system's exact answer.
    run = run_case(case("short-factors-0.999"))
    assert_finished(run)
    assert_within(run)
    assert run.result.state.shots < 20_000


@pytest.mark.filterwarnings("ignore:overflow:RuntimeWarning")  # part of the bug described
def test_energy_creating_form_factors_are_reported_as_divergence() -> None:
    prepared = pipeline.prepare(furnace_box(0.995, 1.0), BOX_MESH)
    try:
        try:
            result = solve(
                prepared.mesh,
                ScaledEngine(prepared.engine, 1.01),
                SolveSettings(max_shots=10_000, time_limit=30.0),
            )
        except SolverError as exc:
            assert "diverg" in str(exc).lower()
            return
    finally:
        prepared.close()
    assert result.stop_reason == "diverged", (
        f"stop reason {result.stop_reason!r}, largest B {np.abs(result.radiosity).max():.3g}"
    )


@pytest.mark.parametrize("name", ["furnace-0.99", "open-window-0.2"])
def test_ambient_is_much_faster_than_progressive(name: str) -> None:
    # Where progressive refinement is slow (rho = 0.99), it is still far from converged at
    # the shot count ambient overshooting needed to converge.
    stress = case(name)
    prepared, _ = prepare(stress)
    try:
        ambient = solve_prepared(stress, prepared, "ambient")
        progressive = solve_prepared(stress, prepared, "progressive", max_shots=ambient.state.shots)
    finally:
        prepared.close()
    assert ambient.stop_reason == "converged"
    assert progressive.stop_reason == "max-shots"
    assert progressive.residual > 100 * ambient.residual
