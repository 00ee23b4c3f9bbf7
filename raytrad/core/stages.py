"""How far the long stages besides the solve have come: the form-factor pass (columns)
and each final gather (patches: a refinement round's new receivers), for a progress bar.

The stages call :func:`report` as they go; it does nothing unless a caller has installed
a sink with :func:`reporting` (the command line does, on a terminal). A context variable
holds the sink, so two renders in one process (threads, or a library user's own) do not
see each other's progress, and the core needs no parameter threaded through every layer
for a display it does not own. The solve reports through its own hook
(:func:`raytrad.outputs.progress.shot_hook`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar

#: ``sink(stage, done, total)``: what :func:`report` calls, when installed.
StageSink = Callable[[str, int, int], None]

#: Stage names :func:`report` is called with.
FORM_FACTORS = "form factors"
FINAL_GATHER = "final gather"

_SINK: ContextVar[StageSink | None] = ContextVar("raytrad_stage_sink", default=None)


def report(stage: str, done: int, total: int) -> None:
    """``done`` of ``total`` parts of ``stage`` are finished (call from the thread that
    runs the stage: worker threads do not see the caller's sink)."""
    sink = _SINK.get()
    if sink is not None:
        sink(stage, done, total)


@contextmanager
def reporting(sink: StageSink | None) -> Iterator[None]:
    """Send the stages' :func:`report` calls in this context to ``sink`` (None: nowhere)."""
    token = _SINK.set(sink)
    try:
        yield
    finally:
        _SINK.reset(token)
