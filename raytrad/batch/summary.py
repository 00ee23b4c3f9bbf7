"""A bake's summary: the table printed at the end and ``bake-summary.json``."""

from __future__ import annotations

import json
import time
from collections import Counter
from pathlib import Path
from typing import Any

from raytrad import __version__
from raytrad.batch.jobs import STATUSES, Job, JobResult
from raytrad.formats.atomic import atomic_write

#: The summary's file name, beside the manifest unless told otherwise.
SUMMARY = "bake-summary.json"


def summary_record(
    manifest: Path | None,
    jobs: list[Job],
    results: list[JobResult],
    runner: str,
    seconds: float,
) -> dict[str, Any]:
    """The summary as written to JSON: the bake, then one entry per job in manifest order
    (its result, scene and output folder)."""
    counts = Counter(result.status for result in results)
    return {
        "raytrad": __version__,
        "manifest": None if manifest is None else str(manifest),
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "runner": runner,
        "seconds": seconds,
        "counts": {status: counts.get(status, 0) for status in STATUSES},
        "jobs": [
            {**result.as_dict(), "scene": str(job.scene), "output": str(job.output)}
            for job, result in zip(jobs, results, strict=True)
        ],
    }


def write_summary(path: Path, record: dict[str, Any]) -> None:
    """Write ``record`` to ``path`` atomically."""
    with atomic_write(path, "w") as handle:
        json.dump(record, handle, indent=2)


def status_text(status: str, resumed: bool, recovered: bool) -> str:
    """A job's status as the table and the progress lines show it: marked ``(resumed)``
    when it continued from a checkpoint, else ``(after a lost run)`` when it took over the
    folder of a run that was lost."""
    if resumed:
        return f"{status} (resumed)"
    return f"{status} (after a lost run)" if recovered else status


def summary_table(record: dict[str, Any]) -> str:
    """The summary as a plain-text table, one row per job, and a closing count."""
    rows = [("job", "status", "tries", "seconds", "error", "outputs")]
    base = Path(record["manifest"]).resolve().parent if record["manifest"] else Path.cwd()
    for job in record["jobs"]:
        error = "-" if job["error"] is None else f"{job['error']:.2e}"
        folder = Path(job["output"])
        if folder.is_relative_to(base):
            folder = folder.relative_to(base)
        outputs = f"{len(job['outputs'])} files in {folder}" if job["outputs"] else "-"
        status = status_text(job["status"], job["resumed"], job["recovered"])
        rows.append(
            (job["name"], status, str(job["attempts"]), f"{job['seconds']:.1f}", error, outputs)
        )
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = [
        "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
        for row in rows
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    for job in record["jobs"]:
        if job["message"]:
            lines.append(f"{job['name']}: {job['message']}")
    counts = ", ".join(f"{n} {status}" for status, n in record["counts"].items() if n)
    lines.append(f"{counts} in {record['seconds']:.1f} s ({record['runner']})")
    return "\n".join(lines) + "\n"
