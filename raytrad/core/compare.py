"""Running several shooting methods on one prepared problem, each logged against the same
reference, for ``raytrad compare``.

Each method gets its own form-factor engine on the same mesh (nothing is shared between
the timed runs, so each pays for its own ray tracing).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from typing import Any

from raytrad.core.convergence import ConvergenceMonitor, ErrorLog, Reference
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolveSettings, solve

log = logging.getLogger(__name__)

#: True-error levels the comparison table reports times for.
LEVELS = (1e-2, 1e-3)


@dataclass
class MethodRun:
    """One method's solve in a comparison."""

    method: str
    log: ErrorLog
    stop_reason: str
    shots: int
    rays: int
    seconds: float
    setup_seconds: float = 0.0

    def row(self) -> dict[str, Any]:
        """Table row: time and shots to each level of true error, final error, rays.

        Times include the method's own form-factor set-up (``setup_seconds``).
        """
        out: dict[str, Any] = {"method": self.method, "stop_reason": self.stop_reason}
        for level in LEVELS:
            reached = self.log.first_below(level)
            out[f"seconds_to_{level:g}"] = (
                None if reached is None else reached[0] + self.setup_seconds
            )
            out[f"shots_to_{level:g}"] = None if reached is None else reached[1]
        final = self.log.true_rms[-1] if self.log.true_rms else None
        out["final_true_rms"] = None if final is None else max(final)
        out["shots"] = self.shots
        out["rays"] = self.rays
        out["seconds"] = self.seconds + self.setup_seconds
        out["setup_seconds"] = self.setup_seconds
        return out


def run_method(
    prepared: Prepared, settings: SolveSettings, method: str, ref: Reference
) -> MethodRun:
    """Solve ``prepared`` with ``method`` on a fresh engine, logging the true error."""
    mesh = prepared.mesh
    start = time.perf_counter()
    engine = prepared.new_engine()
    setup = time.perf_counter() - start
    monitor = ConvergenceMonitor(mesh, engine, ref)
    try:
        result = solve(mesh, engine, replace(settings, method=method), progress=monitor)
    finally:
        engine.close()
    state = result.state
    log.info("%s: %s after %d shots", method, result.stop_reason, state.shots)
    return MethodRun(
        method,
        monitor.finish(state),
        result.stop_reason,
        state.shots,
        engine.rays_cast,
        state.seconds,
        setup,
    )
