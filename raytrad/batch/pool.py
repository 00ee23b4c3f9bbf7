"""The default runner: jobs in processes on this machine, each in a fresh process.

Each job runs in its own ``python -m raytrad.batch.worker`` process, which reads the job
from a file and writes its result to another. A crash or ``kill -9`` of one job's process
loses only that job (the driver retries it), memory a render held goes back to the
system, and the caller's own script is never imported again in the children (as
``multiprocessing``'s spawn would, which breaks scripts without a ``__main__`` guard). The
cores are shared out: ``slots`` jobs at once, each rendering with ``cores // slots``
threads.
"""

from __future__ import annotations

import os
import pickle
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from raytrad.batch.jobs import Job, JobResult
from raytrad.core.visibility import THREADS_VARIABLE, worker_count

#: Seconds :meth:`LocalPool.wait` waits before returning (so that signals are seen).
POLL_SECONDS = 0.5


class WorkerLost(RuntimeError):
    """A job's process ended without writing its result (killed, crashed)."""


@dataclass(eq=False)
class _Running:
    process: subprocess.Popen[bytes]
    result_path: Path


class LocalPool:
    """Run jobs in processes on this machine.

    Parameters
    ----------
    workers : int or None
        Jobs at once; None: one per core. Never more than ``jobs``.
    jobs : int
        How many jobs there are.

    Raises
    ------
    ValueError
        ``workers`` < 1.
    """

    def __init__(self, workers: int | None, jobs: int) -> None:
        if workers is not None and workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        cores = worker_count()
        self.slots = max(1, min(workers or cores, jobs))
        self.threads = max(1, cores // self.slots)
        self.description = (
            f"local pool: {self.slots} process{'es' if self.slots > 1 else ''}, "
            f"{self.threads} thread{'s' if self.threads > 1 else ''} each"
        )
        self._folder: Path | None = None
        self._running: set[_Running] = set()
        self._count = 0

    def submit(self, job: Job) -> _Running:
        if self._folder is None:
            self._folder = Path(tempfile.mkdtemp(prefix="raytrad-bake-"))
        self._count += 1
        job_path = self._folder / f"job-{self._count}.pickle"
        job_path.write_bytes(pickle.dumps(job))
        result_path = self._folder / f"result-{self._count}.pickle"
        environment = {**os.environ, THREADS_VARIABLE: str(self.threads)}
        process = subprocess.Popen(
            [sys.executable, "-m", "raytrad.batch.worker", str(job_path), str(result_path)],
            env=environment,
            stdin=subprocess.DEVNULL,
        )
        running = _Running(process, result_path)
        self._running.add(running)
        return running

    def wait(self, handles: Collection[Any]) -> list[tuple[Any, JobResult | BaseException]]:
        end = time.monotonic() + POLL_SECONDS
        while True:
            finished = [h for h in handles if h.process.poll() is not None]
            if finished or time.monotonic() >= end:
                break
            time.sleep(0.02)
        return [(handle, self._collect(handle)) for handle in finished]

    def _collect(self, handle: _Running) -> JobResult | BaseException:
        self._running.discard(handle)
        code = handle.process.returncode
        try:
            result = pickle.loads(handle.result_path.read_bytes())
        except (OSError, pickle.UnpicklingError, EOFError):
            how = f"killed by signal {-code}" if code < 0 else f"exit status {code}"
            return WorkerLost(f"the job's process ended without a result ({how})")
        return result if isinstance(result, JobResult) else WorkerLost("unreadable result")

    def interrupt(self) -> None:
        for handle in self._running:
            if handle.process.poll() is None:
                handle.process.send_signal(signal.SIGTERM)

    def close(self) -> None:
        for handle in self._running:
            if handle.process.poll() is None:
                handle.process.send_signal(signal.SIGTERM)
        for handle in self._running:
            try:
                handle.process.wait(timeout=60)
            except subprocess.TimeoutExpired:
                handle.process.kill()
        self._running.clear()
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)
            self._folder = None
