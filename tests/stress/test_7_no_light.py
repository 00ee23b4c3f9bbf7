"""Group 7: nothing to light.

A scene with no emitter ends at once with zero radiosity; a lamp that faces away from
everything lights nothing, and all its power escapes.
"""

from __future__ import annotations

import numpy as np

from .cases import AWAY_EXITANCE, assert_finished, assert_within, case, run_case


def test_no_emitter() -> None:
    run = run_case(case("no-emitter"))
    assert_finished(run, "no-emission")
    result = run.result
    assert result.state.shots == 0
    assert (result.radiosity == 0.0).all()
    assert result.residual == 0.0
    assert (result.emitted_power == 0.0).all()


def test_emitter_facing_away_from_everything() -> None:
    run = run_case(case("emitter-facing-away"))
    assert_finished(run)
    result, mesh = run.result, run.mesh
    lamp = (mesh.receiver_emitted_exitance > 0).any(axis=1)
    assert (result.radiosity[~lamp] == 0.0).all()
    np.testing.assert_allclose(result.radiosity[lamp], AWAY_EXITANCE)
    assert (result.state.absorbed == 0.0).all()
    np.testing.assert_allclose(
        result.state.escaped + result.unshot_power, result.emitted_power, rtol=1e-12
    )
    assert_within(run)  # escaped = emitted within the solver tolerance
