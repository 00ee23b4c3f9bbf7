"""Group 2: reflectance exactly 1.

A closed scene that reflects everything in a channel where something emits has no finite
solution: raytrad must say so before any form factor is computed or any shot is taken.
"""

from __future__ import annotations

import numpy as np
import pytest

import raytrad.core.pipeline
from raytrad import api
from raytrad.core.pipeline import prepare
from raytrad.core.reference import dense_solve
from raytrad.core.solver import SolveSettings, solve
from raytrad.errors import SolverError
from raytrad.scene.builtin import furnace_box
from raytrad.settings import RenderSettings

from .cases import BOX_MESH, MAX_SHOTS, TIME_LIMIT, lossless_open_scene


class _NoFormFactors:
    """Stands in for FormFactorEngine: any form-factor work fails the test."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        raise AssertionError("form factors were computed for an unsolvable scene")


def test_closed_scene_of_reflectance_one_is_refused_before_any_work(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(raytrad.core.pipeline, "FormFactorEngine", _NoFormFactors)
    with pytest.raises(SolverError, match="reflectance 1"):
        prepare(furnace_box(1.0, 1.0), BOX_MESH)


def test_reflectance_one_in_one_channel_names_the_channel(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(raytrad.core.pipeline, "FormFactorEngine", _NoFormFactors)
    with pytest.raises(SolverError, match="channel G"):
        prepare(furnace_box((0.5, 1.0, 0.5), 1.0), BOX_MESH)


def test_reflectance_one_in_a_channel_without_emission_is_solved() -> None:
    # Green reflects everything but nothing emits green: B = (2, 0, 2) is finite.
    settings = RenderSettings(
        mesh=BOX_MESH, solve=SolveSettings(max_shots=MAX_SHOTS, time_limit=TIME_LIMIT)
    )
    _, result = api.solve_scene(furnace_box((0.5, 1.0, 0.5), (1.0, 0.0, 1.0)), settings)
    assert result.stop_reason == "converged"
    np.testing.assert_allclose(
        result.radiosity[:, [0, 2]], 2.0, rtol=3e-3
    )  # three times the tolerance (test_solver)
    assert (result.radiosity[:, 1] == 0.0).all()


def test_open_scene_of_reflectance_one_is_solved_or_clearly_refused() -> None:
    # Light escapes to the sky, so the system has a finite solution. The issue accepts the
    # right answer (checked against a dense direct solve) or a clear error.
    settings = RenderSettings(mesh=BOX_MESH)
    try:
        prepared = api.prepare(lossless_open_scene(), settings)
    except SolverError as exc:
        assert "reflectance 1" in str(exc)
        return
    try:
        result = solve(
            prepared.mesh,
            prepared.engine,
            SolveSettings(tolerance=1e-4, max_shots=MAX_SHOTS, time_limit=TIME_LIMIT),
        )
        reference = dense_solve(prepared.mesh, prepared.engine)
    finally:
        prepared.close()
    assert result.stop_reason == "converged"
    np.testing.assert_allclose(result.radiosity, reference, rtol=1e-2, atol=1e-9)
