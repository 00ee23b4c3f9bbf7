"""The Python API: load -> prepare -> solve -> write, in one call (:func:`render`) or step
by step; ``docs/api.md`` has runnable examples. Each step lives in its own layer
(``docs/architecture.md``); this module only joins them. Its public names are re-exported
from :mod:`raytrad`.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from raytrad.core import pipeline
from raytrad.core.accuracy import ErrorParts
from raytrad.core.adaptive import Refinement
from raytrad.core.compare import compare_methods
from raytrad.core.convergence import ConvergenceMonitor, ErrorLog, Reference
from raytrad.core.pipeline import Prepared, RunBudget, timed
from raytrad.core.reference import automatic_reference, named_reference, reference_at_receivers
from raytrad.core.solver import SHOOTING_METHODS, SolveResult, SolverState
from raytrad.core.solver import solve as solve_system
from raytrad.core.stages import reporting as stage_progress  # noqa: F401 (for the CLI)
from raytrad.errors import RaytradError, SettingsError
from raytrad.formats.ply import read_radiosity_ply
from raytrad.outputs import resume as resuming
from raytrad.outputs import run_manifest
from raytrad.outputs.comparison import markdown_table, write_comparison
from raytrad.outputs.plot import plot_convergence
from raytrad.outputs.progress import RenderProgress, pass_hook, shot_hook
from raytrad.outputs.report import add_error_log, add_total_error, build_report, write_report
from raytrad.outputs.resume import checkpoint_path, fingerprint, resume_point
from raytrad.outputs.run_lock import RunLock
from raytrad.outputs.run_manifest import verify_outputs
from raytrad.outputs.write import check_output_range, write_outputs
from raytrad.products.framing import file_camera
from raytrad.products.lightmap import choose_lightmap_uvs
from raytrad.scene import Scene
from raytrad.scenefiles import SceneFile, load_scene_file
from raytrad.settings import RenderSettings, with_scene_defaults

log = logging.getLogger(__name__)

#: How a stopped solve ends; a run that ends so leaves a checkpoint to resume from.
RESUMABLE = ("interrupted", "time-limit", "max-shots")
StopPoll = Callable[[], bool] | None


@dataclass
class RenderOutcome:
    """What :func:`render` did and wrote.

    ``prepared.mesh`` and ``result.radiosity`` are those of the bake: the refined mesh
    and its radiosity when adaptive refinement added receivers.
    """

    result: SolveResult
    prepared: Prepared
    outputs: dict[str, Path]
    report: dict[str, Any]
    error_log: ErrorLog
    refinement: Refinement | None = None
    error: ErrorParts | None = None


def load(path: str | os.PathLike[str], settings: RenderSettings | None = None) -> SceneFile:
    """Read a scene file with what ``settings`` needs of it (lightmap UVs, cameras): the
    scene keeps the model's lightmap UVs only where the settings bake into them
    (:func:`~raytrad.products.lightmap.choose_lightmap_uvs`)."""
    settings = settings or RenderSettings()
    uv_set = settings.lightmap.uv_set_to_read if settings.lightmap else None
    loaded = load_scene_file(
        path, settings.scale, uv_set, settings.image is not None, settings.allow_outside_files
    )
    scene = choose_lightmap_uvs(loaded.scene, settings.lightmap)
    return SceneFile(scene, loaded.cameras, loaded.output, loaded.kind)


def prepare(
    scene: Scene,
    settings: RenderSettings | None = None,
    stop: StopPoll = None,
    columns: Any = None,
    on_column: Any = None,
    balanced: Any = None,
) -> Prepared:
    """Repair, mesh and balance ``scene`` (:func:`raytrad.core.pipeline.prepare`: ``stop``
    cuts the form-factor pass short, ``columns`` of an earlier one are reused, ``on_column``
    follows each column, a finished one's ``balanced`` scales stand in for it)."""
    s = settings or RenderSettings()
    return pipeline.prepare(scene, s.mesh, s.cache_mb, stop, columns, on_column, balanced)


def solve(
    prepared: Prepared,
    settings: RenderSettings | None = None,
    state: SolverState | None = None,
    stop: StopPoll = None,
) -> SolveResult:
    """Shoot until ``settings.solve`` says stop (:func:`raytrad.core.solver.solve`);
    ``state`` (``result.state`` of an earlier solve) continues it, ``stop`` ends it early."""
    settings = settings or RenderSettings()
    return solve_system(prepared.mesh, prepared.engine, settings.solve, state, None, stop)


def write(
    prepared: Prepared,
    result: SolveResult,
    output_dir: str | os.PathLike[str],
    settings: RenderSettings | None = None,
    stem: str = "scene",
) -> dict[str, Path]:
    """Write ``<stem>.ply`` and the outputs ``settings`` asks for (lightmap, image, glb)
    into ``output_dir`` atomically, then its run manifest; no report. Call it several times
    with other settings and folders to write several sets from one solve.

    Returns
    -------
    dict of str to Path, each file written by key (``ply``, ``lightmap``, ``manifest``...).
    """
    settings = with_scene_defaults(settings or RenderSettings(), {})
    output_dir = Path(output_dir)
    with RunLock(output_dir):
        outputs, _ = write_outputs(prepared, result, output_dir, stem, settings)
        stopped = {"solve": {"stop_reason": result.stop_reason}}
        outputs["manifest"] = run_manifest.write_manifest(output_dir, outputs, stopped)
    return outputs


def solve_scene(
    scene: Scene, settings: RenderSettings | None = None
) -> tuple[Prepared, SolveResult]:
    """Mesh and solve an in-memory scene; nothing is written (for batch jobs and tests)."""
    settings = settings or RenderSettings()
    prepared = prepare(scene, settings)
    try:
        result = solve_system(prepared.mesh, prepared.engine, settings.solve)
        prepared, result, _ = refine(prepared, result, settings)
    finally:
        prepared.close()
    return prepared, result


def refine(
    prepared: Prepared, result: SolveResult, settings: RenderSettings, stop: StopPoll = None
) -> tuple[Prepared, SolveResult, Refinement]:
    """Adaptive refinement: the refined copies of ``prepared`` and ``result``, and what was
    done (:func:`raytrad.core.pipeline.refine_solution`)."""
    return pipeline.refine_solution(prepared, result, settings.refine, stop)


def estimate_error(
    solved: Prepared, baked: Prepared, result: SolveResult, error_log: ErrorLog, quick: bool = False
) -> ErrorParts:
    """The bake's total error and its parts (:func:`raytrad.core.pipeline.total_error`):
    ``solved`` holds the mesh that was solved, ``baked`` the (refined) mesh of
    ``result.radiosity``; the algebraic part is the last estimate of ``error_log``;
    ``quick`` (the run's time limit spent): the check traces an eighth of its points."""
    estimate = [np.inf if v is None else v for v in error_log.as_dict()["estimate"][-1]]
    return pipeline.total_error(solved, baked, result, np.asarray(estimate), quick)


def make_reference(spec: str, prepared: Prepared) -> Reference:
    """A reference solution for the true-error log.

    Parameters
    ----------
    spec : str
        ``dense`` (direct solve of the same discrete system), ``analytic`` (B = E/(1-rho),
        closed scenes of uniform materials) or the path of a previous result PLY.

    Raises
    ------
    RaytradError
        When the reference does not apply to this scene.
    """
    if spec in ("dense", "analytic"):
        return named_reference(spec, prepared.mesh, prepared.engine, prepared.occluder is not None)
    positions, triangles, radiosity = read_radiosity_ply(spec)
    at_receivers = reference_at_receivers(positions, triangles, radiosity, prepared.mesh, spec)
    return Reference(at_receivers, "file", f"previous result {spec}")


def render(
    scene_path: str | os.PathLike[str],
    output_dir: str | os.PathLike[str],
    settings: RenderSettings | None = None,
    resume: bool | Literal["auto"] = False,
    progress: Callable[[RenderProgress], None] | None = None,
    stop: Callable[[], bool] | None = None,
    reference: str | None = None,
    plot: bool = False,
) -> RenderOutcome:
    """Load, mesh, solve and write ``<output_dir>/<stem>.ply``, ``report.json``, every
    output ``settings`` asks for, and last the run manifest.

    Parameters
    ----------
    scene_path : path-like
        OBJ (+MTL), glTF 2.0 (.gltf/.glb), PLY or TOML scene file.
    output_dir : path-like
        Created if missing; outputs replaced atomically; one run at a time (``RunLock``).
    settings : RenderSettings
        What it leaves at None the scene file's ``[output]`` gives (else the defaults).
    resume : bool or "auto"
        Continue from ``<output_dir>/<stem>.checkpoint.npz`` if it exists (refused, naming
        what changed, if made for another scene or other mesh settings; ``"auto"``, as
        batch jobs do, passes it over with a warning); ``report.json``'s ``"resumed"``.
    progress : callable or None
        ``progress(RenderProgress)`` after each shot.
    stop : callable or None
        Polled after each column of the pass, each shot and each patch of a refinement
        round; True stops there, writes the outputs so far and a checkpoint.
    reference : str or None
        Measure the true error against this reference (see :func:`make_reference`).
    plot : bool
        Also write ``convergence.png`` (error against time).

    Raises
    ------
    SceneError
        Bad scene file (nothing is written).
    """
    scene_path, output_dir = Path(scene_path), Path(output_dir)
    timings: dict[str, float] = {}
    start = time.perf_counter()
    with timed(timings, "load"):
        loaded = load(scene_path, settings)
    settings = with_scene_defaults(settings or RenderSettings(), loaded.output)
    budget = RunBudget(settings.solve.time_limit, stop, start)  # bounds the whole run
    camera = None
    if settings.image is not None:
        camera = file_camera(loaded.cameras, settings.image.view, scene_path, loaded.kind)
    with RunLock(output_dir):  # one run at a time in a folder
        key = fingerprint(loaded.scene, settings.system_settings())
        checkpoint = checkpoint_path(output_dir, scene_path.stem)
        point = resume_point(checkpoint, key, resume, settings.solve)
        if point.state is not None:  # its save planned at the rate the last one took
            budget.measured(*resuming.last_save(checkpoint))
        taken = resuming.resume_facts(point.state, point.columns, point.scales)  # before solve
        logs: list[ErrorLog] = []  # the solve's error log, saved with its state

        def save(state: SolverState, engine: Any = None, whole: bool = False) -> None:
            engine = engine or prepared.engine  # a pass's columns, a finished one's scales
            resuming.save_run(checkpoint, state, key, engine, whole, logs, lambda: prepared.balance)

        on_column = pass_hook(save, settings.checkpoint_seconds, budget.measured)  # saved too
        prepared = prepare(loaded.scene, settings, budget, point.columns, on_column, point.scales)
        timings.update(prepared.timings)

        try:
            ref = None
            if reference is not None:
                with timed(timings, "reference"):
                    ref = make_reference(reference, prepared)
            monitor = ConvergenceMonitor(prepared.mesh, prepared.engine, ref, point.history)
            logs.append(monitor.log)
            on_shot = shot_hook(monitor, progress, settings, save)
            with timed(timings, "solve"):
                limit = budget.solve_settings(settings.solve, getattr(point.state, "seconds", 0))
                result = solve_system(
                    prepared.mesh, prepared.engine, limit, point.state, on_shot, stop
                )
            error_log = monitor.finish(result.state)
            saved = result.stop_reason in RESUMABLE or budget.seconds is not None
            if saved and not resuming.unchanged(taken, result.state, prepared.mesh.patch_count):
                with timed(timings, "checkpoint"):  # hundreds of MB of columns at large sizes
                    save(result.state, whole=resuming.columns_kept(prepared.engine, result))
            prepared.engine.release_columns()  # refinement and the outputs need none
            check_output_range(result.radiosity, scene_path)
            solved, solution = prepared, result.radiosity
            rounds = resuming.kept_refinement(checkpoint, key, solution) if point.state else None
            taken = resuming.taken_rounds(taken, rounds, settings.refine)
            with timed(timings, "refine"):
                baked, result, refinement = pipeline.refine_solution(
                    prepared, result, settings.refine, budget, rounds
                )
            with timed(timings, "error"):
                error = estimate_error(solved, baked, result, error_log, budget())
            with timed(timings, "write"):
                stem = scene_path.stem
                outputs, facts = write_outputs(baked, result, output_dir, stem, settings, camera)
                if plot:
                    outputs["plot"] = output_dir / "convergence.png"
                    plot_convergence(outputs["plot"], {result.method: error_log}, str(scene_path))
            if refinement.stopped and stop is not None and stop():  # Ctrl-C while refining
                result = replace(result, stop_reason="interrupted")
            if refinement.stopped and not saved:  # no time limit: the columns are released
                save(result.state)  # the solved state, its rounds beside it (README: resume)
            keep = refinement.stopped or (saved and result.stop_reason in RESUMABLE)
            outputs |= resuming.keep_checkpoint(checkpoint, keep, refinement, key, solution)
            report = build_report(scene_path, baked, result, settings, timings, outputs)
            report |= {"outputs_detail": facts, "resumed": taken}
            add_error_log(report, error_log, ref)
            add_total_error(report, error_log, error, refinement, solved.mesh.receiver_count)
            write_report(outputs.setdefault("report", output_dir / "report.json"), report)
            made = run_manifest.content_key(loaded, settings)  # the manifest goes last
            outputs["manifest"] = run_manifest.write_manifest(output_dir, outputs, report, made)
        finally:
            prepared.close()
    return RenderOutcome(result, baked, outputs, report, error_log, refinement, error)


def outputs_current(
    scene_path: str | os.PathLike[str],
    output_dir: str | os.PathLike[str],
    settings: RenderSettings | None = None,
) -> bool:
    """Whether ``output_dir`` holds a complete render of ``scene_path`` with ``settings``
    by this raytrad version: the set verifies (:func:`verify_outputs`), its run was not
    interrupted, and its manifest holds the :func:`~raytrad.outputs.run_manifest.content_key`
    of the scene as it loads now. ``raytrad bake`` skips such jobs.

    Raises
    ------
    SceneError
        The scene cannot be read (so a broken scene fails even beside old outputs).
    """
    if (key := run_manifest.complete_set_key(output_dir)) is None:
        return False
    loaded = load(scene_path, settings)
    resolved = with_scene_defaults(settings or RenderSettings(), loaded.output)
    return key == run_manifest.content_key(loaded, resolved)


def compare(
    scene_path: str | os.PathLike[str],
    output_dir: str | os.PathLike[str],
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
        Keys of :data:`raytrad.core.solver.SHOOTING_METHODS`.
    settings : RenderSettings
        Mesh and stopping rules shared by all runs (its method is ignored).
    reference : str or None
        As ``raytrad render --reference``; None computes one: a dense solve when it fits
        in memory, else a long converged run (the result says which).

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
    for method in methods:
        settings.check_method(method)
    scene_path, output_dir = Path(scene_path), Path(output_dir)
    prepared = prepare(load(scene_path, settings).scene, settings)
    try:
        if reference:
            ref = make_reference(reference, prepared)
        else:
            ref = automatic_reference(prepared.mesh, prepared.engine, settings.solve.tolerance)
        runs, summary = compare_methods(prepared, settings.solve, methods, ref, str(scene_path))
    finally:
        prepared.close()
    write_comparison(output_dir, summary, runs, str(scene_path))
    return summary


def comparison_table(summary: dict[str, Any]) -> str:
    """The Markdown table of a :func:`compare` summary."""
    return markdown_table(summary["table"])


__all__ = [
    "Prepared",
    "RaytradError",
    "RenderOutcome",
    "RenderProgress",
    "compare",
    "comparison_table",
    "load",
    "make_reference",
    "outputs_current",
    "prepare",
    "render",
    "solve",
    "solve_scene",
    "verify_outputs",
    "write",
]
