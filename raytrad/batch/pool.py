"""The default runner: jobs in processes on this machine, each in a fresh process.

Each job runs in its own ``python -m raytrad.batch.worker`` process, which reads the job
from a file and writes its result to another, in a temporary folder of the job's own that
is removed when the job ends. A crash or ``kill -9`` of one job's process
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
#: Seconds :meth:`LocalPool.close` gives a stopping job before it is killed.
CLOSE_SECONDS = 60.0


class WorkerLost(RuntimeError):
    """A job's process ended without writing its result (killed, crashed)."""


@dataclass(eq=False)
class _Running:
    process: subprocess.Popen[bytes]
    folder: Path  # the job's pickle and result, removed when the job ends


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
        self._running: set[_Running] = set()

    def submit(self, job: Job) -> _Running:
        folder = Path(tempfile.mkdtemp(prefix="raytrad-job-"))
        job_path, result_path = folder / "job.pickle", folder / "result.pickle"
        job_path.write_bytes(pickle.dumps(job))
        environment = {**os.environ, THREADS_VARIABLE: str(self.threads)}
        process = subprocess.Popen(
            [sys.executable, "-m", "raytrad.batch.worker", str(job_path), str(result_path)],
            env=environment,
            stdin=subprocess.DEVNULL,
        )
        running = _Running(process, folder)
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
            result = pickle.loads((handle.folder / "result.pickle").read_bytes())
        except (OSError, pickle.UnpicklingError, EOFError):
            result = None
        finally:
            shutil.rmtree(handle.folder, ignore_errors=True)
        if result is None:
            how = f"killed by signal {-code}" if code < 0 else f"exit status {code}"
            return WorkerLost(f"the job's process ended without a result ({how})")
        return result if isinstance(result, JobResult) else WorkerLost("unreadable result")

    def interrupt(self) -> None:
        for handle in self._running:
            if handle.process.poll() is None:
                handle.process.send_signal(signal.SIGTERM)

    def close(self) -> None:
        """Stop the running jobs cleanly (SIGTERM; they save checkpoints) and wait for
        them, at most :data:`CLOSE_SECONDS` each; Ctrl-C while waiting kills them."""
        for handle in self._running:
            if handle.process.poll() is None:
                handle.process.send_signal(signal.SIGTERM)
        try:
            for handle in self._running:
                try:
                    handle.process.wait(timeout=CLOSE_SECONDS)
                except subprocess.TimeoutExpired:
                    handle.process.kill()
        except KeyboardInterrupt:  # a second Ctrl-C: abort
            for handle in self._running:
                handle.process.kill()
            raise
        finally:
            for handle in self._running:
                shutil.rmtree(handle.folder, ignore_errors=True)
            self._running.clear()

    def abort(self) -> None:
        for handle in self._running:
            handle.process.kill()
        self.close()

    def __enter__(self) -> LocalPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
