"""The Dask runner: jobs as tasks on a Dask distributed cluster (the optional extra
``raytrad[distributed]``; this is the one module that imports it, inside functions).

``--local-cluster N`` starts a :class:`distributed.LocalCluster` of N single-threaded
worker processes on this machine, each render using ``cores // N`` threads.
``--scheduler ADDRESS`` submits to a running cluster, where each render uses its
machine's cores divided by its worker's thread count (start one worker per machine, e.g.
``dask worker ADDRESS --nworkers 1 --nthreads 2``, for a job per core pair).

A worker that dies mid-job (killed, pre-empted, out of memory) loses its task; the
scheduler starts it again on another worker (up to Dask's
``distributed.scheduler.allowed-failures``), where it resumes from the job's last
checkpoint (``--checkpoint-every``). The driver's own retries come on top.
"""

from __future__ import annotations

import logging
import uuid
from collections.abc import Collection
from typing import Any

from raytrad.batch.jobs import Job, JobResult, log_to_stderr, run_job
from raytrad.core.visibility import worker_count
from raytrad.errors import SettingsError

log = logging.getLogger(__name__)

#: Seconds :meth:`DaskRunner.wait` waits before returning (so that signals are seen).
POLL_SECONDS = 0.5
#: Seconds to wait for a scheduler to answer.
CONNECT_SECONDS = 30


def _import_distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise SettingsError(
            "Dask is not installed; install raytrad's extra: pip install 'raytrad[distributed]'"
        ) from None
    return distributed


def _run_on_worker(job: Job, threads: int | None) -> JobResult:
    """Run ``job`` in a Dask worker with ``threads``, else the worker machine's cores
    divided by the worker's threads."""
    log_to_stderr()
    if threads is None:
        distributed = _import_distributed()
        slots = distributed.get_worker().state.nthreads
        threads = max(1, worker_count() // max(1, slots))
    return run_job(job, threads)


class DaskRunner:
    """Run jobs on a Dask cluster: a new local one, or one at ``scheduler``.

    Parameters
    ----------
    jobs : int
        How many jobs there are (all are submitted at once; the scheduler places them).
    local_cluster : int or None
        Start a ``LocalCluster`` with this many workers.
    scheduler : str or None
        Address of a running scheduler (``tcp://host:8786``); exclusive with
        ``local_cluster``.

    Raises
    ------
    SettingsError
        Dask is not installed, both or neither of ``local_cluster`` and ``scheduler``, or
        the scheduler does not answer.
    """

    def __init__(
        self, jobs: int, local_cluster: int | None = None, scheduler: str | None = None
    ) -> None:
        if (local_cluster is None) == (scheduler is None):
            raise SettingsError("give either a local cluster's size or a scheduler address")
        if local_cluster is not None and local_cluster < 1:
            raise SettingsError(f"--local-cluster wants N >= 1 workers, got {local_cluster}")
        distributed = _import_distributed()
        if not log.isEnabledFor(logging.DEBUG):  # Dask's own chatter only with -v
            logging.getLogger("distributed").setLevel(logging.WARNING)
        self._distributed = distributed
        self._cluster: Any = None
        self._submitted: set[Any] = set()
        self.slots = max(1, jobs)
        if local_cluster is not None:
            self.threads: int | None = max(1, worker_count() // local_cluster)
            self._cluster = distributed.LocalCluster(
                n_workers=local_cluster,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
            self.client = distributed.Client(self._cluster)
            self.description = (
                f"Dask LocalCluster: {local_cluster} worker{'s' if local_cluster > 1 else ''}, "
                f"{self.threads} thread{'s' if self.threads > 1 else ''} each"
            )
        else:
            self.threads = None
            try:
                self.client = distributed.Client(scheduler, timeout=CONNECT_SECONDS)
            except OSError as exc:
                raise SettingsError(f"{scheduler}: no Dask scheduler answers ({exc})") from exc
            self.description = f"Dask scheduler {scheduler}"

    def submit(self, job: Job) -> Any:
        key = f"raytrad-bake-{job.name}-{uuid.uuid4().hex[:8]}"
        future = self.client.submit(_run_on_worker, job, self.threads, key=key, pure=False)
        self._submitted.add(future)
        return future

    def wait(self, handles: Collection[Any]) -> list[tuple[Any, JobResult | BaseException]]:
        try:
            done, _ = self._distributed.wait(
                list(handles), timeout=POLL_SECONDS, return_when="FIRST_COMPLETED"
            )
        except TimeoutError:
            return []
        finished: list[tuple[Any, JobResult | BaseException]] = []
        for future in done:
            self._submitted.discard(future)
            if future.status == "finished":
                finished.append((future, future.result()))
            else:  # "error" (a worker lost too often: KilledWorker) or "cancelled"
                try:
                    error = future.exception()
                except BaseException as exc:  # a cancelled future raises its cancellation
                    error = exc
                finished.append((future, error or RuntimeError(future.status)))
        return finished

    def interrupt(self) -> None:
        """Cancel the running tasks; their workers keep the jobs' last checkpoints."""
        if self._submitted:
            self.client.cancel(list(self._submitted))

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()

    def abort(self) -> None:
        self.interrupt()
        self.close()

    def __enter__(self) -> DaskRunner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
