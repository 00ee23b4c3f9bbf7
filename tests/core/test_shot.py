"""One shot through a cached column (:mod:`raytrad.core.shot`): the compiled shot against
its numpy reference, and its parallel copy against the serial one."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from raytrad.core import compiled, shot, solver
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
    """The compiled shot (one loop per column) against :func:`numpy_shoot`, its reference:
    the same shots, radiosity and energy ledger to rounding, near-field gathers included."""
    settings = SolveSettings(method=method, max_shots=300, tolerance=1e-9)
    fast = solve(cornell.mesh, cornell.engine, settings)
    monkeypatch.setattr(solver, "_shoot", shot.numpy_shoot)
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
            shoot=getattr(fast, "shoot" + suffix),
            spread_touched=getattr(fast, "spread_touched" + suffix),
        )
        monkeypatch.setattr(compiled, "solver_loops", lambda kernels, wanted, chosen=loops: chosen)
        results.append(_solve(cornell, tolerance=1e-4))
    serial, parallel = results
    assert serial.state.shots == parallel.state.shots > 100
    np.testing.assert_array_equal(serial.radiosity, parallel.radiosity)
    for name in ("patch_radiosity", "shot", "entry_shot", "absorbed", "escaped", "spread"):
        np.testing.assert_array_equal(getattr(serial.state, name), getattr(parallel.state, name))
