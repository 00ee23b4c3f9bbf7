"""Running several shooting methods on one prepared problem, each logged against the same
reference, for ``raytrad compare``.

Every method shoots through the same vertex-to-patch form factors, so all share the one
form-factor pass of ``prepare`` (its columns stay cached): no ray is traced twice. Each
method's times to an error level include that pass's seconds (``setup_seconds``), since
each would need it alone.
"""

from __future__ import annotations

import logging
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

        Times include the shared form-factor pass (``setup_seconds``), which each method
        needs; ``rays`` are that pass's.
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
    """Solve ``prepared`` with ``method`` through its (shared, cached) form factors,
    logging the true error."""
    mesh, engine = prepared.mesh, prepared.engine
    setup = prepared.timings.get("form_factors", 0.0)
    monitor = ConvergenceMonitor(mesh, engine, ref)
    result = solve(mesh, engine, replace(settings, method=method), progress=monitor)
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


def compare_methods(
    prepared: Prepared, settings: SolveSettings, methods: list[str], ref: Reference, scene: str
) -> tuple[list[MethodRun], dict[str, Any]]:
    """Run each of ``methods`` on ``prepared`` against ``ref``: the runs, and the summary
    ``raytrad compare`` writes as compare.json (the table and every error log)."""
    runs = [run_method(prepared, settings, method, ref) for method in methods]
    summary = {
        "scene": scene,
        "receivers": prepared.mesh.receiver_count,
        "patches": prepared.mesh.patch_count,
        "reference": {"kind": ref.kind, "description": ref.description},
        "tolerance": settings.tolerance,
        "table": [run.row() for run in runs],
        "logs": {run.method: run.log.as_dict() for run in runs},
    }
    return runs, summary
