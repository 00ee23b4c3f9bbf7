"""The process :class:`~raytrad.batch.pool.LocalPool` starts for one job:
``python -m raytrad.batch.worker JOB RESULT`` reads the pickled job, runs it and writes the
pickled :class:`~raytrad.batch.jobs.JobResult` atomically (no result: the process was
lost)."""

from __future__ import annotations

import pickle
import sys
from collections.abc import Sequence
from pathlib import Path

from raytrad.batch.jobs import init_worker, run_job
from raytrad.formats.atomic import atomic_write


def main(argv: Sequence[str] | None = None) -> int:
    job_path, result_path = (argv if argv is not None else sys.argv[1:])[:2]
    job = pickle.loads(Path(job_path).read_bytes())
    init_worker()
    result = run_job(job)
    with atomic_write(Path(result_path), "wb") as handle:
        pickle.dump(result, handle)
    return 0


if __name__ == "__main__":
    sys.exit(main())
