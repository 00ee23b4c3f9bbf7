"""The form-factor pass's checkpoint hook (raytrad.outputs.progress.pass_hook)."""

from __future__ import annotations

import time

import pytest

from raytrad.outputs import progress


def _saves(monkeypatch: pytest.MonkeyPatch, seconds: float, save_takes: float, run: float) -> int:
    monkeypatch.setattr(progress, "new_state", lambda mesh: None)
    calls = []

    def save(state: object, engine: object) -> None:
        calls.append(time.perf_counter())
        time.sleep(save_takes)

    hook = progress.pass_hook(save, seconds)  # type: ignore[arg-type]
    end = time.perf_counter() + run
    while time.perf_counter() < end:
        hook(None, None)  # type: ignore[arg-type]
        time.sleep(0.001)
    return len(calls)


def test_a_slow_save_spaces_out_the_next_ones(monkeypatch: pytest.MonkeyPatch) -> None:
    """Saves of 0.05 s wait at least 9 x 0.05 s apart, whatever ``seconds`` asks: over
    0.6 s at most 2 saves (the first one right away) instead of about 12."""
    assert _saves(monkeypatch, 0.0, 0.05, 0.6) <= 2
    assert _saves(monkeypatch, 0.0, 0.0, 0.2) > 20  # quick saves keep the asked interval


def test_the_asked_interval_still_holds(monkeypatch: pytest.MonkeyPatch) -> None:
    assert _saves(monkeypatch, 10.0, 0.0, 0.3) == 0


def test_each_save_tells_what_it_wrote_and_took(monkeypatch: pytest.MonkeyPatch) -> None:
    """The run's budget learns how fast this machine writes a checkpoint from the pass's
    own saves (``measured``): the bytes the engine held and the save's duration."""
    from types import SimpleNamespace

    from raytrad.core.pipeline import SAVE_BYTES_PER_SECOND, RunBudget

    monkeypatch.setattr(progress, "new_state", lambda mesh: None)
    told: list[tuple[int, float]] = []
    hook = progress.pass_hook(
        lambda state, engine: time.sleep(0.02),
        0.0,
        lambda written, seconds: told.append((written, seconds)),
    )
    engine = SimpleNamespace(held_bytes=200_000_000)
    hook(None, engine)  # type: ignore[arg-type]
    ((written, seconds),) = told
    assert written == 200_000_000 and 0.02 <= seconds < 1.0
    budget = RunBudget(100.0)
    assert budget.rate == SAVE_BYTES_PER_SECOND
    budget.measured(written, seconds)
    assert budget.rate == written / seconds
    budget.measured(1_000_000, 1e-4)  # a small save (the page cache's) is not believed
    assert budget.rate == written / seconds
    budget.held(engine)  # type: ignore[arg-type]
    assert budget.reserve() == 200_000_000 / budget.rate
