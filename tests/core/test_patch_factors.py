"""Patch-to-patch factors and the methods that gather over them: closed rows, the paper's
never-overestimate property of positive overshooting and super-shoot-gather, and the
memory check before any work."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from raytrad import api
from raytrad.core.mesh import MeshSettings
from raytrad.core.patch_factors import (
    MAX_PATCH_FACTOR_MB,
    PatchFactors,
    check_patch_factor_memory,
    patch_factor_mb,
)
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolverState, SolveSettings, solve
from raytrad.core.system import DiscreteSystem, patch_average_matrix
from raytrad.errors import SettingsError
from raytrad.settings import RenderSettings
from tests.conftest import SCENES, run_cli


def test_closed_rows_reflect_their_reflectance(prepare_furnace: Callable[..., Prepared]) -> None:
    # in a closed box every row of F sums to 1, so row i of K sums to rho_i
    prepared = prepare_furnace(0.8, 1.0)
    problem = DiscreteSystem.from_mesh(prepared.mesh)
    factors = PatchFactors.from_columns(problem, prepared.engine, problem.receiver_reflectance)
    np.testing.assert_allclose(factors.reflected.sum(axis=2), 0.8, rtol=1e-9)
    # one bounce returns rho^2 sum_j F_ij F_ji of a shot, below rho^2
    returned = factors.returned()
    assert (returned > 0).all() and (returned < 0.64).all()


#: How far the shot radiosity may pass the converged one [1]. In the closed convex box the
#: discrete system is the paper's (patch means of exact factors), and the property holds
#: to rounding. In the Cornell box near receivers gather what a patch shoots as it varies
#: across it (raytrad.core.gather), which the patch-mean factors do not see, so the
#: estimates can pass the answer a little: measured 3.7e-4 (positive) and 2.8e-2
#: (super-shoot-gather) at 2000 receivers; the bounds guard those figures.
OVERSHOOT_ALLOWED = {
    ("furnace", "positive"): 1e-9,
    ("furnace", "super_shoot_gather"): 1e-9,
    ("cornell", "positive"): 1e-3,
    ("cornell", "super_shoot_gather"): 5e-2,
}


@pytest.mark.parametrize(("scene", "method"), sorted(OVERSHOOT_ALLOWED))
def test_never_overestimates(
    cornell: Prepared,
    cornell_dense: np.ndarray,
    prepare_furnace: Callable[..., Prepared],
    scene: str,
    method: str,
) -> None:
    """At every step the radiosity each patch has shot stays at or below its converged
    radiosity (W B of a dense solve), the property the paper states for both methods."""
    if scene == "cornell":
        prepared, dense = cornell, cornell_dense
    else:
        from raytrad.core.reference import dense_solve

        prepared = prepare_furnace(0.9, 1.0)
        dense = dense_solve(prepared.mesh, prepared.engine)
    converged = patch_average_matrix(prepared.mesh) @ dense
    worst = [0.0]

    def watch(state: SolverState, residual: float) -> None:
        excess = (state.shot - converged) / np.maximum(converged, 1e-300)
        worst[0] = max(worst[0], float(excess.max()))

    result = solve(
        prepared.mesh, prepared.engine, SolveSettings(method=method, tolerance=1e-5), progress=watch
    )
    assert result.stop_reason == "converged"
    allowed = OVERSHOOT_ALLOWED[(scene, method)]
    assert worst[0] <= allowed, f"shot exceeded the converged radiosity by {worst[0]:.2e}"


def test_memory_is_checked_and_stated() -> None:
    assert patch_factor_mb(1000) == pytest.approx(1000 * 1000 * 24 / 2**20)
    check_patch_factor_memory(1000, "positive")
    too_many = int((MAX_PATCH_FACTOR_MB * 2**20 / 24) ** 0.5) + 10
    with pytest.raises(SettingsError, match="needs patch-to-patch form factors"):
        check_patch_factor_memory(too_many, "enhanced_super_shoot_gather")


def test_a_method_that_cannot_fit_is_refused_before_any_work(
    tmp_path: object, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"  # type: ignore[operator]
    argv = ["render", str(SCENES / "furnace.obj"), "-o", str(out), "-q", "--method", "positive"]
    status, _, err = run_cli([*argv, "--patches", "20000"], capsys)
    assert status == 1 and "needs patch-to-patch form factors" in err
    assert not out.exists()


def test_compare_runs_all_six_methods(tmp_path: object) -> None:
    methods = [
        "progressive",
        "overrelaxation",
        "ambient",
        "positive",
        "super_shoot_gather",
        "enhanced_super_shoot_gather",
    ]
    settings = RenderSettings(mesh=MeshSettings(receivers=600, patches=50))
    summary = api.compare(SCENES / "furnace.obj", tmp_path, methods, settings)  # type: ignore[arg-type]
    assert [row["method"] for row in summary["table"]] == methods
    for row in summary["table"]:
        assert row["stop_reason"] == "converged", row["method"]
        assert row["final_true_rms"] < 1e-2, row["method"]
