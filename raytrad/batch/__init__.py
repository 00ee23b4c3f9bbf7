"""Batch baking: a manifest of jobs run in a local process pool or on a Dask cluster.

>>> from raytrad.batch import LocalPool, bake, read_manifest   # doctest: +SKIP

:mod:`~raytrad.batch.manifest` reads the TOML manifest, :mod:`~raytrad.batch.jobs` runs
one job (skip, render or fail with one line), :mod:`~raytrad.batch.driver` runs a list of
jobs with retries on a runner (:mod:`~raytrad.batch.pool` or :mod:`~raytrad.batch.dask`),
and :mod:`~raytrad.batch.summary` writes what became of them.
"""

from __future__ import annotations

from raytrad.batch.dask import DaskRunner
from raytrad.batch.driver import Runner, bake
from raytrad.batch.jobs import STATUSES, Job, JobResult, run_job
from raytrad.batch.manifest import JobSpec, read_manifest
from raytrad.batch.pool import LocalPool
from raytrad.batch.summary import (
    SUMMARY,
    status_text,
    summary_record,
    summary_table,
    write_summary,
)

__all__ = [
    "STATUSES",
    "SUMMARY",
    "DaskRunner",
    "Job",
    "JobResult",
    "JobSpec",
    "LocalPool",
    "Runner",
    "bake",
    "read_manifest",
    "run_job",
    "status_text",
    "summary_record",
    "summary_table",
    "write_summary",
]
