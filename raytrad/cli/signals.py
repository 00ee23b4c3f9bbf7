"""Stopping a command cleanly on a signal: the first Ctrl-C, SIGTERM or SIGHUP asks the
run to stop (results so far and checkpoints are written), a second one aborts."""

from __future__ import annotations

import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

#: Signals that stop a run cleanly, as Ctrl-C does: schedulers and container runtimes
#: stop work with SIGTERM, a closed terminal sends SIGHUP.
STOP_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)


class StopFlag:
    """Polled by a run (``flag()`` is True once a stop signal came); ``signum`` is the
    first such signal. A second signal among ``abort_on`` raises KeyboardInterrupt.

    Parameters
    ----------
    message : str
        Printed to stderr on the first signal.
    abort_on : tuple of int
        Signals that abort when they come second (default: every stop signal).
    """

    def __init__(self, message: str, abort_on: tuple[int, ...] = STOP_SIGNALS) -> None:
        self.message = message
        self.abort_on = abort_on
        self.signum = 0

    def __call__(self) -> bool:
        return self.signum != 0

    def handler(self, signum: int, frame: FrameType | None) -> None:
        if self.signum:
            if signum in self.abort_on:
                raise KeyboardInterrupt
            return
        self.signum = signum
        print(f"\nraytrad: {self.message}", file=sys.stderr)


@contextmanager
def stopping_on_signals(flag: StopFlag) -> Iterator[StopFlag]:
    """``flag`` handles :data:`STOP_SIGNALS` inside the block; the previous handlers are
    put back after it."""
    previous = {signum: signal.signal(signum, flag.handler) for signum in STOP_SIGNALS}
    try:
        yield flag
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
