"""The solve's per-patch compiled loops (:mod:`raytrad.core._compiled_spread`): the
touched patches' runs, and spreads left to drift by lazy shots against every spread
summed again after every shot."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core import _compiled_spread, compiled, shot, solver
from raytrad.core.mesh import MeshSettings, build_mesh
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolveSettings, solve
from raytrad.core.system import DiscreteSystem
from raytrad.scene.builtin import cornell_box

pytestmark = pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")


@pytest.fixture(scope="module")
def system() -> DiscreteSystem:
    return DiscreteSystem.from_mesh(build_mesh(cornell_box(), MeshSettings(receivers=800)))


@pytest.mark.parametrize("share", [0.0, 0.05, 0.4, 1.0])
def test_touched_runs_take_every_marked_patch_once_in_runs_of_like_entries(
    system: DiscreteSystem, share: float
) -> None:
    """The compiled shot's spread takes the marked patches ascending, each once, in
    ``SPREAD_PARTS`` runs whose entries differ from an equal share by at most one patch's,
    and clears the marks."""
    fast = compiled.get()
    touched = np.random.default_rng(3).random(len(system.patch_area)) < share
    system.touched[:] = touched
    rows, ends = fast._touched_runs(system.touched, system.patch_ptr)
    np.testing.assert_array_equal(rows, np.flatnonzero(touched))
    assert not system.touched.any()
    parts = _compiled_spread.SPREAD_PARTS
    assert ends[0] == 0 and ends[-1] == len(rows) and len(ends) == parts + 1
    assert (np.diff(ends) >= 0).all()
    sizes = np.diff(system.patch_ptr)[rows]
    per_run = np.add.reduceat(np.append(sizes, 0), ends[:-1])[:parts] * (np.diff(ends) > 0)
    assert per_run.sum() == sizes.sum()
    if len(rows):
        assert np.abs(per_run - sizes.sum() / parts).max() <= sizes.max()


def _solve(prepared: Prepared, monkeypatch: pytest.MonkeyPatch, lazy: bool, **settings: object):
    monkeypatch.setattr(solver, "LAZY_SPREAD", lazy)
    return solve(prepared.mesh, prepared.engine, SolveSettings(**settings))  # type: ignore[arg-type]


@pytest.mark.parametrize("tolerance", [1e-3, 1e-5])
def test_lazy_spreads_solve_as_every_spread_summed_after_every_shot_to_the_bit(
    cornell: Prepared, monkeypatch: pytest.MonkeyPatch, tolerance: float
) -> None:
    """Shots that leave the spreads of far patches to drift, summed again only where the
    choice or the stop could turn on them, choose the same shooters and stop at the same
    shot as shots that sum every changed spread: the same solve to the bit, and a state
    whose spreads are exact once it returns."""
    lazy = _solve(cornell, monkeypatch, True, tolerance=tolerance)
    eager = _solve(cornell, monkeypatch, False, tolerance=tolerance)
    assert lazy.state.shots == eager.state.shots > 100
    assert lazy.stop_reason == eager.stop_reason == "converged"
    assert lazy.residual == eager.residual
    np.testing.assert_array_equal(lazy.radiosity, eager.radiosity)
    for name in ("patch_radiosity", "shot", "entry_shot", "spread", "peak", "captured"):
        np.testing.assert_array_equal(getattr(lazy.state, name), getattr(eager.state, name))
    assert lazy.state.settle is None


def test_a_drifted_spread_stays_within_its_drift_of_the_spread_summed_again(
    cornell: Prepared,
) -> None:
    """After lazy shots the stored spread of every patch is within its drift of the spread
    summed again from the state (the bound the choice and the stop rely on), the drift is
    zero exactly where the spread was summed again, and the totals' width is the
    area-weighted drift."""
    problem = DiscreteSystem.from_mesh(cornell.mesh, cornell.engine.subarea_means)
    state = solver.new_state(cornell.mesh, problem)
    fast = compiled.get()
    loops = compiled.solver_loops(fast, 2)
    rng = np.random.default_rng(5)
    drifted = 0
    for patch in rng.integers(0, cornell.mesh.patch_count, 150):
        amount = rng.uniform(-0.1, 1.0, 3)
        totals = shot.shoot(problem, state, cornell.engine, int(patch), amount, loops, True)
        whole, _ = problem.spread(state.radiosity, state.entry_shot, state.unshot)
        drift = problem.spread_drift
        assert (np.abs(whole - state.spread) <= drift).all()
        exact = ~(drift > 0).any(axis=1)
        np.testing.assert_array_equal(state.spread[exact], whole[exact])
        drifted = max(drifted, int((~exact).sum()))
        assert totals[2] == pytest.approx(float((problem.patch_area @ drift).sum()), rel=1e-12)
    assert drifted > cornell.mesh.patch_count // 4  # the shots did leave spreads to drift
    whole = problem.spread(state.radiosity, state.entry_shot, state.unshot)
    totals = solver._settle(problem, state, loops)
    np.testing.assert_array_equal(state.spread, whole[0])
    np.testing.assert_array_equal(state.peak, whole[1])
    assert not problem.spread_drift.any() and not problem.touched.any() and totals[2] == 0.0


def test_the_convergence_log_reads_settled_spreads_during_a_lazy_solve(
    cornell: Prepared, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A progress hook that reads the state mid-solve (the convergence log) gets its
    spreads summed again first: the unshot magnitude it sees is the whole spread's."""
    monkeypatch.setattr(solver, "LAZY_SPREAD", True)
    seen = []

    def hook(state: solver.SolverState, residual: float) -> None:
        if state.shots % 50 == 0:
            problem = DiscreteSystem.from_mesh(cornell.mesh, cornell.engine.subarea_means)
            magnitude = state.unshot_magnitude  # settles
            whole, _ = problem.spread(state.radiosity, state.entry_shot, state.unshot)
            np.testing.assert_array_equal(magnitude, np.abs(state.unshot) + whole)
            seen.append(residual)

    result = solve(cornell.mesh, cornell.engine, SolveSettings(tolerance=1e-4), progress=hook)
    assert len(seen) >= 2 and result.state.shots > 100
