"""Group 1: closed boxes of reflectance 0.9, 0.99 and 0.999.

Independent expectations: the white furnace B = E / (1 - rho) at every receiver, and for any
closed scene of uniform reflectance the exact power balance
sum_j a_j B_j = sum_j a_j E_j / (1 - rho) (REFERENCE.md section 3). A non-convex closed
scene (a box holding a block) checks that occlusion does not lose energy.
"""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core import pipeline
from raytrad.core.mesh import MeshSettings
from raytrad.core.solver import SolveSettings, solve
from raytrad.scene.builtin import furnace_box

from .cases import HIGH_RHO, OPEN_RHO, assert_finished, assert_within, case, run_case


@pytest.mark.parametrize("rho", HIGH_RHO)
def test_white_furnace(rho: float) -> None:
    # B = E / (1 - rho) everywhere: 10, 100 and 1000 for E = 1.
    run = run_case(case(f"furnace-{rho}"))
    assert_finished(run)
    assert_within(run)


@pytest.mark.parametrize("rho", HIGH_RHO)
def test_power_balance_with_one_emitting_face(rho: float) -> None:
    # The ceiling (1 m2, E = 1) alone emits: sum a B = 1 / (1 - rho) W.
    run = run_case(case(f"one-lamp-{rho}"))
    assert_finished(run)
    assert_within(run)
    # nothing can leave a closed box
    state, emitted = run.result.state, run.result.emitted_power
    assert (state.escaped <= 1e-3 * emitted).all()


def test_power_balance_with_a_floating_block() -> None:
    # Non-convex: the block shadows, the rows are balanced by ray casting, not geometry.
    run = run_case(case(f"block-floating-{OPEN_RHO}"))
    assert_finished(run)
    assert_within(run)


def test_power_balance_with_a_block_standing_on_the_floor() -> None:
    run = run_case(case(f"block-standing-{OPEN_RHO}"))
    assert_finished(run)
    assert_within(run)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("receivers", "rho"), [(300, 0.9999), (2000, 0.999), (2000, 0.9999), (20000, 0.99)]
)
def test_furnace_conserves_at_any_mesh_size(receivers: int, rho: float) -> None:
    # Balancing rows and columns jointly (no capping) and power-conserving near-field
    # shots: a coarse closed box loses nothing, even at rho = 0.9999 where 0.01% lost
    # per bounce would be 100% of the answer. The default settings otherwise.
    prepared = pipeline.prepare(furnace_box(rho, 1.0), MeshSettings(receivers=receivers))
    try:
        result = solve(prepared.mesh, prepared.engine, SolveSettings(max_shots=400_000))
    finally:
        prepared.close()
    assert result.stop_reason == "converged"
    np.testing.assert_allclose(result.radiosity * (1.0 - rho), 1.0, rtol=5e-3)
