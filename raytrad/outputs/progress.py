"""What a running render reports after each shot, and the solver hook that reports it
(logging the error estimate, extrapolating the time left, checkpointing periodically);
the form-factor pass's hook that checkpoints a long pass."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from raytrad.core.convergence import ConvergenceMonitor, ResidualTrend
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.solver import SolverState, new_state
from raytrad.settings import RenderSettings


@dataclass(frozen=True)
class RenderProgress:
    """What a running solve reports after each shot.

    Attributes
    ----------
    shots : int
    seconds : float
        Solve time so far [s].
    rays : int
        Visibility rays cast so far.
    residual : float
        Unshot power over emitted power [1].
    estimate : float
        Predicted relative RMS error still to come [1] (inf before the first estimate).
    eta : float
        Extrapolated seconds to the tolerance [s]; inf while unknown.
    """

    shots: int
    seconds: float
    rays: int
    residual: float
    estimate: float
    eta: float


def shot_hook(
    monitor: ConvergenceMonitor,
    progress: Callable[[RenderProgress], None] | None,
    settings: RenderSettings,
    save: Callable[[SolverState], None],
) -> Callable[[SolverState, float], None]:
    """The solver's per-shot hook: log the error, report progress, checkpoint periodically."""
    trend = ResidualTrend(settings.solve.tolerance)
    last_save = [time.perf_counter()]

    def on_shot(state: SolverState, residual: float) -> None:
        monitor(state, residual)
        if progress is not None:
            eta = trend.add(state.seconds, residual)
            estimate = monitor.latest_estimate
            progress(
                RenderProgress(state.shots, state.seconds, state.rays, residual, estimate, eta)
            )
        if time.perf_counter() - last_save[0] >= settings.checkpoint_seconds:
            save(state)
            last_save[0] = time.perf_counter()

    return on_shot


def pass_hook(
    save: Callable[[SolverState, FormFactorEngine], None],
    seconds: float,
    measured: Callable[[int, float], None] | None = None,
) -> Callable[[RadiosityMesh, FormFactorEngine], None]:
    """The form-factor pass's per-column hook: every ``seconds``, ``save`` the state before
    any shot with the engine (whose columns so far go into the checkpoint), so that a run
    killed during a long pass resumes it instead of starting over.

    The checkpoint holds every column so far, so it grows with the pass: the next save
    waits at least :data:`SAVE_SHARE` times as long as the last one took (at 300 000
    receivers a save writes gigabytes). ``measured(bytes, seconds)`` is told what each
    save wrote and took (:meth:`raytrad.core.pipeline.RunBudget.measured`)."""
    last_save = [time.perf_counter()]
    wait = [seconds]

    def on_column(mesh: RadiosityMesh, engine: FormFactorEngine) -> None:
        if time.perf_counter() - last_save[0] >= wait[0]:
            start = time.perf_counter()
            save(new_state(mesh), engine)
            last_save[0] = time.perf_counter()
            wait[0] = max(seconds, SAVE_SHARE * (last_save[0] - start))
            if measured is not None:
                measured(engine.held_bytes, last_save[0] - start)

    return on_column


#: A pass checkpoint waits at least this many times the last save's duration: saving
#: costs at most about a tenth of the pass.
SAVE_SHARE = 9.0
