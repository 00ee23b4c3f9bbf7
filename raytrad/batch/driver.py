"""Running a list of jobs on a runner: at most ``runner.slots`` at once, failed ones retried
a bounded number of times, lost ones (a killed worker process) retried too.

A runner is where jobs run: :class:`raytrad.batch.pool.LocalPool` (processes on this
machine, the default) or :class:`raytrad.batch.dask.DaskRunner` (a Dask cluster). The
driver itself is the same for both.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import Any, Protocol

from raytrad.batch.jobs import Job, JobResult

log = logging.getLogger(__name__)


class Runner(Protocol):
    """Where jobs run."""

    #: How the runner is set up, for the summary ("local pool: 2 processes, 1 thread each").
    description: str
    #: Jobs in flight at once.
    slots: int

    def submit(self, job: Job) -> Any:
        """Start ``job``; return a handle :meth:`wait` reports on."""

    def wait(self, handles: Collection[Any]) -> list[tuple[Any, JobResult | BaseException]]:
        """Handles that finished within a short while (possibly none), each with its
        result or the exception that lost it (a killed worker)."""

    def interrupt(self) -> None:
        """Ask running jobs to stop cleanly (they save a checkpoint where they can)."""

    def close(self) -> None:
        """Release processes and connections."""

    def abort(self) -> None:
        """Stop the running jobs at once (killed) and release everything."""


def bake(
    jobs: Sequence[Job],
    runner: Runner,
    retries: int = 2,
    on_result: Callable[[JobResult], None] | None = None,
    stop: Callable[[], bool] | None = None,
) -> list[JobResult]:
    """Run ``jobs`` on ``runner``; their results in the jobs' order.

    Parameters
    ----------
    jobs : sequence of Job
        With distinct names and distinct output folders.
    runner : LocalPool or DaskRunner
        Where the jobs run: :class:`~raytrad.batch.pool.LocalPool` (processes on this
        machine) or :class:`~raytrad.batch.dask.DaskRunner` (a Dask cluster), or anything
        with the :class:`Runner` methods. Ctrl-C while waiting aborts the running jobs
        (they keep their last periodic checkpoint); another exception asks them to stop
        cleanly and closes the runner; both propagate.
    retries : int
        Further attempts for a job that failed in a way trying again could help (an
        internal error, a full disk, a lost worker); a missing or broken scene is not
        retried. A retry resumes from the job's checkpoint.
    on_result : callable or None
        Called with each job's final result as it comes.
    stop : callable or None
        Polled while waiting; True interrupts the running jobs (they save checkpoints)
        and starts no more: those left are ``not run``.

    Raises
    ------
    ValueError
        ``retries`` < 0, or two jobs with one name or one output folder.
    """
    if retries < 0:
        raise ValueError(f"retries must be >= 0, got {retries}")
    folders = [Path(job.output).resolve() for job in jobs]  # out/a and ./out/a are one
    for what, values in (("name", [job.name for job in jobs]), ("output", folders)):
        if len(set(values)) < len(values):
            raise ValueError(f"two jobs have the same {what}; each job needs its own")
    try:
        return _run(jobs, runner, retries, on_result, stop)
    except KeyboardInterrupt:  # Ctrl-C in a script, or a second one at the command line
        runner.abort()
        raise
    except BaseException:
        runner.interrupt()
        runner.close()
        raise


def _run(
    jobs: Sequence[Job],
    runner: Runner,
    retries: int,
    on_result: Callable[[JobResult], None] | None,
    stop: Callable[[], bool] | None,
) -> list[JobResult]:
    queue = deque(jobs)
    attempts = {job.name: 0 for job in jobs}
    running: dict[Any, Job] = {}
    results: dict[str, JobResult] = {}
    stopping = False

    def finish(result: JobResult) -> None:
        results[result.name] = result
        if on_result is not None:
            on_result(result)

    while queue or running:
        if not stopping and stop is not None and stop():
            stopping = True
            runner.interrupt()
            while queue:
                finish(JobResult(queue.popleft().name, "not run", message="the bake stopped"))
        while queue and len(running) < runner.slots:
            job = queue.popleft()
            attempts[job.name] += 1
            running[runner.submit(job)] = job
        for handle, outcome in runner.wait(running):
            job = running.pop(handle)
            result = _result(job, outcome)
            result.attempts = attempts[job.name]
            if (
                result.status == "failed"
                and result.retry
                and attempts[job.name] <= retries
                and not stopping
            ):
                log.warning(
                    "%s: %s; trying again (attempt %d of %d)",
                    job.name,
                    result.message,
                    attempts[job.name] + 1,
                    retries + 1,
                )
                queue.append(job)
                continue
            finish(result)
    return [results[job.name] for job in jobs]


def _result(job: Job, outcome: JobResult | BaseException) -> JobResult:
    if isinstance(outcome, JobResult):
        return outcome
    text = " ".join(str(outcome).split())[:200]
    return JobResult(
        job.name,
        "failed",
        message=f"worker lost ({type(outcome).__name__}{': ' + text if text else ''})",
        retry=True,
    )
