"""One bake job, run where a pool or a Dask worker puts it: skip it, render it, or say why
it failed.

:func:`run_job` never raises for a fault of the job's own (a missing scene, bad settings,
an internal error): it returns a :class:`JobResult` saying so, and whether trying again
could help. Only a lost process (a killed worker) reaches the caller as an exception.
"""

from __future__ import annotations

import json
import logging
import math
import os
import signal
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

from raytrad import api
from raytrad.core.visibility import THREADS_VARIABLE
from raytrad.outputs.run_lock import HEARTBEAT_SECONDS, LOCK, STALE_SECONDS, FolderLocked
from raytrad.outputs.run_manifest import MANIFEST, read_manifest
from raytrad.settings import RenderSettings

log = logging.getLogger(__name__)

#: The convergence plot's file name (``plot = true``).
PLOT = "convergence.png"
#: Seconds between tries at a folder locked from another host.
LOCK_POLL_SECONDS = 10.0
#: What became of a job.
STATUSES = ("done", "skipped", "failed", "interrupted", "not run")


@dataclass(frozen=True)
class Job:
    """A render to do: ``scene`` into ``output`` with ``settings`` (picklable, so it can be
    sent to another process or a Dask worker).

    Attributes
    ----------
    name : str
        Names the job in messages and the summary.
    scene : Path
    output : Path
        The job's own output folder.
    settings : RenderSettings
    plot : bool
        Also write ``convergence.png``.
    """

    name: str
    scene: Path
    output: Path
    settings: RenderSettings = field(default_factory=RenderSettings)
    plot: bool = False


@dataclass
class JobResult:
    """What became of one job.

    Attributes
    ----------
    name : str
    status : str
        ``done`` (rendered), ``skipped`` (outputs up to date),
        ``failed``, ``interrupted`` (stopped by a signal; its checkpoint resumes it) or
        ``not run`` (the bake stopped first).
    seconds : float
        Wall time of the last attempt [s].
    attempts : int
        Times it was started (retries included; a Dask task rescheduled after a lost
        worker counts once).
    error : float or None
        The bake's estimated total error (relative RMS against the physical answer,
        worst channel), else the solve's error estimate; None if unknown.
    stop_reason : str or None
        How the solve ended (``converged``, ``time-limit``...).
    outputs : list of str
        Files written, relative to the output folder.
    message : str
        Why it failed, in one line; empty otherwise.
    retry : bool
        Whether trying again could help (False for faults of the input).
    resumed : bool
        The last attempt continued from a checkpoint.
    recovered : bool
        The last attempt found the folder's lock of a run that was lost (a killed worker,
        its task started again here) and took the folder over.
    """

    name: str
    status: str
    seconds: float = 0.0
    attempts: int = 0
    error: float | None = None
    stop_reason: str | None = None
    outputs: list[str] = field(default_factory=list)
    message: str = ""
    retry: bool = False
    resumed: bool = False
    recovered: bool = False

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class _StopOnSignal:
    """In a job's own process (:mod:`raytrad.batch.worker`): SIGTERM or SIGINT asks the
    running render to stop cleanly (it writes its outputs so far and a checkpoint), as
    ``raytrad render`` does."""

    requested = False

    @classmethod
    def handler(cls, signum: int, frame: FrameType | None) -> None:
        cls.requested = True

    @classmethod
    def poll(cls) -> bool:
        return cls.requested


def log_to_stderr() -> None:
    """In a worker process that has no logging set up: warnings to stderr, as the command
    line prints them."""
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.WARNING, format="raytrad: %(levelname)s: %(message)s")
        logging.getLogger("trimesh").setLevel(logging.ERROR)


def init_worker() -> None:
    """Set up a job's own process: warnings to stderr, clean stop on SIGTERM and SIGINT
    (its threads come in its environment, :data:`THREADS_VARIABLE`)."""
    log_to_stderr()
    for name in ("SIGTERM", "SIGINT"):
        signal.signal(getattr(signal, name), _StopOnSignal.handler)


def run_job(job: Job, threads: int | None = None) -> JobResult:
    """Render ``job`` unless its outputs are up to date; resume from its checkpoint when
    one matches.

    Parameters
    ----------
    job : Job
    threads : int or None
        Threads for the render (None: as already set, else every core).

    Returns
    -------
    JobResult
        ``failed`` with a one-line message for faults of the job; ``retry`` is False when
        the input is at fault (a missing or broken scene, bad settings).
    """
    if threads is not None:
        os.environ[THREADS_VARIABLE] = str(max(1, threads))
    start = time.perf_counter()

    def result(status: str, **facts: Any) -> JobResult:
        return JobResult(job.name, status, time.perf_counter() - start, 1, **facts)

    try:
        if _current(job):
            return result("skipped", **_previous(job.output))
        resumed = any(Path(job.output).glob("*.checkpoint.npz"))
        recovered = (Path(job.output) / LOCK).exists()
        outcome = _render(job)
    except api.RaytradError as exc:
        return result("failed", message=str(exc), retry=False)
    except MemoryError:
        return result("failed", message=f"{job.scene}: out of memory", retry=True)
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        return result("failed", message=f"{where}{exc.strerror or exc}", retry=True)
    except Exception as exc:  # a fault of raytrad's own: one line, trying again may help
        log.debug("job %s failed", job.name, exc_info=True)
        text = " ".join(str(exc).split())[:200]
        return result(
            "failed",
            message=f"{job.scene}: internal error ({type(exc).__name__}: {text})",
            retry=True,
        )
    stop_reason = outcome.result.stop_reason
    return result(
        "interrupted" if stop_reason == "interrupted" else "done",
        error=_error(outcome.report),
        stop_reason=stop_reason,
        outputs=sorted(p.name for p in outcome.outputs.values()),
        resumed=resumed,
        recovered=recovered,
    )


def _current(job: Job) -> bool:
    """The job's folder holds its outputs: a current set, with the plot if it asks for
    one (the plot is an output of the run, not of the settings)."""
    if not api.outputs_current(job.scene, job.output, job.settings):
        return False
    return not job.plot or PLOT in (read_manifest(job.output) or {}).get("files", {})


def _render(job: Job) -> api.RenderOutcome:
    """Render ``job``, resuming from a matching checkpoint. A lock held on another host
    (a worker lost there, its task rescheduled here) is waited out until its heartbeat
    has been silent for :data:`~raytrad.outputs.run_lock.STALE_SECONDS`."""
    deadline = time.monotonic() + STALE_SECONDS + 2 * HEARTBEAT_SECONDS
    while True:
        try:
            return api.render(
                job.scene,
                job.output,
                job.settings,
                resume="auto",
                stop=_StopOnSignal.poll,
                plot=job.plot,
            )
        except FolderLocked as exc:
            if not exc.elsewhere or time.monotonic() > deadline or _StopOnSignal.poll():
                raise
            log.warning("%s; waiting for its heartbeat to stop", exc)
            time.sleep(LOCK_POLL_SECONDS)


def _error(report: dict[str, Any]) -> float | None:
    """The worst channel of the total error, else of the solve's estimate."""
    error = report.get("error") or {}
    for key in ("total_rms", "estimate"):
        values = [v for v in error.get(key) or [] if v is not None and math.isfinite(v)]
        if values:
            return float(max(values))
    return None


def _previous(output: Path) -> dict[str, Any]:
    """What the run that made ``output``'s current set reached, and the set's files."""
    manifest = read_manifest(output) or {}
    try:
        report = json.loads((Path(output) / "report.json").read_text())
    except (OSError, ValueError):
        report = {}
    return {
        "error": _error(report),
        "stop_reason": manifest.get("stop_reason"),
        "outputs": sorted([*manifest.get("files", {}), MANIFEST]),
    }
