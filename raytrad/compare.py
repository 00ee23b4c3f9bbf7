"""``raytrad compare``: every solver method on the same receivers, error against time.

Each method gets its own form-factor engine (nothing is shared between the timed runs, so
each pays for its own ray tracing), the same mesh and the same reference.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from raytrad import reference as references
from raytrad.api import Prepared, RenderSettings, make_reference, prepare
from raytrad.convergence import ConvergenceMonitor, ErrorLog, Reference
from raytrad.errors import SettingsError
from raytrad.io.atomic import atomic_write
from raytrad.io.loaders import load_scene
from raytrad.solver import SHOOTING_METHODS, SolveSettings, solve

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


def automatic_reference(prepared: Prepared, settings: RenderSettings) -> Reference:
    """A dense solve when it fits in memory, else a long converged ambient run."""
    mesh = prepared.mesh
    size = mesh.patch_count * mesh.receiver_count
    if mesh.patch_count <= references.DENSE_PATCH_LIMIT and size <= references.DENSE_SIZE_LIMIT:
        return make_reference("dense", prepared)
    tolerance = min(1e-6, settings.solve.tolerance * 1e-2)
    result = solve(mesh, prepared.engine, SolveSettings("ambient", tolerance=tolerance))
    return Reference(
        result.radiosity,
        "converged",
        f"ambient solve of the same system to a residual of {result.residual:.1e} "
        "(too large for a dense solve)",
    )


def compare(
    scene_path: str | Path,
    output_dir: str | Path,
    methods: list[str],
    settings: RenderSettings | None = None,
    reference: str | None = None,
) -> dict[str, Any]:
    """Run each method on ``scene_path`` and write compare.json, compare.md, compare.png.

    Parameters
    ----------
    scene_path : path-like
    output_dir : path-like
    methods : list of str
        Keys of :data:`raytrad.solver.SHOOTING_METHODS`.
    settings : RenderSettings
        Mesh and stopping rules shared by all runs (its method is ignored).
    reference : str or None
        As ``raytrad render --reference``; None computes one (and the result says which).

    Returns
    -------
    dict, the content of compare.json.
    """
    settings = settings or RenderSettings()
    unknown = [m for m in methods if m not in SHOOTING_METHODS]
    if unknown or not methods:
        raise SettingsError(
            f"unknown method(s) {', '.join(unknown) or '(none)'}; "
            f"choose from {', '.join(SHOOTING_METHODS)}"
        )
    scene_path, output_dir = Path(scene_path), Path(output_dir)
    scene = load_scene(scene_path, scale=settings.scale)
    prepared = prepare(scene, settings)
    try:
        ref = (
            make_reference(reference, prepared)
            if reference
            else automatic_reference(prepared, settings)
        )
        runs = [_run(prepared, settings, method, ref) for method in methods]
    finally:
        prepared.close()
    summary = {
        "scene": str(scene_path),
        "receivers": prepared.mesh.receiver_count,
        "patches": prepared.mesh.patch_count,
        "reference": {"kind": ref.kind, "description": ref.description},
        "tolerance": settings.solve.tolerance,
        "table": [run.row() for run in runs],
        "logs": {run.method: run.log.as_dict() for run in runs},
    }
    _write(output_dir, summary, runs, str(scene_path))
    return summary


def _run(prepared: Prepared, settings: RenderSettings, method: str, ref: Reference) -> MethodRun:
    mesh = prepared.mesh
    start = time.perf_counter()
    engine = prepared.new_engine()
    setup = time.perf_counter() - start
    monitor = ConvergenceMonitor(mesh, engine, ref)
    try:
        result = solve(mesh, engine, replace(settings.solve, method=method), progress=monitor)
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


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The comparison table in Markdown."""

    def cell(value: Any, digits: str) -> str:
        if value is None:
            return "not reached"
        return format(value, digits)

    head = ["method"]
    for level in LEVELS:
        head += [f"s to {level:g}", f"shots to {level:g}"]
    head += ["final error", "shots", "rays", "seconds", "stop"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["method"]]
        for level in LEVELS:
            cells += [cell(r[f"seconds_to_{level:g}"], ".2f"), cell(r[f"shots_to_{level:g}"], "d")]
        cells += [
            cell(r["final_true_rms"], ".2e"),
            str(r["shots"]),
            str(r["rays"]),
            f"{r['seconds']:.2f}",
            r["stop_reason"],
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _write(output_dir: Path, summary: dict[str, Any], runs: list[MethodRun], title: str) -> None:
    from raytrad.plot import plot_convergence

    with atomic_write(output_dir / "compare.json", "w") as handle:
        json.dump(summary, handle, indent=2, default=_json_default, allow_nan=False)
    text = (
        f"# Method comparison: {summary['scene']}\n\n"
        f"{summary['receivers']} receivers, {summary['patches']} patches; true error "
        f"against the {summary['reference']['kind']} reference "
        f"({summary['reference']['description']}), relative RMS, worst channel.\n\n"
        + markdown_table(summary["table"])
    )
    with atomic_write(output_dir / "compare.md", "w") as handle:
        handle.write(text)
    plot_convergence(output_dir / "compare.png", {r.method: r.log for r in runs}, title)


def _json_default(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
