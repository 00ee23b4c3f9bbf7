"""From a scene and mesh settings to a solvable problem: repair, acceleration, mesh, form
factors (everything before the first shot), and after the solve, adaptive refinement and
the total error. Nothing here reads or writes a file.

>>> from raytrad.core.pipeline import prepare
>>> from raytrad.core.solver import solve
>>> from raytrad.scene.builtin import furnace_box
>>> with prepare(furnace_box(0.5, 1.0)) as problem:                   # doctest: +SKIP
...     result = solve(problem.mesh, problem.engine)
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import defaults, scene_extent, tol
from raytrad.core import compiled, stages
from raytrad.core.accuracy import (
    RAYS,
    SAMPLES,
    ErrorParts,
    conservation_error,
    discretisation_error,
)
from raytrad.core.adaptive import Refinement, RefineSettings, refine_adaptively
from raytrad.core.balance import COLUMN_SCALE_LIMIT
from raytrad.core.convergence import counted_receivers
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.hidden import hide_receivers
from raytrad.core.mesh import MeshSettings, RadiosityMesh, build_mesh
from raytrad.core.pairs import receiver_points
from raytrad.core.repair import repair_scene
from raytrad.core.solver import SolveResult, SolveSettings, check_solvable, filled_capture
from raytrad.core.visibility import Occluder, nothing_can_occlude, worker_count
from raytrad.errors import SolverError
from raytrad.scene import Scene, has_emission, triangle_areas_normals

log = logging.getLogger(__name__)

#: Seconds between the form-factor pass's progress lines.
PASS_LOG_SECONDS = 10.0

#: Columns finished after the first before the pass's progress line says how long is left
#: (a quarter of the pass, if that is fewer).
PASS_RATE_COLUMNS = 16

#: The balancing log line's words for ``form_factor_balance.stopped``.
_STOPPED = {
    "converged": "converged",
    "stalled": "stopped when they stalled: where nearly every receiver sees surfaces all "
    "round, its rows and columns cannot all hold",
    "rounds": "the most allowed",
}


@dataclass
class Prepared:
    """A scene made ready to solve: its repaired scene, mesh and form-factor engine.

    Attributes
    ----------
    scene : Scene
        The repaired scene the mesh was built from.
    mesh : RadiosityMesh
    engine : FormFactorEngine
        Every column computed, balanced and cached (within the cache budget).
    occluder : Occluder or None
        None when nothing in the scene can occlude (a convex enclosure): no rays at all.
    timings : dict of str to float
        Seconds spent in ``mesh``, ``acceleration`` and ``form_factors`` [s].
    closed_receivers : (R,) bool or None
        Receivers that see no opening (their form factors sum to 1).
    balance : dict
        What balancing did (:meth:`FormFactorEngine.balance`).
    """

    scene: Scene
    mesh: RadiosityMesh
    engine: FormFactorEngine
    occluder: Occluder | None
    timings: dict[str, float]
    closed_receivers: np.ndarray | None = None
    balance: dict[str, float | bool | str] = field(default_factory=dict)

    def close(self) -> None:
        """Release the thread pools and the acceleration structure."""
        self.engine.close()
        if self.occluder is not None:
            self.occluder.close()

    def __enter__(self) -> Prepared:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def new_engine(self) -> FormFactorEngine:
        """A fresh engine on the same mesh (no cached columns), closed rows normalised."""
        engine = FormFactorEngine(self.mesh, self.occluder, cache_bytes=self.engine.cache_bytes)
        engine.balance(self.closed_receivers)
        return engine


@contextmanager
def timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    """Add the seconds the body takes to ``timings[stage]``."""
    start = time.perf_counter()
    try:
        yield
    finally:
        timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


def prepare(
    scene: Scene,
    mesh_settings: MeshSettings | None = None,
    cache_mb: float = defaults.cache_mb,
    stop: Callable[[], bool] | None = None,
    columns: Mapping[str, Any] | None = None,
    on_column: Callable[[RadiosityMesh, FormFactorEngine], None] | None = None,
    balanced: tuple[Mapping[str, np.ndarray], dict[str, Any]] | None = None,
) -> Prepared:
    """Repair, mesh and balance ``scene``: everything before the first shot.

    Duplicate and inside-out faces are fixed (with warnings, :mod:`raytrad.core.repair`);
    no acceleration structure is built when nothing can occlude (a convex enclosure); every
    form-factor column is computed and balanced (:meth:`FormFactorEngine.balance`).

    Parameters
    ----------
    scene : Scene
    mesh_settings : MeshSettings
    cache_mb : float
        Memory for cached form-factor columns [MiB].
    stop : callable or None
        Polled during the form-factor pass (a time budget, Ctrl-C): True cuts it short
        (see :meth:`FormFactorEngine.balance`).
    columns : dict or None
        Columns of an earlier pass cut short (:meth:`FormFactorEngine.pass_columns`, from
        a checkpoint, its large arrays possibly left on disk: restored a column at a
        time): only the others are computed.
    on_column : callable or None
        ``on_column(mesh, engine)`` after each column the pass computes, in the calling
        thread (to checkpoint a long pass).
    balanced : (scales, summary) or None
        A finished pass's balanced scales and balancing's summary, from a checkpoint
        (:meth:`FormFactorEngine.balanced_scales`): no pass is traced, and a column is
        computed only when a shot asks for it.

    Raises
    ------
    SolverError
        The system has no finite solution (checked before any form factor is computed).
    """
    mesh_settings = mesh_settings or MeshSettings()
    timings: dict[str, float] = {}
    with timed(timings, "mesh"):
        scene = repair_scene(scene)
    if not has_emission(scene):  # after repair, which may have dropped the emitters
        log.warning("%s: the scene has no emitter; every radiosity is zero", scene.source)
    with timed(timings, "acceleration"):
        extent = scene_extent(scene.positions[unique(scene.triangles)])
        occluder = None
        if not nothing_can_occlude(scene.positions, scene.triangles, tol.plane * extent):
            occluder = Occluder(scene.positions, scene.triangles)
    with timed(timings, "mesh"):
        mesh = build_mesh(scene, mesh_settings, _enclosure_test(scene, occluder))
    check_solvable(mesh)  # a scene that cannot be solved fails before any compiling
    with timed(timings, "kernels"):  # compiled the first time: not the pass's time
        compiled.get()
        compiled.load_solver(worker_count())  # numba loads them here, not in the solve
    closed = None
    with timed(timings, "form_factors"):
        if occluder is not None:
            _, normals = triangle_areas_normals(scene.triangle_vertices())
            points, _ = receiver_points(mesh, tol.ray_offset * occluder.diagonal)
            closed, hidden = occluder.probe_hemispheres(
                points, mesh.receiver_normal, normals, scene.double_sided
            )
            mesh = hide_receivers(mesh, hidden)
        engine = FormFactorEngine(mesh, occluder, cache_bytes=int(cache_mb * (1 << 20)))
        if isinstance(stop, RunBudget):  # a time limit keeps back the time to save these
            stop.held(engine)
        if columns:
            log.info(
                "form factors: %d columns from the checkpoint", engine.restore_columns(columns)
            )
        if balanced is not None:
            engine.restore_balance(balanced[0])
            log.info("form factors: the balanced scales of the finished pass, from the checkpoint")
            return Prepared(scene, mesh, engine, occluder, timings, closed, dict(balanced[1]))
        progress = _pass_progress(column_weights(mesh, engine.pass_order()))

        def column_done(done: int, total: int) -> None:
            progress(done, total)
            stages.report(stages.FORM_FACTORS, done, total)
            if on_column is not None:
                on_column(mesh, engine)

        balance = engine.balance(closed, column_done, stop=stop)
    if balance["complete"]:
        log.info(
            "form factors balanced in %d rounds (%s): %d receivers that see surfaces all "
            "round have their factors summed to 1 (largest correction %.2e); %d patches "
            "whose factors sent out more than they shoot were scaled down (largest excess "
            "%.2e)",
            balance["iterations"],
            _STOPPED.get(str(balance["stopped"]), str(balance["stopped"])),
            balance["closed_rows"],
            balance["row_error"],
            balance["capped_columns"],
            balance["capture_excess"],
        )
    if balance.get("short_columns"):
        log.log(
            _short_level(mesh, engine.short_patches, float(balance["short_area"])),
            "%d patches (%.2g%% of the surface) deliver less than they shoot, %s%% of it "
            "at worst: surfaces face them from nearer than the receivers are spaced (a gap "
            "of millimetres, as between a table's top and legs that stop just short of it, "
            "or a light facing the ceiling it hangs under); balancing scales a patch's "
            "factors up by %.2f at most, and what they miss counts as escaped in the "
            "energy ledger",
            balance["short_columns"],
            100.0 * float(balance["short_area"]),
            _percent(100.0 * (1.0 - float(balance["column_deficit"]))),
            COLUMN_SCALE_LIMIT,
        )
    return Prepared(scene, mesh, engine, occluder, timings, closed, balance)


def _percent(value: float) -> str:
    """A percentage for the log: whole from 1 on, else two significant digits (a table
    leg's top under the table delivers 0.0012 % of what it shoots, not "0 %")."""
    return f"{value:.0f}" if value >= 1.0 else f"{value:.2g}"


#: The short patches' share of the surface (:meth:`FormFactorEngine.balance`) below which
#: they are logged as information, not warned of, unless one of them emits.
SHORT_AREA_WARNING = 1e-3


def _short_level(mesh: RadiosityMesh, short: np.ndarray, area: float) -> int:
    """The log level for patches balancing left short: a warning when they are at least
    :data:`SHORT_AREA_WARNING` of the surface or one emits (the light it loses is the
    scene's), else information (a table leg's top under the table, 0.08 % of a room)."""
    lit = bool((short & mesh.patch_emits()).any())
    return logging.WARNING if lit or area >= SHORT_AREA_WARNING else logging.INFO


#: How fast a checkpoint's columns are written, as :class:`RunBudget` plans for until the
#: run has measured its own (:meth:`RunBudget.measured`) [B/s]: 549 MB in 2.98 s (184
#: MB/s, spooled then zipped) and hashed for the manifest in 0.4 s on the reference
#: machine (2026-12-03; other saves there ran at 125 and 260 MB/s), rounded down.
SAVE_BYTES_PER_SECOND = 150e6


@dataclass
class RunBudget:
    """The whole run's time limit (``--time-limit``), polled by every stage: the
    form-factor pass, the solve and refinement. Calling it says whether to stop now: the
    time is spent, or ``stop`` (Ctrl-C) asks.

    The checkpoint a time-limited run writes after its solve holds every form-factor column
    so far (hundreds of MB at large sizes, seconds to write), so the budget keeps back the
    time to write the columns the pass's engine (:meth:`held`) holds, at
    :data:`SAVE_BYTES_PER_SECOND` or as fast as the run's own last pass checkpoint wrote
    (:meth:`measured`). A render drops them once they are saved and the pass
    was whole (:meth:`FormFactorEngine.release_columns`), which gives refinement the time
    back; a pass cut short keeps them, and refinement, with no time left anyway, is skipped.

    Attributes
    ----------
    seconds : float or None
        The budget from ``start`` [s]; None: no limit.
    stop : callable or None
        Another stop request, polled too.
    start : float
        ``time.perf_counter()`` when the run began [s].
    engine : FormFactorEngine or None
        The pass's engine, whose columns the checkpoint will hold (:meth:`held`).
    rate : float
        How fast they are planned to be written [B/s].
    """

    seconds: float | None
    stop: Callable[[], bool] | None = None
    start: float = field(default_factory=time.perf_counter)
    engine: FormFactorEngine | None = field(default=None, repr=False)
    rate: float = SAVE_BYTES_PER_SECOND

    def __call__(self) -> bool:
        spent = self.seconds is not None and self.elapsed() + self.reserve() >= self.seconds
        return spent or (self.stop is not None and self.stop())

    def cause(self) -> str:
        """What a True poll meant, for a warning: ``interrupted`` when ``stop`` asks (Ctrl-C,
        a signal), else ``time limit spent``."""
        return "interrupted" if self.stop is not None and self.stop() else "time limit spent"

    def elapsed(self) -> float:
        """Seconds since ``start`` [s]."""
        return time.perf_counter() - self.start

    def reserve(self) -> float:
        """Seconds kept back to write the held engine's columns (0 without one) [s]."""
        return 0.0 if self.engine is None else self.engine.held_bytes / self.rate

    def held(self, engine: FormFactorEngine) -> None:
        """Keep back the time to write ``engine``'s columns (a pass under way)."""
        self.engine = engine

    def measured(self, written: int, seconds: float) -> None:
        """A checkpoint of ``written`` bytes took ``seconds`` [B], [s]: plan the last one's
        writing at that rate (the manifest's hashing, about a tenth more, is not in it; a
        save under 64 MB, mostly the page cache's, says little of a larger one's)."""
        if written >= 1 << 26 and seconds > 0:
            self.rate = written / seconds

    def solve_settings(self, settings: SolveSettings, resumed_seconds: float) -> SolveSettings:
        """``settings`` with the solve's time limit set to what is left of the budget (the
        solver counts a resumed state's seconds too), the columns' writing kept back."""
        if self.seconds is None:
            return settings
        left = self.seconds - self.elapsed() - self.reserve()
        return dataclasses.replace(settings, time_limit=resumed_seconds + max(left, 1e-6))


def _pass_progress(weights: np.ndarray | None = None) -> Callable[[int, int], None]:
    """Logs the form-factor pass's progress and time left every :data:`PASS_LOG_SECONDS`
    (a log line, so that it shows in CI logs and batch runs, not only on a terminal).

    The rate is measured from the first column's end: the first column also pays for
    compiling the kernels on a first run (several seconds), which would inflate the
    estimate many times over. Columns finish in bursts (one a thread), so no time is
    promised until :data:`PASS_RATE_COLUMNS` more have finished: two columns finishing
    together would say "about 0 s left".

    ``weights`` ((total,), in the pass's order; None: all alike) weigh the columns done
    and left (:func:`column_weights`): the pass computes large patches first, which cost
    more, and by count alone the time left read 1.6-2.1 times the truth from a tenth to
    half of the default Cornell pass."""
    start = last = time.perf_counter()
    first = start
    done_weight = None if weights is None else np.concatenate([[0.0], np.cumsum(weights)])

    def report(done: int, total: int) -> None:
        nonlocal last, first
        now = time.perf_counter()
        if done == 1:
            first = now
        if now - last >= PASS_LOG_SECONDS and 1 < done < total:
            last = now
            if done - 1 < min(PASS_RATE_COLUMNS, total // 4):
                log.info(
                    "form factors: %d of %d columns done in %.0f s, time left not known yet",
                    done,
                    total,
                    now - start,
                )
                return
            weight = done_weight  # cumulative, or the count's where there is none
            if weight is None or len(weight) != total + 1:
                weight = np.arange(total + 1.0)
            spent = weight[done] - weight[1]  # the first column's is not timed
            left = (now - first) / spent * (weight[total] - weight[done])
            log.info(
                "form factors: %d of %d columns done in %.0f s, "
                "about %.0f s left to finish the pass",
                done,
                total,
                now - start,
                left,
            )

    return report


def column_weights(mesh: RadiosityMesh, order: np.ndarray) -> np.ndarray:
    """(P,) a guess of each column's cost in the pass's ``order`` for its progress line: 1
    plus the patch's triangles over their mean. The time left it gives from a tenth to
    half of the pass, against the truth (2026-12-03): 1.4-2.0 times it in a two-thread
    Cornell pass at 60 000 receivers (1.6-2.3 by count), 0.80-1.16 in the room of blocks
    at 20 000 (1.07-1.48); the early columns also cost more for reasons it misses."""
    triangles = np.bincount(mesh.triangle_patch, minlength=mesh.patch_count)[order]
    return 1.0 + triangles / max(float(triangles.mean()), 1e-300)


def refine_solution(
    prepared: Prepared,
    result: SolveResult,
    settings: RefineSettings,
    stop: Callable[[], bool] | None = None,
    start: Refinement | None = None,
) -> tuple[Prepared, SolveResult, Refinement]:
    """Adaptive refinement of a solve (:mod:`raytrad.core.adaptive`), going on from
    ``start`` (the rounds an earlier, stopped refinement of this solve made) if given.

    Returns
    -------
    baked : Prepared
        ``prepared`` with the refined mesh (``prepared`` itself when nothing was added;
        it shares the engine and occluder, so close only one of the two).
    result : SolveResult
        ``result`` with the refined mesh's radiosity.
    refinement : Refinement
    """
    refinement = refine_adaptively(
        prepared.scene,
        prepared.mesh,
        prepared.engine,
        prepared.occluder,
        result.radiosity,
        settings,
        stop,
        start,
    )
    if not refinement.added:
        return prepared, result, refinement
    if not np.isfinite(refinement.radiosity).all():
        raise SolverError(
            "refinement gathered non-finite radiosity: the scene's emission or reflectance "
            "overflows double precision"
        )
    baked = dataclasses.replace(prepared, mesh=refinement.mesh)
    return baked, dataclasses.replace(result, radiosity=refinement.radiosity), refinement


#: The fewest points of a quick residual check (:func:`error_samples`).
QUICK_POINTS = 64


def error_samples(receivers: int, quick: bool = False) -> tuple[int, int]:
    """Points and rays a point of the residual check for a bake of ``receivers``; ``quick``
    (a run whose time limit is spent, or interrupted, when the check starts) an eighth of
    the points, at least :data:`QUICK_POINTS`: the check took 1.2 s of a 20 s limit's
    22.9 s at 60 000 receivers, and such a run's error is its unfinished solve's.

    A quarter of the receivers, between 256 and :data:`~raytrad.core.accuracy.SAMPLES`
    points of :data:`~raytrad.core.accuracy.RAYS` rays, so that the check stays a small
    part of a small bake's cost; fewer points make the estimate noisier and, since
    standard errors are added, larger on average, not smaller. Where a quarter of the
    receivers passes twice that cap, the bake's error is small against the gather's noise
    at a point (0.35 % against 0.6 % in the Cornell box's default bake, whose estimate
    the noise then decided), so the same rays go to half the points, twice as many each.
    """
    points = receivers // 4
    if points >= 2 * SAMPLES:
        points, rays = SAMPLES // 2, 2 * RAYS
    else:
        points, rays = int(min(SAMPLES, max(256, points))), RAYS
    return (max(QUICK_POINTS, points // 8), rays) if quick else (points, rays)


def total_error(
    solved: Prepared,
    baked: Prepared,
    result: SolveResult,
    estimate: np.ndarray,
    quick: bool = False,
) -> ErrorParts:
    """The bake's total error and its parts (:mod:`raytrad.core.accuracy`).

    Parameters
    ----------
    solved : Prepared
        Holds the mesh that was solved.
    baked : Prepared
        Holds the (refined) mesh of ``result.radiosity``.
    result : SolveResult
    estimate : (3,) float64
        The solve's estimate of its remaining algebraic error at its end [1]
        (:func:`~raytrad.core.convergence.error_estimate`).
    quick : bool
        The run's time limit is spent: the residual check traces fewer points
        (:func:`error_samples`; noisier, and with its standard errors added, larger on
        average).
    """
    mesh = solved.mesh
    capture = filled_capture(result.state.captured, mesh.patch_area)
    samples, rays = error_samples(mesh.receiver_count, quick)
    residual = discretisation_error(
        baked.scene,
        baked.mesh,
        result.radiosity,
        counted_receivers(baked.mesh),
        float(mesh.patch_area @ capture / max(float(mesh.patch_area.sum()), 1e-300)),
        samples=samples,
        rays=rays,
    )
    return ErrorParts(
        algebraic=np.asarray(estimate, dtype=np.float64),
        discretisation=residual.error,
        conservation=conservation_error(solved.engine, mesh),
        samples=residual.samples,
        discretisation_standard_error=residual.standard_error,
    )


def _enclosure_test(scene: Scene, occluder: Occluder | None) -> Any:
    """``enclosed(points, normals) -> (N,) bool`` for :func:`build_mesh`, or None when
    nothing can occlude."""
    if occluder is None:
        return None
    _, normals = triangle_areas_normals(scene.triangle_vertices())

    def enclosed(points: np.ndarray, point_normals: np.ndarray) -> np.ndarray:
        return occluder.enclosed(points, point_normals, normals, scene.double_sided)

    return enclosed
