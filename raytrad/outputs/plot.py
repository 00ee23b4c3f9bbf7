"""Convergence plots: the one module that imports matplotlib, and only when asked to."""

from __future__ import annotations

from pathlib import Path

from raytrad.core.convergence import ErrorLog
from raytrad.formats.atomic import atomic_write


def _worst(rows: list[list[float]]) -> list[float]:
    return [max(row) for row in rows]


def plot_convergence(path: Path, logs: dict[str, ErrorLog], title: str) -> None:
    """Write a PNG of relative error (log scale) against seconds for one or more solves.

    Each solve shows its true error (solid) when a reference was known, its error
    estimate (dashed) and its guaranteed bound (dotted); the worst channel is plotted.

    Parameters
    ----------
    path : Path
        PNG file to write (atomically).
    logs : dict
        Label -> ErrorLog.
    title : str
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    figure, axes = plt.subplots(figsize=(8, 5), dpi=100)
    for index, (label, log) in enumerate(logs.items()):
        colour = f"C{index}"
        if log.true_rms:
            axes.plot(log.seconds, _worst(log.true_rms), color=colour, label=f"{label}: true")
        axes.plot(
            log.seconds,
            _worst(log.estimate),
            color=colour,
            linestyle="--",
            label=f"{label}: estimate",
        )
        axes.plot(
            log.seconds,
            _worst(log.bound_rms),
            color=colour,
            linestyle=":",
            label=f"{label}: bound",
        )
    axes.set_yscale("log")
    axes.set_xlabel("solve time [s]")
    axes.set_ylabel("relative RMS error (worst channel)")
    axes.set_title(title)
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize="small")
    figure.tight_layout()
    with atomic_write(path) as handle:
        figure.savefig(handle, format="png")
    plt.close(figure)
