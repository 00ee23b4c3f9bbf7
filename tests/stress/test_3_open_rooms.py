"""Group 3: open rooms of reflectance 0.99 everywhere except the opening.

Independent expectations: a dense direct solve of the same discrete system (LAPACK, no
shooting), and the energy ledger emitted = absorbed + escaped + unshot, with the absorbed
power also recomputed from the final radiosity: sum_j a_j (1 - rho_j) (B_j - E_j) / rho_j.
"""

from __future__ import annotations

import numpy as np
import pytest

from .cases import OPEN_RHO, assert_finished, assert_within, case, ledger_error, run_case

OPENINGS = ["front", "window-0.2", "window-0.05"]


@pytest.mark.parametrize("opening", OPENINGS)
def test_open_room_matches_dense_solve_and_ledger(opening: str) -> None:
    run = run_case(case(f"open-{opening}"))
    assert_finished(run)
    assert_within(run)  # every receiver within 1% of the dense solve
    result, mesh = run.result, run.mesh
    assert ledger_error(result) < 1e-9
    rho = mesh.receiver_reflectance
    irradiance = (result.radiosity - mesh.receiver_emitted_exitance) / rho
    absorbed = mesh.receiver_area @ ((1.0 - rho) * irradiance)
    np.testing.assert_allclose(result.state.absorbed, absorbed, rtol=1e-9)
    # it is open: some light leaves, and the absorbed share is the rest
    assert (result.state.escaped > 0.05 * result.emitted_power).all()
    assert np.all(rho[mesh.receiver_emitted_exitance.max(axis=1) == 0] == OPEN_RHO)
