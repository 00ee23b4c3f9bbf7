"""One shot through a cached column (:mod:`raytrad.core.shot`): the compiled shot against
its numpy reference, and its parallel copy against the serial one."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from raytrad.core import compiled, shot, solver, system
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SHOOTING_METHODS, SolveResult, SolveSettings, solve

METHODS = list(SHOOTING_METHODS)


def _solve(prepared: Prepared, **settings: object) -> SolveResult:
    return solve(prepared.mesh, prepared.engine, SolveSettings(**settings))  # type: ignore[arg-type]


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
@pytest.mark.parametrize("method", METHODS)
def test_compiled_shot_agrees_with_numpy_shot(
    cornell: Prepared, method: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The compiled shot (one loop per column) against :func:`numpy_step`, its reference:
    the same shots, radiosity and energy ledger to rounding, near-field gathers included."""
    settings = SolveSettings(method=method, max_shots=300, tolerance=1e-9)
    fast = solve(cornell.mesh, cornell.engine, settings)
    monkeypatch.setattr(solver, "_shoot", shot.numpy_step)
    slow = solve(cornell.mesh, cornell.engine, settings)
    assert any(len(g.receivers) for _, _, g in cornell.engine.near_field())
    assert fast.state.shots == slow.state.shots == 300
    scale = np.abs(slow.radiosity).max()
    np.testing.assert_allclose(fast.radiosity, slow.radiosity, rtol=0, atol=1e-12 * scale)
    for name in ("absorbed", "escaped", "patch_radiosity", "shot", "entry_shot"):
        a, b = getattr(fast.state, name), getattr(slow.state, name)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max())


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_the_parallel_shot_solves_as_the_serial_one_to_the_bit(
    cornell: Prepared, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The shot and spread compiled with ``parallel=True`` (numba's threads) and without
    (one after another) sum the same blocks in the same order: the same solve to the bit,
    whatever the cores."""
    fast = compiled.get()
    results = []
    for suffix in ("", "_parallel"):
        loops = SimpleNamespace(
            **{name: getattr(fast, name + suffix) for name in compiled.SOLVER_LOOPS}
        )
        monkeypatch.setattr(
            compiled,
            "solver_loops",
            lambda kernels, wanted, chosen=loops: compiled.SolverLoops(chosen),
        )
        results.append(_solve(cornell, tolerance=1e-4))
    serial, parallel = results
    assert serial.state.shots == parallel.state.shots > 100
    np.testing.assert_array_equal(serial.radiosity, parallel.radiosity)
    for name in ("patch_radiosity", "shot", "entry_shot", "absorbed", "escaped", "spread"):
        np.testing.assert_array_equal(getattr(serial.state, name), getattr(parallel.state, name))


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_a_column_s_plan_gives_the_shot_it_finds_to_the_bit(
    cornell: Prepared, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The near rows and far and near captures a column's first shot finds and its later
    shots read (:class:`system.ShotPlans`) are what a shot without them finds: the same
    solve to the bit with plans kept and with none (no bytes for them)."""
    read = []
    get = system.ShotPlans.get

    def counted(self: system.ShotPlans, *arguments: object) -> tuple:
        plan = get(self, *arguments)  # type: ignore[arg-type]
        read.append(plan[1])
        return plan

    monkeypatch.setattr(system.ShotPlans, "get", counted)
    planned = _solve(cornell, tolerance=1e-5)
    shooters = int((planned.state.shot != 0).any(axis=1).sum())
    assert planned.state.shots > 2 * shooters  # columns shot again
    assert sum(read) == planned.state.shots - shooters  # every later shot read its plan
    monkeypatch.setattr(system, "PLAN_BYTES", 0)
    unplanned = _solve(cornell, tolerance=1e-5)
    assert unplanned.state.shots == planned.state.shots
    np.testing.assert_array_equal(unplanned.radiosity, planned.radiosity)
    for name in ("patch_radiosity", "entry_shot", "absorbed", "escaped", "spread", "captured"):
        np.testing.assert_array_equal(getattr(unplanned.state, name), getattr(planned.state, name))


def test_shot_plans_are_kept_for_one_engine_and_its_scales_within_their_bytes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A kept plan is read back while the engine and its balancing scales are the same; a
    new engine, new row scales or a new column scale make it to be found again, and
    nothing is kept past :data:`system.PLAN_BYTES`."""

    class Engine:
        pass

    plans = system.ShotPlans()
    engine, rows = Engine(), np.ones(4)
    (near, sums, patches, values), known = plans.get(engine, 3, 2, (rows, 0.5))
    assert not known and near.dtype == patches.dtype == np.int32
    assert near.shape == (2,) and sums.shape == (5,) and values.shape == (0, 3)
    near[:], sums[:] = (1, 4), 0.25
    found = (near, sums, np.array([0, 2], np.int32), np.ones((2, 3)))
    plans.keep(3, found, (rows, 0.5))
    again, known = plans.get(engine, 3, 2, (rows, 0.5))
    assert known and all(a is b for a, b in zip(again, found, strict=True))
    assert not plans.get(engine, 3, 2, (rows, 0.25))[1]  # another column scale
    assert not plans.get(engine, 3, 2, (np.ones(4), 0.5))[1]  # other row scales
    assert not plans.get(engine, 2, 2, (rows, 0.5))[1]  # another patch
    assert not plans.get(Engine(), 3, 2, (rows, 0.5))[1]  # another engine: all forgotten
    assert not plans.get(engine, 3, 2, (rows, 0.5))[1] and plans.bytes == 0
    monkeypatch.setattr(system, "PLAN_BYTES", 100)
    plans.keep(3, found, (rows, 0.5))
    assert not plans.get(engine, 3, 2, (rows, 0.5))[1] and plans.bytes == 0


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
@pytest.mark.parametrize("bytes_for_plans", [0, system.PLAN_BYTES])
def test_the_spread_a_shot_leaves_is_the_whole_spread_to_the_bit(
    cornell: Prepared, monkeypatch: pytest.MonkeyPatch, bytes_for_plans: int
) -> None:
    """The compiled shot sums again only the patches it changed (those of its near
    receivers, those its plan names, the shooter): after many shots, with plans and
    without, the state's spread and peak are :meth:`DiscreteSystem.spread` of the whole
    state to the bit, and its totals are :func:`shot.unshot_totals`' of it."""
    monkeypatch.setattr(system, "PLAN_BYTES", bytes_for_plans)
    problem = system.DiscreteSystem.from_mesh(cornell.mesh, cornell.engine.subarea_means)
    state = solver.new_state(cornell.mesh, problem)
    fast = compiled.get()
    rng = np.random.default_rng(4)
    for patch in rng.integers(0, cornell.mesh.patch_count, 200):
        amount = rng.uniform(-0.2, 1.0, 3) * (1.0 + state.unshot[patch])
        totals = shot.shoot(problem, state, cornell.engine, int(patch), amount)
    whole = problem.spread(state.radiosity, state.entry_shot, state.unshot)
    np.testing.assert_array_equal(state.spread, whole[0])
    np.testing.assert_array_equal(state.peak, whole[1])
    assert totals == shot.unshot_totals(problem, state, fast)
    assert state.shots == 200 and not problem.touched.any()


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_a_solve_that_switches_between_serial_and_parallel_loops_is_the_same_to_the_bit(
    cornell: Prepared, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Another process's load on the cores makes the solve switch to its serial loops
    until it is gone (:class:`compiled.SolverLoops`); switching back and forth in the
    middle of a solve gives the solve of the serial loops alone."""
    fast = compiled.get()
    serial = SimpleNamespace(**{name: getattr(fast, name) for name in compiled.SOLVER_LOOPS})
    monkeypatch.setattr(
        compiled, "solver_loops", lambda kernels, wanted: compiled.SolverLoops(serial)
    )
    alone = _solve(cornell, tolerance=1e-4)
    monkeypatch.undo()
    modes = []
    loads = iter(np.tile([0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 2.0], 1000))  # free, busy, ...
    monkeypatch.setitem(compiled._STATE, "other load", SimpleNamespace(cores=lambda: next(loads)))
    tick = compiled.SolverLoops.tick

    def counted(self: compiled.SolverLoops) -> None:
        tick(self)
        modes.append(self.parallel)

    monkeypatch.setattr(compiled.SolverLoops, "tick", counted)
    switched = _solve(cornell, tolerance=1e-4)
    if compiled.solver_threads(2) > 1:
        assert True in modes and False in modes
    assert switched.state.shots == alone.state.shots > 100
    np.testing.assert_array_equal(switched.radiosity, alone.radiosity)
    for name in ("patch_radiosity", "shot", "entry_shot", "spread", "peak"):
        np.testing.assert_array_equal(getattr(switched.state, name), getattr(alone.state, name))
