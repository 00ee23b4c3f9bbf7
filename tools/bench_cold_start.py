"""A first-time user's wait: a fresh virtual environment, ``pip install`` of this checkout,
the first render, then a second (warm) one, each a whole command timed from outside.

The install compiles the kernels into the package (``setup.py``); the baseline in the
same run is the same checkout installed with ``RAYTRAD_BUILD_KERNELS=0``, which leaves
them to the first render as before. ``--previous SOURCE`` adds another source tree (the
previous release's checkout, say). The rows alternate, so the ratios hold on a noisy
machine; each install copies what a build reads first, so no build folder is shared.

    python tools/bench_cold_start.py [--runs 2] [--receivers 20000] [--previous SOURCE]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]

#: What a build of raytrad reads: copied alone, so that no earlier build's folder or
#: cache comes along.
BUILT_FROM = ("raytrad", "pyproject.toml", "setup.py", "README.md")


def _timed(argv: list[str], env: dict[str, str], cwd: Path) -> float:
    start = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=cwd)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return seconds


def one_try(source: Path, build_kernels: bool, receivers: int, work: Path) -> dict[str, float]:
    """Install ``source`` into a fresh venv and render twice: seconds of each step and the
    first render's ``kernels`` stage."""
    if work.exists():
        shutil.rmtree(work)
    tree = work / "source"
    tree.mkdir(parents=True)
    for name in BUILT_FROM:
        if (source / name).is_dir():
            shutil.copytree(
                source / name, tree / name, ignore=shutil.ignore_patterns("__pycache__")
            )
        elif (source / name).exists():  # an older tree may lack setup.py
            shutil.copy(source / name, tree / name)
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env["RAYTRAD_BUILD_KERNELS"] = "1" if build_kernels else "0"
    venv = work / "venv"
    python = venv / "bin" / "python"
    times = {"venv": _timed([sys.executable, "-m", "venv", str(venv)], env, work)}
    times["install"] = _timed([str(python), "-m", "pip", "install", "-q", "."], env, tree)
    scene = str(source / "scenes" / "cornell-box.obj")
    for name in ("first render", "warm render"):
        out = work / name.replace(" ", "-")
        argv = [str(venv / "bin" / "raytrad"), "render", scene, "-o", str(out), "-q"]
        times[name] = _timed([*argv, "--receivers", str(receivers)], env, work)
        if name == "first render":
            report = json.loads((out / "report.json").read_text())
            times["kernels"] = report["timings_seconds"]["kernels"]
    return times


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--runs", type=int, default=2, help="alternating runs of each row")
    parser.add_argument("--receivers", type=int, default=20000)
    parser.add_argument("--previous", type=Path, help="another source tree to install")
    args = parser.parse_args()
    rows = {
        "this checkout (kernels compiled at install)": (REPOSITORY, True),
        "this checkout, RAYTRAD_BUILD_KERNELS=0 (compiled by the first render)": (
            REPOSITORY,
            False,
        ),
    }
    if args.previous is not None:
        rows[f"previous: {args.previous}"] = (args.previous.resolve(), True)
    work = Path(tempfile.mkdtemp(prefix="bench-cold-"))
    results: dict[str, list[dict[str, float]]] = {name: [] for name in rows}
    try:
        for _ in range(args.runs):
            for name, (source, build) in rows.items():
                results[name].append(one_try(source, build, args.receivers, work / "try"))
                print(f"{name}: {results[name][-1]}", file=sys.stderr)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    steps = ("install", "first render", "kernels", "warm render")
    print(f"\ncold start, Cornell box at --receivers {args.receivers}, medians of {args.runs}")
    print("| install | " + " | ".join(f"{s} [s]" for s in steps) + " | install + first [s] |")
    print("|---" * (len(steps) + 2) + "|")
    totals = {}
    for name, tries in results.items():
        median = {s: statistics.median(t[s] for t in tries) for s in steps}
        totals[name] = statistics.median(t["install"] + t["first render"] for t in tries)
        cells = " | ".join(f"{median[s]:.2f}" for s in steps)
        print(f"| {name} | {cells} | {totals[name]:.1f} |")
    first, *others = totals
    for name in others:
        print(f"{first} / {name}, install + first render: {totals[first] / totals[name]:.2f}")


if __name__ == "__main__":
    main()
