"""``report.json``: the settings, statistics, timings, solve summary, energy ledger and
error log of a run (schema: ``docs/report.schema.json``, fields: ``docs/report.md``).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from raytrad import __version__
from raytrad.core.accuracy import ErrorParts, total_error_column
from raytrad.core.adaptive import Refinement
from raytrad.core.convergence import ErrorLog, Reference
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolveResult
from raytrad.core.visibility import Occluder
from raytrad.formats.atomic import atomic_write
from raytrad.settings import RenderSettings

#: The error columns whose last value is the run's error summary (``report["error"]``).
ERROR_COLUMNS = ("estimate", "bound_rms", "bound_max", "true_rms", "true_max")


def build_report(
    scene_path: Path,
    prepared: Prepared,
    result: SolveResult,
    settings: RenderSettings,
    timings: dict[str, float],
    outputs: dict[str, Path],
) -> dict[str, Any]:
    """The JSON-ready summary of a render: settings, statistics, timings, energy ledger."""
    mesh, state = prepared.mesh, result.state
    rays = prepared.engine.rays_cast  # this run's rays, the form-factor pre-pass included
    tracing = state.seconds + timings.get("form_factors", 0.0)
    rays_per_second = rays / tracing if tracing > 0 else 0.0
    return {
        "raytrad_version": __version__,
        "scene": str(scene_path),
        "settings": {
            "mesh": dataclasses.asdict(settings.mesh),
            "solve": dataclasses.asdict(settings.solve),
            "refine": dataclasses.asdict(settings.refine),
            "scale": settings.scale,
            "exposure": settings.exposure,
            "cache_mb": settings.cache_mb,
            "lightmap": None
            if settings.lightmap is None
            else dataclasses.asdict(settings.lightmap),
            "image": None if settings.image is None else dataclasses.asdict(settings.image),
            "gltf": settings.gltf,
        },
        "statistics": {
            "scene_triangles": prepared.scene.triangle_count,
            "triangles": len(mesh.triangles),
            "receivers": mesh.receiver_count,
            "patches": mesh.patch_count,
            "subareas": mesh.subarea_count,
            "occlusion_tested": prepared.occluder is not None,
            "ray_queries": _ray_queries(prepared.occluder),
            "form_factor_balance": prepared.balance,
        },
        "timings_seconds": timings,
        "solve": {
            "method": result.method,
            "stop_reason": result.stop_reason,
            "shots": state.shots,
            "rays": rays,
            "rays_naive": prepared.engine.rays_naive,
            "rays_per_second": rays_per_second,
            "form_factor_columns": prepared.engine.columns_computed,
            "columns_spilled": prepared.engine.columns_spilled,
            "residual": result.residual,
            "seconds": state.seconds,
            "ambient_gain": state.ambient_gain,
            "divergence_damped": state.damping_events,
        },
        "energy_watts": {
            "emitted": result.emitted_power.tolist(),
            "absorbed": state.absorbed.tolist(),
            "escaped": state.escaped.tolist(),
            "unshot": result.unshot_power.tolist(),
        },
        "outputs": {k: str(v) for k, v in outputs.items()},
    }


def _ray_queries(occluder: Occluder | None) -> str:
    """How the run's rays were traced (``statistics.ray_queries``)."""
    if occluder is None:
        return "none"
    return "packets" if occluder.packets else "embreex"


def add_error_log(
    report: dict[str, Any], error_log: ErrorLog, reference: Reference | None
) -> dict[str, Any]:
    """``report`` with the reference used, the error log and the final errors added."""
    report["reference"] = (
        None
        if reference is None
        else {"kind": reference.kind, "description": reference.description}
    )
    columns = error_log.as_dict()  # non-finite values become null (strict JSON)
    report["convergence"] = columns
    report["error"] = {
        name: (columns[name][-1] if columns[name] else None) for name in ERROR_COLUMNS
    }
    return report


def add_total_error(
    report: dict[str, Any],
    error_log: ErrorLog,
    error: ErrorParts,
    refinement: Refinement,
    solved_receivers: int,
) -> dict[str, Any]:
    """``report`` with the total error (``error.total_rms``, its parts and which one
    dominates), its column in the error log, and what adaptive refinement did."""
    report["convergence"]["total_rms"] = _strict(total_error_column(error_log.bound_rms, error))
    report["error"]["total_rms"] = _strict(error.total.tolist())
    report["error"]["parts"] = {
        "algebraic": _strict(error.algebraic.tolist()),
        "discretisation": _strict(error.discretisation.tolist()),
        "conservation": _strict(error.conservation.tolist()),
    }
    report["error"]["dominant"] = error.dominant
    report["error"]["samples"] = error.samples
    standard_error = error.discretisation_standard_error.tolist()
    report["error"]["discretisation_standard_error"] = _strict(standard_error)
    report["refinement"] = {
        "receivers_solved": solved_receivers,
        "receivers_added": refinement.added,
        "rounds": refinement.rounds,
        "receivers_interpolated": refinement.interpolated,
        "by_object": refinement.by_object,
        "change_rms": refinement.change_rms.tolist(),
        "rays": refinement.rays,
        "rays_naive": refinement.rays_naive,
        "stopped": refinement.stopped,
    }
    return report


def _strict(values: Any) -> Any:
    """Nested lists of floats with non-finite values as None (strict JSON)."""
    if isinstance(values, list):
        return [_strict(v) for v in values]
    if isinstance(values, float | np.floating) and not math.isfinite(values):
        return None
    return values


def write_report(path: Path, report: dict[str, Any]) -> None:
    """Write ``report`` as strict JSON (no NaN), atomically."""
    with atomic_write(path, "w") as handle:
        json.dump(report, handle, indent=2, allow_nan=False)
