"""``raytrad bake MANIFEST``: a manifest's jobs, their options read as ``raytrad render``
reads its own, run on a local pool or a Dask cluster, with a summary at the end."""

from __future__ import annotations

import argparse
import difflib
import signal
import sys
import time
from pathlib import Path
from typing import Any

from raytrad.batch import (
    SUMMARY,
    DaskRunner,
    Job,
    JobResult,
    JobSpec,
    LocalPool,
    Runner,
    bake,
    read_manifest,
    summary_record,
    summary_table,
    write_summary,
)
from raytrad.cli.options import render_settings
from raytrad.cli.parser import build_parser
from raytrad.cli.signals import StopFlag, stopping_on_signals
from raytrad.settings import SettingsError

#: Render options a manifest cannot set: the job gives scene and output, a bake resumes
#: by itself and keeps the console to its own messages.
NOT_IN_MANIFEST = ("scene", "output", "resume", "quiet", "verbose", "help", "reference")


def _render_parser() -> argparse.ArgumentParser:
    """The ``render`` command's parser, raising SettingsError instead of exiting."""
    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    render: argparse.ArgumentParser = commands.choices["render"]

    def error(message: str) -> Any:
        raise SettingsError(message)

    render.error = error  # type: ignore[method-assign]
    return render


def _option_names(render: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {
        flag[2:].replace("-", "_"): action
        for action in render._actions
        for flag in action.option_strings
        if flag.startswith("--")
    }


def job_from_spec(spec: JobSpec, manifest: Path, render: argparse.ArgumentParser) -> Job:
    """``spec``'s options understood as ``raytrad render`` understands its own.

    Raises
    ------
    SettingsError
        One line naming the manifest, the job and the option: an unknown option (with the
        nearest known one), one a manifest cannot set, or a value the option refuses.
    """
    names = _option_names(render)
    argv = [str(spec.scene), "--output", str(spec.output)]
    for key, value in spec.options.items():
        where = f"{manifest}: job {spec.name!r}" if key in spec.own else f"{manifest}: [defaults]"
        if key in NOT_IN_MANIFEST:
            raise SettingsError(f"{where}: {key!r} cannot be set in a manifest")
        if key not in names:
            near = difflib.get_close_matches(key, list(names), n=1)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            raise SettingsError(f"{where}: unknown option {key!r}{hint}")
        flag = "--" + key.replace("_", "-")
        if names[key].nargs == 0:  # a switch: true turns it on
            if not isinstance(value, bool):
                raise SettingsError(f"{where}: {key} wants true or false, got {value!r}")
            argv += [flag] if value else []
        elif isinstance(value, bool):
            raise SettingsError(f"{where}: {key} wants a value, not {str(value).lower()}")
        else:
            if names[key].type is int and isinstance(value, float) and value.is_integer():
                value = int(value)  # receivers = 2e4
            argv += [flag, str(value)]
    try:
        args = render.parse_args(argv)
        args.command = "render"
        settings = render_settings(args, args.method)
    except SettingsError as exc:
        raise SettingsError(f"{manifest}: job {spec.name!r}: {exc}") from None
    return Job(spec.name, spec.scene, spec.output, settings, plot=args.plot)


def _runner(args: argparse.Namespace, jobs: int) -> Runner:
    if args.local_cluster is not None or args.scheduler is not None:
        return DaskRunner(jobs, args.local_cluster, args.scheduler)
    try:
        return LocalPool(args.workers, jobs)
    except ValueError as exc:
        raise SettingsError(f"--workers: {exc}") from None


def run_bake(args: argparse.Namespace) -> int:
    """The ``bake`` command; returns the exit status (1 if a job failed, 128 + signal
    number if the bake was stopped)."""
    if args.retries < 0:
        raise SettingsError(f"--retries wants N >= 0, got {args.retries}")
    manifest = args.manifest
    render = _render_parser()
    jobs = [job_from_spec(spec, manifest, render) for spec in read_manifest(manifest)]
    summary_path = args.summary or manifest.parent / SUMMARY
    start = time.perf_counter()
    runner = _runner(args, len(jobs))
    if not args.quiet:
        print(f"bake       {len(jobs)} jobs from {manifest} ({runner.description})")
    finished = 0

    def report(result: JobResult) -> None:
        nonlocal finished
        finished += 1
        if not args.quiet or result.status == "failed":
            tail = f": {result.message}" if result.message else ""
            status = result.status + (
                " (resumed)"
                if result.resumed
                else " (after a lost run)"
                if result.recovered
                else ""
            )
            print(
                f"[{finished}/{len(jobs)}] {result.name}: {status} in {result.seconds:.1f} s{tail}",
                file=sys.stderr,
            )

    stop = StopFlag(
        "stopping the bake: running jobs save checkpoints, no new ones start (Ctrl-C again "
        "to abort)",
        abort_on=(signal.SIGINT,),
    )
    try:
        with stopping_on_signals(stop):
            results = bake(jobs, runner, args.retries, report, stop)
    finally:
        runner.close()
    record = summary_record(
        manifest.resolve(), jobs, results, runner.description, time.perf_counter() - start
    )
    write_summary(summary_path, record)
    if not args.quiet:
        print(summary_table(record), end="")
        print(f"wrote      {summary_path}")
    if stop.signum:
        return 128 + stop.signum
    return 1 if any(result.status in ("failed", "interrupted") for result in results) else 0
