"""``raytrad`` command line: argument parsing, progress and messages; no numerics here."""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import signal
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from raytrad import api
from raytrad.cli.bake import run_bake
from raytrad.cli.options import render_settings
from raytrad.cli.parser import build_parser
from raytrad.cli.signals import StopFlag, stopping_on_signals

log = logging.getLogger("raytrad")

__all__ = ["build_parser", "main"]


def _verify(directory: Path, finished: bool) -> int:
    problems = api.verify_outputs(directory, finished=finished)
    for problem in problems:
        print(f"raytrad: {problem}", file=sys.stderr)
    if not problems:
        print(f"{directory}: complete and consistent{', finished' if finished else ''}")
    return 1 if problems else 0


class _Progress:
    """tqdm progress bars on a terminal; nothing when output is redirected (CI logs, which
    get the pass's progress as log lines instead).

    One bar a stage: the form-factor pass (columns), the solve (shots, the residual
    (unshot power / emitted power), the error estimate, rays/s and the time to the target
    tolerance extrapolated from the recent decay) and each refinement round's final
    gather (patches). tqdm gives the pass's and the gathers' time left from their rates.
    """

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self._bar: Any = None  # the solve's
        self._stage: tuple[str, Any] | None = None  # (name, bar) of the pass or a gather
        self._last = 0.0
        self._report: api.RenderProgress | None = None  # the solve's latest

    @staticmethod
    def _new_bar(**options: Any) -> Any:
        from tqdm import tqdm

        return tqdm(dynamic_ncols=True, file=sys.stderr, mininterval=0.25, **options)

    def __call__(self, report: api.RenderProgress) -> None:
        if not self.enabled:
            return
        self._end_stage()
        if self._bar is None:
            self._bar = self._new_bar(unit="shot", desc="solve")
        self._bar.update(report.shots - self._bar.n)
        self._report = report
        now = time.perf_counter()
        if now - self._last > 0.25:
            self._postfix()
            self._last = now

    def _postfix(self) -> None:
        """The solve's latest figures on its bar (rays/s once a quarter second is solved:
        before, a handful of rays over microseconds reads as a rate)."""
        report = self._report
        if report is None:
            return
        rate = f"{report.rays / report.seconds:.3g}" if report.seconds >= 0.25 else "-"
        eta_text = f"{report.eta:.0f}s" if math.isfinite(report.eta) else "?"
        self._bar.set_postfix_str(
            f"residual {report.residual:.2e}  error~{report.estimate:.1e}  "
            f"rays/s {rate}  ETA {eta_text}"
        )

    def _end_solve(self) -> None:
        """Close the solve's bar with its last figures, not the last throttled ones."""
        if self._bar is not None:
            self._postfix()
            self._bar.close()
            self._bar = None

    def stage(self, name: str, done: int, total: int) -> None:
        """``done`` of ``total`` columns of the pass, or patches of a final gather."""
        if not self.enabled:
            return
        self._end_solve()  # the solve is over, if it ran
        if self._stage is None or self._stage[0] != name or done < self._stage[1].n:
            self._end_stage()
            unit = "column" if name == "form factors" else "patch"
            self._stage = (name, self._new_bar(total=total, desc=name, unit=unit, leave=False))
        bar = self._stage[1]
        bar.update(done - bar.n)
        if done >= total:
            self._end_stage()

    def _end_stage(self) -> None:
        if self._stage is not None:
            self._stage[1].close()
            self._stage = None

    def close(self) -> None:
        self._end_stage()
        self._end_solve()


@contextlib.contextmanager
def _log_above(bars: bool) -> Iterator[None]:
    """Log lines printed above the progress bars rather than through them (tqdm's
    redirect of the console handlers), when there are bars."""
    if not bars:
        yield
        return
    from tqdm.contrib.logging import logging_redirect_tqdm

    with logging_redirect_tqdm():
        yield


def _compare(args: argparse.Namespace) -> int:
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    summary = api.compare(
        args.scene, args.output, methods, render_settings(args, "ambient"), args.reference
    )
    if not args.quiet:
        ref = summary["reference"]
        print(f"reference: {ref['kind']} ({ref['description']})")
        print(api.comparison_table(summary), end="")
        print(f"wrote      {args.output / 'compare.md'}, compare.json, compare.png")
    return 0


def _render(args: argparse.Namespace) -> int:
    settings = render_settings(args, args.method)
    progress = _Progress(enabled=not args.quiet)
    stop = StopFlag(
        "stopping after the current column, shot or refinement patch, then writing the "
        "results and a checkpoint (Ctrl-C again to abort)"
    )
    try:
        with stopping_on_signals(stop), _log_above(progress.enabled):
            with api.stage_progress(progress.stage if progress.enabled else None):
                outcome = api.render(
                    args.scene,
                    args.output,
                    settings,
                    args.resume,
                    progress,
                    stop,
                    reference=args.reference,
                    plot=args.plot,
                )
    finally:
        progress.close()
    if not args.quiet:
        _print_summary(outcome.report, outcome.outputs)
    if outcome.result.stop_reason == "interrupted" or stop.signum:  # or came after refinement
        return 128 + (stop.signum or signal.SIGINT)  # 130 for Ctrl-C, 143 for SIGTERM
    return 0


def _share(part: int, whole: int) -> str:
    return f"{100.0 * part / whole:.0f}%" if whole else "-"


def _taken_pass(taken: dict[str, Any]) -> str:
    """What a resumed run that traced nothing took of its pass from the checkpoint."""
    if taken.get("form_factor_scales") and not taken.get("form_factor_columns"):
        return " (the finished pass's balanced scales came from the checkpoint)"
    return " (every column came from the checkpoint)"


def _naive(rays: int, naive: int) -> str:
    """``rays`` against the naive count: seeing (receiver, patch) pairs x sample points
    (more than 100 % where many pairs are near: near sub-areas are traced per triangle)."""
    return f"{_share(rays, naive)} of a naive caster's {naive}"


def _named_below(error: dict[str, Any]) -> str:
    """Why the dominant part named is not the largest number, when it is not: the
    discretisation check sees an unfinished solve's error too, so it is named only above
    twice the algebraic part (:attr:`raytrad.core.accuracy.ErrorParts.dominant`)."""
    parts = error.get("parts") or {}

    def worst(name: str) -> float:
        return max((v for v in parts[name] if v is not None), default=0.0)

    largest = max(parts, key=worst, default=None)
    if largest == "discretisation" and error.get("dominant") == "algebraic":
        return (
            ", since the discretisation figure includes the unfinished solve's own error "
            "(it is named only above twice the algebraic)"
        )
    return ""


def _sampling(error: dict[str, Any], part: str) -> str:
    """`` ± SE`` after the discretisation part: its own standard error from the residual
    check's sampling, in the channel of its largest value (another seed's check lands
    within about that)."""
    spread = error.get("discretisation_standard_error")
    values = error["parts"][part]
    if part != "discretisation" or not spread or None in values or None in spread:
        return ""
    worst = spread[max(range(len(values)), key=values.__getitem__)]
    return f" ± {_fmt(worst)}" if worst > 0 else ""


def _solved(report: dict[str, Any]) -> str:
    """`` (N solved, the rest added by refinement)`` when refinement added receivers."""
    refinement = report.get("refinement") or {}
    if not refinement.get("receivers_added"):
        return ""
    return f" ({refinement['receivers_solved']} solved, the rest added by refinement)"


def _solve_end(report: dict[str, Any]) -> str:
    """How the solve ended, after how many shots: a converged solve whose refinement a
    signal cut short (``interrupted`` in the report) says it converged first."""
    s, refinement = report["solve"], report.get("refinement") or {}
    tolerance = report.get("settings", {}).get("solve", {}).get("tolerance", 0.0)
    line = f"{{}} after {s['shots']} shots, residual {s['residual']:.2e}"
    if s["stop_reason"] == "interrupted" and refinement.get("stopped"):
        if s["residual"] <= tolerance:
            return line.format("converged") + " (then interrupted while refining)"
    return line.format(s["stop_reason"])


def _print_summary(report: dict[str, Any], outputs: dict[str, Path]) -> None:
    s, stats, t = report["solve"], report["statistics"], report["timings_seconds"]
    total = sum(t.values())
    lines = [
        f"scene      {report['scene']}: {stats['receivers']} receivers{_solved(report)}, "
        f"{stats['patches']} patches, {stats['subareas']} sample points",
        f"solve      {s['method']}: {_solve_end(report)}",
        f"rays       {s['rays']} in the form-factor pass"
        + (" of this run" if report.get("resumed") else "")
        + (
            " (nothing can occlude, no rays needed)"
            if not stats["occlusion_tested"]
            else _taken_pass(report["resumed"])
            if report.get("resumed") and not s["rays_naive"]
            else f" ({s['rays_per_second']:.2e} rays/s; {_naive(s['rays'], s['rays_naive'])})"
        ),
        "time       " + ", ".join(f"{k} {v:.2f}s" for k, v in t.items()) + f"; total {total:.2f}s",
    ]
    error = report.get("error") or {}
    if error.get("estimate") is not None:
        text = (
            f"error      estimate {_fmt(max(_finite(error['estimate'])))}, "
            f"bound {_fmt(max(_finite(error['bound_rms'])))}"
        )
        if error.get("true_rms") is not None:
            text += f", true {max(error['true_rms']):.2e} ({report['reference']['kind']})"
        lines.append(text + " of the solve (relative RMS, worst channel)")
    if error.get("total_rms") is not None and math.isfinite(max(_finite(error["total_rms"]))):
        parts = ", ".join(
            f"{name} {_fmt(max(_finite(values)))}" + _sampling(error, name)
            for name, values in error["parts"].items()
        )
        lines.append(
            f"total      {_fmt(max(_finite(error['total_rms'])))} estimated against the "
            f"physical answer, {error['dominant']} dominates{_named_below(error)}: {parts}"
        )
    refinement = report.get("refinement") or {}
    why = "an interrupt" if report["solve"]["stop_reason"] == "interrupted" else "the time limit"
    cut = f"; stopped early by {why}" if refinement.get("stopped") else ""
    rounds = f"{refinement.get('rounds', 0)} round" + ("" if refinement.get("rounds") == 1 else "s")
    if refinement.get("receivers_interpolated"):
        rounds += " and one cut short"
        cut += f"; {refinement['receivers_interpolated']} of them interpolated: a round cut short"
    earlier = int((report.get("resumed") or {}).get("refinement_rounds", 0))
    if earlier:  # the counts are the whole refinement's, as the mesh is
        cut += f"; {earlier} of the rounds and their rays from an earlier run"
    if refinement.get("receivers_added"):
        lines.append(
            f"refined    +{refinement['receivers_added']} receivers in "
            f"{rounds} (solved {refinement['receivers_solved']}; "
            f"{refinement['rays']} rays, "
            f"{_naive(refinement['rays'], refinement['rays_naive'])}{cut})"
        )
    elif cut:
        lines.append(f"refined    nothing: {why} came first")
    lines += [f"wrote      {path}" for path in outputs.values()]
    print("\n".join(lines))


def _finite(values: list[float | None]) -> list[float]:
    return [math.inf if v is None else v for v in values]


def _fmt(value: float) -> str:
    return f"{value:.2e}" if math.isfinite(value) else "none yet"


def _subject(args: argparse.Namespace) -> Path:
    """What a command works on: its scene, else its manifest."""
    return Path(getattr(args, "scene", None) or args.manifest)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``raytrad`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "verify":
        return _verify(args.directory, args.finished)
    level = logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO
    logging.basicConfig(level=level, format="raytrad: %(levelname)s: %(message)s")
    logging.getLogger("trimesh").setLevel(logging.ERROR)
    logging.getLogger("numba").setLevel(logging.WARNING)  # its compiler's debug: 10^5 lines
    try:
        if args.command == "render":
            return _render(args)
        if args.command == "compare":
            return _compare(args)
        if args.command == "bake":
            return run_bake(args)
    except api.RaytradError as exc:
        print(f"raytrad: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # unwritable output directory, full disk, ...
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"raytrad: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("raytrad: aborted", file=sys.stderr)
        return 130
    except MemoryError:
        print(
            f"raytrad: error: {_subject(args)}: out of memory (lower --receivers or --cache-mb)",
            file=sys.stderr,
        )
        return 1
    except Exception as exc:  # a fault of raytrad's own: one line, the traceback with -v
        if args.verbose:
            raise
        print(
            f"raytrad: error: {_subject(args)}: internal error ({type(exc).__name__}: "
            f"{' '.join(str(exc).split())[:200]}); rerun with -v for the traceback and "
            "please report it",
            file=sys.stderr,
        )
        return 1
    parser.error(f"unknown command {args.command}")
    return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
