"""Balancing (raytrad.core.balance): the compiled loop against its numpy reference, and the
constraints it must meet, on random sparse matrices whose answers are checked directly."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core import balance, compiled
from raytrad.core.balance import (
    BALANCE_CONVERGED,
    BALANCE_ITERATIONS,
    BALANCE_STALL,
    COLUMN_SCALE_LIMIT,
    balance_columns,
    balance_streamed,
    numpy_balance_columns,
)


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
    # a closed patch is held to 1 unless that takes more than the limit's scale
    assert found.column_scale.max() <= COLUMN_SCALE_LIMIT
    held = found.column_scale < COLUMN_SCALE_LIMIT
    np.testing.assert_allclose(capture[closed & held], 1.0, atol=1e-6)
    assert (capture[closed & ~held] < 1.0).all()
    assert capture.max() <= 1.0 + 1e-6
    summary = found.summary(dense.sum(axis=1), fixed, closed, area)
    assert summary["short_columns"] == (closed & ~held).sum()
    assert summary["short_area"] == pytest.approx(area[closed & ~held].sum() / area.sum())
    short = capture[closed & ~held]
    assert summary["column_deficit"] == pytest.approx(1.0 - short.min() if len(short) else 0.0)
    np.testing.assert_allclose(found.row_sums, sums, rtol=1e-12)
    np.testing.assert_allclose(found.capture_after, capture, rtol=1e-12)
    np.testing.assert_allclose(found.capture_before, (a @ dense) / area, rtol=1e-12)


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
@pytest.mark.parametrize("seed", [3, 4])
def test_compiled_balance_matches_numpy(seed: int) -> None:
    args = _random_columns(seed)[:7]
    fast, slow = balance_columns(*args), numpy_balance_columns(*args)
    assert fast.iterations == slow.iterations
    assert fast.stopped == slow.stopped == "converged"
    for a, b in zip(fast[:-1], slow[:-1], strict=True):
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
    assert fast.stopped == slow.stopped
    for got, want in zip(fast[:-1], slow[:-1], strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)


@pytest.mark.parametrize("streamed", [True, False])
def test_a_gap_narrower_than_the_receivers_is_not_balanced_by_far_factors(streamed: bool) -> None:
    """A light 1 mm under a ceiling, facing it: the ceiling's receivers over the light see
    nothing else (rows held to 1) but their areas sum to 70 % of the light's, so the light
    cannot capture all it shoots through them. Before the limit, Sinkhorn scaled the
    light's column until the small factors of receivers outside the gap made up the rest:
    the far receiver's factor 0.003 came out 0.27, 90 times the light it should get. Now
    the column scales by the limit at most, the light delivers 70 % x 1.25 of what it
    shoots, and the far receiver's factor grows by 1.25 at most.
    """
    # receivers 0-2 in the gap (closed, each sees only the light); 3 far away (open) sees
    # the light barely and the wall mostly; patch 0 the light (closed), patch 1 a wall
    dense = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.003, 0.5]])
    receiver_area = np.array([0.21, 0.21, 0.21, 1.0])
    patch_area = np.array([0.9, 10.0])
    fixed = np.array([True, True, True, False])
    closed = np.array([True, False])
    rows, cols = np.nonzero(dense.T)
    pointer = np.searchsorted(rows, np.arange(3)).astype(np.int64)
    values = dense.T[rows, cols]
    args = (pointer, cols, values, receiver_area, patch_area, fixed, closed)
    found = balance_columns(*args) if streamed else numpy_balance_columns(*args)
    assert found.column_scale[0] == pytest.approx(COLUMN_SCALE_LIMIT)
    balanced = found.row_scale[:, None] * dense * found.column_scale[None, :]
    np.testing.assert_allclose(balanced[:3].sum(axis=1), 1.0, atol=1e-12)  # gap rows held
    assert balanced[3, 0] <= COLUMN_SCALE_LIMIT * 0.003 + 1e-15
    capture = receiver_area @ balanced / patch_area
    assert capture[0] == pytest.approx((0.63 + 0.003 * COLUMN_SCALE_LIMIT) / 0.9)  # short of 1
    summary = found.summary(dense.sum(axis=1), fixed, closed, patch_area)
    assert summary["short_columns"] == 1
    assert summary["short_area"] == pytest.approx(0.9 / 10.9)
    assert summary["column_deficit"] == pytest.approx(1.0 - capture[0])


def test_balancing_stops_when_its_misses_stall_or_meet_the_tolerance() -> None:
    reason = balance.stop_reason
    assert reason([0.3, 1e-4, BALANCE_CONVERGED]) == "converged"
    assert reason([0.3, 1e-4, 2 * BALANCE_CONVERGED]) == ""
    halving = [2.0**-k for k in range(25)]  # halves each round: never stalls (2**-25 > 1e-9)
    assert not any(reason(halving[: k + 1]) for k in range(25))
    slow = [1e-3 * 0.95**k for k in range(40)]  # halves in 14 rounds: stalls after 10
    stops = [k for k in range(len(slow)) if reason(slow[: k + 1])]
    assert stops[0] == BALANCE_STALL and reason(slow[: BALANCE_STALL + 1]) == "stalled"
    # stalled far from the constraints (a light 1 mm under a ceiling): goes on
    plateau = [0.3 * 0.99**k for k in range(40)]
    assert not any(reason(plateau[: k + 1]) for k in range(len(plateau)))


def test_capture_miss_skips_short_and_empty_patches() -> None:
    capture = np.array([0.5, 0.9, 1.2, 0.0, 0.7, 1.5])
    scale = np.array([2.0, 1.0, 0.9, 1.0, COLUMN_SCALE_LIMIT, 1.0])
    closed = np.array([True, True, False, True, True, False])
    # g = 1.0, 0.9 (closed: misses 0.1), 1.08 (open: 0.08 over), nothing, 0.875 (held
    # at the limit), 1.5 (open: 0.5 over)
    assert balance.capture_miss(capture, scale, closed) == pytest.approx(0.5)
    assert balance.capture_miss(capture[:5], scale[:5], closed[:5]) == pytest.approx(0.1)
    assert balance.capture_miss(capture[4:5], scale[4:5], closed[4:5]) == 0.0


@pytest.mark.parametrize("streamed", [True, False])
def test_a_closed_scene_with_a_short_patch_stops_early_with_its_rows_held(streamed: bool) -> None:
    """Every receiver closed and every patch closed, one patch short of delivering what it
    shoots (its factors a third of the others'): the row and column constraints cannot all
    hold, since sum_j a_j sum_p F'_jp = sum_p A_p g_p. Sinkhorn drifted for all its rounds
    (the column scales creeping towards ones that would undo the limit); it now stops when
    its misses stall, with the rows at 1 and the other patches capturing the short one's
    deficit between them."""
    rng = np.random.default_rng(11)
    receivers, patches = 300, 40
    dense = rng.random((receivers, patches)) * (rng.random((receivers, patches)) < 0.5)
    dense /= dense.sum(axis=1, keepdims=True)
    receiver_area = rng.uniform(0.5, 1.5, receivers)
    patch_area = receiver_area @ dense  # sums to the receivers' area: only patch 0 is short
    dense[:, 0] /= 3.0  # patch 0 captures a third of its area: short at scale 1.25
    rows, cols = np.nonzero(dense.T)
    pointer = np.searchsorted(rows, np.arange(patches + 1)).astype(np.int64)
    fixed, closed = np.ones(receivers, bool), np.ones(patches, bool)
    args = (pointer, cols, dense.T[rows, cols], receiver_area, patch_area, fixed, closed)
    found = balance_columns(*args) if streamed else numpy_balance_columns(*args)
    assert found.iterations < BALANCE_ITERATIONS and found.stopped == "stalled"
    balanced = found.row_scale[:, None] * dense * found.column_scale[None, :]
    np.testing.assert_allclose(balanced.sum(axis=1), 1.0, atol=1e-12)
    capture = receiver_area @ balanced / patch_area
    short = found.short(closed)
    assert short[0] and short.sum() == 1
    assert found.column_scale[0] == COLUMN_SCALE_LIMIT and capture[0] < 0.6
    # the others capture the deficit between them, none much more than its even share
    deficit = patch_area[0] * (1.0 - capture[0])
    np.testing.assert_allclose(patch_area[1:] @ (capture[1:] - 1.0), deficit, rtol=1e-9)
    even = deficit / patch_area[1:].sum()
    assert 0.5 * even < (capture[1:] - 1.0).min() and (capture[1:] - 1.0).max() < 1.5 * even
