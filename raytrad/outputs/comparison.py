"""Writing a method comparison: ``compare.json``, ``compare.md`` (the table) and
``compare.png`` (true error against time).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from raytrad.core.compare import LEVELS, MethodRun
from raytrad.formats.atomic import atomic_write
from raytrad.outputs.plot import plot_convergence


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The comparison table in Markdown."""

    def cell(value: Any, digits: str) -> str:
        if value is None:
            return "not reached"
        return format(value, digits)

    head = ["method"]
    for level in LEVELS:
        head += [f"s to {level:g}", f"shots to {level:g}"]
    head += ["final error", "shots", "rays", "seconds", "stop"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["method"]]
        for level in LEVELS:
            cells += [cell(r[f"seconds_to_{level:g}"], ".2f"), cell(r[f"shots_to_{level:g}"], "d")]
        cells += [
            cell(r["final_true_rms"], ".2e"),
            str(r["shots"]),
            str(r["rays"]),
            f"{r['seconds']:.2f}",
            r["stop_reason"],
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_comparison(
    output_dir: Path, summary: dict[str, Any], runs: list[MethodRun], title: str
) -> None:
    """Write ``compare.json`` (``summary``), ``compare.md`` and ``compare.png``."""
    with atomic_write(output_dir / "compare.json", "w") as handle:
        json.dump(summary, handle, indent=2, default=_json_default, allow_nan=False)
    text = (
        f"# Method comparison: {summary['scene']}\n\n"
        f"{summary['receivers']} receivers, {summary['patches']} patches; true error "
        f"against the {summary['reference']['kind']} reference "
        f"({summary['reference']['description']}), relative RMS, worst channel.\n\n"
        + markdown_table(summary["table"])
    )
    with atomic_write(output_dir / "compare.md", "w") as handle:
        handle.write(text)
    plot_convergence(output_dir / "compare.png", {r.method: r.log for r in runs}, title)


def _json_default(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
