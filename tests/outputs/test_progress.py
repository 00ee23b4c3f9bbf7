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
