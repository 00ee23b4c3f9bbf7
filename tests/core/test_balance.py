"""Balancing (raytrad.core.balance): the compiled loop against its numpy reference, and the
constraints it must meet, on random sparse matrices whose answers are checked directly."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core import balance, compiled
from raytrad.core.balance import balance_columns, balance_streamed, numpy_balance_columns


def _random_columns(seed: int, receivers: int = 400, patches: int = 60):
    """Random column-stored factors with rows summing to about 1 (0.9-1.1)."""
    rng = np.random.default_rng(seed)
    dense = rng.random((receivers, patches)) * (rng.random((receivers, patches)) < 0.4)
    dense *= rng.uniform(0.9, 1.1, size=(receivers, 1)) / np.maximum(
        dense.sum(axis=1, keepdims=True), 1e-9
    )
    rows, cols = np.nonzero(dense.T)  # column-major: entries grouped by patch
    pointer = np.searchsorted(rows, np.arange(patches + 1)).astype(np.int64)
    receiver_area = rng.uniform(0.5, 1.5, receivers)
    # patch areas chosen so that captures straddle 1
    capture = receiver_area @ dense
    patch_area = capture * rng.uniform(0.8, 1.3, patches)
    fixed = rng.random(receivers) < 0.7
    closed = rng.random(patches) < 0.3
    return pointer, cols, dense.T[rows, cols], receiver_area, patch_area, fixed, closed, dense


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_balanced_factors_meet_the_constraints(seed: int) -> None:
    pointer, rows, values, a, area, fixed, closed, dense = _random_columns(seed)
    found = balance_columns(pointer, rows, values, a, area, fixed, closed)
    balanced = found.row_scale[:, None] * dense * found.column_scale[None, :]
    sums = balanced.sum(axis=1)
    np.testing.assert_allclose(sums[fixed & (dense.sum(axis=1) > 0)], 1.0, atol=1e-12)
    capture = (a @ balanced) / area
    np.testing.assert_allclose(capture[closed], 1.0, atol=1e-6)
    assert capture.max() <= 1.0 + 1e-6
    np.testing.assert_allclose(found.row_sums, sums, rtol=1e-12)
    np.testing.assert_allclose(found.capture_after, capture, rtol=1e-12)
    np.testing.assert_allclose(found.capture_before, (a @ dense) / area, rtol=1e-12)


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
@pytest.mark.parametrize("seed", [3, 4])
def test_compiled_balance_matches_numpy(seed: int) -> None:
    args = _random_columns(seed)[:7]
    fast, slow = balance_columns(*args), numpy_balance_columns(*args)
    assert fast.iterations == slow.iterations
    for a, b in zip(fast, slow, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0)


@pytest.mark.parametrize("kernels", ["compiled", "numpy"])
def test_streamed_balance_matches_the_numpy_reference(
    kernels: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Balancing a column at a time (compiled per-column loops, or their numpy versions)
    gives the whole-matrix Sinkhorn's scales, captures and row sums, float32 factors
    included; patches with no entries are skipped by the source and keep scale 1."""
    if kernels == "compiled" and compiled.get() is None:
        pytest.skip("numba is not installed")
    if kernels == "numpy":
        monkeypatch.setattr(balance.compiled, "get", lambda: None)
    _, _, _, a, area, fixed, closed, dense = _random_columns(5)
    dense[:, 7] = 0.0  # patch 7 has no entries
    rows, cols = np.nonzero(dense.T)
    pointer = np.searchsorted(rows, np.arange(len(area) + 1)).astype(np.int64)
    rows, values = cols, dense.T[rows, cols].astype(np.float32)
    slow = numpy_balance_columns(pointer, rows, values, a, area, fixed, closed)

    def columns():
        for p in range(len(area)):
            if pointer[p + 1] > pointer[p]:
                yield p, rows[pointer[p] : pointer[p + 1]], values[pointer[p] : pointer[p + 1]]

    calls = []
    fast = balance_streamed(lambda: calls.append(1) or columns(), a, area, fixed, closed)
    assert fast.iterations == slow.iterations
    assert len(calls) == fast.iterations + 2  # one sweep a round, one before, one after
    assert fast.column_scale[7] == 1.0
    for got, want in zip(fast, slow, strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
